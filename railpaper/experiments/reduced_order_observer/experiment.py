"""Chapter ``reduced-order-observer`` (paper 001): wheel–rail force from a reduced-order observer.

The whole computation of the chapter as a function of its parameters: simulate the single-wheelset
vehicle on a US FRA class-5 vertical profile, observe ``[ż_w, z_w]`` from the measured body
signals ``[ż_c, z_c]`` and the known irregularity ``q`` with the Gopinath observer of Eq. (12),
and turn the estimate into the wheel–rail force with the linearised Hertz stiffness (Eq. 4).

Definitions used for the metrics
--------------------------------
* convergence time: the first time after which ``|ẑ_w − z_w|`` stays below
  ``convergence_fraction`` (5 %) of the RMS of the true ``z_w`` to the end of the run;
* force RMS error: RMS of ``f̂ − f`` over ``t ≥ error_window_start_s`` (after the transient).

The single runs (seed ``seed``) are illustrations; the claims are decided on the Monte Carlo
evidence of :mod:`railpaper.experiments.reduced_order_observer.evidence` (``mc_seeds`` seeds, both
readings of P0), whose metrics ``data/reduced-order-observer/claims.toml`` reads.  On the same
records, :mod:`railpaper.experiments.reduced_order_observer.kalman` runs a Kalman filter with a
track shaping filter and its RTS smoother beside the paper's observer (metrics
``force_rms_error_ratio_*`` and ``mc_force_rms_error_ratio_*``).
"""

from __future__ import annotations

import time

import numpy as np
import pandas as pd

from railpaper import track
from railpaper.estimators import reduced_order_observer
from railpaper.experiments.base import ParameterError, default_progress
from railpaper.experiments.records import RecordMap, map_in_process
from railpaper.experiments.reduced_order_observer import evidence, kalman, record
from railpaper.experiments.reduced_order_observer.record import (  # noqa: F401 (chapter API)
    ObserverRun,
    Record,
    SpeedRun,
    _simulate_hertz,
    run_observer,
    simulate_record,
    simulate_speed,
)
from railpaper.experiments.reduced_order_observer.result import (
    ReducedOrderObserverResult,
)
from railpaper.experiments.reduced_order_observer.spec import NOISE_SWEEP_FRACTIONS, Settings
from railpaper.models import single_wheelset
from railpaper.timing import steps_per_second


#: The chapter's per-record studies (the evidence store and the decisive run compute them).
STUDIES = (evidence.MONTE_CARLO, evidence.HERTZ, kalman.ESTIMATOR_RECORDS,
           kalman.TRACK_NOISE_RECORDS)


def validate(settings: Settings) -> None:
    """Refuse non-physical or inconsistent settings with one line, before any work."""
    if settings.plant not in ("linear", "hertz"):
        raise ParameterError(f"parameter 'plant' must be 'linear' or 'hertz', got {settings.plant!r}")
    if settings.observer_form not in ("paper", "foh"):
        raise ParameterError(
            f"parameter 'observer_form' must be 'paper' or 'foh', got {settings.observer_form!r}")
    if settings.p0_basis not in single_wheelset.P0_BASES:
        raise ParameterError(
            f"parameter 'p0_basis' must be 'wheel' or 'wheelset', got {settings.p0_basis!r}")
    if settings.mc_seeds >= 1000:
        raise ParameterError("parameter 'mc_seeds' must be < 1000 (seed batches 1000 apart are "
                             f"disjoint), got {settings.mc_seeds}")
    if not 1 <= settings.track_class <= 6:
        raise ParameterError(f"parameter 'track_class' must be 1..6, got {settings.track_class}")
    if len(settings.observer_poles) != 2 or max(settings.observer_poles) >= 0:
        raise ParameterError("parameter 'observer_poles' needs two negative numbers, e.g. [-30, -40]")
    if settings.dt_s > 5e-4:
        raise ParameterError(
            f"parameter 'dt_s' = {settings.dt_s} s is too coarse for the 243 Hz wheelset mode "
            "(use ≤ 5e-4 s)")
    if settings.error_window_start_s >= settings.duration_s:
        raise ParameterError("parameter 'error_window_start_s' must be shorter than 'duration_s'")


def design_observers(A, B, settings: Settings) -> dict:
    """The paper's observer (12) discretised two ways: ``paper`` (ZOH) and ``foh``."""
    observer = reduced_order_observer.design(A, B, 2, settings.observer_poles)
    return {form: observer.discretise(settings.dt_s, "zoh" if form == "paper" else "foh")
            for form in ("paper", "foh")}


def _label(speed_kmh: float) -> str:
    return f"{speed_kmh:g}kmh"


def _rms(x, axis=0):
    return np.sqrt(np.mean(x**2, axis=axis))


