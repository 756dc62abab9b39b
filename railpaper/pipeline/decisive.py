"""Registered sample sizes and the decisive evidence the book's ledger reads.

Two steps, in this order, each a command:

1. ``railpaper register CHAPTER`` fixes every declared row's sample size by power before any
   deciding run (:func:`railpaper.pipeline.declarations.registered_size`): rates and single-run
   rows from the vocabulary alone; paired changes and equivalences from the per-record σ of the
   effect on *pilot* records, seeds :data:`PILOT_SEED` onwards, never used to decide.  The sizes
   and fingerprints go to the registry (``data/claims_registry.json``).
2. ``railpaper evidence --decisive`` computes each study at the largest size its rows registered
   (seeds from the chapter's own first seed, the records the book's run also starts with) into
   ``data/evidence/<chapter>/`` (:class:`~railpaper.pipeline.evidence_store.EvidenceStore`),
   with a ``provenance.json`` per chapter.  A study whose size would take the whole run past
   :data:`CPU_BUDGET_S` (estimated from its first chunk) is left out, and the ledger says what
   its rows would need.
"""

from __future__ import annotations

import datetime
import functools
import json
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from railpaper.experiments import load_chapter
from railpaper.experiments.records import RecordStudy, map_in_process
from railpaper.paths import DATA_DIR
from railpaper.pipeline.chapters import PipelineError, chapter_spec
from railpaper.pipeline.declarations import (
    Declaration,
    decide,
    first_records,
    load_declarations,
    load_registry,
    register,
    registered_size,
    write_registry,
)
from railpaper.pipeline.evidence_store import EvidenceStore, current_commit, stored_map
from railpaper.pipeline.soundness import estimator_catalogue, posterior_study, with_soundness
from railpaper.rulebook import Vocabulary, relative_change_sd
from railpaper.timing import machine

#: First seed of the pilot records behind the sizes of continuous statistics: far from every
#: seed a chapter's run or the decisive evidence uses.
PILOT_SEED = 900_000
#: Pilot records per study.
PILOT_RECORDS = 30
#: CPU time the whole decisive run may take (the issue's two CPU-hours).
CPU_BUDGET_S = 2 * 3600.0
DECISIVE_DIR = DATA_DIR / "evidence"
#: ``<root>/allocation.json``: the size of each study the last decisive run's budget paid for.
ALLOCATION_FILE = "allocation.json"


def chapter_studies(chapter: str) -> dict[str, RecordStudy]:
    """The chapter's per-record studies by name (its module's ``STUDIES``)."""
    studies = getattr(load_chapter(chapter), "STUDIES", None)
    if not studies:
        raise PipelineError(f"chapter '{chapter}' exposes no per-record studies (STUDIES)")
    return {study.name: study for study in studies}


def pilot_sigma(declaration: Declaration, rows) -> float:
    """The per-record σ of a row's effect on pilot rows: for a paired change or equivalence of
    [A, B], the delta method's ``sd((B − A) − r A) / |mean A|``; for deviations, their sd."""
    if len(declaration.metrics) == 1:
        return float(np.std(rows[declaration.metrics[0]].to_numpy(float), ddof=1))
    return relative_change_sd(rows[declaration.metrics[0]].to_numpy(float),
                              rows[declaration.metrics[1]].to_numpy(float))[1]


