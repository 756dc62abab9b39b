"""Condition-monitoring statistics: false alarms as the field counts them, delays as survival data.

A detector on a railway vehicle is judged by two numbers: how long it runs on a healthy vehicle
between false alarms, and how soon it alarms after a fault.  This module holds the arithmetic
of both, independent of any detector:

* :func:`cusum_alarms` — the one-sided CUSUM recursion ``S_k = max(0, S_{k-1} + x_k)`` with an
  alarm when ``S_k > h`` and a restart at zero after each alarm (how a monitor keeps running);
* :func:`restarted_cusum_alarms` — the same alarms from the stored path of a CUSUM that was run
  without restarts (its increments are recoverable wherever the path is positive);
* :func:`mean_time_between_false_alarms_h` — fault-free running time over the alarms in it, in
  hours, with the one-sided lower confidence bound of a Poisson count (so 0 alarms in 10 h still
  says "at least 3.3 h", not "infinite");
* :func:`cusum_average_run_length` — Brook & Evans (1972): the CUSUM's average run length from
  a Markov chain on a grid of its state, for Gaussian increments;
* :func:`block_maxima` and :func:`fit_exponential_tail` — a threshold for a mean time between
  false alarms far beyond the running measured: the largest statistic in each block of
  fault-free running, an exponential tail fitted to the largest of them (the Gumbel domain of
  a log-likelihood ratio), and :class:`ExponentialTail`'s mean time at a threshold and
  threshold at a mean time; :func:`shiryaev_roberts_mtbfa_lower_h` — the bound E[T] ≥ A of a
  Shiryaev–Roberts detector with threshold A (Pollak 1987), for a detector whose likelihood
  ratios are exact;
* :func:`poisson_p_two_sided` and :func:`poisson_count_interval` — a count of alarms against
  the count a model predicts, and the exact interval of its mean;
* :func:`poisson_excess_power` and :func:`running_for_power` — how much fault-free running a
  direct check of a tail model needs: the power of the one-sided Poisson test that finds
  ``ratio`` times the alarms the model predicts at a threshold for a given mean time;
* :func:`kaplan_meier` and :func:`kaplan_meier_median` — detection delays are censored (a record
  ends, or reaches flange contact, before the alarm): the Kaplan–Meier survival curve, its median
  with the Brookmeyer–Crowley interval (Greenwood's variance, log–log transformed), and
  :func:`detected_within` — the probability of detection within a time.

>>> cusum_alarms([0.5, 0.7, -2.0, 1.5, 0.2], threshold=1.0)
[2, 4]
>>> round(mean_time_between_false_alarms_h(36000.0, 2).value_h, 3)
5.0
>>> kaplan_meier_median([1.0, 2.0, 3.0, 4.0], [True, True, False, True]).median
2.0
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Sequence

import numpy as np
from scipy import stats as scipy_stats

SECONDS_PER_HOUR = 3600.0


def cusum_alarms(increments: Sequence[float], threshold: float) -> list[int]:
    """Steps (1-based) at which the one-sided CUSUM ``S_k = max(0, S_{k-1} + x_k)`` alarms
    (``S_k > threshold``), restarting from ``S = 0`` after each alarm."""
    if threshold <= 0:
        raise ValueError(f"the CUSUM threshold must be positive, got {threshold}")
    alarms, s = [], 0.0
    for k, x in enumerate(np.asarray(increments, float), start=1):
        s = max(0.0, s + x)
        if s > threshold:
            alarms.append(k)
            s = 0.0
    return alarms


def restarted_cusum_alarms(path: Sequence[float], threshold: float) -> list[int]:
    """Alarms (1-based steps) of a CUSUM restarted at zero after each alarm, from the path
    ``g_k = max(0, g_{k-1} + l_k)`` of the same CUSUM run without restarts (what a detector
    stores).  Exact up to rounding: where ``g_k > 0`` the increment is ``l_k = g_k − g_{k−1}``; where
    ``g_k = 0`` the restarted path, never above the unrestarted one, is 0 too."""
    if threshold <= 0:
        raise ValueError(f"the CUSUM threshold must be positive, got {threshold}")
    g = np.asarray(path, float)
    alarms, restarted, previous = [], 0.0, 0.0
    for k, value in enumerate(g, start=1):
        restarted = max(0.0, restarted + value - previous) if value > 0 else 0.0
        previous = value
        if restarted > threshold:
            alarms.append(k)
            restarted = 0.0
    return alarms


@dataclass(frozen=True)
class FalseAlarmTime:
    """Mean time between false alarms (h) with its one-sided ``level`` lower bound (h)."""

    value_h: float
    lower_h: float
    alarms: int
    running_h: float


def mean_time_between_false_alarms_h(fault_free_s: float, alarms: int, level: float = 0.95
                                     ) -> FalseAlarmTime:
    """Fault-free running time over the false alarms in it (inf when there are none), in hours,
    with the one-sided lower bound ``T / (χ²_{level}(2 (k + 1)) / 2)`` of a Poisson count of k
    alarms in running time T (exact for a constant alarm rate)."""
    if fault_free_s < 0 or alarms < 0:
        raise ValueError("running time and alarms must be non-negative")
    running_h = fault_free_s / SECONDS_PER_HOUR
    upper_rate = float(scipy_stats.chi2.ppf(level, 2 * (alarms + 1))) / 2.0   # alarms per T
    value = math.inf if alarms == 0 else running_h / alarms
    return FalseAlarmTime(value, running_h / upper_rate, int(alarms), running_h)


def cusum_average_run_length(mean: float, threshold: float, sd: float = 1.0,
                             cells: int = 200) -> float:
    """Average run length (steps) of the one-sided CUSUM of i.i.d. N(mean, sd²) increments to
    its first ``S_k > threshold``, from S_0 = 0, by Brook & Evans' Markov chain: the state is
    the atom at zero or one of ``cells`` cells of width w = h / cells on (0, h], each at its
    centre; ARL = first entry of (I − R)⁻¹ 1, R the transition probabilities among those
    in-control states (leaving (0, h] upwards is the alarm)."""
    if threshold <= 0 or sd <= 0 or cells < 1:
        raise ValueError("need threshold > 0, sd > 0 and at least one cell")
    w = threshold / cells
    values = np.concatenate([[0.0], (np.arange(1, cells + 1) - 0.5) * w])   # atom, centres
    edges = np.arange(cells + 1) * w                                        # 0, w, ..., h
    cdf = scipy_stats.norm(loc=mean, scale=sd).cdf
    below = cdf(edges[None, :] - values[:, None])                 # P(c + X <= edge)
    R = np.concatenate([below[:, :1], np.diff(below, axis=1)], axis=1)   # atom, then cells
    arl = np.linalg.solve(np.eye(cells + 1) - R, np.ones(cells + 1))
    return float(arl[0])


def block_maxima(statistic: Sequence[float], first_row: int, block_rows: int) -> np.ndarray:
    """The largest value in each complete block of ``block_rows`` samples from ``first_row`` on
    (a trailing partial block is dropped, so the running time is blocks × block length)."""
    if block_rows < 1 or first_row < 0:
        raise ValueError("need block_rows >= 1 and first_row >= 0")
    x = np.asarray(statistic, float)[first_row:]
    blocks = x.size // block_rows
    return x[:blocks * block_rows].reshape(blocks, block_rows).max(axis=1)


def poisson_excess_power(mean: float | np.ndarray, ratio: float, alpha: float = 0.05
                         ) -> float | np.ndarray:
    """Power of the one-sided level-``alpha`` test of a Poisson count of expected ``mean``
    (alarms the model predicts) against ``ratio`` × ``mean``: it rejects at a count ≥ c, c the
    smallest with P(X ≥ c | mean) ≤ ``alpha``; the power is P(X ≥ c | ratio · mean)."""
    mean = np.asarray(mean, float)
    critical = scipy_stats.poisson.isf(alpha, mean) + 1.0        # P(X > isf) <= alpha
    power = scipy_stats.poisson.sf(critical - 1.0, ratio * mean)
    return float(power) if power.ndim == 0 else power


def poisson_p_two_sided(count, mean):
    """Two-sided p-value of a Poisson count (or an array of counts) of expected ``mean``:
    ``min(1, 2 min(P(X ≤ k), P(X ≥ k)))``."""
    count = np.asarray(count)
    p = np.minimum(1.0, 2.0 * np.minimum(scipy_stats.poisson.cdf(count, mean),
                                         scipy_stats.poisson.sf(count - 1, mean)))
    return float(p) if p.ndim == 0 else p


def poisson_count_interval(count: int, alpha: float = 0.05) -> tuple[float, float]:
    """The exact (Garwood) two-sided ``1 − alpha`` interval of a Poisson mean from ``count``
    events: ``χ²_{α/2}(2k) / 2`` (0 for k = 0) to ``χ²_{1−α/2}(2k + 2) / 2``."""
    low = float(scipy_stats.chi2.ppf(alpha / 2, 2 * count)) / 2.0 if count else 0.0
    return low, float(scipy_stats.chi2.ppf(1 - alpha / 2, 2 * (count + 1))) / 2.0


def poisson_two_sided_power(mean: float, ratio: float, level: float = 0.05) -> float:
    """Power of the two-sided test that calls a Poisson count of expected ``mean`` inconsistent
    when its p-value ``2 min(P(X ≤ k), P(X ≥ k))`` (capped at 1) is below ``level``, against
    ``ratio`` × ``mean``: the probability, under the larger mean, of a count it rejects
    (summed over the counts up to far in the larger mean's tail)."""
    if mean <= 0 or ratio <= 0:
        raise ValueError("need mean > 0 and ratio > 0")
    counts = np.arange(0, int(ratio * mean + 20 * math.sqrt(ratio * mean) + 50))
    rejected = poisson_p_two_sided(counts, mean) < level
    return float(scipy_stats.poisson.pmf(counts, ratio * mean)[rejected].sum())


def running_for_power(check_mtbfa_h: float, record_s: float, ratio: float = 2.0,
                      alpha: float = 0.05, power: float = 0.8, most: int = 100_000) -> int:
    """The fewest records of ``record_s`` seconds of fault-free running whose alarm count at a
    threshold set for ``check_mtbfa_h`` hours finds ``ratio`` times the predicted alarms with
    :func:`poisson_excess_power` ≥ ``power`` (the first such size: the power of a discrete
    test is a sawtooth in the size, and the one reached is what the caller reports)."""
    if check_mtbfa_h <= 0 or record_s <= 0 or ratio <= 1:
        raise ValueError("need check_mtbfa_h > 0, record_s > 0 and ratio > 1")
    records = np.arange(1, most + 1)
    reached = poisson_excess_power(records * record_s / SECONDS_PER_HOUR / check_mtbfa_h,
                                   ratio, alpha) >= power
    if not reached.any():
        raise ValueError(f"no size up to {most} records reaches power {power:g}")
    return int(records[np.argmax(reached)])


@dataclass(frozen=True)
class ExponentialTail:
    """P(a block's maximum > h) = ``exceed`` · exp(−(h − ``level``) / ``scale``) for h ≥ level:
    the tail of the block maxima of a fault-free statistic (one alarm per exceeding block, so a
    detector restarted after an alarm is not counted twice in one block).

    Attributes
    ----------
    level : float
        The (k+1)-th largest block maximum: the tail starts there.
    scale : float
        Mean excess over ``level`` of the k largest (the exponential's maximum-likelihood scale).
    exceed : float
        k / blocks.
    blocks : int
    block_s : float
        Length of a block, s.
    """

    level: float
    scale: float
    exceed: float
    blocks: int
    block_s: float

    def mtbfa_h(self, threshold: float) -> float:
        """Mean time between false alarms at ``threshold`` (≥ ``level``), hours (inf beyond
        e^700: a tail so steep that the threshold is never reached)."""
        if threshold < self.level:
            raise ValueError(f"threshold {threshold:g} lies below the tail ({self.level:g})")
        log_h = (math.log(self.block_s / self.exceed / SECONDS_PER_HOUR)
                 + (threshold - self.level) / self.scale)
        return math.exp(log_h) if log_h < 700.0 else math.inf

    def threshold(self, mtbfa_h: float) -> float:
        """The threshold whose mean time between false alarms is ``mtbfa_h`` hours (at least
        the one at ``level``, :meth:`mtbfa_h` of ``level``)."""
        if mtbfa_h < self.mtbfa_h(self.level):
            raise ValueError(f"{mtbfa_h:g} h lies below the tail's range "
                             f"({self.mtbfa_h(self.level):g} h)")
        return self.level + self.scale * math.log(self.exceed * mtbfa_h * SECONDS_PER_HOUR
                                                  / self.block_s)


def fit_exponential_tail(maxima: Sequence[float], block_s: float, tail_fraction: float = 0.2
                         ) -> ExponentialTail:
    """:class:`ExponentialTail` of block maxima: the k = max(2, ⌈tail_fraction · n⌉) largest
    are the tail, above the (k+1)-th largest; their mean excess is the scale."""
    m = np.sort(np.asarray(maxima, float))[::-1]
    m = m[np.isfinite(m)]
    k = max(2, math.ceil(tail_fraction * m.size))
    if m.size < k + 1:
        raise ValueError(f"an exponential tail needs at least {k + 1} finite block maxima, "
                         f"got {m.size}")
    level = float(m[k])
    scale = float(np.mean(m[:k] - level))
    if not scale > 0:
        raise ValueError("the block maxima's tail has no spread (all equal)")
    return ExponentialTail(level, scale, k / m.size, int(m.size), float(block_s))


def shiryaev_roberts_mtbfa_lower_h(log_threshold: float, dt_s: float) -> float:
    """Lower bound on the mean time between false alarms of a Shiryaev–Roberts detector that
    alarms when log R_k ≥ ``log_threshold``: E∞[T] ≥ A = e^log_threshold samples (Pollak 1987;
    R_k − k is a zero-mean martingale under no change when every likelihood ratio is exact),
    in hours at ``dt_s`` per sample.  A window only lowers R_k, so it holds for the windowed
    statistic too."""
    return math.exp(log_threshold) * dt_s / SECONDS_PER_HOUR


@dataclass(frozen=True)
class SurvivalCurve:
    """Kaplan–Meier estimate: at each distinct event time, the survival S(t) just after it and
    Greenwood's variance sum Σ d / (n (n − d))."""

    times: np.ndarray
    survival: np.ndarray
    greenwood: np.ndarray


def kaplan_meier(times: Sequence[float], observed: Sequence[bool]) -> SurvivalCurve:
    """The Kaplan–Meier survival curve of ``times`` (delays, s), ``observed`` False where the
    record ended first (censored).  A censored time equal to an event time counts as still at
    risk at that event (the usual convention)."""
    t = np.asarray(times, float)
    e = np.asarray(observed, bool)
    if t.shape != e.shape or t.ndim != 1 or t.size == 0:
        raise ValueError("need one observed flag per time, at least one time")
    if np.any(~np.isfinite(t)) or np.any(t < 0):
        raise ValueError("times must be finite and non-negative (a delay, not a code)")
    event_times = np.unique(t[e])
    survival, greenwood, s, g = [], [], 1.0, 0.0
    for u in event_times:
        at_risk = int(np.sum(t >= u))
        d = int(np.sum((t == u) & e))
        s *= 1.0 - d / at_risk
        g += d / (at_risk * (at_risk - d)) if at_risk > d else math.inf
        survival.append(s)
        greenwood.append(g)
    return SurvivalCurve(event_times, np.array(survival), np.array(greenwood))


@dataclass(frozen=True)
class MedianDelay:
    """The Kaplan–Meier median (s; None when the curve never falls to ½) and its interval
    (``high`` None when unbounded: too many records never detected)."""

    median: float | None
    low: float | None
    high: float | None
    n: int
    detected: int


def kaplan_meier_median(times: Sequence[float], observed: Sequence[bool],
                        level: float = 0.95) -> MedianDelay:
    """Median of the Kaplan–Meier curve (the first event time with S ≤ ½) and the
    Brookmeyer–Crowley interval: the event times whose log–log transformed pointwise interval
    of S(t) contains ½ (Greenwood's variance), reported as the first and the last of them (the
    set holds on to the next event time; some software reports that one as the upper end)."""
    curve = kaplan_meier(times, observed)
    z = float(scipy_stats.norm.ppf(0.5 + level / 2))
    at = curve.survival <= 0.5
    median = float(curve.times[np.argmax(at)]) if at.any() else None
    inside, falls_below = [], False
    for t, s, g in zip(curve.times, curve.survival, curve.greenwood):
        if 0.0 < s < 1.0 and math.isfinite(g):
            half = z * math.sqrt(g) / abs(math.log(s))       # log-log: Var = g / (log S)^2
            low_s, high_s = s ** math.exp(half), s ** math.exp(-half)
        else:                                                # S = 0 after the last at risk
            low_s = high_s = s
        if low_s <= 0.5 <= high_s:
            inside.append(float(t))
        falls_below |= high_s < 0.5
    n, detected = int(np.size(times)), int(np.sum(observed))
    return MedianDelay(median, inside[0] if inside else None,
                       inside[-1] if inside and falls_below else None, n, detected)


def detected_within(times: Sequence[float], observed: Sequence[bool], horizon_s: float) -> float:
    """Probability of detection within ``horizon_s``: 1 − S(horizon_s) of the Kaplan–Meier
    curve (the records censored before it count while they were watched)."""
    curve = kaplan_meier(times, observed)
    before = curve.times <= horizon_s
    return float(1.0 - (curve.survival[before][-1] if before.any() else 1.0))


__all__ = ["ExponentialTail", "FalseAlarmTime", "MedianDelay", "SECONDS_PER_HOUR", "SurvivalCurve",
           "block_maxima", "cusum_alarms", "cusum_average_run_length", "detected_within",
           "fit_exponential_tail", "kaplan_meier", "kaplan_meier_median",
           "mean_time_between_false_alarms_h", "poisson_count_interval", "poisson_excess_power",
           "poisson_p_two_sided", "poisson_two_sided_power", "restarted_cusum_alarms",
           "running_for_power", "shiryaev_roberts_mtbfa_lower_h"]
