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
from dataclasses import dataclass, field

import numpy as np
import pandas as pd

from railpaper import track
from railpaper.estimators import reduced_order_observer as roo
from railpaper.experiments.reduced_order_observer import evidence
from railpaper.experiments.reduced_order_observer import kalman
from railpaper.experiments.base import ChapterResult, ChapterSpec, Parameter, ParameterError
from railpaper.experiments.reduced_order_observer.record import (  # noqa: F401 (chapter API)
    ObserverRun, Record, SpeedRun, _simulate_hertz, run_observer,
    simulate_record, simulate_speed)
from railpaper.models import single_wheelset as sw

SPEC = ChapterSpec(
    name="reduced-order-observer",
    title="Reduced-order observer of the wheel–rail force (Li, Zheng & Chai 2014)",
    paper="001_b49ad810fb7b323c.txt",
    notebook="reduced_order_observer.ipynb",
    quick_sizes="1 s simulated instead of 2 s; trend sweep over 4 speeds instead of 9; "
                "40 Monte Carlo seeds instead of 20 (a 1 s run's trends are noisier)",
    notebook_requires={"side_tables": True},
    parameters=[
        Parameter("speeds_kmh", [60.0, 100.0], "list[float]",
                  "speeds of the main runs (figures, time series, metrics), km/h", positive=True),
        Parameter("sweep_speeds_kmh", [40.0, 60.0, 80.0, 100.0, 120.0, 140.0, 160.0, 180.0, 200.0],
                  "list[float]", "speeds of the trend figures, km/h",
                  quick=[40.0, 100.0, 160.0, 200.0], positive=True),
        Parameter("duration_s", 2.0, "float", "simulated time per run, s", quick=1.0, positive=True),
        Parameter("dt_s", 1e-4, "float", "time step of plant samples and observer (paper: 1e-4 s), s",
                  positive=True),
        Parameter("observer_poles", [-30.0, -40.0], "list[float]",
                  "poles of the observer error dynamics A22 − L·A12, 1/s (real, negative)"),
        Parameter("observer_form", "paper", "str",
                  "discretisation of observer (12): 'paper' (y, q held over a step, ZOH) or 'foh' "
                  "(y, q linear between samples)"),
        Parameter("plant", "linear", "str",
                  "plant that generates the truth: 'linear' (paper) or 'hertz' (nonlinear contact)"),
        Parameter("noise_fraction", 0.01, "float",
                  "sensor noise σ as a fraction of each measured channel's RMS (paper's D = 0.01)",
                  minimum=0.0),
        Parameter("track_noise_fraction", 0.0, "float",
                  "noise σ on the irregularity q given to the observer, fraction of its RMS",
                  minimum=0.0),
        Parameter("initial_error_m", 0.005, "float",
                  "initial error of the observer's wheelset displacement, m"),
        Parameter("track_class", 5, "int", "US FRA track class (1-6) of the vertical profile",
                  minimum=1),
        Parameter("convergence_fraction", 0.05, "float",
                  "convergence threshold as a fraction of the RMS of the true z_w", positive=True),
        Parameter("error_window_start_s", 0.5, "float",
                  "force errors are measured from this time to the end of the run, s", minimum=0.0),
        Parameter("p0_basis", "wheel", "str",
                  "reading of P0 in Eq. (3) for the single runs: 'wheel' (per-wheel static load, "
                  "two contacts) or 'wheelset' (the text: wheelset static load, one contact); the "
                  "Monte Carlo evidence always covers both"),
        Parameter("seed", 0, "int", "seed of the track profile and the sensor noise", minimum=0),
        Parameter("mc_seeds", 20, "int",
                  "Monte Carlo seeds (seed, seed + 1 and so on; fewer than 1000) behind every claim verdict",
                  quick=40, minimum=2),
        Parameter("side_tables", True, "bool",
                  "also compute the noise-sensitivity and linear-vs-Hertz tables and the Monte "
                  "Carlo evidence (sweep samples switch them off: they need only the main runs)"),
    ],
)

