"""The exact posterior of Ding et al.'s parameters, and the calibration of every filter against it.

Given θ, both of the chapter's models (the Eq. (18) toy and the 16-state lateral vehicle) are
linear-Gaussian, so a Kalman filter gives the exact likelihood p(y_1..t | θ) and the posterior
p(θ | y_1..t) under the chapter's uniform prior box needs no particle-filter approximation of θ.
IBIS (:func:`railpaper.engine.ibis.run_ibis`, Chopin 2002) samples it after every step —
reweighting by the Kalman predictive likelihood, resampling when the ESS drops, and moving the
particles with Metropolis–Hastings steps on the full-history likelihood — so it is also a
parameter filter whose target at every step is the posterior: the calibrated scheme of this
chapter.  The chapter runs it with the RBPF's own prior box, state prior (x0, P0) and noise:

* toy: the box of initial condition 1 (:data:`~railpaper.experiments.rbpf_parameter_estimation.toy.TOY_INITS` ±
  ``toy_prior_halfwidth``), x0 = 0, P0 = I, ``toy_ibis_particles`` particles, on every toy
  record (re-simulated from its seed: the same draws as the filters');
* lateral: θ × [``prior_low``, ``prior_high``], x0 = 0, P0 = 1e-10 I, the record's Q and R,
  ``ibis_particles`` particles, on the first ``ibis_records`` records.

Each sampler draws from its own generator ``[seed, 17]`` (the filters use ``seed`` (toy),
``[seed, 7]``, ``[seed, 11]`` and ``[seed, 13]`` (lateral)), so adding it changes no other
number of the chapter.  IBIS moves use the independent Gaussian proposal (Chopin's choice: on
the lateral model cheaper than the random walk for the same posterior), and at least one move
per resampling event (``MIN_MOVES``): the displacement rule of
:func:`~railpaper.engine.ibis.run_ibis` adds moves until the particles are as far from their
resampled positions as half-independent draws, so a second move is made only where the first
did not get there.

Calibration: a 90 % interval covers the truth when it holds the true value; the coverage of a
scheme is the fraction of records × parameters covered at the last step.  IBIS's interval is its
5–95 % weighted quantiles; an RBPF's is its final weighted mean ± 1.645 × weighted sd (the
Gaussian reading of the particle spread behind its estimate, Eq. 17).
"""

from __future__ import annotations

import json
from dataclasses import replace

import numpy as np
import pandas as pd

from railpaper.engine import credible_interval_covers, run_ibis
from railpaper.experiments.base import ProgressCallback, no_progress
from railpaper.experiments.rbpf_parameter_estimation import toy
from railpaper.experiments.rbpf_parameter_estimation.result import (
    LateralPart,
    LateralRecord,
    PosteriorRun,
    ToyPart,
)
from railpaper.experiments.rbpf_parameter_estimation.spec import Settings
from railpaper.experiments.records import RecordMap, RecordStudy, map_in_process, normalised
from railpaper.models import lateral_16state
from railpaper.models.linear_toys import EQ18_G, Simulation
from railpaper.settling import holds_from
from railpaper.stats import median_interval, rate
from railpaper.threads import one_thread

SEED_KEY = 17                      # the samplers' generators: [seed, SEED_KEY]
START, WITHIN = 350, 0.05          # the paper's claim: every parameter within 5 % after 350 steps
PROPOSAL = "independent"
MIN_MOVES = 1                      # moves per event: at least one, more until decorrelated


# ----------------------------------------------------------------------------- one record
def toy_box(settings: Settings, start: np.ndarray = toy.TOY_INITS[1]
            ) -> tuple[np.ndarray, np.ndarray]:
    """The RBPF's uniform prior box of the toy: ``start`` ± ``toy_prior_halfwidth`` (1)."""
    hw = settings.toy_prior_halfwidth
    return np.asarray(start, float) - hw, np.asarray(start, float) + hw


def toy_posterior(settings: Settings, sim: Simulation, seed: int,
                  start: np.ndarray = toy.TOY_INITS[1], salt: tuple[int, ...] = ()
                  ) -> PosteriorRun:
    """The exact posterior of x1..x4 after every step of one toy record (IBIS, generator
    ``[seed, 17, *salt]``) under the RBPF's prior box around ``start``, x0 = 0, P0 = I."""
    lower, upper = toy_box(settings, start)
    run = run_ibis(toy.system(settings), sim.y, lower, upper, np.zeros(2), np.eye(2),
                   np.random.default_rng([seed, SEED_KEY, *salt]), u=sim.u,
                   n_particles=settings.toy_ibis_particles, proposal=PROPOSAL, min_moves=MIN_MOVES)
    return PosteriorRun.from_ibis(run)


