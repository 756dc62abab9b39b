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

import numpy as np

from railpaper.engine import LinearGaussianBatch, windowed_change_statistics
from railpaper.experiments.records import map_in_process
from railpaper.pipeline.chapters import chapter_spec
from railpaper.pipeline.decisive import chapter_studies

#: The studies whose first record compiles the most (chapter 003's paper-scheme RBPF and its toy,
#: each several times any other): they start first so that the processes finish together.
FIRST = (("rbpf-parameter-estimation", "lateral_paper_scheme"),
         ("rbpf-parameter-estimation", "toy"))
#: Kernels no paper chapter's study calls, compiled by a small call of their own: the fault
#: appendix's windowed change bank (:func:`railpaper.engine.windowed_change_statistics`, about
#: 6 s to compile), which the quick book and the tests would otherwise compile while they run.
ENGINE = "engine"
ENGINE_TASKS = ((ENGINE, "windowed_change_statistics"),)


def kernel_tasks(chapters: list[str]) -> list[tuple[str, str]]:
    """(chapter, study) for every per-record study of ``chapters``, :data:`FIRST` first; a
    study that repeats another under other settings (``RecordStudy.repeats``) compiles nothing
    new and is left out."""
    tasks = [(chapter, name) for chapter in chapters
             for name, study in chapter_studies(chapter).items() if not study.repeats]
    return sorted(tasks, key=lambda task: task not in FIRST) + list(ENGINE_TASKS)


def _one_record(chapter: str, study: str) -> tuple[str, str, float]:
    """Compute (and discard) the first record of one study at the chapter's quick settings."""
    started = time.perf_counter()
    if chapter == ENGINE:
        _windowed_bank_once()
        return chapter, study, time.perf_counter() - started
    settings = chapter_spec(chapter).resolve({}, True)
    target = chapter_studies(chapter)[study]
    map_in_process(target, settings, [target.first(settings)])
    return chapter, study, time.perf_counter() - started


def _windowed_bank_once() -> None:
    """:func:`railpaper.engine.windowed_change_statistics` on a two-state model with an input
    (the argument types of the appendix's lateral records: float64 stacks, a B matrix)."""
    def system(theta):
        theta = np.atleast_2d(theta)
        F = np.zeros((len(theta), 2, 2))
        F[:, 0, 0], F[:, 1, 1] = theta[:, 0], 0.5
        return LinearGaussianBatch(F, np.eye(2), np.ones((len(theta), 1, 2)), np.eye(1),
                                   np.ones((len(theta), 2, 1)))
    windowed_change_statistics(system, np.zeros((6, 1)), [0.9], [[0.5], [0.1]], 2,
                               np.zeros(2), np.eye(2), u=np.zeros((6, 1)))


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


__all__ = ["ENGINE_TASKS", "FIRST", "compile_kernels", "kernel_tasks"]
