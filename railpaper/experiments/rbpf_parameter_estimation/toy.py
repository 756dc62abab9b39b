"""Part 1 of the ``rbpf-parameter-estimation`` chapter: Ding et al.'s Eq. (18) toy on many records.

The RBPF exactly as the paper's Steps 1–2.6 (``scheme="paper"``, prior uniform on the initial
condition ± ``toy_prior_halfwidth``), our working scheme beside it (no claim reads it), and an
augmented-state EKF, each from the paper's initial conditions 1 = (0, 0, 0, 0) and
2 = (−0.26, 1, 0.24, −0.5).  One record is :func:`simulate` then :func:`filter_record` on one
generator; :func:`run_toy` does that for records ``seed`` … ``seed + toy_seeds − 1``: the
illustrated record here, the others as the study :data:`TOY` (one row per seed,
:func:`toy_rows`) through the caller's record map.
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from railpaper.engine import FilterRun, run_rbpf
from railpaper.estimators.ekf import EKFRun, eq18_model, run_augmented_ekf
from railpaper.experiments.base import ProgressCallback, no_progress
from railpaper.experiments.rbpf_parameter_estimation.result import ToyPart, ToyRun
from railpaper.experiments.rbpf_parameter_estimation.spec import (
    JUDGED_PARTICLES,
    Settings,
    after_the_seen_records,
)
from railpaper.experiments.records import RecordMap, RecordStudy, map_in_process, normalised
from railpaper.models.linear_toys import EQ18_G, Simulation, eq18_system, simulate_eq18
from railpaper.settling import settling_step
from railpaper.threads import one_thread

TOY_INITS = {1: np.zeros(4), 2: np.array([-0.26, 1.0, 0.24, -0.5])}
EKF_BOUND = 1e3       # |x_j| above this: the toy EKF has diverged; its error then counts as this
Z90 = 1.6448536269514722    # standard normal 95 % quantile: mean ± Z90 sd is a 90 % interval


def gaussian_covers(mean: np.ndarray, sd: np.ndarray, truth: np.ndarray) -> np.ndarray:
    """Whether ``mean ± Z90 sd`` (a particle filter's 90 % interval read as Gaussian) holds the
    truth, per parameter (bool array of the broadcast shape)."""
    return np.abs(np.asarray(truth) - np.asarray(mean)) <= Z90 * np.asarray(sd)


def truth(settings: Settings) -> np.ndarray:
    """The true (x1, x2, x3, x4) of Eq. (18) from the parameters ``toy_x1`` … ``toy_x4``."""
    return np.array([settings.toy_x1, settings.toy_x2, settings.toy_x3, settings.toy_x4])


def system(settings: Settings):
    """``system(theta)``: Eq. (18) for a batch of parameter particles, W and V of variance
    ``toy_noise_var`` (:func:`railpaper.models.linear_toys.eq18_system`)."""
    return eq18_system(settings.toy_noise_var, settings.toy_noise_var)


def simulate(settings: Settings, rng: np.random.Generator) -> Simulation:
    """One record of ``toy_steps`` measurements at the true x: input u ~ N(0, 1), then the
    process and measurement noise, drawn from ``rng``."""
    v = settings.toy_noise_var
    return simulate_eq18(truth(settings), v, v, settings.toy_steps, rng)


def prior(settings: Settings, start: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """``toy_particles`` particles (N, 4) uniform on ``start`` ± ``toy_prior_halfwidth``."""
    hw = settings.toy_prior_halfwidth
    return rng.uniform(start - hw, start + hw, (settings.toy_particles, 4))


def rbpf(settings: Settings, model, sim: Simulation, theta0: np.ndarray, rng: np.random.Generator,
         scheme: str) -> FilterRun:
    """The RBPF of ``model`` (from :func:`system`) from particles ``theta0`` on one record:
    ``scheme="paper"`` (Steps 1–2.6: resample and move every step, Liu–West δ =
    ``paper_delta``) or ``"working"`` (ours: tempering over ``toy_tempering_steps``, resampling
    when ESS < ``toy_ess_fraction`` N, δ = ``working_delta``).  Each particle's Kalman filter starts
    at x = 0 with covariance I."""
    options = (dict(scheme="paper", delta=settings.paper_delta) if scheme == "paper" else
               dict(scheme="working", delta=settings.working_delta,
                    ess_fraction=settings.toy_ess_fraction,
                    tempering_steps=settings.toy_tempering_steps))
    return run_rbpf(model, sim.y, theta0, np.zeros(2), np.eye(2), rng, u=sim.u, **options)


def ekf(settings: Settings, sim: Simulation, start: np.ndarray) -> EKFRun:
    """The augmented-state EKF on one record from x = ``start`` (P_θ = I, x0 = 0 with P = I,
    random walk of variance ``toy_ekf_q_theta`` per step on each x_j)."""
    v = settings.toy_noise_var
    Q, R = v * EQ18_G @ EQ18_G.T, np.array([[v]])
    return run_augmented_ekf(eq18_model, sim.y, start, np.zeros(2), np.eye(2), 1.0, Q, R,
                             settings.toy_ekf_q_theta, u=sim.u, divergence_bound=EKF_BOUND)


def filter_record(settings: Settings, sim: Simulation, ic: int, rng: np.random.Generator
                  ) -> ToyRun:
    """Prior draw, both RBPF schemes (same particles) and the EKF from initial condition ``ic``."""
    start, model = TOY_INITS[ic], system(settings)
    theta0 = prior(settings, start, rng)
    paper = rbpf(settings, model, sim, theta0, rng, "paper")
    working = rbpf(settings, model, sim, theta0, rng, "working")
    ek = ekf(settings, sim, start)
    return ToyRun(ic, start, paper.theta_mean, working.theta_mean, ek.theta, ek.diverged,
                  ek.diverged_step, paper.theta_std, working.theta_std)


def _record_stats(settings: Settings, seed: int, run: ToyRun) -> dict:
    """One row of :attr:`ToyPart.records`: final errors, converged flags and settle steps, and
    the signed final errors θ̂_j − x_j of the EKF (NaN after a numerical divergence) and of the
    paper-scheme RBPF (``ekf_final_error_x<j>``, ``rbpf_final_error_x<j>``)."""
    x, tol = truth(settings), settings.toy_bias_tol

    def err(theta):                                       # max |error| over x_j per step
        e = np.nan_to_num(np.abs(theta - x).max(axis=1), nan=EKF_BOUND)
        return np.minimum(e, EKF_BOUND)

    e_rb, e_rw, e_ek = err(run.rbpf_paper), err(run.rbpf_working), err(run.ekf)
    if run.ekf_diverged:
        e_ek[run.ekf_diverged_step - 1:] = EKF_BOUND
    signed = {f"{key}_final_error_x{j + 1}": float(theta[-1, j] - x[j]) if ok else np.nan
              for key, theta, ok in (("ekf", run.ekf, not run.ekf_diverged),
                                     ("rbpf", run.rbpf_paper, True))
              for j in range(len(x))}
    return dict(seed=seed, init=run.initial_condition, rbpf_err_max=e_rb[-1],
                rbpf_working_err_max=e_rw[-1], ekf_err_max=e_ek[-1],
                ekf_diverged=run.ekf_diverged,
                ekf_converged=not run.ekf_diverged and e_ek[-1] <= tol,
                rbpf_converged=bool(e_rb[-1] <= tol),
                rbpf_settle=settling_step(e_rb <= tol, never=len(e_rb) + 1),
                ekf_settle=settling_step(e_ek <= tol, never=len(e_ek) + 1),
                **{f"{key}_covers_x{j + 1}": bool(c) for key, (mean, sd) in
                   (("rbpf", (run.rbpf_paper, run.rbpf_paper_sd)),
                    ("rbpf_working", (run.rbpf_working, run.rbpf_working_sd)))
                   for j, c in enumerate(gaussian_covers(mean[-1], sd[-1], x))},
                **signed)


def toy_rows(settings: Settings, seeds) -> pd.DataFrame:
    """The toy study's rows (:data:`railpaper.experiments.rbpf_parameter_estimation.experiment.
    TOY`): one wide row per seed, :func:`_record_stats` of initial conditions 1 and 2 with their
    columns suffixed ``_init1``, ``_init2`` (record ``seed`` is :func:`simulate` then
    :func:`filter_record` from 1 then 2, all on ``numpy.random.default_rng(seed)``)."""
    with one_thread():
        return pd.DataFrame([wide_row(seed, [_record_stats(settings, int(seed), run)
                                             for run in record_runs(settings, int(seed))])
                             for seed in seeds])


def record_runs(settings: Settings, seed: int) -> list[ToyRun]:
    """Record ``seed`` filtered from initial conditions 1 and 2 (:data:`TOY_INITS`), in order,
    on one generator."""
    rng = np.random.default_rng(seed)
    sim = simulate(settings, rng)
    return [filter_record(settings, sim, ic, rng) for ic in TOY_INITS]


def wide_row(seed: int, stats: list[dict]) -> dict:
    """One seed's row from its per-initial-condition stats (``init`` dropped, the rest
    suffixed ``_init<ic>``), then ``rbpf_converged_both_inits``, ``ekf_converged_both_inits``
    and ``ekf_outcome_differs_between_inits`` (yes/no over both initial conditions)."""
    row = {"seed": seed}
    for one in stats:
        ic = one["init"]
        row.update({f"{k}_init{ic}": v for k, v in one.items() if k not in ("seed", "init")})
    # the record's outcome over both initial conditions (what 'immune to the initial value'
    # and 'sensitive to the initial value' read): yes/no
    row["rbpf_converged_both_inits"] = all(one["rbpf_converged"] for one in stats)
    row["ekf_converged_both_inits"] = all(one["ekf_converged"] for one in stats)
    row["ekf_outcome_differs_between_inits"] = len({one["ekf_converged"] for one in stats}) > 1
    return row


def long_records(wide: pd.DataFrame) -> pd.DataFrame:
    """The wide rows of :func:`toy_rows` as :attr:`ToyPart.records`: one row per (record,
    initial condition), seed-major, columns ``seed``, ``init`` and the stats."""
    parts = []
    for ic in TOY_INITS:
        suffix = f"_init{ic}"
        part = wide[["seed"] + [c for c in wide.columns if c.endswith(suffix)]]
        part = part.rename(columns={c: c[:-len(suffix)] for c in part.columns if c != "seed"})
        part.insert(1, "init", ic)
        parts.append(part.assign(order=np.arange(len(wide)) * len(TOY_INITS) + ic - 1))
    return (pd.concat(parts, ignore_index=True).sort_values("order", kind="stable")
            .drop(columns="order").reset_index(drop=True))


def run_toy(settings: Settings, record_map: RecordMap = map_in_process,
            progress: ProgressCallback = no_progress) -> ToyPart:
    """Eq. (18) on records ``seed`` … ``seed + toy_seeds − 1``: the illustrated record
    ``seed`` in full here, the others as the rows of the study ``TOY`` through ``record_map``
    (:func:`toy_rows`)."""
    runs = record_runs(settings, settings.seed)
    illustrated = {run.initial_condition: run for run in runs}
    first = normalised(pd.DataFrame([wide_row(settings.seed, [
        _record_stats(settings, settings.seed, run) for run in runs])]))
    wide = first
    if settings.toy_seeds > 1:
        others = record_map(TOY, settings, range(settings.seed + 1,
                                                 settings.seed + settings.toy_seeds), progress)
        wide = pd.concat([first, others], ignore_index=True)
    return ToyPart(truth=truth(settings), steps=settings.toy_steps, seed=settings.seed,
                   illustrated=illustrated, records=long_records(wide), rows=wide)


#: The toy's per-record work: one wide row per seed (:func:`toy_rows`), a record at a time.
TOY = RecordStudy("rbpf-parameter-estimation", "toy", toy_rows, chunk_records=10)


def judged_particles_rows(settings: Settings, seeds) -> pd.DataFrame:
    """The study :data:`TOY_JUDGED`'s rows: :func:`toy_rows` with :data:`JUDGED_PARTICLES` RBPF
    particles in place of ``toy_particles``."""
    return toy_rows(settings.replace(toy_particles=JUDGED_PARTICLES), seeds)


#: The toy's records with :data:`JUDGED_PARTICLES` (1000) RBPF particles, the count at which the
#: ledger judges the paper's RBPF (blind policy,
#: ``data/rbpf-parameter-estimation/blind/particles_reply.md``); :data:`TOY` keeps our cheaper
#: ``toy_particles`` beside it.
TOY_JUDGED = RecordStudy("rbpf-parameter-estimation", "toy_judged_particles",
                         judged_particles_rows, chunk_records=10,
                         first_record=after_the_seen_records, repeats="toy")
