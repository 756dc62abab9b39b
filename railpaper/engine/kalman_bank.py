"""Fused, compiled Kalman step for a bank of N filters (one per particle): the RBPF hot path.

Same model and conventions as :mod:`railpaper.engine.kalman`::

    x_k = F x_{k-1} + B u_k + noise(Q),   y_k = H x_k + noise(R)

One call does the time update, the measurement update and the predictive log-likelihood of every
filter.  It is written for speed, not generality:

* numba, parallel over blocks of ``BLOCK`` filters (``prange``); inside a block every operation
  runs over the filters in the innermost loop (structure of arrays), so each scalar formula of a
  16×16 product becomes one SIMD loop over the block — no Python loop over particles;
* symmetry: only the upper triangle of ``F P Fᵀ`` and of the posterior is computed;
* the update uses the whitened gain ``W = L⁻¹ H P⁻`` (``S = L Lᵀ``)::

      x = x⁻ + Wᵀ z,   z = L⁻¹ v       (= x⁻ + K v,  K = P⁻ Hᵀ S⁻¹)
      P = P⁻ − Wᵀ W                     (= P⁻ − K S Kᵀ, symmetric by construction)

  which costs ≈ 8.5k multiply-adds per filter for n = 16, p = 5 instead of ≈ 16k for the
  Joseph form of :func:`railpaper.engine.kalman.update`.  The two agree to rounding on
  well-conditioned problems (tests/engine/test_kalman_bank.py compares them on random stable systems
  and on the lateral model); the Joseph form stays the reference.

Per-filter matrices are (N, ·, ·); a shared one is passed as a (1, ·, ·) stack (stride 0 in the
kernel), so every call has the same compiled signature.
"""

from __future__ import annotations

import math

import numba
import numpy as np

from railpaper.engine.batch_expm import stack_matmul
from railpaper.engine.kalman import LOG_2PI
from railpaper.engine.linear_gaussian import LinearGaussianBatch

BLOCK = 64          # filters per block: the SIMD loop length inside the kernels


@numba.njit(fastmath={"contract"}, cache=True)
def _symmetric_abt(A, B, D, lo, d_stride, C):  # pragma: no cover - compiled
    """C = A Bᵀ + D[(lo + q) · d_stride] for a block (batch in the last axis) whose result is
    known to be symmetric: the upper triangle is computed and mirrored."""
    r, k, nb = A.shape[0], A.shape[1], A.shape[2]
    for i in range(r):
        for j in range(i, r):
            for q in range(nb):
                C[i, j, q] = D[(lo + q) * d_stride, i, j]
        for l in range(k):
            for j in range(i, r):
                for q in range(nb):
                    C[i, j, q] += A[i, l, q] * B[j, l, q]
        for j in range(i + 1, r):
            for q in range(nb):
                C[j, i, q] = C[i, j, q]


