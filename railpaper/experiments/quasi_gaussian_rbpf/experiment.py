"""Chapter "quasi-gaussian-rbpf": the Q-GRBPF versus the RBPF, against the exact posterior.

One record of the Q-GRBPF paper's toy (Eqs. 20–21, our reading) is filtered by

* ``rbpf``            — the RBPF as Ding et al. (2014) describe it (resample + Liu–West every
  step);
* ``rbpf_working``    — the same engine, resampling when ESS < N/2 and moving only then;
* ``qgrbpf``          — the Q-GRBPF with Eq. (10) read as an importance ratio (= 1);
* ``qgrbpf_printed``  — the Q-GRBPF with Eq. (10) read literally (weights = Gaussian density),

(and both Q-GRBPFs once more without their weight threshold, same random stream, for the
threshold claim) and compared with the exact posterior of (a, b) on a grid (uniform prior on the paper-style box).
Convergence is judged against the exact posterior: a filter "converges at step k" when from
step k on its estimate stays within two posterior standard deviations of the posterior mean
(−1: outside at the last step).  For comparison with the paper we also report the first step at
which the estimate gets within ``tolerance_to_truth`` of the true value.  The same is repeated
for ``n_monte_carlo`` records, the study :data:`MONTE_CARLO` (one row per record from record
``record`` on; the main record ``record`` is computed here in full and gives its row, the
others are mapped by the caller's record map, in this process by default); the exact posterior's readings study is the
study :data:`READINGS`.  The statistics the claim rules read are computed from the table of rows
(the reduce) by :mod:`~railpaper.experiments.quasi_gaussian_rbpf.evidence`; the computing times
(curves over N and paired repeats at the paper's N) by
:mod:`~railpaper.experiments.quasi_gaussian_rbpf.computing_time`.
``eq10_reading`` only selects which Q-GRBPF the illustrations show in full: the evidence of both
readings is always computed.  :func:`run` returns a
:class:`~railpaper.experiments.quasi_gaussian_rbpf.result.QuasiGaussianRBPFResult` (named fields).
"""

from __future__ import annotations

import time
from typing import Sequence

import numpy as np
import pandas as pd

from railpaper.engine import QuasiGaussianRBPF, RaoBlackwellisedPF, grid_posterior, run_filter
from railpaper.experiments.base import (
    ParameterError,
    check_banks,
    default_progress,
)
from railpaper.experiments.quasi_gaussian_rbpf.computing_time import operation_metrics, timing
from railpaper.experiments.quasi_gaussian_rbpf.evidence import (
    Z_SATISFACTORY,
    accuracy_gain,
    monte_carlo_metrics,
)
from railpaper.experiments.quasi_gaussian_rbpf.readings import (
    load_readings,
    readings_rows,
    study_from_rows,
)
from railpaper.experiments.quasi_gaussian_rbpf.result import (
    ComputingTime,
    OneRecord,
    QuasiGaussianRBPFResult,
)
from railpaper.experiments.quasi_gaussian_rbpf.spec import (
    FILTERS,
    NO_THRESHOLD,
    PARAMS,
    QGRBPF_READINGS,
    SPEC,
    Settings,
)
from railpaper.experiments.records import RecordMap, RecordStudy, map_in_process, normalised
from railpaper.models.linear_toys import paper004_system, simulate_paper004
from railpaper.settling import first_step, settling_step
from railpaper.threads import one_thread

EQ10_READINGS = ("ratio", "printed")


