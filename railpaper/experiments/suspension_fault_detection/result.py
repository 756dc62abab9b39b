"""Typed results of the fault-detection appendix: the faults, every record's alarm statistics,
and the illustrated record.

:func:`railpaper.experiments.suspension_fault_detection.experiment.run` returns a
:class:`FaultDetectionResult`: the pipeline's :class:`ChapterResult` (metrics, timings, time
series) plus the records (:class:`RecordRun`, one per simulated record and speed), each
detector's threshold, the faults' critical speeds and the illustrated record
(:class:`IllustratedRecord`).  Times are seconds from the record's start; a statistic's row k − 1
is its value after measurement k (time k·dt_s).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import pandas as pd

from railpaper.experiments.base import ChapterResult
from railpaper.monitoring import ExponentialTail

#: The fault name of a fault-free record.
NO_FAULT = "none"


def speed_key(speed_kmh: float) -> str:
    """``300kmh`` for 300.0: the speed as it appears in metric names."""
    return f"{speed_kmh:g}kmh"


@dataclass(frozen=True)
class CensoredMedian:
    """The median of values that may be infinite (a record never alarmed, or never reaching
    flange contact) and its distribution-free 95 % interval [x_(l), x_(u)]
    (:func:`railpaper.stats.quantile_ranks`; order statistics stay valid under censoring).
    An end beyond the record is ``None``, never a number standing for it.

    Attributes
    ----------
    median, low, high : float or None
        s; ``None`` where the order statistic is infinite ("beyond the record").
    n : int
        Values (records).
    """

    median: float | None
    low: float | None
    high: float | None
    n: int

    def metrics(self, prefix: str, tag: str) -> dict:
        """``<prefix>_s_<tag>`` with ``_low``/``_high`` where they lie within the record, and
        the separate fields ``<prefix>_reached_<tag>`` (the median lies within it) and
        ``<prefix>_high_bounded_<tag>`` (so does the interval's upper end)."""
        m = {f"{prefix}_reached_{tag}": self.median is not None,
             f"{prefix}_high_bounded_{tag}": self.high is not None}
        for tail, value in (("", self.median), ("_low", self.low), ("_high", self.high)):
            if value is not None:
                m[f"{prefix}_s_{tag}{tail}"] = value
        return m


def read_censored_median(metrics: dict, prefix: str, tag: str) -> CensoredMedian | None:
    """What :meth:`CensoredMedian.metrics` wrote, read back (``None``: not computed, e.g. a
    detector not run at that speed)."""
    if f"{prefix}_reached_{tag}" not in metrics:
        return None
    values = [metrics.get(f"{prefix}_s_{tag}{tail}") for tail in ("", "_low", "_high")]
    return CensoredMedian(*values, n=int(metrics.get(f"{prefix}_s_{tag}_n", 0)))


@dataclass(frozen=True)
class Fault:
    """One fault of ``data/suspension-fault-detection/faults.toml`` (or the user's own).

    Attributes
    ----------
    name : str
        Its key (``csaly_half``, …).
    parameter : str
        The model parameter it changes (:data:`railpaper.models.lateral_16state.PARAM_NAMES`).
    factor : float
        The parameter's value after the fault, as a fraction of nominal (1).
    kind : str
        ``"abrupt"`` (from the fault time on) or ``"drift"`` (linear from 1 to ``factor`` over
        the catalogue's ``drift_s``).
    label : str
        Words for figures and tables.
    """

    name: str
    parameter: str
    factor: float
    kind: str
    label: str


@dataclass(frozen=True)
class RecordRun:
    """Every detector on one record.

    Attributes
    ----------
    fault : str
        The fault's name, or :data:`NO_FAULT`.
    role : str
        ``"fault"``; for a fault-free record ``"calibration"`` (its statistics set the
        thresholds) or ``"evaluation"`` (its alarms are the false alarms counted).
    speed_kmh : float
        Vehicle speed, km/h.
    seed : int
        Seed of the track profile and the sensor noise.
    fault_time_s : float
        When the fault starts (−1 for a fault-free record), s.
    end_s : float
        When the record ends, s: its duration, or the first sample at which a wheelset reaches
        flange contact.
    flange_contact : bool
        The record ended at flange contact.
    statistics : dict of str to ndarray (K,)
        Each detector's alarm statistic after every sample (dimensionless: the CUSUM's
        log-likelihood ratio, the windowed sum of squared whitened innovations, the GLR's
        largest log-likelihood ratio, the log of the mixture Shiryaev–Roberts statistic, the
        oracle's posterior probability that the fault has happened; −inf where a statistic is
        not yet defined).
    post_fault_estimate : dict of str to float
        Each estimating detector's value of the faulted parameter at the record's end, as a
        fraction of nominal (``oracle``: the posterior mean over its hypotheses; ``glr``: the
        factor of the GLR's best hypothesis if it names this parameter, else 1).
    true_factor_end : float
        The faulted parameter's true value at the record's end, fraction of nominal (1 when
        fault-free).
    bank_hypothesis : ndarray of int, (K,), optional
        After every sample, the hypothesis of the GLR's maximum (an index into
        :func:`~railpaper.experiments.suspension_fault_detection.detectors.bank_hypotheses`;
        −1 before the first change step): which parameter the detectors that do not know the
        fault blame.
    """

    fault: str
    role: str
    speed_kmh: float
    seed: int
    fault_time_s: float
    end_s: float
    flange_contact: bool
    statistics: dict[str, np.ndarray]
    post_fault_estimate: dict[str, float]
    true_factor_end: float
    bank_hypothesis: np.ndarray | None = None


@dataclass(frozen=True)
class IllustratedRecord:
    """The record drawn in the chapter's first figure (fault ``fault``, seed ``seed``, first
    speed), with the oracle's posterior after it.

    Attributes
    ----------
    run : RecordRun
    dt_s : float
        Sample time, s.
    fault_times_s : ndarray, (J,)
        The oracle's grid of fault times, s.
    fault_time_posterior : ndarray, (J,)
        P(fault time | all the record, a fault happened).
    value_posterior : dict of str to float
        P(which fault | all the record, a fault happened), by fault name.
    """

    run: RecordRun
    dt_s: float
    fault_times_s: np.ndarray
    fault_time_posterior: np.ndarray
    value_posterior: dict[str, float]


def tail_of(metrics: dict, tag: str, block_s: float) -> ExponentialTail | None:
    """The run's false-alarm tail of ``tag`` (``<detector>_<speed>``) from its metrics
    (``tail_level_``, ``tail_scale_``, ``tail_exceed_``, ``tail_blocks_``); None without one."""
    if f"tail_level_{tag}" not in metrics:
        return None
    return ExponentialTail(level=metrics[f"tail_level_{tag}"], scale=metrics[f"tail_scale_{tag}"],
                           exceed=metrics[f"tail_exceed_{tag}"],
                           blocks=int(metrics[f"tail_blocks_{tag}"]), block_s=block_s)


@dataclass(frozen=True)
class LongRunningCheck:
    """The tail model of each detector's false alarms against long fault-free running (the
    stored evidence's ``fault_free_running``), per speed and detector.

    Attributes
    ----------
    records : int
        Fault-free records per speed.
    running_h : dict of float to float
        Speed (km/h) → running watched, h (whole blocks of the monitoring windows).
    flange_contacts : dict of float to int
        Speed → fault-free records cut at flange contact.
    block_s : float
        Length of a block, s (one alarm per exceeding block).
    maxima : dict of (str, float) to ndarray
        (detector, speed) → every block's maximum of its statistic, largest first.
    checks : pandas.DataFrame
        One row per (speed_kmh, detector, mtbfa_h): the run's tail threshold for ``mtbfa_h``
        hours, the alarms the tail predicts in the running (``expected_alarms``), the blocks
        that exceed it (``alarms``), the mean time between false alarms measured
        (``mtbfa_direct_h``, inf without an alarm) with its exact 95 % Poisson interval
        (``mtbfa_low_h``, ``mtbfa_high_h``), the two-sided Poisson p-value of the count and
        the check's ``outcome``: ``consistent`` (p ≥ 0.05), ``more alarms`` or ``fewer
        alarms`` than the tail predicts.
    refits : pandas.DataFrame
        One row per (speed_kmh, detector, mtbfa_h) of the run's operating points: the run's
        threshold, the threshold the same tail model fitted to the long running gives
        (``threshold_running``), and the mean time between false alarms that tail gives the
        run's threshold (``mtbfa_h_of_run_threshold``).
    delays : pandas.DataFrame
        One row per (speed_kmh, detector, fault) of the run's records: the Kaplan–Meier median
        delay (s, NaN where fewer than half are detected) and the probability of detection
        within 2 s at the threshold for ``spec.OPERATING_POINT_H`` hours (100) of the run's
        tail (``…_run``) and of the tail refitted to the running (``…_running``).
    """

    records: int
    running_h: dict[float, float]
    flange_contacts: dict[float, int]
    block_s: float
    maxima: dict[tuple[str, float], np.ndarray]
    checks: pd.DataFrame
    refits: pd.DataFrame
    delays: pd.DataFrame = field(default_factory=pd.DataFrame)


@dataclass
class FaultDetectionResult(ChapterResult):
    """A run of the appendix: :class:`ChapterResult` plus

    Attributes
    ----------
    faults : tuple of Fault
        The faults studied, in the run's order.
    records : tuple of RecordRun
        Every record at every speed.
    thresholds : dict of (str, float) to float
        (detector, speed km/h) → its alarm threshold, set on the calibration records.
    dt_s : float
        Sample time, s.
    monitor_from_s : float
        Alarms count from this time (the first possible fault time), s.
    critical_speeds : pandas.DataFrame
        Per fault (and ``none``): the model's critical (hunting) speed, km/h (NaN: stable up to
        the top of the range searched), after the fault has fully developed.
    roc : pandas.DataFrame
        One row per (detector, speed, fault, threshold): false alarms per hour and the rate of
        detection within 1 s.
    illustrated : IllustratedRecord
    delay_curve : pandas.DataFrame
        One row per (detector, speed, fault, mean time between false alarms on a grid, h):
        the threshold of the detector's fault-free tail model there, the Kaplan–Meier median
        delay (s; NaN where fewer than half the records are detected) and the probability of
        detection within 2 s.
    ladder : pandas.DataFrame
        The realism ladder: one row per (rung, detector, fault) at the ladder's speed and
        operating point: Kaplan–Meier median delay (s), detection within 0.5 s and 2 s, and
        within 2 s at the ideal rung's thresholds.
    bank_hypotheses : tuple of (str, float)
        The hypotheses of ``glr`` and ``bayes`` in their order: (parameter name, factor).
    """

    faults: tuple[Fault, ...] = ()
    records: tuple[RecordRun, ...] = ()
    thresholds: dict[tuple[str, float], float] = field(default_factory=dict)
    dt_s: float = 0.0
    monitor_from_s: float = 0.0
    critical_speeds: pd.DataFrame | None = None
    roc: pd.DataFrame | None = None
    illustrated: IllustratedRecord | None = None
    delay_curve: pd.DataFrame | None = None
    ladder: pd.DataFrame | None = None
    bank_hypotheses: tuple[tuple[str, float], ...] = ()

    def select(self, *, fault: str | None = None, role: str | None = None,
               speed_kmh: float | None = None, detector: str | None = None
               ) -> list[RecordRun]:
        """The records of one fault / role / speed (None: any), with a statistic of
        ``detector`` when given."""
        return [r for r in self.records
                if (fault is None or r.fault == fault) and (role is None or r.role == role)
                and (speed_kmh is None or r.speed_kmh == speed_kmh)
                and (detector is None or detector in r.statistics)]


__all__ = ["NO_FAULT", "CensoredMedian", "Fault", "FaultDetectionResult", "IllustratedRecord",
           "LongRunningCheck", "RecordRun", "read_censored_median", "speed_key", "tail_of"]
