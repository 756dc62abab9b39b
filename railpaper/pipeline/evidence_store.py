"""The evidence store: per-record rows of the chapters' Monte Carlo studies, kept and reused.

A row is keyed by chapter, study, the settings that change a record's numbers
(:meth:`ChapterSettings.record_key`) and seed, and carries the commit that wrote it.  The rows of
one (chapter, study, settings) live in ``ROOT/<chapter>/<study>/<key>/rows.csv`` (``key`` = the
first 16 hex digits of the SHA-256 of the canonical JSON of the record key, which ``key.json``
beside it holds in full, and ``columns.json`` each column's dtype).  Floats are written at ``%.17g`` and read back exactly.

A run asks for seeds; the store gives the rows it holds and the run computes only the missing
ones, appending each finished chunk at once (a line per record, flushed), so raising a sample
size extends the evidence and an interrupted run keeps what finished.  Rows written by another
commit (or by an uncommitted tree) are reused only after a few of them, drawn with a fixed seed,
are recomputed here and found equal bit for bit; otherwise the store is refused in one line.

>>> import tempfile, pandas as pd
>>> from railpaper.experiments.records import RecordStudy
>>> def squares(settings, seeds):
...     return pd.DataFrame({"seed": list(seeds), "square_m2": [s * s / 3 for s in seeds]})
>>> store = EvidenceStore(tempfile.mkdtemp())
>>> record_map = stored_map(store, commit="abc")
>>> study = RecordStudy("demo", "squares", squares)
>>> record_map(study, None, [1, 2]).square_m2.tolist() == [1 / 3, 4 / 3]
True
>>> store.read(study, None).seed.tolist()
[1, 2]
"""

from __future__ import annotations

import atexit
import contextlib
import hashlib
import json
import os
import subprocess
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Sequence

import numpy as np
import pandas as pd

from railpaper.experiments.base import ChapterSettings, ProgressCallback, no_progress
from railpaper.experiments.records import (
    RecordMap,
    RecordStudy,
    checked_rows,
    column_types,
    no_rows,
    normalised,
    read_rows,
)
from railpaper.paths import REPO_DIR
from railpaper.pipeline.chapters import PipelineError
from railpaper.pipeline.sweep import close_client, make_client

#: Rows of another commit recomputed before the store's rows are reused.
SPOT_CHECK_RECORDS = 3
#: Seed of the draw of those rows (fixed: the same rows are checked on every machine).
SPOT_CHECK_SEED = 20261206


class EvidenceStoreError(PipelineError):
    """Stored rows that the code no longer reproduces, or a store that cannot be read."""


def current_commit(repo: Path = REPO_DIR) -> str:
    """``git rev-parse HEAD`` of the checkout, with ``+dirty`` when tracked files differ from it
    (``unknown`` outside a git checkout).  The stored evidence itself (``data/evidence``) is
    what a run writes, not what computes it: rows written, extended or removed there do not make
    the commit dirty."""
    def git(*args: str) -> subprocess.CompletedProcess:
        return subprocess.run(["git", "-C", str(repo), *args], capture_output=True, text=True)
    head = git("rev-parse", "HEAD")
    if head.returncode != 0:
        return "unknown"
    dirty = git("diff", "--quiet", "HEAD", "--", ".", ":(exclude)data/evidence").returncode != 0
    return head.stdout.strip() + ("+dirty" if dirty else "")


def record_key(settings: Any) -> dict[str, Any]:
    """The settings that change a record's numbers (all of a non-chapter settings object's
    fields are taken as such; None for a study without settings)."""
    if settings is None:
        return {}
    if isinstance(settings, ChapterSettings):
        return settings.record_key()
    raise TypeError(f"settings of type {type(settings).__name__} have no record key")


def key_digest(key: dict[str, Any]) -> str:
    """First 16 hex digits of the SHA-256 of the key's canonical JSON."""
    text = json.dumps(key, sort_keys=True, separators=(",", ":"))
    return hashlib.sha256(text.encode()).hexdigest()[:16]


def _whole_lines(text: str) -> str:
    """``text`` without a last line cut short by an interrupted write."""
    return text if text.endswith("\n") else text[:text.rfind("\n") + 1]


def _csv_lines(frame: pd.DataFrame) -> list[str]:
    """The frame's CSV data lines (no header), floats at ``%.17g``."""
    return frame.to_csv(index=False, header=False, float_format="%.17g").splitlines()


