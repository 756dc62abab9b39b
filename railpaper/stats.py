"""Monte Carlo evidence for the claims ledger: a statistic over seeds with its 95 % interval.

Every interval here is deterministic (no resampling, no random numbers), so the same samples give
the same bytes in ``metrics.json``:

* :func:`median_interval` — the sample median with the distribution-free order-statistic interval
  (the binomial(n, 1/2) quantiles pick the ranks);
* :func:`proportion_interval` — a rate k/n with the Clopper–Pearson (exact binomial) interval;
* :func:`mean_interval` — the mean with Student's t interval;
* :func:`prediction_interval` — where a single run falls: the central 95 % of the records
  (their 2.5 % and 97.5 % quantiles), each quantile with its own order-statistic confidence
  interval, for claims a paper read off one run (is its number a plausible draw?);
* :func:`paired_slope` — a trend with power: the mean over seeds of each seed's least-squares
  slope of the value on the level, with Student's t interval (the per-seed slopes are
  continuous, unlike a Spearman ρ over a few levels);
* :func:`paired_trend` — a trend over ordered levels (speeds) measured on the same seeds: the
  per-seed Spearman correlation between level and value, its median with an order-statistic
  interval, and the two-sided sign-test p-value of "as many seeds rise as fall".

``evidence_metrics`` turns one of these into the ``<name>``, ``<name>_low``, ``<name>_high`` and
``<name>_n`` metrics a claim rule reads (``primary``, ``interval``, ``n_samples``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import stats as _st

LEVEL = 0.95


@dataclass(frozen=True)
class Estimate:
    """A statistic of ``n`` Monte Carlo samples with its ``level`` interval [low, high]."""

    value: float
    low: float
    high: float
    n: int
    level: float = LEVEL

    def metrics(self, name: str) -> dict[str, float | int]:
        """``{name, name_low, name_high, name_n}`` for ``metrics.json``."""
        return {name: self.value, f"{name}_low": self.low, f"{name}_high": self.high,
                f"{name}_n": self.n}


def _finite(samples, what: str) -> np.ndarray:
    x = np.asarray(samples, dtype=float).ravel()
    if x.size == 0:
        raise ValueError(f"{what}: no samples")
    if not np.all(np.isfinite(x)):
        raise ValueError(f"{what}: samples must be finite (use a rate for 'never happened')")
    return x


def median_interval(samples, level: float = LEVEL) -> Estimate:
    """Sample median with its distribution-free order-statistic confidence interval.

    The interval is [x_(r), x_(n+1-r)] (1-based order statistics) with the largest r such that
    P(Binomial(n, 1/2) <= r - 1) <= (1 - level) / 2, so its coverage of the population median is
    at least ``level`` for any continuous distribution.  When n is too small for that (n <= 5 at
    95 %), the interval is [min, max] and covers with probability 1 - 2^(1-n) only.

    Parameters
    ----------
    samples : array_like
        Finite values, one per Monte Carlo sample.
    level : float
        Confidence level.
    """
    x = np.sort(_finite(samples, "median_interval"))
    n = x.size
    # largest r >= 1 with P(B <= r-1) <= alpha/2, B ~ Binomial(n, 1/2)
    r = int(_st.binom.ppf((1 - level) / 2, n, 0.5))      # smallest k with cdf(k) >= alpha/2
    if _st.binom.cdf(r, n, 0.5) > (1 - level) / 2:
        r -= 1                                          # now cdf(r) <= alpha/2 (or r = -1)
    r = max(r + 1, 1)                                   # rank of the lower end, 1-based
    return Estimate(float(np.median(x)), float(x[r - 1]), float(x[n - r]), n, level)


def proportion_interval(k: int, n: int, level: float = LEVEL) -> Estimate:
    """Rate k/n with the Clopper–Pearson (exact binomial) interval."""
    if n <= 0 or not 0 <= k <= n:
        raise ValueError(f"proportion_interval: need 0 <= k <= n and n > 0, got k={k}, n={n}")
    alpha = 1 - level
    low = 0.0 if k == 0 else float(_st.beta.ppf(alpha / 2, k, n - k + 1))
    high = 1.0 if k == n else float(_st.beta.ppf(1 - alpha / 2, k + 1, n - k))
    return Estimate(k / n, low, high, int(n), level)


def quantile_ranks(n: int, p: float, level: float = LEVEL) -> tuple[int, int]:
    """1-based ranks (l, u) of the distribution-free interval [x_(l), x_(u)] of the p-quantile.

    With B ~ Binomial(n, p) the number of samples below the quantile, P(x_(l) <= ξ_p <= x_(u))
    >= P(l <= B <= u − 1); l is the largest rank with P(B <= l − 1) <= (1 − level)/2 and u the
    smallest with P(B >= u) <= (1 − level)/2.  A rank that does not exist at this n (l < 1 or
    u > n) is clipped to the sample's minimum or maximum, whose coverage at that end is then
    below ``level`` (the interval says "no record went further", not more).
    """
    low, high = _quantile_ranks(n, p, level)
    return max(low, 1), min(high, n)


def _quantile_ranks(n: int, p: float, level: float) -> tuple[int, int]:
    """The unclipped ranks of :func:`quantile_ranks` (l < 1 or u > n: no such order statistic)."""
    alpha = (1 - level) / 2
    low = int(_st.binom.ppf(alpha, n, p))             # smallest k with cdf(k) >= alpha
    if _st.binom.cdf(low, n, p) > alpha:
        low -= 1                                      # cdf(low) <= alpha, or low = -1
    high = int(_st.binom.ppf(1 - alpha, n, p))        # smallest k with cdf(k) >= 1 - alpha
    return low + 1, high + 1


@dataclass(frozen=True)
class PredictionInterval:
    """The central ``coverage`` of the records: quantiles ``low`` and ``high`` (each a record's
    value), with the ``level`` interval of each quantile, over ``n`` records."""

    low: float
    low_low: float
    low_high: float
    high: float
    high_low: float
    high_high: float
    n: int
    coverage: float = 0.95
    low_clipped: bool = False
    high_clipped: bool = False

    def metrics(self, name: str) -> dict[str, float | int]:
        """``{name_p025, name_p025_low, name_p025_high, name_p975, …_low, …_high}`` and
        ``name_p025_clipped`` / ``name_p975_clipped`` (1 when that quantile's outer end is the
        sample's extreme, whose confidence is below the level: a rule must not call a value
        beyond it implausible).  The names are those of the default 95 % coverage."""
        return {f"{name}_p025": self.low, f"{name}_p025_low": self.low_low,
                f"{name}_p025_high": self.low_high, f"{name}_p975": self.high,
                f"{name}_p975_low": self.high_low, f"{name}_p975_high": self.high_high,
                f"{name}_p025_clipped": int(self.low_clipped),
                f"{name}_p975_clipped": int(self.high_clipped)}


def prediction_interval(samples, coverage: float = 0.95, level: float = LEVEL
                        ) -> PredictionInterval:
    """Central ``coverage`` prediction interval of one more record, from the records' quantiles.

    A paper's number read off one run is a plausible draw when it lies inside
    [q_(1−c)/2, q_(1+c)/2]; each quantile is the record at rank ⌈n·q⌉ (the inverted empirical
    cdf) and carries the order-statistic interval of :func:`quantile_ranks`, so a rule can tell
    "inside even the narrowest interval our n allows" from "outside even the widest".
    """
    x = np.sort(_finite(samples, "prediction_interval"))
    n = x.size
    ends, clipped = [], []
    # rounded: (1 - 0.95) / 2 is 0.025000000000000022 in floating point, which would move the
    # inverted-cdf quantile one rank up whenever n * 0.025 is an integer
    for q in (round((1 - coverage) / 2, 12), round((1 + coverage) / 2, 12)):
        point = float(np.quantile(x, q, method="inverted_cdf"))
        lo_rank, hi_rank = _quantile_ranks(n, q, level)
        ends += [point, float(x[max(lo_rank, 1) - 1]), float(x[min(hi_rank, n) - 1])]
        clipped.append(lo_rank < 1 if q < 0.5 else hi_rank > n)
    return PredictionInterval(*ends, n=n, coverage=coverage, low_clipped=clipped[0],
                              high_clipped=clipped[1])


def mean_interval(samples, level: float = LEVEL) -> Estimate:
    """Sample mean with Student's t interval (a single sample: the interval is the value)."""
    x = _finite(samples, "mean_interval")
    n = x.size
    mean = float(x.mean())
    if n == 1:
        return Estimate(mean, mean, mean, 1, level)
    half = float(_st.t.ppf(0.5 + level / 2, n - 1) * x.std(ddof=1) / np.sqrt(n))
    return Estimate(mean, mean - half, mean + half, n, level)