def validate(settings: Settings) -> None:
    """Refuse non-physical or inconsistent settings with one line, before any work."""
    if not settings.a_min < settings.a_true < settings.a_max:
        raise ParameterError(f"a_true={settings.a_true} must lie inside the prior box "
                             f"({settings.a_min}, {settings.a_max})")
    if not settings.b_min < settings.b_true < settings.b_max:
        raise ParameterError(f"b_true={settings.b_true} must lie inside the prior box "
                             f"({settings.b_min}, {settings.b_max})")
    if not 1.0 / 3.0 < settings.liu_west_delta <= 1.0:
        raise ParameterError(f"liu_west_delta must be in (1/3, 1], got {settings.liu_west_delta}")
    if not settings.ess_fraction <= 1.0:
        raise ParameterError(f"ess_fraction must be in (0, 1], got {settings.ess_fraction}")
    if not settings.weight_threshold < 1.0:
        raise ParameterError(f"weight_threshold must be < 1 (a fraction of 1/N), "
                             f"got {settings.weight_threshold}")
    if settings.eq10_reading not in EQ10_READINGS:
        raise ParameterError(f"eq10_reading must be one of {', '.join(EQ10_READINGS)}, "
                             f"got {settings.eq10_reading!r}")
    if max(settings.timing_particles) < 2:
        raise ParameterError("timing_particles needs at least one count >= 2")
    check_banks([("n_particles", settings.n_particles, settings.n_particles, 2, 6,
                  "the RBPF and Q-GRBPFs"),
                 ("timing_particles", list(settings.timing_particles),
                  max(settings.timing_particles) * settings.timing, 2, 6, "the timed filters"),
                 ("timing_ratio_particles", settings.timing_ratio_particles,
                  settings.timing_ratio_particles * settings.timing, 2, 6, "the timed filters"),
                 ("grid_size", settings.grid_size, settings.grid_size ** 2, 2,
                  6 + settings.n_steps, "the exact posterior's grid of Kalman filters")])


def prior_box(settings: Settings) -> tuple[np.ndarray, np.ndarray]:
    """Lower and upper corners ``(a_min, b_min)``, ``(a_max, b_max)`` of the uniform prior (1)."""
    return np.array([settings.a_min, settings.b_min]), np.array([settings.a_max, settings.b_max])


def initial_state(settings: Settings) -> tuple[np.ndarray, np.ndarray]:
    """Initial mean ``x0 = 0`` and covariance ``P0 = p0_std² I`` of every particle's Kalman
    filter (and of the exact posterior's)."""
    return np.zeros(2), settings.p0_std ** 2 * np.eye(2)


def prior_particles(settings: Settings, rng: np.random.Generator) -> np.ndarray:
    """``n_particles`` initial parameter particles (N, 2), uniform on :func:`prior_box`."""
    lower, upper = prior_box(settings)
    return lower + (upper - lower) * rng.random((settings.n_particles, 2))


def make_filter(name: str, settings: Settings, system, theta0, rng):
    """Filter ``name`` (one of FILTERS, or a Q-GRBPF name + NO_THRESHOLD)."""
    x0, P0 = initial_state(settings)
    if name == "rbpf":
        return RaoBlackwellisedPF(system, theta0, x0, P0, rng, scheme="paper",
                                  delta=settings.liu_west_delta)
    if name == "rbpf_working":
        return RaoBlackwellisedPF(system, theta0, x0, P0, rng, scheme="working",
                                  delta=settings.liu_west_delta, ess_fraction=settings.ess_fraction,
                                  tempering_steps=settings.tempering_steps)
    base = name.removesuffix(NO_THRESHOLD)
    weighting = "printed" if base == "qgrbpf_printed" else "ratio"
    threshold = 0.0 if name.endswith(NO_THRESHOLD) else settings.weight_threshold
    return QuasiGaussianRBPF(system, theta0, x0, P0, rng, weighting=weighting,
                             weight_threshold=threshold)


def streams(seed: int, replicate: int) -> dict[str, np.random.Generator]:
    """Independent generators per use (``data``, ``prior`` and one per filter), fixed by
    (seed, replicate)."""
    names = ("data", "prior") + FILTERS
    children = np.random.SeedSequence([seed, replicate]).spawn(len(names))
    return {n: np.random.default_rng(c) for n, c in zip(names, children)}


