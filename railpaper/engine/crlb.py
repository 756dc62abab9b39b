"""Cramér–Rao bound of static parameters of a linear-Gaussian model from the Kalman likelihood.

The exact log-likelihood of a record is ``Σ_k log N(v_k(θ); 0, S_k(θ))`` with the Kalman
innovations v_k and their covariances S_k.  Its Fisher information is (Åström's innovation
form)::

    I_ij = Σ_k [ ∂_i v_kᵀ S_k⁻¹ ∂_j v_k + ½ tr(S_k⁻¹ ∂_i S_k S_k⁻¹ ∂_j S_k) ]

where the expectation over records is replaced by the record itself (the innovation sensitivities
are computed along the given record).  The derivatives are central finite differences of the
Kalman filter run at θ ± h_j e_j (relative step ``rel_step``).
"""

from __future__ import annotations

from typing import Callable

import numpy as np

from railpaper.engine.kalman import predict, update
from railpaper.engine.linear_gaussian import LinearGaussianBatch


def innovations(system: Callable[[np.ndarray], LinearGaussianBatch], theta: np.ndarray,
                y: np.ndarray, x0, P0, u: np.ndarray | None = None
                ) -> tuple[np.ndarray, np.ndarray]:
    """Innovations v (M, K, p) and covariances S (M, K, p, p) of M Kalman filters run in parallel.

    ``theta`` (M, d): one filter per row (batched, no loop over filters).
    """
    theta = np.atleast_2d(theta)
    s = system(theta)
    M = theta.shape[0]
    x0, P0 = np.asarray(x0, float), np.asarray(P0, float)
    x = np.broadcast_to(x0, (M, x0.shape[-1])).copy()
    P = np.broadcast_to(P0, (M,) + P0.shape[-2:]).copy()
    K, p = y.shape
    v_all = np.zeros((M, K, p))
    S_all = np.zeros((M, K, p, p))
    for k in range(K):
        x, P = predict(x, P, s.F, s.Q, s.B, None if u is None else u[k])
        x, P, _, v, S = update(x, P, y[k], s.H, s.R)
        v_all[:, k] = v
        S_all[:, k] = S
    return v_all, S_all


def fisher_information(system, theta, y, x0, P0, u=None, rel_step: float = 1e-5,
                       checkpoints: tuple[int, ...] | None = None) -> dict[int, np.ndarray]:
    """Fisher information (d, d) of θ after each checkpoint number of steps (default: all K).

    Parameters
    ----------
    system : callable
        ``system(theta (M, d)) -> LinearGaussianBatch``.
    theta : ndarray, (d,)
        Point (usually the true parameters) where the information is evaluated.
    y : ndarray, (K, p)
    rel_step : float
        Central-difference step relative to |θ_j| (absolute when θ_j = 0).
    checkpoints : tuple of int, optional
        Step counts at which the accumulated information is returned.
    """
    theta = np.asarray(theta, float)
    d = theta.shape[0]
    h = rel_step * np.where(theta != 0, np.abs(theta), 1.0)
    pts = np.concatenate([theta[None], theta + np.diag(h), theta - np.diag(h)])
    v, S = innovations(system, pts, np.asarray(y, float), x0, P0, u)
    dv = (v[1:d + 1] - v[d + 1:]) / (2 * h[:, None, None])               # (d, K, p)
    dS = (S[1:d + 1] - S[d + 1:]) / (2 * h[:, None, None, None])         # (d, K, p, p)
    Sinv = np.linalg.inv(S[0])                                           # (K, p, p)
    a = np.einsum("ikp,kpq,jkq->kij", dv, Sinv, dv)
    SdS = np.einsum("kpq,ikqr->ikpr", Sinv, dS)
    b = 0.5 * np.einsum("ikpq,jkqp->kij", SdS, SdS)
    per_step = a + b
    cum = np.cumsum(per_step, axis=0)
    K = len(y)
    checkpoints = (K,) if checkpoints is None else checkpoints
    return {c: cum[min(c, K) - 1] for c in checkpoints}


def crlb_std(information: np.ndarray) -> np.ndarray:
    """Bound on the standard deviation of each parameter: sqrt(diag(I⁻¹)) (inf if singular)."""
    try:
        cov = np.linalg.inv(information)
    except np.linalg.LinAlgError:
        return np.full(information.shape[0], np.inf)
    return np.sqrt(np.clip(np.diag(cov), 0.0, None))