@dataclass(frozen=True)
class Trend:
    """A trend over ordered levels measured on the same seeds (see :func:`paired_trend`).

    Attributes
    ----------
    rho : Estimate
        Median over seeds of the per-seed Spearman correlation (level order vs value), with its
        order-statistic interval.
    rising, falling : int
        Seeds whose correlation is > 0 / < 0.
    sign_p : float
        Two-sided sign-test p-value of rising vs falling (ties dropped; 1.0 when all tie).
    """

    rho: Estimate
    rising: int
    falling: int
    sign_p: float

    def metrics(self, name: str) -> dict[str, float | int]:
        """``{name, name_low, name_high, name_n, name_sign_p, name_rising_fraction}``."""
        out = self.rho.metrics(name)
        out[f"{name}_sign_p"] = self.sign_p
        out[f"{name}_rising_fraction"] = self.rising / self.rho.n
        return out


def paired_trend(values, level: float = LEVEL) -> Trend:
    """Trend of a quantity over ordered levels, paired by seed.

    Parameters
    ----------
    values : array_like, shape (n_seeds, n_levels)
        ``values[i, j]``: the quantity on seed i at level j (levels in increasing order, e.g.
        speeds).  Each row is one paired experiment (same track and noise seed at every level).

    Returns
    -------
    Trend
        Per-seed Spearman ρ(level, value) summarised over seeds.  A row whose values are all
        equal has ρ = 0 (no trend).
    """
    v = np.asarray(values, dtype=float)
    if v.ndim != 2 or v.shape[1] < 2:
        raise ValueError(f"paired_trend: need shape (n_seeds, n_levels >= 2), got {v.shape}")
    if not np.all(np.isfinite(v)):
        raise ValueError("paired_trend: values must be finite")
    levels = np.arange(v.shape[1])
    rhos = []
    for row in v:
        if np.all(row == row[0]):
            rhos.append(0.0)
        else:
            rhos.append(float(_st.spearmanr(levels, row).statistic))
    rhos = np.asarray(rhos)
    rising, falling = int(np.sum(rhos > 0)), int(np.sum(rhos < 0))
    m = rising + falling
    p = 1.0 if m == 0 else float(_st.binomtest(rising, m, 0.5).pvalue)
    return Trend(median_interval(rhos, level), rising, falling, p)


