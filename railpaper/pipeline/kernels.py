"""Compile the library's numba kernels into numba's on-disk cache once, before anything runs.

The engine's kernels are ``numba.njit(cache=True)``: the first process that calls one compiles
it for the argument types it sees and writes the machine code beside the source
(``__pycache__/*.nbi``, ``*.nbc``); every later process loads it.  On a fresh checkout nothing
is cached, and the processes of a test session — two test workers, the quick book's chapter
kernels, dask workers — start together and each compile the same kernels.
:func:`compile_kernels` does that work once, before them: one record of every chapter's every
per-record study at its quick settings, the studies spread over a few processes, largest
first, and the engine's kernels that no study calls but its tests and the bench do
(:func:`engine_only_kernels`: two test workers would otherwise compile them at once).  The
records computed are thrown away; only the cache stays.  ``make test`` runs it
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

from railpaper.engine import QuasiGaussianRBPF, zoh_sparse, zoh_stack
from railpaper.experiments.lateral_vehicle import vehicle
from railpaper.experiments.records import map_in_process
from railpaper.models import lateral_16state
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
    """Compute (and discard) the first record of one study at the chapter's quick settings (or,
    for :data:`ENGINE_ONLY`, call :func:`engine_only_kernels`)."""
    started = time.perf_counter()
    if (chapter, study) == ENGINE_ONLY:
        engine_only_kernels()
        return chapter, study, time.perf_counter() - started
    settings = chapter_spec(chapter).resolve({}, True)
    target = chapter_studies(chapter)[study]
    map_in_process(target, settings, [target.first(settings)])
    return chapter, study, time.perf_counter() - started


#: The task of :func:`engine_only_kernels` in :func:`compile_kernels`'s list.
ENGINE_ONLY = ("engine", "kernels no study calls")


def engine_only_kernels() -> None:
    """Call, once, the engine's compiled paths that no chapter study takes (the studies use the
    affine passes and the affine ZOH), with the argument types the engine's tests give them: the
    dense batch ZOH (``zoh_stack``, Van Loan through the parallel ``expm_stack``), the general
    sparse ZOH (``zoh_sparse``) and the step-by-step Q-GRBPF's compiled split update
    (``kalman_predict``, then ``kalman_update``) on the 16-state lateral model, 300 km/h, 1 ms."""
    fixed, theta = vehicle()
    speed_mps, dt_s = 300 / 3.6, 1e-3
    A0, Ak = lateral_16state.affine_terms(fixed, speed_mps)
    B = lateral_16state.input_matrix()
    A = lateral_16state.a_of_theta(A0, Ak, theta * np.linspace(0.6, 1.4, 4)[:, None])
    zoh_stack(A, B, dt_s)
    zoh_sparse(A, B, dt_s)
    R = np.diag([0.1, 0.1, 0.1, 0.01, 0.001]) ** 2
    system = lateral_16state.lateral_system(fixed, speed_mps, dt_s, 1e-12 * np.eye(16), R)
    rng = np.random.default_rng(0)
    particles = theta * rng.uniform(0.5, 1.7, (8, 5))
    filt = QuasiGaussianRBPF(system, particles, np.zeros(16), 1e-10 * np.eye(16), rng)
    for _ in range(2):
        filt.step(1e-3 * rng.standard_normal(5), np.zeros(2))
    filt.materialise()


def compile_kernels(chapters: list[str], jobs: int = 2,
                    progress: Callable[[str], None] | None = print) -> float:
    """One record of every study of ``chapters``, and :func:`engine_only_kernels`, on ``jobs``
    fresh processes (spawned: no state of this one is shared); returns the wall seconds.  A failure is raised as it is."""
    started = time.perf_counter()
    tasks = [ENGINE_ONLY] + kernel_tasks(chapters)             # the longest task first
    context = multiprocessing.get_context("spawn")
    with ProcessPoolExecutor(max_workers=max(1, jobs), mp_context=context) as pool:
        futures = [pool.submit(_one_record, chapter, study) for chapter, study in tasks]
        for done, future in enumerate(as_completed(futures), 1):
            chapter, study, seconds = future.result()
            if progress is not None:
                progress(f"railpaper: compile: {done}/{len(tasks)} {chapter} {study} "
                         f"({seconds:.1f} s)")
    return time.perf_counter() - started


__all__ = ["ENGINE_ONLY", "FIRST", "compile_kernels", "engine_only_kernels", "kernel_tasks"]
