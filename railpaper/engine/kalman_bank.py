"""Fused, compiled Kalman step for a bank of N filters (one per particle): the RBPF hot path.

Same model and conventions as :mod:`railpaper.engine.kalman`::

    x_k = F x_{k-1} + B u_k + noise(Q),   y_k = H x_k + noise(R)

One call of :func:`kalman_step` (or :func:`kalman_run`, K steps) does the time update, the
measurement update and the predictive log-likelihood of every filter.  The same step split in
two, for a filter whose update matrices are known only after its weights (the Q-GRBPF, whose
H(θ) is that of the new θ): :func:`kalman_predict` (time update and predictive
log-likelihood, no gain, no covariance update) and :func:`kalman_update` (measurement update
of a stored prior, kept between the two in the kernels' block layout: :class:`BankPrior`); both
kernels share :func:`_kf_run`'s block functions, so predict + update gives the fused step's
bits.  It is written for speed, not generality:

* numba, parallel over blocks of ``BLOCK`` filters (``prange``); inside a block every operation
  runs over the filters in the innermost loop (structure of arrays), so each scalar formula of a
  16×16 product becomes one SIMD loop over the block — no Python loop over particles;
* symmetry: only the upper triangle of ``F P Fᵀ`` and of the posterior is computed;
* sparsity: ``H P⁻``, ``S`` and the innovation run over H's structural nonzeros only
  (:func:`measurement_pattern`, the union over the bank; same bits as the dense products);
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
from dataclasses import dataclass

import numba
import numpy as np

from railpaper.engine.batch_expm import stack_matmul
from railpaper.engine.kalman import LOG_2PI
from railpaper.engine.kernel_arrays import kernel_array
from railpaper.engine.linear_gaussian import LinearGaussianBatch

BLOCK = 64          # filters per block: the SIMD loop length inside the kernels


@numba.njit(fastmath={"contract"}, cache=True)
def _symmetric_abt(A, B, D, lo, d_stride, C):  # pragma: no cover - compiled
    """C = A Bᵀ + D[(lo + q) · d_stride] for a block (batch in the last axis) whose result is
    known to be symmetric: the upper triangle is computed and mirrored.  Four terms per load
    and store of C, added in the order l = 0, 1, … (the bits of the plain loop, as
    :func:`~railpaper.engine.batch_expm.stack_matmul`)."""
    r, k, nb = A.shape[0], A.shape[1], A.shape[2]
    k4 = k - k % 4
    for i in range(r):
        for j in range(i, r):
            for q in range(nb):
                C[i, j, q] = D[(lo + q) * d_stride, i, j]
        for l in range(0, k4, 4):
            for j in range(i, r):
                for q in range(nb):
                    C[i, j, q] = (C[i, j, q] + A[i, l, q] * B[j, l, q]
                                  + A[i, l + 1, q] * B[j, l + 1, q]
                                  + A[i, l + 2, q] * B[j, l + 2, q]
                                  + A[i, l + 3, q] * B[j, l + 3, q])
        for l in range(k4, k):
            for j in range(i, r):
                for q in range(nb):
                    C[i, j, q] += A[i, l, q] * B[j, l, q]
        for j in range(i + 1, r):
            for q in range(nb):
                C[j, i, q] = C[i, j, q]


@numba.njit(fastmath={"contract"}, cache=True)
def _predict_block(Fl, xl, Pl, B, sB, u, Q, sQ, lo, xp, FP):  # pragma: no cover - compiled
    """Time update of a block: ``xp`` = x⁻, and P⁻ overwrites ``Pl``."""
    n, nb = xl.shape
    m = B.shape[2]
    # x⁻ = F x + B u
    xp[:] = 0.0
    for i in range(n):
        for k in range(n):
            for q in range(nb):
                xp[i, q] += Fl[i, k, q] * xl[k, q]
        for c in range(m):
            for q in range(nb):
                xp[i, q] += B[(lo + q) * sB, i, c] * u[c]
    stack_matmul(Fl, Pl, FP)              # F P
    _symmetric_abt(FP, Fl, Q, lo, sQ, Pl)  # P⁻ = F P Fᵀ + Q; it overwrites Pl


@numba.njit(fastmath={"contract"}, error_model="numpy", cache=True)
def _innovation_block(Hl, hcols, hcount, Pl, xp, y, R, sR, lo, gain, HP, S, v, Lc, z, W,
                      logdet, bad, loglik):  # pragma: no cover - compiled
    """Predictive log-likelihood of a block, ``loglik`` = log N(y; H x⁻, H P⁻ Hᵀ + R), with the
    whitened innovation ``z`` and, when ``gain``, the whitened gain ``W`` = L⁻¹ H P⁻ (zeroed,
    with z, where S is not positive definite: no update there; log-likelihood −inf).

    H's products run over its structural nonzeros only: row r's columns ``hcols[r, :hcount[r]]``
    (ascending; :func:`measurement_pattern`).  A skipped term is an exact zero, and the kept
    ones are summed in the dense loops' order, so the bits are the dense products' (for finite
    P⁻)."""
    p, n, nb = Hl.shape
    # H P⁻ (p, n)
    HP[:] = 0.0
    for r in range(p):
        for t in range(hcount[r]):
            k = hcols[r, t]
            for j in range(n):
                for q in range(nb):
                    HP[r, j, q] += Hl[r, k, q] * Pl[k, j, q]
    # S = H P⁻ Hᵀ + R (upper triangle, mirrored)
    for i in range(p):
        for j in range(i, p):
            for q in range(nb):
                S[i, j, q] = R[(lo + q) * sR, i, j]
            for t in range(hcount[j]):
                k = hcols[j, t]
                for q in range(nb):
                    S[i, j, q] += HP[i, k, q] * Hl[j, k, q]
        for j in range(i + 1, p):
            for q in range(nb):
                S[j, i, q] = S[i, j, q]
    # v = y − H x⁻
    for r in range(p):
        for q in range(nb):
            v[r, q] = y[r]
        for t in range(hcount[r]):
            k = hcols[r, t]
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
        if gain:
            for j in range(n):
                for q in range(nb):
                    W[r, j, q] = HP[r, j, q]
        for k in range(r):
            for q in range(nb):
                z[r, q] -= Lc[r, k, q] * z[k, q]
            if gain:
                for j in range(n):
                    for q in range(nb):
                        W[r, j, q] -= Lc[r, k, q] * W[k, j, q]
        for q in range(nb):
            z[r, q] /= Lc[r, r, q]
        if gain:
            for j in range(n):
                for q in range(nb):
                    W[r, j, q] /= Lc[r, r, q]
    # log N(v; 0, S) = −½ (zᵀz + log|S| + p log 2π)
    for q in range(nb):
        zz = 0.0
        for r in range(p):
            zz += z[r, q] * z[r, q]
        loglik[q] = -math.inf if bad[q] else -0.5 * (zz + logdet[q] + p * LOG_2PI)
        if bad[q] and gain:               # keep the prior: x = x⁻, P = P⁻
            for r in range(p):
                z[r, q] = 0.0
                for j in range(n):
                    W[r, j, q] = 0.0


@numba.njit(fastmath={"contract"}, cache=True)
def _posterior_block(xp, W, z, xl, Pl):  # pragma: no cover - compiled
    """Measurement update of a block from its whitened gain: ``xl`` = x, P overwrites ``Pl``."""
    p, n, nb = W.shape
    # x = x⁻ + Wᵀ z ; P = P⁻ − Wᵀ W (upper triangle, mirrored)
    for i in range(n):
        for q in range(nb):
            acc = xp[i, q]
            for r in range(p):
                acc += W[r, i, q] * z[r, q]
            xl[i, q] = acc
    p4 = p - p % 4                      # four rows of W per load and store of P, in order
    for r in range(0, p4, 4):
        for i in range(n):
            for j in range(i, n):
                for q in range(nb):
                    Pl[i, j, q] = (Pl[i, j, q] - W[r, i, q] * W[r, j, q]
                                   - W[r + 1, i, q] * W[r + 1, j, q]
                                   - W[r + 2, i, q] * W[r + 2, j, q]
                                   - W[r + 3, i, q] * W[r + 3, j, q])
    for r in range(p4, p):
        for i in range(n):
            for j in range(i, n):
                for q in range(nb):
                    Pl[i, j, q] -= W[r, i, q] * W[r, j, q]
    for i in range(n):
        for j in range(i + 1, n):
            for q in range(nb):
                Pl[j, i, q] = Pl[i, j, q]


@numba.njit(fastmath={"contract"}, cache=True)
def _gather_block(x, P, rows, xl, Pl):  # pragma: no cover - compiled
    """Filters ``rows`` of x (N, n), P (N, n, n) into a block (batch in the last axis)."""
    n, nb = xl.shape
    for i in range(n):
        for q in range(nb):
            xl[i, q] = x[rows[q], i]
        for j in range(n):
            for q in range(nb):
                Pl[i, j, q] = P[rows[q], i, j]


@numba.njit(fastmath={"contract"}, cache=True)
def _gather_matrix(M, rows, stride, Ml):  # pragma: no cover - compiled
    """Matrices ``M[rows[q] · stride]`` of a block (stride 0: one matrix shared by all)."""
    r, c, nb = Ml.shape
    for i in range(r):
        for j in range(c):
            for q in range(nb):
                Ml[i, j, q] = M[rows[q] * stride, i, j]


@numba.njit(fastmath={"contract"}, cache=True)
def _gather_stack(M, rows, stride):  # pragma: no cover - compiled
    """``M[rows[q] · stride]`` as a stack (nb, r, c), or (1, r, c) when shared (stride 0): read
    at ``q · stride`` by the block functions (their ``lo`` = 0)."""
    k = rows.shape[0] if stride else 1
    out = np.empty((k, M.shape[1], M.shape[2]))
    for q in range(k):
        out[q] = M[rows[q] * stride]
    return out


@numba.njit(fastmath={"contract"}, cache=True)
def _scatter_block(xl, Pl, lo, x_out, P_out):  # pragma: no cover - compiled
    """A block back into rows lo.. of x_out (N, n), P_out (N, n, n)."""
    n, nb = xl.shape
    for q in range(nb):
        for i in range(n):
            x_out[lo + q, i] = xl[i, q]
            for j in range(n):
                P_out[lo + q, i, j] = Pl[i, j, q]


@numba.njit(fastmath={"contract"}, cache=True)
def _copy_lanes(x_src, P_src, x_dst, P_dst, nb):  # pragma: no cover - compiled
    """Lanes 0..nb−1 of a block's x (n, ·) and P (n, n, ·) into another block's: the
    contiguous copy that keeps a prior in block layout between :func:`_kf_predict` and
    :func:`_kf_update` (:class:`BankPrior`)."""
    n = x_src.shape[0]
    for i in range(n):
        for q in range(nb):
            x_dst[i, q] = x_src[i, q]
        for j in range(n):
            for q in range(nb):
                P_dst[i, j, q] = P_src[i, j, q]


@numba.njit(cache=True)
def _innovation_workspace(n, p, nb, gain):  # pragma: no cover - compiled
    """Scratch arrays of :func:`_innovation_block` for a block of nb filters: ``HP`` (H P⁻),
    ``S``, ``v``, ``Lc`` (its Cholesky factor), ``z``, ``W`` (the whitened gain, empty without
    ``gain``), ``logdet``, ``bad`` and ``ll`` (the log-likelihoods)."""
    W = np.empty((p, n, nb)) if gain else np.empty((0, 0, 0))
    return (np.empty((p, n, nb)), np.empty((p, p, nb)), np.empty((p, nb)),
            np.zeros((p, p, nb)), np.empty((p, nb)), W, np.empty(nb),
            np.empty(nb, dtype=np.bool_), np.empty(nb))


@numba.njit(fastmath={"contract"}, cache=True)
def _own_block(F, H, sF, sH, lo, nb):  # pragma: no cover - compiled
    """A block's own F and H (batch in the last axis), its x and P and the step's scratch
    (:func:`_innovation_workspace` with the gain, after ``xp`` and ``FP``): what the kernels
    that run filters over many rows set up once per block."""
    n, p = F.shape[1], H.shape[1]
    own = np.arange(lo, lo + nb)                  # the block's own matrices
    Fl, Hl = np.empty((n, n, nb)), np.empty((p, n, nb))
    _gather_matrix(F, own, sF, Fl)
    _gather_matrix(H, own, sH, Hl)
    work = (np.empty((n, nb)), np.empty((n, n, nb))) + _innovation_workspace(n, p, nb, True)
    return Fl, Hl, np.empty((n, nb)), np.empty((n, n, nb)), work


@numba.njit(fastmath={"contract"}, cache=True)
def _filter_step(Fl, Hl, xl, Pl, B, sB, u, Q, sQ, hcols, hcount, y, R, sR, lo,
                 work):  # pragma: no cover - compiled
    """One predict + update of a block (:func:`_predict_block`, :func:`_innovation_block`,
    :func:`_posterior_block`) in place on ``xl``, ``Pl``; the log-likelihoods in ``work``'s
    last array."""
    xp, FP, HP, S, v, Lc, z, W, logdet, bad, ll = work
    _predict_block(Fl, xl, Pl, B, sB, u, Q, sQ, lo, xp, FP)                  # x⁻, P⁻
    _innovation_block(Hl, hcols, hcount, Pl, xp, y, R, sR, lo, True, HP, S, v, Lc, z, W,
                      logdet, bad, ll)                                      # z, W, log N
    _posterior_block(xp, W, z, xl, Pl)                                      # x, P


@numba.njit(parallel=True, fastmath={"contract"}, cache=True)
def _kf_run(x, P, F, Q, B, U, H, hcols, hcount, R, Y, ancestors, x_out, P_out, loglik, x_hist,
            var_hist, record, block):  # pragma: no cover - compiled
    """Predict + update (:func:`_predict_block`, :func:`_innovation_block`,
    :func:`_posterior_block`) of every filter over the rows of Y."""
    N, n = x_out.shape
    n_steps = Y.shape[0]
    sF, sQ, sB = int(F.shape[0] > 1), int(Q.shape[0] > 1), int(B.shape[0] > 1)
    sH, sR = int(H.shape[0] > 1), int(R.shape[0] > 1)        # 0: one matrix shared by all
    n_blocks = (N + block - 1) // block
    for b in numba.prange(n_blocks):
        lo = b * block
        nb = min(block, N - lo)
        Fl, Hl, xl, Pl, work = _own_block(F, H, sF, sH, lo, nb)
        ll = work[-1]
        # gather the block once (structure of arrays); x, P from the ancestor: a resampling's
        # copy
        _gather_block(x, P, ancestors[lo:lo + nb], xl, Pl)
        for t in range(n_steps):                  # the block stays in cache over the steps
            _filter_step(Fl, Hl, xl, Pl, B, sB, U[t], Q, sQ, hcols, hcount, Y[t], R, sR, lo,
                         work)
            for q in range(nb):
                loglik[lo + q, t] = ll[q]
            if record:
                for q in range(nb):
                    for i in range(n):
                        x_hist[lo + q, t, i] = xl[i, q]
                        var_hist[lo + q, t, i] = Pl[i, i, q]
        _scatter_block(xl, Pl, lo, x_out, P_out)  # scatter the block once


@numba.njit(parallel=True, fastmath={"contract"}, cache=True)
def _kf_run_restarting(x_start, P_start, phase, period, F, Q, B, U, H, hcols, hcount, R, Y,
                       loglik, block):  # pragma: no cover - compiled
    """:func:`_kf_run` over the rows of Y, except that filter i is restarted from
    ``x_start[t]``, ``P_start[t]`` before row t wherever ``t % period == phase[i]`` (every
    filter starts from row 0's); only the log-likelihoods are kept."""
    N = loglik.shape[0]
    n = x_start.shape[1]
    n_steps = Y.shape[0]
    sF, sQ, sB = int(F.shape[0] > 1), int(Q.shape[0] > 1), int(B.shape[0] > 1)
    sH, sR = int(H.shape[0] > 1), int(R.shape[0] > 1)        # 0: one matrix shared by all
    n_blocks = (N + block - 1) // block
    for b in numba.prange(n_blocks):
        lo = b * block
        nb = min(block, N - lo)
        Fl, Hl, xl, Pl, work = _own_block(F, H, sF, sH, lo, nb)
        ll = work[-1]
        for t in range(n_steps):                  # the block stays in cache over the steps
            for q in range(nb):
                if t == 0 or t % period == phase[lo + q]:
                    for i in range(n):
                        xl[i, q] = x_start[t, i]
                        for j in range(n):
                            Pl[i, j, q] = P_start[t, i, j]
            _filter_step(Fl, Hl, xl, Pl, B, sB, U[t], Q, sQ, hcols, hcount, Y[t], R, sR, lo,
                         work)
            for q in range(nb):
                loglik[lo + q, t] = ll[q]


@numba.njit(parallel=True, fastmath={"contract"}, cache=True)
def _kf_predict(x, P, F, Q, B, u, H, hcols, hcount, R, y, ancestors, rows, x_blocks, P_blocks,
                loglik, block):  # pragma: no cover - compiled
    """Time update and predictive log-likelihood of every filter, no measurement update: the
    same arithmetic as the first half of :func:`_kf_run`'s step, without the gain.  Filter i
    starts from x, P at ``ancestors[i]`` and uses the matrices at ``rows[i]``; the priors stay
    in block layout (``x_blocks`` (n_blocks, n, block), ``P_blocks`` (n_blocks, n, n, block)),
    a contiguous copy instead of the scatter's transpose."""
    N, n = loglik.shape[0], x.shape[1]
    p = H.shape[1]
    sF, sQ, sB = int(F.shape[0] > 1), int(Q.shape[0] > 1), int(B.shape[0] > 1)
    sH, sR = int(H.shape[0] > 1), int(R.shape[0] > 1)        # 0: one matrix shared by all
    n_blocks = (N + block - 1) // block
    for b in numba.prange(n_blocks):
        lo = b * block
        nb = min(block, N - lo)
        Fl, Pl, Hl = np.empty((n, n, nb)), np.empty((n, n, nb)), np.empty((p, n, nb))
        xl = np.empty((n, nb))
        _gather_block(x, P, ancestors[lo:lo + nb], xl, Pl)
        mine = rows[lo:lo + nb]
        _gather_matrix(F, mine, sF, Fl)
        _gather_matrix(H, mine, sH, Hl)
        Bl, Ql, Rl = _gather_stack(B, mine, sB), _gather_stack(Q, mine, sQ), \
            _gather_stack(R, mine, sR)
        xp, FP = np.empty((n, nb)), np.empty((n, n, nb))
        HP, S, v, Lc, z, W, logdet, bad, ll = _innovation_workspace(n, p, nb, False)
        _predict_block(Fl, xl, Pl, Bl, sB, u, Ql, sQ, 0, xp, FP)             # x⁻, P⁻
        _innovation_block(Hl, hcols, hcount, Pl, xp, y, Rl, sR, 0, False, HP, S, v, Lc, z, W,
                          logdet, bad, ll)                                # log N(y; Hx⁻, S)
        for q in range(nb):
            loglik[lo + q] = ll[q]
        _copy_lanes(xp, Pl, x_blocks[b], P_blocks[b], nb)   # the block as it is: no transpose


@numba.njit(parallel=True, fastmath={"contract"}, cache=True)
def _kf_update(x_blocks, P_blocks, H, hcols, hcount, R, y, x_out, P_out, loglik,
               block):  # pragma: no cover - compiled
    """Measurement update of every filter from its prior in block layout (as
    :func:`_kf_predict` leaves it): the same arithmetic as the second half of
    :func:`_kf_run`'s step."""
    N, n = x_out.shape
    p = H.shape[1]
    sH, sR = int(H.shape[0] > 1), int(R.shape[0] > 1)        # 0: one matrix shared by all
    n_blocks = (N + block - 1) // block
    for b in numba.prange(n_blocks):
        lo = b * block
        nb = min(block, N - lo)
        Pl, Hl, xp = np.empty((n, n, nb)), np.empty((p, n, nb)), np.empty((n, nb))
        _copy_lanes(x_blocks[b], P_blocks[b], xp, Pl, nb)   # the block as it is: no transpose
        own = np.arange(lo, lo + nb)
        _gather_matrix(H, own, sH, Hl)
        xl = np.empty((n, nb))
        HP, S, v, Lc, z, W, logdet, bad, ll = _innovation_workspace(n, p, nb, True)
        _innovation_block(Hl, hcols, hcount, Pl, xp, y, R, sR, lo, True, HP, S, v, Lc, z, W,
                          logdet, bad, ll)                                # z, W, log N
        _posterior_block(xp, W, z, xl, Pl)                                  # x, P
        for q in range(nb):
            loglik[lo + q] = ll[q]
        _scatter_block(xl, Pl, lo, x_out, P_out)


def block_size(N: int) -> int:
    """Filters per block for a bank of N: :data:`BLOCK`, or half the bank when it holds at most
    one block, so that a small bank (a waste-free IBIS chain step, say) still gives both
    cores a block.  Every filter's arithmetic is the same in any block (the SIMD loops run
    over filters, never across them), so the choice changes the speed, not the bits
    (tests/engine/test_kalman_bank.py)."""
    return BLOCK if N > BLOCK else max(1, (N + 1) // 2)


def multiply_adds(n: int, p: int, m: int, h_row_nonzeros=None) -> int:
    """Multiply-adds of one filter's step in :func:`_kf_run`, as the kernel runs it.

    ``h_row_nonzeros`` (p,): the structural nonzeros of each row of H (``hcount`` of
    :func:`measurement_pattern`; default n each, a dense H), c_r below.
    x⁻ = F x + B u: n² + n m;  F P: n³;  F P Fᵀ (upper triangle): n²(n+1)/2;  H P⁻: n Σ c_r;
    S (upper): Σ_j (j + 1) c_j;  v: Σ c_r;  Cholesky: Σ_j j (p − j);  z and W = L⁻¹ H P⁻:
    (n + 1) p(p−1)/2;  zᵀz: p;  x += Wᵀ z: n p;  P −= Wᵀ W (upper): p n(n+1)/2.  Lateral
    model (n = 16, p = 5, m = 2): 9 115 with a dense H, 7 926 with its 21 nonzeros (rows
    5, 5, 6, 4, 1).
    Divisions, square roots and logs are not counted.
    """
    c = [n] * p if h_row_nonzeros is None else [int(k) for k in h_row_nonzeros]
    chol = sum(j * (p - j) for j in range(p))
    return (n * n + n * m + n ** 3 + n * n * (n + 1) // 2 + n * sum(c)
            + sum((j + 1) * c[j] for j in range(p)) + sum(c) + chol
            + (n + 1) * p * (p - 1) // 2 + p + n * p + p * n * (n + 1) // 2)


@numba.njit(cache=True)
def _structural_nonzeros(H):  # pragma: no cover - compiled
    """:func:`measurement_pattern` of a stack H (N, p, n): an elementwise OR over the stack
    (one SIMD loop), then each row's columns."""
    p, n = H.shape[1], H.shape[2]
    used = np.zeros((p, n), np.bool_)
    for q in range(H.shape[0]):
        for r in range(p):
            for k in range(n):
                used[r, k] |= H[q, r, k] != 0.0
    hcols, hcount = np.zeros((p, n), np.int64), np.zeros(p, np.int64)
    for r in range(p):
        for k in range(n):
            if used[r, k]:
                hcols[r, hcount[r]] = k
                hcount[r] += 1
    return hcols, hcount


def measurement_pattern(H: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The structural nonzeros of a stack of measurement matrices H (N, p, n), the kernels'
    ``hcols``, ``hcount``: row r's columns where any H_i[r] is nonzero (or NaN), ascending, in
    ``hcols[r, :hcount[r]]``.  The lateral model's H (accelerations: rows of A(θ)) has 21 of
    its 80 entries nonzero, so H P⁻ costs 21 n instead of p n² multiply-adds."""
    return _structural_nonzeros(kernel_array(np.asarray(H, float)))


def _stack(M: np.ndarray | None, shape: tuple[int, int]) -> np.ndarray:
    """M as a C-contiguous (N, r, c) or (1, r, c) stack (1: shared by every filter)."""
    if M is None:
        return np.zeros((1,) + shape)
    M = np.asarray(M, float)
    return kernel_array(M if M.ndim == 3 else M[None])


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
    x = kernel_array(x)
    N, n = x.shape
    if ancestors is None:
        ancestors = np.arange(N)
    else:
        ancestors = kernel_array(ancestors, np.int64)
        if ancestors.ndim != 1 or (ancestors.size
                                   and not 0 <= ancestors.min() <= ancestors.max() < N):
            raise ValueError(f"kalman_run: ancestors must be indices into the {N} filters")
        N = len(ancestors)
    Y = kernel_array(np.atleast_2d(np.asarray(Y, float)))
    K = Y.shape[0]
    p = system.H.shape[-2]
    B = system.B
    if B is None or U is None:
        B, U = None, np.zeros((K, 1))
    U = kernel_array(np.asarray(U, float).reshape(K, -1))
    x_out, P_out, loglik = np.empty((N, n)), np.empty((N, n, n)), np.empty((N, K))
    hist_shape = (N, K, n) if record else (0, 0, 0)
    x_hist, var_hist = np.empty(hist_shape), np.empty(hist_shape)
    H = _stack(system.H, (p, n))
    _kf_run(x, kernel_array(P), _stack(system.F, (n, n)),
            _stack(system.Q, (n, n)), _stack(B, (n, 1)), U, H, *measurement_pattern(H),
            _stack(system.R, (p, p)), Y, ancestors, x_out, P_out, loglik, x_hist, var_hist,
            record, block_size(N))
    if record:
        return x_out, P_out, loglik, x_hist, var_hist
    return x_out, P_out, loglik


def kalman_run_restarting(x_start: np.ndarray, P_start: np.ndarray, system: LinearGaussianBatch,
                          Y: np.ndarray, U: np.ndarray | None, phase: np.ndarray,
                          period: int) -> np.ndarray:
    """Log-likelihoods (N, K) of N Kalman filters over the K rows of Y, filter i restarted from
    ``x_start[t]``, ``P_start[t]`` before every row t with ``t % period == phase[i]`` (and
    before row 0): filters that each live ``period`` rows from a state given per row, run as
    one bank that stays in cache over the rows instead of K calls of :func:`kalman_step` — a
    windowed change detector's ring of hypotheses
    (:func:`railpaper.engine.changepoint.windowed_change_statistics`).  Step by step the
    arithmetic is that of :func:`kalman_run`.

    Parameters
    ----------
    x_start, P_start : ndarray, (K, n), (K, n, n)
        The state a filter restarted before row t starts from.
    system : LinearGaussianBatch
        The filters' matrices (per filter or shared).
    Y : ndarray, (K, p);  U : ndarray, (K, m), optional
    phase : ndarray of int, (N,)
        Each filter's restart phase, in 0..period−1.
    period : int
        Rows between a filter's restarts.
    """
    Y = kernel_array(np.atleast_2d(np.asarray(Y, float)))
    K = Y.shape[0]
    phase = kernel_array(phase, np.int64)
    N = phase.shape[0]
    x_start = kernel_array(np.asarray(x_start, float))
    n = x_start.shape[1]
    if x_start.shape != (K, n) or np.shape(P_start) != (K, n, n):
        raise ValueError(f"kalman_run_restarting: x_start and P_start need one state per row "
                         f"({K}), got {x_start.shape} and {np.shape(P_start)}")
    if period < 1 or (N and not 0 <= phase.min() <= phase.max() < period):
        raise ValueError("kalman_run_restarting: phases must lie in 0..period-1")
    p = system.H.shape[-2]
    B = system.B
    if B is None or U is None:
        B, U = None, np.zeros((K, 1))
    U = kernel_array(np.asarray(U, float).reshape(K, -1))
    loglik = np.empty((N, K))
    H = _stack(system.H, (p, n))
    _kf_run_restarting(x_start, kernel_array(np.asarray(P_start, float)), phase, int(period),
                       _stack(system.F, (n, n)), _stack(system.Q, (n, n)), _stack(B, (n, 1)), U,
                       H, *measurement_pattern(H), _stack(system.R, (p, p)), Y, loglik,
                       block_size(N))
    return loglik


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


def _indices(a: np.ndarray | None, N: int, default: int, name: str) -> np.ndarray:
    """``a`` as int64 indices into N rows (filters or matrices; default 0..default−1)."""
    if a is None:
        return np.arange(default)
    a = kernel_array(a, np.int64)
    if a.ndim != 1 or (a.size and not 0 <= a.min() <= a.max() < N):
        raise ValueError(f"kalman_predict: {name} must be indices into {N} rows")
    return a


@dataclass(frozen=True, eq=False)               # arrays: no elementwise ==
class BankPrior:
    """The priors x⁻, P⁻ of N filters, held as the kernels hold them: blocks of ``block``
    filters with the filters last (``x_blocks`` (n_blocks, n, block), ``P_blocks``
    (n_blocks, n, n, block); the last block's unused lanes are never read).
    :func:`kalman_predict` leaves them so and :func:`kalman_update` reads them so, with no
    transpose to (N, n, n) and back in between (the Q-GRBPF's two calls a step).  ``x`` and
    ``P`` give them as (N, n), (N, n, n); :meth:`from_arrays` makes one from those."""

    x_blocks: np.ndarray
    P_blocks: np.ndarray
    n_filters: int

    @property
    def block(self) -> int:
        return self.x_blocks.shape[2]

    @property
    def x(self) -> np.ndarray:
        """x⁻ (N, n)."""
        n = self.x_blocks.shape[1]
        return np.swapaxes(self.x_blocks, 1, 2).reshape(-1, n)[:self.n_filters].copy()

    @property
    def P(self) -> np.ndarray:
        """P⁻ (N, n, n)."""
        n = self.x_blocks.shape[1]
        return np.moveaxis(self.P_blocks, 3, 1).reshape(-1, n, n)[:self.n_filters].copy()

    @classmethod
    def from_arrays(cls, x_prior: np.ndarray, P_prior: np.ndarray) -> "BankPrior":
        """The priors x⁻ (N, n), P⁻ (N, n, n) in the kernels' blocks (:func:`block_size`)."""
        x_prior, P_prior = np.asarray(x_prior, float), np.asarray(P_prior, float)
        N, n = x_prior.shape
        if P_prior.shape != (N, n, n):
            raise ValueError(f"BankPrior: P_prior must be ({N}, {n}, {n}), got {P_prior.shape}")
        prior = _empty_prior(N, n)
        k, block = prior.x_blocks.shape[0], prior.block
        x_pad, P_pad = np.zeros((k * block, n)), np.zeros((k * block, n, n))
        x_pad[:N], P_pad[:N] = x_prior, P_prior
        prior.x_blocks[:] = np.swapaxes(x_pad.reshape(k, block, n), 1, 2)
        prior.P_blocks[:] = np.moveaxis(P_pad.reshape(k, block, n, n), 1, 3)
        return prior


def _empty_prior(N: int, n: int) -> BankPrior:
    block = block_size(N)
    k = (N + block - 1) // block
    return BankPrior(np.empty((k, n, block)), np.empty((k, n, n, block)), N)


def kalman_predict(x: np.ndarray, P: np.ndarray, system: LinearGaussianBatch, y: np.ndarray,
                   u: np.ndarray | None = None, ancestors: np.ndarray | None = None,
                   matrix_rows: np.ndarray | None = None) -> tuple[BankPrior, np.ndarray]:
    """Time update and predictive log-likelihood of N Kalman filters, no measurement update.

    For a filter whose measurement update uses matrices known only after its weight (the
    Q-GRBPF's step (4) with H(θ) of the new θ): :func:`kalman_update` of the returned prior
    completes the step.  ``kalman_update(kalman_predict(x, P, s, y, u)[0], y, s.H, s.R)``
    equals :func:`kalman_step` ``(x, P, s, y, u)`` (same arithmetic, in two kernels).

    Parameters are those of :func:`kalman_step`, and

    matrix_rows : ndarray of int, (N,), optional
        Filter i uses the matrices of ``system`` at ``matrix_rows[i]`` (default i; the
        system may hold fewer models than there are filters).  With
        ``ancestors`` the same indices, filter i continues the whole filter ``ancestors[i]``,
        state and matrices: a resampling's copy of a particle whose θ is not moved (the
        Q-GRBPF's search), made in the kernel's gather instead of by copying the arrays.

    Returns
    -------
    prior : BankPrior
        ``x⁻ = F x + B u``, ``P⁻ = F P Fᵀ + Q`` in the kernels' block layout (``prior.x``,
        ``prior.P`` as arrays).
    log_likelihood : (N,)
        ``log N(y; H x⁻, H P⁻ Hᵀ + R)``; −inf where that S is not positive definite.
    """
    x = kernel_array(x)
    N, n = x.shape
    ancestors = _indices(ancestors, N, N, "ancestors")
    N = len(ancestors)
    batch = max([M.shape[0] for M in (system.F, system.Q, system.H, system.R, system.B)
                 if M is not None and M.ndim == 3] or [N])      # shared: any row
    matrix_rows = _indices(matrix_rows, batch, N, "matrix_rows")
    y = kernel_array(np.asarray(y, float).reshape(-1))
    p = system.H.shape[-2]
    B = system.B
    if B is None or u is None:
        B, u = None, np.zeros(1)
    u = kernel_array(np.asarray(u, float).reshape(-1))
    prior, loglik = _empty_prior(N, n), np.empty(N)
    H = _stack(system.H, (p, n))
    _kf_predict(x, kernel_array(P), _stack(system.F, (n, n)),
                _stack(system.Q, (n, n)), _stack(B, (n, 1)), u, H, *measurement_pattern(H),
                _stack(system.R, (p, p)), y, ancestors, matrix_rows, prior.x_blocks,
                prior.P_blocks, loglik, prior.block)
    return prior, loglik


def kalman_update(prior: BankPrior, y: np.ndarray, H: np.ndarray, R: np.ndarray
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Measurement update of N Kalman filters from their priors, in one compiled pass.

    The update of :func:`kalman_step` (whitened gain ``W = L⁻¹ H P⁻``, ``S = L Lᵀ``)::

        x = x⁻ + Wᵀ z,  z = L⁻¹ (y − H x⁻)      (= x⁻ + K v)
        P = P⁻ − Wᵀ W                            (= P⁻ − K S Kᵀ, symmetric by construction)

    Parameters
    ----------
    prior : BankPrior
        Prior means and covariances: from :func:`kalman_predict`, or
        ``BankPrior.from_arrays(x_prior (N, n), P_prior (N, n, n))``.
    y : ndarray, (p,)
        Measurement shared by all filters.
    H : ndarray, (p, n) or (N, p, n)
    R : ndarray, (p, p) or (N, p, p)

    Returns
    -------
    x_post : (N, n), P_post : (N, n, n), log_likelihood : (N,)
        ``log N(y; H x⁻, H P⁻ Hᵀ + R)`` with these H, R.  Where S is not positive definite
        that filter is not updated (x = x⁻, P = P⁻) and its log-likelihood is −inf.
    """
    if not isinstance(prior, BankPrior):
        raise TypeError("kalman_update: prior must be a BankPrior (kalman_predict's, or "
                        "BankPrior.from_arrays(x_prior, P_prior))")
    N, n = prior.n_filters, prior.x_blocks.shape[1]
    y = kernel_array(np.asarray(y, float).reshape(-1))
    p = y.shape[0]
    x_out, P_out, loglik = np.empty((N, n)), np.empty((N, n, n)), np.empty(N)
    H = _stack(H, (p, n))
    _kf_update(prior.x_blocks, prior.P_blocks, H, *measurement_pattern(H),
               _stack(R, (p, p)), y, x_out, P_out, loglik, prior.block)
    return x_out, P_out, loglik
