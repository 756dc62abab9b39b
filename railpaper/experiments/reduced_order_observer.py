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
evidence of :mod:`railpaper.experiments.reduced_order_observer_evidence` (``mc_seeds`` seeds, both
readings of P0), whose metrics ``data/reduced-order-observer/claims.toml`` reads.
"""

from __future__ import annotations

import time

import numpy as np
import pandas as pd

from railpaper import track
from railpaper.discretise import foh, simulate_foh
from railpaper.estimators import reduced_order_observer as roo
from railpaper.experiments import reduced_order_observer_evidence as evidence
from railpaper.experiments.base import ChapterResult, ChapterSpec, Parameter, ParameterError
from railpaper.models import single_wheelset as sw
from railpaper.settling import settled_index

SPEC = ChapterSpec(
    name="reduced-order-observer",
    title="Reduced-order observer of wheel–rail force (paper 001)",
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
        Parameter("dt_s", 1e-4, "float", "time step of plant samples and observer, s (paper: 1e-4)",
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
                  "Monte Carlo seeds (seed, seed+1, …, < seed + 1000) behind every claim verdict",
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


def convergence_time_s(t_s: np.ndarray, error: np.ndarray, threshold: float) -> float:
    """First time after which ``|error| < threshold`` to the end; -1 if never."""
    index = settled_index(np.abs(error) < threshold)
    return -1.0 if index < 0 else float(t_s[index])


def _simulate_hertz(vehicle, t_s, q_m, x0, substeps=4):
    """RK4 with ``substeps`` per sample and q interpolated linearly (nonlinear Hertz plant)."""
    dt = (t_s[1] - t_s[0]) / substeps
    x = np.empty((len(t_s), 4))
    x[0] = x0
    state = np.array(x0, float)
    f = lambda s, q: sw.nonlinear_derivative(vehicle, s, q)  # noqa: E731
    for k in range(len(t_s) - 1):
        q0, q1 = q_m[k], q_m[k + 1]
        for j in range(substeps):
            qa, qm, qb = (q0 + (q1 - q0) * (j + c) / substeps for c in (0.0, 0.5, 1.0))
            k1 = f(state, qa)
            k2 = f(state + 0.5 * dt * k1, qm)
            k3 = f(state + 0.5 * dt * k2, qm)
            k4 = f(state + dt * k3, qb)
            state = state + dt / 6.0 * (k1 + 2 * k2 + 2 * k3 + k4)
        x[k + 1] = state
    return x


def design_observers(A, B, params) -> dict:
    """The paper's observer (12) discretised two ways: ``paper`` (ZOH) and ``foh``."""
    observer = roo.design(A, B, 2, params["observer_poles"])
    return {form: observer.discretise(params["dt_s"], "zoh" if form == "paper" else "foh")
            for form in ("paper", "foh")}


