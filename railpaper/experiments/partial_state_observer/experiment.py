"""Chapter ``partial-state-observer`` (paper 000): functional observer of wheelset vibration.

The whole computation of the chapter as a function of its parameters: build the 10-DOF vertical
model, test Darouach's existence conditions for three measurement sets, design the functional
observer of ``z = [z_w1 … z_w4]`` (the paper's, which needs the track input u = q, and the
``H B = 0`` variant, which does not) with a pole-region LMI, simulate the plant exactly on a US
FRA class-5 profile at several speeds, and compare with two baselines: ``ẑ = q`` and a
steady-state Kalman filter with a shaping filter for q (not told q).

Table 1's suspension rows can be read two ways (:mod:`~railpaper.experiments.partial_state_observer.evidence`); the
parameter ``suspension_reading`` selects the one the single-record illustrations use, and the
Monte Carlo evidence of every reading is computed in every run (metrics ending ``_labels``,
``_symbols``).  The single-record metrics (no ``mc_`` prefix) are one record (seed ``seed``).

Definitions used for the metrics (all from the run's own signals, wheelsets 1-4 pooled)
-----------------------------------------------------------------------------------------
* convergence time (single record): first time after which ``|ẑ_i − z_i|`` stays below
  ``convergence_fraction`` (5 %) of the RMS of the true ``z_i`` (over the run) for every
  wheelset i, to the end of the run; -1 if the error is above it at the last sample;
* max error after 1 s: ``max_{i, t ≥ 1 s} |ẑ_i − z_i|`` (m);
* mean relative error: mean over wheelsets of ``mean_{t ≥ 1 s} |ẑ_i − z_i| / RMS_{t ≥ 1 s}(z_i)``.
"""

from __future__ import annotations

import time

import numpy as np
import pandas as pd

from railpaper import track
from railpaper.discretise import foh
from railpaper.estimators import functional_observer as fo
from railpaper.estimators import kalman_baseline as kb
from railpaper.experiments.base import ParameterError, default_progress
from railpaper.experiments.partial_state_observer import evidence
from railpaper.experiments.partial_state_observer.result import (
    Estimates,
    PartialStateObserverResult,
    Record,
)
from railpaper.experiments.partial_state_observer.spec import Settings
from railpaper.experiments.track_shaping import shaping_filter
from railpaper.models import vertical_10dof as v10
from railpaper.settling import settling_time_s
from railpaper.threads import one_thread

MEASUREMENT = evidence.MEASUREMENT
existence_table, rank_claims, ranks = evidence.existence_table, evidence.rank_claims, evidence.ranks
PROFILE_DX_M = 0.05
SEED_GROUP = 10               # seeds simulated together (memory ~ 0.3 GB per group at 8 s)
KALMAN_SEEDS = 20             # the Kalman baseline (an illustration, no claim) runs on these many
ESTIMATORS = ("paper", "hb0", "kalman", "q")


def validate(settings: Settings) -> None:
    """Refuse non-physical or inconsistent resolved settings with one line, before any work."""
    if settings.suspension_reading not in evidence.READINGS:
        raise ParameterError(f"parameter 'suspension_reading' must be one of "
                             f"{', '.join(evidence.READINGS)}, got {settings.suspension_reading!r}")
    if settings.n_seeds >= 1000:
        raise ParameterError("parameter 'n_seeds' must be < 1000 (seed batches of "
                             "`railpaper bands` are 1000 apart)")
    if settings.beta <= 1.0:
        raise ParameterError(f"parameter 'beta' must be > 1 (a strip α ≤ −Re λ ≤ βα), "
                             f"got {settings.beta}")
    if not 1 <= settings.track_class <= 6:
        raise ParameterError(f"parameter 'track_class' must be 1..6, got {settings.track_class}")
    if settings.dt_s > 2e-3:
        raise ParameterError(f"parameter 'dt_s' = {settings.dt_s} s cannot resolve the 229 Hz "
                             "wheelset mode (use ≤ 2e-3 s)")
    if settings.error_window_start_s >= settings.duration_s:
        raise ParameterError("parameter 'error_window_start_s' must be shorter than 'duration_s'")
    if len(set(settings.speeds_kmh)) != len(settings.speeds_kmh):
        raise ParameterError(f"parameter 'speeds_kmh' has repeated speeds: "
                             f"{list(settings.speeds_kmh)}")
    if (settings.wavelength_min_m >= settings.wavelength_max_m
            or settings.wavelength_min_m < 2 * PROFILE_DX_M):
        raise ParameterError("need 0.1 m ≤ wavelength_min_m < wavelength_max_m")


