"""From every record's statistics to the appendix's evidence: thresholds at one false-alarm
probability and at mean times between false alarms, alarms, delays, detection rates, false
alarms per hour, post-fault estimates, which parameter is blamed and ROC curves — each with its
95 % interval over records.

Definitions (times in s from the record's start):

* *monitoring window*: from ``monitor_from_s`` (the prior's first fault time) to the record's
  end; an alarm is the first sample in it whose statistic reaches the threshold;
* *threshold*: each detector's, per speed, is set on the calibration records (fault-free) so
  that at most a fraction ``false_alarm_probability`` of them alarm in their window;
* *false alarms per hour*: the evaluation records (other fault-free records) alarmed in their
  window, over the hours they were watched (each to its real end) — the rate of rare,
  independent alarms, with the exact Poisson interval of the count;
* *delay*: alarm time − fault time for a record without an alarm before its fault; a record
  that is never alarmed (or cut at flange contact first) has an infinite delay, so the median
  is beyond the record where fewer than half the records are alarmed (then no number is
  written: ``delay_median_reached_<tag>`` is False);
* *detected within d*: the alarm falls in (τ, τ + d]; a record alarmed before its fault, never,
  or cut at flange contact before τ + d without an alarm is not;
* *threshold for T hours between false alarms*: the calibration records' monitoring windows
  are cut into blocks of ``false_alarm_block_s``; an exponential tail is fitted to the largest
  fifth of the block maxima (:func:`railpaper.monitoring.fit_exponential_tail`, one alarm per
  exceeding block) and solved for T; the tail is checked on the evaluation records at the
  shortest mean time they resolve (:func:`tail_check`) — far short of T, so the thresholds at
  T are the tail model's extrapolation, not a measurement;
* *the tail checked on long running* (:func:`long_running_check`, the stored evidence's
  fault-free running, about an hour per speed): at the thresholds the run's tail sets for
  :data:`RUNNING_CHECK_H` hours, the exceeding blocks counted against the count the tail
  predicts.  The rule, fixed before the running was computed: a check is *consistent* when
  the two-sided Poisson p-value of the count is at least 0.05, else *more alarms* or *fewer
  alarms* than predicted; the check at 0.1 h is the one the running was sized for (power 0.8
  against twice the predicted alarms), the others are read beside it and are not independent
  of it (their counts are nested).
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from railpaper.engine import first_alarm
from railpaper.experiments.suspension_fault_detection.result import (
    NO_FAULT,
    CensoredMedian,
    LongRunningCheck,
    RecordRun,
    speed_key,
    tail_of,
)
from railpaper.experiments.suspension_fault_detection.spec import (
    DETECTORS,
    MTBFA_CURVE_H,
    MTBFA_TARGETS_H,
    OPERATING_POINT_H,
    PAIRS,
    RUNNING_CHECK_H,
    RUNNING_CHECK_LEVEL,
    WITHIN_S,
    Settings,
)
from railpaper.monitoring import (
    SECONDS_PER_HOUR,
    ExponentialTail,
    block_maxima,
    detected_within,
    fit_exponential_tail,
    kaplan_meier_median,
    mean_time_between_false_alarms_h,
    poisson_count_interval,
    poisson_p_two_sided,
    restarted_cusum_alarms,
    shiryaev_roberts_mtbfa_lower_h,
)
from railpaper.stats import median_interval, quantile_ranks, rate

#: Points of each ROC curve (thresholds), at most.
ROC_POINTS = 60


def window_rows(dt_s: float, monitor_from_s: float) -> int:
    """First row (0-based) of the monitoring window: the sample at ``monitor_from_s``."""
    return max(int(round(monitor_from_s / dt_s)) - 1, 0)


def rows_per_block(settings: Settings, dt_s: float) -> int:
    """Samples in one ``false_alarm_block_s`` block of the false-alarm tail (at least one)."""
    return max(1, int(round(settings.false_alarm_block_s / dt_s)))


def window_max(statistic: np.ndarray, first_row: int) -> float:
    """Largest statistic in the monitoring window (−inf when the record ends before it)."""
    tail = statistic[first_row:]
    return float(tail.max()) if tail.size else -np.inf


def threshold(maxima: np.ndarray, false_alarm_probability: float) -> float:
    """Smallest threshold at which at most ``false_alarm_probability`` of the calibration
    records' window maxima reach it: just above the (⌊α n⌋ + 1)-th largest."""
    ordered = np.sort(np.asarray(maxima, float))[::-1]
    allowed = int(np.floor(false_alarm_probability * ordered.size))
    if allowed >= ordered.size:
        return -np.inf
    return float(np.nextafter(ordered[allowed], np.inf))


