"""Time-varying Kalman filter and fixed-interval (RTS) smoother of a linear-Gaussian model whose
covariances do not depend on the data, for many records at once.

For ``x_k = F x_{k-1} + w_k`` (``w ~ N(0, Q)``), ``y_k = H x_k + v_k`` (``v ~ N(0, R)``) and the
prior ``x_0 ~ N(m_0, P_0)`` of the first measured state, the filter's gains and covariances are
the same for every record.  :func:`gains` computes them once per model of a batch (leading axis G
of F, Q, R, P_0) with the covariance steps of :mod:`railpaper.engine.kalman` (Joseph-form
update), compiled; :func:`filter_means` and :func:`smoother_means` then apply them to S records
per model in compiled loops:

    x⁺_k = x⁻_k + K_k v_k,   v_k = y_k − H x⁻_k,   x⁻_{k+1} = F x⁺_k,   K_k = P⁻_k Hᵀ S_k⁻¹.

The smoother gives the Rauch–Tung–Striebel means ``x_{k|T}`` in the modified Bryson–Frazier form
(Bierman 1977), which needs no inverse of the prior covariance — the RTS gain
``P⁺_k Fᵀ (P⁻_{k+1})⁻¹`` is numerically meaningless when P⁻ spans fifteen decades, as it does for
a wheelset whose contact deflection is known to nanometres and its displacement to millimetres:

    λ̂_{T-1} = 0,   x_{k|T} = x⁺_k − P⁺_k λ̂_k,
    λ̃_k = −Hᵀ S_k⁻¹ v_k + (I − K_k H)ᵀ λ̂_k,   λ̂_{k-1} = Fᵀ λ̃_k.

The filter equals filterpy's ``KalmanFilter.batch_filter(..., update_first=True)`` and the smoother
its ``rts_smoother``, the references they are tested against.  The estimators take matrices,
never vehicle models.
"""

from __future__ import annotations

from dataclasses import dataclass

import numba
import numpy as np

from railpaper.engine import kernel_array


@dataclass(frozen=True)
class Gains:
    """Gains and covariances of the filter of G models at every step.

    Attributes
    ----------
    K : ndarray, shape (T, G, n, p)
        Filter gains ``P⁻ Hᵀ S⁻¹``.
    M : ndarray, shape (T, G, n, p)
        ``Hᵀ S⁻¹`` (the smoother's innovation weight).
    P_post : ndarray, shape (T, G, n, n)
        Posterior covariances ``P⁺`` (state units squared).
    """

    K: np.ndarray
    M: np.ndarray
    P_post: np.ndarray


@numba.njit(cache=True)
def _mm(a, b, out):
    """out = a @ b for small dense matrices (explicit loops: no BLAS call per product)."""
    for i in range(a.shape[0]):
        for j in range(b.shape[1]):
            acc = 0.0
            for k in range(a.shape[1]):
                acc += a[i, k] * b[k, j]
            out[i, j] = acc


@numba.njit(cache=True)
def _mmT(a, b, out):
    """out = a @ b.T for small dense matrices."""
    for i in range(a.shape[0]):
        for j in range(b.shape[0]):
            acc = 0.0
            for k in range(a.shape[1]):
                acc += a[i, k] * b[j, k]
            out[i, j] = acc