#: Sensor-noise levels (fraction of channel RMS) of the noise-sensitivity table.
NOISE_SWEEP_FRACTIONS = (0.0, 1e-5, 1e-4, 1e-3, 1e-2)


def validate(params: dict) -> None:
    """Refuse non-physical or inconsistent resolved parameters with one line, before any work."""
    if params["plant"] not in ("linear", "hertz"):
        raise ParameterError(f"parameter 'plant' must be 'linear' or 'hertz', got {params['plant']!r}")
    if params["observer_form"] not in ("paper", "foh"):
        raise ParameterError(
            f"parameter 'observer_form' must be 'paper' or 'foh', got {params['observer_form']!r}")
    if params["p0_basis"] not in sw.P0_BASES:
        raise ParameterError(
            f"parameter 'p0_basis' must be 'wheel' or 'wheelset', got {params['p0_basis']!r}")
    if params["mc_seeds"] >= 1000:
        raise ParameterError("parameter 'mc_seeds' must be < 1000 (seed batches 1000 apart are "
                             f"disjoint), got {params['mc_seeds']}")
    if not 1 <= params["track_class"] <= 6:
        raise ParameterError(f"parameter 'track_class' must be 1..6, got {params['track_class']}")
    if len(params["observer_poles"]) != 2 or max(params["observer_poles"]) >= 0:
        raise ParameterError("parameter 'observer_poles' needs two negative numbers, e.g. [-30, -40]")
    if params["dt_s"] > 5e-4:
        raise ParameterError(
            f"parameter 'dt_s' = {params['dt_s']} s is too coarse for the 243 Hz wheelset mode "
            "(use ≤ 5e-4 s)")
    if params["error_window_start_s"] >= params["duration_s"]:
        raise ParameterError("parameter 'error_window_start_s' must be shorter than 'duration_s'")


def design_observers(A, B, params) -> dict:
    """The paper's observer (12) discretised two ways: ``paper`` (ZOH) and ``foh``."""
    observer = roo.design(A, B, 2, params["observer_poles"])
    return {form: observer.discretise(params["dt_s"], "zoh" if form == "paper" else "foh")
            for form in ("paper", "foh")}


def _label(speed_kmh: float) -> str:
    return f"{speed_kmh:g}kmh"


@dataclass
class ReducedOrderObserverResult(ChapterResult):
    """What :func:`run` returns: the pipeline's :class:`ChapterResult` plus named results.

    Attributes
    ----------
    vehicle : SingleWheelset
        The vehicle of the single runs (reading ``p0_basis``).
    A, B : ndarray
        Continuous ``ẋ = A x + B q`` of the vehicle (Eq. 7, errata fixed), SI units.
    observer : ReducedOrderObserver
        The continuous observer of Eq. (12) with error poles ``observer_poles``.
    error_poles_per_s : ndarray
        Eigenvalues of ``A22 − L A12``, 1/s.
    runs : dict of float to SpeedRun
        The single runs of seed ``seed``, by speed (km/h): ``speeds_kmh`` then the sweep.
    speed_sweep : DataFrame
        One row per sweep speed (``speed_kmh``); the ``observer_form`` observer's convergence
        time (s, -1 never), force and displacement RMS errors (N, m), the force RMS (N), and the
        other discretisation's convergence time and force error (suffix ``_paper``/``_foh``).
    noise_sweep : DataFrame
        Force relative RMS error and displacement RMS error (m) against ``noise_fraction`` at
        the first speed (seed ``seed``, its own noise draws); empty without ``side_tables``.
    plant_comparison : DataFrame
        Linear vs Hertz plant, noise-free, FOH observer: force RMS (N), its RMS error (N), the
        fraction of samples with contact lost; empty without ``side_tables``.
    monte_carlo : DataFrame
        :func:`evidence.monte_carlo` samples (``mc_seeds`` seeds × speeds × readings); empty
        without ``side_tables``.
    estimators : KalmanComparison or None
        :func:`kalman.compare`: the paper's observer, the Kalman filter with a track shaping
        filter and its RTS smoother on the Monte Carlo records at several noise levels; None
        without ``side_tables``.
    """

    vehicle: sw.SingleWheelset | None = None
    A: np.ndarray | None = None
    B: np.ndarray | None = None
    observer: roo.ReducedOrderObserver | None = None
    error_poles_per_s: np.ndarray | None = None
    runs: dict = field(default_factory=dict)
    speed_sweep: pd.DataFrame = field(default_factory=pd.DataFrame)
    noise_sweep: pd.DataFrame = field(default_factory=pd.DataFrame)
    plant_comparison: pd.DataFrame = field(default_factory=pd.DataFrame)
    monte_carlo: pd.DataFrame = field(default_factory=pd.DataFrame)
    estimators: kalman.KalmanComparison | None = None


