"""Chapter ``partial-state-observer`` (paper 000): functional observer of wheelset vibration.

The whole computation of the chapter as a function of its parameters: build the 10-DOF vertical
model, test Darouach's existence conditions for three measurement sets, design the functional
observer of ``z = [z_w1 … z_w4]`` (the paper's, which needs the track input u = q, and the
``H B = 0`` variant, which does not) with a pole-region LMI, simulate the plant exactly on a US
FRA class-5 profile at several speeds, and compare with two baselines: ``ẑ = q`` and a
steady-state Kalman filter with a shaping filter for q (not told q).

Definitions used for the metrics (all from the run's own signals, wheelsets 1-4 pooled)
-----------------------------------------------------------------------------------------
* convergence time: first time after which ``|ẑ_i − z_i|`` stays below ``convergence_fraction``
  (5 %) of the RMS of the true ``z_i`` (over the run) for every wheelset i, to the end of the
  run; -1 if the error is above it at the last sample;
* max error after 1 s: ``max_{i, t ≥ 1 s} |ẑ_i − z_i|`` (m);
* mean relative error: mean over wheelsets of ``mean_{t ≥ 1 s} |ẑ_i − z_i| / RMS_{t ≥ 1 s}(z_i)``.
"""

from __future__ import annotations

import time

import numpy as np
import pandas as pd

from railpaper import track
from railpaper.discretise import foh, simulate_foh
from railpaper.estimators import functional_observer as fo
from railpaper.estimators import kalman_baseline as kb
from railpaper.experiments.base import ChapterResult, ChapterSpec, Parameter, ParameterError
from railpaper.experiments.partial_state_observer_claims import claims_table  # noqa: F401
from railpaper.models import vertical_10dof as v10
from railpaper.settling import settled_index

SPEC = ChapterSpec(
    name="partial-state-observer",
    title="Partial-state observer of wheel vibration (paper 000)",
    paper="000_2d1086b2834afcb9.txt",
    notebook="partial_state_observer.ipynb",
    quick_sizes="2 s simulated instead of 8 s; 3 Monte Carlo seeds instead of 10; "
                "α sweep over 3 values instead of 6",
    parameters=[
        Parameter("speeds_kmh", [60.0, 80.0, 120.0, 160.0], "list[float]",
                  "simulated speeds (paper: 60, 80, 120; Fig. 11 adds 160), km/h", positive=True),
        Parameter("duration_s", 8.0, "float", "simulated time per run (paper: 8 s), s",
                  quick=2.0, positive=True),
        Parameter("dt_s", 1e-3, "float", "sample time of sensors and observer (paper: 1 ms), s",
                  positive=True),
        Parameter("lead_in_s", 1.0, "float",
                  "plant runs this long before the observer starts (settled start), s", minimum=0.0),
        Parameter("noise_fraction", 0.005, "float",
                  "sensor noise σ as a fraction of each channel's RMS (paper: 0.5 %)", minimum=0.0),
        Parameter("alpha_per_s", 20.0, "float",
                  "pole region of the paper's observer: slowest decay rate α, 1/s", positive=True),
        Parameter("beta", 2.0, "float", "pole region α ≤ −Re λ ≤ β α: ratio β (> 1)",
                  positive=True),
        Parameter("hb_zero_alpha_per_s", 10.0, "float",
                  "pole region α of the H B = 0 variant (its poles are fixed at −K_p/C_p), 1/s",
                  positive=True),
        Parameter("alpha_sweep_per_s", [5.0, 10.0, 20.0, 40.0, 80.0, 160.0], "list[float]",
                  "values of α for the convergence-time sweep, 1/s",
                  quick=[10.0, 40.0, 160.0], positive=True),
        Parameter("initial_error_m", 0.005, "float",
                  "initial error of every wheelset-displacement estimate, m"),
        Parameter("convergence_fraction", 0.05, "float",
                  "convergence threshold as a fraction of the RMS of the true z_w", positive=True),
        Parameter("error_window_start_s", 1.0, "float",
                  "errors are measured from this time on (paper: after 1 s), s", minimum=0.0),
        Parameter("track_class", 5, "int", "US FRA track class (1-6) of the vertical profile",
                  minimum=1),
        Parameter("wavelength_min_m", 1.524, "float", "shortest wavelength of the profile, m",
                  positive=True),
        Parameter("wavelength_max_m", 304.8, "float", "longest wavelength of the profile, m",
                  positive=True),
        Parameter("n_seeds", 10, "int", "Monte Carlo runs (seeds seed, seed+1, …)", quick=3,
                  minimum=1),
        Parameter("seed", 0, "int", "seed of the default run (track profile and sensor noise)",
                  minimum=0),
    ],
)

