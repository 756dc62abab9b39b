"""railpaper.monitoring against hand computations, published tables and a brute-force simulation."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import stats as scipy_stats

from railpaper.monitoring import (
    cusum_alarms,
    cusum_average_run_length,
    detected_within,
    kaplan_meier,
    kaplan_meier_median,
    mean_time_between_false_alarms_h,
    poisson_count_interval,
    poisson_excess_power,
    poisson_p_two_sided,
    poisson_two_sided_power,
    running_for_power,
)


def test_cusum_alarms_restart_after_each_alarm_by_hand():
    # S: 0.5, 1.2 > 1 (alarm, reset), 0, 1.5 > 1 (alarm, reset), 0.2
    assert cusum_alarms([0.5, 0.7, -2.0, 1.5, 0.2], 1.0) == [2, 4]
    assert cusum_alarms([1.0, 0.0], 1.0) == []                       # S = h is not an alarm
    with pytest.raises(ValueError):
        cusum_alarms([1.0], 0.0)


def test_mean_time_between_false_alarms_and_its_poisson_bound_by_hand():
    none = mean_time_between_false_alarms_h(36_000.0, 0)          # 10 h, no alarm
    assert none.value_h == math.inf and none.running_h == 10.0
    assert none.lower_h == pytest.approx(10.0 / 2.995732, rel=1e-6)  # -ln(0.05) = 2.9957
    two = mean_time_between_false_alarms_h(36_000.0, 2)
    assert two.value_h == 5.0
    assert two.lower_h == pytest.approx(10.0 / (scipy_stats.chi2.ppf(0.95, 6) / 2))
    assert two.lower_h == pytest.approx(10.0 / 6.295794, rel=1e-6)   # Poisson upper, k = 2


@pytest.mark.parametrize("shift, published", [(0.0, 336.0), (1.0, 8.38)])
def test_brook_evans_average_run_length_matches_the_published_table(shift, published):
    """Standardised one-sided CUSUM, k = 0.5, h = 4: the values tabulated in the CUSUM literature
    (e.g. Hawkins & Olwell 1998; a two-sided scheme's 168 is half of 336); the brute-force test
    below checks the same function independently of any table."""
    arl = cusum_average_run_length(shift - 0.5, 4.0)
    assert arl == pytest.approx(published, rel=0.005)


def test_brook_evans_agrees_with_a_brute_force_run_length_simulation():
    rng = np.random.default_rng(20261206)
    n, h, drift = 20_000, 4.0, 0.5                          # shift 1, reference value 0.5
    s, run = np.zeros(n), np.zeros(n, dtype=int)
    alive = np.ones(n, dtype=bool)
    step = 0
    while alive.any():
        step += 1
        s = np.where(alive, np.maximum(0.0, s + rng.normal(drift, 1.0, n)), s)
        hit = alive & (s > h)
        run[hit], alive = step, alive & ~hit
    mean, se = run.mean(), run.std(ddof=1) / math.sqrt(n)
    assert abs(mean - cusum_average_run_length(drift, h)) < 4 * se


def test_kaplan_meier_by_hand():
    # delays 1, 2, 3 (record ended: censored), 4
    curve = kaplan_meier([1.0, 2.0, 3.0, 4.0], [True, True, False, True])
    assert curve.times.tolist() == [1.0, 2.0, 4.0]
    assert curve.survival.tolist() == [0.75, 0.5, 0.0]                 # 3/4, 3/4 * 2/3, 0
    assert curve.greenwood[:2].tolist() == pytest.approx([1 / 12, 1 / 12 + 1 / 6])
    assert detected_within([1.0, 2.0, 3.0, 4.0], [True, True, False, True], 2.5) == 0.5
    assert detected_within([1.0, 2.0], [True, True], 0.5) == 0.0
    with pytest.raises(ValueError, match="delay, not a code"):
        kaplan_meier([-1.0, 2.0], [False, True])                         # "not detected" as -1


def test_kaplan_meier_median_without_censoring_is_the_lower_sample_median():
    times = np.arange(1.0, 41.0)
    result = kaplan_meier_median(times, np.ones(40, bool))
    assert result.median == 20.0 and result.detected == 40 == result.n
    assert result.low < 20.0 < result.high                           # a proper interval
    # Brookmeyer-Crowley with log-log Greenwood: by hand at t = 14, S = 26/40
    s, g = 26 / 40, sum(1 / ((40 - i) * (39 - i)) for i in range(14))
    half = 1.959964 * math.sqrt(g) / abs(math.log(s))
    assert (s ** math.exp(half) <= 0.5) == (result.low <= 14.0)


def test_kaplan_meier_median_is_unbounded_when_most_records_are_never_detected():
    result = kaplan_meier_median([1.0, 2.0, 5.0, 5.0, 5.0, 5.0], [True, True] + [False] * 4)
    assert result.median is None and result.high is None and result.detected == 2


def test_restarted_alarms_from_a_stored_path_equal_the_restarted_recursion():
    from railpaper.monitoring import restarted_cusum_alarms

    rng = np.random.default_rng(7)
    for _ in range(20):
        increments = rng.normal(-0.2, 1.0, 500)
        path, g = [], 0.0
        for x in increments:                              # the detector's path, no restarts
            g = max(0.0, g + x)
            path.append(g)
        assert restarted_cusum_alarms(path, 3.0) == cusum_alarms(increments, 3.0)


def test_block_maxima_by_hand():
    from railpaper.monitoring import block_maxima
    x = [9.0, 9.0, 1.0, 3.0, 2.0, 5.0, 4.0, 0.0, 7.0]
    np.testing.assert_array_equal(block_maxima(x, 2, 3), [3.0, 5.0])   # 7.0: a partial block
    np.testing.assert_array_equal(block_maxima(x, 0, 1), x)
    with pytest.raises(ValueError):
        block_maxima(x, 0, 0)


def test_exponential_tail_by_hand():
    """Block maxima 1..10 of 0.5 s blocks: the 2 largest (9, 10) are the tail above 8, mean
    excess 1.5, 2 of 10 blocks exceed 8: one block in 5 (2.5 s) at the level; at
    8 + 1.5 ln 2 one in 10 (5 s); the threshold for 5 s is that value."""
    from railpaper.monitoring import fit_exponential_tail
    tail = fit_exponential_tail(np.arange(1.0, 11.0), block_s=0.5)
    assert (tail.level, tail.scale, tail.exceed, tail.blocks) == (8.0, 1.5, 0.2, 10)
    assert tail.mtbfa_h(8.0) * 3600 == pytest.approx(2.5)
    assert tail.mtbfa_h(8.0 + 1.5 * math.log(2.0)) * 3600 == pytest.approx(5.0)
    assert tail.threshold(5.0 / 3600) == pytest.approx(8.0 + 1.5 * math.log(2.0))
    with pytest.raises(ValueError, match="below the tail"):
        tail.mtbfa_h(7.0)
    assert tail.mtbfa_h(8.0 + 1.5 * 800) == math.inf             # e^800: never, not an error
    with pytest.raises(ValueError, match="at least 3"):
        fit_exponential_tail([1.0, 2.0], 0.5)


def test_exponential_tail_recovers_a_known_tail():
    """4000 block maxima 3 + Exp(1) (P(M > h) = e^{-(h-3)}), the 800 largest fitted: the mean
    time at the threshold exceeded once in 10^4 blocks, 12.5 times beyond the tail's own
    range, is right to the extrapolation's precision. Its log error is the scale's relative
    error (standard error 1/sqrt(800)) times (h - level) / scale = ln(10^4 / 800) ≈ 2.5 plus
    the level's own, about 0.27 in all: over 20 seeds the log errors have a mean within 0.2 of
    zero (0.12 here: the level, an order statistic, sits a little low) and none beyond 3
    standard errors (0.8)."""
    from railpaper.monitoring import fit_exponential_tail
    h = 3.0 + math.log(1e4)
    errors = []
    for seed in range(20):
        rng = np.random.default_rng(seed)
        tail = fit_exponential_tail(3.0 + rng.exponential(size=4000), block_s=1.0)
        errors.append(math.log(tail.mtbfa_h(h) * 3600 / 1e4))
    assert abs(np.mean(errors)) < 0.2 and np.max(np.abs(errors)) < 0.8


def test_shiryaev_roberts_bound_by_hand_and_by_simulation():
    """A = e^h samples: e^h = 720 samples of 5 s is one hour. Simulated: the Shiryaev-Roberts
    recursion R_n = (1 + R_{n-1}) exp(x_n - 1/2) for a unit mean shift of N(0, 1) data, run
    with no shift until R_n >= 50, has a mean run length above 50 (Pollak's bound; 4000 runs)."""
    from railpaper.monitoring import shiryaev_roberts_mtbfa_lower_h
    assert shiryaev_roberts_mtbfa_lower_h(math.log(720.0), 5.0) == pytest.approx(1.0)
    rng = np.random.default_rng(12)
    runs, r, length = 4000, np.zeros(4000), np.zeros(4000)
    alive = np.ones(runs, bool)
    while alive.any():
        r[alive] = (1.0 + r[alive]) * np.exp(rng.standard_normal(alive.sum()) - 0.5)
        length[alive] += 1
        alive &= r < 50.0
    assert length.mean() > 50.0


def test_poisson_excess_power_by_a_brute_force_sum():
    # mean 10: P(X >= 15 | 10) = 0.0835 > 0.05 >= P(X >= 16 | 10) = 0.0487, so the test
    # rejects from 16 alarms; the power is P(X >= 16 | 20), summed term by term here
    def tail(k, mean):
        return 1.0 - sum(math.exp(-mean) * mean ** j / math.factorial(j) for j in range(k))
    assert tail(15, 10.0) > 0.05 >= tail(16, 10.0)
    assert poisson_excess_power(10.0, 2.0) == pytest.approx(tail(16, 20.0), abs=1e-12)
    assert poisson_excess_power(10.0, 2.0) == pytest.approx(0.8435, abs=1e-4)


def test_running_for_power_is_the_first_size_that_reaches_the_power():
    # records of 3 s at a threshold for 0.1 h: n records predict n * 3 / 360 alarms
    n = running_for_power(0.1, 3.0)
    assert poisson_excess_power(n * 3.0 / 360.0, 2.0) >= 0.8
    assert all(poisson_excess_power(m * 3.0 / 360.0, 2.0) < 0.8 for m in range(1, n))
    assert n == 1088
    with pytest.raises(ValueError):
        running_for_power(0.1, 3.0, ratio=1.0)


def test_poisson_two_sided_power_by_a_brute_force_sum():
    # the rule: p = min(1, 2 min(P(X <= k), P(X >= k))) under mean 10 below 0.05 rejects; its
    # power is the mass of those counts under mean 20, summed term by term here
    def pmf(k, mean):
        return math.exp(-mean) * mean ** k / math.factorial(k)

    def p_value(k, mean):
        below = sum(pmf(j, mean) for j in range(k + 1))
        above = 1.0 - sum(pmf(j, mean) for j in range(k))
        return min(1.0, 2.0 * min(below, above))

    power = sum(pmf(k, 20.0) for k in range(120) if p_value(k, 10.0) < 0.05)
    assert poisson_two_sided_power(10.0, 2.0) == pytest.approx(power, abs=1e-10)
    assert poisson_two_sided_power(10.0, 2.0) < poisson_excess_power(10.0, 2.0)  # 0.025 a side


def test_poisson_p_value_and_count_interval_by_hand():
    # 0 alarms where 5 were expected: P(X <= 0) = e^-5, p = 2 e^-5; 5 of 5: both tails > 1/2
    assert poisson_p_two_sided(0, 5.0) == pytest.approx(2 * math.exp(-5.0))
    assert poisson_p_two_sided(5, 5.0) == 1.0
    assert poisson_p_two_sided(np.array([0, 5]), 5.0).tolist() == pytest.approx(
        [2 * math.exp(-5.0), 1.0])
    # Garwood: no event gives [0, -ln 0.025]; k events give the means whose tail beyond k is
    # 2.5 % each
    assert poisson_count_interval(0) == pytest.approx((0.0, -math.log(0.025)))
    low, high = poisson_count_interval(4)
    assert scipy_stats.poisson.sf(3, low) == pytest.approx(0.025)
    assert scipy_stats.poisson.cdf(4, high) == pytest.approx(0.025)