def register_chapter(chapter: str, date: str | None = None, quick: bool = False,
                     pilot_records: int = PILOT_RECORDS) -> tuple[dict[str, int | None], list[str]]:
    """Sizes of every declared row by power (pilot records for continuous statistics) written
    to the registry with the rows' fingerprints; returns the sizes and the revised keys."""
    vocabulary = Vocabulary.load()
    rows = load_declarations(chapter, vocabulary)
    if not rows:
        raise PipelineError(f"chapter '{chapter}' has no data/{chapter}/declarations.toml")
    settings = chapter_spec(chapter).resolve({}, quick)
    studies, pilots, sizes = chapter_studies(chapter), {}, {}
    for d in rows:
        sigma = None
        if d.study:
            if d.study not in studies:
                raise PipelineError(f"{d.key}: chapter '{chapter}' has no study {d.study!r}")
            if d.study not in pilots:      # once per study: the σ and the columns it has
                pilots[d.study] = map_in_process(studies[d.study], settings, range(
                    PILOT_SEED, PILOT_SEED + pilot_records))
            absent = [m for m in d.metrics if m not in pilots[d.study].columns]
            if absent:                     # a declared column the study does not compute
                raise PipelineError(f"{d.key}: study {d.study!r} has no column {absent[0]!r} at "
                                    "the chapter's defaults")
            if d.procedure in ("paired-change", "equivalence", "departure"):
                sigma = pilot_sigma(d, pilots[d.study])
        sizes[d.key] = registered_size(d, vocabulary, sigma)
    registry, revised = register(rows, vocabulary, load_registry(), sizes,
                                 date or datetime.date.today().isoformat())
    write_registry(registry)
    return sizes, revised


@dataclass(frozen=True)
class StudyPlan:
    """One study of the decisive run: its size and seeds, or why it is left out."""

    chapter: str
    study: str
    size: int
    first: int
    cpu_s_per_record: float | None = None
    skipped: str = ""
    sizes: tuple[int, ...] = ()


def plan(chapters: list[str]) -> list[StudyPlan]:
    """Every study the registered rows read, at the largest size registered for it, and every
    study a chapter sizes itself (its ``stored_sizes(settings)``: evidence no declared row
    decides, such as the fault appendix's long fault-free running)."""
    registry, vocabulary = load_registry(), Vocabulary.load()
    plans = []
    for chapter in chapters:
        settings = chapter_spec(chapter).resolve({}, False)
        sizes: dict[str, set[int]] = {}
        for d in load_declarations(chapter, vocabulary):
            size = registry.get(d.key, {}).get("size")
            if d.study and size:
                sizes.setdefault(d.study, set()).add(int(size))
        fixed_sizes = getattr(load_chapter(chapter), "stored_sizes", None)
        for study, size in (fixed_sizes(settings) if fixed_sizes else {}).items():
            sizes.setdefault(study, set()).add(int(size))   # a size the chapter fixes itself
        for study in list(sizes):          # the exact posterior of its records, same sizes
            posterior = posterior_study(chapter, study)
            if posterior is not None:
                sizes.setdefault(posterior.name, set()).update(sizes[study])
        studies = chapter_studies(chapter) if sizes else {}
        plans += [StudyPlan(chapter, study, max(wanted), studies[study].first(settings),
                            sizes=tuple(sorted(wanted)))
                  for study, wanted in sizes.items()]
    return plans


