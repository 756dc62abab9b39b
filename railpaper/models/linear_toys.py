"""The two low-order linear-Gaussian toys used to test parameter estimators.

* Paper 004, Eqs. (20)–(21) (our reading of the garbled print, see ``data/quasi-gaussian-rbpf``)::

      x_k = [[0, 1], [a, b]] x_{k-1} + [[-1, 0.38], [-1.5, 1]] w_{k-1}
      y_k = [[1, -0.38], [0.5, 0.7]] x_k + e_k,     θ = (a, b)

* Paper 003, Eq. (18)::

      X(n) = [[0, 1.5], [x1, x2]] X(n-1) + [x3, x4]ᵀ u(n-1) + [-1.0, -1.3]ᵀ W(n-1)
      y(n) = [1, 0] X(n) + V(n),        θ = (x1, x2, x3, x4), u known

Timing convention shared by the simulators and the estimators: for k = 1 … K first
``x_k = F x_{k-1} + B u_k + G w_{k-1}``, then ``y_k = H x_k + e_k``; row ``k-1`` of the returned
``y`` and ``u`` arrays belongs to step k (``u_k`` is the input of the transition into step k,
the paper's u(n-1)).  This is the package's row convention (:mod:`railpaper.discretise`): K steps
give states (K+1, n) with ``x[0] = x_0``, inputs (K, m) and measurements (K, p).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np

from railpaper.discretise import propagate
from railpaper.engine import AffineSystem, LinearGaussianBatch

PAPER004_G = np.array([[-1.0, 0.38], [-1.5, 1.0]])
PAPER004_H = np.array([[1.0, -0.38], [0.5, 0.7]])
EQ18_G = np.array([[-1.0], [-1.3]])
EQ18_H = np.array([[1.0, 0.0]])

SystemBuilder = Callable[[np.ndarray], LinearGaussianBatch]


def paper004_system(q_var: float, r_var: float) -> SystemBuilder:
    """``system(theta)`` for paper 004: theta (N, 2) = (a, b) → batched matrices.

    Parameters
    ----------
    q_var, r_var : float
        Variances of each component of w and e (Q = q_var I, R = r_var I).
    """
    Q = PAPER004_G @ (q_var * np.eye(2)) @ PAPER004_G.T
    R = r_var * np.eye(2)
    F0, F_theta = np.zeros((2, 2)), np.zeros((2, 2, 2))
    F0[0, 1] = 1.0
    F_theta[0, 1, 0] = F_theta[1, 1, 1] = 1.0                 # F[1] = (a, b)
    return AffineSystem(F0, F_theta, Q, PAPER004_H, R)


def eq18_system(w_var: float, v_var: float) -> SystemBuilder:
    """``system(theta)`` for paper 003's Eq. (18): theta (N, 4) = (x1, x2, x3, x4)."""
    Q = w_var * EQ18_G @ EQ18_G.T
    R = np.array([[v_var]])
    F0, F_theta = np.zeros((2, 2)), np.zeros((4, 2, 2))
    F0[0, 1] = 1.5
    F_theta[0, 1, 0] = F_theta[1, 1, 1] = 1.0                 # F[1] = (x1, x2)
    B_theta = np.zeros((4, 2, 1))
    B_theta[2, 0, 0] = B_theta[3, 1, 0] = 1.0                 # B = (x3, x4)ᵀ
    return AffineSystem(F0, F_theta, Q, EQ18_H, R, np.zeros((2, 1)), B_theta)


@dataclass
class Simulation:
    """A simulated record: states x (K+1, n) with x[0] = x_0, measurements y (K, p),
    inputs u (K, m) or None."""

    x: np.ndarray
    y: np.ndarray
    u: np.ndarray | None = None


def _root(cov: np.ndarray) -> np.ndarray:
    """Symmetric square root of a PSD covariance (zero covariance allowed)."""
    val, vec = np.linalg.eigh(np.atleast_2d(cov))
    return vec * np.sqrt(np.clip(val, 0.0, None))


def simulate_linear(F: np.ndarray, G: np.ndarray, H: np.ndarray, Qw: np.ndarray, R: np.ndarray,
                    P0: np.ndarray, n_steps: int, rng: np.random.Generator,
                    B: np.ndarray | None = None, u: np.ndarray | None = None) -> Simulation:
    """Simulate ``x_k = F x_{k-1} + B u_k + G w_{k-1}``, ``y_k = H x_k + e_k``, k = 1…K.

    Random numbers are drawn in a fixed order (x_0, then all w, then all e), so the same
    generator state gives the same record.  ``x_0 ~ N(0, P0)``.

    Parameters
    ----------
    F, G, H : ndarray
        (n, n), (n, q), (p, n).
    Qw, R : ndarray
        Covariances of w (q, q) and e (p, p).
    P0 : ndarray, shape (n, n)
        Covariance of x_0.
    n_steps : int
        K.
    rng : numpy.random.Generator
    B : ndarray, shape (n, m), optional
    u : ndarray, shape (K, m) or (K,), optional
        ``u[k-1]`` is u_k, the input of the transition into step k.

    Returns
    -------
    Simulation
        ``x`` (K+1, n) with ``x[0] = x_0``; ``y`` (K, p) with ``y[k-1] = H x[k] + e_k``;
        ``u`` (K, m) or None (units those of the model).
    """
    n = F.shape[0]
    x0 = rng.standard_normal(n) @ _root(P0).T
    w = rng.standard_normal((n_steps, G.shape[1])) @ _root(Qw).T
    e = rng.standard_normal((n_steps, H.shape[0])) @ _root(R).T
    drive = w @ G.T
    if B is not None and u is not None:
        drive = drive + np.asarray(u, float).reshape(n_steps, -1) @ B.T
    x = propagate(F, drive, x0)
    y = x[1:] @ H.T + e
    return Simulation(x=x, y=y, u=None if u is None else np.asarray(u, float).reshape(n_steps, -1))


def simulate_paper004(a: float, b: float, q_var: float, r_var: float, p0_std: float,
                      n_steps: int, rng: np.random.Generator) -> Simulation:
    """A record of paper 004's system (Eqs. 20–21), x_0 ~ N(0, p0_std² I)."""
    F = np.array([[0.0, 1.0], [a, b]])
    return simulate_linear(F, PAPER004_G, PAPER004_H, q_var * np.eye(2), r_var * np.eye(2),
                           p0_std ** 2 * np.eye(2), n_steps, rng)


def simulate_eq18(theta: np.ndarray, w_var: float, v_var: float, n_steps: int,
                  rng: np.random.Generator, p0_std: float = 0.0) -> Simulation:
    """A record of paper 003's Eq. (18) with known input u ~ N(0, 1), drawn first."""
    x1, x2, x3, x4 = np.asarray(theta, float)
    u = rng.standard_normal((n_steps, 1))
    F = np.array([[0.0, 1.5], [x1, x2]])
    B = np.array([[x3], [x4]])
    return simulate_linear(F, EQ18_G, EQ18_H, np.array([[w_var]]), np.array([[v_var]]),
                           p0_std ** 2 * np.eye(2), n_steps, rng, B=B, u=u)
