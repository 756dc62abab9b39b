"""Exact discretisation and linear simulation of continuous-time state-space models.

All functions work on the last two axes, so a stack of systems ``A`` of shape ``(..., n, n)``
is discretised in one call.

Row convention of every simulation in the package (:func:`propagate`, :func:`simulate_zoh`,
:func:`simulate_foh`, :func:`railpaper.models.lateral_16state.simulate_truth`,
:func:`railpaper.models.linear_toys.simulate_linear`): K steps give states of shape (K+1, n) with
``x[0] = x0`` and ``x[k]`` the state after step k; a held input has K rows, ``u[k-1]`` acting over
step k (``x[k] = Phi x[k-1] + Gamma u[k-1]``); measurements have K rows, ``y[k-1]`` measuring
``x[k]``.  A first-order hold needs the input at both ends of every step, so its input has the
K+1 rows of the state times.
"""

from __future__ import annotations

import numpy as np
from scipy.linalg import expm


def _block_expm(blocks: np.ndarray) -> np.ndarray:
    """``expm`` over the last two axes of a (possibly stacked) array.

    scipy's ``expm`` takes the stack in one call (its Padé kernel loops over the leading axes
    in compiled code), and each matrix is bit-identical to ``expm`` of that matrix alone.
    """
    return expm(blocks)


def _checked(A, B, dt_s: float):
    """A, B as float arrays, their sizes n, m and the broadcast batch shape; dt_s must be > 0."""
    if not dt_s > 0:
        raise ValueError(f"dt_s must be > 0, got {dt_s!r}")
    A = np.asarray(A, dtype=float)
    B = np.asarray(B, dtype=float)
    return A, B, A.shape[-1], B.shape[-1], np.broadcast_shapes(A.shape[:-2], B.shape[:-2])


def zoh(A: np.ndarray, B: np.ndarray, dt_s: float) -> tuple[np.ndarray, np.ndarray]:
    """Zero-order-hold discretisation: ``x[k+1] = Phi x[k] + Gamma u[k]``.

    Phi = e^{A dt}, Gamma = ∫_0^dt e^{A s} ds B, both from one matrix exponential of
    ``[[A, B], [0, 0]] dt`` (Van Loan).

    Parameters
    ----------
    A : ndarray, shape (..., n, n)
        Continuous state matrix, 1/s.
    B : ndarray, shape (..., n, m)
        Continuous input matrix.
    dt_s : float
        Sample time, s.

    Returns
    -------
    Phi : ndarray, shape (..., n, n)
    Gamma : ndarray, shape (..., n, m)
    """
    A, B, n, m, batch = _checked(A, B, dt_s)
    block = np.zeros(batch + (n + m, n + m))
    block[..., :n, :n] = A * dt_s
    block[..., :n, n:] = B * dt_s
    E = _block_expm(block)
    return E[..., :n, :n], E[..., :n, n:]


def foh(A: np.ndarray, B: np.ndarray, dt_s: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Exact discretisation for inputs linear between samples (first-order hold).

    With ``u(t) = u[k] + (t - t_k)/dt (u[k+1] - u[k])`` on ``[t_k, t_k+dt]``:
    ``x[k+1] = Phi x[k] + Gamma0 u[k] + Gamma1 (u[k+1] - u[k])``, where
    Gamma0 = ∫_0^dt e^{A s} ds B and Gamma1 = ∫_0^dt e^{A s} (dt - s)/dt ds B (Van Loan).

    Returns
    -------
    Phi, Gamma0, Gamma1 : ndarray
    """
    A, B, n, m, batch = _checked(A, B, dt_s)
    block = np.zeros(batch + (n + 2 * m, n + 2 * m))
    block[..., :n, :n] = A * dt_s
    block[..., :n, n:n + m] = B * dt_s
    block[..., n:n + m, n + m:] = np.eye(m)
    E = _block_expm(block)
    return E[..., :n, :n], E[..., :n, n:n + m], E[..., :n, n + m:]


def propagate(Phi: np.ndarray, drive: np.ndarray, x0: np.ndarray | None = None) -> np.ndarray:
    """States of ``x[k] = Phi x[k-1] + drive[k-1]``, k = 1 … K: the one simulation loop.

    Parameters
    ----------
    Phi : ndarray, shape (n, n)
        Transition matrix over one step.
    drive : ndarray, shape (K, n)
        What enters the state in each step (input and noise terms), state units.
    x0 : ndarray, shape (n,), optional
        Initial state (zero by default).

    Returns
    -------
    x : ndarray, shape (K+1, n)
        ``x[0] = x0``, ``x[k]`` the state after step k.
    """
    drive = np.asarray(drive, dtype=float)
    x = np.zeros((len(drive) + 1, Phi.shape[0]))
    if x0 is not None:
        x[0] = x0
    for k in range(len(drive)):
        x[k + 1] = Phi @ x[k] + drive[k]
    return x


def _as_rows(u: np.ndarray) -> np.ndarray:
    u = np.asarray(u, dtype=float)
    return u[:, None] if u.ndim == 1 else u


def simulate_foh(Phi: np.ndarray, Gamma0: np.ndarray, Gamma1: np.ndarray, u: np.ndarray,
                 x0: np.ndarray | None = None) -> np.ndarray:
    """States of ``x[k] = Phi x[k-1] + Gamma0 u[k-1] + Gamma1 (u[k] - u[k-1])`` (first-order hold).

    Parameters
    ----------
    Phi, Gamma0, Gamma1 : ndarray
        From :func:`foh`.
    u : ndarray, shape (K+1, m) or (K+1,)
        Input samples at the K+1 state times (the input is linear between them).
    x0 : ndarray, shape (n,), optional
        Initial state (zero by default).

    Returns
    -------
    x : ndarray, shape (K+1, n)
        ``x[0] = x0``, ``x[k]`` the state at the time of ``u[k]`` (as many rows as ``u``).
    """
    u = _as_rows(u)
    drive = u[:-1] @ (Gamma0 - Gamma1).T + u[1:] @ Gamma1.T   # input term of each step
    return propagate(Phi, drive, x0)


def simulate_zoh(Phi: np.ndarray, Gamma: np.ndarray, u: np.ndarray,
                 x0: np.ndarray | None = None) -> np.ndarray:
    """States of ``x[k] = Phi x[k-1] + Gamma u[k-1]`` (zero-order hold), k = 1 … K.

    Parameters
    ----------
    Phi, Gamma : ndarray
        From :func:`zoh`: (n, n) and (n, m).
    u : ndarray, shape (K, m) or (K,)
        ``u[k-1]`` is held over step k.
    x0 : ndarray, shape (n,), optional
        Initial state (zero by default).

    Returns
    -------
    x : ndarray, shape (K+1, n)
        ``x[0] = x0``, ``x[k]`` the state after step k (one row more than ``u``).
    """
    return propagate(Phi, _as_rows(u) @ Gamma.T, x0)