def run_decisive(chapters: list[str], client=None, workers: int = 1, progress=print,
                 budget_s: float = CPU_BUDGET_S, root: Path = DECISIVE_DIR) -> list[StudyPlan]:
    """Compute every planned study into ``root`` (rows already there are reused after their
    spot check), writing ``<root>/<chapter>/provenance.json``.  Each study's CPU seconds per
    record come from its provenance, else from timing one chunk here; the sizes the
    ``budget_s`` pays for are chosen across all studies at once, cheapest first
    (:func:`allocate_sizes`), and the sizes left out are reported with their cost."""
    store, commit = EvidenceStore(root), current_commit()
    record_map = stored_map(store, client=client, commit=commit)
    items = plan(chapters)
    rates = {}
    for item in items:
        rate_s = _stored_cpu_per_record(root / item.chapter, item.study)
        if not rate_s:                           # time one chunk here (its rows are not kept)
            study = chapter_studies(item.chapter)[item.study]
            settings = chapter_spec(item.chapter).resolve({}, False)
            probe = list(range(item.first, item.first + study.chunk_records))
            started = time.process_time()
            map_in_process(study, settings, probe)
            rate_s = (time.process_time() - started) / len(probe)
        rates[(item.chapter, item.study)] = rate_s
    chosen = allocate_sizes({(i.chapter, i.study): (rates[(i.chapter, i.study)],
                                                    i.sizes or (i.size,)) for i in items},
                            budget_s)
    write_allocation(root, chosen)
    done = []
    for item in items:
        key = (item.chapter, item.study)
        size, skipped = chosen[key]
        per_record = rates[key]
        if skipped:
            progress(f"railpaper: {item.chapter} {item.study}: {skipped}")
        if size == 0:                    # every registered size left out
            done.append(StudyPlan(**{**item.__dict__, "size": 0, "cpu_s_per_record": per_record,
                                     "skipped": skipped}))
            continue
        item = StudyPlan(**{**item.__dict__, "size": size, "skipped": skipped})
        settings = chapter_spec(item.chapter).resolve({}, False)
        study = chapter_studies(item.chapter)[item.study]
        before, started = dict(record_map.usage), time.perf_counter()
        record_map(study, settings, list(range(item.first, item.first + size)),
                   lambda fraction, message: progress(f"railpaper: {item.chapter} {message}"))
        wall = time.perf_counter() - started
        cpu = record_map.usage["cpu_s"] - before["cpu_s"]
        computed = record_map.usage["records"] - before["records"]
        done.append(StudyPlan(**{**item.__dict__, "cpu_s_per_record": per_record}))
        if computed:                     # a study only reused keeps the cost it was computed at
            _write_provenance(root / item.chapter, item, settings, commit, workers, wall, cpu,
                              computed)
    for chapter in chapters:
        if (root / chapter / "provenance.json").exists():
            write_stored_verdicts(chapter, root)
    return done


def allocate_sizes(studies: dict, budget_s: float) -> dict:
    """For ``studies`` {key: (CPU seconds per record, registered sizes)}, the size of each that
    the whole run computes, and a line naming the sizes left out with their CPU-hours: every
    (study, size) taken in order of its total cost, cheapest first, while the sum over the
    studies of rate × chosen size stays within ``budget_s`` (so a study's largest size cannot
    starve the others' smaller ones; the rule is fixed before any record is seen).

    >>> allocate_sizes({"a": (1.0, (30, 5000)), "b": (2.0, (30, 600))}, 1500.0)
    {'a': (30, 'sizes 5000 left out: they need about 1.39 CPU-hours'), 'b': (600, '')}
    """
    chosen = {key: 0 for key in studies}
    candidates = sorted((rate_s * n, key, n) for key, (rate_s, sizes) in studies.items()
                        for n in sizes)
    for _, key, n in candidates:
        rate_s = studies[key][0]
        spent = sum(studies[k][0] * m for k, m in chosen.items())
        if n > chosen[key] and spent + rate_s * (n - chosen[key]) <= budget_s:
            chosen[key] = n
    out = {}
    for key, (rate_s, sizes) in studies.items():
        left = sorted(n for n in sizes if n > chosen[key])
        out[key] = (chosen[key], "" if not left else (
            f"sizes {', '.join(str(n) for n in left)} left out: they need about "
            f"{rate_s * left[-1] / 3600:.2f} CPU-hours"))
    return out


def write_allocation(root: Path, chosen: dict) -> Path:
    """``<root>/allocation.json``: {"chapter/study": {"size", "left_out"}} of
    :func:`allocate_sizes`' choice, merged into the entries of chapters this run did not plan.
    Readers of the stored evidence use no more records of a study than its size here, so rows
    stored by an earlier run under another allocation cannot decide what today's budget would
    not pay for."""
    path = Path(root) / ALLOCATION_FILE
    entries = json.loads(path.read_text()) if path.exists() else {}
    planned = {chapter for chapter, _ in chosen}
    entries = {key: value for key, value in entries.items()
               if key.split("/", 1)[0] not in planned}
    entries.update({f"{chapter}/{study}": {"size": int(size), "left_out": skipped}
                    for (chapter, study), (size, skipped) in chosen.items()})
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(entries, indent=1, sort_keys=True) + "\n")
    return path


