"""Compile the library's numba kernels into numba's on-disk cache once, before anything runs.

The engine's kernels are ``numba.njit(cache=True)``: the first process that calls one compiles
it for the argument types it sees and writes the machine code beside the source
(``__pycache__/*.nbi``, ``*.nbc``); every later process loads it.  On a fresh checkout nothing
is cached, and the processes of a test session — two test workers, the quick book's chapter
kernels, dask workers — start together and each compile the same kernels.
:func:`compile_kernels` does that work once, before them: one record of every chapter's every
per-record study at its quick settings, the studies spread over a few processes, largest
first.  The records computed are thrown away; only the cache stays.  ``make test`` runs it
(``railpaper compile``) when the package's source has changed since it last did.

>>> [task[0] for task in kernel_tasks(["partial-state-observer"])][:1]
['partial-state-observer']
"""

from __future__ import annotations

import multiprocessing
import time
from concurrent.futures import ProcessPoolExecutor, as_completed
from typing import Callable

from railpaper.experiments.records import map_in_process
from railpaper.pipeline.chapters import chapter_spec
from railpaper.pipeline.decisive import chapter_studies

#: The studies whose first record compiles the most (chapter 003's paper-scheme RBPF and its toy,
#: each several times any other): they start first so that the processes finish together.
FIRST = (("rbpf-parameter-estimation", "lateral_paper_scheme"),
         ("rbpf-parameter-estimation", "toy"))


def kernel_tasks(chapters: list[str]) -> list[tuple[str, str]]:
    """(chapter, study) for every per-record study of ``chapters``, :data:`FIRST` first; a
    study that repeats another under other settings (``RecordStudy.repeats``) compiles nothing
    new and is left out."""
    tasks = [(chapter, name) for chapter in chapters
             for name, study in chapter_studies(chapter).items() if not study.repeats]
    return sorted(tasks, key=lambda task: task not in FIRST)


def _one_record(chapter: str, study: str) -> tuple[str, str, float]:
    """Compute (and discard) the first record of one study at the chapter's quick settings."""
    started = time.perf_counter()
    settings = chapter_spec(chapter).resolve({}, True)
    target = chapter_studies(chapter)[study]
    map_in_process(target, settings, [target.first(settings)])
    return chapter, study, time.perf_counter() - started


def compile_kernels(chapters: list[str], jobs: int = 2,
                    progress: Callable[[str], None] | None = print) -> float:
    """One record of every study of ``chapters`` on ``jobs`` fresh processes (spawned: no
    state of this one is shared); returns the wall seconds.  A failure is raised as it is."""
    started = time.perf_counter()
    tasks = kernel_tasks(chapters)
    context = multiprocessing.get_context("spawn")
    with ProcessPoolExecutor(max_workers=max(1, jobs), mp_context=context) as pool:
        futures = [pool.submit(_one_record, chapter, study) for chapter, study in tasks]
        for done, future in enumerate(as_completed(futures), 1):
            chapter, study, seconds = future.result()
            if progress is not None:
                progress(f"railpaper: compile: {done}/{len(tasks)} {chapter} {study} "
                         f"({seconds:.1f} s)")
    return time.perf_counter() - started


__all__ = ["FIRST", "compile_kernels", "kernel_tasks"]
