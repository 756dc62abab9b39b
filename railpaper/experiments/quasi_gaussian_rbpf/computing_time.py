"""Computing times of chapter ``quasi-gaussian-rbpf`` (paper 004, Fig. 5): wall clock.

Two measurements, both on the chapter's main record:

* **curves** (the figure): seconds per step of every filter at every particle count in
  ``timing_particles`` (fastest of ``timing_repeats`` runs, filters interleaved);
* **paired repeats** (the evidence of the computing-time claims): at ``timing_ratio_particles``
  (the paper's N = 1000), ``timing_ratio_repeats`` repeats, each timing the RBPF and the
  Q-GRBPF under both readings of Eq. (10) back to back (median seconds of one step over the
  record's steps), then one systematic resampling of the RBPF's bank (indices and copies of θ,
  x, P; median of 20 calls).  Ratios are taken within a repeat, so the machine load a repeat
  sees cancels; the median over repeats comes with its distribution-free 95 % interval
  (:func:`railpaper.stats.median_interval`).

The claims on computing time are decided on a third measure that no machine load moves: the
**operations per step** each algorithm does, counted from its steps (:func:`operations_per_step`);
the wall clock is shown beside it.

Everything is timed on one thread (:func:`railpaper.threads.one_thread`): the comparison is of
the work each algorithm does per step, and a parallel Kalman bank on a machine busy with other
processes spends most of its time waiting for its threads, which would swamp the resampling
share.  Wall-clock numbers are not
reproducible bit for bit: they go to ``timings.json``.
"""

from __future__ import annotations

import time
from typing import Callable

import numpy as np
import pandas as pd

from railpaper.engine import bank_multiply_adds, run_filter, systematic_resample
from railpaper.experiments.quasi_gaussian_rbpf.spec import Settings
from railpaper.stats import median_interval
from railpaper.threads import one_thread
from railpaper.timing import interleaved

#: Filters timed in the paired repeats: the RBPF, then the Q-GRBPF under both readings.
PAIRED = ("rbpf", "qgrbpf", "qgrbpf_printed")
RESAMPLING_CALLS = 20