def allocated_size(chapter: str, study: str, root: Path = DECISIVE_DIR) -> int | None:
    """The records of ``study`` the decisive run's budget paid for (None: no allocation
    recorded for it, and every stored record counts)."""
    path = Path(root) / ALLOCATION_FILE
    if not path.exists():
        return None
    stat = path.stat()
    entry = _allocation(str(path), stat.st_mtime_ns, stat.st_size).get(f"{chapter}/{study}")
    return None if entry is None else int(entry["size"])


@functools.lru_cache(maxsize=4)
def _allocation(path: str, mtime_ns: int, size: int) -> dict[str, Any]:  # noqa: ARG001
    """The allocation file, parsed once per version (modification time and size: the cache
    key; the ledger asks for it per row)."""
    return json.loads(Path(path).read_text())


def affordable(rows, chapter: str, study: str, root: Path = DECISIVE_DIR):
    """The stored ``rows`` of ``study`` the budget paid for: the first
    :func:`allocated_size` of them by seed (all of them without an allocation)."""
    allowed = allocated_size(chapter, study, root)
    return rows if allowed is None or len(rows) <= allowed else first_records(rows, allowed)


def stored_rows(chapter: str, study: str, settings: Any, root: Path = DECISIVE_DIR
                ) -> pd.DataFrame | None:
    """The stored rows of ``study`` under ``settings`` (the share the budget paid for, sorted
    by seed, without the ``commit`` column), or None where the store holds none for them: a
    page's figure from evidence its own run cannot afford, at the settings it was stored at."""
    rows = affordable(EvidenceStore(root).read(RecordStudy(chapter, study, rows=None), settings),
                      chapter, study, root)
    if not len(rows):
        return None
    return rows.drop(columns="commit", errors="ignore").sort_values("seed").reset_index(drop=True)


def stored_provenance(chapter: str, study: str, root: Path = DECISIVE_DIR) -> dict[str, Any]:
    """What the stored ``study`` of ``chapter`` cost and where it came from: its entry of
    ``provenance.json`` (``records``, ``seeds``, ``cpu_s``, ``wall_s``, ``workers``) with the
    run's ``commit`` and ``date``; empty where nothing is stored."""
    path = Path(root) / chapter / "provenance.json"
    if not path.exists():
        return {}
    record = json.loads(path.read_text())
    entry = record.get("studies", {}).get(study)
    return {} if entry is None else {**entry, "commit": record.get("commit", ""),
                                     "date": record.get("date", "")}


def stored_verdicts(chapter: str, root: Path = DECISIVE_DIR) -> dict[str, dict[str, Any]]:
    """Each sampled declared row's decision on the stored evidence alone: its first registered
    size of records (the records the default book decides it on); rows whose study holds fewer
    are left out."""
    vocabulary, registry = Vocabulary.load(), load_registry()
    settings = chapter_spec(chapter).resolve({}, False)
    store, out, tables = EvidenceStore(root), {}, {}
    for d in load_declarations(chapter, vocabulary):
        size = registry.get(d.key, {}).get("size")
        if not d.study or not size:
            continue
        if d.study not in tables:                     # one read per study (000's: 17 MB)
            tables[d.study] = affordable(store.read(RecordStudy(chapter, d.study, rows=None),
                                                    settings), chapter, d.study, root)
        rows = tables[d.study]
        if len(rows) < size:
            continue
        rows = first_records(rows.drop(columns="commit"), size)
        posterior = posterior_study(chapter, d.study)
        if posterior is not None:                     # its filters' soundness (version 3)
            if posterior.name not in tables:          # as the ledger reads it (study_rows)
                tables[posterior.name] = affordable(store.read(posterior, settings), chapter,
                                                    posterior.name, root)
            known = tables[posterior.name]             # joined by seed
            rows = with_soundness(chapter, d.study, rows,
                                  known.drop(columns="commit", errors="ignore")
                                  if len(known) else None, settings)
        decision = decide(d, vocabulary, rows, {}, size,
                          estimator_of=estimator_catalogue(chapter, d.study))
        out[d.id] = {"verdict": decision.verdict, "statistic": decision.statistic,
                     "low": decision.low, "high": decision.high, "n": decision.n}
    return out


