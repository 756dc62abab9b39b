"""Chapter ``partial-state-observer`` (paper 000): functional observer of wheelset vibration.

The whole computation of the chapter as a function of its parameters: build the 10-DOF vertical
model, test Darouach's existence conditions for three measurement sets, design the functional
observer of ``z = [z_w1 … z_w4]`` (the paper's, which needs the track input u = q, and the
``H B = 0`` variant, which does not) with a pole-region LMI, simulate the plant exactly on a US
FRA class-5 profile at several speeds, and compare with two baselines: ``ẑ = q`` and a
steady-state Kalman filter with a shaping filter for q (not told q).

Table 1's suspension rows can be read two ways (:mod:`~railpaper.experiments.partial_state_observer.records`); the
parameter ``suspension_reading`` selects the one the single-record illustrations use, and the
Monte Carlo evidence of every reading is computed in every run (metrics ending ``_labels``,
``_symbols``).  The single-record metrics (no ``mc_`` prefix) are one record (seed ``seed``).
The Monte Carlo is a map over records (one per seed:
:mod:`~railpaper.experiments.partial_state_observer.records`) and a reduce
(:func:`~railpaper.experiments.partial_state_observer.evidence.monte_carlo_metrics`); where the
records are computed is the caller's ``record_map``.

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

from railpaper.estimators import functional_observer
from railpaper.experiments.base import ParameterError, default_progress
from railpaper.experiments.partial_state_observer import evidence, records
from railpaper.experiments.partial_state_observer.records import (
    KALMAN_BASELINE,
    KALMAN_SEEDS,
    MONTE_CARLO,
    Context,
    batch_seeds,
    context,
    record,
    run_kalman,
    simulated,
)
from railpaper.experiments.partial_state_observer.result import (
    Estimates,
    PartialStateObserverResult,
    Record,
)
from railpaper.experiments.partial_state_observer.spec import Settings
from railpaper.experiments.records import RecordMap, map_in_process
from railpaper.models import vertical_10dof
from railpaper.settling import settling_time_s
from railpaper.threads import one_thread
from railpaper.timing import steps_per_second

MEASUREMENT = records.MEASUREMENT
existence_table, rank_claims, ranks = evidence.existence_table, evidence.rank_claims, evidence.ranks
ESTIMATORS = ("paper", "hb0", "kalman", "q")


def validate(settings: Settings) -> None:
    """Refuse non-physical or inconsistent resolved settings with one line, before any work."""
    if settings.suspension_reading not in records.READINGS:
        raise ParameterError(f"parameter 'suspension_reading' must be one of "
                             f"{', '.join(records.READINGS)}, got {settings.suspension_reading!r}")
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
            or settings.wavelength_min_m < 2 * records.PROFILE_DX_M):
        raise ParameterError("need 0.1 m ≤ wavelength_min_m < wavelength_max_m")


def _label(speed_kmh: float) -> str:
    return f"{speed_kmh:g}kmh"


def error_metrics(t_s, z_true, z_est, settings: Settings) -> dict:
    """Convergence time, max error and mean relative error after the window start."""
    err = z_est - z_true
    thr = settings.convergence_fraction * np.sqrt(np.mean(z_true**2, axis=0))
    win = t_s >= settings.error_window_start_s
    rms = np.sqrt(np.mean(z_true[win] ** 2, axis=0))
    return {"convergence_time_s": settling_time_s(t_s, np.all(np.abs(err) < thr, axis=-1)),
            "max_error_after_1s_m": float(np.abs(err[win]).max()),
            "mean_relative_error": float(np.mean(np.mean(np.abs(err[win]), axis=0) / rms))}


def estimates(ctx: Context, settings: Settings, speed_kmh: float, truth: dict,
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


def alpha_sweep(ctx: Context, settings: Settings, truths: dict) -> pd.DataFrame:
    """Convergence time of the paper's observer (ZOH) against the pole region α, every speed."""
    m, rows = ctx.model, []
    for alpha in settings.alpha_sweep_per_s:
        try:
            obs = functional_observer.design(m.A, m.B, ctx.C, m.L, alpha, settings.beta)
        except functional_observer.LMIInfeasible:
            continue
        disc = obs.discretise(settings.dt_s, "zoh")
        try:
            functional_observer.design(m.A, m.B, ctx.C, m.L, alpha, settings.beta, hb_zero=True)
            hb0_ok = True
        except functional_observer.LMIInfeasible:
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


def run(settings: Settings, *, progress=None,
        record_map: RecordMap = map_in_process) -> PartialStateObserverResult:
    """Run the chapter with its resolved ``settings`` (:data:`SPEC`).

    Every seed runs every speed under both readings of Table 1 (same track, same noise
    draws): the records of :data:`~railpaper.experiments.partial_state_observer.records.MONTE_CARLO`
    (seeds ``seed`` … ``seed + n_seeds − 1``) and of the selected reading's
    :data:`~railpaper.experiments.partial_state_observer.records.KALMAN_BASELINE` (the first
    :data:`~railpaper.experiments.partial_state_observer.records.KALMAN_SEEDS` of them), computed
    by ``record_map`` (default: here, in chunks); the selected reading's seed ``seed`` is the
    single record the figures show.  Runs on one numba and one OpenBLAS thread
    (:func:`railpaper.threads.one_thread`), as do the records wherever they are computed: with two
    OpenBLAS threads 28 of the Kalman baseline's quick metrics differed from one thread's in
    their last bits, so the metrics depended on the machine's thread count.
    """
    with one_thread():
        return _run(settings, progress, record_map)