def operations_per_step(name: str, n_particles: int, n: int, p: int, d: int, m: int = 0
                        ) -> dict[str, int]:
    """Floating-point operations of one step of filter ``name`` (``rbpf``: the paper scheme,
    resample and move every step; ``qgrbpf``, ``qgrbpf_printed``: paper 004's Steps (1)-(6)),
    counted from the algorithm, by part.

    Counting convention: a multiply-add, a comparison, an exp/log or one random variate is one
    operation; copying a number is one.  N particles, state dimension n, p measurements, m
    inputs, d parameters.  Both filters share the Kalman bank (one prediction and update per
    particle, :func:`railpaper.engine.kalman_bank.multiply_adds`), the weights (max, exp, sum:
    3N, ESS 2N), the parameter moments (mean N d, centring N d, covariance N d²), the state's
    mixture moments (5 N n) and the new matrices of the N new parameter vectors (N n² entries
    of F(θ)).  The RBPF adds systematic resampling (cumulative sum N, merge N, one uniform,
    copies N (d + n + n²)) and the Liu–West move (Cholesky d³/6, shrinkage 2 N d, draws N d,
    L z: N d(d+1)/2).  The Q-GRBPF adds the weight threshold (2N), the Gaussian draws of Eq. 9
    (Cholesky d³/6, N d variates, L z N d(d+1)/2), the weights of Eqs. 10-11 (3N; the printed
    reading also evaluates the density of each draw, N (d(d+1)/2 + 2d)) and the search of
    Eqs. 16-17 (N uniforms, cumulative sum N, N ⌈log₂ N⌉ comparisons, copies N (d + n + n²)).
    """
    N = n_particles
    log2 = int(np.ceil(np.log2(max(N, 2))))
    common = {"kalman bank": N * bank_multiply_adds(n, p, m), "weights": 5 * N,
              "parameter moments": N * (2 * d + d * d), "state moments": 5 * N * n,
              "new matrices": N * n * n}
    copies = N * (d + n + n * n)
    draws = d ** 3 // 6 + N * d + N * d * (d + 1) // 2
    if name == "rbpf":
        return {**common, "resampling (systematic)": 2 * N + 1 + copies,
                "Liu-West move": draws + 2 * N * d}
    if name in ("qgrbpf", "qgrbpf_printed"):
        density = N * (d * (d + 1) // 2 + 2 * d) if name == "qgrbpf_printed" else 0
        return {**common, "weight threshold": 2 * N, "Gaussian draws (Eq. 9)": draws,
                "weights of Eqs. 10-11": 3 * N + density,
                "search (Eqs. 16-17)": N + N + N * log2 + copies}
    raise ValueError(f"no operation count for filter {name!r}")


def operation_metrics(n_particles: int, n: int, p: int, d: int, m: int = 0) -> dict:
    """``operations_per_step_<f>`` of every :data:`PAIRED` filter at ``n_particles``,
    ``operation_ratio_<q>_over_rbpf`` of each Q-GRBPF reading and
    ``operation_share_resampling_of_rbpf_step`` (the systematic resampling's share of an RBPF
    step's operations) (deterministic: metrics.json)."""
    parts = {f: operations_per_step(f, n_particles, n, p, d, m) for f in PAIRED}
    totals = {f: sum(parts[f].values()) for f in PAIRED}
    out = {f"operations_per_step_{f}": totals[f] for f in PAIRED}
    out["operation_share_resampling_of_rbpf_step"] = (
        parts["rbpf"]["resampling (systematic)"] / totals["rbpf"])
    for q in PAIRED[1:]:
        out[f"operation_ratio_{q}_over_rbpf"] = totals[q] / totals["rbpf"]
    return out


def resampling_seconds(n: int, rng: np.random.Generator, calls: int = RESAMPLING_CALLS) -> float:
    """Median over ``calls`` calls of the seconds of one systematic resampling of an N-particle
    bank (indices and copies of θ (N, 2), x (N, 2), P (N, 2, 2)); the median ignores calls the
    operating system interrupted."""
    w = rng.random(n)
    w /= w.sum()
    arrays = (rng.random((n, 2)), rng.random((n, 2)), rng.random((n, 2, 2)))
    seconds = np.empty(calls)
    for i in range(calls):
        start = time.perf_counter()
        idx = systematic_resample(w, rng)
        _ = [a[idx] for a in arrays]
        seconds[i] = time.perf_counter() - start
    return float(np.median(seconds))


def seconds_per_step(make_filter: Callable, name: str, n: int, y: np.ndarray, repeat: int) -> float:
    """Wall seconds per step of filter ``name`` with ``n`` particles over the measurements ``y``
    (total time of the run / steps).

    ``make_filter(name, n, repeat)`` builds a fresh filter (particles and stream fixed by
    ``repeat``)."""
    filt = make_filter(name, n, repeat)
    start = time.perf_counter()
    run_filter(filt, y)
    return (time.perf_counter() - start) / len(y)


def median_step_seconds(make_filter: Callable, name: str, n: int, y: np.ndarray,
                        repeat: int) -> float:
    """Median over the steps of ``y`` of the wall seconds of one ``step`` call of filter
    ``name`` (steps the operating system interrupted do not move the median).  For filters
    that do the same work at every step (the paper-scheme RBPF, the Q-GRBPF)."""
    filt = make_filter(name, n, repeat)
    seconds = np.empty(len(y))
    for k, y_k in enumerate(y):
        start = time.perf_counter()
        filt.step(y_k)
        seconds[k] = time.perf_counter() - start
    return float(np.median(seconds))


def paired_samples(settings: Settings, make_filter: Callable, y: np.ndarray) -> pd.DataFrame:
    """One row per paired repeat: median seconds per step of each :data:`PAIRED` filter and
    of one resampling, at ``timing_ratio_particles``, measured back to back."""
    n, repeats = settings.timing_ratio_particles, settings.timing_ratio_repeats
    rng = np.random.default_rng([settings.seed, 20_000])

    def timed(name: str) -> Callable[[], float]:
        index = iter(range(repeats))                  # repeat r: particles and stream 20000 + r
        return lambda: median_step_seconds(make_filter, name, n, y, 20_000 + next(index))

    runs = {name: timed(name) for name in PAIRED}
    runs["resampling"] = lambda: resampling_seconds(n, rng)
    return pd.DataFrame({"repeat": range(repeats), **interleaved(runs, repeats)})


def paired_metrics(samples: pd.DataFrame) -> dict:
    """``time_ratio_paired_<q>_over_rbpf`` (Q-GRBPF / RBPF seconds per step, per repeat) and
    ``resampling_share_of_rbpf_step`` (resampling / RBPF step), medians over the repeats with
    their 95 % intervals (``_low``, ``_high``, ``_n``)."""
    m = {}
    for q in PAIRED[1:]:
        m.update(median_interval(samples[q] / samples["rbpf"]).metrics(
            f"time_ratio_paired_{q}_over_rbpf"))
    m.update(median_interval(samples["resampling"] / samples["rbpf"]).metrics(
        "resampling_share_of_rbpf_step"))
    return m


def timing(settings: Settings, make_filter: Callable, filters: tuple[str, ...], y: np.ndarray,
           progress) -> tuple[dict, pd.DataFrame, pd.DataFrame]:
    """Curves and paired repeats (module docstring), on one numba thread."""
    with one_thread():
        return _timing(settings, make_filter, filters, y, progress)


def _timing(settings: Settings, make_filter: Callable, filters: tuple[str, ...], y: np.ndarray,
            progress) -> tuple[dict, pd.DataFrame, pd.DataFrame]:
    """Curves and paired repeats (module docstring).

    Parameters
    ----------
    settings : Settings
        The chapter's settings.
    make_filter : callable
        ``make_filter(name, n, repeat)`` → a fresh filter.
    filters : tuple of str
        Filters of the curves.
    y : ndarray, (K, 2)
        The main record's measurements; the first ``timing_steps`` are filtered.
    progress : callable
        ``progress(fraction, message)``.

    Returns
    -------
    timings : dict
        ``seconds_per_step_<f>_N<n>``, ``time_ratio_qgrbpf_over_rbpf[_N<n>]`` (curves, at
        ``n_particles`` without suffix), ``time_saving_qgrbpf_vs_rbpf_percent``,
        ``resampling_share_of_rbpf_step_N<n>``, ``steps_per_second_<f>`` (Hz: filter steps per
        second at ``n_particles``, the rate an online filter sustains) and :func:`paired_metrics`.
    curves : DataFrame
        ``filter, n_particles, seconds_per_step``.
    samples : DataFrame
        :func:`paired_samples`.
    """
    counts = sorted(set(int(n) for n in settings.timing_particles if n >= 2)
                    | {settings.n_particles})
    y = y[: settings.timing_steps]
    rows = []
    rng = np.random.default_rng([settings.seed, 10_000])
    timings = {}
    for i, n in enumerate(counts):
        progress(0.9 + 0.08 * i / len(counts), f"timing N={n}")
        best = {name: np.inf for name in filters}
        best_resampling = np.inf
        for r in range(settings.timing_repeats):
            for name in filters:                        # interleaved: same machine load
                best[name] = min(best[name], seconds_per_step(make_filter, name, n, y, 10_000 + r))
            best_resampling = min(best_resampling, resampling_seconds(n, rng))
        rows += [dict(filter=name, n_particles=n, seconds_per_step=best[name]) for name in filters]
        timings[f"resampling_share_of_rbpf_step_N{n}"] = best_resampling / best["rbpf"]
    curves = pd.DataFrame(rows)
    timings.update({f"seconds_per_step_{r.filter}_N{r.n_particles}": r.seconds_per_step
                    for r in curves.itertuples()})
    per = curves.pivot(index="n_particles", columns="filter", values="seconds_per_step")
    for n in per.index:
        timings[f"time_ratio_qgrbpf_over_rbpf_N{n}"] = per.loc[n, "qgrbpf"] / per.loc[n, "rbpf"]
    timings["time_ratio_qgrbpf_over_rbpf"] = timings[
        f"time_ratio_qgrbpf_over_rbpf_N{settings.n_particles}"]
    timings["time_saving_qgrbpf_vs_rbpf_percent"] = 100.0 * (
        1.0 - timings["time_ratio_qgrbpf_over_rbpf"])
    for name in filters:                   # the rate an online filter sustains at the paper's N
        timings[f"steps_per_second_{name}"] = 1.0 / per.loc[settings.n_particles, name]
    progress(0.98, f"paired timing N={settings.timing_ratio_particles}")
    samples = paired_samples(settings, make_filter, y)
    timings.update(paired_metrics(samples))
    return timings, curves, samples
