"""Appendix ``suspension-fault-detection``: how soon does a failed damper show in the data?

The whole computation as a function of the settings.  At every speed of ``speeds_kmh``:
``records_per_fault`` records of each fault (:mod:`.faults`), the fault at a time drawn from the
prior's grid (or ``fault_time_s``), and ``fault_free_records`` records without a fault (half set
the thresholds, half count false alarms); on each, the five detectors of :mod:`.detectors`
(cusum, chi2, glr, bayes and the oracle).  :mod:`.evidence` turns the statistics into
thresholds, delays, detection rates, false alarms per hour, post-fault estimates, which
parameter the detectors that do not know the fault blame, and ROC points.

One record by hand::

    settings = SPEC.resolve({}, quick=True)
    fixed, theta = lateral_vehicle.vehicle()
    catalogue, fault_settings = faults.catalogue()
    rec = records.simulate_faulted(settings, fault_settings, fixed, theta, catalogue["csaly_0"],
                                   1.5, 300.0, seed=0)
    system = lateral_vehicle.filter_system(records.record_settings(settings, 300.0), fixed,
                                           theta, rec.record, theta_ref=theta)
    g = detectors.residual_cusum(system, theta, rec.record, settings.cusum_variance_ratio)
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np
import pandas as pd

from railpaper.experiments.base import ParameterError, check_sample_time, default_progress
from railpaper.experiments.lateral_vehicle import filter_system, vehicle
from railpaper.experiments.records import RecordStudy
from railpaper.experiments.suspension_fault_detection import detectors, faults, records
from railpaper.experiments.suspension_fault_detection.evidence import (
    detector_outcomes,
    evidence,
    false_alarm_metrics,
    fault_metrics,
    flange_metrics,
    rows_per_block,
    statistic_from_peaks,
    statistic_peaks,
    window_rows,
)
from railpaper.experiments.suspension_fault_detection.result import (
    NO_FAULT,
    Fault,
    FaultDetectionResult,
    IllustratedRecord,
    RecordRun,
    speed_key,
)
from railpaper.experiments.suspension_fault_detection.spec import (
    DETECTORS,
    LADDER,
    LADDER_MTBFA_H,
    RUN_TRACK_UNKNOWN_RECORDS,
    RUNGS_WITHOUT_TRACK,
    STORED_DETECTORS,
    STORED_RUNGS,
    Settings,
)
from railpaper.experiments.track_shaping import shaping_filter
from railpaper.models import lateral_16state, lateral_unknown_track
from railpaper.monitoring import block_maxima, running_for_power
from railpaper.threads import one_thread
from railpaper.track import SPECTRA

#: Offsets of the fault-free records' seeds from ``seed`` (calibration, evaluation).
FREE_SEED_OFFSETS = {"calibration": 300, "evaluation": 600}


def chosen_faults(settings: Settings) -> list[Fault]:
    """The run's faults: the catalogue's named in ``faults``, then the user's own."""
    catalogue, _ = faults.catalogue()
    names = [n.strip() for n in settings.faults.split(",") if n.strip()]
    chosen = [catalogue[n] for n in names]
    if settings.extra_fault_parameter:
        name, factor = settings.extra_fault_parameter, settings.extra_fault_factor
        chosen.append(Fault(name=f"{name}_x{factor:g}", parameter=name, factor=factor,
                            kind="abrupt", label=f"{name} to {100 * factor:g} % (yours)"))
    return chosen