def lateral_posterior(settings: Settings, system, record: LateralRecord, theta: np.ndarray,
                      seed: int) -> PosteriorRun:
    """The exact posterior of θ after every step of one lateral record, divided by the true θ:
    IBIS (generator ``[seed, 17]``) on the filters' model ``system`` (from
    :func:`~railpaper.experiments.rbpf_parameter_estimation.lateral.record_system`) with the RBPF's
    box θ × [``prior_low``, ``prior_high``] and state prior x0 = 0, P0 = 1e-10 I."""
    run = run_ibis(system, record.y, settings.prior_low * theta, settings.prior_high * theta,
                   np.zeros(lateral_16state.N_STATES), 1e-10 * np.eye(lateral_16state.N_STATES),
                   np.random.default_rng([seed, SEED_KEY]), u=record.u_mps,
                   n_particles=settings.ibis_particles, proposal=PROPOSAL, min_moves=MIN_MOVES)
    return PosteriorRun.from_ibis(run, theta)


# ----------------------------------------------------------------------------- toy, every record
def _calibration_row(seed: int, post: PosteriorRun, truth: np.ndarray) -> dict:
    """One toy record's exact posterior after the last step: per parameter its mean, its 5 and
    95 % quantiles and whether that interval holds the true value (dimensionless)."""
    covers = credible_interval_covers(post, truth)
    row = {"seed": int(seed)}
    for j in range(4):
        row[f"posterior_mean_x{j + 1}"] = float(post.mean[-1, j])
        row[f"posterior_q05_x{j + 1}"] = float(post.q05[-1, j])
        row[f"posterior_q95_x{j + 1}"] = float(post.q95[-1, j])
        row[f"posterior_covers_x{j + 1}"] = bool(covers[j])
    return row


def toy_calibration_rows(settings: Settings, seeds) -> pd.DataFrame:
    """The study :data:`TOY_CALIBRATION`'s rows: per seed, :func:`_calibration_row` of the
    exact posterior (:func:`toy_posterior`, initial condition 1's box) on the record the toy
    study filtered (:func:`~railpaper.experiments.rbpf_parameter_estimation.toy.simulate` on
    ``default_rng(seed)``)."""
    truth, rows = toy.truth(settings), []
    with one_thread():
        for seed in seeds:
            sim = toy.simulate(settings, np.random.default_rng(int(seed)))
            rows.append(_calibration_row(seed, toy_posterior(settings, sim, int(seed)), truth))
    return pd.DataFrame(rows)


#: The toy's calibration records: the exact posterior of every toy record after the illustrated
#: one, up to ``toy_ibis_records`` (the illustrated record's is computed in full in the run).
TOY_CALIBRATION = RecordStudy("rbpf-parameter-estimation", "toy_calibration",
                              toy_calibration_rows, chunk_records=10)


def toy_posteriors(settings: Settings, part: ToyPart, record_map: RecordMap = map_in_process,
                   progress: ProgressCallback = no_progress) -> ToyPart:
    """IBIS on the first ``toy_ibis_records`` toy records of ``part`` (records ``seed`` …,
    initial condition 1's box): the illustrated record ``seed`` in full here, the others as the
    rows of :data:`TOY_CALIBRATION` through ``record_map``; returns ``part`` with
    :attr:`ToyPart.record`, :attr:`~ToyPart.posterior` (the illustrated record) and
    :attr:`~ToyPart.coverage` (one row per record × parameter) filled."""
    n_records = min(settings.toy_ibis_records, settings.toy_seeds)
    sim = toy.simulate(settings, np.random.default_rng(settings.seed))  # run_toy's record
    post = toy_posterior(settings, sim, settings.seed)
    wide = normalised(pd.DataFrame([_calibration_row(settings.seed, post, part.truth)]))
    if n_records > 1:
        others = record_map(TOY_CALIBRATION, settings,
                            range(settings.seed + 1, settings.seed + n_records), progress)
        wide = pd.concat([wide, others], ignore_index=True)
    one = part.records[part.records.init == 1].set_index("seed")
    rows = []
    for record in wide.to_dict("records"):
        seed = int(record["seed"])
        for j in range(4):
            name = f"x{j + 1}"
            rows.append(dict(seed=seed, parameter=name, truth=part.truth[j],
                             posterior_mean=record[f"posterior_mean_{name}"],
                             posterior_q05=record[f"posterior_q05_{name}"],
                             posterior_q95=record[f"posterior_q95_{name}"],
                             posterior_covers=bool(record[f"posterior_covers_{name}"]),
                             paper_covers=bool(one.loc[seed, f"rbpf_covers_{name}"]),
                             tempered_covers=bool(one.loc[seed, f"rbpf_working_covers_{name}"])))
    return replace(part, record=sim, posterior=post, coverage=pd.DataFrame(rows))


def toy_metrics(part: ToyPart) -> dict:
    """Coverage of the 90 % intervals over toy records × parameters (initial condition 1):
    ``coverage_90_exact_posterior_toy`` (IBIS), ``coverage_90_paper_scheme_toy``,
    ``coverage_90_tempered_toy`` (our tempered RBPF), each with ``_low``, ``_high``, ``_n``
    (95 % Clopper–Pearson); and the illustrated record's posterior sd after the last step,
    ``toy_posterior_sd_final_x<j>``."""
    c = part.coverage
    out = {}
    for column, name in (("posterior_covers", "exact_posterior"),
                         ("paper_covers", "paper_scheme"), ("tempered_covers", "tempered")):
        out.update(rate(c[column].to_numpy(bool)).metrics(f"coverage_90_{name}_toy"))
    for j in range(4):
        out[f"toy_posterior_sd_final_x{j + 1}"] = float(part.posterior.sd[-1, j])
    return out


