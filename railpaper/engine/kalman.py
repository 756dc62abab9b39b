"""Batched Kalman-filter primitives on the last two axes (simdkalman style).

One code path serves one filter or a stack of ``N`` filters (one per particle or grid point):

* unbatched: ``x`` (n,), ``P`` (n, n), ``F`` (n, n), ``H`` (p, n), ``y`` (p,), ``R`` (p, p);
* batched: ``x`` (N, n), ``P`` (N, n, n); every matrix may be shared (2-D) or per filter (3-D),
  ``y`` may be shared (p,) or per filter (N, p).

Conventions follow filterpy's ``KalmanFilter``: ``predict`` gives the prior
``x_{k|k-1}, P_{k|k-1}``; ``update`` gives the posterior ``x_{k|k}, P_{k|k}`` with the Joseph-form
covariance; the prior is never overwritten (the functions return new arrays).  No explicit matrix
inverse is formed: the innovation covariance is factorised once by Cholesky and all solves use that
factor.  The model equations are

    x_k = F x_{k-1} + B u_k + (noise with covariance Q)
    y_k = H x_k + (noise with covariance R)

where ``Q`` is the covariance of the process noise *as it enters the state* (``G Q_w G^T`` when
the noise enters through a matrix ``G``).
"""

from __future__ import annotations

import numpy as np

LOG_2PI = float(np.log(2.0 * np.pi))


def _mT(a: np.ndarray) -> np.ndarray:
    """Transpose of the last two axes."""
    return np.swapaxes(a, -1, -2)


