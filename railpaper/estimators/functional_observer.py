"""Functional (partial-state) observer of ``z = L x`` for ``ẋ = A x + B u``, ``y = C x``.

Observer (paper 000, Eq. 14; Darouach 2000; Trinh & Fernando 2006)::

    ẇ = N w + J y + H B u,     ẑ = w + E y,     H = L − E C.

The error ``e = w − H x`` obeys ``ė = N e + (N H + J C − H A) x``; the design makes the bracket
vanish and N Hurwitz.  Writing ``K = J − N E`` the bracket is zero iff
``[N E K] [L; CA; C] = L A``, whose general solution is (Darouach 2000)::

    Π = I − L⁺L,  ψ = L A Π,  Ω = [C A Π; C Π],  Γ = [C A L⁺; C L⁺]
    N1 = L A L⁺ − ψ Ω⁺ Γ,        N2 = (I − Ω Ω⁺) Γ,        N = N1 − Z N2
    [E K] = ψ Ω⁺ + Z (I − Ω Ω⁺)  (E multiplies the C A rows, K the C rows)
    H = H1 − Z H2,  H1 = L − ψ Ω⁺ [C; 0],  H2 = (I − Ω Ω⁺) [C; 0],   J = K + N E

with Z free; Z comes from a pole-region LMI (:mod:`railpaper.estimators.lmi_region`).
Existence (Darouach 2000): (1) rank[LA; CA; C; L] = rank[CA; C; L];
(2) rank[sL − LA; CA; C] = rank[CA; C; L] for all Re s ≥ 0 (⇔ (N1, N2) detectable).

All computations run on a scaled copy of the system (time in units of ``1/ρ(A)``, states balanced
by powers of two, output rows normalised): stiff contact springs put entries of ~1e6 in A next
to ~1 (and stiffnesses ~1e9 in the physical coefficients), which would otherwise spoil the
pseudo-inverses, ranks and LMIs.  Results are mapped back and checked in physical units.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.linalg import matrix_balance

from railpaper.discretise import foh, zoh
from railpaper.estimators.lmi_region import LMIInfeasible, in_region, region_gain

__all__ = ["Scaling", "scaling_for", "numerical_rank", "pencil_zeros", "existence", "Parametrisation", "parametrise", "design",
           "FunctionalObserver", "DiscreteFunctionalObserver", "fixed_modes", "LMIInfeasible"]

RANK_RTOL = 1e-9


@dataclass(frozen=True)
class Scaling:
    """``t = tau_s · t'``, ``x = diag(S) x̃``, ``ỹ = diag(Dy) y``, ``z̃ = diag(Dz) z``."""

    tau_s: float
    S: np.ndarray
    Dy: np.ndarray
    Dz: np.ndarray

    def apply(self, A, B, C, L):
        """Scaled ``(Ã, B̃, C̃, L̃)`` = (τ S⁻¹AS, τ S⁻¹B, Dy C S, Dz L S); u stays unscaled."""
        Si = 1.0 / self.S
        At = self.tau_s * (Si[:, None] * A * self.S[None, :])
        Bt = self.tau_s * (Si[:, None] * B)
        Ct = self.Dy[:, None] * C * self.S[None, :]
        Lt = self.Dz[:, None] * L * self.S[None, :]
        return At, Bt, Ct, Lt


def scaling_for(A: np.ndarray, C: np.ndarray, L: np.ndarray) -> Scaling:
    """Time unit 1/ρ(A), power-of-two balancing of τA, unit-norm output rows."""
    tau = 1.0 / np.max(np.abs(np.linalg.eigvals(A)))
    _, (S, _) = matrix_balance(tau * A, permute=False, separate=True)
    S = np.asarray(S, float)
    Dy = 1.0 / np.linalg.norm(C * S[None, :], axis=1)
    Dz = 1.0 / np.linalg.norm(L * S[None, :], axis=1)
    return Scaling(tau, S, Dy, Dz)


def numerical_rank(X: np.ndarray) -> int:
    """Number of singular values above ``RANK_RTOL`` times the largest (call on scaled matrices)."""
    if X.size == 0:
        return 0
    s = np.linalg.svd(X, compute_uv=False)
    return int(np.sum(s > RANK_RTOL * s[0])) if s[0] > 0 else 0


def _pinv(X: np.ndarray) -> np.ndarray:
    return np.linalg.pinv(X, rtol=RANK_RTOL)