MEASUREMENT = "both"          # the only set that passes Darouach's conditions (see existence)
PROFILE_DX_M = 0.05
ESTIMATORS = ("paper", "hb0", "kalman", "q")


def validate(p: dict) -> None:
    """Refuse non-physical or inconsistent resolved parameters with one line, before any work."""
    if p["beta"] <= 1.0:
        raise ParameterError(f"parameter 'beta' must be > 1 (a strip α ≤ −Re λ ≤ βα), got {p['beta']}")
    if not 1 <= p["track_class"] <= 6:
        raise ParameterError(f"parameter 'track_class' must be 1..6, got {p['track_class']}")
    if p["dt_s"] > 2e-3:
        raise ParameterError(f"parameter 'dt_s' = {p['dt_s']} s cannot resolve the 229 Hz "
                             "wheelset mode (use ≤ 2e-3 s)")
    if p["error_window_start_s"] >= p["duration_s"]:
        raise ParameterError("parameter 'error_window_start_s' must be shorter than 'duration_s'")
    if len(set(p["speeds_kmh"])) != len(p["speeds_kmh"]):
        raise ParameterError(f"parameter 'speeds_kmh' has repeated speeds: {p['speeds_kmh']}")
    if p["wavelength_min_m"] >= p["wavelength_max_m"] or p["wavelength_min_m"] < 2 * PROFILE_DX_M:
        raise ParameterError("need 0.1 m ≤ wavelength_min_m < wavelength_max_m")


def _label(speed_kmh: float) -> str:
    return f"{speed_kmh:g}kmh"


def existence_table(model: v10.Model) -> pd.DataFrame:
    """Darouach's conditions for z = [z_w1 … z_w4] with each measurement set."""
    rows = []
    for name in v10.MEASUREMENT_SETS:
        C = model.output_matrix(name)
        ex = fo.existence(model.A, C, model.L)
        rows.append({"measurement set": name, "outputs": C.shape[0],
                     "rank [CA; C; L]": ex["rank_CA_C_L"], "rank [LA; CA; C; L]": ex["rank_LA_CA_C_L"],
                     "condition 1": ex["condition1"],
                     "rank-drop points Re s ≥ 0": int(np.sum(ex["pencil_zeros"].real >= 0)),
                     "condition 2": ex["condition2"], "observer exists": ex["exists"]})
    return pd.DataFrame(rows)


def rank_claims(model: v10.Model) -> pd.DataFrame:
    """The ranks the paper quotes after Eq. (13) beside ours (C = its acceleration matrix).

    Controllability is tested by PBH on the scaled model: the Kalman matrix [B AB … A¹⁹B] of
    the unscaled model spans ~1e100 and its numerical rank is meaningless.
    """
    Ca, L = model.output_matrix("accelerations"), model.L
    sc = fo.scaling_for(model.A, model.output_matrix("both"), L)
    At, Bt, _, _ = sc.apply(model.A, model.B, model.output_matrix("both"), L)
    pbh = min(fo.numerical_rank(np.hstack([lam * np.eye(20) - At, Bt])) for lam in np.linalg.eigvals(At))
    kalman = int(np.linalg.matrix_rank(np.hstack([np.linalg.matrix_power(model.A, k) @ model.B
                                                  for k in range(20)])))
    rows = [("rank(Q0), controllability", 20, pbh,
             f"PBH on the scaled model; the unscaled Kalman matrix gives a numerical rank of {kalman}"),
            ("rank(C)", 20, fo.numerical_rank(Ca * sc.S[None, :]), "C is 6×20: its rank cannot exceed 6"),
            ("rank(L)", 4, fo.numerical_rank(L), ""),
            ("rank(C Lᵀ)", 10, fo.numerical_rank(Ca @ L.T), "C Lᵀ is 6×4: its rank cannot exceed 4")]
    return pd.DataFrame(rows, columns=["quantity", "paper", "ours", "note"])


def shaping_filter(spectrum: str, speed_mps: float, band_m: tuple[float, float]):
    """Second-order shaping filter fitted to the spectrum at speed V: ``S_t(ω) = S(ω/V)/V``.

    Returns the filter and the fitted (ω, S_t) samples (log-spaced over the band).
    """
    omega_m = np.logspace(np.log10(2 * np.pi / band_m[1]), np.log10(2 * np.pi / band_m[0]), 200)
    omega_t = omega_m * speed_mps
    S_t = track.psd(spectrum, "vertical", omega_m) / speed_mps
    variance = track.band_variance(spectrum, "vertical", *band_m)
    return kb.fit_shaping_filter(omega_t, S_t, variance), omega_t, S_t