def validate(settings: Settings) -> None:
    """Refuse non-physical or inconsistent settings with one line, before any work."""
    catalogue, fault_settings = faults.catalogue()
    names = [n.strip() for n in settings.faults.split(",") if n.strip()]
    unknown = [n for n in names if n not in catalogue]
    if unknown or not (names or settings.extra_fault_parameter):
        raise ParameterError(f"parameter 'faults': unknown fault '{unknown[0] if unknown else ''}'"
                             f"; faults: {', '.join(catalogue)}")
    extra = settings.extra_fault_parameter
    if extra and extra not in lateral_16state.PARAM_NAMES:
        raise ParameterError(f"parameter 'extra_fault_parameter': unknown parameter '{extra}'; "
                             f"parameters: {', '.join(lateral_16state.PARAM_NAMES)}")
    if settings.spectrum not in SPECTRA:
        raise ParameterError(f"parameter 'spectrum': unknown spectrum '{settings.spectrum}'")
    grid = faults.fault_times_s(fault_settings)
    if settings.duration_s < grid[-1] + 2.0:
        raise ParameterError(f"parameter 'duration_s' must be >= {grid[-1] + 2.0:g} s: the last "
                             "fault time of the prior plus the 2 s of the longest horizon")
    t = settings.fault_time_s
    if t != -1.0:
        if not 0.0 < t < settings.duration_s:
            raise ParameterError(f"parameter 'fault_time_s' = {t:g} s lies outside the record "
                                 f"(0 … {settings.duration_s:g} s)")
        if np.min(np.abs(grid - t)) > 1e-9:
            raise ParameterError(f"parameter 'fault_time_s' = {t:g} s is not on the prior's grid "
                                 f"({grid[0]:g}, {grid[1]:g} … {grid[-1]:g} s)")
    steps = grid / settings.dt_s
    if np.max(np.abs(steps - np.round(steps))) > 1e-6:
        raise ParameterError(f"parameter 'dt_s' = {settings.dt_s:g} s must divide the fault "
                             "times' grid spacing")
    for key, value, most in (("records_per_fault", settings.records_per_fault, 300),
                             ("fault_free_records", settings.fault_free_records, 600)):
        if value > most:
            raise ParameterError(f"parameter '{key}' must be <= {most} (seed ranges), got "
                                 f"{value}")
    if not settings.false_alarm_probability < 1:
        raise ParameterError("parameter 'false_alarm_probability' must be < 1")
    if not settings.cusum_variance_ratio > 1:
        raise ParameterError("parameter 'cusum_variance_ratio' must be > 1 (a growth)")
    if settings.ladder_records_per_fault >= 2 and settings.ladder_fault_free_records >= 4 \
            and settings.ladder_speed_kmh not in settings.speeds_kmh:
        speeds = ", ".join(f"{v:g}" for v in settings.speeds_kmh)
        raise ParameterError(f"parameter 'ladder_speed_kmh' = {settings.ladder_speed_kmh:g} "
                             f"km/h is not one of speeds_kmh ({speeds})")
    if window_steps(settings) < 1:
        raise ParameterError(f"parameter 'bank_window_s' = {settings.bank_window_s:g} s is "
                             f"shorter than one sample ({settings.dt_s:g} s)")
    fixed, theta = vehicle()
    for speed in settings.speeds_kmh:
        check_sample_time("dt_s", settings.dt_s,
                          lateral_16state.build_A_direct(fixed, theta, speed / 3.6),
                          f"the lateral vehicle at {speed:g} km/h")


def window_steps(settings: Settings) -> int:
    """W of ``glr`` and ``bayes``: ``bank_window_s`` in samples."""
    return int(round(settings.bank_window_s / settings.dt_s))


def plan(settings: Settings, chosen: list[Fault]) -> list[tuple[str, str, int]]:
    """(fault, role, seed) of every record at one speed, in run order."""
    items = []
    for fault in chosen:
        for i in range(settings.records_per_fault):
            items.append((fault.name, "fault", settings.seed + i))
    half = settings.fault_free_records // 2
    for role, offset in FREE_SEED_OFFSETS.items():
        for i in range(half):
            items.append((NO_FAULT, role, settings.seed + offset + i))
    return items


def fault_time(settings: Settings, grid_s: np.ndarray, seed: int) -> float:
    """The record's fault time, s: ``fault_time_s``, or drawn from the prior's grid (generator
    ``[seed, 13]``: the records of one seed share it across faults and speeds)."""
    if settings.fault_time_s != -1.0:
        return float(settings.fault_time_s)
    return float(grid_s[np.random.default_rng([seed, 13]).integers(len(grid_s))])


def track_model(settings: Settings, fixed: dict, speed_kmh: float
                ) -> tuple[np.ndarray, np.ndarray, int]:
    """What filters that are not given the track model of it at ``speed_kmh``: the discrete
    shaping filter ``(Φ_s, Q_s)`` of a second-order fit to the alignment spectrum of the run's
    track (its band) and the wheelbase delay in samples
    (:mod:`railpaper.models.lateral_unknown_track`)."""
    speed_mps = speed_kmh / 3.6
    fit, _, _ = shaping_filter(settings.spectrum, speed_mps,
                               (settings.wavelength_min_m, settings.wavelength_max_m),
                               "alignment")
    Af, Bf, _ = fit.state_space()
    Phi_s, Q_s = lateral_unknown_track.discrete_shaping(Af, Bf, settings.dt_s)
    return Phi_s, Q_s, lateral_unknown_track.delay_steps(2 * fixed["a"], speed_mps,
                                                         settings.dt_s)