def pencil_zeros(E: np.ndarray, F: np.ndarray, rng_seed: int = 0,
                 max_modulus: float = 1e6) -> tuple[int, np.ndarray]:
    """Normal rank of the pencil ``s E − F`` and the finite s where its rank drops.

    Candidates are the generalized eigenvalues of a random square compression (every rank-drop
    point of the pencil is one); each is kept when the pencil's singular values confirm the
    drop.  Works for tall, wide or square pencils.  Candidates with ``|s| > max_modulus`` are
    numerically infinite eigenvalues (``sE − F ≈ sE`` loses rank when E does) and are dropped;
    call it on a well-scaled pencil (‖E‖ ≈ ‖F‖ ≈ 1).
    """
    rng = np.random.default_rng(rng_seed)
    probe = [np.complex128(complex(*rng.standard_normal(2))) for _ in range(3)]
    normal = max(numerical_rank(s * E - F) for s in probe)
    rows, cols = E.shape
    if normal == 0:
        return 0, np.zeros(0, complex)
    Rl = rng.standard_normal((normal, rows))
    Rr = rng.standard_normal((cols, normal))
    from scipy.linalg import eigvals
    cand = eigvals(Rl @ F @ Rr, Rl @ E @ Rr)
    cand = cand[np.isfinite(cand) & (np.abs(cand) < max_modulus)]
    zeros = [s for s in cand if numerical_rank(s * E - F) < normal]
    return normal, np.array(zeros, complex)


def existence(A: np.ndarray, C: np.ndarray, L: np.ndarray) -> dict:
    """Darouach's existence conditions for a functional observer of ``z = L x`` (scaled ranks).

    Returns
    -------
    dict
        ``rank_CA_C_L``, ``rank_LA_CA_C_L``, ``condition1``; ``pencil_normal_rank`` of
        ``[sL − LA; CA; C]``, ``pencil_zeros`` (s where it drops), ``condition2`` (normal rank =
        rank[CA; C; L] and no zero with Re s ≥ 0), ``exists`` (both).
    """
    sc = scaling_for(A, C, L)
    At, _, Ct, Lt = sc.apply(A, np.zeros((A.shape[0], 0)), C, L)
    base = np.vstack([Ct @ At, Ct, Lt])
    r_base = numerical_rank(base)
    r_ext = numerical_rank(np.vstack([Lt @ At, base]))
    E = np.vstack([Lt, np.zeros((2 * Ct.shape[0], Lt.shape[1]))])
    F = np.vstack([Lt @ At, -Ct @ At, -Ct])
    normal, zeros = pencil_zeros(E, F)
    zeros = zeros / sc.tau_s
    cond2 = normal == r_base and not np.any(zeros.real >= -1e-9 / sc.tau_s)
    return {"rank_CA_C_L": r_base, "rank_LA_CA_C_L": r_ext, "condition1": r_ext == r_base,
            "pencil_normal_rank": normal, "pencil_zeros": zeros, "condition2": bool(cond2),
            "exists": bool(r_ext == r_base and cond2)}


@dataclass
class Parametrisation:
    """Darouach's affine parametrisation of all observers, in scaled coordinates."""

    N1: np.ndarray
    N2: np.ndarray
    H1: np.ndarray
    H2: np.ndarray
    EK1: np.ndarray      # ψ Ω⁺
    EK2: np.ndarray      # I − Ω Ω⁺
    q: int               # number of outputs
    condition1_residual: float

    def matrices(self, Z: np.ndarray):
        """``N, J, H, E`` (scaled) for a given Z."""
        N = self.N1 - Z @ self.N2
        H = self.H1 - Z @ self.H2
        EK = self.EK1 + Z @ self.EK2
        E, K = EK[:, :self.q], EK[:, self.q:]
        return N, K + N @ E, H, E