def toy_record_table(sim: Simulation) -> pd.DataFrame:
    """``toy_record.csv``: ``step`` (1..K), ``u`` (u_k, the input of the transition into step
    k) and ``y`` (y_k), dimensionless."""
    return pd.DataFrame({"step": np.arange(1, len(sim.y) + 1), "u": sim.u[:, 0], "y": sim.y[:, 0]})


def toy_posterior_json(settings: Settings, post: PosteriorRun) -> str:
    """``toy_posterior.json``: the toy record's exact-posterior reference — the uniform prior
    box, the state prior before the first transition, the noise variances, and the posterior
    mean and sd of x1..x4 after the last step (IBIS)."""
    lower, upper = toy_box(settings)
    doc = dict(model="Ding et al. (2014) Eq. (18): X(n) = [[0, 1.5], [x1, x2]] X(n-1) + "
               "[x3, x4]' u(n) + G W(n-1), y(n) = [1, 0] X(n) + V(n), G = "
               f"{EQ18_G[:, 0].tolist()}'; u(n) in column u of toy_record.csv",
               prior_lower=lower.tolist(), prior_upper=upper.tolist(), x0=[0.0, 0.0],
               P0=np.eye(2).tolist(), w_var=settings.toy_noise_var,
               v_var=settings.toy_noise_var,
               step=int(post.mean.shape[0]), mean=post.mean[-1].tolist(),
               sd=post.sd[-1].tolist(), sampler=f"IBIS, {post.particles} particles")
    return json.dumps(doc, indent=2) + "\n"


# ----------------------------------------------------------------------------- lateral
def lateral_metrics(part: LateralPart, simulated: bool = True) -> dict:
    """Statistics of the exact posterior over the lateral records that have it.

    Returns
    -------
    dict
        Of the illustrated record: ``posterior_sd_rel_<k>_<param>`` and
        ``posterior_mean_rel_error_<k>_<param>`` (sd / true value and mean / true value − 1 at
        step k = 100, 350 and ``final``), 1.  Over records (simulated only), each with
        ``_low``, ``_high``, ``_n`` (95 %): ``lateral_within_5pct_from_350_rate_posterior``
        (the posterior mean keeps every parameter within 5 % from step 350 to the end),
        ``posterior_sd_rel_350_max`` (median over records of the largest relative posterior sd
        at step 350), ``posterior_sd_rel_350_median_<param>`` (median over records), and the
        coverage of the 90 % intervals at the last step over records × parameters:
        ``coverage_90_exact_posterior_lateral`` (IBIS), ``coverage_90_paper_scheme_lateral``,
        ``coverage_90_tempered_lateral`` (our tempered RBPF).
    """
    runs = [r for r in part.runs if r.posterior is not None]
    out = {}
    first = runs[0].posterior
    for j, name in enumerate(lateral_16state.PARAM_NAMES):
        for label, k in (("100", 100), ("350", START), ("final", len(first.mean))):
            out[f"posterior_sd_rel_{label}_{name}"] = float(first.sd[k - 1, j])
            out[f"posterior_mean_rel_error_{label}_{name}"] = float(first.mean[k - 1, j] - 1)
    if not simulated:
        return out
    out.update(rate([holds_from(np.abs(r.posterior.mean - 1.0) <= WITHIN, START).all()
                     for r in runs])
               .metrics("lateral_within_5pct_from_350_rate_posterior"))
    sd350 = np.array([r.posterior.sd[START - 1] for r in runs])
    out.update(median_interval(sd350.max(axis=1)).metrics("posterior_sd_rel_350_max"))
    for j, name in enumerate(lateral_16state.PARAM_NAMES):
        out.update(median_interval(sd350[:, j]).metrics(f"posterior_sd_rel_350_median_{name}"))
    ones = np.ones(len(lateral_16state.PARAM_NAMES))
    covers = {"exact_posterior": [credible_interval_covers(r.posterior, ones) for r in runs],
              "paper_scheme": [toy.gaussian_covers(r.rbpf_paper_norm[-1],
                                                   r.rbpf_paper_sd_norm[-1], 1.0) for r in runs],
              "tempered": [toy.gaussian_covers(r.rbpf_working_norm[-1],
                                               r.rbpf_working_sd_norm[-1], 1.0) for r in runs]}
    for name, flags in covers.items():
        out.update(rate(np.array(flags)).metrics(f"coverage_90_{name}_lateral"))
    return out


__all__ = ["PROPOSAL", "SEED_KEY", "TOY_CALIBRATION", "lateral_metrics", "lateral_posterior",
           "toy_box", "toy_calibration_rows", "toy_metrics", "toy_posterior", "toy_posterior_json",
           "toy_posteriors", "toy_record_table"]