def run_record(settings: Settings, fault_settings: dict, fixed: dict, theta: np.ndarray,
               fault: Fault | None, role: str, speed_kmh: float, seed: int, values: np.ndarray,
               bank: detectors.BankHypotheses, track: tuple | None = None,
               model_error: faults.ModelError | None = None) -> tuple[RecordRun, dict]:
    """Simulate one record and run the detectors on it: the record's :class:`RecordRun` and
    what the illustration needs (the oracle's posterior).  ``fault_settings`` are the
    catalogue's (:func:`.faults.catalogue`), ``values`` the oracle's hypotheses and ``bank``
    those of ``glr`` and ``bayes``; with ``track`` (:func:`track_model`) the filters are not
    given the track input and estimate it; with ``model_error`` the truth has it
    (:func:`.records.simulate_faulted`) and the filters do not."""
    grid_s = faults.fault_times_s(fault_settings)
    tau = fault_time(settings, grid_s, seed) if fault is not None else -1.0
    rec = records.simulate_faulted(settings, fault_settings, fixed, theta, fault, max(tau, 0.0),
                                   speed_kmh, seed, model_error)
    system = filter_system(records.record_settings(settings, speed_kmh), fixed, theta,
                           rec.record, theta_ref=theta)
    if track is not None:
        system = lateral_unknown_track.unknown_track_system(system, *track)
    steps = np.round(grid_s / settings.dt_s).astype(int) + 1
    oracle = detectors.oracle_change_posterior(system, theta, rec.record, values, steps,
                                               fault_settings["p_no_fault"])
    innovations = detectors.nominal_innovations(system, theta, rec.record)
    W = window_steps(settings)
    first_step = evidence_window_row(settings, grid_s) + 1          # the window's first step
    changes = detectors.change_bank(system, theta, rec.record, bank, W,
                                    max(2, first_step - W + 1))
    statistics = {"cusum": detectors.residual_cusum(system, theta, rec.record,
                                                    settings.cusum_variance_ratio, innovations),
                  "chi2": detectors.windowed_chi2(innovations, settings.chi2_window_samples),
                  "glr": changes.glr,
                  "bayes": changes.log_shiryaev_roberts,
                  "oracle": oracle.log_odds,
                  "hunting": detectors.hunting_rms(
                      rec.record, settings.dt_s, speed_kmh / 3.6,
                      detectors.hunting_frequency_hz(fixed, theta, speed_kmh / 3.6))}
    j = None if fault is None else lateral_16state.PARAM_NAMES.index(fault.parameter)
    estimate = {}
    if j is not None:
        estimate["oracle"] = float(oracle.value_posterior @ (values[:, j] / theta[j]))
        best = int(changes.glr_value[-1]) if len(changes.glr_value) else -1
        if best >= 0:
            estimate["glr"] = float(bank.factor[best]) if bank.parameter[best] == j else 1.0
    run = RecordRun(fault=NO_FAULT if fault is None else fault.name, role=role,
                    speed_kmh=speed_kmh, seed=seed, fault_time_s=tau,
                    end_s=rec.end_step * settings.dt_s, flange_contact=rec.flange_contact,
                    statistics=statistics, post_fault_estimate=estimate,
                    true_factor_end=float(rec.factor[-1]) if len(rec.factor) else 1.0,
                    bank_hypothesis=changes.glr_value)
    return run, {"oracle": oracle, "factor": rec.factor}


def evidence_window_row(settings: Settings, grid_s: np.ndarray) -> int:
    """First row (0-based) of the monitoring window (:func:`.evidence.window_rows` at the
    prior's first fault time)."""
    return window_rows(settings.dt_s, float(grid_s[0]))


def illustration(run: RecordRun, extra: dict, names: list[str], grid_s, dt_s
                 ) -> IllustratedRecord:
    """The illustrated record's :class:`IllustratedRecord`."""
    oracle = extra["oracle"]
    return IllustratedRecord(run=run, dt_s=dt_s, fault_times_s=np.asarray(grid_s),
                             fault_time_posterior=oracle.fault_time_posterior,
                             value_posterior=dict(zip(names, map(float,
                                                                 oracle.value_posterior))))


#: Metrics of a ladder rung's evidence kept (with the prefix ``ladder_<rung>_``): at the
#: ladder's operating point, detection within the shortest and longest horizon, the
#: Kaplan–Meier median delay, and the tail's threshold and check.
LADDER_KEPT = ("detected_within_0.5s_", "detected_within_2s_", "km_delay_median_s_",
               "km_delay_median_reached_", "threshold_at_", "mtbfa_h_at_", "tail_check_p_")


def _ladder_items(settings: Settings, chosen: list[Fault]) -> list[tuple[str, str, int]]:
    """The records of every rung: the first ``ladder_records_per_fault`` of each fault and the
    first half of ``ladder_fault_free_records`` of each fault-free role (the same seeds as the
    run's, so the rungs are paired record by record)."""
    rung = settings.replace(records_per_fault=settings.ladder_records_per_fault,
                            fault_free_records=settings.ladder_fault_free_records)
    return plan(rung, chosen)


def track_unknown_fault_records(settings: Settings) -> int:
    """Fault records per fault on the rungs whose filters estimate the track: the first
    :data:`RUN_TRACK_UNKNOWN_RECORDS` of the ladder's (0: those rungs are left out of the
    run)."""
    n = min(RUN_TRACK_UNKNOWN_RECORDS, settings.ladder_records_per_fault)
    return n if n >= 2 else 0


def _kept(metrics: dict, prefix: str) -> dict:
    point = f"_at_{LADDER_MTBFA_H:g}h"
    return {prefix + k: v for k, v in metrics.items()
            if k.startswith(LADDER_KEPT) and (point in k or k.startswith("tail_check_p_"))}


