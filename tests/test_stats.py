"""Monte Carlo evidence statistics against independent references (scipy, brute force)."""

import itertools
import math

import numpy as np
import pytest
from scipy import stats

from railpaper.stats import (
    mean_interval,
    median_interval,
    paired_trend,
    proportion_interval,
)


@pytest.mark.parametrize("n", [6, 9, 10, 20, 21, 50])
def test_median_interval_ranks_match_brute_force_binomial(n):
    """The ranks are the widest-inside symmetric pair whose exact coverage is >= 95 %."""
    x = np.arange(n, dtype=float)[::-1] * 1.5       # unsorted, distinct
    est = median_interval(x)
    # brute force: coverage of [x_(r), x_(n+1-r)] is 1 - 2 P(B <= r-1), B ~ Bin(n, 1/2)
    cover = {r: 1 - 2 * sum(stats.binom.pmf(k, n, 0.5) for k in range(r)) for r in range(1, n // 2 + 1)}
    r = max(r for r, c in cover.items() if c >= 0.95)
    xs = np.sort(x)
    assert est.low == xs[r - 1] and est.high == xs[n - r]
    assert est.value == np.median(x) and est.n == n


def test_median_interval_small_n_is_min_max():
    est = median_interval([3.0, 1.0, 2.0, 5.0, 4.0])
    assert (est.low, est.high, est.value) == (1.0, 5.0, 3.0)


def test_median_interval_covers_at_least_nominal():
    rng = np.random.default_rng(1)
    samples = rng.exponential(size=(4000, 20))
    hits = 0
    for s in samples:
        e = median_interval(s)
        hits += e.low <= np.log(2) <= e.high
    assert hits / len(samples) > 0.945


@pytest.mark.parametrize("k,n", [(0, 10), (3, 10), (10, 10), (7, 20), (1, 1)])
def test_proportion_interval_is_clopper_pearson(k, n):
    ref = stats.binomtest(k, n).proportion_ci(confidence_level=0.95, method="exact")
    est = proportion_interval(k, n)
    assert est.value == k / n
    assert est.low == pytest.approx(ref.low, abs=1e-12)
    assert est.high == pytest.approx(ref.high, abs=1e-12)


def test_proportion_interval_rejects_bad_counts():
    with pytest.raises(ValueError, match="0 <= k <= n"):
        proportion_interval(3, 2)


def test_mean_interval_matches_scipy_t_interval():
    x = np.array([1.0, 2.5, 2.0, 4.0, 3.5, 0.5])
    est = mean_interval(x)
    low, high = stats.t.interval(0.95, len(x) - 1, loc=x.mean(), scale=stats.sem(x))
    assert (est.low, est.high) == pytest.approx((low, high), rel=1e-12)


def test_nan_samples_refused():
    with pytest.raises(ValueError, match="finite"):
        median_interval([1.0, float("nan")])


def test_paired_trend_counts_rising_rows_and_sign_test():
    rng = np.random.default_rng(0)
    rising = np.sort(rng.normal(size=(15, 4)), axis=1)           # every seed strictly rising
    falling = np.sort(rng.normal(size=(5, 4)), axis=1)[:, ::-1]  # five seeds falling
    trend = paired_trend(np.vstack([rising, falling]))
    assert (trend.rising, trend.falling) == (15, 5)
    assert trend.rho.value == 1.0
    assert trend.sign_p == pytest.approx(stats.binomtest(15, 20, 0.5).pvalue)
    metrics = trend.metrics("t")
    assert metrics["t_rising_fraction"] == 0.75 and metrics["t_n"] == 20


def test_paired_trend_rho_is_scipy_spearman_per_row():
    v = np.array([[1.0, 3.0, 2.0, 4.0], [4.0, 1.0, 2.0, 3.0], [2.0, 2.0, 2.0, 2.0]])
    expected = [stats.spearmanr(range(4), v[0]).statistic,
                stats.spearmanr(range(4), v[1]).statistic, 0.0]
    assert paired_trend(v).rho.value == pytest.approx(np.median(expected))


@pytest.mark.parametrize("n, p", [(20, 0.025), (100, 0.025), (100, 0.975), (400, 0.025),
                                  (400, 0.975), (1000, 0.5), (37, 0.3)])
def test_quantile_ranks_cover_and_are_the_tightest(n, p):
    """The order-statistic interval of a quantile against the brute-force binomial sum: its
    coverage P(l <= B <= u - 1) is >= 95 % (unless a rank was clipped at the sample's end), and
    moving either rank inward drops one tail's share below 2.5 %."""
    from railpaper.stats import quantile_ranks
    low, high = quantile_ranks(n, p)
    pmf = [math.comb(n, k) * p ** k * (1 - p) ** (n - k) for k in range(n + 1)]
    below = sum(pmf[:low - 1])                  # P(B <= l - 1): the quantile lies below x_(l)
    above = sum(pmf[high:])                     # P(B >= u): it lies above x_(u)
    assert low == 1 or below <= 0.025 + 1e-12
    assert high == n or above <= 0.025 + 1e-12
    assert sum(pmf[:low + 1]) > 0.025 - 1e-12   # l + 1 would leave more than 2.5 % below
    assert high == n or sum(pmf[high - 1:]) > 0.025 - 1e-12


def test_prediction_interval_holds_a_new_record_95_percent_of_the_time():
    """Over many simulated sets of records, one more record falls inside [q_2.5, q_97.5] about
    95 % of the time (distribution-free), and the quantiles' intervals hold the true quantiles
    of the distribution at least as often as their level (away from clipped ends)."""
    from scipy import stats as st
    from railpaper.stats import prediction_interval
    rng = np.random.default_rng(3)
    n, trials = 400, 2000
    inside = low_covered = high_covered = 0
    q_low, q_high = st.norm.ppf(0.025), st.norm.ppf(0.975)
    for _ in range(trials):
        pi = prediction_interval(rng.standard_normal(n))
        x = rng.standard_normal()
        inside += pi.low <= x <= pi.high
        low_covered += pi.low_low <= q_low <= pi.low_high
        high_covered += pi.high_low <= q_high <= pi.high_high
    assert abs(inside / trials - 0.95) < 0.015
    assert low_covered / trials >= 0.94 and high_covered / trials >= 0.94
    assert pi.metrics("x")["x_p025_low"] == pi.low_low and pi.n == n


def test_paired_slope_is_the_mean_of_scipy_per_seed_regressions():
    """Against scipy.stats.linregress per seed and scipy's t interval of their mean."""
    from railpaper.stats import paired_slope
    rng = np.random.default_rng(5)
    speeds = np.array([40.0, 60.0, 100.0, 160.0, 200.0])
    values = 0.1 + 2e-4 * speeds + rng.normal(0, 0.01, (30, speeds.size))
    est = paired_slope(values, speeds)
    slopes = [stats.linregress(speeds, row).slope for row in values]
    low, high = stats.t.interval(0.95, len(slopes) - 1, loc=np.mean(slopes),
                                 scale=stats.sem(slopes))
    assert est.value == pytest.approx(np.mean(slopes), rel=1e-12)
    assert (est.low, est.high) == (pytest.approx(low, rel=1e-10), pytest.approx(high, rel=1e-10))
    assert est.n == 30 and est.low > 0                  # the rise of 2e-4 s per km/h is found
    with pytest.raises(ValueError, match="distinct levels"):
        paired_slope(values, np.ones(5))
