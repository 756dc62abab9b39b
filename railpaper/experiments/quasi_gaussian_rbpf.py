"""Chapter "quasi-gaussian-rbpf": paper 004's Q-GRBPF versus the RBPF, against the exact posterior.

One record of paper 004's toy (Eqs. 20–21, our reading) is filtered by

* ``rbpf``            — the RBPF as papers 003/004 describe it (resample + Liu–West every step);
* ``rbpf_working``    — the same engine, resampling when ESS < N/2 and moving only then;
* ``qgrbpf``          — the Q-GRBPF with Eq. (10) read as an importance ratio (= 1);
* ``qgrbpf_printed``  — the Q-GRBPF with Eq. (10) read literally (weights = Gaussian density),

and compared with the exact posterior of (a, b) on a grid (uniform prior on the paper-style box).
Convergence is judged against the exact posterior: a filter "converges at step k" when from
step k on its estimate stays within two posterior standard deviations of the posterior mean
(−1: outside at the last step).  For comparison with the paper we also report the first step at
which the estimate gets within ``tolerance_to_truth`` of the true value.  The same is repeated
for ``n_monte_carlo`` records (replicate ``record`` is the main record, the others follow it); the
records other than the main one are run by a caller-supplied function (the notebook runs them as a
sweep on worker processes, each sample being this module's ``run`` for one record) or in this
process.  The computing time of each filter is measured on the main record for several particle
counts.
"""

from __future__ import annotations

import time

import numpy as np
import pandas as pd

from railpaper.estimators.grid_posterior import grid_posterior
from railpaper.estimators.particles import systematic_resample
from railpaper.estimators.qgrbpf import QuasiGaussianRBPF
from railpaper.estimators.rbpf import RaoBlackwellisedPF, run_filter
from railpaper.experiments.base import (ChapterResult, ChapterSpec, Parameter, ParameterError,
                                        no_progress)
from railpaper.experiments.quasi_gaussian_rbpf_claims import claims_table  # noqa: F401
from railpaper.models.linear_toys import paper004_system, simulate_paper004
from railpaper.settling import settled_index

P = Parameter
SPEC = ChapterSpec(
    name="quasi-gaussian-rbpf",
    title="Quasi-Gaussian RBPF versus RBPF for parameter estimation",
    paper="004_e1cb56090c839832.txt",
    notebook="quasi_gaussian_rbpf.ipynb",
    quick_sizes="300 particles, 200 steps, 61x61 grid, 8 Monte Carlo records, timing up to N=1000",
    notebook_requires={"timing": True},
    parameters=[
        P("a_true", -0.7, "float", "true parameter a of Eq. (20), 1"),
        P("b_true", 1.5, "float", "true parameter b of Eq. (20), 1"),
        P("q_var", 0.001, "float", "variance of each process-noise component w, 1", positive=True),
        P("r_var", 0.001, "float", "variance of each measurement-noise component e, 1",
          positive=True),
        P("p0_std", 0.05, "float", "initial state standard deviation (P0 = p0_std^2 I), 1",
          positive=True),
        P("n_particles", 1000, "int", "particles of every filter", quick=300, minimum=2),
        P("n_steps", 300, "int", "measurements per record", quick=200, minimum=2),
        P("a_min", -1.0, "float", "lower bound of the uniform prior on a, 1"),
        P("a_max", 0.4, "float", "upper bound of the uniform prior on a, 1"),
        P("b_min", 1.0, "float", "lower bound of the uniform prior on b, 1"),
        P("b_max", 2.8, "float", "upper bound of the uniform prior on b, 1"),
        P("liu_west_delta", 0.98, "float", "Liu-West discount factor delta of the RBPF move, 1",
          positive=True),
        P("ess_fraction", 0.5, "float", "working RBPF resamples when ESS < ess_fraction N, 1",
          positive=True),
        P("tempering_steps", 0, "int", "working RBPF likelihood tempering steps (0 = off)",
          minimum=0),
        P("weight_threshold", 0.01, "float",
          "Q-GRBPF drops likelihood weights below weight_threshold/N, 1", minimum=0.0),
        P("grid_size", 81, "int", "grid points per parameter of the exact posterior",
          quick=61, minimum=3),
        P("n_monte_carlo", 50, "int", "records (seeds) of the Monte Carlo study", quick=8,
          minimum=1),
        P("record", 0, "int", "index of the main record (random streams (seed, record)); the "
          "Monte Carlo records are record+1, record+2, …", minimum=0),
        P("timing", True, "bool", "measure computing times (false: a Monte Carlo sample of a "
          "sweep, which needs only the record's metrics)"),
        P("timing_particles", [100, 300, 1000, 3000, 10000], "list[int]",
          "particle counts of the computing-time comparison", quick=[100, 300, 1000],
          positive=True),
        P("timing_steps", 100, "int", "steps timed per filter and particle count", quick=50,
          minimum=1),
        P("timing_repeats", 3, "int", "repeats per timing (the fastest is kept)", quick=3,
          minimum=1),
        P("tolerance_to_truth", 0.05, "float",
          "paper-like convergence: first step with |estimate - truth| below this, 1",
          positive=True),
        P("seed", 0, "int", "seed of records, initial particles and filters", minimum=0),
    ],
)

