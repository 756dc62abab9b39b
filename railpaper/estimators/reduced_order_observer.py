"""Reduced-order (Gopinath) Luenberger observer (paper 001, Eq. 12).

For ``ẋ = A x + B u`` partitioned as ``x = [x1; x2]`` with ``x1 = y`` measured:

    ẇ  = (A22 − L A12) w + [(A22 − L A12) L + (A21 − L A11)] y + (B2 − L B1) u
    x̂2 = w + L y

The error ``e = x2 − x̂2`` obeys ``ė = (A22 − L A12) e``: its poles are those of
``A22 − L A12``, placed by pole placement on the dual pair ``(A22ᵀ, A12ᵀ)``.

The same algebra holds for a discrete plant ``x[k+1] = Φ x[k] + Γ u[k]``: with ``(Φ, Γ)`` in
place of ``(A, B)`` the observer ``w[k+1] = F w[k] + G y[k] + H u[k]`` has the error
``e[k+1] = (Φ22 − L Φ12) e[k]`` (:func:`design_discrete`).  Two discrete observers follow:
:meth:`ReducedOrderObserver.discretise` (the paper's continuous observer, ZOH-discretised with
y and u held over a step) and :func:`design_discrete` (designed on the exactly discretised plant;
with ``u[k] = [q[k], q[k+1]]`` it is exact for a track input linear between samples).
"""

from __future__ import annotations

from dataclasses import dataclass

import control
import numpy as np

from railpaper.discretise import zoh


@dataclass(frozen=True)
class ReducedOrderObserver:
    """Continuous observer ``ẇ = F w + G y + H u``, ``x̂2 = w + L y``."""

    F: np.ndarray
    G: np.ndarray
    H: np.ndarray
    L: np.ndarray

    def discretise(self, dt_s: float) -> "DiscreteReducedOrderObserver":
        """ZOH discretisation with y and u held over each step."""
        inputs = np.hstack([self.G, self.H])
        Phi, Gamma = zoh(self.F, inputs, dt_s)
        ny = self.G.shape[1]
        return DiscreteReducedOrderObserver(Phi, Gamma[:, :ny], Gamma[:, ny:], self.L)


@dataclass(frozen=True)
class DiscreteReducedOrderObserver:
    """``w[k+1] = Phi w[k] + Gy y[k] + Gu u[k]``, ``x̂2[k] = w[k] + L y[k]``."""

    Phi: np.ndarray
    Gy: np.ndarray
    Gu: np.ndarray
    L: np.ndarray

    def run(self, y: np.ndarray, u: np.ndarray, x2_initial: np.ndarray) -> np.ndarray:
        """Estimates x̂2 (K, n2) from measurements y (K, n1) and inputs u (K, m).

        The observer starts from ``x̂2[0] = x2_initial`` (w[0] = x2_initial − L y[0]).
        """
        y = np.asarray(y, float)
        u = np.asarray(u, float).reshape(len(y), -1)
        drive = y @ self.Gy.T + u @ self.Gu.T
        w = np.empty((len(y), self.Phi.shape[0]))
        w[0] = np.asarray(x2_initial, float) - self.L @ y[0]
        for k in range(len(y) - 1):
            w[k + 1] = self.Phi @ w[k] + drive[k]          # w[k+1] = Φ w[k] + Γy y[k] + Γu u[k]
        return w + y @ self.L.T                            # x̂2 = w + L y


def partition(A: np.ndarray, B: np.ndarray, n1: int):
    """Blocks A11, A12, A21, A22, B1, B2 for ``x1 = x[:n1]``."""
    return A[:n1, :n1], A[:n1, n1:], A[n1:, :n1], A[n1:, n1:], B[:n1], B[n1:]


def _gopinath(A: np.ndarray, B: np.ndarray, n1: int, poles):
    """F, G, H, L of the Gopinath observer for x2 = x[n1:] with eig(A22 − L A12) = poles."""
    A11, A12, A21, A22, B1, B2 = partition(np.asarray(A, float), np.asarray(B, float), n1)
    n2 = A22.shape[0]
    poles = np.asarray(poles)
    if poles.shape != (n2,):
        raise ValueError(f"need {n2} observer poles, got {poles.tolist()}")
    if np.linalg.matrix_rank(control.obsv(A22, A12)) < n2:
        raise ValueError("(A22, A12) is not observable: the reduced-order observer cannot be placed")
    # A12 may be rank deficient (paper 001: the z_c row of A12 is zero), and pole placement needs
    # independent outputs: place on the row space of A12 (A12 = U_r S_r V_rᵀ), then map back.
    U, s, Vt = np.linalg.svd(A12)
    rank = int(np.sum(s > s[0] * 1e-12))
    A12_eff = s[:rank, None] * Vt[:rank]                   # independent rows of A12
    L_eff = control.place(A22.T, A12_eff.T, poles).T       # eig(A22 − L_eff A12_eff) = poles (dual)
    L = L_eff @ U[:, :rank].T                              # L A12 = L_eff A12_eff
    F = A22 - L @ A12
    G = F @ L + (A21 - L @ A11)
    H = B2 - L @ B1
    return F, G, H, L


def design(A: np.ndarray, B: np.ndarray, n1: int, poles) -> ReducedOrderObserver:
    """Continuous observer (paper Eq. 12) for ``x2 = x[n1:]`` with error poles ``poles`` (1/s).

    Raises
    ------
    ValueError
        If (A22, A12) is not observable, so the poles cannot be placed.
    """
    return ReducedOrderObserver(*_gopinath(A, B, n1, poles))


def design_discrete(Phi: np.ndarray, Gamma: np.ndarray, n1: int,
                    poles_s, dt_s: float) -> DiscreteReducedOrderObserver:
    """Observer designed on the discrete plant, error poles ``exp(poles_s · dt_s)``.

    Parameters
    ----------
    Phi, Gamma : ndarray
        Discrete plant ``x[k+1] = Phi x[k] + Gamma u[k]``.
    poles_s : array_like
        Continuous-time equivalent poles, 1/s.
    dt_s : float
        Sample time, s.
    """
    F, G, H, L = _gopinath(Phi, Gamma, n1, np.exp(np.asarray(poles_s, float) * dt_s))
    return DiscreteReducedOrderObserver(F, G, H, L)
