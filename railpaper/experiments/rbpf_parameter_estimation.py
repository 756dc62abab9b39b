"""Chapter "rbpf-parameter-estimation": paper 003's RBPF versus an augmented-state EKF.

Part 1 — Eq. (18) toy: the RBPF exactly as the paper's Steps 1–2.6 (``scheme="paper"``, prior
uniform on the initial condition ± ``toy_prior_halfwidth``) and an augmented-state EKF from the
paper's initial conditions 1 = (0, 0, 0, 0) and 2 = (−0.26, 1, 0.24, −0.5), over several seeds.

Part 2 — the lateral vehicle (Eqs. 1–9, :mod:`railpaper.models.lateral_16state`): truth simulated
at ``dt_truth_s`` from an alignment profile of ``spectrum``, sampled at ``dt_s`` with stated sensor
noise; the RBPF over θ = (Csy, λ, Kpy, Ksy, Csaly) with the paper's literal scheme and with our
working scheme (tempering, ESS-triggered resampling, Liu–West move only after resampling, on
normalised log-parameters); the Kalman-likelihood CRLB; the augmented 21-state EKF from
``ekf_guesses`` initial guesses.  ``measurements_csv`` runs the working scheme on a user's file.
``lateral=False`` skips Part 2 (Monte Carlo samples of the toy, see the notebook's sweep).
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np
import pandas as pd

from railpaper import track
from railpaper.data import DATA_DIR, load_quantities
from railpaper.estimators.crlb import crlb_std, fisher_information
from railpaper.estimators.ekf import eq18_model, run_augmented_ekf
from railpaper.estimators.rbpf import run_rbpf
from railpaper.experiments.base import (ChapterResult, ChapterSpec, Parameter, ParameterError,
                                        check_sample_time, no_progress)
from railpaper.models import lateral_16state as L
from railpaper.models.linear_toys import EQ18_G, eq18_system, simulate_eq18
from railpaper.settling import settled_index

P = Parameter
SPEC = ChapterSpec(
    name="rbpf-parameter-estimation",
    title="RBPF versus EKF for suspension parameters of a high-speed vehicle",
    paper="003_106973ea68498aa8.txt",
    notebook="rbpf_parameter_estimation.ipynb",
    quick_sizes="toy: 300 steps, 300 particles, 6 seeds; lateral: 1000 steps, 150 particles, "
                "2 seeds (working), 1 seed (paper scheme), EKF 10 guesses x 1000 steps",
    notebook_requires={"lateral": True},
    parameters=[
        P("seed", 0, "int", "seed of the main run (seed + i for the i-th replicate)", minimum=0),
        P("toy_x1", -0.4, "float", "true x1 of Eq. (18), 1"),
        P("toy_x2", 0.5, "float", "true x2 of Eq. (18), 1"),
        P("toy_x3", 0.5, "float", "true x3 of Eq. (18), 1"),
        P("toy_x4", 1.0, "float", "true x4 of Eq. (18), 1"),
        P("toy_noise_var", 0.1, "float", "variance of W and V in Eq. (18), 1", positive=True),
        P("toy_steps", 500, "int", "measurements of the toy record", quick=300, minimum=10),
        P("toy_particles", 500, "int", "RBPF particles (toy)", quick=300, minimum=2),
        P("toy_seeds", 20, "int", "toy records for the divergence/bias statistics", quick=6,
          minimum=1),
        P("toy_prior_halfwidth", 2.0, "float",
          "RBPF prior: uniform on initial condition +- this, per parameter, 1", positive=True),
        P("toy_tempering_steps", 50, "int", "toy working-scheme RBPF: tempering steps",
          minimum=0),
        P("toy_ekf_q_theta", 1e-6, "float", "EKF random-walk variance of each x_j per step, 1",
          positive=True),
        P("toy_bias_tol", 0.2, "float", "toy: final |error| above this in any x_j = biased, 1",
          positive=True),
        P("speed_kmh", 300.0, "float", "vehicle speed, km/h", positive=True),
        P("n_steps", 3000, "int", "filter steps of the lateral run (at dt_s)", quick=1000,
          minimum=400),
        P("dt_s", 0.001, "float", "filter sample time, s", positive=True),
        P("truth_substeps", 10, "int", "truth steps per filter step (truth dt = dt_s / this)",
          minimum=1),
        P("spectrum", "german-low", "str", "alignment irregularity spectrum (railpaper.track)"),
        P("wavelength_min_m", 1.0, "float", "shortest irregularity wavelength, m", positive=True),
        P("wavelength_max_m", 100.0, "float", "longest irregularity wavelength, m", positive=True),
        P("noise_acc_wheelset_mps2", 0.1, "float", "wheelset accelerometer noise std, m/s^2",
          positive=True),
        P("noise_acc_bogie_mps2", 0.1, "float", "bogie accelerometer noise std, m/s^2",
          positive=True),
        P("noise_acc_body_mps2", 0.01, "float", "car-body accelerometer noise std, m/s^2",
          positive=True),
        P("noise_yawrate_radps", 0.001, "float", "bogie yaw-rate gyro noise std, rad/s",
          positive=True),
        P("n_particles", 200, "int", "RBPF particles (lateral)", quick=150, minimum=2),
        P("prior_low", 0.5, "float", "prior box lower edge, fraction of the true value",
          positive=True),
        P("prior_high", 1.7, "float", "prior box upper edge, fraction of the true value",
          positive=True),
        P("paper_delta", 0.98, "float", "Liu-West delta of the paper scheme, 1", positive=True),
        P("working_delta", 0.9, "float", "Liu-West delta of the working scheme, 1",
          positive=True),
        P("tempering_steps", 300, "int", "working scheme: likelihood tempering steps", minimum=0),
        P("ess_fraction", 0.8, "float", "working scheme: resample when ESS < this N, 1",
          positive=True),
        P("n_seeds", 4, "int", "lateral records filtered by the working scheme", quick=2,
          minimum=1),
        P("n_seeds_paper", 2, "int", "lateral records filtered by the paper scheme", quick=1,
          minimum=1),
        P("ekf_guesses", 10, "int", "initial parameter guesses of the lateral EKF", minimum=1),
        P("ekf_steps", 1500, "int", "steps of each lateral EKF run (<= n_steps)", quick=400,
          minimum=10),
        P("measurements_csv", "", "str",
          "user CSV (t_s, acc_w1_mps2, acc_w2_mps2, acc_b_mps2, acc_bd_mps2, yawrate_b_radps"
          "[, ydot_t1_mps, ydot_t2_mps]) instead of simulated data; empty = simulate",
          path=True),
        P("lateral", True, "bool", "run Part 2, the lateral vehicle (Monte Carlo samples of the "
          "toy switch it off; the notebook's main run needs it)"),
        P("mc_seeds", 12, "int", "Monte Carlo toy records of the notebook's sweep (one per seed, "
          "after the main run's toy_seeds records)", quick=4, minimum=2),
    ],
)

TOY_INITS = {1: np.zeros(4), 2: np.array([-0.26, 1.0, 0.24, -0.5])}
WITHIN = 0.05


def vehicle(params_path: Path | None = None) -> tuple[dict, np.ndarray]:
    """Fixed quantities and true θ from ``data/rbpf-parameter-estimation/parameters.toml``."""
    q = load_quantities(params_path or DATA_DIR / SPEC.name / "parameters.toml",
                        L.FIXED_KEYS + L.PARAM_NAMES)
    return {k: q[k].value for k in L.FIXED_KEYS}, np.array([q[k].value for k in L.PARAM_NAMES])


def steps_to_within(norm: np.ndarray, tol: float = WITHIN) -> np.ndarray:
    """Per column: first step (1-based) after which |norm − 1| <= tol to the end; -1 if never."""
    ok = np.abs(np.atleast_2d(norm.T).T - 1.0) <= tol
    index = np.array([settled_index(column) for column in ok.T])
    return np.where(index < 0, -1, index + 1)


# ----------------------------------------------------------------------------- Part 1: toy
def run_toy(p: dict) -> dict:
    """Eq. (18): RBPF (paper scheme) and augmented EKF from both initial conditions, all seeds."""
    truth = np.array([p["toy_x1"], p["toy_x2"], p["toy_x3"], p["toy_x4"]])
    v = p["toy_noise_var"]
    system = eq18_system(v, v)
    Q, R = v * EQ18_G @ EQ18_G.T, np.array([[v]])
    series, stats = {}, []
    for i in range(p["toy_seeds"]):
        rng = np.random.default_rng(p["seed"] + i)
        sim = simulate_eq18(truth, v, v, p["toy_steps"], rng)
        for ic, init in TOY_INITS.items():
            hw = p["toy_prior_halfwidth"]
            theta0 = rng.uniform(init - hw, init + hw, (p["toy_particles"], 4))
            rb = run_rbpf(system, sim.y, theta0, np.zeros(2), np.eye(2), rng, u=sim.u,
                          scheme="paper", delta=p["paper_delta"])
            rw = run_rbpf(system, sim.y, theta0, np.zeros(2), np.eye(2), rng, u=sim.u,
                          scheme="working", delta=p["working_delta"],
                          ess_fraction=p["ess_fraction"],
                          tempering_steps=p["toy_tempering_steps"])
            ek = run_augmented_ekf(eq18_model, sim.y, init, np.zeros(2), np.eye(2), 1.0, Q, R,
                                   p["toy_ekf_q_theta"], u=sim.u, divergence_bound=1e3)
            err_rb = np.abs(rb.theta_mean[-1] - truth)
            err_ek = np.abs(ek.theta[-1] - truth)
            stats.append(dict(seed=p["seed"] + i, init=ic, rbpf_err_max=err_rb.max(),
                              rbpf_working_err_max=np.abs(rw.theta_mean[-1] - truth).max(),
                              ekf_err_max=err_ek.max(), ekf_diverged=ek.diverged,
                              ekf_biased=ek.diverged or err_ek.max() > p["toy_bias_tol"]))
            if i == 0:
                series[f"rbpf_init{ic}"] = rb.theta_mean
                series[f"rbpfworking_init{ic}"] = rw.theta_mean
                series[f"ekf_init{ic}"] = ek.theta
    table = pd.DataFrame({"step": np.arange(1, p["toy_steps"] + 1)})
    for key, arr in series.items():
        for j in range(4):
            table[f"x{j + 1}_{key}"] = arr[:, j]
    return dict(truth=truth, table=table, stats=pd.DataFrame(stats))


# ----------------------------------------------------------------------------- Part 2: lateral
def noise_std(p: dict) -> np.ndarray:
    return np.array([p["noise_acc_wheelset_mps2"]] * 2 + [p["noise_acc_bogie_mps2"],
                    p["noise_acc_body_mps2"], p["noise_yawrate_radps"]])


def simulate_lateral(p: dict, fixed: dict, theta: np.ndarray, seed: int) -> dict:
    """Truth at dt_s / truth_substeps, measurements at dt_s (+ noise), filter inputs u_k."""
    v = p["speed_kmh"] / 3.6
    dtf = p["dt_s"] / p["truth_substeps"]
    dur = p["n_steps"] * p["dt_s"]
    length = max(v * dur + 2 * fixed["a"] + 10.0, 1.05 * p["wavelength_max_m"])
    dx = min(0.05, p["wavelength_min_m"] / 2)
    s, z = track.synthesize_profile(p["spectrum"], "alignment", length, dx, seed=seed,
                                    wavelength_min_m=p["wavelength_min_m"],
                                    wavelength_max_m=p["wavelength_max_m"])
    _, _, dq = track.wheelset_inputs(s, z, v, [0.0, 2 * fixed["a"]], dtf, dur, derivative=True)
    x = L.simulate_truth(fixed, theta, v, dtf, dq[:-1])
    sub = p["truth_substeps"]
    H = L.measurement_matrix(L.build_A_direct(fixed, theta, v))
    rng = np.random.default_rng([seed, 7])
    y = x[sub::sub][:p["n_steps"]] @ H.T
    y = y + rng.standard_normal(y.shape) * noise_std(p)
    u = dq[0:-1:sub][:p["n_steps"]]                       # u_k = ẏt(t_{k-1}), held over the step
    du = np.diff(dq[::sub], axis=0)
    return dict(y=y, u=u, du_var=du.var(axis=0), dq_var=dq.var(axis=0))


def filter_noise(fixed, theta, p, input_var) -> tuple[np.ndarray, np.ndarray]:
    """Q = Γ diag(input_var) Γᵀ (+1e-14 I) at the nominal θ, R = diag(noise²)."""
    _, G = L.zoh_batch(L.build_A_direct(fixed, theta, p["speed_kmh"] / 3.6)[None],
                       L.input_matrix(), p["dt_s"])
    Q = G[0] @ np.diag(input_var) @ G[0].T + 1e-14 * np.eye(L.N_STATES)
    return Q, np.diag(noise_std(p) ** 2)


def run_lateral_rbpf(p, fixed, theta, data, seed, scheme) -> np.ndarray:
    """Normalised estimates θ̂/θ (K, 5) of one RBPF run."""
    Q, R = filter_noise(fixed, theta, p, data["du_var"])
    system = L.lateral_system(fixed, p["speed_kmh"] / 3.6, p["dt_s"], Q, R)
    rng = np.random.default_rng([seed, 11])
    theta0 = theta * rng.uniform(p["prior_low"], p["prior_high"], (p["n_particles"], 5))
    opts = (dict(scheme="paper", delta=p["paper_delta"]) if scheme == "paper" else
            dict(scheme="working", delta=p["working_delta"], ess_fraction=p["ess_fraction"],
                 tempering_steps=p["tempering_steps"], log_mask=np.ones(5, bool)))
    run = run_rbpf(system, data["y"], theta0, np.zeros(L.N_STATES), 1e-10 * np.eye(L.N_STATES),
                   rng, u=data["u"], **opts)
    return run.theta_mean / theta


def lateral_crlb(p, fixed, theta, data) -> dict:
    """Relative CRLB after 350 and n_steps steps, input known / unknown (process noise)."""
    v = p["speed_kmh"] / 3.6
    out = {}
    for label, var, u in (("known", data["du_var"], data["u"]), ("unknown", data["dq_var"], None)):
        Q, R = filter_noise(fixed, theta, p, var)
        info = fisher_information(L.lateral_system(fixed, v, p["dt_s"], Q, R), theta, data["y"],
                                  np.zeros(L.N_STATES), 1e-10 * np.eye(L.N_STATES), u,
                                  checkpoints=(350, p["n_steps"]))
        for c, I in info.items():
            out[(label, c)] = crlb_std(I) / theta
    return out


def lateral_ekf(p, fixed, theta, data, seed) -> list[np.ndarray]:
    """Normalised EKF estimates (K, 5) from ``ekf_guesses`` guesses U(prior box) x θ."""
    Q, R = filter_noise(fixed, theta, p, data["du_var"])
    model = L.ekf_model(fixed, p["speed_kmh"] / 3.6, p["dt_s"])
    rng = np.random.default_rng([seed, 13])
    runs = []
    for _ in range(p["ekf_guesses"]):
        guess = theta * rng.uniform(p["prior_low"], p["prior_high"], 5)
        K = min(p["ekf_steps"], p["n_steps"])
        r = run_augmented_ekf(model, data["y"][:K], guess, np.zeros(L.N_STATES),
                              1e-10 * np.eye(L.N_STATES), (0.3 * theta) ** 2, Q, R,
                              (1e-4 * theta) ** 2, u=data["u"][:K], divergence_bound=1e12)
        runs.append(r.theta / theta if not r.diverged else np.full_like(r.theta, np.nan))
    return runs


CSV_INPUT = ("ydot_t1_mps", "ydot_t2_mps")


def read_measurements(path: str, p: dict) -> dict:
    """A user's record: columns ``t_s`` and :data:`L.CHANNELS` (SI units), optionally the track
    lateral velocities ``ydot_t1_mps, ydot_t2_mps`` (m/s); uniform time step = ``dt_s``."""
    try:
        frame = pd.read_csv(path)
    except (OSError, ValueError) as exc:
        raise ParameterError(f"measurements_csv: cannot read {path!r}: {exc}") from None
    missing = [c for c in ("t_s",) + L.CHANNELS if c not in frame.columns]
    if missing:
        raise ParameterError(f"measurements_csv: missing column(s) {missing}; need t_s, "
                             f"{', '.join(L.CHANNELS)} and optionally {', '.join(CSV_INPUT)}")
    cols = ["t_s", *L.CHANNELS, *[c for c in CSV_INPUT if c in frame.columns]]
    arr = frame[cols].apply(pd.to_numeric, errors="coerce").to_numpy(float)
    if len(arr) < 10:
        raise ParameterError(f"measurements_csv: need >= 10 rows, got {len(arr)}")
    bad = ~np.isfinite(arr)
    if bad.any():
        row, col = np.argwhere(bad)[0]
        raise ParameterError(f"measurements_csv: column {cols[col]} has a NaN, infinite or "
                             f"non-numeric value in data row {row + 1}")
    dt = np.diff(arr[:, 0])
    if np.any(dt <= 0):
        raise ParameterError(f"measurements_csv: t_s is not increasing (data row "
                             f"{int(np.argmax(dt <= 0)) + 2})")
    if np.any(np.abs(dt - p["dt_s"]) > 1e-6 * p["dt_s"] + 1e-9):
        raise ParameterError(f"measurements_csv: t_s must step uniformly by dt_s = {p['dt_s']} s")
    has_u = all(c in frame.columns for c in CSV_INPUT)
    u = arr[:, 6:8] if has_u else None
    y = arr[:, 1:6]
    u_var = np.var(np.diff(u, axis=0), axis=0) if has_u else np.full(2, 0.04 ** 2)
    return dict(y=y, u=None if u is None else np.vstack([u[:1], u[:-1]]), du_var=u_var,
                dq_var=u_var)


def validate(p: dict) -> None:
    """Refuse non-physical or inconsistent resolved parameters with one line, before any work."""
    if not p["prior_low"] < 1.0 < p["prior_high"]:
        raise ParameterError("prior_low < 1 < prior_high is needed (the box must hold the truth)")
    if not 1 / 3 < p["paper_delta"] <= 1 or not 1 / 3 < p["working_delta"] <= 1:
        raise ParameterError("Liu-West delta must be in (1/3, 1]")
    if p["wavelength_min_m"] < 2 * p["speed_kmh"] / 3.6 * p["dt_s"]:
        raise ParameterError("wavelength_min_m is shorter than the filter's Nyquist wavelength "
                             "2 V dt_s")
    if p["spectrum"] not in track.SPECTRA:
        raise ParameterError(f"parameter 'spectrum': unknown spectrum {p['spectrum']!r}; "
                             f"one of {', '.join(track.SPECTRA)}")
    if p["ess_fraction"] > 1:
        raise ParameterError("ess_fraction must be <= 1")
    fixed, theta = vehicle()
    check_sample_time("dt_s", p["dt_s"], L.build_A_direct(fixed, theta, p["speed_kmh"] / 3.6),
                      f"the lateral model at {p['speed_kmh']:g} km/h")
    if p["measurements_csv"]:
        read_measurements(p["measurements_csv"], p)


def run_lateral(p: dict, metrics: dict, timings: dict, data_out: dict, progress
                ) -> pd.DataFrame:
    """Part 2 (critical speed, RBPF, CRLB, EKF) into the dicts; returns the time series."""
    fixed, theta = vehicle()
    v = p["speed_kmh"] / 3.6
    # critical speed, both readings of "half"
    speeds = np.arange(10.0, 200.01, 2.0)
    halved = dict(fixed, mw=fixed["mw"] / 2, mb=fixed["mb"] / 2)
    doubled = dict(fixed, mw=fixed["mw"] * 2, mb=fixed["mb"] * 2)
    curves = {}
    for key, fx in (("chosen", fixed), ("all_halved", halved), ("wheelset_bogie_doubled", doubled)):
        re, vc = L.critical_speed(fx, theta, speeds)
        curves[key] = re
        metrics[f"critical_speed_kmh_{key}"] = vc * 3.6 if vc > 0 else -1
    metrics["least_damped_real_at_speed_per_s"] = L.least_damped(L.build_A_direct(fixed, theta,
                                                                                  v))[0]
    data_out["critical"] = pd.DataFrame({"speed_kmh": speeds * 3.6, **curves})
    # Part 2: data
    user = bool(p["measurements_csv"])
    records = ([read_measurements(p["measurements_csv"], p)] if user else
               [simulate_lateral(p, fixed, theta, p["seed"] + i)
                for i in range(max(p["n_seeds"], p["n_seeds_paper"]))])
    if user:
        p = dict(p, n_steps=len(records[0]["y"]), n_seeds=1, n_seeds_paper=1)
    runs = {"working": [], "paper": []}
    for scheme, count in (("working", p["n_seeds"]), ("paper", p["n_seeds_paper"])):
        t0 = time.perf_counter()
        for i in range(count):
            progress(0.1 + 0.5 * i / count, f"RBPF {scheme} scheme, record {i}")
            runs[scheme].append(run_lateral_rbpf(p, fixed, theta, records[i], p["seed"] + i,
                                                 scheme))
        timings[f"rbpf_{scheme}_per_run_s"] = (time.perf_counter() - t0) / count
    for scheme, suffix in (("working", ""), ("paper", "_paper_scheme")):
        norm = runs[scheme][0]
        steps = steps_to_within(norm)
        metrics[f"steps_to_within_5pct_all{suffix}"] = (int(steps.max()) if np.all(steps > 0)
                                                        else -1)
        for j, name in enumerate(L.PARAM_NAMES):
            metrics[f"steps_to_within_5pct_{name}{suffix}"] = int(steps[j])
            metrics[f"final_relative_error_{name}{suffix}"] = float(norm[-1, j] - 1)
        finals = np.array([r[-1] - 1 for r in runs[scheme]])
        metrics[f"seeds_all_within_5pct_fraction{suffix}"] = float(
            np.mean(np.all(np.abs(finals) <= WITHIN, axis=1)))
        metrics[f"final_abs_relative_error_max_over_seeds{suffix}"] = float(np.abs(finals).max())
    data_out["runs"] = runs
    # CRLB and EKF (simulated data only: they need the truth)
    if not user:
        progress(0.7, "CRLB")
        t0 = time.perf_counter()
        cr = lateral_crlb(p, fixed, theta, records[0])
        timings["crlb_s"] = time.perf_counter() - t0
        rows = []
        for j, name in enumerate(L.PARAM_NAMES):
            metrics[f"crlb_rel_350_{name}"] = float(cr[("known", 350)][j])
            metrics[f"crlb_rel_final_{name}"] = float(cr[("known", p["n_steps"])][j])
            metrics[f"crlb_rel_350_unknown_input_{name}"] = float(cr[("unknown", 350)][j])
            rows.append(dict(parameter=name, **{f"{a}_{c}": cr[(a, c)][j] for a, c in cr}))
        data_out["crlb"] = pd.DataFrame(rows)
        progress(0.8, "EKF")
        t0 = time.perf_counter()
        ekf = lateral_ekf(p, fixed, theta, records[0], p["seed"])
        timings["ekf_lateral_s"] = time.perf_counter() - t0
        conv = [bool(np.all(np.isfinite(r[-1])) and np.all(np.abs(r[-1] - 1) <= WITHIN))
                for r in ekf]
        metrics["ekf_lateral_converged_count"] = int(sum(conv))
        if p["ekf_guesses"] == 10:
            metrics["ekf_lateral_converged_of_10"] = int(sum(conv))
        data_out["ekf"] = ekf
    main = runs["working"][0]
    paper, names = runs["paper"][0], list(enumerate(L.PARAM_NAMES))
    return pd.DataFrame({"t_s": np.arange(1, len(main) + 1) * p["dt_s"],
                         **{f"{name}_norm": main[:, j] for j, name in names},
                         **{f"{name}_norm_paper_scheme": paper[:, j] for j, name in names}})


def run(*, quick: bool = False, progress=None, **p) -> ChapterResult:
    """The whole chapter for resolved parameters ``p`` (see :data:`SPEC`)."""
    progress = progress or no_progress
    validate(p)
    metrics, timings, data_out = {}, {}, {}
    # Part 1
    progress(0.05, "toy")
    t0 = time.perf_counter()
    toy = run_toy(p)
    timings["toy_s"] = time.perf_counter() - t0
    st = toy["stats"]
    for ic in (1, 2):
        main = st[(st.seed == p["seed"]) & (st.init == ic)].iloc[0]
        sub = st[st.init == ic]
        metrics[f"toy_ekf_diverged_init{ic}"] = bool(main.ekf_diverged)
        metrics[f"toy_ekf_final_abs_error_max_init{ic}"] = float(main.ekf_err_max)
        metrics[f"toy_final_abs_error_max_rbpf_init{ic}"] = float(main.rbpf_err_max)
        metrics[f"toy_ekf_diverged_fraction_init{ic}"] = float(sub.ekf_diverged.mean())
        metrics[f"toy_ekf_biased_fraction_init{ic}"] = float(sub.ekf_biased.mean())
        metrics[f"toy_rbpf_error_median_init{ic}"] = float(sub.rbpf_err_max.median())
        metrics[f"toy_rbpf_error_p90_init{ic}"] = float(sub.rbpf_err_max.quantile(0.9))
        metrics[f"toy_rbpf_working_error_median_init{ic}"] = float(
            sub.rbpf_working_err_max.median())
        metrics[f"toy_rbpf_working_error_p90_init{ic}"] = float(
            sub.rbpf_working_err_max.quantile(0.9))
    data_out["toy_truth"], data_out["toy_stats"] = toy["truth"], st
    ts = run_lateral(p, metrics, timings, data_out, progress) if p["lateral"] else None
    progress(1.0, "done")
    return ChapterResult(metrics=metrics, timings=timings, timeseries=ts,
                         extra_tables={"toy_timeseries": toy["table"]}, data=data_out)