FILTERS = ("rbpf", "rbpf_working", "qgrbpf", "qgrbpf_printed")
PARAMS = ("a", "b")


def validate(p: dict) -> None:
    """Refuse non-physical or inconsistent resolved parameters with one line, before any work."""
    if not p["a_min"] < p["a_true"] < p["a_max"]:
        raise ParameterError(f"a_true={p['a_true']} must lie inside the prior box "
                             f"({p['a_min']}, {p['a_max']})")
    if not p["b_min"] < p["b_true"] < p["b_max"]:
        raise ParameterError(f"b_true={p['b_true']} must lie inside the prior box "
                             f"({p['b_min']}, {p['b_max']})")
    if not 1.0 / 3.0 < p["liu_west_delta"] <= 1.0:
        raise ParameterError(f"liu_west_delta must be in (1/3, 1], got {p['liu_west_delta']}")
    if not p["ess_fraction"] <= 1.0:
        raise ParameterError(f"ess_fraction must be in (0, 1], got {p['ess_fraction']}")
    if not p["weight_threshold"] < 1.0:
        raise ParameterError(f"weight_threshold must be < 1 (a fraction of 1/N), "
                             f"got {p['weight_threshold']}")
    if max(p["timing_particles"]) < 2:
        raise ParameterError("timing_particles needs at least one count >= 2")


def _box(p: dict) -> tuple[np.ndarray, np.ndarray]:
    return np.array([p["a_min"], p["b_min"]]), np.array([p["a_max"], p["b_max"]])


def _make_filter(name: str, p: dict, system, theta0, rng):
    x0, P0 = np.zeros(2), p["p0_std"] ** 2 * np.eye(2)
    if name == "rbpf":
        return RaoBlackwellisedPF(system, theta0, x0, P0, rng, scheme="paper",
                                  delta=p["liu_west_delta"])
    if name == "rbpf_working":
        return RaoBlackwellisedPF(system, theta0, x0, P0, rng, scheme="working",
                                  delta=p["liu_west_delta"], ess_fraction=p["ess_fraction"],
                                  tempering_steps=p["tempering_steps"])
    weighting = "printed" if name == "qgrbpf_printed" else "ratio"
    return QuasiGaussianRBPF(system, theta0, x0, P0, rng, weighting=weighting,
                             weight_threshold=p["weight_threshold"])


def _streams(seed: int, replicate: int) -> dict[str, np.random.Generator]:
    """Independent generators per use, fixed by (seed, replicate)."""
    names = ("data", "prior") + FILTERS
    children = np.random.SeedSequence([seed, replicate]).spawn(len(names))
    return {n: np.random.default_rng(c) for n, c in zip(names, children)}


def convergence_step(estimate: np.ndarray, post_mean: np.ndarray, post_std: np.ndarray,
                     n_std: float = 2.0) -> int:
    """First step (1-based) from which |estimate − posterior mean| ≤ n_std · posterior std
    holds until the end; −1 if it fails at the last step."""
    index = settled_index(np.abs(estimate - post_mean) <= n_std * post_std)
    return -1 if index < 0 else index + 1


def first_within(estimate: np.ndarray, truth: float, tolerance: float) -> int:
    """First step (1-based) with |estimate − truth| ≤ tolerance; −1 if never."""
    hits = np.flatnonzero(np.abs(estimate - truth) <= tolerance)
    return int(hits[0]) + 1 if hits.size else -1