@numba.njit(cache=True)
def _riccati_kernel(F, Q, H, R, P0, K, M, P_post):
    """Covariance steps of ``kalman.update`` (Joseph form) and ``kalman.predict`` for every step
    and model; fills K, M = Hᵀ S⁻¹ and P_post."""
    T, G, n, p = K.shape
    P, PHt, S, L = np.empty((n, n)), np.empty((n, p)), np.empty((p, p)), np.zeros((p, p))
    HtSi, IKH, A1, KR, Pp = (np.empty((n, p)), np.empty((n, n)), np.empty((n, n)),
                             np.empty((n, p)), np.empty((n, n)))
    for g in range(G):
        P[:, :] = P0[g]
        for k in range(T):
            _mmT(P, H, PHt)                                    # P⁻ Hᵀ
            _mm(H, PHt, S)                                     # S = H P⁻ Hᵀ + R (symmetrised)
            for i in range(p):
                for j in range(p):
                    L[i, j] = 0.5 * (S[i, j] + S[j, i]) + R[g, i, j]
            for i in range(p):                                 # Cholesky in place: S = L Lᵀ
                for j in range(i + 1):
                    acc = L[i, j]
                    for m in range(j):
                        acc -= L[i, m] * L[j, m]
                    L[i, j] = np.sqrt(acc) if i == j else acc / L[j, j]
            for c in range(n):                                 # row c of Hᵀ S⁻¹ = S⁻¹ H[:, c]
                for i in range(p):                             # L z = H[:, c]
                    acc = H[i, c]
                    for m in range(i):
                        acc -= L[i, m] * HtSi[c, m]
                    HtSi[c, i] = acc / L[i, i]
                for i in range(p - 1, -1, -1):                 # Lᵀ u = z
                    acc = HtSi[c, i]
                    for m in range(i + 1, p):
                        acc -= L[m, i] * HtSi[c, m]
                    HtSi[c, i] = acc / L[i, i]
            _mm(P, HtSi, K[k, g])                              # K = P⁻ Hᵀ S⁻¹
            M[k, g] = HtSi
            _mm(K[k, g], H, IKH)
            for i in range(n):                                 # I − K H
                for j in range(n):
                    IKH[i, j] = (1.0 if i == j else 0.0) - IKH[i, j]
            _mm(IKH, P, A1)
            _mmT(A1, IKH, Pp)                                  # (I − KH) P⁻ (I − KH)ᵀ
            _mm(K[k, g], R[g], KR)
            _mmT(KR, K[k, g], A1)                              # K R Kᵀ
            for i in range(n):
                for j in range(n):
                    P_post[k, g, i, j] = 0.5 * (Pp[i, j] + Pp[j, i] + A1[i, j] + A1[j, i])
            _mm(F[g], P_post[k, g], A1)                        # P⁻_{k+1} = F P⁺ Fᵀ + Q
            _mmT(A1, F[g], Pp)
            for i in range(n):
                for j in range(n):
                    P[i, j] = 0.5 * (Pp[i, j] + Pp[j, i]) + Q[g, i, j]


def gains(F: np.ndarray, Q: np.ndarray, H: np.ndarray, R: np.ndarray, P0: np.ndarray,
          n_steps: int) -> Gains:
    """Gains of the filter and the smoother of G models for ``n_steps`` measurements.

    The covariance recursion is that of :func:`railpaper.engine.kalman.update` (Joseph form,
    symmetrised) and :func:`~railpaper.engine.kalman.predict`, compiled and tested equal to
    them: the library's generic batched steps, called once per step, are too slow for 20 000-step
    records.

    Parameters
    ----------
    F, Q : ndarray, shape (G, n, n) or (n, n)
        Transition matrix and process-noise covariance in state coordinates (shared when 2-D).
    H : ndarray, shape (p, n)
        Measurement matrix (shared).
    R : ndarray, shape (G, p, p) or (p, p)
        Measurement-noise covariances (positive definite).
    P0 : ndarray, shape (G, n, n) or (n, n)
        Covariance of the prior of the first measured state.
    n_steps : int
        Number of measurements T (≥ 1).

    Returns
    -------
    Gains
    """
    F, Q, H, R, P = (np.asarray(M, float) for M in (F, Q, H, R, P0))
    G = max(len(M) if M.ndim == 3 else 1 for M in (F, Q, R, P))
    n, p = H.shape[1], H.shape[0]
    F, Q, R, P = (kernel_array(np.broadcast_to(M, (G,) + M.shape[-2:])) for M in (F, Q, R, P))
    K, M = np.empty((n_steps, G, n, p)), np.empty((n_steps, G, n, p))
    P_post = np.empty((n_steps, G, n, n))
    _riccati_kernel(F, Q, kernel_array(H), R, P, K, M, P_post)
    return Gains(K=K, M=M, P_post=P_post)