def simulate_speed(vehicle, observers, params, distance_m, profile_m, speed_kmh, salt=()) -> dict:
    """One run at one speed: truth, measurements, both observers' estimates, forces (SI units).

    The sensor noise draws are :func:`evidence.noise_draws` of ``(seed, speed, *salt)``.
    """
    dt, duration = params["dt_s"], params["duration_s"]
    t_s, q = track.wheelset_inputs(distance_m, profile_m, speed_kmh / 3.6, [0.0], dt, duration)
    q = q[:, 0]
    noise = evidence.noise_draws(params["seed"], speed_kmh, len(t_s), salt)
    A, B = sw.state_space(vehicle)
    x0 = np.array([0.0, q[0], 0.0, q[0]])                 # static equilibrium on q(0)
    if params["plant"] == "linear":
        x = simulate_foh(*foh(A, B, dt), q[:, None], x0)   # exact for q linear between samples
    else:
        x = _simulate_hertz(vehicle, t_s, q, x0)
    y = x[:, :2].copy()                                    # measured x1 = [ż_c, z_c]
    noise_y, noise_q = noise
    y += noise_y * params["noise_fraction"] * np.sqrt(np.mean(y**2, axis=0))
    q_meas = q + noise_q * params["track_noise_fraction"] * np.sqrt(np.mean(q**2))
    x2_initial = x[0, 2:] + np.array([0.0, params["initial_error_m"]])
    force_true = sw.dynamic_contact_force_N(vehicle, x[:, 3], q, params["plant"])
    threshold = params["convergence_fraction"] * np.sqrt(np.mean(x[:, 3] ** 2))
    window = t_s >= params["error_window_start_s"]
    error_free = np.empty((len(t_s), 2))                   # error dynamics alone: e[k+1] = Φ e[k]
    error_free[0] = x2_initial - x[0, 2:]
    for k in range(len(t_s) - 1):
        error_free[k + 1] = observers["paper"].Phi @ error_free[k]
    result = {"t_s": t_s, "q_m": q, "z_w_true_m": x[:, 3], "force_true_N": force_true,
              "z_w_rms_m": float(np.sqrt(np.mean(x[:, 3] ** 2))),
              "predicted_convergence_time_s": convergence_time_s(t_s, error_free[:, 1], threshold),
              "force_rms_N": float(np.sqrt(np.mean(force_true[window] ** 2))),
              "contact_lost_fraction": float(np.mean(
                  force_true <= -vehicle.contacts * vehicle.static_wheel_load_N))}
    for form, observer in observers.items():
        z_w_est = observer.run(y, q_meas[:, None], x2_initial)[:, 1]
        force_est = sw.dynamic_contact_force_N(vehicle, z_w_est, q_meas, "linear")
        error = z_w_est - x[:, 3]
        suffix = "" if form == params["observer_form"] else f"_{form}"
        result.update({
            f"z_w_est_m{suffix}": z_w_est, f"force_est_N{suffix}": force_est,
            f"convergence_time_s{suffix}": convergence_time_s(t_s, error, threshold),
            f"force_rms_error_N{suffix}": float(np.sqrt(np.mean((force_est - force_true)[window] ** 2))),
            f"displacement_rms_error_m{suffix}": float(np.sqrt(np.mean(error[window] ** 2))),
        })
    return result


def _label(speed_kmh: float) -> str:
    return f"{speed_kmh:g}kmh"