def parametrise(At: np.ndarray, Ct: np.ndarray, Lt: np.ndarray) -> Parametrisation:
    """N1, N2, H1, H2 and the E/K parts of the general solution (scaled matrices)."""
    n, q = At.shape[0], Ct.shape[0]
    Lp = _pinv(Lt)
    Pi = np.eye(n) - Lp @ Lt
    psi = Lt @ At @ Pi
    Omega = np.vstack([Ct @ At @ Pi, Ct @ Pi])
    Op = _pinv(Omega)
    Gam = np.vstack([Ct @ At @ Lp, Ct @ Lp])
    proj = np.eye(2 * q) - Omega @ Op
    C0 = np.vstack([Ct, np.zeros_like(Ct)])
    residual = np.linalg.norm(psi - psi @ Op @ Omega) / max(np.linalg.norm(psi), 1e-300)
    return Parametrisation(
        N1=Lt @ At @ Lp - psi @ Op @ Gam, N2=proj @ Gam, H1=Lt - psi @ Op @ C0, H2=proj @ C0,
        EK1=psi @ Op, EK2=proj, q=q, condition1_residual=float(residual))


def fixed_modes(N1: np.ndarray, N2: np.ndarray, rtol: float = 1e-7) -> np.ndarray:
    """Eigenvalues of N1 unobservable through N2 (PBH): no Z can move them."""
    p = N1.shape[0]
    scale = np.linalg.norm(np.vstack([N1, N2]), 2)
    out = []
    for lam in np.linalg.eigvals(N1):
        s = np.linalg.svd(np.vstack([lam * np.eye(p) - N1, N2]), compute_uv=False)
        if s[-1] <= rtol * scale:
            out.append(lam)
    return np.array(out, complex)


@dataclass
class FunctionalObserver:
    """Continuous observer in physical units; ``HB`` is H B (zero for the input-free variant)."""

    N: np.ndarray
    J: np.ndarray
    H: np.ndarray
    E: np.ndarray
    HB: np.ndarray
    poles: np.ndarray
    residual: float           # ‖NH + JC − HA‖_F / ‖HA‖_F (physical units)
    residual_scaled: float    # the same in scaled coordinates
    fixed_poles: np.ndarray   # modes of N no Z can move (1/s)
    scaling: Scaling

    def discretise(self, dt_s: float, hold: str = "zoh") -> "DiscreteFunctionalObserver":
        """Discretise ``ẇ = N w + [J, HB] [y; u]``.

        ``hold="zoh"``: y and u held over each step (the paper's choice); ``"foh"``: linear
        between samples (exact for inputs linear between samples).
        """
        inputs = np.hstack([self.J, self.HB])
        if hold == "zoh":
            Phi, Gam = zoh(self.N, inputs, dt_s)
            return DiscreteFunctionalObserver(Phi, Gam, np.zeros_like(Gam), self.E, dt_s)
        if hold == "foh":
            Phi, Gam0, Gam1 = foh(self.N, inputs, dt_s)
            return DiscreteFunctionalObserver(Phi, Gam0 - Gam1, Gam1, self.E, dt_s)
        raise ValueError(f"hold must be 'zoh' or 'foh', got {hold!r}")


@dataclass
class DiscreteFunctionalObserver:
    """``w[k+1] = Φ w[k] + Γ_now v[k] + Γ_next v[k+1]``, ``v = [y; u]``, ``ẑ[k] = w[k] + E y[k]``."""

    Phi: np.ndarray
    Gamma_now: np.ndarray
    Gamma_next: np.ndarray
    E: np.ndarray
    dt_s: float

    def run(self, y: np.ndarray, u: np.ndarray | None, z0: np.ndarray) -> np.ndarray:
        """Estimates ``ẑ`` (..., K, p) from measurements y (..., K, q) and inputs u (..., K, m).

        Leading axes are independent runs (batched).  The observer starts from the estimate
        ``ẑ[0] = z0`` (..., p), i.e. ``w[0] = z0 − E y[0]``.  ``u`` may be None when the
        observer needs no input (H B = 0).
        """
        y = np.asarray(y, float)
        m_in = self.Gamma_now.shape[1] - y.shape[-1]
        if u is None:
            u = np.zeros(y.shape[:-1] + (m_in,))
        v = np.concatenate([y, np.broadcast_to(np.asarray(u, float), y.shape[:-1] + (m_in,))],
                           axis=-1)
        lead, K, p = y.shape[:-2], y.shape[-2], self.Phi.shape[0]
        v_t = np.moveaxis(v.reshape((-1, K, v.shape[-1])), 1, 0)          # time-major (K, B, ·)
        drive = v_t[:-1] @ self.Gamma_now.T + v_t[1:] @ self.Gamma_next.T
        w = np.empty((K, drive.shape[1], p))
        w0 = np.asarray(z0, float) - y[..., 0, :] @ self.E.T
        w[0] = np.broadcast_to(w0, lead + (p,)).reshape(-1, p)
        PhiT = self.Phi.T
        for k in range(K - 1):
            np.matmul(w[k], PhiT, out=w[k + 1])
            w[k + 1] += drive[k]
        return np.moveaxis(w, 0, 1).reshape(lead + (K, p)) + y @ self.E.T