@dataclass(frozen=True)
class RungAtIdealThresholds:
    """A rung's records at the ideal rung's thresholds: metrics
    (``ladder_<rung>_ideal_thresholds_…``) and the ladder table's rows."""

    metrics: dict
    rows: list


def rung_evidence(rung: str, records_: list[RecordRun], settings: Settings,
                  chosen: list[Fault], ideal_thresholds: dict, bank_parameter: np.ndarray,
                  prefix: str = "ladder_", detectors_: dict = DETECTORS
                  ) -> tuple[dict, RungAtIdealThresholds]:
    """One ladder rung's evidence (:func:`.evidence.evidence` on its records at
    ``ladder_speed_kmh``, thresholds recalibrated on its own fault-free records) and, given
    the ideal rung's thresholds for :data:`LADDER_MTBFA_H` hours (``{detector: threshold}``,
    empty for the ideal rung itself), the rung's false alarms and detections at them, with one
    ladder-table row per (detector, fault); ``detectors_``: the detectors read."""
    _, fault_settings = faults.catalogue()
    speed = settings.ladder_speed_kmh
    monitor_from = float(faults.fault_times_s(fault_settings)[0])
    first_row = window_rows(settings.dt_s, monitor_from)
    sk = speed_key(speed)
    fault_parameter = {f.name: lateral_16state.PARAM_NAMES.index(f.parameter) for f in chosen}
    m, _, _, _ = evidence(records_, list(detectors_), (speed,), [f.name for f in chosen],
                          settings, settings.dt_s, monitor_from, bank_parameter, fault_parameter)
    metrics, rows = {}, []
    free = [r for r in records_ if r.role == "evaluation"]
    for det in detectors_:
        h_ideal = ideal_thresholds.get(det)
        if h_ideal is not None and free:
            fa = false_alarm_metrics(free, det, h_ideal, first_row, settings.dt_s, f"{det}_{sk}")
            metrics.update({f"{prefix}{rung}_ideal_thresholds_{k}": v for k, v in fa.items()})
        for f in chosen:
            tag = f"{det}_{f.name}_{sk}_at_{LADDER_MTBFA_H:g}h"
            row = {"rung": rung, "detector": det, "fault": f.name,
                   "km_delay_median_s": m.get(f"km_delay_median_s_{tag}", np.nan),
                   "detected_within_0.5s": m.get(f"detected_within_0.5s_{tag}", np.nan),
                   "detected_within_2s": m.get(f"detected_within_2s_{tag}", np.nan),
                   "detected_within_2s_at_ideal_thresholds": np.nan}
            runs_ = [r for r in records_ if r.fault == f.name]
            if h_ideal is not None and runs_:
                outcomes = detector_outcomes(runs_, det, h_ideal, first_row, settings.dt_s)
                at_ideal = fault_metrics(outcomes, tag)
                metrics.update({f"{prefix}{rung}_ideal_thresholds_{k}": v
                                for k, v in at_ideal.items()
                                if k.startswith("detected_within_2s_")})
                row["detected_within_2s_at_ideal_thresholds"] = \
                    at_ideal[f"detected_within_2s_{tag}"]
            rows.append(row)
    return m, RungAtIdealThresholds(metrics, rows)


def ladder(settings: Settings, fault_settings: dict, fixed: dict, theta: np.ndarray,
           chosen: list[Fault], values: np.ndarray, bank, ideal: list[RecordRun],
           progress) -> tuple[dict, pd.DataFrame]:
    """The realism ladder (:data:`LADDER`) at ``ladder_speed_kmh``: the same seeds' records
    with fewer or noisier sensors, every detector's thresholds recalibrated on each rung's own
    fault-free records (and its tail model for :data:`LADDER_MTBFA_H` hours); the ideal rung is
    the run's own records of those seeds, recalibrated the same way.  Also each rung's records
    at the ideal rung's thresholds for :data:`LADDER_MTBFA_H` hours (``…_ideal_thresholds_``):
    what a monitor tuned on the ideal sensors does with the worse ones.  The rungs whose
    filters estimate the track (:data:`RUNGS_WITHOUT_TRACK`) run the first
    :data:`RUN_TRACK_UNKNOWN_RECORDS` of each fault's records and all the fault-free ones, or
    not at all below two (the default: the stored evidence holds them,
    :data:`STORED_LADDER`).  Metrics
    ``ladder_<rung>_<metric>`` (:data:`LADDER_KEPT`) and one row per (rung, detector, fault)."""
    if settings.ladder_records_per_fault < 2 or settings.ladder_fault_free_records < 4:
        return {}, pd.DataFrame()
    speed = settings.ladder_speed_kmh
    items = _ladder_items(settings, chosen)
    by_name = {f.name: f for f in chosen}
    wanted = {(fault, role, seed) for fault, role, seed in items}
    rungs = {"ideal": [r for r in ideal if r.speed_kmh == speed
                       and (r.fault, r.role, r.seed) in wanted]}
    for n, (rung, (_, overrides)) in enumerate(LADDER.items()):
        if rung in RUNGS_WITHOUT_TRACK and not track_unknown_fault_records(settings):
            continue                           # left out of the run (the stored evidence)
        worse = settings.replace(**overrides)
        track = track_model(worse, fixed, speed) if rung in RUNGS_WITHOUT_TRACK else None
        rungs[rung] = []
        for i, (fault_name, role, seed) in enumerate(items):
            if (track is not None and role == "fault"
                    and seed >= settings.seed + track_unknown_fault_records(settings)):
                continue                       # this rung runs the first share of each fault
            progress(0.95 + 0.04 * (n * len(items) + i) / (len(LADDER) * len(items)),
                     f"ladder {rung}, {fault_name}, seed {seed}")
            run_, _ = run_record(worse, fault_settings, fixed, theta, by_name.get(fault_name),
                                 role, speed, seed, values, bank, track)
            rungs[rung].append(run_)
    metrics, rows, ideal_thresholds = {}, [], {}
    for rung, records_ in rungs.items():
        m, r = rung_evidence(rung, records_, settings, chosen, ideal_thresholds, bank.parameter)
        metrics.update(_kept(m, f"ladder_{rung}_"))
        metrics.update(r.metrics)
        rows += r.rows
        if rung == "ideal":
            sk = speed_key(speed)
            ideal_thresholds = {d: m.get(f"threshold_at_{LADDER_MTBFA_H:g}h_{d}_{sk}")
                                for d in DETECTORS}
    return metrics, pd.DataFrame(rows)


