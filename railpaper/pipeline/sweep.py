"""Monte Carlo sweeps of a chapter's experiment on ``dask.distributed``.

A sweep runs every combination of grid values × seeds by calling the chapter's experiment function
``railpaper.experiments.<module>.run(quick=..., **parameters)`` in worker processes (no notebook
kernel per sample).  Without a scheduler address the workers form a
``dask.distributed.LocalCluster`` on this machine (one single-threaded process per core); with
``scheduler="tcp://host:port"`` the same futures go to that cluster, whose workers must be able to
import ``railpaper`` (and should run with ``OMP_NUM_THREADS=1``, as dask's nannies set by default,
for metrics bit-identical to local runs).

Outputs in ``out_dir`` (see :mod:`railpaper.pipeline.sweep_table`): ``results.csv`` (one row per
sample, rewritten atomically as samples finish, so an interrupted sweep keeps its finished rows and
a re-run skips them), ``summary.csv`` (count, mean, std, quantiles per grid point and metric) and
``sweep.json`` (the command and its parameters).
"""

from __future__ import annotations

import itertools
import json
import os
import sys
import time
from pathlib import Path
from typing import Any, Iterable

import numpy as np
import pandas as pd

from railpaper.experiments import load_chapter
from railpaper.experiments.base import ChapterSpec, ParameterError, check_metrics
from railpaper.pipeline.chapters import PipelineError, chapter_spec
from railpaper.pipeline.sweep_table import (RESERVED_COLUMNS, load_results, sample_key,
                                            summarise, write_csv_atomic)

#: The chapter parameter that seeds every random draw of a run (all chapters have it).
SEED_PARAMETER = "seed"

#: One BLAS/OpenMP/numba thread per worker process: two numpy processes on two cores with default
#: threading slow each other several-fold, and the thread count changes the last digits of floats.
#: Numba's parallel loops (the Kalman bank) with two threads in each of two workers run several
#: times slower than with one.
SINGLE_THREAD_ENV = {"OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1", "MKL_NUM_THREADS": "1",
                     "NUMBA_NUM_THREADS": "1"}


def parse_seeds(text: str | Iterable[int]) -> list[int]:
    """Seeds from ``"A:B"`` (A, A+1, …, B−1), ``"A,B,C"`` or ``"A"``; or an iterable of ints."""
    if not isinstance(text, str):
        seeds = [int(s) for s in text]
    else:
        try:
            if ":" in text:
                start, stop = (int(part) for part in text.split(":"))
                seeds = list(range(start, stop))
            else:
                seeds = [int(part) for part in text.split(",")]
        except ValueError:
            raise ValueError(f"--seeds expects START:STOP (e.g. 0:50) or a list like 0,3,7; "
                             f"got {text!r}") from None
    if not seeds:
        raise ValueError(f"--seeds {text!r} gives no seeds (STOP must be greater than START)")
    if len(set(seeds)) != len(seeds):
        raise ValueError(f"--seeds {text!r} repeats a seed")
    return seeds


def parse_grid_option(text: str, parse_value) -> tuple[str, list]:
    """``NAME=V1,V2,...`` → (NAME, [values]); commas inside ``[...]`` do not split.

    ``parse_value`` turns one value's text into a value (the CLI parses YAML, like ``run -p``).
    """
    name, sep, values = text.partition("=")
    if not sep or not name.strip() or not values.strip():
        raise ValueError(f"--grid expects NAME=V1,V2,... (e.g. speeds_kmh=[60],[100]), got {text!r}")
    parts, depth, current = [], 0, ""
    for char in values:
        depth += {"[": 1, "]": -1, "{": 1, "}": -1}.get(char, 0)
        if char == "," and depth == 0:
            parts.append(current)
            current = ""
        else:
            current += char
    parts.append(current)
    if depth != 0 or any(not part.strip() for part in parts):
        raise ValueError(f"--grid {name.strip()}: cannot split {values!r} into values")
    return name.strip(), [parse_value(part.strip()) for part in parts]