@numba.njit(parallel=True, fastmath={"contract"}, cache=True)
def _kf_run(x, P, F, Q, B, U, H, R, Y, ancestors, x_out, P_out, loglik, x_hist, var_hist,
            record, block):  # pragma: no cover - compiled
    N, n = x_out.shape
    p = H.shape[1]
    m = B.shape[2]
    n_steps = Y.shape[0]
    sF, sQ, sB = int(F.shape[0] > 1), int(Q.shape[0] > 1), int(B.shape[0] > 1)
    sH, sR = int(H.shape[0] > 1), int(R.shape[0] > 1)        # 0: one matrix shared by all
    n_blocks = (N + block - 1) // block
    for b in numba.prange(n_blocks):
        lo = b * block
        nb = min(block, N - lo)
        Fl, Pl, Hl = np.empty((n, n, nb)), np.empty((n, n, nb)), np.empty((p, n, nb))
        xl = np.empty((n, nb))
        anc = ancestors[lo:lo + nb]               # x, P from the ancestor: a resampling's copy
        for i in range(n):                        # gather the block once (structure of arrays)
            for q in range(nb):
                xl[i, q] = x[anc[q], i]
            for j in range(n):
                for q in range(nb):
                    Fl[i, j, q] = F[(lo + q) * sF, i, j]
                for q in range(nb):
                    Pl[i, j, q] = P[anc[q], i, j]
        for r in range(p):
            for j in range(n):
                for q in range(nb):
                    Hl[r, j, q] = H[(lo + q) * sH, r, j]
        xp, FP, HP = np.empty((n, nb)), np.empty((n, n, nb)), np.empty((p, n, nb))
        S, v, Lc = np.empty((p, p, nb)), np.empty((p, nb)), np.zeros((p, p, nb))
        z, W = np.empty((p, nb)), np.empty((p, n, nb))
        logdet, bad = np.empty(nb), np.empty(nb, dtype=np.bool_)
        for t in range(n_steps):                  # the block stays in cache over the steps
            # x⁻ = F x + B u
            xp[:] = 0.0
            for i in range(n):
                for k in range(n):
                    for q in range(nb):
                        xp[i, q] += Fl[i, k, q] * xl[k, q]
                for c in range(m):
                    for q in range(nb):
                        xp[i, q] += B[(lo + q) * sB, i, c] * U[t, c]
            stack_matmul(Fl, Pl, FP)              # F P
            _symmetric_abt(FP, Fl, Q, lo, sQ, Pl)  # P⁻ = F P Fᵀ + Q; it overwrites Pl
            stack_matmul(Hl, Pl, HP)              # H P⁻ (p, n)
            _symmetric_abt(HP, Hl, R, lo, sR, S)  # S = H P⁻ Hᵀ + R
            # v = y − H x⁻
            for r in range(p):
                for q in range(nb):
                    v[r, q] = Y[t, r]
                for k in range(n):
                    for q in range(nb):
                        v[r, q] -= Hl[r, k, q] * xp[k, q]
            # S = L Lᵀ (Cholesky per filter); not positive definite -> no update, −inf
            logdet[:] = 0.0
            bad[:] = False
            for j in range(p):
                for q in range(nb):
                    s = S[j, j, q]
                    for k in range(j):
                        s -= Lc[j, k, q] * Lc[j, k, q]
                    if not s > 0.0:               # also catches NaN
                        bad[q] = True
                        s = 1.0
                    Lc[j, j, q] = math.sqrt(s)
                    logdet[q] += math.log(s)
                for i in range(j + 1, p):
                    for q in range(nb):
                        s = S[j, i, q]
                        for k in range(j):
                            s -= Lc[i, k, q] * Lc[j, k, q]
                        Lc[i, j, q] = s / Lc[j, j, q]
            # z = L⁻¹ v ; W = L⁻¹ H P⁻ (forward substitution)
            for r in range(p):
                for q in range(nb):
                    z[r, q] = v[r, q]
                for j in range(n):
                    for q in range(nb):
                        W[r, j, q] = HP[r, j, q]
                for k in range(r):
                    for q in range(nb):
                        z[r, q] -= Lc[r, k, q] * z[k, q]
                    for j in range(n):
                        for q in range(nb):
                            W[r, j, q] -= Lc[r, k, q] * W[k, j, q]
                for q in range(nb):
                    z[r, q] /= Lc[r, r, q]
                for j in range(n):
                    for q in range(nb):
                        W[r, j, q] /= Lc[r, r, q]
            # log N(v; 0, S) = −½ (zᵀz + log|S| + p log 2π)
            for q in range(nb):
                zz = 0.0
                for r in range(p):
                    zz += z[r, q] * z[r, q]
                loglik[lo + q, t] = -math.inf if bad[q] else -0.5 * (zz + logdet[q]
                                                                      + p * LOG_2PI)
                if bad[q]:                        # keep the prior: x = x⁻, P = P⁻
                    for r in range(p):
                        z[r, q] = 0.0
                        for j in range(n):
                            W[r, j, q] = 0.0
            # x = x⁻ + Wᵀ z ; P = P⁻ − Wᵀ W (upper triangle, mirrored)
            for i in range(n):
                for q in range(nb):
                    acc = xp[i, q]
                    for r in range(p):
                        acc += W[r, i, q] * z[r, q]
                    xl[i, q] = acc
            for r in range(p):
                for i in range(n):
                    for j in range(i, n):
                        for q in range(nb):
                            Pl[i, j, q] -= W[r, i, q] * W[r, j, q]
            for i in range(n):
                for j in range(i + 1, n):
                    for q in range(nb):
                        Pl[j, i, q] = Pl[i, j, q]
            if record:
                for q in range(nb):
                    for i in range(n):
                        x_hist[lo + q, t, i] = xl[i, q]
                        var_hist[lo + q, t, i] = Pl[i, i, q]
        for q in range(nb):                       # scatter the block once
            for i in range(n):
                x_out[lo + q, i] = xl[i, q]
                for j in range(n):
                    P_out[lo + q, i, j] = Pl[i, j, q]