def run(settings: Settings, *, progress=None) -> FaultDetectionResult:
    """Run the appendix with ``settings`` (of :data:`SPEC`; a quick run's sizes are already in
    them).  Everything runs on one numba and one OpenBLAS thread
    (:func:`railpaper.threads.one_thread`): the Kalman banks here are a few hundred filters of
    16 states, stepped one sample at a time, which a second thread hardly speeds up, and a
    chapter that shares the machine with another waits for its own threads otherwise."""
    with one_thread():
        return _run(settings, progress)


def _run(settings: Settings, progress) -> FaultDetectionResult:
    """:func:`run` on the current threads."""
    validate(settings)
    progress = progress or default_progress()
    started = time.perf_counter()
    fixed, theta = vehicle()
    _, fault_settings = faults.catalogue()
    chosen = chosen_faults(settings)
    by_name = {f.name: f for f in chosen}
    names, values = detectors.oracle_hypotheses(chosen, theta)
    if not names:
        raise ParameterError("parameter 'faults': the oracle needs at least one abrupt fault")
    bank = detectors.bank_hypotheses(theta, faults.bayes_factors())
    grid_s = faults.fault_times_s(fault_settings)
    speeds = settings.speeds_kmh
    records_, illustrated = [], None
    items = plan(settings, chosen)
    total = len(items) * len(speeds)
    for s, speed in enumerate(speeds):
        for i, (fault_name, role, seed) in enumerate(items):
            progress(0.95 * (s * len(items) + i) / total,
                     f"{speed:g} km/h, {fault_name}, seed {seed}")  # the ladder: 0.95-0.99
            run_, extra = run_record(settings, fault_settings, fixed, theta,
                                     by_name.get(fault_name), role, speed, seed, values, bank)
            records_.append(run_)
            if illustrated is None and s == 0 and role == "fault":
                illustrated = illustration(run_, extra, names, grid_s, settings.dt_s)
    monitor_from = float(grid_s[0])
    metrics, thresholds, roc, delay_curve = evidence(records_, list(DETECTORS), speeds,
                                        [f.name for f in chosen], settings, settings.dt_s,
                                        monitor_from, bank.parameter,
                                        {f.name: lateral_16state.PARAM_NAMES.index(f.parameter)
                                         for f in chosen})
    ladder_metrics, ladder_rows = ladder(settings, fault_settings, fixed, theta, chosen, values,
                                         bank, records_, progress)
    metrics.update(ladder_metrics)
    critical = faults.critical_speeds(fixed, theta, chosen)
    for row in critical.itertuples():
        found = bool(np.isfinite(row.critical_speed_kmh))        # else: stable to the search's end
        metrics[f"critical_speed_found_{row.fault}"] = found
        if found:
            metrics[f"critical_speed_kmh_{row.fault}"] = row.critical_speed_kmh
    metrics["records"] = len(records_)
    progress(1.0, "done")
    timings = {"total_s": time.perf_counter() - started}
    return FaultDetectionResult(metrics=metrics, timings=timings,
                                timeseries=_timeseries(illustrated), faults=tuple(chosen),
                                records=tuple(records_), thresholds=thresholds,
                                dt_s=settings.dt_s, monitor_from_s=monitor_from,
                                critical_speeds=critical, roc=roc, illustrated=illustrated,
                                delay_curve=delay_curve, ladder=ladder_rows,
                                bank_hypotheses=tuple(
                                    (lateral_16state.PARAM_NAMES[j], float(f))
                                    for j, f in zip(bank.parameter, bank.factor)))