@numba.njit(cache=True)
def _filter_kernel(K, F, H, y, x0, out, innovations):
    T, G, S, p = y.shape
    n = F.shape[-1]
    x = x0.copy()                                              # prior of step 0, (G, S, n)
    for k in range(T):                                         # records innermost: memory order
        for g in range(G):
            for s in range(S):
                for i in range(p):                             # v = y − H x⁻
                    acc = y[k, g, s, i]
                    for j in range(n):
                        acc -= H[i, j] * x[g, s, j]
                    innovations[k, g, s, i] = acc
                for i in range(n):                             # x⁺ = x⁻ + K v
                    acc = x[g, s, i]
                    for j in range(p):
                        acc += K[k, g, i, j] * innovations[k, g, s, j]
                    out[k, g, s, i] = acc
                for i in range(n):                             # x⁻_{k+1} = F x⁺_k
                    acc = 0.0
                    for j in range(n):
                        acc += F[g, i, j] * out[k, g, s, j]
                    x[g, s, i] = acc


@numba.njit(cache=True)
def _smoother_kernel(K, M, P_post, F, H, innovations, x_post, out):
    T, G, S, p = innovations.shape
    n = F.shape[-1]
    lam = np.zeros((G, S, n))                                  # λ̂_{T-1} = 0
    lam_t, t = np.empty(n), np.empty(p)
    for k in range(T - 1, -1, -1):
        for g in range(G):
            for s in range(S):
                for i in range(n):                             # x_{k|T} = x⁺_k − P⁺_k λ̂_k
                    acc = x_post[k, g, s, i]
                    for j in range(n):
                        acc -= P_post[k, g, i, j] * lam[g, s, j]
                    out[k, g, s, i] = acc
                for i in range(p):                             # t = Kᵀ λ̂
                    acc = 0.0
                    for j in range(n):
                        acc += K[k, g, j, i] * lam[g, s, j]
                    t[i] = acc
                for i in range(n):                             # λ̃ = −Hᵀ S⁻¹ v + λ̂ − Hᵀ Kᵀ λ̂
                    acc = lam[g, s, i]
                    for j in range(p):
                        acc -= M[k, g, i, j] * innovations[k, g, s, j] + H[j, i] * t[j]
                    lam_t[i] = acc
                for i in range(n):                             # λ̂_{k-1} = Fᵀ λ̃_k
                    acc = 0.0
                    for j in range(n):
                        acc += F[g, j, i] * lam_t[j]
                    lam[g, s, i] = acc


def _per_model(g: Gains, F) -> np.ndarray:
    G = g.K.shape[1]
    return kernel_array(np.broadcast_to(np.asarray(F, float), (G,) + np.shape(F)[-2:]))


def filter_means(g: Gains, F: np.ndarray, H: np.ndarray, y: np.ndarray,
                 x0: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Filtered means and innovations of S records per model.

    Parameters
    ----------
    g : Gains
        From :func:`gains` with at least T steps.
    F : ndarray, shape (G, n, n) or (n, n)
    H : ndarray, shape (p, n)
    y : ndarray, shape (T, G, S, p)
        Measurements: S records for each of the G models.
    x0 : ndarray, shape (G, S, n) or broadcastable
        Prior mean of the first step.

    Returns
    -------
    x_post : ndarray, shape (T, G, S, n)
        Filtered means ``x⁺_k``.
    innovations : ndarray, shape (T, G, S, p)
        ``y_k − H x⁻_k`` (the smoother's input).
    """
    y = kernel_array(y)
    if y.ndim != 4 or y.shape[1] != g.K.shape[1] or len(y) > len(g.K):
        raise ValueError(f"y must have shape (T ≤ {len(g.K)}, G = {g.K.shape[1]}, S, p), "
                         f"got {y.shape}")
    F = _per_model(g, F)
    x0 = kernel_array(np.broadcast_to(np.asarray(x0, float), y.shape[1:3] + (F.shape[-1],)))
    out = np.empty(y.shape[:3] + (F.shape[-1],))
    innovations = np.empty_like(y)
    _filter_kernel(kernel_array(g.K), F, kernel_array(H), y, x0, out, innovations)
    return out, innovations


def smoother_means(g: Gains, F: np.ndarray, H: np.ndarray, innovations: np.ndarray,
                   x_post: np.ndarray) -> np.ndarray:
    """Smoothed means ``x_{k|T}``, shape (T, G, S, n), from the filtered means and innovations
    of :func:`filter_means` (the whole record: offline)."""
    out = np.empty_like(x_post)
    _smoother_kernel(kernel_array(g.K), kernel_array(g.M), kernel_array(g.P_post),
                     _per_model(g, F), kernel_array(H), kernel_array(innovations),
                     kernel_array(x_post), out)
    return out