def replicate(settings: Settings, index: int) -> OneRecord:
    """Simulate record ``index``, run the four filters, the two Q-GRBPFs without threshold (on
    the same random streams as with it) and the exact posterior on it."""
    gen = streams(settings.seed, index)
    system = paper004_system(settings.q_var, settings.r_var)
    sim = simulate_paper004(settings.a_true, settings.b_true, settings.q_var, settings.r_var,
                            settings.p0_std, settings.n_steps, gen["data"])
    lower, upper = prior_box(settings)
    theta0 = prior_particles(settings, gen["prior"])
    exact = grid_posterior(system, sim.y, lower, upper, settings.grid_size,
                           *initial_state(settings))
    runs = {name: run_filter(make_filter(name, settings, system, theta0, gen[name]), sim.y)
            for name in FILTERS}
    off = {q + NO_THRESHOLD: run_filter(make_filter(q + NO_THRESHOLD, settings, system, theta0,
                                                    streams(settings.seed, index)[q]), sim.y)
           for q in QGRBPF_READINGS}
    return OneRecord(index=index, states=sim.x, measurements=sim.y, exact=exact, runs=runs,
                     runs_without_threshold=off)


def record_metrics(settings: Settings, rep: OneRecord) -> dict:
    """Per-record metrics (all filters, both parameters; final error and z of the Q-GRBPFs
    without threshold)."""
    exact, truth = rep.exact, (settings.a_true, settings.b_true)
    tol = settings.tolerance_to_truth
    short = min(settings.short_horizon, settings.n_steps) - 1  # index of that step (or the last)
    m = {}
    for j, par in enumerate(PARAMS):
        mean, std = exact.mean[:, j], exact.std[:, j]
        m[f"final_error_{par}_posterior"] = mean[-1] - truth[j]
        m[f"short_error_{par}_posterior"] = mean[short] - truth[j]
        m[f"final_std_{par}_posterior"] = std[-1]
        m[f"first_within_{par}_posterior"] = first_step(np.abs(mean - truth[j]) <= tol)
        m[f"settling_step_{par}_posterior"] = settling_step(np.abs(mean - mean[-1]) <= tol)
        below = np.flatnonzero(std <= settings.tolerance_to_truth)
        m[f"posterior_std_below_tolerance_step_{par}"] = int(below[0]) + 1 if below.size else -1
        for name, run in rep.runs.items():
            est = run.theta_mean[:, j]
            m[f"convergence_step_{par}_{name}"] = settling_step(np.abs(est - mean) <= 2.0 * std)
            m[f"first_within_{par}_{name}"] = first_step(np.abs(est - truth[j]) <= tol)
            m[f"settling_step_{par}_{name}"] = settling_step(np.abs(est - est[-1]) <= tol)
            # the same read off a figure that ended at step short_horizon (the shortest the
            # paper's can have had): the other end of the chapter's horizon bracket
            m[f"short_settling_step_{par}_{name}"] = settling_step(
                np.abs(est[:short + 1] - est[short]) <= tol)
            m[f"final_error_{par}_{name}"] = est[-1] - truth[j]
            m[f"short_error_{par}_{name}"] = est[short] - truth[j]
            m[f"final_z_{par}_{name}"] = (est[-1] - mean[-1]) / std[-1]
            m[f"final_std_ratio_{par}_{name}"] = run.theta_std[-1, j] / std[-1]
        for name, run in rep.runs_without_threshold.items():
            est = run.theta_mean[:, j]
            m[f"final_error_{par}_{name}"] = est[-1] - truth[j]
            m[f"final_z_{par}_{name}"] = (est[-1] - mean[-1]) / std[-1]
    return dict(m, **derived_columns(m, truth))


def derived_columns(m: dict, truth) -> dict:
    """The per-record columns a declaration reads directly, from the record's ``m``:
    ``abs_final_error_<p>_<f>`` (|final error|, 1), ``worst_abs_final_z_<f>`` (max over a and b
    of |final z|, posterior std), ``satisfactory_<f>`` (that at most 2: the filter ends within two
    posterior std on both parameters) and ``accuracy_gain_pct_<p>_<q>`` (the paper's accuracy gain
    of Q-GRBPF reading ``q`` over the RBPF, :func:`~railpaper.experiments.quasi_gaussian_rbpf.
    evidence.accuracy_gain`, percentage points of the truth)."""
    out = {}
    for j, par in enumerate(PARAMS):
        for name in FILTERS + ("posterior",):
            out[f"abs_final_error_{par}_{name}"] = abs(m[f"final_error_{par}_{name}"])
    for name in FILTERS + tuple(q + NO_THRESHOLD for q in QGRBPF_READINGS):
        out[f"worst_abs_final_z_{name}"] = max(abs(m[f"final_z_{par}_{name}"]) for par in PARAMS)
    for name in FILTERS:
        out[f"satisfactory_{name}"] = bool(out[f"worst_abs_final_z_{name}"] <= Z_SATISFACTORY)
    for q in QGRBPF_READINGS:
        for j, par in enumerate(PARAMS):
            out[f"accuracy_gain_pct_{par}_{q}"] = float(accuracy_gain(
                m[f"final_error_{par}_rbpf"], m[f"final_error_{par}_{q}"], truth[j]))
    return out