def _label(speed_kmh: float) -> str:
    return f"{speed_kmh:g}kmh"


def error_dynamics(disc: fo.DiscreteFunctionalObserver, n_steps: int, e0: float) -> np.ndarray:
    """The error dynamics alone, ``ε[k] = Φ^k ε[0]`` with every component of ε[0] = e0."""
    eps = np.empty((n_steps, disc.Phi.shape[0]))
    eps[0] = e0
    for k in range(n_steps - 1):
        eps[k + 1] = disc.Phi @ eps[k]
    return eps


def predicted_convergence_s(eps: np.ndarray, t_s, z_true, settings: Settings) -> float:
    """Convergence time of the error dynamics ``eps`` alone against the run's threshold."""
    thr = settings.convergence_fraction * np.sqrt(np.mean(z_true**2, axis=0))
    return settling_time_s(t_s, np.all(np.abs(eps[: len(t_s)]) < thr, axis=-1))


def error_metrics(t_s, z_true, z_est, settings: Settings) -> dict:
    """Convergence time, max error and mean relative error after the window start."""
    err = z_est - z_true
    thr = settings.convergence_fraction * np.sqrt(np.mean(z_true**2, axis=0))
    win = t_s >= settings.error_window_start_s
    rms = np.sqrt(np.mean(z_true[win] ** 2, axis=0))
    return {"convergence_time_s": settling_time_s(t_s, np.all(np.abs(err) < thr, axis=-1)),
            "max_error_after_1s_m": float(np.abs(err[win]).max()),
            "mean_relative_error": float(np.mean(np.mean(np.abs(err[win]), axis=0) / rms))}


class _Context:
    """Everything that does not depend on the seed, for one reading of Table 1: model,
    observers, discretisations (and the Kalman baseline's models when ``kalman``)."""

    def __init__(self, settings: Settings, reading: str, kalman: bool = True):
        self.reading = reading
        self.vehicle = v = v10.load_parameters(**evidence.suspension(reading))
        self.model = m = v10.build_model(self.vehicle)
        self.C = m.output_matrix(MEASUREMENT)
        self.plant = foh(m.A, m.B, settings.dt_s)
        try:
            self.paper = fo.design(m.A, m.B, self.C, m.L, settings.alpha_per_s, settings.beta)
        except fo.LMIInfeasible as exc:
            raise ParameterError(f"parameters 'alpha_per_s', 'beta': no observer with poles in "
                                 f"[{settings.alpha_per_s:g}, "
                                 f"{settings.beta * settings.alpha_per_s:g}] 1/s ({exc})") from None
        # H B = 0 leaves no freedom: every pole sits at −K_p/C_p; a region around it
        corner = v.primary_stiffness_N_per_m / v.primary_damping_Ns_per_m
        self.hb0 = fo.design(m.A, m.B, self.C, m.L, corner / np.sqrt(settings.beta), settings.beta,
                             hb_zero=True)
        self.paper_zoh = self.paper.discretise(settings.dt_s, "zoh")
        self.paper_foh = self.paper.discretise(settings.dt_s, "foh")
        self.hb0_zoh = self.hb0.discretise(settings.dt_s, "zoh")
        n_steps = int(round(settings.duration_s / settings.dt_s)) + 1
        self.eps = {name: error_dynamics(d, n_steps, settings.initial_error_m)
                    for name, d in (("paper", self.paper_zoh), ("hb0", self.hb0_zoh))}
        self.spectrum = f"fra-{settings.track_class}"
        self.band = (settings.wavelength_min_m, settings.wavelength_max_m)
        self.lead = int(round(settings.lead_in_s / settings.dt_s))
        self.filters, self.kalman_model = {}, {}
        if kalman:
            self.filters = {s: shaping_filter(self.spectrum, s / 3.6, self.band)
                            for s in settings.speeds_kmh}
            for s, (filt, _, _) in self.filters.items():
                Aa, Ga, Ca = kb.augment(m.A, m.B, self.C, [filt] * 4)
                self.kalman_model[s] = kb.discretise_noise(Aa, Ga, np.eye(4), settings.dt_s) + (Ca,)