def run(*, quick: bool = False, progress=None, **params) -> ChapterResult:
    """Run the chapter; ``params`` are the resolved parameters of :data:`SPEC`.

    Single runs of seed ``seed`` (reading ``p0_basis``) give the illustrations and their metrics;
    with ``side_tables`` the run adds the side tables and the claims' evidence: the Monte Carlo
    metrics (``mc_*``, every reading) and the deterministic structure metrics (``rank_*``, …).
    """
    validate(params)
    progress = progress or (lambda fraction, message: None)
    started = time.perf_counter()
    vehicle = sw.load_parameters(p0_basis=params["p0_basis"])
    A, B = sw.state_space(vehicle)
    observers = design_observers(A, B, params)
    other = "foh" if params["observer_form"] == "paper" else "paper"
    all_speeds = evidence.all_speeds(params)
    distance_m, profile_m = evidence.profile(params, params["seed"])
    runs = {}
    for i, speed in enumerate(all_speeds):
        progress(0.5 * i / len(all_speeds), f"{speed:g} km/h")
        runs[speed] = simulate_speed(vehicle, observers, params, distance_m, profile_m, speed)
    noise_rows, plant_rows = [], []
    speed = params["speeds_kmh"][0]
    for fraction in NOISE_SWEEP_FRACTIONS if params["side_tables"] else ():
        r = simulate_speed(vehicle, observers, dict(params, noise_fraction=fraction),
                           distance_m, profile_m, speed, salt=(1,))
        noise_rows.append({"noise_fraction": fraction, "speed_kmh": speed,
                           "force_relative_rms_error": r["force_rms_error_N"] / r["force_rms_N"],
                           "displacement_rms_error_m": r["displacement_rms_error_m"]})
    for speed in params["speeds_kmh"] if params["side_tables"] else ():  # cost of linearising
        for plant in ("linear", "hertz"):
            progress(0.55, f"{plant} plant, noise-free, {speed:g} km/h")
            r = simulate_speed(vehicle, observers, dict(params, plant=plant, noise_fraction=0.0),
                               distance_m, profile_m, speed, salt=(2,))
            plant_rows.append({"speed_kmh": speed, "plant": plant, "force_rms_N": r["force_rms_N"],
                               "force_rms_error_N_foh_observer": r.get("force_rms_error_N_foh",
                                                                       r["force_rms_error_N"]),
                               "contact_lost_fraction": r["contact_lost_fraction"]})

    metrics, columns = {}, {"t_s": runs[params["speeds_kmh"][0]]["t_s"]}
    for speed in params["speeds_kmh"]:
        r, lab = runs[speed], _label(speed)
        metrics[f"convergence_time_s_{lab}"] = r["convergence_time_s"]
        metrics[f"force_rms_error_N_{lab}"] = r["force_rms_error_N"]
        metrics[f"force_relative_rms_error_{lab}"] = r["force_rms_error_N"] / r["force_rms_N"]
        metrics[f"displacement_rms_error_m_{lab}"] = r["displacement_rms_error_m"]
        columns[f"wheelset_displacement_true_m_{lab}"] = r["z_w_true_m"]
        columns[f"wheelset_displacement_est_m_{lab}"] = r["z_w_est_m"]
        columns[f"wheel_rail_force_true_N_{lab}"] = r["force_true_N"]
        columns[f"wheel_rail_force_est_N_{lab}"] = r["force_est_N"]
    mc = pd.DataFrame()
    timings = {"single_runs_s": time.perf_counter() - started}
    if params["side_tables"]:
        mc_started = time.perf_counter()
        mc = evidence.monte_carlo(params, lambda f, m: progress(0.6 + 0.4 * f, m))
        metrics.update(evidence.legacy_band_metrics(mc, params))
        metrics.update(evidence.evidence_metrics(mc, params))
        metrics.update(evidence.structure_metrics(params))
        timings["monte_carlo_s"] = time.perf_counter() - mc_started
    progress(1.0, "done")
    sweep = pd.DataFrame([{
        "speed_kmh": s, "convergence_time_s": runs[s]["convergence_time_s"],
        "force_rms_error_N": runs[s]["force_rms_error_N"], "force_rms_N": runs[s]["force_rms_N"],
        "displacement_rms_error_m": runs[s]["displacement_rms_error_m"],
        "contact_lost_fraction": runs[s]["contact_lost_fraction"],
        "z_w_rms_m": runs[s]["z_w_rms_m"],
        "predicted_convergence_time_s": runs[s]["predicted_convergence_time_s"],
        f"convergence_time_s_{other}": runs[s][f"convergence_time_s_{other}"],
        f"force_rms_error_N_{other}": runs[s][f"force_rms_error_N_{other}"],
    } for s in params["sweep_speeds_kmh"]])
    error_poles = np.linalg.eigvals(roo.design(A, B, 2, params["observer_poles"]).F)
    data = {"runs": runs, "sweep": sweep, "noise_sweep": pd.DataFrame(noise_rows),
            "plant_comparison": pd.DataFrame(plant_rows), "vehicle": vehicle, "A": A, "B": B,
            "observer_gain": observers["paper"].L, "error_poles": error_poles, "monte_carlo": mc}
    timings["run_s"] = time.perf_counter() - started
    return ChapterResult(metrics=metrics, timings=timings, timeseries=pd.DataFrame(columns),
                         extra_tables={"speed_sweep": sweep, "monte_carlo_samples": mc}
                         if params["side_tables"] else {"speed_sweep": sweep}, data=data)


def rank_table(metrics: dict) -> pd.DataFrame:
    """The ranks the paper quotes, per reading of P0: exact (rational arithmetic), numpy's
    floating-point rank of the Kalman matrix (default tolerance) and the PBH rank."""
    rows = []
    for name, what in (("Q0", "rank Q0 = [B AB A²B A³B] (paper: 4)"),
                       ("Q1", "rank Q1 = [C; CA; CA²; CA³] (paper: 4)"),
                       ("reduced", "rank [A12; A12·A22] (reduced pair, needs 2)")):
        for reading in evidence.READINGS:
            rows.append((what, f"P0 per {reading}", metrics[f"rank_{name}_exact_{reading}"],
                         metrics[f"rank_{name}_numpy_{reading}"],
                         metrics[f"rank_{name}_pbh_{reading}"]))
    return pd.DataFrame(rows, columns=["test", "reading", "exact rank", "numpy rank (default tol.)",
                                       "PBH rank"])