def _rms(x, axis=0):
    return np.sqrt(np.mean(x**2, axis=axis))


def _side_tables(vehicle, observers, params, distance_m, profile_m, progress):
    """The noise-sensitivity table (first speed, the ``observer_form`` observer at each of
    :data:`NOISE_SWEEP_FRACTIONS`, noise draws salted 1) and the linear-vs-Hertz table
    (noise-free sensors, FOH observer, every speed of ``speeds_kmh``, draws salted 2), each
    simulated as one batch (one plant run per table and plant)."""
    dt, e0, seed = params["dt_s"], params["initial_error_m"], params["seed"]

    def inputs(speed, salt):
        t_s, q = track.wheelset_inputs(distance_m, profile_m, speed / 3.6, [0.0], dt,
                                       params["duration_s"])
        ny, nq = evidence.noise_draws(seed, speed, len(t_s), salt)
        return t_s, q[:, 0], ny, nq

    def errors(observer, y, q, q_meas, z_w, force, window):
        x2 = np.column_stack([np.zeros(q.shape[1]), q[0] + e0])
        z_est = evidence._observer_batch(observer, y, q_meas, x2)
        f_est = sw.dynamic_contact_force_N(vehicle, z_est, q_meas, "linear")
        return _rms((f_est - force)[window]), _rms((z_est - z_w)[window])

    speed, fractions = params["speeds_kmh"][0], np.array(NOISE_SWEEP_FRACTIONS)
    t_s, q, ny, nq = inputs(speed, (1,))
    y, z_w = evidence._plant_batch(vehicle, params["plant"], dt, q[:, None])
    force = sw.dynamic_contact_force_N(vehicle, z_w, q[:, None], params["plant"])
    window = t_s >= params["error_window_start_s"]
    y_meas = y + ny[:, None] * fractions[:, None] * _rms(y)               # (K, levels, 2)
    q_meas = np.repeat((q + nq * params["track_noise_fraction"] * _rms(q))[:, None],
                       len(fractions), axis=1)
    force_error, z_error = errors(observers[params["observer_form"]], y_meas,
                                  np.repeat(q[:, None], len(fractions), axis=1), q_meas,
                                  z_w, force, window)
    noise_rows = [{"noise_fraction": f, "speed_kmh": speed,
                   "force_relative_rms_error": force_error[i] / _rms(force[window])[0],
                   "displacement_rms_error_m": z_error[i]} for i, f in enumerate(fractions)]
    speeds = params["speeds_kmh"]
    columns = [inputs(v, (2,)) for v in speeds]
    q = np.column_stack([c[1] for c in columns])
    q_meas = q + np.column_stack([c[3] for c in columns]) * params["track_noise_fraction"] * _rms(q)
    plant_rows = []
    for plant in ("linear", "hertz"):                      # cost of linearising the contact
        progress(0.55, f"{plant} plant, noise-free")
        y, z_w = evidence._plant_batch(vehicle, plant, dt, q)
        force = sw.dynamic_contact_force_N(vehicle, z_w, q, plant)
        force_error, _ = errors(observers["foh"], y, q, q_meas, z_w, force, window)
        lost = np.mean(force <= -vehicle.contacts * vehicle.static_wheel_load_N, axis=0)
        plant_rows += [{"speed_kmh": v, "plant": plant, "force_rms_N": _rms(force[window])[i],
                        "force_rms_error_N_foh_observer": force_error[i],
                        "contact_lost_fraction": lost[i]} for i, v in enumerate(speeds)]
    plant_rows.sort(key=lambda r: (speeds.index(r["speed_kmh"]), r["plant"] != "linear"))
    return pd.DataFrame(noise_rows), pd.DataFrame(plant_rows)