def _side_tables(vehicle, observers, settings: Settings, distance_m, profile_m, progress):
    """The noise-sensitivity table (first speed, the ``observer_form`` observer at each of
    :data:`NOISE_SWEEP_FRACTIONS`, noise draws salted 1) and the linear-vs-Hertz table
    (noise-free sensors, FOH observer, every speed of ``speeds_kmh``, draws salted 2), each
    simulated as one batch (one plant run per table and plant)."""
    dt, e0, seed = settings.dt_s, settings.initial_error_m, settings.seed

    def inputs(speed, salt):
        t_s, q = track.wheelset_inputs(distance_m, profile_m, speed / 3.6, [0.0], dt,
                                       settings.duration_s)
        ny, nq = record.noise_draws(seed, speed, len(t_s), salt)
        return t_s, q[:, 0], ny, nq

    def errors(observer, y, q, q_meas, z_w, force, window):
        x2 = np.column_stack([np.zeros(q.shape[1]), q[0] + e0])
        z_est = record._observer_batch(observer, y, q_meas, x2)
        f_est = single_wheelset.dynamic_contact_force_N(vehicle, z_est, q_meas, "linear")
        return _rms((f_est - force)[window]), _rms((z_est - z_w)[window])

    speed, fractions = settings.speeds_kmh[0], np.array(NOISE_SWEEP_FRACTIONS)
    t_s, q, ny, nq = inputs(speed, (1,))
    y, z_w = record._plant_batch(vehicle, settings.plant, dt, q[:, None])
    force = single_wheelset.dynamic_contact_force_N(vehicle, z_w, q[:, None], settings.plant)
    window = t_s >= settings.error_window_start_s
    y_meas = y + ny[:, None] * fractions[:, None] * _rms(y)               # (K, levels, 2)
    q_meas = np.repeat((q + nq * settings.track_noise_fraction * _rms(q))[:, None],
                       len(fractions), axis=1)
    force_error, z_error = errors(observers[settings.observer_form], y_meas,
                                  np.repeat(q[:, None], len(fractions), axis=1), q_meas,
                                  z_w, force, window)
    noise_rows = [{"noise_fraction": f, "speed_kmh": speed,
                   "force_relative_rms_error": force_error[i] / _rms(force[window])[0],
                   "displacement_rms_error_m": z_error[i]} for i, f in enumerate(fractions)]
    speeds = settings.speeds_kmh
    columns = [inputs(v, (2,)) for v in speeds]
    q = np.column_stack([c[1] for c in columns])
    q_meas = q + np.column_stack([c[3] for c in columns]) * settings.track_noise_fraction * _rms(q)
    plant_rows = []
    for plant in ("linear", "hertz"):                      # cost of linearising the contact
        progress(0.55, f"{plant} plant, noise-free")
        y, z_w = record._plant_batch(vehicle, plant, dt, q)
        force = single_wheelset.dynamic_contact_force_N(vehicle, z_w, q, plant)
        force_error, _ = errors(observers["foh"], y, q, q_meas, z_w, force, window)
        lost = np.mean(force <= -vehicle.contacts * vehicle.static_wheel_load_N, axis=0)
        plant_rows += [{"speed_kmh": v, "plant": plant, "force_rms_N": _rms(force[window])[i],
                        "force_rms_error_N_foh_observer": force_error[i],
                        "contact_lost_fraction": lost[i]} for i, v in enumerate(speeds)]
    plant_rows.sort(key=lambda r: (speeds.index(r["speed_kmh"]), r["plant"] != "linear"))
    return pd.DataFrame(noise_rows), pd.DataFrame(plant_rows)