def validate_grid(spec: ChapterSpec, grid: dict[str, list], fixed: dict[str, Any],
                  seeds: list[int], quick: bool) -> tuple[dict[str, list], dict[str, Any]]:
    """Checked grid and fixed values (through the chapter's parameters), before any work starts."""
    spec.parameter(SEED_PARAMETER)
    checked_grid, checked_fixed = {}, {}
    for name, values in grid.items():
        if name == SEED_PARAMETER:
            raise ParameterError(f"give seeds with --seeds, not as a grid of '{SEED_PARAMETER}'")
        if name in fixed:
            raise ParameterError(f"parameter '{name}' is both in the grid and fixed")
        parameter = spec.parameter(name)
        if isinstance(values, (str, bytes)) or not isinstance(values, Iterable):
            raise ParameterError(f"grid of '{name}' must be a list of values, got {values!r}")
        values = [parameter.coerce(v) for v in values]
        if not values:
            raise ParameterError(f"grid of '{name}' is empty")
        checked_grid[name] = values
    for name, value in fixed.items():
        if name == SEED_PARAMETER:
            raise ParameterError(f"give seeds with --seeds, not as a fixed '{SEED_PARAMETER}'")
        checked_fixed[name] = spec.parameter(name).coerce(value)
    seed_parameter = spec.parameter(SEED_PARAMETER)
    for seed in seeds:
        seed_parameter.coerce(seed)
    spec.resolve(dict(checked_fixed, **{k: v[0] for k, v in checked_grid.items()}), quick)
    return checked_grid, checked_fixed


def one_line(exc: BaseException) -> str:
    """``Type: first line of the message`` of an exception."""
    lines = str(exc).strip().splitlines()
    return f"{type(exc).__name__}: {lines[0]}" if lines else type(exc).__name__


def _flatten(metrics: dict[str, Any]) -> dict[str, Any]:
    """Scalar metrics as they are; sequences as ``name_0, name_1, …``; dicts as ``name_key``."""
    flat = {}
    for key, value in metrics.items():
        if isinstance(value, dict):
            flat.update(_flatten({f"{key}_{k}": v for k, v in value.items()}))
        elif isinstance(value, (list, tuple)) or getattr(value, "ndim", 0) > 0:
            flat.update(_flatten({f"{key}_{i}": v for i, v in enumerate(list(value))}))
        else:
            flat[key] = value
    return flat


def run_sample(chapter: str, quick: bool, overrides: dict[str, Any]) -> dict[str, Any]:
    """One sample, on a worker: the chapter's ``run`` with ``overrides``; never raises.

    Returns the row: ``metrics`` (flat dict), ``wall_time_s``, ``status`` ("ok" or "error") and
    ``error`` (one line, empty when ok).
    """
    started = time.perf_counter()
    try:
        module = load_chapter(chapter)
        result = module.run(module.SPEC.resolve(overrides, quick))
        metrics, status, error = check_metrics(_flatten(result.metrics)), "ok", ""
    except Exception as exc:  # noqa: BLE001 - one failing sample must not stop the sweep
        metrics, status, error = {}, "error", one_line(exc)
    return {"metrics": metrics, "wall_time_s": time.perf_counter() - started,
            "status": status, "error": error}


def _samples(grid: dict[str, list], fixed: dict[str, Any], seeds: list[int]):
    """(grid values incl. seed, overrides for run) for every combination, seeds innermost."""
    names = list(grid)
    for values in itertools.product(*(grid[n] for n in names)):
        for seed in seeds:
            point = dict(zip(names, values), **{SEED_PARAMETER: seed})
            yield point, dict(fixed, **point)


def make_client(scheduler: str | None, workers: int | None):
    """A dask Client: of a new LocalCluster (returned too, to close) or of ``scheduler``."""
    from distributed import Client, LocalCluster
    if scheduler:
        try:
            return Client(scheduler, timeout="5s"), None
        except Exception as exc:  # noqa: BLE001 - OSError, TimeoutError, ValueError of the address
            raise PipelineError(f"cannot reach dask scheduler {scheduler!r}: {one_line(exc)}"
                                ) from None
    n = workers or os.cpu_count() or 1
    cluster = LocalCluster(n_workers=n, threads_per_worker=1, processes=True, host="127.0.0.1",
                           dashboard_address=":0", env=dict(SINGLE_THREAD_ENV))
    client = Client(cluster)
    client.run(_quiet_worker_logs)     # our workers share our stderr: progress lines only there
    return client, cluster


