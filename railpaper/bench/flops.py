"""FLOP count of a paper-scheme RBPF step and the fraction of the machine's peak it attains.

The work of one step at N particles is counted from the kernels' structure, not measured:

* the Kalman bank: :func:`railpaper.engine.kalman_bank.multiply_adds` per particle, H's
  structural zeros skipped as the kernels skip them;
* the new matrices of the moved particles: :func:`railpaper.engine.sparse_zoh.multiply_adds` with the
  Taylor terms and squarings each particle's θ really needs (:func:`railpaper.engine.sparse_zoh.term_counts`);

one multiply-add = 2 FLOP.  Divided by the profiled milliseconds of those parts it gives the
attained GFLOP/s.  The reference rate is measured in the same process: numpy's ``matmul`` of two
2000 × 2000 matrices (OpenBLAS dgemm on every core), the practical peak of this machine for
double precision.  A nominal peak from the clock (cores × 32 FLOP per cycle: two AVX-512 FMA
units) is reported beside it, labelled as an assumption (dgemm reaching ≈ 90 % of it on the
benchmark machine supports it).
"""

from __future__ import annotations

import os
import time

import numpy as np

from railpaper.engine import bank_multiply_adds, measurement_pattern, term_counts, zoh_multiply_adds
from railpaper.models import lateral_16state

NOMINAL_FLOP_PER_CYCLE = 32      # per core, double: two 512-bit FMA units (8 lanes x 2 FLOP x 2)


def dgemm_gflops(n: int = 2000, repeats: int = 5) -> float:
    """Median GFLOP/s of ``A @ B`` (n × n, float64) over ``repeats`` timed products."""
    rng = np.random.default_rng(0)
    A, B = rng.standard_normal((n, n)), rng.standard_normal((n, n))
    A @ B                                                   # warm the BLAS threads
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        A @ B
        times.append(time.perf_counter() - t0)
    return 2.0 * n ** 3 / float(np.median(times)) / 1e9


def clock_ghz() -> float | None:
    """The first core's clock from /proc/cpuinfo (GHz), None where not available."""
    try:
        with open("/proc/cpuinfo") as f:
            for line in f:
                if line.startswith("cpu MHz"):
                    return float(line.split(":")[1]) / 1e3
    except OSError:
        pass
    return None


def step_budget(prob: dict, profile_ms: dict, N: int = 1000, seed: int = 11) -> dict:
    """FLOP of a paper-scheme step at N and the attained rates of its two kernels.

    ``profile_ms`` is :func:`railpaper.bench.rbpf_engine.profile_step`'s medians at the same N.
    """
    settings, theta = prob["settings"], prob["theta"]
    rng = np.random.default_rng(seed)
    th = theta * rng.uniform(settings.prior_low, settings.prior_high, (N, 5))
    A = lateral_16state.a_of_theta(prob["A0"], prob["Ak"], th)
    B = lateral_16state.input_matrix()
    K, s = term_counts(A, B, settings.dt_s)
    nnz = int(np.count_nonzero((A != 0).any(axis=0))) + int(np.count_nonzero(B))
    n, m, n_ch = lateral_16state.N_STATES, B.shape[1], len(lateral_16state.CHANNELS)
    zoh_madds = float(np.mean([zoh_multiply_adds(nnz, n, m, int(k), int(q))
                               for k, q in zip(K, s)]))
    # as the kernels skip
    h_row_nonzeros = measurement_pattern(lateral_16state.measurement_matrix(A))[1]
    bank_madds = bank_multiply_adds(n, n_ch, m, h_row_nonzeros)
    bank_gflop = 2.0 * bank_madds * N / 1e9
    zoh_gflop = 2.0 * zoh_madds * N / 1e9
    dgemm = dgemm_gflops()
    ghz = clock_ghz()
    cores = os.cpu_count()
    bank_rate = bank_gflop / (profile_ms["kalman_bank_ms"] / 1e3)
    zoh_rate = zoh_gflop / (profile_ms["zoh_all_particles_ms"] / 1e3)
    return dict(N=N, bank_multiply_adds_per_particle=bank_madds,
                zoh_multiply_adds_per_particle=zoh_madds, zoh_terms_median=float(np.median(K)),
                step_gflop=bank_gflop + zoh_gflop,
                bank_gflops=bank_rate, zoh_gflops=zoh_rate, dgemm_gflops=dgemm,
                bank_fraction_of_dgemm=bank_rate / dgemm, zoh_fraction_of_dgemm=zoh_rate / dgemm,
                nominal_flop_per_cycle=NOMINAL_FLOP_PER_CYCLE,
                nominal_peak_gflops=(None if ghz is None
                                     else cores * NOMINAL_FLOP_PER_CYCLE * ghz),
                clock_ghz=ghz)