def paired_slope(values, levels, level: float = LEVEL) -> Estimate:
    """Mean over seeds of the per-seed least-squares slope of value on level, t interval.

    Parameters
    ----------
    values : array_like, shape (n_seeds, n_levels)
        ``values[i, j]``: the quantity on seed i at level j (paired: same seed at every level).
    levels : array_like, shape (n_levels,)
        The levels (e.g. speeds, km/h); the slope is in value units per level unit.
    """
    v = np.asarray(values, dtype=float)
    x = np.asarray(levels, dtype=float)
    if v.ndim != 2 or v.shape[1] < 2 or x.shape != (v.shape[1],) or np.ptp(x) == 0:
        raise ValueError(f"paired_slope: need values (n_seeds, n_levels >= 2) and distinct "
                         f"levels of that length, got {v.shape} and {x.shape}")
    if not np.all(np.isfinite(v)):
        raise ValueError("paired_slope: values must be finite")
    dx = x - x.mean()
    slopes = (v - v.mean(axis=1, keepdims=True)) @ dx / (dx @ dx)     # OLS slope per seed
    return mean_interval(slopes, level)


def rate(hits, level: float = LEVEL) -> Estimate:
    """Rate of True among the records' flags with its Clopper–Pearson interval."""
    hits = np.asarray(hits, bool).ravel()
    return proportion_interval(int(hits.sum()), hits.size, level)


def max_abs_bias(errors, level: float = LEVEL) -> Estimate:
    """Largest |mean| over the columns of ``errors`` with a simultaneous interval.

    Each column's mean gets a Student t interval at level ``1 − (1 − level)/d`` (Bonferroni), so
    all d intervals hold together with probability >= ``level``; the interval of
    ``max_j |μ_j|`` is then [max_j distance of interval j from 0, max_j largest |end| of
    interval j].

    Parameters
    ----------
    errors : array_like, shape (n, d)
        One row per record, one column per parameter (e.g. final relative errors).
    level : float
        Simultaneous confidence level.
    """
    x = np.asarray(errors, float)
    if x.ndim != 2 or x.shape[0] < 2:
        raise ValueError(f"max_abs_bias needs shape (n >= 2, d), got {x.shape}")
    per = [mean_interval(col, 1.0 - (1.0 - level) / x.shape[1]) for col in x.T]
    return largest_abs(per, level)


def max_abs_median(samples, level: float = LEVEL) -> Estimate:
    """Largest |median| over the columns of ``samples`` (n, d) with a simultaneous interval: each
    column's median gets a distribution-free interval at the Bonferroni level
    ``1 − (1 − level)/d`` (:func:`median_interval`), combined as in :func:`largest_abs`."""
    x = np.asarray(samples, float)
    if x.ndim != 2 or x.shape[0] < 2:
        raise ValueError(f"max_abs_median needs shape (n >= 2, d), got {x.shape}")
    return largest_abs([median_interval(col, 1.0 - (1.0 - level) / x.shape[1]) for col in x.T],
                       level)


def largest_abs(per: list[Estimate], level: float = LEVEL) -> Estimate:
    """max_j |value_j| of simultaneous intervals ``per`` (one per parameter, all holding together
    at ``level``): the interval of the largest |value| is [max_j distance of interval j from 0,
    max_j largest |end| of interval j]."""
    return Estimate(max(abs(e.value) for e in per),
                    max(max(0.0, e.low, -e.high) for e in per),
                    max(max(abs(e.low), abs(e.high)) for e in per), per[0].n, level)