def block_size(N: int) -> int:
    """Filters per block for a bank of N: :data:`BLOCK`, or half the bank when it holds at most
    one block, so that a small bank (a waste-free IBIS chain step, say) still gives both
    cores a block.  Every filter's arithmetic is the same in any block (the SIMD loops run
    over filters, never across them), so the choice changes the speed, not the bits
    (tests/engine/test_kalman_bank.py)."""
    return BLOCK if N > BLOCK else max(1, (N + 1) // 2)


def multiply_adds(n: int, p: int, m: int) -> int:
    """Multiply-adds of one filter's step in :func:`_kf_run` (as the kernel runs it, dense H).

    x⁻ = F x + B u: n² + n m;  F P: n³;  F P Fᵀ (upper triangle): n²(n+1)/2;  H P⁻: p n²;
    S (upper): n p(p+1)/2;  v: p n;  Cholesky: Σ_j j (p − j);  z and W = L⁻¹ H P⁻:
    (n + 1) p(p−1)/2;  zᵀz: p;  x += Wᵀ z: n p;  P −= Wᵀ W (upper): p n(n+1)/2.  Lateral
    model (n = 16, p = 5, m = 2): 9 115.  Divisions, square roots and logs are not counted.
    """
    chol = sum(j * (p - j) for j in range(p))
    return (n * n + n * m + n ** 3 + n * n * (n + 1) // 2 + p * n * n + n * p * (p + 1) // 2
            + p * n + chol + (n + 1) * p * (p - 1) // 2 + p + n * p + p * n * (n + 1) // 2)


def _stack(M: np.ndarray | None, shape: tuple[int, int]) -> np.ndarray:
    """M as a C-contiguous (N, r, c) or (1, r, c) stack (1: shared by every filter)."""
    if M is None:
        return np.zeros((1,) + shape)
    M = np.asarray(M, float)
    return np.ascontiguousarray(M if M.ndim == 3 else M[None])


def kalman_run(x: np.ndarray, P: np.ndarray, system: LinearGaussianBatch, Y: np.ndarray,
               U: np.ndarray | None = None, record: bool = False,
               ancestors: np.ndarray | None = None):
    """``K`` consecutive predict + update steps of N Kalman filters with fixed matrices.

    The covariance recursion does not depend on the data, and between parameter moves an
    RBPF's matrices are fixed, so K steps can run in one call: each block of filters is
    gathered once and stays in cache over the K steps.  Step by step the arithmetic is the
    same as K calls of :func:`kalman_step`.

    Parameters
    ----------
    x, P : ndarray, (N, n), (N, n, n)
        Posterior mean and covariance before the first step.
    system : LinearGaussianBatch
    Y : ndarray, (K, p)
        Measurements (shared by the filters).
    U : ndarray, (K, m), optional
        Known inputs.
    record : bool
        Also return every step's posterior means and variances.
    ancestors : ndarray of int, (N,), optional
        Filter i starts from ``x[ancestors[i]], P[ancestors[i]]`` (a resampling's copy, done
        in the kernel's gather instead of as two array copies); its matrices are those of
        ``system`` at i.  Default: filter i starts from ``x[i], P[i]``.

    Returns
    -------
    x_post : (N, n), P_post : (N, n, n)
        After the last step.
    log_likelihood : (N, K)
    x_hist, var_hist : (N, K, n)
        Posterior means and the diagonals of the posterior covariances (``record`` only).
    """
    x = np.ascontiguousarray(x, dtype=float)
    N, n = x.shape
    if ancestors is None:
        ancestors = np.arange(N)
    else:
        ancestors = np.ascontiguousarray(ancestors, dtype=np.int64)
        if ancestors.ndim != 1 or (ancestors.size
                                   and not 0 <= ancestors.min() <= ancestors.max() < N):
            raise ValueError(f"kalman_run: ancestors must be indices into the {N} filters")
        N = len(ancestors)
    Y = np.ascontiguousarray(np.atleast_2d(np.asarray(Y, float)))
    K = Y.shape[0]
    p = system.H.shape[-2]
    B = system.B
    if B is None or U is None:
        B, U = None, np.zeros((K, 1))
    U = np.ascontiguousarray(np.asarray(U, float).reshape(K, -1))
    x_out, P_out, loglik = np.empty((N, n)), np.empty((N, n, n)), np.empty((N, K))
    hist_shape = (N, K, n) if record else (0, 0, 0)
    x_hist, var_hist = np.empty(hist_shape), np.empty(hist_shape)
    _kf_run(x, np.ascontiguousarray(P, dtype=float), _stack(system.F, (n, n)),
            _stack(system.Q, (n, n)), _stack(B, (n, 1)), U, _stack(system.H, (p, n)),
            _stack(system.R, (p, p)), Y, ancestors, x_out, P_out, loglik, x_hist, var_hist,
            record, block_size(N))
    if record:
        return x_out, P_out, loglik, x_hist, var_hist
    return x_out, P_out, loglik


def kalman_step(x: np.ndarray, P: np.ndarray, system: LinearGaussianBatch, y: np.ndarray,
                u: np.ndarray | None = None, ancestors: np.ndarray | None = None
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Predict + update of N Kalman filters in one compiled pass.

    Parameters
    ----------
    x : ndarray, (N, n)
        Posterior means at step k−1.
    P : ndarray, (N, n, n)
        Posterior covariances at step k−1.
    system : LinearGaussianBatch
        F, Q (n, n) or (N, n, n); H (p, n) or (N, p, n); R (p, p) or (N, p, p); B optional.
    y : ndarray, (p,)
        Measurement y_k shared by all filters.
    u : ndarray, (m,), optional
        Known input u_k.
    ancestors : ndarray of int, (N,), optional
        As in :func:`kalman_run`.

    Returns
    -------
    x_post : (N, n), P_post : (N, n, n), log_likelihood : (N,)
        ``log N(y; H x⁻, H P⁻ Hᵀ + R)``.  Where S is not positive definite (e.g. exactly
        singular) that filter is not updated (x = x⁻, P = P⁻) and its log-likelihood is −inf:
        a particle the model cannot weigh, never a NaN.
    """
    y = np.asarray(y, float).reshape(1, -1)
    U = None if u is None else np.asarray(u, float).reshape(1, -1)
    x_out, P_out, loglik = kalman_run(x, P, system, y, U, ancestors=ancestors)
    return x_out, P_out, loglik[:, 0]