#: First seed of the stored fault-free running: far from the run's fault and fault-free records
#: (seed … seed + 899) and from the pilot seeds of the decisive pipeline (900 000 on).
RUNNING_SEED_OFFSET = 100_000
#: The mean time between false alarms, h, at which the stored running checks the tail model
#: with the power :func:`running_records` asks for (its other checks ride along).
RUNNING_POWER_CHECK_H = 0.1


def monitored_s(settings: Settings) -> float:
    """Fault-free running a full record adds to the false-alarm count, s: the complete
    ``false_alarm_block_s`` blocks of its monitoring window (from the prior's first fault time)."""
    _, fault_settings = faults.catalogue()
    first_row = evidence_window_row(settings, faults.fault_times_s(fault_settings))
    block_rows = rows_per_block(settings, settings.dt_s)
    steps = int(round(settings.duration_s / settings.dt_s))
    return (steps - first_row) // block_rows * block_rows * settings.dt_s


def running_records(settings: Settings) -> int:
    """Size of the stored fault-free running, fixed before it ran: the fewest records per speed
    whose alarm count at a threshold set for :data:`RUNNING_POWER_CHECK_H` hours finds twice
    the alarms the tail model predicts with power 0.8 (one-sided Poisson test at 5 %,
    :func:`railpaper.monitoring.running_for_power`; the size at the defaults is pinned in a
    test).  The check applied is two-sided and loses the running cut at flange contact, so its
    power is lower; the page computes and says it."""
    return running_for_power(RUNNING_POWER_CHECK_H, monitored_s(settings))


def first_running_seed(settings: Settings) -> int:
    """The stored running's first seed: ``seed`` + :data:`RUNNING_SEED_OFFSET`."""
    return settings.seed + RUNNING_SEED_OFFSET


def running_rows(settings: Settings, seeds) -> pd.DataFrame:
    """The stored fault-free running (study ``fault_free_running``): per seed and speed, one
    fault-free record with every detector run on it as in the chapter's run, kept as the
    maxima of its statistics over the ``false_alarm_block_s`` blocks of the monitoring window
    (``block_max_<detector>_<speed>_<i>``, NaN for a block the record did not reach), its
    running (``running_s_<speed>``, s) and whether it was cut at flange contact."""
    fixed, theta = vehicle()
    _, fault_settings = faults.catalogue()
    chosen = chosen_faults(settings)
    _, values = detectors.oracle_hypotheses(chosen, theta)
    bank = detectors.bank_hypotheses(theta, faults.bayes_factors())
    first_row = evidence_window_row(settings, faults.fault_times_s(fault_settings))
    block_rows = rows_per_block(settings, settings.dt_s)
    blocks = (int(round(settings.duration_s / settings.dt_s)) - first_row) // block_rows
    rows = []
    with one_thread():
        for seed in seeds:
            row = {"seed": int(seed)}
            for speed in settings.speeds_kmh:
                tag = speed_key(speed)
                run_, _ = run_record(settings, fault_settings, fixed, theta, None, "running",
                                     speed, int(seed), values, bank)
                for detector in DETECTORS:
                    maxima = block_maxima(run_.statistics[detector], first_row, block_rows)
                    for i in range(blocks):
                        row[f"block_max_{detector}_{tag}_{i}"] = (
                            float(maxima[i]) if i < maxima.size else np.nan)
                row[f"running_s_{tag}"] = float(min(blocks, maxima.size) * block_rows
                                                * settings.dt_s)
                row[f"flange_contact_{tag}"] = bool(run_.flange_contact)
            rows.append(row)
    return pd.DataFrame(rows)


#: Long fault-free running, beyond what the book's run can afford: computed once into the
#: stored evidence (``railpaper evidence --decisive suspension-fault-detection``), read by the
#: page through :func:`railpaper.pipeline.decisive.stored_rows`.
FAULT_FREE_RUNNING = RecordStudy(
    "suspension-fault-detection", "fault_free_running", running_rows, chunk_records=8,
    first_record=first_running_seed)
#: The stored ladder rungs' record roles besides the faults: a fault-free record of seed
#: ``seed + offset + i`` each (:data:`FREE_SEED_OFFSETS`).
STORED_FREE_ROLES = tuple(FREE_SEED_OFFSETS)


