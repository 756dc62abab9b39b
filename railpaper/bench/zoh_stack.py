"""Micro-benchmark of the per-particle ZOH alone: the sparse Taylor route vs the engine's.

:func:`railpaper.engine.sparse_zoh.zoh_sparse` against :func:`railpaper.engine.batch_expm.zoh_stack` (balanced
degree-12 Taylor with one squaring on the dense 18×18 augmented blocks), on N lateral
A(θ) with θ drawn over the prior box (0.5–1.7 × truth, seed 1), dt = 1 ms, 300 km/h.

Timed in this process, interleaved (old, new, old, new, …; :mod:`railpaper.timing`): each
alternation times ``CALLS`` calls of each and keeps their median; a time is the median over
the alternations with its min–max, a ratio the median of the per-alternation ratios.  Run at 1
and at ``NUMBA_NUM_THREADS`` numba threads; the 1-minute load is sampled before, between and
after.  Multiply-adds per particle are counted from the pattern and the term counts.

Usage: ``NUMBA_NUM_THREADS=2 .venv/bin/python -m railpaper.bench.zoh_stack [N] [alternations]``;
prints one JSON document.
"""

from __future__ import annotations

import json
import sys
import time

import numba
import numpy as np

from railpaper.engine import ZOH_BLOCK, term_counts, zoh_multiply_adds, zoh_sparse, zoh_stack
from railpaper.experiments.rbpf_parameter_estimation.lateral import vehicle
from railpaper.models import lateral_16state
from railpaper.timing import LoadLog, interleaved, paired_ratio, summary

CALLS = 15
DENSE_MULTIPLY_ADDS = 6 * 18 ** 3   # expm_stack: 5 products (Paterson–Stockmeyer) + 1 squaring


def lateral_stack(n_particles: int, seed: int = 1) -> tuple[np.ndarray, np.ndarray]:
    fixed, theta = vehicle()
    A0, Ak = lateral_16state.affine_terms(fixed, 300 / 3.6)
    factors = np.random.default_rng(seed).uniform(0.5, 1.7, (n_particles, 5))
    return lateral_16state.a_of_theta(A0, Ak, theta * factors), lateral_16state.input_matrix()


def median_call_s(f, A, B, dt) -> float:
    """Median wall time (s) of CALLS calls."""
    times = []
    for _ in range(CALLS):
        t0 = time.perf_counter()
        f(A, B, dt)
        times.append(time.perf_counter() - t0)
    return float(np.median(times))


def main(n_particles: int = 1000, alternations: int = 7) -> dict:
    A, B = lateral_stack(n_particles)
    dt = 1e-3
    zoh_stack(A, B, dt), zoh_sparse(A, B, dt)                  # compile / load the caches
    K, s = term_counts(A, B, dt)
    nnz = int(np.count_nonzero(np.any(np.concatenate(
        [A, np.broadcast_to(B, A.shape[:1] + B.shape)], axis=-1) != 0, axis=0)))
    log, out = LoadLog(), dict(n_particles=n_particles, alternations=alternations, calls=CALLS)
    log.sample("start")
    for threads in (1, numba.config.NUMBA_NUM_THREADS):
        numba.set_num_threads(threads)
        t = interleaved({"dense": lambda: median_call_s(zoh_stack, A, B, dt),
                         "sparse": lambda: median_call_s(zoh_sparse, A, B, dt)}, alternations)
        out[f"threads_{threads}"] = dict(
            dense_ms=summary(np.array(t["dense"]) * 1e3),
            sparse_ms=summary(np.array(t["sparse"]) * 1e3),
            ratio_dense_over_sparse=paired_ratio(t["dense"], t["sparse"]))
        log.sample(f"after {threads} thread(s)")
    # per particle, each block runs its largest K (its lanes are masked, not skipped)
    blocks = [K[i:i + ZOH_BLOCK].max() for i in range(0, len(K), ZOH_BLOCK)]
    out["multiply_adds_per_particle"] = dict(
        sparse_own_terms=float(np.mean([zoh_multiply_adds(nnz, 16, 2, k, q)
                                        for k, q in zip(K, s)])),
        sparse_as_run=float(np.mean([zoh_multiply_adds(nnz, 16, 2, k) for k in blocks])),
        dense=DENSE_MULTIPLY_ADDS, nnz=nnz,
        terms=dict(min=int(K.min()), max=int(K.max()), mean=float(K.mean())),
        squarings_max=int(s.max()))
    out.update(log.as_dict())
    return out


if __name__ == "__main__":
    args = [int(a) for a in sys.argv[1:3]]
    print(json.dumps(main(*args), indent=1))