def settling_step(estimate: np.ndarray, tolerance: float) -> int:
    """First step (1-based) from which the estimate stays within ``tolerance`` of its own final
    value (what one reads off a plot as "converged")."""
    return settled_index(np.abs(estimate - estimate[-1]) <= tolerance) + 1


def replicate(p: dict, index: int) -> dict:
    """Simulate record ``index``, run the four filters and the exact posterior on it."""
    streams = _streams(p["seed"], index)
    system = paper004_system(p["q_var"], p["r_var"])
    sim = simulate_paper004(p["a_true"], p["b_true"], p["q_var"], p["r_var"], p["p0_std"],
                            p["n_steps"], streams["data"])
    lower, upper = _box(p)
    theta0 = lower + (upper - lower) * streams["prior"].random((p["n_particles"], 2))
    exact = grid_posterior(system, sim.y, lower, upper, p["grid_size"], np.zeros(2),
                           p["p0_std"] ** 2 * np.eye(2))
    runs = {name: run_filter(_make_filter(name, p, system, theta0, streams[name]), sim.y)
            for name in FILTERS}
    return dict(sim=sim, exact=exact, runs=runs)


def _record_metrics(p: dict, rep: dict) -> dict:
    """Per-record metrics (all filters, both parameters)."""
    exact, truth = rep["exact"], (p["a_true"], p["b_true"])
    m = {}
    for j, par in enumerate(PARAMS):
        mean, std = exact.mean[:, j], exact.std[:, j]
        m[f"final_error_{par}_posterior"] = mean[-1] - truth[j]
        m[f"final_std_{par}_posterior"] = std[-1]
        m[f"first_within_{par}_posterior"] = first_within(mean, truth[j], p["tolerance_to_truth"])
        m[f"settling_step_{par}_posterior"] = settling_step(mean, p["tolerance_to_truth"])
        below = np.flatnonzero(std <= p["tolerance_to_truth"])
        m[f"posterior_std_below_tolerance_step_{par}"] = int(below[0]) + 1 if below.size else -1
        for name, run in rep["runs"].items():
            est = run.theta_mean[:, j]
            m[f"convergence_step_{par}_{name}"] = convergence_step(est, mean, std)
            m[f"first_within_{par}_{name}"] = first_within(est, truth[j], p["tolerance_to_truth"])
            m[f"settling_step_{par}_{name}"] = settling_step(est, p["tolerance_to_truth"])
            m[f"final_error_{par}_{name}"] = est[-1] - truth[j]
            m[f"final_z_{par}_{name}"] = (est[-1] - mean[-1]) / std[-1]
            m[f"final_std_ratio_{par}_{name}"] = run.theta_std[-1, j] / std[-1]
    return m


def _quantile_steps(steps: np.ndarray, n_steps: int, q: float) -> int:
    """Quantile of convergence steps with 'never' (−1) counted as later than the last step."""
    value = np.quantile(np.where(steps < 0, n_steps + 1, steps), q, method="inverted_cdf")
    return -1 if value > n_steps else int(value)


def _monte_carlo_metrics(p: dict, table: pd.DataFrame) -> dict:
    m = {"mc_records": len(table)}
    for par in PARAMS:
        for name in FILTERS:
            steps = table[f"convergence_step_{par}_{name}"].to_numpy()
            for label, q in (("q10", 0.1), ("median", 0.5), ("q90", 0.9)):
                m[f"mc_{label}_convergence_step_{par}_{name}"] = _quantile_steps(
                    steps, p["n_steps"], q)
            m[f"mc_never_converged_fraction_{par}_{name}"] = float(np.mean(steps < 0))
            first = table[f"first_within_{par}_{name}"].to_numpy()
            m[f"mc_median_first_within_{par}_{name}"] = _quantile_steps(first, p["n_steps"], 0.5)
            settle = table[f"settling_step_{par}_{name}"].to_numpy()
            m[f"mc_median_settling_step_{par}_{name}"] = _quantile_steps(settle, p["n_steps"], 0.5)
            err = table[f"final_error_{par}_{name}"].to_numpy()
            m[f"mc_median_abs_final_error_{par}_{name}"] = float(np.median(np.abs(err)))
            m[f"mc_rms_final_error_{par}_{name}"] = float(np.sqrt(np.mean(err ** 2)))
            z = table[f"final_z_{par}_{name}"].to_numpy()
            m[f"mc_median_abs_final_z_{par}_{name}"] = float(np.median(np.abs(z)))
            m[f"mc_within_2std_fraction_{par}_{name}"] = float(np.mean(np.abs(z) <= 2.0))
            ratio = table[f"final_std_ratio_{par}_{name}"].to_numpy()
            m[f"mc_median_final_std_ratio_{par}_{name}"] = float(np.median(ratio))
        err = table[f"final_error_{par}_posterior"].to_numpy()
        m[f"mc_median_abs_final_error_{par}_posterior"] = float(np.median(np.abs(err)))
        m[f"mc_rms_final_error_{par}_posterior"] = float(np.sqrt(np.mean(err ** 2)))
        m[f"mc_median_final_std_{par}_posterior"] = float(
            np.median(table[f"final_std_{par}_posterior"]))
        m[f"mc_median_settling_step_{par}_posterior"] = _quantile_steps(
            table[f"settling_step_{par}_posterior"].to_numpy(), p["n_steps"], 0.5)
    return m