def record_row(settings: Settings, rep: OneRecord) -> dict:
    """Record ``rep``'s row of the Monte Carlo table: ``seed`` (= the record index) and
    :func:`record_metrics`."""
    return dict(seed=rep.index, **record_metrics(settings, rep))


def monte_carlo_rows(settings: Settings, seeds: Sequence[int]) -> pd.DataFrame:
    """The Monte Carlo rows (:func:`record_row`) of records ``seeds``, one after another on one
    thread: the chapter's per-record work (:data:`MONTE_CARLO`)."""
    with one_thread():
        return pd.DataFrame([record_row(settings, replicate(settings, int(index)))
                             for index in seeds])


#: The Monte Carlo records: one row per record (column ``seed`` = record index, the settings'
#: ``seed`` staying in the settings), a record at a time as the chapter always ran them.
def first_monte_carlo_record(settings: Settings) -> int:
    """The Monte Carlo records start at the main record (computed in full by the chapter, its
    row the same as the study's)."""
    return settings.record


def first_readings_record(settings: Settings) -> int:  # noqa: ARG001 - RecordStudy signature
    """The readings study's records count from 0 (their streams are (seed, 7004, r))."""
    return 0


MONTE_CARLO = RecordStudy(SPEC.name, "monte_carlo", monte_carlo_rows, chunk_records=1,
                          first_record=first_monte_carlo_record)

#: The readings study's records (:func:`readings_rows` of
#: :mod:`~railpaper.experiments.quasi_gaussian_rbpf.readings`): one wide row per record (every
#: reading, horizon and parameter), column ``seed`` = record.
READINGS = RecordStudy(SPEC.name, "readings", readings_rows, chunk_records=1,
                       first_record=first_readings_record)


def _timeseries(rep: OneRecord) -> pd.DataFrame:
    exact, runs = rep.exact, rep.runs
    cols = {"step": rep.steps, "y1": rep.measurements[:, 0], "y2": rep.measurements[:, 1]}
    for name in ("rbpf", "qgrbpf"):
        cols[f"a_est_{name}"], cols[f"b_est_{name}"] = runs[name].theta_mean.T
    cols["a_post_mean"], cols["b_post_mean"] = exact.mean.T
    cols["a_post_std"], cols["b_post_std"] = exact.std.T
    for name in ("rbpf_working", "qgrbpf_printed"):
        cols[f"a_est_{name}"], cols[f"b_est_{name}"] = runs[name].theta_mean.T
    for name in FILTERS:
        cols[f"a_std_{name}"], cols[f"b_std_{name}"] = runs[name].theta_std.T
        cols[f"ess_{name}"] = runs[name].ess
    cols["x1_true"], cols["x2_true"] = rep.states[1:].T
    for name in FILTERS:
        cols[f"x1_est_{name}"], cols[f"x2_est_{name}"] = runs[name].x_mean.T
    return pd.DataFrame(cols)


def _timing(settings: Settings, y: np.ndarray, progress):
    """Computing times on the main record (:func:`~railpaper.experiments.quasi_gaussian_rbpf.computing_time.timing`)."""
    system = paper004_system(settings.q_var, settings.r_var)

    def fresh_filter(name: str, n: int, repeat: int):
        gen = streams(settings.seed, repeat)
        return make_filter(name, settings, system,
                           prior_particles(settings.replace(n_particles=n), gen["prior"]),
                           gen[name])

    return timing(settings, fresh_filter, FILTERS, y, progress)