def convergence_time_s(t_s: np.ndarray, error: np.ndarray, threshold: np.ndarray) -> float:
    """First time after which ``|error| < threshold`` (every column) to the end; -1 if never."""
    index = settled_index(np.all(np.abs(error) < threshold, axis=-1))
    return -1.0 if index < 0 else float(t_s[index])


def predicted_convergence_s(disc: fo.DiscreteFunctionalObserver, t_s, z_true, p) -> float:
    """Convergence time of the error dynamics alone, ``ε[k] = Φ^k ε[0]``, same threshold."""
    thr = p["convergence_fraction"] * np.sqrt(np.mean(z_true**2, axis=0))
    eps = np.empty((len(t_s), disc.Phi.shape[0]))
    eps[0] = p["initial_error_m"]
    for k in range(len(t_s) - 1):
        eps[k + 1] = disc.Phi @ eps[k]
    return convergence_time_s(t_s, eps, thr)


def error_metrics(t_s, z_true, z_est, p) -> dict:
    """Convergence time, max error and mean relative error after the window start."""
    err = z_est - z_true
    thr = p["convergence_fraction"] * np.sqrt(np.mean(z_true**2, axis=0))
    win = t_s >= p["error_window_start_s"]
    rms = np.sqrt(np.mean(z_true[win] ** 2, axis=0))
    return {"convergence_time_s": convergence_time_s(t_s, err, thr),
            "max_error_after_1s_m": float(np.abs(err[win]).max()),
            "mean_relative_error": float(np.mean(np.mean(np.abs(err[win]), axis=0) / rms))}


class _Context:
    """Everything that does not depend on the seed: model, observers, discretisations."""

    def __init__(self, p: dict):
        self.vehicle = v10.load_parameters()
        self.model = m = v10.build_model(self.vehicle)
        self.C = m.output_matrix(MEASUREMENT)
        self.plant = foh(m.A, m.B, p["dt_s"])
        try:
            self.paper = fo.design(m.A, m.B, self.C, m.L, p["alpha_per_s"], p["beta"])
        except fo.LMIInfeasible as exc:
            raise ParameterError(f"parameters 'alpha_per_s', 'beta': no observer with poles in "
                                 f"[{p['alpha_per_s']:g}, {p['beta'] * p['alpha_per_s']:g}] 1/s ({exc})") from None
        try:
            self.hb0 = fo.design(m.A, m.B, self.C, m.L, p["hb_zero_alpha_per_s"], p["beta"],
                                 hb_zero=True)
        except fo.LMIInfeasible as exc:
            raise ParameterError(f"parameter 'hb_zero_alpha_per_s': the H B = 0 observer cannot "
                                 f"reach its region ({exc})") from None
        self.paper_zoh = self.paper.discretise(p["dt_s"], "zoh")
        self.paper_foh = self.paper.discretise(p["dt_s"], "foh")
        self.hb0_zoh = self.hb0.discretise(p["dt_s"], "zoh")
        self.spectrum = f"fra-{p['track_class']}"
        self.band = (p["wavelength_min_m"], p["wavelength_max_m"])
        self.filters = {s: shaping_filter(self.spectrum, s / 3.6, self.band) for s in p["speeds_kmh"]}
        self.lead = int(round(p["lead_in_s"] / p["dt_s"]))
        self.kalman_model = {}
        for s, (filt, _, _) in self.filters.items():
            Aa, Ga, Ca = kb.augment(m.A, m.B, self.C, [filt] * 4)
            self.kalman_model[s] = kb.discretise_noise(Aa, Ga, np.eye(4), p["dt_s"]) + (Ca,)


def simulate_truth(ctx: _Context, p: dict, distance_m, profile_m, speed_kmh: float, rng) -> dict:
    """Exact plant response (track linear between samples) and noisy measurements."""
    m = ctx.model
    t, q = track.wheelset_inputs(distance_m, profile_m, speed_kmh / 3.6, ctx.vehicle.axle_offsets_m,
                                 p["dt_s"], p["duration_s"] + ctx.lead * p["dt_s"])
    x0 = -np.linalg.solve(m.A, m.B @ q[0])          # static equilibrium on the first samples
    x = simulate_foh(*ctx.plant, q, x0)[ctx.lead:]
    q, t = q[ctx.lead:], t[ctx.lead:] - t[ctx.lead]
    y_clean = x @ ctx.C.T
    sigma = p["noise_fraction"] * np.sqrt(np.mean(y_clean**2, axis=0))
    y = y_clean + rng.standard_normal(y_clean.shape) * sigma
    return {"t_s": t, "q_m": q, "x": x, "z_m": x @ m.L.T, "y_clean": y_clean, "y": y,
            "sigma": sigma}


