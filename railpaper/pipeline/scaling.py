"""How the chapters' Monte Carlo scales with workers: a benchmark, not a test.

On a fixed subset of every chapter's per-record work — about 5 % of the records its decisive
evidence holds, or of its default run where it has none stored — the same records are computed
by the pipeline's record map (:func:`railpaper.pipeline.evidence_store.stored_map`, no store) on a
dask ``LocalCluster`` of 1 and of 2 single-threaded workers, alternated (1, 2, 1, 2, …; each
cluster started before its timing).  Printed per chapter: the median wall time of each, the
speed-up 1 → 2 as the median of the per-alternation ratios with its min–max, the records per
CPU-second (CPU measured in the workers), and the load the rest of the machine put on the cores
meanwhile.  ``railpaper bench --scaling --out FILE`` keeps the payload.
"""

from __future__ import annotations

import json
import os
import statistics
import time
from dataclasses import dataclass

from railpaper.experiments import load_chapter
from railpaper.pipeline.chapters import chapter_spec
from railpaper.pipeline.decisive import DECISIVE_DIR
from railpaper.pipeline.evidence_store import stored_map
from railpaper.pipeline.sweep import close_client, make_client
from railpaper.timing import machine_busy_s

#: Share of a study's records the benchmark computes.
SUBSET_SHARE = 0.05
#: Fewest records per timing (two chunks at least, so two workers can share them).
MIN_RECORDS = 8


@dataclass(frozen=True)
class Work:
    """One chapter's subset: a study and its records."""

    chapter: str
    study: str
    seeds: tuple[int, ...]


def subsets(chapters: list[str]) -> list[Work]:
    """Each chapter's first study, over :data:`SUBSET_SHARE` of the records stored for it
    (else of its default run's), at least :data:`MIN_RECORDS` and two chunks."""
    work = []
    for chapter in chapters:
        studies = getattr(load_chapter(chapter), "STUDIES", ())
        if not studies:
            continue
        study = studies[0]
        settings = chapter_spec(chapter).resolve({}, False)
        provenance = DECISIVE_DIR / chapter / "provenance.json"
        total = (json.loads(provenance.read_text())["studies"].get(study.name, {}).get("records")
                 if provenance.exists() else None) or _default_records(settings)
        n = max(MIN_RECORDS, 2 * study.chunk_records, round(SUBSET_SHARE * total))
        first = study.first(settings)
        work.append(Work(chapter, study.name, tuple(range(first, first + n))))
    return work


def _default_records(settings) -> int:
    for name in ("mc_seeds", "n_seeds", "n_monte_carlo", "n_records"):
        if hasattr(settings, name):
            return int(getattr(settings, name))
    return MIN_RECORDS


def time_once(work: Work, workers: int) -> dict:
    """One timing of ``work`` on a fresh cluster of ``workers``."""
    study = {s.name: s for s in load_chapter(work.chapter).STUDIES}[work.study]
    settings = chapter_spec(work.chapter).resolve({}, False)
    client, cluster = make_client(None, workers)
    try:
        record_map = stored_map(None, client=client, commit="bench")
        record_map(study, settings, work.seeds[:study.chunk_records])   # workers warm (imports)
        before = dict(record_map.usage)
        busy, started = machine_busy_s() or 0.0, time.perf_counter()
        record_map(study, settings, work.seeds)
        wall = time.perf_counter() - started
        busy = (machine_busy_s() or 0.0) - busy
    finally:
        close_client(client, cluster)
    cpu = record_map.usage["cpu_s"] - before["cpu_s"]
    return {"workers": workers, "wall_s": wall, "cpu_s": cpu,
            "other_cores": max(0.0, (busy - cpu) / wall)}


def run_scaling(chapters: list[str], alternations: int = 3, say=print) -> dict:
    """The benchmark's payload: per chapter the timings, the 1 → 2 speed-up and records per
    CPU-second; one table printed."""
    rows = []
    for work in subsets(chapters):
        timings = {1: [], 2: []}
        for _ in range(alternations):
            for workers in (1, 2):
                timings[workers].append(time_once(work, workers))
        ratios = [a["wall_s"] / b["wall_s"] for a, b in zip(timings[1], timings[2])]
        cpu = [t["cpu_s"] for t in timings[1] + timings[2]]
        rows.append({"chapter": work.chapter, "study": work.study, "records": len(work.seeds),
                     "wall_s_1": statistics.median(t["wall_s"] for t in timings[1]),
                     "wall_s_2": statistics.median(t["wall_s"] for t in timings[2]),
                     "speedup": statistics.median(ratios), "speedup_min": min(ratios),
                     "speedup_max": max(ratios),
                     "records_per_cpu_s": len(work.seeds) / statistics.median(cpu),
                     "other_cores_max": max(t["other_cores"]
                                            for t in timings[1] + timings[2])})
    say(f"{'chapter':24s} {'study':14s} {'records':>7s} {'1 worker s':>10s} {'2 workers s':>11s} "
        f"{'speed-up [min-max]':>20s} {'records/CPU-s':>13s} {'other load':>10s}")
    for r in rows:
        say(f"{r['chapter']:24s} {r['study']:14s} {r['records']:7d} {r['wall_s_1']:10.1f} "
            f"{r['wall_s_2']:11.1f} {r['speedup']:8.2f} [{r['speedup_min']:.2f}-"
            f"{r['speedup_max']:.2f}] {r['records_per_cpu_s']:13.2f} {r['other_cores_max']:10.2f}")
    return {"alternations": alternations, "cores": os.cpu_count(), "rows": rows}


__all__ = ["SUBSET_SHARE", "Work", "run_scaling", "subsets", "time_once"]