def design(A: np.ndarray, B: np.ndarray, C: np.ndarray, L: np.ndarray, alpha_per_s: float,
           beta: float, sector_deg: float | None = None, hb_zero: bool = False) -> FunctionalObserver:
    """Design the observer with every pole in ``α ≤ −Re λ ≤ βα`` (and the sector, if given).

    Parameters
    ----------
    A, B, C, L : ndarray
        Plant (physical units): ``ẋ = A x + B u``, ``y = C x``, ``z = L x``.
    alpha_per_s : float
        Minimum decay rate of the error, 1/s.
    beta : float
        Ratio of the fastest to the slowest allowed decay rate (> 1).
    sector_deg : float, optional
        Half-angle of a damping sector, degrees.
    hb_zero : bool
        Impose ``H B = 0`` (the observer then needs no input u).

    Raises
    ------
    ValueError
        Darouach's condition 1 fails (no observer of this form exists).
    LMIInfeasible
        The pole region is not reachable.
    """
    sc = scaling_for(A, C, L)
    At, Bt, Ct, Lt = sc.apply(A, B, C, L)
    par = parametrise(At, Ct, Lt)
    if par.condition1_residual > 1e-8:
        raise ValueError(f"Darouach condition 1 fails (residual {par.condition1_residual:.2e}): "
                         "L A is not in the row space of [CA; C; L]")
    # LMI on a time axis where the strip is [1/√β, √β]: N' = Ñ / (ω0 τ), ω0 = α √β.
    w0 = alpha_per_s * np.sqrt(beta) * sc.tau_s
    equality = (par.H2 @ Bt, par.H1 @ Bt) if hb_zero else None
    N1, N2 = par.N1, par.N2
    fixed = fixed_modes(N1, N2)
    if hb_zero:   # fixed modes of the constrained family N1' − Y N2'
        U, V = equality
        Up = _pinv(U)
        if np.linalg.norm(V - V @ Up @ U) > 1e-8 * max(np.linalg.norm(V), 1.0):
            raise ValueError("H B = 0 has no solution Z for this system")
        fixed = fixed_modes(N1 - V @ Up @ N2, (np.eye(U.shape[0]) - U @ Up) @ N2)
    if len(fixed) and not in_region(fixed / sc.tau_s, alpha_per_s, beta, sector_deg, rtol=1e-9):
        raise LMIInfeasible(f"fixed poles {np.round(np.sort_complex(fixed / sc.tau_s), 4)} 1/s lie "
                            f"outside the region {alpha_per_s:g} ≤ −Re λ ≤ {beta * alpha_per_s:g}")
    Z, _ = region_gain(N1 / w0, N2 / w0, 1.0 / np.sqrt(beta), beta, sector_deg, equality)
    Ns, Js, Hs, Es = par.matrices(Z)
    Dz, Dy, S, tau = sc.Dz, sc.Dy, sc.S, sc.tau_s
    N = (Ns * Dz[None, :] / Dz[:, None]) / tau
    J = (Js * Dy[None, :] / Dz[:, None]) / tau
    H = Hs / Dz[:, None] / S[None, :]
    E = Es * Dy[None, :] / Dz[:, None]
    HA = H @ A
    residual = np.linalg.norm(N @ H + J @ C - HA) / np.linalg.norm(HA)
    residual_s = np.linalg.norm(Ns @ Hs + Js @ Ct - Hs @ At) / np.linalg.norm(Hs @ At)
    HB = H @ B
    if hb_zero:
        HB = np.zeros_like(HB)
    poles = np.linalg.eigvals(N)
    if not in_region(poles, alpha_per_s, beta, sector_deg, rtol=1e-4):
        raise LMIInfeasible(f"poles {np.sort_complex(poles)} outside the requested region")
    return FunctionalObserver(N=N, J=J, H=H, E=E, HB=HB, poles=poles, residual=float(residual),
                              residual_scaled=float(residual_s), fixed_poles=fixed / tau,
                              scaling=sc)