def run(settings: Settings, *, progress=None,
        record_map: RecordMap = map_in_process) -> ReducedOrderObserverResult:
    """Run the chapter with its resolved ``settings`` (of :data:`SPEC`; quick sizes included).

    Single runs of seed ``seed`` (reading ``p0_basis``) give the illustrations and their metrics;
    with ``side_tables`` the run adds the side tables and the claims' evidence: the Monte Carlo
    metrics (``mc_*``, every reading), the deterministic structure metrics (``rank_*`` and
    ``pole_placement_*``) and the estimator comparison (:func:`kalman.compare`, reading
    ``p0_basis``).  The per-seed records of the studies (:data:`evidence.MONTE_CARLO`,
    :data:`evidence.HERTZ`, :data:`kalman.ESTIMATOR_RECORDS`,
    :data:`kalman.TRACK_NOISE_RECORDS`) are computed by ``record_map`` (default: here) and
    written as the extra tables ``records_<study>``; the metrics are their reduce.
    """
    validate(settings)
    progress = progress or default_progress()
    started = time.perf_counter()
    vehicle = single_wheelset.load_parameters(p0_basis=settings.p0_basis)
    A, B = single_wheelset.state_space(vehicle)
    observers = design_observers(A, B, settings)
    form = settings.observer_form
    other = "foh" if form == "paper" else "paper"
    all_speeds = record.all_speeds(settings)
    distance_m, profile_m = record.profile(settings, settings.seed)
    runs = {}
    for i, speed in enumerate(all_speeds):
        progress(0.5 * i / len(all_speeds), f"{speed:g} km/h")
        runs[speed] = simulate_speed(vehicle, observers, settings, distance_m, profile_m, speed)
    noise_sweep, plant_comparison = _side_tables(
        vehicle, observers, settings, distance_m, profile_m, progress) if settings.side_tables \
        else (pd.DataFrame(), pd.DataFrame())

    metrics, columns = {}, {"t_s": runs[settings.speeds_kmh[0]].record.t_s}
    for speed in settings.speeds_kmh:
        r, lab = runs[speed], _label(speed)
        main = r.observer(form)
        metrics[f"convergence_time_s_{lab}"] = main.convergence_time_s
        metrics[f"force_rms_error_N_{lab}"] = main.force_rms_error_N
        metrics[f"force_relative_rms_error_{lab}"] = main.force_rms_error_N / r.force_rms_N
        metrics[f"displacement_rms_error_m_{lab}"] = main.displacement_rms_error_m
        columns[f"wheelset_displacement_true_m_{lab}"] = r.record.x_true[:, 3]
        columns[f"wheelset_displacement_est_m_{lab}"] = main.z_w_est_m
        columns[f"wheel_rail_force_true_N_{lab}"] = r.record.force_true_N
        columns[f"wheel_rail_force_est_N_{lab}"] = main.force_est_N
    mc, estimators, records = pd.DataFrame(), None, {}
    timings = {"single_runs_s": time.perf_counter() - started}
    first = runs[settings.speeds_kmh[0]].record          # the paper's observer, one record
    timings["observer_steps_per_second"] = steps_per_second(
        lambda: observers["paper"].run(first.y_measured, first.q_measured_m[:, None],
                                       first.x2_initial), len(first.t_s))
    if settings.side_tables:
        mc_started = time.perf_counter()
        records.update(evidence.monte_carlo_records(
            settings, lambda f, m: progress(0.6 + 0.2 * f, m), record_map))
        mc = evidence.samples_table(records[evidence.MONTE_CARLO.name],
                                    records[evidence.HERTZ.name], settings)
        metrics.update(evidence.legacy_band_metrics(mc, settings))
        metrics.update(evidence.evidence_metrics(mc, settings))
        metrics.update(evidence.structure_metrics(settings))
        timings["monte_carlo_s"] = time.perf_counter() - mc_started
        kalman_started = time.perf_counter()
        records.update(kalman.comparison_records(
            settings, lambda f, m: progress(0.8 + 0.19 * f, m), record_map))
        estimators = kalman.comparison(records, settings)
        metrics.update(kalman.comparison_metrics(estimators, settings))
        timings["kalman_s"] = time.perf_counter() - kalman_started
    progress(1.0, "done")
    sweep = pd.DataFrame([{
        "speed_kmh": s, "convergence_time_s": runs[s].observer(form).convergence_time_s,
        "force_rms_error_N": runs[s].observer(form).force_rms_error_N,
        "force_rms_N": runs[s].force_rms_N,
        "displacement_rms_error_m": runs[s].observer(form).displacement_rms_error_m,
        "contact_lost_fraction": runs[s].contact_lost_fraction,
        "z_w_rms_m": runs[s].z_w_rms_m,
        "predicted_convergence_time_s": runs[s].predicted_convergence_time_s,
        f"convergence_time_s_{other}": runs[s].observer(other).convergence_time_s,
        f"force_rms_error_N_{other}": runs[s].observer(other).force_rms_error_N,
    } for s in settings.sweep_speeds_kmh])
    observer = reduced_order_observer.design(A, B, 2, settings.observer_poles)
    timings["run_s"] = time.perf_counter() - started
    return ReducedOrderObserverResult(
        metrics=metrics, timings=timings, timeseries=pd.DataFrame(columns),
        extra_tables={"speed_sweep": sweep, "monte_carlo_samples": mc,
                      "estimator_samples": estimators.samples,
                      **{f"records_{name}": rows for name, rows in records.items()}}
        if settings.side_tables else {"speed_sweep": sweep},
        vehicle=vehicle, A=A, B=B, observer=observer,
        error_poles_per_s=np.linalg.eigvals(observer.F), runs=runs, speed_sweep=sweep,
        noise_sweep=noise_sweep, plant_comparison=plant_comparison, monte_carlo=mc,
        estimators=estimators)
