"""Augmented-state extended Kalman filter for static parameters of a linear-Gaussian model.

The augmented state is ``z = [x; θ]`` with a small random walk on θ::

    x_k = F(θ) x_{k-1} + B(θ) u_k + (noise Q),     θ_k = θ_{k-1} + (noise q_theta)
    y_k = H(θ) x_k + (noise R)

The model is a callable ``model(theta (d,)) -> (F, B, H, dF, dB, dH)`` with the derivatives
``dF[j] = ∂F/∂θ_j`` (d, n, n), ``dB[j]`` (d, n, m) (or None) and ``dH[j]`` (d, p, n) (or None).
The Jacobian of the transition is ``[[F, [dF_j x + dB_j u]_j], [0, I]]`` and of the
measurement ``[H, [dH_j x]_j]``.  Covariance updates are in Joseph form (as filterpy's
``ExtendedKalmanFilter.update``).  The filter is declared diverged when a number becomes
non-finite, the innovation covariance stops being positive definite, or a parameter leaves
``±divergence_bound``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np


@dataclass
class EKFRun:
    """Per-step outputs (row k-1 = after y_k); rows after a divergence repeat the last value.

    Attributes
    ----------
    theta : ndarray, (K, d)
    theta_std : ndarray, (K, d)
    x : ndarray, (K, n)
    diverged : bool
    diverged_step : int
        First step (1-based) at which it diverged, -1 if never.
    """

    theta: np.ndarray
    theta_std: np.ndarray
    x: np.ndarray
    diverged: bool
    diverged_step: int


def ekf_step(z, P, y, u, model, Q, R, q_theta):
    """One predict + update of the augmented EKF; returns (z, P, ok)."""
    n = Q.shape[0]
    d = z.shape[0] - n
    x, th = z[:n], z[n:]
    F, B, H, dF, dB, dH = model(th)
    # predict
    J = np.eye(n + d)
    J[:n, :n] = F
    J[:n, n:] = np.einsum("jab,b->aj", dF, x)
    x_new = F @ x
    if B is not None and u is not None:
        x_new = x_new + B @ u
        if dB is not None:
            J[:n, n:] += np.einsum("jab,b->aj", dB, u)
    z = np.concatenate([x_new, th])
    Qa = np.zeros((n + d, n + d))
    Qa[:n, :n] = Q
    Qa[n:, n:] = np.diag(np.broadcast_to(q_theta, (d,)))
    P = J @ P @ J.T + Qa
    P = 0.5 * (P + P.T)
    # update (model re-evaluated at the predicted θ, which equals the previous θ here)
    Hx = np.zeros((H.shape[0], n + d))
    Hx[:, :n] = H
    if dH is not None:
        Hx[:, n:] = np.einsum("jab,b->aj", dH, x_new)
    v = y - H @ x_new
    S = Hx @ P @ Hx.T + R
    try:
        L = np.linalg.cholesky(0.5 * (S + S.T))
    except np.linalg.LinAlgError:
        return z, P, False
    K = np.linalg.solve(L.T, np.linalg.solve(L, Hx @ P)).T
    z = z + K @ v
    IKH = np.eye(n + d) - K @ Hx
    P = IKH @ P @ IKH.T + K @ R @ K.T
    P = 0.5 * (P + P.T)
    return z, P, bool(np.all(np.isfinite(z)) and np.all(np.isfinite(P)))


def run_augmented_ekf(model: Callable, y: np.ndarray, theta0, x0, P0_x, P0_theta, Q, R,
                      q_theta, u: np.ndarray | None = None, divergence_bound: float = 1e6
                      ) -> EKFRun:
    """Run the augmented EKF over measurements ``y`` (K, p) with inputs ``u`` (K, m) or None.

    Parameters
    ----------
    model : callable
        ``model(theta) -> (F, B, H, dF, dB, dH)`` (see module docstring).
    theta0 : array_like, (d,)
        Initial parameter guess.
    x0 : array_like, (n,)
        Initial state mean.
    P0_x : ndarray, (n, n)
    P0_theta : array_like, (d,) or (d, d)
        Initial parameter variances (or covariance).
    Q, R : ndarray
        Process-noise covariance of x (state coordinates) and measurement-noise covariance.
    q_theta : float or array_like, (d,)
        Random-walk variance per step of each parameter.
    divergence_bound : float
        |θ_j| above this counts as divergence.
    """
    y = np.asarray(y, float)
    theta0 = np.asarray(theta0, float)
    x0 = np.asarray(x0, float)
    n, d = x0.shape[0], theta0.shape[0]
    z = np.concatenate([x0, theta0])
    P = np.zeros((n + d, n + d))
    P[:n, :n] = P0_x
    P0_theta = np.asarray(P0_theta, float)
    P[n:, n:] = P0_theta if P0_theta.ndim == 2 else np.diag(np.broadcast_to(P0_theta, (d,)))
    Q, R = np.asarray(Q, float), np.asarray(R, float)
    K = len(y)
    theta = np.zeros((K, d))
    theta_std = np.zeros((K, d))
    xs = np.zeros((K, n))
    diverged_step = -1
    for k in range(K):
        if diverged_step < 0:
            z_new, P_new, ok = ekf_step(z, P, y[k], None if u is None else np.asarray(u[k], float),
                                        model, Q, R, q_theta)
            if not ok or np.any(np.abs(z_new[n:]) > divergence_bound):
                diverged_step = k + 1
            else:
                z, P = z_new, P_new
        theta[k] = z[n:]
        theta_std[k] = np.sqrt(np.clip(np.diag(P)[n:], 0.0, None))
        xs[k] = z[:n]
    return EKFRun(theta=theta, theta_std=theta_std, x=xs, diverged=diverged_step > 0,
                  diverged_step=diverged_step)


def eq18_model(theta):
    """Model callable of paper 003's Eq. (18) for :func:`run_augmented_ekf`, θ = (x1..x4)."""
    x1, x2, x3, x4 = theta
    F = np.array([[0.0, 1.5], [x1, x2]])
    B = np.array([[x3], [x4]])
    H = np.array([[1.0, 0.0]])
    dF = np.zeros((4, 2, 2))
    dF[0, 1, 0] = 1.0
    dF[1, 1, 1] = 1.0
    dB = np.zeros((4, 2, 1))
    dB[2, 0, 0] = 1.0
    dB[3, 1, 0] = 1.0
    return F, B, H, dF, dB, None
