"""Observer-gain LMIs with pole-region constraints (Chilali & Gahinet 1996), solved by cvxpy.

For a pair ``(N1, N2)`` find ``Z`` such that every eigenvalue of ``N = N1 − Z N2`` lies in

    D = {λ : α ≤ −Re λ ≤ β α}  (∩ optionally the sector |Im λ| ≤ tan θ · (−Re λ)),

via ``P = Pᵀ ≽ I`` and ``G = P Z``:

    sym(P N1 − G N2) + 2 α P ≺ 0          (Re λ < −α, the decay-rate LMI)
    sym(P N1 − G N2) + 2 β α P ≻ 0        (Re λ > −β α)
    [[sin θ (M + Mᵀ), cos θ (M − Mᵀ)], [cos θ (Mᵀ − M), sin θ (M + Mᵀ)]] ≺ 0,  M = P N1 − G N2

with a common P (a sufficient condition for the intersection of LMI regions).  Optional linear
equality constraints ``G U = P V`` express ``Z U = V`` (e.g. H B = 0).
"""

from __future__ import annotations

import warnings

import numpy as np


class LMIInfeasible(RuntimeError):
    """The LMI has no solution (the requested pole region is not reachable)."""


def _sym(X):
    return X + X.T


def region_gain(N1: np.ndarray, N2: np.ndarray, alpha: float, beta: float,
                sector_deg: float | None = None, equality: tuple | None = None,
                margin: float = 1e-6) -> tuple[np.ndarray, np.ndarray]:
    """Solve the pole-region LMI for Z (``N = N1 − Z N2``), minimising ``‖G‖_F``.

    Parameters
    ----------
    N1 : ndarray, shape (p, p)
    N2 : ndarray, shape (r, p)
    alpha : float
        Minimum decay rate (same time unit as N1), > 0.
    beta : float
        Ratio of the fastest to the slowest allowed decay rate, > 1.
    sector_deg : float, optional
        Half-angle θ of the conic sector around the negative real axis, degrees.
    equality : (U, V), optional
        Linear constraint ``Z U = V`` imposed as ``G U = P V``.
    margin : float
        Strictness margin of the matrix inequalities (they are well scaled when α ~ 1).

    An ``optimal_inaccurate`` solver status is accepted: callers check the resulting poles
    (:func:`in_region`).

    Returns
    -------
    Z : ndarray, shape (p, r)
    P : ndarray, shape (p, p)

    Raises
    ------
    LMIInfeasible
    """
    import cvxpy as cp

    if not alpha > 0 or not beta > 1:
        raise ValueError(f"need alpha > 0 and beta > 1, got alpha={alpha!r}, beta={beta!r}")
    p, r = N1.shape[0], N2.shape[0]
    P = cp.Variable((p, p), symmetric=True)
    G = cp.Variable((p, r))
    M = P @ N1 - G @ N2
    eye = np.eye(p)
    cons = [P >> eye,
            _sym(M) + 2 * alpha * P << -margin * eye,
            _sym(M) + 2 * beta * alpha * P >> margin * eye]
    if sector_deg is not None:
        th = np.deg2rad(sector_deg)
        block = cp.bmat([[np.sin(th) * _sym(M), np.cos(th) * (M - M.T)],
                         [np.cos(th) * (M.T - M), np.sin(th) * _sym(M)]])
        cons.append(0.5 * (block + block.T) << -margin * np.eye(2 * p))
    if equality is not None:
        U, V = equality
        cons.append(G @ U == P @ V)
    problem = cp.Problem(cp.Minimize(cp.norm(G, "fro") + 1e-3 * cp.trace(P)), cons)
    try:
        with warnings.catch_warnings():   # "inaccurate" is reported through the status below
            warnings.simplefilter("ignore", UserWarning)
            problem.solve(solver=cp.CLARABEL)
    except cp.error.SolverError as exc:  # numerical failure: treat as infeasible, say so
        raise LMIInfeasible(f"solver failed: {exc}") from None
    if problem.status not in (cp.OPTIMAL, cp.OPTIMAL_INACCURATE) or P.value is None:
        raise LMIInfeasible(f"LMI status '{problem.status}'")
    Pv = 0.5 * (P.value + P.value.T)
    Z = np.linalg.solve(Pv, G.value)
    return Z, Pv


def in_region(poles: np.ndarray, alpha: float, beta: float, sector_deg: float | None = None,
              rtol: float = 1e-6) -> bool:
    """True when every pole satisfies α ≤ −Re λ ≤ βα (and the sector), up to ``rtol``."""
    rate = -np.real(poles)
    ok = np.all(rate >= alpha * (1 - rtol)) and np.all(rate <= beta * alpha * (1 + rtol))
    if sector_deg is not None:
        ok = ok and np.all(np.abs(np.imag(poles)) <= np.tan(np.deg2rad(sector_deg)) * rate
                           * (1 + rtol) + 1e-12)
    return bool(ok)