def simulate_foh_batch(Phi, Gamma0, Gamma1, u: np.ndarray, x0: np.ndarray) -> np.ndarray:
    """:func:`railpaper.discretise.simulate_foh` for many runs: u (..., K, m), x0 (..., n).

    The step loop runs on a time-major copy (each step reads one contiguous block).
    """
    lead, K = u.shape[:-2], u.shape[-2]
    u_t = np.moveaxis(u.reshape((-1,) + u.shape[-2:]), 1, 0)              # (K, B, m)
    drive = u_t[:-1] @ (Gamma0 - Gamma1).T + u_t[1:] @ Gamma1.T
    x = np.empty((K, drive.shape[1], Phi.shape[0]))
    x[0] = np.reshape(x0, (-1, Phi.shape[0]))
    PhiT = Phi.T
    for k in range(K - 1):
        np.matmul(x[k], PhiT, out=x[k + 1])
        x[k + 1] += drive[k]
    return np.ascontiguousarray(np.moveaxis(x, 0, 1)).reshape(lead + (K, Phi.shape[0]))


def simulate_truths(ctx: _Context, settings: Settings, q_in: np.ndarray, t_s: np.ndarray, seeds,
                    speeds) -> dict:
    """Exact plant responses (track linear between samples) and noisy measurements of many runs.

    ``q_in[i, j]`` (K + lead, 4) is the track under the wheelsets for seed i at speed j; the noise
    of that run is drawn from ``default_rng([seed, 1000 V])``.  Arrays of the result have leading
    axes (seed, speed); ``sigma`` is each channel's noise σ (0.5 % of its RMS).
    """
    m, n_lead = ctx.model, ctx.lead
    x0 = -np.linalg.solve(m.A, m.B @ q_in[..., 0, :, None])[..., 0]   # static equilibrium
    x = np.ascontiguousarray(simulate_foh_batch(*ctx.plant, q_in, x0)[..., n_lead:, :])
    y_clean = x @ ctx.C.T
    sigma = settings.noise_fraction * np.sqrt(np.mean(y_clean**2, axis=-2))
    unit = np.stack([[np.random.default_rng([seed, int(round(v * 1000))]).standard_normal(
        y_clean.shape[-2:]) for v in speeds] for seed in seeds])
    return {"t_s": t_s, "q_m": q_in[..., n_lead:, :], "x": x, "z_m": x @ m.L.T,
            "y_clean": y_clean, "y": y_clean + unit * sigma[..., None, :], "unit_noise": unit,
            "sigma": sigma, "speeds": list(speeds)}


def record(tr: dict, i: int, j: int) -> dict:
    """One run (seed index i, speed index j) of :func:`simulate_truths` as the notebook uses it."""
    return {k: tr[k] if k == "t_s" else tr[k][i, j] for k in
            ("t_s", "q_m", "x", "z_m", "y_clean", "y", "sigma")} | {"speed_kmh": tr["speeds"][j]}


def run_kalman(ctx: _Context, speed_kmh: float, tr: dict, j: int | None, e0: float,
               noisy: bool = True) -> np.ndarray:
    """Steady-state Kalman estimates of z_w (not told q), started with the same error e0; each
    run's filter is told that run's noise σ (R = diag σ², kept > 0 without noise).

    ``tr`` holds runs at leading axes (seed, speed) and ``j`` picks the speed (None: ``tr`` is
    one run); returns the estimates, seed axis first (or of the one run).
    """
    pick = (lambda a: a) if j is None else (lambda a: a[:, j])
    Phi, Qd, Ca = ctx.kalman_model[speed_kmh]
    y_clean, sigma, q, x = (pick(tr[k]) for k in ("y_clean", "sigma", "q_m", "x"))
    y = pick(tr["y"]) if noisy else y_clean
    lead = y.shape[:-2]
    rms = np.sqrt(np.mean(y_clean**2, axis=-2)).reshape(-1, y.shape[-1])
    filters = [kb.steady_state_kalman(Phi, Qd, Ca, np.diag(np.maximum(s, 1e-6 * r) ** 2))
               for s, r in zip(sigma.reshape(-1, y.shape[-1]), rms)]
    A_updT = np.stack([(np.eye(Phi.shape[0]) - f.K @ f.C).T for f in filters])
    drive = np.einsum("bkq,bnq->bkn", y.reshape((-1,) + y.shape[-2:]), np.stack([f.K for f in filters]))
    dq = (q[..., 1, :] - q[..., 0, :]) / tr["t_s"][1]
    prior = np.concatenate([x[..., 0, :], np.stack([q[..., 0, :], dq], axis=-1).reshape(
        lead + (8,))], axis=-1).reshape(len(filters), -1)
    prior[:, [12, 14, 16, 18]] += e0
    prior[:, 20::2] += e0
    out = np.empty(drive.shape[:2] + (4,))
    PhiT = Phi.T
    for k in range(drive.shape[1]):                 # x⁺ = (I − K C) x⁻ + K y;  x⁻ ← Φ x⁺
        post = (prior[:, None, :] @ A_updT)[:, 0] + drive[:, k]
        out[:, k] = post[:, [12, 14, 16, 18]]
        prior = post @ PhiT
    return out.reshape(lead + out.shape[1:])


