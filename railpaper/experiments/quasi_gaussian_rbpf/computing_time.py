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

from railpaper.engine.particles import systematic_resample
from railpaper.engine.rbpf import run_filter
from railpaper.stats import median_interval
from railpaper.threads import one_thread
from railpaper.timing import interleaved

#: Filters timed in the paired repeats: the RBPF, then the Q-GRBPF under both readings.
PAIRED = ("rbpf", "qgrbpf", "qgrbpf_printed")
RESAMPLING_CALLS = 20


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


def paired_samples(p: dict, make_filter: Callable, y: np.ndarray) -> pd.DataFrame:
    """One row per paired repeat: median seconds per step of each :data:`PAIRED` filter and
    of one resampling, at ``timing_ratio_particles``, measured back to back."""
    n, repeats = p["timing_ratio_particles"], p["timing_ratio_repeats"]
    rng = np.random.default_rng([p["seed"], 20_000])

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


def timing(p: dict, make_filter: Callable, filters: tuple[str, ...], y: np.ndarray,
           progress) -> tuple[dict, pd.DataFrame, pd.DataFrame]:
    """Curves and paired repeats (module docstring), on one numba thread."""
    with one_thread():
        return _timing(p, make_filter, filters, y, progress)


def _timing(p: dict, make_filter: Callable, filters: tuple[str, ...], y: np.ndarray,
            progress) -> tuple[dict, pd.DataFrame, pd.DataFrame]:
    """Curves and paired repeats (module docstring).

    Parameters
    ----------
    p : dict
        Resolved chapter parameters.
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
        ``resampling_share_of_rbpf_step_N<n>`` and :func:`paired_metrics`.
    curves : DataFrame
        ``filter, n_particles, seconds_per_step``.
    samples : DataFrame
        :func:`paired_samples`.
    """
    counts = sorted(set(int(n) for n in p["timing_particles"] if n >= 2) | {p["n_particles"]})
    y = y[: p["timing_steps"]]
    rows = []
    rng = np.random.default_rng([p["seed"], 10_000])
    timings = {}
    for i, n in enumerate(counts):
        progress(0.9 + 0.08 * i / len(counts), f"timing N={n}")
        best = {name: np.inf for name in filters}
        best_resampling = np.inf
        for r in range(p["timing_repeats"]):
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
        f"time_ratio_qgrbpf_over_rbpf_N{p['n_particles']}"]
    timings["time_saving_qgrbpf_vs_rbpf_percent"] = 100.0 * (
        1.0 - timings["time_ratio_qgrbpf_over_rbpf"])
    progress(0.98, f"paired timing N={p['timing_ratio_particles']}")
    samples = paired_samples(p, make_filter, y)
    timings.update(paired_metrics(samples))
    return timings, curves, samples
