"""Reduced-order (Gopinath) Luenberger observer (paper 001, Eq. 12).

For ``ẋ = A x + B u`` partitioned as ``x = [x1; x2]`` with ``x1 = y`` measured:

    ẇ  = (A22 − L A12) w + [(A22 − L A12) L + (A21 − L A11)] y + (B2 − L B1) u
    x̂2 = w + L y

The error ``e = x2 − x̂2`` obeys ``ė = (A22 − L A12) e``: its poles are those of
``A22 − L A12``, placed by pole placement on the dual pair ``(A22ᵀ, A12ᵀ)``.

Two discretisations of the continuous observer serve a sampled implementation:
``hold="zoh"`` holds y and u over each step (the paper's), ``hold="foh"`` takes them linear
between samples (exact for a track input linear between samples, error O(dt²) for smooth y).
"""

from __future__ import annotations

from dataclasses import dataclass

import control
import numpy as np

from railpaper.discretise import foh, zoh


@dataclass(frozen=True)
class ReducedOrderObserver:
    """Continuous observer ``ẇ = F w + G y + H u``, ``x̂2 = w + L y``."""

    F: np.ndarray
    G: np.ndarray
    H: np.ndarray
    L: np.ndarray

    def discretise(self, dt_s: float, hold: str = "zoh") -> "DiscreteReducedOrderObserver":
        """Discretise with y and u held (``"zoh"``) or linear (``"foh"``) between samples."""
        inputs = np.hstack([self.G, self.H])
        if hold == "zoh":
            Phi, Gamma = zoh(self.F, inputs, dt_s)
            return DiscreteReducedOrderObserver(Phi, Gamma, np.zeros_like(Gamma), self.L)
        if hold == "foh":
            Phi, Gamma0, Gamma1 = foh(self.F, inputs, dt_s)
            return DiscreteReducedOrderObserver(Phi, Gamma0 - Gamma1, Gamma1, self.L)
        raise ValueError(f"hold must be 'zoh' or 'foh', got {hold!r}")


@dataclass(frozen=True)
class DiscreteReducedOrderObserver:
    """``w[k+1] = Φ w[k] + Γ_now v[k] + Γ_next v[k+1]``, ``v = [y; u]``, ``x̂2[k] = w[k] + L y[k]``."""

    Phi: np.ndarray
    Gamma_now: np.ndarray
    Gamma_next: np.ndarray
    L: np.ndarray

    def run(self, y: np.ndarray, u: np.ndarray, x2_initial: np.ndarray) -> np.ndarray:
        """Estimates x̂2 (K, n2) from measurements y (K, n1) and inputs u (K, m).

        The observer starts from ``x̂2[0] = x2_initial`` (w[0] = x2_initial − L y[0]).
        """
        y = np.asarray(y, float)
        v = np.hstack([y, np.asarray(u, float).reshape(len(y), -1)])
        drive = v[:-1] @ self.Gamma_now.T + v[1:] @ self.Gamma_next.T
        w = np.empty((len(y), self.Phi.shape[0]))
        w[0] = np.asarray(x2_initial, float) - self.L @ y[0]
        for k in range(len(y) - 1):
            w[k + 1] = self.Phi @ w[k] + drive[k]          # w[k+1] = Φ w[k] + Γ_now v[k] + Γ_next v[k+1]
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