def stored_ladder_item(settings: Settings, record: int) -> tuple[str, str, str, int]:
    """What record ``record`` of the study ``stored_ladder`` is (it counts from ``seed``):
    ``(rung, key, role, record seed)``.  Per i = 0, 1, …, for each rung of
    :data:`STORED_RUNGS`: the record of seed ``seed`` + i of every fault (key: the fault's
    name), then the fault-free ones of seeds ``seed`` + 300 + i (calibration) and
    ``seed`` + 600 + i (evaluation)."""
    keys = [(f.name, "fault", 0) for f in chosen_faults(settings)] + [
        (role, role, FREE_SEED_OFFSETS[role]) for role in STORED_FREE_ROLES]
    j = int(record) - settings.seed
    i, rest = divmod(j, len(STORED_RUNGS) * len(keys))
    rung = list(STORED_RUNGS)[rest // len(keys)]
    key, role, offset = keys[rest % len(keys)]
    return rung, key, role, settings.seed + offset + i


def stored_ladder_rows(settings: Settings, records_) -> pd.DataFrame:
    """The stored ladder rungs (study ``stored_ladder``, :data:`STORED_RUNGS`) at
    ``ladder_speed_kmh``, one row per record (:func:`stored_ladder_item`): the detectors run on
    it as on the run's ladder, each statistic kept as :func:`.evidence.statistic_peaks`
    (``<detector>_peaks``), with ``rung``, ``record`` (the fault's name or the fault-free
    role), ``record_seed``, ``fault_time_s``, ``end_s`` and ``flange_contact``: all that
    :func:`stored_ladder` reads."""
    fixed, theta = vehicle()
    _, fault_settings = faults.catalogue()
    chosen = {f.name: f for f in chosen_faults(settings)}
    _, values = detectors.oracle_hypotheses(list(chosen.values()), theta)
    bank = detectors.bank_hypotheses(theta, faults.bayes_factors())
    first_row = evidence_window_row(settings, faults.fault_times_s(fault_settings))
    block_rows = rows_per_block(settings, settings.dt_s)
    speed = settings.ladder_speed_kmh
    truth_error = faults.model_error()
    rungs = {}                      # per rung: its settings, track model and truth's error
    for rung, (_, overrides, with_error) in STORED_RUNGS.items():
        worse = settings.replace(**overrides)
        rungs[rung] = (worse, track_model(worse, fixed, speed),
                       truth_error if with_error else None)
    rows = []
    with one_thread():
        for record in records_:
            rung, key, role, record_seed = stored_ladder_item(settings, record)
            worse, track, error = rungs[rung]
            run_, _ = run_record(worse, fault_settings, fixed, theta, chosen.get(key), role,
                                 speed, record_seed, values, bank, track, error)
            row = {"seed": int(record), "rung": rung, "record": key,
                   "record_seed": record_seed, "fault_time_s": run_.fault_time_s,
                   "end_s": run_.end_s, "flange_contact": bool(run_.flange_contact)}
            for detector in STORED_DETECTORS:
                row[f"{detector}_peaks"] = statistic_peaks(run_.statistics[detector],
                                                           first_row, block_rows)
            rows.append(row)
    return pd.DataFrame(rows)


def _text(value) -> str:
    """A stored text cell: an empty one reads back from CSV as NaN."""
    return value if isinstance(value, str) else ""


def stored_ladder_records(rows: pd.DataFrame, settings: Settings, rung: str) -> list[RecordRun]:
    """The records of one stored rung (:func:`stored_ladder_rows`) as :class:`RecordRun`
    whose statistics keep only their peaks (:func:`.evidence.statistic_from_peaks`: every
    threshold, block maximum and alarm time the rung's evidence reads is the original's; no
    estimates, no GLR hypotheses, so no blame metrics)."""
    out = []
    for row in rows[rows["rung"] == rung].to_dict("records"):
        length = int(round(row["end_s"] / settings.dt_s))
        role = row["record"] if row["record"] in STORED_FREE_ROLES else "fault"
        out.append(RecordRun(
            fault=row["record"] if role == "fault" else NO_FAULT, role=role,
            speed_kmh=settings.ladder_speed_kmh, seed=int(row["record_seed"]),
            fault_time_s=float(row["fault_time_s"]), end_s=float(row["end_s"]),
            flange_contact=bool(row["flange_contact"]),
            statistics={d: statistic_from_peaks(_text(row[f"{d}_peaks"]), length)
                        for d in STORED_DETECTORS if f"{d}_peaks" in row},
            post_fault_estimate={}, true_factor_end=np.nan, bank_hypothesis=None))
    return out


def stored_ladder(rows: pd.DataFrame, settings: Settings, run_records: list[RecordRun]
                  ) -> tuple[dict, pd.DataFrame]:
    """The stored rungs' evidence beside the ideal rung of the run's own records at
    ``ladder_speed_kmh``, on the records (fault, role, seed) that the run and every stored rung
    hold (the rungs are paired record by record), each as the run's
    ladder computes its rungs (:func:`rung_evidence`: thresholds for :data:`LADDER_MTBFA_H`
    hours recalibrated on the rung's fault-free records, and the ideal rung's applied):
    metrics ``stored_ladder_<rung>_<metric>`` (:data:`LADDER_KEPT` and at the ideal
    thresholds), each rung's flange contacts after the faults, on the records that reached
    their fault (``…_flange_contact_rate_…``, ``…_flange_contact_after_…``), its tail
    check (``…_tail_check_…``) and its stored records before pairing
    (``stored_ladder_<rung>_stored_records``), and the ladder table's rows, with the records
    per fault (``records``) and the fault records that ended before their fault
    (``ended_before_fault``)."""
    speed = settings.ladder_speed_kmh
    sk = speed_key(speed)
    bank = detectors.bank_hypotheses(vehicle()[1], faults.bayes_factors())
    chosen = chosen_faults(settings)
    stored = {rung: stored_ladder_records(rows, settings, rung) for rung in STORED_RUNGS}
    out = {f"stored_ladder_{rung}_stored_records": len(records_)
           for rung, records_ in stored.items()}

    def key(r):
        return r.fault, r.role, r.seed
    ours = [r for r in run_records if r.speed_kmh == speed]
    paired = {key(r) for r in ours}.intersection(*({key(r) for r in records_}
                                                   for records_ in stored.values()))
    rungs = {"ideal": [r for r in ours if key(r) in paired]}
    rungs.update({rung: [r for r in records_ if key(r) in paired]
                  for rung, records_ in stored.items()})
    table, ideal = [], {}
    for rung, records_ in rungs.items():
        if not records_:
            continue
        m, at_ideal = rung_evidence(rung, records_, settings, chosen, ideal, bank.parameter,
                                    prefix="stored_ladder_", detectors_=STORED_DETECTORS)
        out.update(_kept(m, f"stored_ladder_{rung}_"))
        out.update({f"stored_ladder_{rung}_{k}": v for k, v in m.items()
                    if k.startswith("tail_check_")})
        for f in chosen:                 # the records that reached their fault
            reached = [r for r in records_ if r.fault == f.name and r.end_s > r.fault_time_s]
            if reached:
                out.update({f"stored_ladder_{rung}_{k}": v for k, v in flange_metrics(
                    reached, f"{f.name}_{sk}").items()})
        out.update(at_ideal.metrics)
        if rung == "ideal":
            ideal = {d: m.get(f"threshold_at_{LADDER_MTBFA_H:g}h_{d}_{sk}")
                     for d in STORED_DETECTORS}
        free = [r for r in records_ if r.fault == NO_FAULT]
        out[f"stored_ladder_{rung}_fault_free_flange_contacts"] = sum(
            r.flange_contact for r in free)
        out[f"stored_ladder_{rung}_fault_free_records"] = len(free)
        for row in at_ideal.rows:
            runs_ = [r for r in records_ if r.fault == row["fault"]]
            table.append(dict(row, records=len(runs_), ended_before_fault=sum(
                r.end_s <= r.fault_time_s for r in runs_)))
    return out, pd.DataFrame(table)


#: The stored ladder rungs (:data:`STORED_RUNGS`), computed once into the stored evidence
#: like the long running (:func:`stored_ladder_rows`).
STORED_LADDER = RecordStudy(
    "suspension-fault-detection", "stored_ladder", stored_ladder_rows, chunk_records=7)
#: The appendix's per-record studies.
STUDIES = (FAULT_FREE_RUNNING, STORED_LADDER)


def stored_ladder_size(settings: Settings) -> int:
    """Records of the study ``stored_ladder``: on each stored rung the run's
    ``records_per_fault`` records of every fault and as many fault-free records of each role
    (the run's ``fault_free_records`` in all), so the stored rungs are paired record by record
    with the run's records at the ladder's speed.  Not sized by power: no finding reads
    them; the page gives their intervals."""
    return (settings.records_per_fault * len(STORED_RUNGS)
            * (len(chosen_faults(settings)) + len(STORED_FREE_ROLES)))


def stored_sizes(settings: Settings) -> dict[str, int]:
    """Records of each stored study the decisive run computes (no declared rows decide this
    appendix; its sizes are fixed here by :func:`running_records` and
    :func:`stored_ladder_size`)."""
    return {FAULT_FREE_RUNNING.name: running_records(settings),
            STORED_LADDER.name: stored_ladder_size(settings)}


def _timeseries(ill: IllustratedRecord) -> pd.DataFrame:
    """The illustrated record's statistics, one row per sample."""
    run_ = ill.run
    K = len(run_.statistics["oracle"])
    out = pd.DataFrame({"t_s": ill.dt_s * np.arange(1, K + 1)})
    for name, stat in run_.statistics.items():
        out[f"statistic_{name}"] = stat
    out["glr_hypothesis"] = run_.bank_hypothesis
    return out


__all__ = ["FAULT_FREE_RUNNING", "LADDER_KEPT", "RUNNING_POWER_CHECK_H",
           "RUNNING_SEED_OFFSET", "RungAtIdealThresholds", "STORED_LADDER", "STUDIES",
           "chosen_faults", "first_running_seed", "ladder", "monitored_s", "plan",
           "run", "run_record", "rung_evidence", "running_records", "running_rows",
           "stored_ladder", "stored_ladder_records", "stored_ladder_item", "stored_ladder_size",
           "stored_ladder_rows", "stored_sizes", "track_model",
           "track_unknown_fault_records", "validate", "window_steps"]