def run_kalman(ctx: _Context, speed_kmh: float, truth: dict, y: np.ndarray, sigma, e0: float):
    """Steady-state Kalman estimate of z_w (not told q), started with the same error e0."""
    Phi, Qd, Ca = ctx.kalman_model[speed_kmh]
    rms = np.sqrt(np.mean(truth["y_clean"] ** 2, axis=0))
    R = np.diag(np.maximum(sigma, 1e-6 * rms) ** 2)     # a noise-free run keeps R > 0
    kf = kb.steady_state_kalman(Phi, Qd, Ca, R)
    q, dq = truth["q_m"][0], (truth["q_m"][1] - truth["q_m"][0]) / (truth["t_s"][1])
    x0 = np.concatenate([truth["x"][0], np.column_stack([q, dq]).ravel()])
    x0[[12, 14, 16, 18]] += e0
    x0[20::2] += e0
    return kf.run(y, x0)[:, [12, 14, 16, 18]], kf


def estimates(ctx: _Context, p: dict, speed_kmh: float, truth: dict, noisy: bool = True) -> dict:
    """Wheelset-displacement estimates of every estimator for one run."""
    y = truth["y"] if noisy else truth["y_clean"]
    z0 = truth["z_m"][0] + p["initial_error_m"]
    out = {"paper": ctx.paper_zoh.run(y, truth["q_m"], z0),
           "hb0": ctx.hb0_zoh.run(y, None, z0),
           "kalman": run_kalman(ctx, speed_kmh, truth, y, truth["sigma"], p["initial_error_m"])[0],
           "q": truth["q_m"].copy()}
    if not noisy:
        out["paper_foh"] = ctx.paper_foh.run(y, truth["q_m"], z0)
    return out


def alpha_sweep(ctx: _Context, p: dict, truths: dict) -> pd.DataFrame:
    """Convergence time of the paper's observer (ZOH) against the pole region α, every speed."""
    m, rows = ctx.model, []
    for alpha in p["alpha_sweep_per_s"]:
        try:
            obs = fo.design(m.A, m.B, ctx.C, m.L, alpha, p["beta"])
        except fo.LMIInfeasible:
            continue
        disc = obs.discretise(p["dt_s"], "zoh")
        try:
            fo.design(m.A, m.B, ctx.C, m.L, alpha, p["beta"], hb_zero=True)
            hb0_ok = True
        except fo.LMIInfeasible:
            hb0_ok = False
        for speed, tr in truths.items():
            z0 = tr["z_m"][0] + p["initial_error_m"]
            for noisy in (True, False):
                zh = disc.run(tr["y"] if noisy else tr["y_clean"], tr["q_m"], z0)
                met = error_metrics(tr["t_s"], tr["z_m"], zh, p)
                thr = p["convergence_fraction"] * np.sqrt(np.mean(tr["z_m"] ** 2, axis=0)).min()
                rate = float(np.min(-obs.poles.real))
                rows.append({"alpha_per_s": alpha, "slowest_rate_per_s": rate,
                             "fastest_rate_per_s": float(np.max(-obs.poles.real)),
                             "speed_kmh": speed, "noisy": noisy,
                             "convergence_time_s": met["convergence_time_s"],
                             "predicted_s": float(np.log(abs(p["initial_error_m"]) / thr) / rate),
                             "hb_zero_feasible": hb0_ok})
    return pd.DataFrame(rows)