def alarm_time_s(statistic: np.ndarray, h: float, first_row: int, dt_s: float) -> float:
    """Time of the first sample in the window at or above ``h`` (inf: none)."""
    row = first_alarm(statistic[first_row:], h)
    return float((first_row + row + 1) * dt_s) if row >= 0 else np.inf


def censored_median(values) -> CensoredMedian:
    """The :class:`CensoredMedian` of ``values`` (inf: beyond the record)."""
    x = np.sort(np.asarray(values, float))
    n = x.size
    low, high = quantile_ranks(n, 0.5)
    med = x[(n - 1) // 2] if n % 2 else 0.5 * (x[n // 2 - 1] + x[n // 2])
    kept = [float(v) if np.isfinite(v) else None for v in (med, x[low - 1], x[high - 1])]
    return CensoredMedian(*kept, n=n)


def detector_outcomes(runs: list[RecordRun], detector: str, h: float, first_row: int,
                      dt_s: float) -> pd.DataFrame:
    """Per faulty record: alarm time, whether it came before the fault, the delay (inf: never
    after the fault), the window maxima before the fault and within 1 s after it."""
    rows = []
    for r in runs:
        s = r.statistics[detector]
        t = alarm_time_s(s, h, first_row, dt_s)
        fault_row = int(round(r.fault_time_s / dt_s))             # first post-fault row
        early = t <= r.fault_time_s
        one_s = fault_row + int(round(1.0 / dt_s))
        rows.append({"seed": r.seed, "alarm_s": t, "early": early,
                     "delay_s": np.inf if early else t - r.fault_time_s,
                     "pre_max": window_max(s[:fault_row], first_row),
                     "post_max_1s": float(s[fault_row:one_s].max()) if s[fault_row:one_s].size
                     else -np.inf,
                     "end_s": r.end_s, "flange_contact": r.flange_contact,
                     "watched_s": max(0.0, r.end_s - r.fault_time_s)})
    return pd.DataFrame(rows)


def watched_h(runs: list[RecordRun], first_row: int, dt_s: float) -> float:
    """Fault-free running watched in the monitoring windows of ``runs``, hours: each record from
    the window's start to its real end (records cut at flange contact are shorter)."""
    return sum(max(0, int(round(r.end_s / dt_s)) - first_row) for r in runs) * dt_s / 3600.0


def false_alarm_metrics(runs: list[RecordRun], detector: str, h: float, first_row: int,
                        dt_s: float, tag: str) -> dict:
    """False alarms per hour on the evaluation records: the records alarmed in their window
    (at most one each) over the hours watched (:func:`watched_h`), with the exact Poisson
    (Garwood) 95 % interval of the count; ``_n``: the records."""
    maxima = np.array([window_max(r.statistics[detector], first_row) for r in runs])
    alarms = int(np.sum(maxima >= h))
    hours = watched_h(runs, first_row, dt_s)
    low, high = poisson_count_interval(alarms)
    return {f"false_alarms_per_hour_{tag}": alarms / hours,
            f"false_alarms_per_hour_{tag}_low": low / hours,
            f"false_alarms_per_hour_{tag}_high": high / hours,
            f"false_alarms_per_hour_{tag}_n": len(runs)}


def cusum_false_alarms(paths, h: float, first_row: int, dt_s: float) -> tuple[int, float]:
    """False alarms of the residual CUSUM on fault-free records, the detector restarted after
    each alarm (:func:`railpaper.monitoring.restarted_cusum_alarms` on each stored path from the
    monitoring start, alarm when the statistic exceeds ``h``), and the running time they were
    watched, s (each record's real length: records end early at flange contact)."""
    alarms, running_s = 0, 0.0
    for path in paths:
        watched = np.asarray(path, float)[first_row:]
        alarms += len(restarted_cusum_alarms(watched, h))
        running_s += watched.size * dt_s
    return alarms, running_s


def mean_time_between_false_alarms_metrics(alarms: int, running_s: float, tag: str) -> dict:
    """``false_alarms_restarted_<tag>``, ``false_alarm_running_h_<tag>``,
    ``mtbfa_h_lower_<tag>`` (the one-sided 95 % Poisson lower bound, h) and, when there was an
    alarm, ``mtbfa_h_<tag>`` (running hours per alarm)."""
    est = mean_time_between_false_alarms_h(running_s, alarms)
    m = {f"false_alarms_restarted_{tag}": alarms, f"false_alarm_running_h_{tag}": est.running_h,
         f"mtbfa_h_lower_{tag}": est.lower_h}
    if alarms:
        m[f"mtbfa_h_{tag}"] = est.value_h
    return m


def fault_metrics(outcomes: pd.DataFrame, tag: str) -> dict:
    """Detection within each horizon, early alarms and the median delay of one detector on one
    fault's records."""
    m = {}
    delay = outcomes["delay_s"].to_numpy()
    for d in WITHIN_S:
        m.update(rate(delay <= d + 1e-9).metrics(f"detected_within_{d:g}s_{tag}"))
    early = rate(outcomes["early"].to_numpy())
    m.update({f"alarm_before_fault_{tag}": early.value, f"alarm_before_fault_{tag}_low": early.low,
              f"alarm_before_fault_{tag}_high": early.high})
    m.update(censored_median(delay).metrics("delay_median", tag))
    m[f"delay_median_s_{tag}_n"] = len(delay)
    m.update(survival_delay_metrics(outcomes, tag))
    return m


def survival_delay_metrics(outcomes: pd.DataFrame, tag: str) -> dict:
    """The delays as survival data (:mod:`railpaper.monitoring`): a record watched after the
    fault until its end or flange contact and never alarmed is censored there; one that alarmed
    before the fault is censored at 0 (that alarm is a false alarm, not a detection).
    ``km_delay_median_s_<tag>`` with ``_low``/``_high`` (Brookmeyer–Crowley) and the separate
    fields ``km_delay_median_reached_<tag>`` / ``km_delay_high_bounded_<tag>`` (False: not
    detected on enough records for the median, or its upper end; the number is then absent,
    never coded), and ``km_detected_within_<d>s_<tag>``."""
    delay = outcomes["delay_s"].to_numpy(float)
    detected = np.isfinite(delay)
    times = np.where(detected, delay,
                     np.where(outcomes["early"].to_numpy(bool), 0.0,
                              outcomes["watched_s"].to_numpy(float)))
    if times.size == 0:
        return {}
    median = kaplan_meier_median(times, detected)
    m = {f"km_delay_median_reached_{tag}": median.median is not None,
         f"km_delay_high_bounded_{tag}": median.high is not None,
         f"km_delay_n_{tag}": median.n, f"km_delay_detected_{tag}": median.detected}
    for key, value in (("", median.median), ("_low", median.low), ("_high", median.high)):
        if value is not None:
            m[f"km_delay_median_s_{tag}{key}"] = value
    for d in WITHIN_S:
        m[f"km_detected_within_{d:g}s_{tag}"] = detected_within(times, detected, d + 1e-9)
    return m


def estimate_metrics(runs: list[RecordRun], detector: str, tag: str) -> dict:
    """Median |post-fault estimate − truth| (fraction of nominal) over the fault's records."""
    errors = np.array([abs(r.post_fault_estimate[detector] - r.true_factor_end) for r in runs
                       if detector in r.post_fault_estimate])
    if errors.size < 2:
        return {}
    return median_interval(errors).metrics(f"post_fault_error_{tag}")


def flange_metrics(runs: list[RecordRun], tag: str) -> dict:
    """How often a fault's records reach flange contact, and how soon after the fault."""
    m = rate([r.flange_contact for r in runs]).metrics(f"flange_contact_rate_{tag}")
    times = np.array([r.end_s - r.fault_time_s if r.flange_contact else np.inf for r in runs])
    m.update(censored_median(times).metrics("flange_contact_after", tag))
    return m


def fault_free_flange_metrics(runs: list[RecordRun], tag: str) -> dict:
    """How often records with no fault reach flange contact within their length
    (``flange_contact_rate_fault_free_<speed>`` with its interval, and the count): the running
    every fault's rate is read against, and records whose detectors watch less than the window
    because they end there."""
    m = rate([r.flange_contact for r in runs]).metrics(f"flange_contact_rate_fault_free_{tag}")
    m[f"flange_contacts_fault_free_{tag}"] = int(sum(r.flange_contact for r in runs))
    return m


def roc_rows(calibration: list[RecordRun], evaluation: list[RecordRun],
             outcomes_of, detector: str, first_row: int, dt_s: float) -> list[dict]:
    """ROC points of one detector and speed: per fault, false alarms per hour on all the
    fault-free records (records alarmed over the hours watched) against detection within 1 s,
    over thresholds spanning the maxima."""
    free = np.array([window_max(r.statistics[detector], first_row)
                     for r in calibration + evaluation])
    hours = watched_h(calibration + evaluation, first_row, dt_s)
    rows = []
    for fault, outcomes in outcomes_of.items():
        pre, post = outcomes["pre_max"].to_numpy(), outcomes["post_max_1s"].to_numpy()
        levels = np.concatenate([free, post])
        levels = np.unique(levels[np.isfinite(levels)])
        if levels.size > ROC_POINTS:
            levels = np.quantile(levels, np.linspace(0, 1, ROC_POINTS))
        for h in np.concatenate([levels, [np.inf]]):
            rows.append({"detector": detector, "fault": fault, "threshold": h,
                         "false_alarms_per_hour": float(np.sum(free >= h)) / hours,
                         "detected_within_1s": float(np.mean((pre < h) & (post >= h)))})
    return rows


def isolation_metrics(runs: list[RecordRun], outcomes: pd.DataFrame, dt_s: float,
                      hypothesis_parameter: np.ndarray, parameter: int, tag: str) -> dict:
    """Of one fault's records that a detector alarmed after the fault, how many the GLR's best
    hypothesis at the alarm blames on the faulted parameter (``isolated_<tag>`` with its
    Clopper–Pearson interval and count): the diagnosis that comes with an alarm of the
    detectors that do not know the fault."""
    right = []
    for run, (_, row) in zip(runs, outcomes.iterrows()):
        if not np.isfinite(row["delay_s"]) or run.bank_hypothesis is None:
            continue
        best = int(run.bank_hypothesis[int(round(row["alarm_s"] / dt_s)) - 1])
        right.append(best >= 0 and int(hypothesis_parameter[best]) == parameter)
    return rate(right).metrics(f"isolated_{tag}") if right else {}


def false_alarm_tail(runs: list[RecordRun], detector: str, first_row: int, block_rows: int,
                     dt_s: float) -> ExponentialTail | None:
    """The exponential tail of one detector's block maxima over fault-free records
    (:func:`railpaper.monitoring.fit_exponential_tail`, blocks of ``block_rows`` samples from
    the monitoring window's start, each record's real length); None when there are too few
    blocks."""
    maxima = np.concatenate([block_maxima(r.statistics[detector], first_row, block_rows)
                             for r in runs] or [np.zeros(0)])
    try:
        return fit_exponential_tail(maxima, block_rows * dt_s)
    except ValueError:
        return None


#: The detectors whose alarms come with a diagnosis (the GLR's best hypothesis).
BLAMING = ("glr", "bayes")


def blame_metrics(runs: list[RecordRun], outcomes: pd.DataFrame, detector: str, dt_s: float,
                  hypothesis_parameter: np.ndarray | None, fault_parameter: dict | None,
                  fault: str, tag: str) -> dict:
    """:func:`isolation_metrics` of one fault's records for a detector of :data:`BLAMING`,
    given the hypotheses' and the faults' parameters; nothing otherwise."""
    if detector not in BLAMING or hypothesis_parameter is None or fault_parameter is None:
        return {}
    return isolation_metrics(runs, outcomes, dt_s, hypothesis_parameter,
                             fault_parameter[fault], tag)


#: Bootstrap resamples (over calibration records) of each detector's false-alarm tail.
TAIL_RESAMPLES = 200


def tail_intervals(runs: list[RecordRun], detector: str, first_row: int, block_rows: int,
                   dt_s: float, tail: ExponentialTail, rng: np.random.Generator,
                   tag: str) -> dict:
    """How far the tail model's operating points can be trusted, by resampling the calibration
    records with replacement (:data:`TAIL_RESAMPLES` times; the blocks of one record share its
    track, so records, not blocks, are the independent units): for each mean time T of
    :data:`MTBFA_TARGETS_H`, the 2.5 and 97.5 % points of the resampled tails' thresholds for T
    (``threshold_at_<T>h_<tag>_low``/``_high``) and of the mean time they give at the point
    threshold (``mtbfa_h_at_<T>h_<tag>_low``/``_high``, h; ``…_high_bounded`` False, and no
    ``_high``, where a resampled tail never reaches the threshold))."""
    per_record = [block_maxima(r.statistics[detector], first_row, block_rows) for r in runs]
    points = {t: tail.threshold(t) for t in MTBFA_TARGETS_H}
    thresholds = {t: [] for t in MTBFA_TARGETS_H}
    mtbfa = {t: [] for t in MTBFA_TARGETS_H}
    for _ in range(TAIL_RESAMPLES):
        pick = rng.integers(len(per_record), size=len(per_record))
        try:
            again = fit_exponential_tail(np.concatenate([per_record[i] for i in pick]),
                                         block_rows * dt_s)
        except ValueError:                        # a resample without spread: no tail
            continue
        for t in MTBFA_TARGETS_H:
            thresholds[t].append(again.threshold(max(t, again.mtbfa_h(again.level))))
            mtbfa[t].append(again.mtbfa_h(points[t]) if points[t] >= again.level
                            else again.mtbfa_h(again.level))
    m = {}
    for t in MTBFA_TARGETS_H:
        if len(thresholds[t]) < TAIL_RESAMPLES // 2:
            continue
        low, high = np.quantile(thresholds[t], [0.025, 0.975])
        m[f"threshold_at_{t:g}h_{tag}_low"], m[f"threshold_at_{t:g}h_{tag}_high"] = low, high
        low, high = np.quantile(mtbfa[t], [0.025, 0.975], method="inverted_cdf")
        m[f"mtbfa_h_at_{t:g}h_{tag}_low"] = float(low)
        m[f"mtbfa_h_at_{t:g}h_{tag}_high_bounded"] = bool(np.isfinite(high))
        if np.isfinite(high):
            m[f"mtbfa_h_at_{t:g}h_{tag}_high"] = float(high)
    return m


def tail_check(tail: ExponentialTail, runs: list[RecordRun], detector: str, first_row: int,
               block_rows: int, tag: str, expected: float = 5.0) -> dict:
    """The tail model against a direct count on other fault-free records: at the threshold the
    tail predicts ``expected`` exceeding blocks in their running (or at its level, if that
    predicts fewer), the blocks that do exceed it.  ``tail_check_mtbfa_h_<tag>`` (the mean time
    between false alarms checked, h), ``tail_check_expected_<tag>``, ``tail_check_alarms_<tag>``
    and ``tail_check_p_<tag>`` (the two-sided Poisson p-value of the count)."""
    maxima = np.concatenate([block_maxima(r.statistics[detector], first_row, block_rows)
                             for r in runs] or [np.zeros(0)])
    if maxima.size == 0:
        return {}
    running_h = maxima.size * tail.block_s / SECONDS_PER_HOUR
    mtbfa_h = max(running_h / expected, tail.mtbfa_h(tail.level))
    h = tail.threshold(mtbfa_h)
    mean = running_h / mtbfa_h
    alarms = int(np.sum(maxima > h))
    p = poisson_p_two_sided(alarms, mean)
    return {f"tail_check_mtbfa_h_{tag}": mtbfa_h, f"tail_check_expected_{tag}": mean,
            f"tail_check_alarms_{tag}": alarms, f"tail_check_p_{tag}": p}


def operating_point_metrics(tail: ExponentialTail, runs_of: dict, detector: str,
                            first_row: int, dt_s: float, speed_tag: str,
                            hypothesis_parameter: np.ndarray | None = None,
                            fault_parameter: dict[str, int] | None = None) -> dict:
    """At each mean time between false alarms of :data:`MTBFA_TARGETS_H`: the tail's threshold
    (``threshold_at_<T>h_<detector>_<speed>``; for ``bayes`` also the Shiryaev–Roberts lower
    bound on the mean time at that threshold, ``sr_bound_mtbfa_h_at_<T>h_bayes_<speed>``) and,
    per fault, :func:`fault_metrics` at it (detection within each horizon with its interval,
    early alarms, the median delay, the delays as survival data:
    ``…_<detector>_<fault>_<speed>_at_<T>h``) and, for ``glr`` and ``bayes`` given the
    hypotheses' and faults' parameters, :func:`isolation_metrics` at it."""
    m = {}
    for target in MTBFA_TARGETS_H:
        h = tail.threshold(target)
        m[f"threshold_at_{target:g}h_{detector}_{speed_tag}"] = h
        if detector == "bayes":
            m[f"sr_bound_mtbfa_h_at_{target:g}h_bayes_{speed_tag}"] = \
                shiryaev_roberts_mtbfa_lower_h(h, dt_s)
        for fault, runs in runs_of.items():
            outcomes = detector_outcomes(runs, detector, h, first_row, dt_s)
            tag = f"{detector}_{fault}_{speed_tag}_at_{target:g}h"
            m.update(fault_metrics(outcomes, tag))
            m.update(blame_metrics(runs, outcomes, detector, dt_s, hypothesis_parameter,
                                   fault_parameter, fault, tag))
    return m


def delay_curve_rows(tail: ExponentialTail, runs_of: dict, detector: str, first_row: int,
                     dt_s: float, speed_kmh: float) -> list[dict]:
    """Rows of the delay against mean time between false alarms picture: on the grid
    :data:`MTBFA_CURVE_H` (from the tail's level on), per fault, the Kaplan–Meier median delay
    (NaN: not reached) and the probability of detection within 2 s."""
    rows = []
    for mtbfa_h in MTBFA_CURVE_H:
        if mtbfa_h < tail.mtbfa_h(tail.level):
            continue
        h = tail.threshold(mtbfa_h)
        for fault, runs in runs_of.items():
            m = survival_delay_metrics(detector_outcomes(runs, detector, h, first_row, dt_s), "x")
            rows.append({"detector": detector, "speed_kmh": speed_kmh, "fault": fault,
                         "mtbfa_h": mtbfa_h, "threshold": h,
                         "km_delay_median_s": m.get("km_delay_median_s_x", np.nan),
                         "km_detected_within_2s": m.get("km_detected_within_2s_x", np.nan)})
    return rows


def paired_metrics(delay_a: np.ndarray, delay_b: np.ndarray, tag: str) -> dict:
    """Two detectors on the same records (delays, inf where a record is not detected after
    its fault, an alarm before it included): ``paired_earlier_<tag>`` and
    ``paired_later_<tag>``, the share of records on which A's delay is shorter (longer) than
    B's, each with its Clopper–Pearson interval (the rest are ties: the same sample, or
    neither detecting); ``paired_sign_share_<tag>``, the share of A earlier among the records
    where they differ (the sign test's, with its interval; absent without such a record); and,
    conditional on both detecting, the median of B's delay − A's
    (``paired_difference_median_s_<tag>``, distribution-free interval;
    ``paired_both_detected_<tag>`` records)."""
    a, b = np.asarray(delay_a, float), np.asarray(delay_b, float)
    m = {}
    m.update(rate(a < b).metrics(f"paired_earlier_{tag}"))
    m.update(rate(a > b).metrics(f"paired_later_{tag}"))
    discordant = a != b
    if discordant.any():                                 # the sign test's share
        m.update(rate((a < b)[discordant]).metrics(f"paired_sign_share_{tag}"))
    both = np.isfinite(a) & np.isfinite(b)
    m[f"paired_both_detected_{tag}"] = int(both.sum())
    if both.any():
        m.update(median_interval(b[both] - a[both]).metrics(
            f"paired_difference_median_s_{tag}"))
    return m


def paired_comparisons(tails: dict, runs_of: dict, first_row: int, dt_s: float,
                       speed_tag: str) -> dict:
    """:func:`paired_metrics` of every pair of :data:`~.spec.PAIRS` with both tails, per fault, at
    each detector's threshold for :data:`OPERATING_POINT_H` hours
    (``…_<A>_vs_<B>_<fault>_<speed>_at_<T>h``)."""
    m = {}
    for a, b in PAIRS:
        if a not in tails or b not in tails:
            continue
        for fault, runs in runs_of.items():
            delays = [detector_outcomes(runs, d, tails[d].threshold(OPERATING_POINT_H),
                                        first_row, dt_s)["delay_s"].to_numpy(float)
                      for d in (a, b)]
            m.update(paired_metrics(*delays, f"{a}_vs_{b}_{fault}_{speed_tag}"
                                             f"_at_{OPERATING_POINT_H:g}h"))
    return m


def evidence(records: list[RecordRun], detectors: list[str], speeds: tuple[float, ...],
             faults: list[str], settings: Settings, dt_s: float, monitor_from_s: float,
             hypothesis_parameter: np.ndarray | None = None,
             fault_parameter: dict[str, int] | None = None
             ) -> tuple[dict, dict, pd.DataFrame, pd.DataFrame]:
    """Thresholds, metrics and ROC points of every detector, speed and fault (``settings``:
    the run's ``duration_s`` and ``false_alarm_probability``); with ``hypothesis_parameter``
    (the changed parameter of each of ``glr``/``bayes``' hypotheses) and ``fault_parameter``
    (each fault's), also which parameter those two blame at their alarms.  Besides the
    thresholds at the run's false-alarm probability, each detector's thresholds at the mean
    times between false alarms of :data:`MTBFA_TARGETS_H` (an exponential tail of its
    calibration records' block maxima, checked on the evaluation records) and its delays
    there; the fourth value returned is the delay against mean time between false alarms
    table (:func:`delay_curve_rows`)."""
    first_row = window_rows(dt_s, monitor_from_s)
    block_rows = rows_per_block(settings, dt_s)
    metrics, thresholds, roc, curve = {}, {}, [], []
    for speed in speeds:
        at = [r for r in records if r.speed_kmh == speed]
        for fault in faults:
            metrics.update(flange_metrics([r for r in at if r.fault == fault],
                                          f"{fault}_{speed_key(speed)}"))
        free = [r for r in at if r.fault == NO_FAULT]
        if free:
            metrics.update(fault_free_flange_metrics(free, speed_key(speed)))
        tails, faulty = {}, {}
        for detector in detectors:
            have = [r for r in at if detector in r.statistics]
            calibration = [r for r in have if r.role == "calibration"]
            evaluation = [r for r in have if r.role == "evaluation"]
            if not calibration or not evaluation:
                continue
            h = threshold([window_max(r.statistics[detector], first_row) for r in calibration],
                          settings.false_alarm_probability)
            thresholds[(detector, speed)] = h
            tag = f"{detector}_{speed_key(speed)}"
            metrics[f"threshold_{tag}"] = h
            metrics.update(false_alarm_metrics(evaluation, detector, h, first_row, dt_s, tag))
            if detector == "cusum":            # a CUSUM: restarts recoverable from its path
                metrics.update(mean_time_between_false_alarms_metrics(*cusum_false_alarms(
                    [r.statistics[detector] for r in evaluation], h, first_row, dt_s), tag))
            outcomes_of = {}
            for fault in faults:
                runs = [r for r in have if r.fault == fault]
                if not runs:
                    continue
                outcomes_of[fault] = detector_outcomes(runs, detector, h, first_row, dt_s)
                ftag = f"{detector}_{fault}_{speed_key(speed)}"
                metrics.update(fault_metrics(outcomes_of[fault], ftag))
                metrics.update(estimate_metrics(runs, detector, ftag))
                metrics.update(blame_metrics(runs, outcomes_of[fault], detector, dt_s,
                                             hypothesis_parameter, fault_parameter, fault,
                                             ftag))
            for row in roc_rows(calibration, evaluation, outcomes_of, detector, first_row,
                                dt_s):
                roc.append(dict(row, speed_kmh=speed))
            tail = false_alarm_tail(calibration, detector, first_row, block_rows, dt_s)
            if tail is None:
                continue
            tails[detector] = tail
            metrics.update({f"tail_level_{tag}": tail.level, f"tail_scale_{tag}": tail.scale,
                            f"tail_exceed_{tag}": tail.exceed, f"tail_blocks_{tag}": tail.blocks})
            metrics.update(tail_check(tail, evaluation, detector, first_row, block_rows, tag))
            rng = np.random.default_rng([settings.seed, 39, speeds.index(speed),
                                         detectors.index(detector)])
            metrics.update(tail_intervals(calibration, detector, first_row, block_rows, dt_s,
                                          tail, rng, tag))
            runs_of = {f: [r for r in have if r.fault == f] for f in faults}
            runs_of = {f: runs for f, runs in runs_of.items() if runs}
            faulty = runs_of
            metrics.update(operating_point_metrics(tail, runs_of, detector, first_row, dt_s,
                                                   speed_key(speed), hypothesis_parameter,
                                                   fault_parameter))
            curve += delay_curve_rows(tail, runs_of, detector, first_row, dt_s, speed)
        metrics.update(paired_comparisons(tails, faulty, first_row, dt_s, speed_key(speed)))
    return metrics, thresholds, pd.DataFrame(roc), pd.DataFrame(curve)


def poisson_check(alarms: int, expected: float, running_h: float) -> dict:
    """A count of ``alarms`` exceeding blocks where ``expected`` were predicted, in
    ``running_h`` hours: the mean time between false alarms measured with its exact 95 %
    Poisson interval (h; inf without an alarm / as the upper end), the two-sided p-value and
    the outcome of the rule in this module's docstring."""
    low_rate, high_rate = poisson_count_interval(alarms)
    p = poisson_p_two_sided(alarms, expected)
    outcome = ("consistent" if p >= RUNNING_CHECK_LEVEL else
               "more alarms" if alarms > expected else "fewer alarms")
    return {"alarms": int(alarms), "expected_alarms": expected,
            "mtbfa_direct_h": running_h / alarms if alarms else np.inf,
            "mtbfa_low_h": running_h / high_rate,
            "mtbfa_high_h": running_h / low_rate if alarms else np.inf,
            "p_value": p, "outcome": outcome}


def long_running_check(rows: pd.DataFrame, metrics: dict, settings: Settings,
                       runs: tuple[RecordRun, ...] = (), monitor_from_s: float = 0.0
                       ) -> LongRunningCheck:
    """Each detector's tail model of the run (``metrics``) against the stored fault-free
    running ``rows`` (:func:`~railpaper.experiments.suspension_fault_detection.experiment.
    running_rows`): the checks at :data:`RUNNING_CHECK_H` (those at or above the tail's
    level), the same tail model refitted to the running, and, given the run's records
    ``runs`` (watched from ``monitor_from_s``), each fault's delays at the thresholds for
    :data:`OPERATING_POINT_H` hours of both tails (:class:`LongRunningCheck`)."""
    block_s = settings.false_alarm_block_s
    first_row = window_rows(settings.dt_s, monitor_from_s)
    maxima, checks, refits, running_h, contacts, delays = {}, [], [], {}, {}, []
    for speed in settings.speeds_kmh:
        key = speed_key(speed)
        running_h[speed] = float(rows[f"running_s_{key}"].sum()) / SECONDS_PER_HOUR
        contacts[speed] = int(rows[f"flange_contact_{key}"].sum())
        for detector in DETECTORS:
            columns = [c for c in rows.columns if c.startswith(f"block_max_{detector}_{key}_")]
            values = rows[columns].to_numpy(float).ravel()
            values = np.sort(values[np.isfinite(values)])[::-1]
            maxima[(detector, speed)] = values
            tail = tail_of(metrics, f"{detector}_{key}", block_s)
            if tail is None or not values.size:
                continue
            for mtbfa_h in RUNNING_CHECK_H:
                if mtbfa_h < tail.mtbfa_h(tail.level):
                    continue
                h = tail.threshold(mtbfa_h)
                checks.append({"speed_kmh": speed, "detector": detector, "mtbfa_h": mtbfa_h,
                               "threshold": h,
                               **poisson_check(int(np.sum(values > h)),
                                               running_h[speed] / mtbfa_h, running_h[speed])})
            try:
                again = fit_exponential_tail(values, block_s)
            except ValueError:                 # too few blocks, or a tail without spread
                continue
            for mtbfa_h in MTBFA_TARGETS_H:
                h = tail.threshold(mtbfa_h)
                refits.append({"speed_kmh": speed, "detector": detector, "mtbfa_h": mtbfa_h,
                               "threshold": h, "threshold_running": again.threshold(mtbfa_h),
                               "mtbfa_h_of_run_threshold": (again.mtbfa_h(h) if h >= again.level
                                                            else np.nan)})
            faulty = {}
            for r in runs:
                if r.speed_kmh == speed and r.fault != NO_FAULT and detector in r.statistics:
                    faulty.setdefault(r.fault, []).append(r)
            for fault, of_fault in faulty.items():
                row = {"speed_kmh": speed, "detector": detector, "fault": fault}
                for name, h in (("run", tail.threshold(OPERATING_POINT_H)),
                                ("running", again.threshold(OPERATING_POINT_H))):
                    m = survival_delay_metrics(detector_outcomes(of_fault, detector, h,
                                                                 first_row, settings.dt_s), "x")
                    row[f"km_delay_median_s_{name}"] = m.get("km_delay_median_s_x", np.nan)
                    row[f"km_detected_within_2s_{name}"] = m.get("km_detected_within_2s_x",
                                                                 np.nan)
                delays.append(row)
    return LongRunningCheck(records=len(rows), running_h=running_h, flange_contacts=contacts,
                            block_s=block_s, maxima=maxima, checks=pd.DataFrame(checks),
                            refits=pd.DataFrame(refits), delays=pd.DataFrame(delays))


def statistic_peaks(statistic: np.ndarray, first_row: int, block_rows: int) -> str:
    """A statistic kept as the few samples every metric of a stored ladder rung reads:
    from ``first_row`` on, each sample that exceeds all before it in the window (so the first
    sample at or above any threshold is kept, hence every alarm time) and each complete
    block's largest sample (so every block maximum).  Text ``"row:value row:value …"`` with
    the values' shortest exact repr; :func:`statistic_from_peaks` reads it back.  Not kept:
    the rest of the path, so a metric that reads it (the maximum in the second after the fault
    of the ROC points, the restarted CUSUM's alarm count) is wrong on a statistic read back;
    the stored ladder keeps none of them."""
    x = np.asarray(statistic, float)
    if np.isnan(x).any():
        raise ValueError("a statistic with NaN cannot be kept as its peaks")
    window = x[first_row:]
    before = np.concatenate([[-np.inf], np.maximum.accumulate(window)[:-1]]) if window.size \
        else window
    rows = set((np.flatnonzero(window > before) + first_row).tolist())
    blocks = window.size // block_rows
    if blocks:
        peaks = window[:blocks * block_rows].reshape(blocks, block_rows).argmax(axis=1)
        rows.update((first_row + np.arange(blocks) * block_rows + peaks).tolist())
    return " ".join(f"{r}:{float(x[r])!r}" for r in sorted(rows))


def statistic_from_peaks(text: str, length: int) -> np.ndarray:
    """The statistic of :func:`statistic_peaks` with −inf wherever a sample was not kept:
    its window maximum, block maxima and first crossing of every threshold are the
    original's."""
    out = np.full(length, -np.inf)
    for item in text.split():
        row, value = item.split(":")
        out[int(row)] = float(value)
    return out


__all__ = ["BLAMING", "TAIL_RESAMPLES", "blame_metrics", "censored_median",
           "delay_curve_rows", "evidence", "false_alarm_tail", "isolation_metrics",
           "long_running_check", "operating_point_metrics", "paired_comparisons",
           "paired_metrics", "poisson_check", "rows_per_block", "statistic_from_peaks",
           "statistic_peaks", "tail_check", "tail_intervals", "threshold", "watched_h", "window_rows"]