def run(settings: Settings, *, progress=None,
        record_map: RecordMap = map_in_process) -> QuasiGaussianRBPFResult:
    """Run the chapter: main record, Monte Carlo over records, computing times.

    Parameters
    ----------
    settings : Settings
        The chapter's settings (:data:`SPEC`; ``SPEC.resolve(overrides, quick)``); checked by
        :func:`validate` first.
    progress : callable, optional
        ``progress(fraction, message)``.
    record_map : callable, optional
        ``record_map(study, settings, seeds, progress)`` → the rows of ``seeds``
        (:data:`railpaper.experiments.records.RecordMap`): where the Monte Carlo records other
        than the main one (:data:`MONTE_CARLO`) and the readings study's records
        (:data:`READINGS`) are computed.  Default: in this process.

    Returns
    -------
    QuasiGaussianRBPFResult
        Metrics, timings, the main record's time series and the Monte Carlo table for the
        pipeline; the main record (:class:`OneRecord`), the Monte Carlo table and the computing
        times (:class:`ComputingTime`) as named fields.

    Notes
    -----
    Runs on one numba and one OpenBLAS thread (:func:`railpaper.threads.one_thread`), and so do
    the rows functions of the studies wherever the record map runs them.
    """
    progress = progress or default_progress()
    validate(settings)
    with one_thread():
        return _run(settings, progress, record_map)


def _run(settings: Settings, progress, record_map: RecordMap) -> QuasiGaussianRBPFResult:
    """:func:`run` on validated settings, on one numba thread."""
    start = time.perf_counter()
    main = replicate(settings, settings.record)
    first = record_row(settings, main)
    mc_table = normalised(pd.DataFrame([first]))
    first_record = MONTE_CARLO.first(settings) + 1          # after the main record
    records = list(range(first_record, first_record + settings.n_monte_carlo - 1))
    if records:
        others = record_map(MONTE_CARLO, settings, records,
                            lambda fraction, message: progress(0.9 * fraction, message))
        if list(others.columns) != list(mc_table.columns):
            raise ValueError(f"Monte Carlo rows of records {records[0]}-{records[-1]} have other "
                             f"columns than the main record's")
        mc_table = pd.concat([mc_table, others], ignore_index=True)
    mc_seconds = time.perf_counter() - start
    metrics = {k: v for k, v in first.items() if k != "seed"}
    metrics.update(monte_carlo_metrics(mc_table, settings))
    metrics["grid_min_std_over_spacing"] = main.exact.min_std_over_spacing
    metrics["grid_edge_mass"] = main.exact.edge_mass
    model = paper004_system(settings.q_var, settings.r_var)(np.zeros((1, 2)))
    (n_state, _), (n_meas, _) = model.F.shape[-2:], model.H.shape[-2:]
    metrics.update(operation_metrics(settings.timing_ratio_particles, n=n_state, p=n_meas, d=2))
    timings, timing_table, timing_samples = (_timing(settings, main.measurements, progress)
                                             if settings.timing else ({}, None, None))
    timings["monte_carlo_seconds"] = mc_seconds
    readings = None
    if settings.readings_records > 0:
        start = time.perf_counter()
        rows = record_map(READINGS, settings, range(
            READINGS.first(settings), READINGS.first(settings) + settings.readings_records),
                          lambda fraction, message: progress(0.98 + 0.02 * fraction, message))
        readings = study_from_rows(rows, *load_readings())
        metrics.update(readings.metrics())
        timings["readings_seconds"] = time.perf_counter() - start
    progress(1.0, "done")
    return QuasiGaussianRBPFResult(
        metrics=metrics, timings=timings, timeseries=_timeseries(main),
        extra_tables=dict({"records_monte_carlo": mc_table},
                          **({} if readings is None else {"readings": readings.table,
                                                          "records_readings": rows}),
                          **({} if timing_samples is None else {"timing_samples": timing_samples})),
        main=main, monte_carlo=mc_table,
        computing_time=(None if timing_table is None
                        else ComputingTime(timing_table, timing_samples)),
        readings=readings)
