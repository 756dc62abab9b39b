"""Matrix exponentials of a stack of small matrices, compiled: the per-particle ZOH of the RBPF.

For a stack ``M`` (N, k, k) of matrices of similar size (one per particle, e.g. ``[[A(θ_i) dt,
B dt], [0, 0]]``) we compute ``e^M`` by

1. balancing with a fixed diagonal similarity ``X = D⁻¹ M D`` (``D`` from
   :func:`scipy.linalg.matrix_balance` of a representative matrix, powers of two, so exact):
   for the lateral model of paper 003 this takes the 1-norm of ``A dt`` from ≈ 80 to ≈ 1;
2. scaling ``X / 2^s`` with ``s`` chosen per block so that ``‖X / 2^s‖₁ ≤ 1/2``;
3. the degree-12 Taylor polynomial by Paterson–Stockmeyer (5 matrix products); the truncation
   error is ≤ ``(1/2)^13 / 13! · e^{1/2} ≈ 3e-14`` relative;
4. ``s`` squarings and undoing the balancing.

The result agrees with :func:`scipy.linalg.expm` (Padé 13) to ≈ 1e-13 relative for the lateral
model; tests/engine/test_kalman_bank.py asserts ≤ 1e-10 on it and on random stable matrices.

:func:`railpaper.engine.sparse_zoh.zoh_sparse` computes the same ZOH on the augmented matrix's nonzeros,
without squaring inside the lateral model's prior box (≈ 13k instead of ≈ 35k multiply-adds per
particle), and :func:`railpaper.engine.sparse_zoh.zoh_affine` does so straight from θ: the lateral model's
``system`` uses the latter since issue 15.  :func:`zoh_stack` stays the dense general-purpose
route (and :func:`stack_matmul` the Kalman bank's product).
"""

from __future__ import annotations

import math

import numba
import numpy as np
from scipy.linalg import matrix_balance

from railpaper.engine.kernel_arrays import kernel_array

BLOCK = 64
TAYLOR = tuple(1.0 / math.factorial(j) for j in range(13))


@numba.njit(fastmath={"contract"}, cache=True)
def stack_matmul(A, B, C):  # pragma: no cover - compiled
    """C = A @ B for stacks A (r, k, nb), B (k, c, nb), C (r, c, nb): the matrices' batch axis
    is the last one, so the innermost loop runs over the batch (one SIMD loop per formula).

    Register blocking: two rows of C share each load of B, and four terms are added per load
    and store of C (``C[i, j] += A[i, l] B[l, j]`` for l, …, l+3, in that order).  Every entry
    is still the sum over l = 0, 1, …, k−1 in order, one fused multiply-add per term, so the bits
    are those of the plain triple loop; the blocking only keeps C in registers longer (on the
    16 × 16 products of the Kalman bank ≈ 1.4× the plain loop's rate)."""
    r, k, c, nb = A.shape[0], A.shape[1], B.shape[1], A.shape[2]
    r2, k4 = r - r % 2, k - k % 4
    C[:] = 0.0
    for i in range(0, r2, 2):
        for l in range(0, k4, 4):
            for j in range(c):
                for q in range(nb):
                    b0, b1, b2, b3 = B[l, j, q], B[l + 1, j, q], B[l + 2, j, q], B[l + 3, j, q]
                    C[i, j, q] = (C[i, j, q] + A[i, l, q] * b0 + A[i, l + 1, q] * b1
                                  + A[i, l + 2, q] * b2 + A[i, l + 3, q] * b3)
                    C[i + 1, j, q] = (C[i + 1, j, q] + A[i + 1, l, q] * b0
                                      + A[i + 1, l + 1, q] * b1 + A[i + 1, l + 2, q] * b2
                                      + A[i + 1, l + 3, q] * b3)
        for l in range(k4, k):
            for j in range(c):
                for q in range(nb):
                    C[i, j, q] += A[i, l, q] * B[l, j, q]
                    C[i + 1, j, q] += A[i + 1, l, q] * B[l, j, q]
    for i in range(r2, r):
        for l in range(k):
            for j in range(c):
                for q in range(nb):
                    C[i, j, q] += A[i, l, q] * B[l, j, q]