def estimates(ctx: _Context, settings: Settings, speed_kmh: float, truth: dict,
              noisy: bool = True) -> dict:
    """Wheelset-displacement estimates of every estimator for one run."""
    y = truth["y"] if noisy else truth["y_clean"]
    z0 = truth["z_m"][0] + settings.initial_error_m
    out = {"paper": ctx.paper_zoh.run(y, truth["q_m"], z0),
           "hb0": ctx.hb0_zoh.run(y, None, z0),
           "kalman": run_kalman(ctx, speed_kmh, truth, None, settings.initial_error_m, noisy),
           "q": truth["q_m"].copy()}
    if not noisy:
        out["paper_foh"] = ctx.paper_foh.run(y, truth["q_m"], z0)
    return out


def alpha_sweep(ctx: _Context, settings: Settings, truths: dict) -> pd.DataFrame:
    """Convergence time of the paper's observer (ZOH) against the pole region α, every speed."""
    m, rows = ctx.model, []
    for alpha in settings.alpha_sweep_per_s:
        try:
            obs = fo.design(m.A, m.B, ctx.C, m.L, alpha, settings.beta)
        except fo.LMIInfeasible:
            continue
        disc = obs.discretise(settings.dt_s, "zoh")
        try:
            fo.design(m.A, m.B, ctx.C, m.L, alpha, settings.beta, hb_zero=True)
            hb0_ok = True
        except fo.LMIInfeasible:
            hb0_ok = False
        for speed, tr in truths.items():
            z0 = tr["z_m"][0] + settings.initial_error_m
            for noisy in (True, False):
                zh = disc.run(tr["y"] if noisy else tr["y_clean"], tr["q_m"], z0)
                met = error_metrics(tr["t_s"], tr["z_m"], zh, settings)
                thr = settings.convergence_fraction * np.sqrt(np.mean(tr["z_m"] ** 2, axis=0)).min()
                rate = float(np.min(-obs.poles.real))
                rows.append({"alpha_per_s": alpha, "slowest_rate_per_s": rate,
                             "fastest_rate_per_s": float(np.max(-obs.poles.real)),
                             "speed_kmh": speed, "noisy": noisy,
                             "convergence_time_s": met["convergence_time_s"],
                             "predicted_s": float(np.log(abs(settings.initial_error_m) / thr)
                                                  / rate),
                             "hb_zero_feasible": hb0_ok})
    return pd.DataFrame(rows)


def monte_carlo_runs(ctx: _Context, settings: Settings, tr: dict, kalman: bool) -> dict:
    """Estimates of the runs of :func:`simulate_truths` (speeds ascending): the paper's observer
    with the paper's noise (``paper``), noise-free (``paper_noisefree``) and with speed-independent
    noise (``paper_fixednoise``: each channel's σ of the lowest speed, on the same draws); the
    H B = 0 variant, ẑ = q and (if ``kalman``) the Kalman baseline with the paper's noise."""
    sigma_fixed = tr["sigma"][:, :1, None, :]
    z0 = tr["z_m"][..., 0, :] + settings.initial_error_m
    ys = np.stack([tr["y"], tr["y_clean"], tr["y_clean"] + tr["unit_noise"] * sigma_fixed], axis=2)
    us = np.broadcast_to(tr["q_m"][:, :, None], ys.shape[:-1] + (4,))
    paper = ctx.paper_zoh.run(ys, us, z0[:, :, None, :])
    out = {"paper": paper[:, :, 0], "paper_noisefree": paper[:, :, 1],
           "paper_fixednoise": paper[:, :, 2], "hb0": ctx.hb0_zoh.run(tr["y"], None, z0),
           "q": tr["q_m"]}
    if kalman:
        out["kalman"] = np.stack([run_kalman(ctx, v, tr, j, settings.initial_error_m)
                                  for j, v in enumerate(tr["speeds"])], axis=1)
    return out