def run(*, quick: bool = False, progress=None, **params) -> ChapterResult:
    """Run the chapter; ``params`` are the resolved parameters of :data:`SPEC`."""
    p = params
    validate(p)
    progress = progress or (lambda fraction, message: None)
    started = time.perf_counter()
    ctx = _Context(p)
    timings = {"design_s": time.perf_counter() - started}
    speeds = p["speeds_kmh"]
    length_m = (max(speeds) / 3.6 * (p["duration_s"] + p["lead_in_s"] + 0.1)
                + max(ctx.vehicle.axle_offsets_m) + 1.0)
    length_m = max(length_m, p["wavelength_max_m"] * 1.01)
    seeds = [p["seed"] + i for i in range(p["n_seeds"])]
    mc_rows, default, truths, clean = [], {}, {}, {}
    for si, seed in enumerate(seeds):
        progress(si / len(seeds), f"seed {seed}")
        distance, profile = track.synthesize_profile(
            ctx.spectrum, "vertical", length_m, PROFILE_DX_M, seed,
            wavelength_min_m=p["wavelength_min_m"], wavelength_max_m=p["wavelength_max_m"])
        for speed in speeds:
            rng = np.random.default_rng([seed, int(round(speed * 1000))])
            tr = simulate_truth(ctx, p, distance, profile, speed, rng)
            est = estimates(ctx, p, speed, tr)
            for name, zh in est.items():
                met = error_metrics(tr["t_s"], tr["z_m"], zh, p)
                disc = {"paper": ctx.paper_zoh, "hb0": ctx.hb0_zoh}.get(name)
                pred = predicted_convergence_s(disc, tr["t_s"], tr["z_m"], p) if disc else -1.0
                mc_rows.append({"seed": seed, "speed_kmh": speed, "estimator": name, **met,
                                "predicted_convergence_s": pred})
            if seed == p["seed"]:
                truths[speed], default[speed] = tr, est
                clean[speed] = estimates(ctx, p, speed, tr, noisy=False)
    timings["monte_carlo_s"] = time.perf_counter() - started - timings["design_s"]
    progress(0.95, "alpha sweep")
    sweep = alpha_sweep(ctx, p, truths)
    mc = pd.DataFrame(mc_rows)
    metrics = _metrics(ctx, p, truths, default, clean, mc)
    columns = {"t_s": truths[speeds[0]]["t_s"]}
    for speed in speeds:
        for i in range(4):
            columns[f"zw{i + 1}_true_m_{_label(speed)}"] = truths[speed]["z_m"][:, i]
            columns[f"zw{i + 1}_est_m_{_label(speed)}"] = default[speed]["paper"][:, i]
    progress(1.0, "done")
    timings["run_s"] = time.perf_counter() - started
    data = {"context": ctx, "truths": truths, "estimates": default, "clean": clean,
            "monte_carlo": mc, "alpha_sweep": sweep, "existence": existence_table(ctx.model),
            "modal_table": v10.modal_table(ctx.model), "rank_claims": rank_claims(ctx.model)}
    return ChapterResult(metrics=metrics, timings=timings, timeseries=pd.DataFrame(columns),
                         extra_tables={"monte_carlo": mc, "alpha_sweep": sweep}, data=data)


def _metrics(ctx, p, truths, default, clean, mc) -> dict:
    metrics = {}
    for _, row in existence_table(ctx.model).iterrows():
        name = row["measurement set"]
        metrics[f"existence_rank_{name}"] = int(row["rank [CA; C; L]"])
        metrics[f"existence_ok_{name}"] = bool(row["observer exists"])
    suffix = {"paper": "", "kalman": "_kalman", "hb0": "_hb0", "q": "_q"}
    for speed in p["speeds_kmh"]:
        lab, tr = _label(speed), truths[speed]
        for name, suf in suffix.items():
            met = error_metrics(tr["t_s"], tr["z_m"], default[speed][name], p)
            for key, value in met.items():
                metrics[f"{key}_{lab}{suf}"] = value
            sub = mc[(mc.speed_kmh == speed) & (mc.estimator == name)]["max_error_after_1s_m"]
            metrics[f"max_error_after_1s_m_{lab}{suf}_p05"] = float(np.percentile(sub, 5))
            metrics[f"max_error_after_1s_m_{lab}{suf}_p95"] = float(np.percentile(sub, 95))
        for name, suf in (("paper", "_noisefree"), ("paper_foh", "_noisefree_foh"),
                          ("kalman", "_kalman_noisefree")):
            met = error_metrics(tr["t_s"], tr["z_m"], clean[speed][name], p)
            for key, value in met.items():
                metrics[f"{key}_{lab}{suf}"] = value
    metrics["observer_slowest_rate_per_s"] = float(np.min(-ctx.paper.poles.real))
    metrics["observer_fastest_rate_per_s"] = float(np.max(-ctx.paper.poles.real))
    metrics["observer_residual"] = ctx.paper.residual
    metrics["hb0_fixed_pole_per_s"] = float(np.max(ctx.hb0.fixed_poles.real))
    metrics["hb0_residual"] = ctx.hb0.residual
    return metrics