def _mv(M: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Matrix-vector product on the last axes, broadcasting the batch: (…, r, c) @ (…, c)."""
    return (M @ v[..., None])[..., 0]


def symmetrise(P: np.ndarray) -> np.ndarray:
    """``(P + P^T) / 2`` on the last two axes."""
    return 0.5 * (P + _mT(P))


def predict(x: np.ndarray, P: np.ndarray, F: np.ndarray, Q: np.ndarray,
            B: np.ndarray | None = None, u: np.ndarray | None = None
            ) -> tuple[np.ndarray, np.ndarray]:
    """Time update (prior) of one or N Kalman filters.

    Parameters
    ----------
    x : ndarray, shape (n,) or (N, n)
        Posterior mean at step k-1.
    P : ndarray, shape (n, n) or (N, n, n)
        Posterior covariance at step k-1.
    F : ndarray, shape (n, n) or (N, n, n)
        State transition matrix.
    Q : ndarray, shape (n, n) or (N, n, n)
        Process-noise covariance in state coordinates.
    B : ndarray, shape (n, m) or (N, n, m), optional
        Input matrix.
    u : ndarray, shape (m,) or (N, m), optional
        Known input.

    Returns
    -------
    x_prior : ndarray, shape of x (broadcast with the batch of F)
    P_prior : ndarray
    """
    x_prior = _mv(F, x)                                   # x⁻ = F x
    if B is not None and u is not None:
        x_prior = x_prior + _mv(B, np.asarray(u, float))  # x⁻ = F x + B u
    P_prior = symmetrise(F @ P @ _mT(F) + Q)              # P⁻ = F P Fᵀ + Q
    return x_prior, P_prior


def gaussian_logpdf(residual: np.ndarray, S: np.ndarray
                    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Log density of zero-mean Gaussians at ``residual``, via the Cholesky factor of ``S``.

    Parameters
    ----------
    residual : ndarray, shape (p,) or (N, p)
    S : ndarray, shape (p, p) or (N, p, p)
        Symmetric positive-definite covariances.

    Returns
    -------
    logpdf : ndarray, shape () or (N,)
        ``-½ (rᵀ S⁻¹ r + log det S + p log 2π)``.
    L : ndarray
        Lower Cholesky factor of ``S`` (``S = L Lᵀ``).
    z : ndarray
        Whitened residual ``L⁻¹ r``.
    """
    residual = np.asarray(residual, float)
    L = np.linalg.cholesky(S)                                              # S = L Lᵀ
    z = np.linalg.solve(L, residual[..., None])[..., 0]                    # z = L⁻¹ r
    log_det = 2.0 * np.sum(np.log(np.diagonal(L, axis1=-2, axis2=-1)), axis=-1)  # log|S|
    p = residual.shape[-1]
    logpdf = -0.5 * (np.sum(z * z, axis=-1) + log_det + p * LOG_2PI)      # log N(r; 0, S)
    return logpdf, L, z


def innovation(x: np.ndarray, P: np.ndarray, y: np.ndarray, H: np.ndarray, R: np.ndarray
               ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Innovation, its covariance and the predictive log-likelihood (no state update).

    Returns
    -------
    log_likelihood : ndarray, shape () or (N,)
        ``log N(y; H x, H P Hᵀ + R)``.
    v : ndarray
        Innovation ``y - H x``.
    S : ndarray
        Innovation covariance.
    L : ndarray
        Cholesky factor of ``S``.
    """
    v = np.asarray(y, float) - _mv(H, x)              # v = y − H x⁻
    S = symmetrise(H @ P @ _mT(H) + R)                # S = H P⁻ Hᵀ + R
    log_likelihood, L, _ = gaussian_logpdf(v, S)      # log N(v; 0, S)
    return log_likelihood, v, S, L


def update(x: np.ndarray, P: np.ndarray, y: np.ndarray, H: np.ndarray, R: np.ndarray
           ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Measurement update (posterior) of one or N Kalman filters, Joseph form.

    Parameters
    ----------
    x, P : ndarray
        Prior mean (n,)/(N, n) and covariance (n, n)/(N, n, n).
    y : ndarray, shape (p,) or (N, p)
        Measurement.
    H : ndarray, shape (p, n) or (N, p, n)
    R : ndarray, shape (p, p) or (N, p, p)

    Returns
    -------
    x_post, P_post : ndarray
        Posterior mean and covariance.
    log_likelihood : ndarray, shape () or (N,)
        Predictive log-likelihood ``log N(y; H x⁻, S)`` (natural log).
    innovation : ndarray
        ``y - H x⁻``.
    S : ndarray
        Innovation covariance ``H P⁻ Hᵀ + R``.

    Where S is not positive definite (e.g. exactly singular: P⁻ = 0 and R = 0) that filter is
    not updated (x = x⁻, P = P⁻) and its log-likelihood is −inf, as in
    :func:`railpaper.engine.kalman_bank.kalman_step`.
    """
    v = np.asarray(y, float) - _mv(H, x)                  # v = y − H x⁻
    HP = H @ P                                            # H P⁻ (= (P⁻ Hᵀ)ᵀ, P⁻ symmetric)
    S = symmetrise(HP @ _mT(H) + R)                       # S = H P⁻ Hᵀ + R
    S_safe, bad = _positive_definite_or_identity(S)
    L = np.linalg.cholesky(S_safe)                        # S = L Lᵀ
    n = x.shape[-1]
    batch = np.broadcast_shapes(HP.shape[:-2], v.shape[:-1])
    rhs = np.concatenate([np.broadcast_to(HP, batch + HP.shape[-2:]),
                          np.broadcast_to(v[..., None], batch + (v.shape[-1], 1))], axis=-1)
    L = np.broadcast_to(L, batch + L.shape[-2:])
    W = np.linalg.solve(L, rhs)                           # [L⁻¹ H P⁻ | L⁻¹ v]
    z = W[..., n]                                         # z = L⁻¹ v (whitened innovation)
    K = _mT(np.linalg.solve(_mT(L), W[..., :n]))          # K = P⁻ Hᵀ S⁻¹ = (L⁻ᵀ L⁻¹ H P⁻)ᵀ
    x_post = x + _mv(K, v)                                # x = x⁻ + K v
    I_KH = np.eye(n) - K @ H                              # I − K H
    P_post = symmetrise(I_KH @ P @ _mT(I_KH) + K @ R @ _mT(K))  # P = (I−KH)P⁻(I−KH)ᵀ + K R Kᵀ
    log_det = 2.0 * np.sum(np.log(np.diagonal(L, axis1=-2, axis2=-1)), axis=-1)
    log_likelihood = -0.5 * (np.sum(z * z, axis=-1) + log_det + v.shape[-1] * LOG_2PI)
    if bad is not None:                                   # no update where S is not PD
        x_post = np.where(bad[..., None], x, x_post)
        P_post = np.where(bad[..., None, None], P, P_post)
        log_likelihood = np.where(bad, -np.inf, log_likelihood)
    return x_post, P_post, log_likelihood, v, S


def _positive_definite_or_identity(S: np.ndarray) -> tuple[np.ndarray, np.ndarray | None]:
    """``S`` with every non-positive-definite matrix replaced by I, and the mask of those.

    The mask is None when the whole batch factorises (the usual case: one Cholesky call).
    """
    try:
        np.linalg.cholesky(S)
        return S, None
    except np.linalg.LinAlgError:
        pass
    stack = S.reshape((-1,) + S.shape[-2:])
    bad = np.zeros(len(stack), dtype=bool)
    for i, Si in enumerate(stack):                        # rare path: find the culprits
        try:
            np.linalg.cholesky(Si)
        except np.linalg.LinAlgError:
            bad[i] = True
    safe = np.where(bad[:, None, None], np.eye(S.shape[-1]), stack).reshape(S.shape)
    return safe, bad.reshape(S.shape[:-2])