def _quiet_worker_logs() -> None:
    """On a local worker: only critical messages of dask's loggers.  An interrupted sweep
    otherwise ends in 'Async instruction … ended with CancelledError' warnings of the cancelled
    samples and, when the interrupt closes the scheduler while a worker is still busy, in that
    worker's 'Failed to communicate with scheduler during heartbeat' error with a traceback.
    Nothing is lost: a sample's own failure reaches the sweep through its future (its row's
    ``error``), and a lost worker is reported by its nanny, in the sweep's process."""
    import logging
    logging.getLogger("distributed").setLevel(logging.CRITICAL)


def close_client(client, cluster) -> None:
    """Close the client and our LocalCluster with only errors of dask's loggers in this process:
    after an interrupt a worker busy with a cancelled sample takes its nanny (here) more than 4 s
    to stop, and the nanny's 'still alive after 4.0 seconds, killing' warning is that
    cancellation's noise, like the workers' warnings :func:`_quiet_worker_logs` silences."""
    import logging
    dask_log = logging.getLogger("distributed")
    level = dask_log.level
    dask_log.setLevel(logging.ERROR)
    try:
        if client is not None:
            client.close()
        if cluster is not None:
            cluster.close()
    finally:
        dask_log.setLevel(level)


class _Progress:
    """``railpaper: sweep 12/50 done, 1 failed, ETA 1m05s`` on stderr, at most once a second.

    The ETA uses the pace since the first sample finished (the first includes worker start-up).
    """

    def __init__(self, total: int, already: int, enabled: bool):
        self.total, self.already, self.enabled = total, already, enabled
        self.done = self.failed = 0
        self.started = self.last = self.first = time.monotonic()

    def update(self, status: str) -> None:
        self.done += 1
        self.failed += status != "ok"
        now = time.monotonic()
        if self.done == 1:
            self.first = now
        if self.enabled and (now - self.last >= 1.0 or self.already + self.done == self.total):
            self.last = now
            pace = ((now - self.first) / (self.done - 1) if self.done > 1
                    else now - self.started)
            eta = round(pace * (self.total - self.already - self.done))
            print(f"railpaper: sweep {self.already + self.done}/{self.total} done, "
                  f"{self.failed} failed, ETA {eta // 60}m{eta % 60:02d}s",
                  file=sys.stderr, flush=True)


def _check_directory(out: Path, chapter: str, quick: bool, fixed: dict[str, Any]) -> None:
    """Refuse an output directory that holds a sweep of another chapter, mode or fixed values."""
    path = out / "sweep.json"
    if out.exists() and not out.is_dir():
        raise PipelineError(f"--out {out} is a file, not a directory")
    if path.exists():
        try:
            previous = json.loads(path.read_text())
        except json.JSONDecodeError:
            raise PipelineError(f"{path} is not a sweep record; use another --out") from None
        if (previous.get("chapter"), previous.get("quick")) != (chapter, quick):
            raise PipelineError(f"{out} holds a sweep of {previous.get('chapter')} "
                                f"(quick={previous.get('quick')}); use another --out")
        if previous.get("fixed", {}) != json.loads(json.dumps(fixed)):
            raise PipelineError(f"{out} holds a sweep with other fixed parameters "
                                f"({previous.get('fixed')}); use another --out")


def _record(out: Path, chapter: str, quick: bool, grid: dict, fixed: dict, seeds: list[int],
            scheduler: str | None, workers: int | None) -> None:
    """``sweep.json``: the command and its parameters."""
    path = out / "sweep.json"
    record = {"chapter": chapter, "quick": quick, "grid": grid, "fixed": fixed, "seeds": seeds,
              "scheduler": scheduler, "workers": workers, "command": sys.argv,
              "started_utc": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())}
    tmp = path.with_name(".sweep.json.tmp")
    tmp.write_text(json.dumps(record, indent=2) + "\n")
    tmp.replace(path)