def run(*, quick: bool = False, progress=None, **params) -> ReducedOrderObserverResult:
    """Run the chapter; ``params`` are the resolved parameters of :data:`SPEC`.

    Single runs of seed ``seed`` (reading ``p0_basis``) give the illustrations and their metrics;
    with ``side_tables`` the run adds the side tables and the claims' evidence: the Monte Carlo
    metrics (``mc_*``, every reading), the deterministic structure metrics (``rank_*`` and
    ``pole_placement_*``) and the estimator comparison (:func:`kalman.compare`, reading
    ``p0_basis``).
    ``quick`` is not read: ``params`` already hold the quick sizes.
    """
    validate(params)
    progress = progress or (lambda fraction, message: None)
    started = time.perf_counter()
    vehicle = sw.load_parameters(p0_basis=params["p0_basis"])
    A, B = sw.state_space(vehicle)
    observers = design_observers(A, B, params)
    form = params["observer_form"]
    other = "foh" if form == "paper" else "paper"
    all_speeds = evidence.all_speeds(params)
    distance_m, profile_m = evidence.profile(params, params["seed"])
    runs = {}
    for i, speed in enumerate(all_speeds):
        progress(0.5 * i / len(all_speeds), f"{speed:g} km/h")
        runs[speed] = simulate_speed(vehicle, observers, params, distance_m, profile_m, speed)
    noise_sweep, plant_comparison = _side_tables(vehicle, observers, params, distance_m, profile_m,
                                                 progress) if params["side_tables"] else \
        (pd.DataFrame(), pd.DataFrame())

    metrics, columns = {}, {"t_s": runs[params["speeds_kmh"][0]].record.t_s}
    for speed in params["speeds_kmh"]:
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
    mc, estimators = pd.DataFrame(), None
    timings = {"single_runs_s": time.perf_counter() - started}
    if params["side_tables"]:
        mc_started = time.perf_counter()
        mc = evidence.monte_carlo(params, lambda f, m: progress(0.6 + 0.2 * f, m))
        metrics.update(evidence.legacy_band_metrics(mc, params))
        metrics.update(evidence.evidence_metrics(mc, params))
        metrics.update(evidence.structure_metrics(params))
        timings["monte_carlo_s"] = time.perf_counter() - mc_started
        kalman_started = time.perf_counter()
        estimators = kalman.compare(params, lambda f, m: progress(0.8 + 0.2 * f, m))
        metrics.update(kalman.comparison_metrics(estimators, params))
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
    } for s in params["sweep_speeds_kmh"]])
    observer = roo.design(A, B, 2, params["observer_poles"])
    timings["run_s"] = time.perf_counter() - started
    return ReducedOrderObserverResult(
        metrics=metrics, timings=timings, timeseries=pd.DataFrame(columns),
        extra_tables={"speed_sweep": sweep, "monte_carlo_samples": mc,
                      "estimator_samples": estimators.samples}
        if params["side_tables"] else {"speed_sweep": sweep},
        vehicle=vehicle, A=A, B=B, observer=observer,
        error_poles_per_s=np.linalg.eigvals(observer.F), runs=runs, speed_sweep=sweep,
        noise_sweep=noise_sweep, plant_comparison=plant_comparison, monte_carlo=mc,
        estimators=estimators)