def _timeseries(p: dict, rep: dict) -> pd.DataFrame:
    sim, exact, runs = rep["sim"], rep["exact"], rep["runs"]
    cols = {"step": np.arange(1, p["n_steps"] + 1), "y1": sim.y[:, 0], "y2": sim.y[:, 1]}
    for name in ("rbpf", "qgrbpf"):
        cols[f"a_est_{name}"], cols[f"b_est_{name}"] = runs[name].theta_mean.T
    cols["a_post_mean"], cols["b_post_mean"] = exact.mean.T
    cols["a_post_std"], cols["b_post_std"] = exact.std.T
    for name in ("rbpf_working", "qgrbpf_printed"):
        cols[f"a_est_{name}"], cols[f"b_est_{name}"] = runs[name].theta_mean.T
    for name in FILTERS:
        cols[f"a_std_{name}"], cols[f"b_std_{name}"] = runs[name].theta_std.T
        cols[f"ess_{name}"] = runs[name].ess
    cols["x1_true"], cols["x2_true"] = sim.x[1:].T
    for name in FILTERS:
        cols[f"x1_est_{name}"], cols[f"x2_est_{name}"] = runs[name].x_mean.T
    return pd.DataFrame(cols)


def _resampling_cost(p: dict, counts: list[int], table: pd.DataFrame) -> dict:
    """Seconds of one systematic resampling (indices + copying θ, x, P) as a share of an RBPF
    step: the cost the paper says dominates."""
    out = {}
    rng = np.random.default_rng(p["seed"])
    for n in counts:
        w = rng.random(n)
        w /= w.sum()
        arrays = (rng.random((n, 2)), rng.random((n, 2)), rng.random((n, 2, 2)))
        best = np.inf
        for _ in range(p["timing_repeats"]):
            start = time.perf_counter()
            for _ in range(20):
                idx = systematic_resample(w, rng)
                _ = [a[idx] for a in arrays]
            best = min(best, (time.perf_counter() - start) / 20)
        step = table.query("filter == 'rbpf' and n_particles == @n")["seconds_per_step"].iloc[0]
        out[f"resampling_share_of_rbpf_step_N{n}"] = best / step
    return out


def _timing(p: dict, y: np.ndarray, progress) -> tuple[dict, pd.DataFrame]:
    """Seconds per step of every filter at every N (fastest of ``timing_repeats``)."""
    system = paper004_system(p["q_var"], p["r_var"])
    lower, upper = _box(p)
    counts = sorted(set(int(n) for n in p["timing_particles"] if n >= 2) | {p["n_particles"]})
    y = y[: p["timing_steps"]]
    rows = []
    for i, n in enumerate(counts):
        progress(0.9 + 0.1 * i / len(counts), f"timing N={n}")
        best = {name: np.inf for name in FILTERS}
        for r in range(p["timing_repeats"]):
            for name in FILTERS:                       # interleaved: same machine load
                streams = _streams(p["seed"], 10_000 + r)
                theta0 = lower + (upper - lower) * streams["prior"].random((n, 2))
                filt = _make_filter(name, p, system, theta0, streams[name])
                start = time.perf_counter()
                run_filter(filt, y)
                best[name] = min(best[name], (time.perf_counter() - start) / len(y))
        rows += [dict(filter=name, n_particles=n, seconds_per_step=best[name]) for name in FILTERS]
    table = pd.DataFrame(rows)
    timings = _resampling_cost(p, counts, table)
    timings.update({f"seconds_per_step_{r.filter}_N{r.n_particles}": r.seconds_per_step
               for r in table.itertuples()})
    per = table.pivot(index="n_particles", columns="filter", values="seconds_per_step")
    for n in per.index:
        timings[f"time_ratio_qgrbpf_over_rbpf_N{n}"] = per.loc[n, "qgrbpf"] / per.loc[n, "rbpf"]
    timings["time_ratio_qgrbpf_over_rbpf"] = timings[
        f"time_ratio_qgrbpf_over_rbpf_N{p['n_particles']}"]
    timings["time_saving_qgrbpf_vs_rbpf_percent"] = 100.0 * (
        1.0 - timings["time_ratio_qgrbpf_over_rbpf"])
    return timings, table