def run_sweep(chapter: str, grid: dict[str, list], seeds: str | Iterable[int],
              out_dir: str | Path, *, fixed: dict[str, Any] | None = None, quick: bool = False,
              workers: int | None = None, scheduler: str | None = None,
              progress: bool = True) -> pd.DataFrame:
    """Run a chapter's experiment for every grid combination × seed on dask workers.

    Parameters
    ----------
    chapter : str
        Chapter name, e.g. ``"reduced-order-observer"``.
    grid : dict of str to list
        Parameter name → values; every combination is run.  Checked by the chapter's parameters.
    seeds : str or iterable of int
        Values of the chapter's ``seed`` parameter (``"0:50"`` = 0…49).
    out_dir : path
        Directory of ``results.csv``, ``summary.csv``, ``sweep.json``; re-running the same sweep
        there skips samples already completed with status ``ok``.
    fixed : dict, optional
        Parameter values applied to every sample (not columns of the results).
    quick : bool
        The chapter's quick sizes.
    workers : int, optional
        Local worker processes (default: all cores); ignored with ``scheduler``.
    scheduler : str, optional
        Address of a running ``dask.distributed`` scheduler, e.g. ``"tcp://10.0.0.5:8786"``.
    progress : bool
        Progress lines on stderr.

    Returns
    -------
    pandas.DataFrame
        The rows of this sweep's samples (grid parameters, seed, metrics, ``wall_time_s``,
        ``status``, ``error``), in grid order.
    """
    from distributed import as_completed

    spec = chapter_spec(chapter)
    seeds = parse_seeds(seeds)
    grid, fixed = validate_grid(spec, dict(grid), dict(fixed or {}), seeds, quick)
    if workers is not None and workers < 1:
        raise ValueError(f"--workers must be >= 1, got {workers}")
    out = Path(out_dir)
    _check_directory(out, chapter, quick, fixed)
    samples = [(sample_key(point), point, overrides) for point, overrides in
               _samples(grid, fixed, seeds)]
    keys = {key for key, _, _ in samples}
    existing = load_results(out / "results.csv")
    done = set(existing.loc[existing.status == "ok", "sample"]) if len(existing) else set()
    rows = existing[(existing["sample"].isin(done)) | ~existing["sample"].isin(keys)] \
        .to_dict("records") if len(existing) else []
    todo = [s for s in samples if s[0] not in done]
    client, cluster = make_client(scheduler, workers) if todo else (None, None)
    try:
        out.mkdir(parents=True, exist_ok=True)
        _record(out, chapter, quick, grid, fixed, seeds, scheduler, workers)
        if progress:
            print(f"railpaper: sweep of {chapter}: {len(samples)} samples, "
                  f"{len(samples) - len(todo)} already done", file=sys.stderr, flush=True)
        futures = {client.submit(run_sample, chapter, quick, overrides, pure=False):
                   (key, point) for key, point, overrides in todo}
        meter = _Progress(len(samples), len(samples) - len(todo), progress)
        for future in as_completed(futures) if futures else ():     # all done: no client
            key, point = futures.pop(future)
            try:
                outcome = future.result()
            except Exception as exc:  # noqa: BLE001 - a lost worker fails this sample only
                outcome = {"metrics": {}, "wall_time_s": float("nan"), "status": "error",
                           "error": one_line(exc)}
            rows.append(_row(key, point, outcome))
            write_csv_atomic(pd.DataFrame(rows), out / "results.csv")
            meter.update(outcome["status"])
    finally:
        close_client(client, cluster)
    order = {key: i for i, (key, _, _) in enumerate(samples)}
    everything = pd.DataFrame(rows)                          # this sweep's rows in grid order first
    everything = everything.iloc[np.argsort(everything["sample"].map(order).fillna(len(order))
                                            .to_numpy(), kind="stable")].reset_index(drop=True)
    write_csv_atomic(everything, out / "results.csv")
    frame = everything[everything["sample"].isin(keys)].reset_index(drop=True)
    write_csv_atomic(summarise(frame, list(grid)), out / "summary.csv")
    return frame


def _row(key: str, point: dict[str, Any], outcome: dict[str, Any]) -> dict[str, Any]:
    """One results.csv row: grid values, seed, metrics, wall time, status, error, sample key."""
    row = {name: json.dumps(v) if isinstance(v, list) else v for name, v in point.items()}
    for name, value in outcome["metrics"].items():
        row[f"metric_{name}" if name in row or name in RESERVED_COLUMNS else name] = value
    row.update(wall_time_s=outcome["wall_time_s"], status=outcome["status"],
               error=outcome["error"], sample=key)
    return row