@dataclass(frozen=True)
class EvidenceStore:
    """The rows under ``root`` (e.g. ``data/evidence`` or a user's ``runs/evidence``)."""

    root: Path

    def __post_init__(self) -> None:
        object.__setattr__(self, "root", Path(self.root))

    def folder(self, study: RecordStudy, settings: Any) -> Path:
        """Where the rows of ``study`` under ``settings`` live."""
        return self.root / study.chapter / study.name / key_digest(record_key(settings))

    def read(self, study: RecordStudy, settings: Any) -> pd.DataFrame:
        """The stored rows (columns ``seed``, the study's, ``commit``), as written; a line cut
        short by an interrupted write is ignored."""
        path = self.folder(study, settings) / "rows.csv"
        if not path.exists():
            return pd.DataFrame({"seed": pd.Series([], dtype="int64"),
                                 "commit": pd.Series([], dtype="object")})
        text = _whole_lines(path.read_text())
        types = json.loads((path.parent / "columns.json").read_text())
        frame = read_rows(text, types)
        return frame.drop_duplicates("seed", keep="first").reset_index(drop=True)

    def append(self, study: RecordStudy, settings: Any, rows: pd.DataFrame, commit: str) -> None:
        """Append ``rows`` (one per seed, column ``seed``) as written by ``commit``."""
        folder = self.folder(study, settings)
        folder.mkdir(parents=True, exist_ok=True)
        key_path = folder / "key.json"
        if not key_path.exists():
            key_path.write_text(json.dumps({"chapter": study.chapter, "study": study.name,
                                            "settings": record_key(settings)},
                                           indent=1, sort_keys=True) + "\n")
        path = folder / "rows.csv"
        frame = rows.copy()                 # one block: no fragmented-frame warning
        frame["commit"] = commit
        header = ",".join(frame.columns)
        if path.exists():
            text = path.read_text()
            if _whole_lines(text) != text:              # an interrupted write: drop its line
                path.write_text(_whole_lines(text))
            stored_header = text.split("\n", 1)[0]
            if stored_header != header:
                raise EvidenceStoreError(
                    f"evidence store {folder}: its columns differ from this code's rows (remove "
                    f"the folder to recompute)")
        else:
            (folder / "columns.json").write_text(json.dumps(column_types(frame), indent=1) + "\n")
            path.write_text(header + "\n")
        with path.open("a") as handle:
            handle.write("\n".join(_csv_lines(frame)) + "\n")
            handle.flush()

    def verify(self, study: RecordStudy, settings: Any, stored: pd.DataFrame, commit: str,
               n_records: int = SPOT_CHECK_RECORDS) -> list[int]:
        """Recompute up to ``n_records`` rows of ``stored`` written by other commits than
        ``commit`` (or by an uncommitted tree), drawn with :data:`SPOT_CHECK_SEED`, and raise
        :class:`EvidenceStoreError` in one line if any value differs in any bit.  Returns the
        seeds checked."""
        foreign = stored[(stored["commit"] != commit) | stored["commit"].str.endswith("+dirty")]
        if foreign.empty:
            return []
        rng = np.random.default_rng(SPOT_CHECK_SEED)
        picked = sorted(int(s) for s in rng.choice(foreign["seed"].to_numpy(),
                                                   size=min(n_records, len(foreign)),
                                                   replace=False))
        fresh = normalised(checked_rows(study, picked, study.rows(settings, tuple(picked))))
        old = stored.set_index("seed").loc[picked].reset_index()
        for column in fresh.columns:
            if column not in old.columns:
                raise EvidenceStoreError(
                    f"evidence store {self.folder(study, settings)}: no column {column} in the "
                    f"stored rows; regenerate with 'railpaper evidence' after removing the folder")
            for seed, new_text, old_text in zip(picked, _csv_lines(fresh[[column]]),
                                                _csv_lines(old[[column]])):
                if new_text != old_text:
                    written_by = old.loc[old["seed"] == seed, "commit"].iloc[0]
                    raise EvidenceStoreError(
                        f"evidence store {self.folder(study, settings)}: seed {seed}'s {column} "
                        f"is {new_text} here but {old_text} in the rows of commit {written_by}; "
                        f"regenerate with 'railpaper evidence' after removing the folder")
        return picked


def timed_rows(rows, settings: Any, seeds: tuple[int, ...]) -> tuple[pd.DataFrame, float]:
    """``rows(settings, seeds)`` and the CPU seconds it took in the process that ran it."""
    started = time.process_time()
    frame = rows(settings, seeds)
    return frame, time.process_time() - started


