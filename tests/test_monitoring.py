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
