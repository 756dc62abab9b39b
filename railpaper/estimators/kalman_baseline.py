"""Steady-state Kalman filter with a shaping filter for a coloured, unknown input.

The plant ``ẋ = A x + B u`` is driven by an unknown input u (track irregularity under each
wheelset) whose one-sided PSD is not white.  Each input channel is modelled as the output of a
second-order shaping filter driven by unit white noise::

    H(s) = g / ((s + a)(s + b)),    S_u(ω) = g² / (π (ω² + a²)(ω² + b²))   (one-sided, per rad/s)

(with ``E[w(t) w(τ)] = δ(t − τ)`` the two-sided PSD of w is 1, its one-sided density 1/π).
The augmented model is discretised exactly (ZOH for the dynamics, Van Loan for the process-noise
covariance) and the steady-state gain comes from the discrete algebraic Riccati equation,
solved on a balanced copy of the model (states spanning metres to micrometres).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.linalg import expm, matrix_balance
from scipy.optimize import least_squares


@dataclass(frozen=True)
class ShapingFilter:
    """``H(s) = gain / ((s + a)(s + b))`` with a ≤ b (rad/s), driven by unit white noise."""

    gain: float
    a: float
    b: float

    def psd(self, omega_rad_s) -> np.ndarray:
        """One-sided output PSD, (unit of u)² per rad/s."""
        w2 = np.asarray(omega_rad_s, float) ** 2
        return self.gain**2 / (np.pi * (w2 + self.a**2) * (w2 + self.b**2))

    def variance(self) -> float:
        """Output variance, g² / (2 a b (a + b))."""
        return self.gain**2 / (2 * self.a * self.b * (self.a + self.b))

    def state_space(self):
        """``(Af, Bf, Cf)`` with states [u, u̇]: ü = −ab u − (a+b) u̇ + g w."""
        Af = np.array([[0.0, 1.0], [-self.a * self.b, -(self.a + self.b)]])
        Bf = np.array([[0.0], [self.gain]])
        Cf = np.array([[1.0, 0.0]])
        return Af, Bf, Cf


def fit_shaping_filter(omega_rad_s: np.ndarray, psd: np.ndarray,
                       variance: float | None = None, variance_weight: float = 30.0) -> ShapingFilter:
    """Least-squares fit of a second-order shaping filter to PSD samples (log scale).

    Parameters
    ----------
    omega_rad_s : ndarray
        Angular frequencies (rad/s) where the target PSD is known, > 0 (log-spaced is best).
    psd : ndarray
        Target one-sided PSD at those frequencies (> 0).
    variance : float, optional
        Target variance (e.g. the band-limited variance of the simulated input); adds the
        residual ``variance_weight · log(var_model / variance)`` so a band-limited target does not
        pull ``a`` to zero.

    Returns
    -------
    ShapingFilter
    """
    w = np.asarray(omega_rad_s, float)
    S = np.asarray(psd, float)
    if np.any(w <= 0) or np.any(S <= 0) or w.shape != S.shape:
        raise ValueError("need positive frequencies and PSD values of the same shape")
    logS = np.log(S)

    def model(theta):
        g, a, b = np.exp(theta)
        return ShapingFilter(g, a, b)

    def residuals(theta):
        f = model(theta)
        r = np.log(f.psd(w)) - logS
        if variance is not None:
            r = np.append(r, variance_weight * np.log(f.variance() / variance))
        return r

    # start: a at the lowest, b at the geometric middle, gain from the highest frequency
    a0, b0 = w.min(), np.sqrt(w.min() * w.max())
    g0 = np.sqrt(np.pi * S[-1] * (w[-1] ** 2 + a0**2) * (w[-1] ** 2 + b0**2))
    sol = least_squares(residuals, np.log([g0, a0, b0]), method="lm", xtol=1e-12, ftol=1e-12)
    f = model(sol.x)
    a, b = sorted((f.a, f.b))
    return ShapingFilter(f.gain, a, b)


def augment(A: np.ndarray, B: np.ndarray, C: np.ndarray, filters: list[ShapingFilter]):
    """Plant plus one shaping filter per input: ``(Aa, Ga, Ca)`` with unit white-noise inputs.

    The augmented state is ``[x; u_1, u̇_1; …; u_m, u̇_m]``.
    """
    n, m = B.shape
    if len(filters) != m:
        raise ValueError(f"need {m} shaping filters, got {len(filters)}")
    na = n + 2 * m
    Aa = np.zeros((na, na))
    Ga = np.zeros((na, m))
    Aa[:n, :n] = A
    for i, f in enumerate(filters):
        Af, Bf, Cf = f.state_space()
        sl = slice(n + 2 * i, n + 2 * i + 2)
        Aa[sl, sl] = Af
        Ga[sl, i] = Bf[:, 0]
        Aa[:n, sl] = B[:, [i]] @ Cf
    Ca = np.hstack([C, np.zeros((C.shape[0], 2 * m))])
    return Aa, Ga, Ca


def discretise_noise(A: np.ndarray, G: np.ndarray, W: np.ndarray, dt_s: float):
    """``Φ = e^{A dt}`` and ``Qd = ∫_0^dt e^{As} G W Gᵀ e^{Aᵀs} ds`` (Van Loan 1978)."""
    n = A.shape[0]
    block = np.zeros((2 * n, 2 * n))
    block[:n, :n] = -A
    block[:n, n:] = G @ W @ G.T
    block[n:, n:] = A.T
    F = expm(block * dt_s)
    Phi = F[n:, n:].T
    Qd = Phi @ F[:n, n:]
    return Phi, 0.5 * (Qd + Qd.T)


@dataclass
class SteadyStateKalman:
    """``x⁻[k+1] = Φ x⁺[k]``, ``x⁺[k] = x⁻[k] + K (y[k] − C x⁻[k])`` (no known input)."""

    Phi: np.ndarray
    C: np.ndarray
    K: np.ndarray
    P_prior: np.ndarray

    def run(self, y: np.ndarray, x0: np.ndarray) -> np.ndarray:
        """Filtered states ``x⁺`` (..., T, n) for measurements y (..., T, q); prior mean x0 (..., n)."""
        y = np.asarray(y, float)
        n = self.Phi.shape[0]
        out = np.empty(y.shape[:-1] + (n,))
        prior = np.broadcast_to(np.asarray(x0, float), y.shape[:-2] + (n,)).copy()
        A_upd = np.eye(n) - self.K @ self.C        # x⁺ = (I − K C) x⁻ + K y
        drive = y @ self.K.T
        AT, PhiT = A_upd.T, self.Phi.T
        for k in range(y.shape[-2]):
            post = prior @ AT + drive[..., k, :]
            out[..., k, :] = post
            prior = post @ PhiT
        return out


def dare_doubling(A: np.ndarray, B: np.ndarray, Q: np.ndarray, R: np.ndarray,
                  rtol: float = 1e-13, max_iter: int = 100) -> np.ndarray:
    """Stabilising solution of ``X = Aᵀ X A − Aᵀ X B (R + Bᵀ X B)⁻¹ Bᵀ X A + Q``.

    Structure-preserving doubling (Chu, Fan, Lin 2005): with ``G = B R⁻¹ Bᵀ`` and ``H = Q``,
    ``W = I + G H``, ``A ← A W⁻¹ A``, ``G ← G + A W⁻¹ G Aᵀ``, ``H ← H + Aᵀ H W⁻¹ A``;
    ``H → X`` quadratically.  For the filter DARE pass ``(Φᵀ, Cᵀ, Qd, R)``.
    """
    n = A.shape[0]
    Ak, Gk, Hk = A.copy(), B @ np.linalg.solve(R, B.T), Q.copy()
    Gk, Hk = 0.5 * (Gk + Gk.T), 0.5 * (Hk + Hk.T)
    eye = np.eye(n)
    for _ in range(max_iter):
        W = eye + Gk @ Hk
        WiA = np.linalg.solve(W, Ak)
        WiG = np.linalg.solve(W, Gk)
        H_new = Hk + Ak.T @ Hk @ WiA
        Gk = Gk + Ak @ WiG @ Ak.T
        Ak = Ak @ WiA
        Gk, H_new = 0.5 * (Gk + Gk.T), 0.5 * (H_new + H_new.T)
        done = np.linalg.norm(H_new - Hk) <= rtol * np.linalg.norm(H_new)
        Hk = H_new
        if done:
            return Hk
    raise RuntimeError("DARE doubling did not converge (is the model detectable?)")


def steady_state_kalman(Phi: np.ndarray, Qd: np.ndarray, C: np.ndarray,
                        R: np.ndarray) -> SteadyStateKalman:
    """Steady-state gain from the DARE, solved on a balanced copy of ``(Φ, Qd, C)``.

    The DARE is solved by the structure-preserving doubling algorithm (:func:`dare_doubling`):
    the QZ-based ``scipy.linalg.solve_discrete_are`` fails on some of this chapter's models
    (closed-loop poles within 3e-3 of the unit circle, covariances spanning many decades).

    With ``x = S x̃`` (S from power-of-two balancing of Φ) and outputs scaled to unit-norm rows,
    the DARE is solved for x̃ and mapped back: ``P = S P̃ S``, ``K = S K̃ Dy``.
    """
    _, (S, _) = matrix_balance(Phi, permute=False, separate=True)
    S = np.asarray(S, float)
    Si = 1.0 / S
    Pt = Si[:, None] * Phi * S[None, :]
    Qt = Si[:, None] * Qd * Si[None, :]
    Dy = 1.0 / np.linalg.norm(C * S[None, :], axis=1)
    Ct = Dy[:, None] * C * S[None, :]
    Rt = Dy[:, None] * R * Dy[None, :]
    Xt = dare_doubling(Pt.T, Ct.T, Qt, Rt)
    Kt = Xt @ Ct.T @ np.linalg.inv(Ct @ Xt @ Ct.T + Rt)
    P = S[:, None] * Xt * S[None, :]
    K = S[:, None] * Kt * Dy[None, :]
    return SteadyStateKalman(Phi=Phi, C=C, K=K, P_prior=P)