def records_in_process(p: dict, records: list[int], progress=no_progress) -> pd.DataFrame:
    """Per-record metrics (column ``replicate`` = record index) of ``records``, one by one."""
    rows = []
    for i, index in enumerate(records):
        progress(0.9 * (i + 1) / (len(records) + 1), f"Monte Carlo record {i + 1}/{len(records)}")
        rows.append(dict(replicate=index, **_record_metrics(p, replicate(p, index))))
    return pd.DataFrame(rows)


def run(*, quick: bool = False, progress=None, monte_carlo=None, **params) -> ChapterResult:
    """Run the chapter: main record, Monte Carlo over records, computing times.

    Parameters
    ----------
    quick : bool
        The chapter's quick sizes for parameters not given.
    progress : callable, optional
        ``progress(fraction, message)``.
    monte_carlo : callable, optional
        ``monte_carlo(p, records, progress)`` → DataFrame with a ``replicate`` column (the record
        index) and the per-record metrics of ``records`` (all but the main record), e.g. a sweep
        of this function with ``n_monte_carlo = 1``, ``timing = False`` and ``record`` as the grid.
        Default: :func:`records_in_process`.
    **params
        Chapter parameters (:data:`SPEC`).
    """
    progress = progress or no_progress
    p = SPEC.resolve(params, quick)        # idempotent on resolved parameters; fills gaps
    validate(p)
    start = time.perf_counter()
    main = replicate(p, p["record"])
    first = dict(replicate=p["record"], **_record_metrics(p, main))
    records = list(range(p["record"] + 1, p["record"] + p["n_monte_carlo"]))
    mc_table = pd.DataFrame([first])
    if records:
        others = (monte_carlo or records_in_process)(p, records, progress)
        missing = sorted(set(first) - set(others.columns))
        if missing or sorted(others["replicate"]) != records:
            raise ValueError(f"Monte Carlo records incomplete: expected records {records[0]}-"
                             f"{records[-1]}{', columns ' + ', '.join(missing[:3]) if missing else ''}")
        others = others.sort_values("replicate", kind="stable")[list(first)]
        mc_table = pd.concat([mc_table, others], ignore_index=True)
    mc_seconds = time.perf_counter() - start
    metrics = {k: v for k, v in first.items() if k != "replicate"}
    metrics.update(_monte_carlo_metrics(p, mc_table))
    exact = main["exact"]
    metrics["grid_min_std_over_spacing"] = exact.min_std_over_spacing
    metrics["grid_edge_mass"] = exact.edge_mass
    metrics["paper_accuracy_gain_a_percent"] = 100.0 * (
        abs(metrics["final_error_a_rbpf"]) - abs(metrics["final_error_a_qgrbpf"])) / abs(p["a_true"])
    metrics["paper_accuracy_gain_b_percent"] = 100.0 * (
        abs(metrics["final_error_b_rbpf"]) - abs(metrics["final_error_b_qgrbpf"])) / abs(p["b_true"])
    timings, timing_table = _timing(p, main["sim"].y, progress) if p["timing"] else ({}, None)
    timings["monte_carlo_seconds"] = mc_seconds
    progress(1.0, "done")
    return ChapterResult(
        metrics=metrics, timings=timings, timeseries=_timeseries(p, main),
        extra_tables={"monte_carlo": mc_table},
        data={"timing_table": timing_table, "exact": exact, "runs": main["runs"],
              "sim": main["sim"], "monte_carlo": mc_table, "filters": FILTERS})