@numba.njit(fastmath={"contract"}, cache=True)
def _poly(X, X2, X3, X4, c, out):  # pragma: no cover - compiled
    """out = c0 I + c1 X + c2 X² + c3 X³ (+ c4 X⁴ when len(c) == 5)."""
    k, nb = X.shape[0], X.shape[2]
    for i in range(k):
        for j in range(k):
            for q in range(nb):
                v = c[1] * X[i, j, q] + c[2] * X2[i, j, q] + c[3] * X3[i, j, q]
                if c.shape[0] == 5:
                    v += c[4] * X4[i, j, q]
                out[i, j, q] = v + (c[0] if i == j else 0.0)


@numba.njit(parallel=True, fastmath={"contract"}, cache=True)
def _expm_stack(M, scale, coef, out):  # pragma: no cover - compiled
    N, k = M.shape[0], M.shape[1]
    n_blocks = (N + BLOCK - 1) // BLOCK
    for b in numba.prange(n_blocks):
        lo = b * BLOCK
        nb = min(BLOCK, N - lo)
        X = np.empty((k, k, nb))
        for q in range(nb):
            for i in range(k):
                for j in range(k):
                    X[i, j, q] = M[lo + q, i, j] * scale[j] / scale[i]      # D⁻¹ M D
        norm = 0.0                                                        # max ‖X‖₁ in block
        for q in range(nb):
            for j in range(k):
                col = 0.0
                for i in range(k):
                    col += abs(X[i, j, q])
                norm = max(norm, col)
        s = 0
        while norm > 0.5 and s < 60:
            norm *= 0.5
            s += 1
        X *= 0.5 ** s                                                     # X / 2^s
        X2, X3, X4 = np.empty_like(X), np.empty_like(X), np.empty_like(X)
        T, U = np.empty_like(X), np.empty_like(X)
        stack_matmul(X, X, X2)
        stack_matmul(X2, X, X3)
        stack_matmul(X2, X2, X4)
        _poly(X, X2, X3, X4, coef[8:13], T)                               # Paterson–Stockmeyer
        stack_matmul(X4, T, U)
        _poly(X, X2, X3, X4, coef[4:8], T)
        T += U
        stack_matmul(X4, T, U)
        _poly(X, X2, X3, X4, coef[0:4], T)
        T += U
        for _ in range(s):                                                # (e^{X/2^s})^(2^s)
            stack_matmul(T, T, U)
            T[:] = U
        for q in range(nb):
            for i in range(k):
                for j in range(k):
                    out[lo + q, i, j] = T[i, j, q] * scale[i] / scale[j]  # D e^X D⁻¹


def balancing(M: np.ndarray) -> np.ndarray:
    """Diagonal ``d`` (powers of two) with ``diag(d)⁻¹ M diag(d)`` balanced (scipy)."""
    _, (scale, _) = matrix_balance(np.asarray(M, float), permute=False, separate=True)
    return np.asarray(scale, float)


def expm_stack(M: np.ndarray, scale: np.ndarray | None = None) -> np.ndarray:
    """``e^{M_i}`` for a stack ``M`` (N, k, k) (or one matrix (k, k)).

    Parameters
    ----------
    M : ndarray, (N, k, k) or (k, k)
    scale : ndarray, (k,), optional
        Balancing diagonal (see :func:`balancing`); default: balance ``M[0]``.

    Returns
    -------
    ndarray, shape of M
    """
    M = np.asarray(M, float)
    single = M.ndim == 2
    stack = kernel_array(M[None] if single else M)
    if not np.all(np.isfinite(stack)):
        raise ValueError("expm_stack: matrix has NaN or inf entries")
    d = balancing(stack[0]) if scale is None else np.asarray(scale, float)
    out = np.empty_like(stack)
    _expm_stack(stack, d, np.array(TAYLOR), out)
    return out[0] if single else out


def zoh_stack(A: np.ndarray, B: np.ndarray, dt_s: float, scale: np.ndarray | None = None
              ) -> tuple[np.ndarray, np.ndarray]:
    """Exact ZOH ``(e^{A dt}, ∫₀^dt e^{As} ds B)`` of a stack A (N, n, n) with a shared B (n, m).

    One :func:`expm_stack` of ``[[A dt, B dt], [0, 0]]`` (Van Loan); ``scale`` balances that
    augmented (n+m)-matrix.
    """
    A = np.asarray(A, float)
    N, n, m = A.shape[0], A.shape[-1], B.shape[-1]
    M = np.zeros((N, n + m, n + m))
    M[:, :n, :n] = A * dt_s
    M[:, :n, n:] = B * dt_s
    E = expm_stack(M, scale)
    return np.ascontiguousarray(E[:, :n, :n]), np.ascontiguousarray(E[:, :n, n:])  # copied once