def _run(settings: Settings, progress, record_map: RecordMap) -> PartialStateObserverResult:
    validate(settings)
    progress = progress or default_progress()
    started = time.perf_counter()
    chosen = settings.suspension_reading
    ctxs = {r: context(settings, r) for r in records.READINGS}
    ctx = ctxs[chosen]
    timings = {"design_s": time.perf_counter() - started}
    speeds = sorted(settings.speeds_kmh)
    seeds = [settings.seed + i for i in range(settings.n_seeds)]
    rows = record_map(MONTE_CARLO, settings, seeds,
                      lambda fraction, message: progress(0.8 * fraction, message))
    kalman_rows = record_map(KALMAN_BASELINE[chosen], settings, seeds[:KALMAN_SEEDS],
                             lambda fraction, message: progress(0.8 + 0.1 * fraction, message))
    timings["monte_carlo_s"] = time.perf_counter() - started - timings["design_s"]
    progress(0.9, f"single record (seed {settings.seed})")
    tr, _ = simulated(settings, chosen, batch_seeds([settings.seed]))
    truths, default, clean = {}, {}, {}
    for j, speed in enumerate(speeds):
        truths[speed] = record(tr, 0, j)
        default[speed] = estimates(ctx, settings, speed, truths[speed])
        clean[speed] = estimates(ctx, settings, speed, truths[speed], noisy=False)
    first = truths[speeds[0]]                            # the paper's observer, one record
    timings["observer_steps_per_second"] = steps_per_second(
        lambda: ctx.paper_zoh.run(first["y"], first["q_m"],
                                  first["z_m"][0] + settings.initial_error_m),
        len(first["t_s"]))
    progress(0.95, "alpha sweep")
    sweep = alpha_sweep(ctx, settings, truths)
    mc = evidence.runs_table(rows, kalman_rows, settings)
    metrics = _metrics(ctxs, settings, truths, default, clean)
    metrics.update(evidence.monte_carlo_metrics(rows, kalman_rows, settings))
    columns = {"t_s": truths[speeds[0]]["t_s"]}
    for speed in speeds:
        for i in range(4):
            columns[f"zw{i + 1}_true_m_{_label(speed)}"] = truths[speed]["z_m"][:, i]
            columns[f"zw{i + 1}_est_m_{_label(speed)}"] = default[speed]["paper"][:, i]
    progress(1.0, "done")
    timings["run_s"] = time.perf_counter() - started
    return PartialStateObserverResult(
        metrics=metrics, timings=timings, timeseries=pd.DataFrame(columns),
        extra_tables={"monte_carlo": mc, "alpha_sweep": sweep, "records_monte_carlo": rows,
                      f"records_kalman_baseline_{chosen}": kalman_rows},
        design=ctx, designs=ctxs,
        records={s: Record.from_run(tr) for s, tr in truths.items()},
        estimates={s: Estimates.from_dict(e) for s, e in default.items()},
        noise_free={s: Estimates.from_dict(e) for s, e in clean.items()},
        monte_carlo=mc, alpha_sweep=sweep, existence=existence_table(ctx.model),
        modal_table=vertical_10dof.modal_table(ctx.model), rank_claims=rank_claims(ctx.model))


def _metrics(ctxs, settings: Settings, truths, default, clean) -> dict:
    """Single-record metrics (the selected reading, seed ``seed``) and deterministic metrics of
    every reading (the Monte Carlo's are :func:`evidence.monte_carlo_metrics`)."""
    ctx, metrics = ctxs[settings.suspension_reading], {}
    for reading, rctx in ctxs.items():
        for _, row in existence_table(rctx.model).iterrows():
            name = row["measurement set"]
            for suf in ("", f"_{reading}") if rctx is ctx else (f"_{reading}",):
                metrics[f"existence_rank_{name}{suf}"] = int(row["rank [CA; C; L]"])
                metrics[f"existence_ok_{name}{suf}"] = bool(row["observer exists"])
        metrics.update({f"{k}_{reading}": v for k, v in ranks(rctx.model).items()})
        metrics[f"hb0_fixed_pole_per_s_{reading}"] = float(np.max(rctx.hb0.fixed_poles.real))
    metrics.update(evidence.printed_lmi19(ctx.model))
    metrics.update(evidence.wheelset_similarity(ctx.model, ctx.spectrum, ctx.band,
                                                settings.speeds_kmh))
    suffix = {"paper": "", "kalman": "_kalman", "hb0": "_hb0", "q": "_q"}
    for speed in settings.speeds_kmh:
        lab, tr = _label(speed), truths[speed]
        for name, suf in suffix.items():
            met = error_metrics(tr["t_s"], tr["z_m"], default[speed][name], settings)
            for key, value in met.items():
                metrics[f"{key}_{lab}{suf}"] = value
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