def track_inputs(ctx: _Context, settings: Settings, seeds, speeds, length_m: float):
    """Times, track under the wheelsets (seed, speed, K + lead, 4) and each seed's
    speed-independent convergence threshold (5 % of its whole profile's RMS), m."""
    q_in, fixed = [], []
    for seed in seeds:
        distance, profile = track.synthesize_profile(
            ctx.spectrum, "vertical", length_m, PROFILE_DX_M, seed,
            wavelength_min_m=settings.wavelength_min_m, wavelength_max_m=settings.wavelength_max_m)
        fixed.append(settings.convergence_fraction * float(np.sqrt(np.mean(profile**2))))
        runs = [track.wheelset_inputs(distance, profile, v / 3.6, ctx.vehicle.axle_offsets_m,
                                      settings.dt_s, settings.duration_s + ctx.lead * settings.dt_s)
                for v in speeds]
        q_in.append([q for _, q in runs])
    t = runs[0][0]
    return t[ctx.lead:] - t[ctx.lead], np.array(q_in), np.array(fixed)


def _runs_table(ctx: _Context, settings: Settings, tr: dict, est: dict, seeds,
                fixed) -> pd.DataFrame:
    """One row per (seed, speed, estimator) with :func:`evidence.run_measures`."""
    rows = []
    for name, zh in est.items():
        meas = evidence.run_measures(tr["t_s"], tr["z_m"], zh, fixed[:, None],
                                     settings.convergence_fraction, settings.error_window_start_s)
        for i, seed in enumerate(seeds):
            for j, speed in enumerate(tr["speeds"]):
                pred = (predicted_convergence_s(ctx.eps[name], tr["t_s"], tr["z_m"][i, j], settings)
                        if name in ctx.eps else -1.0)
                rows.append({"reading": ctx.reading, "seed": seed, "speed_kmh": speed,
                             "estimator": name, **{k: v[i, j].item() for k, v in meas.items()},
                             "predicted_convergence_s": pred})
    return pd.DataFrame(rows)


def run(settings: Settings, *, progress=None) -> PartialStateObserverResult:
    """Run the chapter with its resolved ``settings`` (:data:`SPEC`).

    Every seed runs every speed under both readings of Table 1 (same track, same noise
    draws); the selected reading's seed ``seed`` is the single record the figures show.  Runs
    on one numba and one OpenBLAS thread (:func:`railpaper.threads.one_thread`): with two
    OpenBLAS threads 28 of the Kalman baseline's quick metrics differed from one thread's in
    their last bits, so the metrics depended on the machine's thread count.
    """
    with one_thread():
        return _run(settings, progress)