def write_stored_verdicts(chapter: str, root: Path = DECISIVE_DIR) -> Path:
    """``<root>/<chapter>/verdicts.json``: :func:`stored_verdicts`, which CI recomputes."""
    path = root / chapter / "verdicts.json"
    path.write_text(json.dumps(stored_verdicts(chapter, root), indent=1, sort_keys=True) + "\n")
    return path


def _stored_cpu_per_record(folder: Path, study: str) -> float:
    """CPU seconds per record of a study already in the store (its provenance), else 0."""
    path = folder / "provenance.json"
    if path.exists():
        entry = json.loads(path.read_text()).get("studies", {}).get(study)
        if entry and entry.get("records"):
            return entry["cpu_s"] / entry["records"]
    return 0.0


def _write_provenance(folder: Path, item: StudyPlan, settings, commit: str, workers: int,
                      wall_s: float, cpu_s: float, computed: int) -> None:
    """Record a study's computation in ``folder/provenance.json``: this run computed
    ``computed`` of its ``item.size`` records; the others were stored, and keep their share of
    what the stored records cost (their recorded time per record)."""
    path = folder / "provenance.json"
    record = json.loads(path.read_text()) if path.exists() else {"studies": {}}
    record.update(commit=commit, date=datetime.date.today().isoformat(),
                  settings=settings.as_dict(), machine=machine())
    before = record["studies"].get(item.study, {})
    reused = (item.size - computed) / before["records"] if before.get("records") else 0.0
    record["studies"][item.study] = {
        "seeds": [item.first, item.first + item.size], "records": item.size,
        "workers": workers,
        "wall_s": round(reused * before.get("wall_s", 0.0) + wall_s, 1),
        "cpu_s": round(reused * before.get("cpu_s", 0.0) + cpu_s, 1)}
    folder.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(record, indent=1, sort_keys=True) + "\n")


def check_provenance(chapter: str, root: Path = DECISIVE_DIR) -> list[str]:
    """One line per problem of a chapter's stored evidence: a provenance whose settings are not
    the chapter's defaults, or a study whose stored rows are fewer than it says."""
    path = root / chapter / "provenance.json"
    if not path.exists():
        return []
    record = json.loads(path.read_text())
    problems = []
    defaults = chapter_spec(chapter).resolve({}, False)
    if record.get("settings") != defaults.as_dict():
        problems.append(f"{path}: its settings are not the chapter's defaults; regenerate with "
                        "'railpaper evidence --decisive'")
    store = EvidenceStore(root)
    for name, study in record.get("studies", {}).items():
        rows = store.read(RecordStudy(chapter, name, rows=None), defaults)
        if len(rows) < study["records"]:
            problems.append(f"{path}: study {name} holds {len(rows)} of its {study['records']} "
                            "records")
    return problems


__all__ = ["ALLOCATION_FILE", "CPU_BUDGET_S", "DECISIVE_DIR", "PILOT_SEED", "StudyPlan",
           "affordable", "allocate_sizes", "allocated_size", "chapter_studies",
           "check_provenance", "pilot_sigma", "plan", "register_chapter", "run_decisive",
           "stored_provenance", "stored_rows", "stored_verdicts", "write_allocation",
           "write_stored_verdicts"]