def stored_map(store: EvidenceStore | None, *, client: Any = None, commit: str | None = None
               ) -> RecordMap:
    """A :data:`RecordMap` that reads ``store`` (None: no store), computes the missing records
    in this process or, with a dask ``client``, on its workers (one task per chunk), and appends
    each finished chunk to the store.  The progress callback counts records done across
    workers.  ``record_map.usage`` adds up the records computed and their CPU seconds (measured
    where they ran)."""
    commit = commit or current_commit()
    usage = {"records": 0, "cpu_s": 0.0}

    def record_map(study: RecordStudy, settings: Any, seeds: Sequence[int],
                   progress: ProgressCallback = no_progress) -> pd.DataFrame:
        seeds = [int(s) for s in seeds]
        stored = store.read(study, settings) if store is not None else no_rows()
        stored = stored[stored["seed"].isin(seeds)]
        if store is not None and len(stored):
            store.verify(study, settings, stored, commit)
        have = set(int(s) for s in stored["seed"])
        missing = [s for s in seeds if s not in have]
        frames = [stored.drop(columns="commit")] if len(stored) else []
        done, total = len(have), len(seeds)
        progress(done / max(total, 1), f"{study.name}: {done}/{total} records")
        chunks = study.chunks(missing)

        def finished(chunk, result):
            nonlocal done
            frame, cpu_s = result
            usage["records"] += len(chunk)
            usage["cpu_s"] += cpu_s
            frame = normalised(checked_rows(study, chunk, frame))
            if store is not None:
                store.append(study, settings, frame, commit)
            frames.append(frame)
            done += len(chunk)
            progress(done / max(total, 1), f"{study.name}: {done}/{total} records")

        if client is None:
            for chunk in chunks:
                finished(chunk, timed_rows(study.rows, settings, chunk))
        else:
            from distributed import as_completed
            futures = {client.submit(timed_rows, study.rows, settings, chunk, pure=False): chunk
                       for chunk in chunks}
            for future in as_completed(futures):
                finished(futures[future], future.result())
        if not frames:
            return no_rows()
        table = pd.concat(frames, ignore_index=True).set_index("seed").loc[seeds].reset_index()
        return normalised(table)

    record_map.usage = usage
    return record_map




#: Environment variables through which ``railpaper run`` and ``railpaper build`` hand a chapter
#: notebook's kernel where its records run and are kept (:func:`notebook_record_map`).
WORKERS_VARIABLE = "RAILPAPER_WORKERS"
SCHEDULER_VARIABLE = "RAILPAPER_SCHEDULER"
STORE_VARIABLE = "RAILPAPER_EVIDENCE_STORE"

_CLIENTS: dict[tuple, Any] = {}


def record_map_for(workers: int | None = None, scheduler: str | None = None,
                   store: str | Path | None = None) -> RecordMap:
    """The record map of a run: in this process without ``workers`` or ``scheduler`` (today's
    behaviour), else on a dask ``LocalCluster`` of ``workers`` single-threaded processes or on
    the cluster at ``scheduler``; rows kept in and reused from ``store`` when given.  The client
    is made once per process and closed at its exit."""
    client = None
    if workers or scheduler:
        key = (workers, scheduler)
        if key not in _CLIENTS:
            _CLIENTS[key] = make_client(scheduler, workers)
            atexit.register(close_client, *_CLIENTS[key])
        client = _CLIENTS[key][0]
    return stored_map(EvidenceStore(store) if store else None, client=client)


def notebook_record_map() -> RecordMap:
    """:func:`record_map_for` as the pipeline asked for it (:data:`WORKERS_VARIABLE`,
    :data:`SCHEDULER_VARIABLE`, :data:`STORE_VARIABLE`; none set: in the notebook's process,
    no store)."""
    workers = int(os.environ.get(WORKERS_VARIABLE, "0")) or None
    return record_map_for(workers, os.environ.get(SCHEDULER_VARIABLE) or None,
                          os.environ.get(STORE_VARIABLE) or None)


@contextlib.contextmanager
def records_on(workers: int | None = None, scheduler: str | None = None,
               store: str | Path | None = None):
    """Where the chapters run by ``railpaper run`` / ``build`` compute their records, for the
    duration of the block: with ``workers``, one dask ``LocalCluster`` of that many
    single-threaded processes made here and shared by every chapter (``build --jobs 2`` runs two
    chapters whose records share the same K workers); with ``scheduler``, that cluster; with
    ``store``, rows kept and reused there.  The chapters' notebook kernels inherit the address
    and the store through :data:`SCHEDULER_VARIABLE` and :data:`STORE_VARIABLE`; without any of
    them nothing changes (records in each chapter's own process).  Yields the scheduler address
    (None without one)."""
    if workers is not None and workers < 1:
        raise ValueError(f"--workers must be >= 1, got {workers}")
    if workers and scheduler:
        raise ValueError("give --workers (a local cluster) or --scheduler (yours), not both")
    saved = {name: os.environ.get(name) for name in (SCHEDULER_VARIABLE, STORE_VARIABLE,
                                                     WORKERS_VARIABLE)}
    client = cluster = None
    try:
        if workers:
            client, cluster = make_client(None, workers)
            scheduler = cluster.scheduler_address
        elif scheduler:
            client, cluster = make_client(scheduler, None)    # reachable? one line if not
        if scheduler:
            os.environ[SCHEDULER_VARIABLE] = scheduler
        if store:
            os.environ[STORE_VARIABLE] = str(Path(store).resolve())
        yield scheduler
    finally:
        for name, value in saved.items():
            if value is None:
                os.environ.pop(name, None)
            else:
                os.environ[name] = value
        if client is not None:
            close_client(client, cluster)


__all__ = ["EvidenceStore", "EvidenceStoreError", "SCHEDULER_VARIABLE", "SPOT_CHECK_RECORDS",
           "STORE_VARIABLE", "WORKERS_VARIABLE", "current_commit", "key_digest",
           "notebook_record_map", "record_key", "record_map_for", "records_on", "stored_map"]