def _run(settings: Settings, progress) -> PartialStateObserverResult:
    validate(settings)
    progress = progress or default_progress()
    started = time.perf_counter()
    chosen = settings.suspension_reading
    ctxs = {r: _Context(settings, r, kalman=r == chosen) for r in evidence.READINGS}
    ctx = ctxs[chosen]
    timings = {"design_s": time.perf_counter() - started}
    speeds = sorted(settings.speeds_kmh)
    length_m = (max(speeds) / 3.6 * (settings.duration_s + settings.lead_in_s + 0.1)
                + max(ctx.vehicle.axle_offsets_m) + 1.0)
    length_m = max(length_m, settings.wavelength_max_m * 1.01)
    seeds = [settings.seed + i for i in range(settings.n_seeds)]
    tables, default, truths, clean = [], {}, {}, {}
    for g in range(0, len(seeds), SEED_GROUP):
        group = seeds[g:g + SEED_GROUP]
        progress(g / len(seeds), f"seeds {group[0]}-{group[-1]}")
        t_s, q_in, fixed = track_inputs(ctx, settings, group, speeds, length_m)
        for reading, rctx in ctxs.items():
            tr = simulate_truths(rctx, settings, q_in, t_s, group, speeds)
            est = monte_carlo_runs(rctx, settings, tr, reading == chosen and g < KALMAN_SEEDS)
            tables.append(_runs_table(rctx, settings, tr, est, group, fixed))
            if group[0] == settings.seed and reading == chosen:
                for j, speed in enumerate(speeds):
                    truths[speed] = record(tr, 0, j)
                    default[speed] = estimates(ctx, settings, speed, truths[speed])
                    clean[speed] = estimates(ctx, settings, speed, truths[speed], noisy=False)
    timings["monte_carlo_s"] = time.perf_counter() - started - timings["design_s"]
    progress(0.95, "alpha sweep")
    sweep = alpha_sweep(ctx, settings, truths)
    mc = pd.concat(tables, ignore_index=True)
    metrics = _metrics(ctxs, settings, truths, default, clean, mc)
    columns = {"t_s": truths[speeds[0]]["t_s"]}
    for speed in speeds:
        for i in range(4):
            columns[f"zw{i + 1}_true_m_{_label(speed)}"] = truths[speed]["z_m"][:, i]
            columns[f"zw{i + 1}_est_m_{_label(speed)}"] = default[speed]["paper"][:, i]
    progress(1.0, "done")
    timings["run_s"] = time.perf_counter() - started
    return PartialStateObserverResult(
        metrics=metrics, timings=timings, timeseries=pd.DataFrame(columns),
        extra_tables={"monte_carlo": mc, "alpha_sweep": sweep}, design=ctx, designs=ctxs,
        records={s: Record.from_run(tr) for s, tr in truths.items()},
        estimates={s: Estimates.from_dict(e) for s, e in default.items()},
        noise_free={s: Estimates.from_dict(e) for s, e in clean.items()},
        monte_carlo=mc, alpha_sweep=sweep, existence=existence_table(ctx.model),
        modal_table=v10.modal_table(ctx.model), rank_claims=rank_claims(ctx.model))


def _metrics(ctxs, settings: Settings, truths, default, clean, mc) -> dict:
    """Single-record metrics (the selected reading, seed ``seed``), deterministic metrics of
    every reading and the Monte Carlo evidence of every reading."""
    ctx, metrics = ctxs[settings.suspension_reading], {}
    for reading, rctx in ctxs.items():
        for _, row in existence_table(rctx.model).iterrows():
            name = row["measurement set"]
            for suf in ("", f"_{reading}") if rctx is ctx else (f"_{reading}",):
                metrics[f"existence_rank_{name}{suf}"] = int(row["rank [CA; C; L]"])
                metrics[f"existence_ok_{name}{suf}"] = bool(row["observer exists"])
        metrics.update({f"{k}_{reading}": v for k, v in ranks(rctx.model).items()})
        metrics[f"hb0_fixed_pole_per_s_{reading}"] = float(np.max(rctx.hb0.fixed_poles.real))
        metrics.update(evidence.evidence_metrics(mc, reading))
    metrics.update(evidence.printed_lmi19(ctx.model))
    metrics.update(evidence.wheelset_similarity(ctx.model, ctx.spectrum, ctx.band,
                                                settings.speeds_kmh))
    own = mc[mc.reading == settings.suspension_reading]
    suffix = {"paper": "", "kalman": "_kalman", "hb0": "_hb0", "q": "_q"}
    for speed in settings.speeds_kmh:
        lab, tr = _label(speed), truths[speed]
        for name, suf in suffix.items():
            met = error_metrics(tr["t_s"], tr["z_m"], default[speed][name], settings)
            for key, value in met.items():
                metrics[f"{key}_{lab}{suf}"] = value
            sub = own[(own.speed_kmh == speed) & (own.estimator == name)]["max_error_after_1s_m"]
            metrics[f"max_error_after_1s_m_{lab}{suf}_p05"] = float(np.percentile(sub, 5))
            metrics[f"max_error_after_1s_m_{lab}{suf}_p95"] = float(np.percentile(sub, 95))
        for name, suf in (("paper", "_noisefree"), ("paper_foh", "_noisefree_foh"),
                          ("kalman", "_kalman_noisefree")):
            met = error_metrics(tr["t_s"], tr["z_m"], clean[speed][name], settings)
            for key, value in met.items():
                metrics[f"{key}_{lab}{suf}"] = value
    metrics["observer_slowest_rate_per_s"] = float(np.min(-ctx.paper.poles.real))
    metrics["observer_fastest_rate_per_s"] = float(np.max(-ctx.paper.poles.real))
    metrics["observer_residual"] = ctx.paper.residual
    metrics["hb0_fixed_pole_per_s"] = float(np.max(ctx.hb0.fixed_poles.real))
    metrics["hb0_residual"] = ctx.hb0.residual
    return metrics
