"""Paper 003's lateral high-speed vehicle model (§1.1, Eqs. 1–9): 7 DOF, 16 states.

State (paper's order)::

    0 ẏw1  1 yw1  2 ψ̇w1  3 ψw1  4 ẏw2  5 yw2  6 ψ̇w2  7 ψw2
    8 ẏb   9 yb  10 ψ̇b  11 ψb  12 ẏbd 13 ybd 14 d1   15 d2

(m, rad, m/s, rad/s), input ``u = (ẏt1, ẏt2)`` (track lateral velocity under each wheelset,
m/s; the rear one delayed by 2a/V), ``ḋ_j = ẏw_j − ẏt_j`` (Eqs. 8–9, the paper's B has 17
rows — an erratum; here B is 16×2 with −1 in rows d1, d2).

The estimated parameters θ = (Csy, λ, Kpy, Ksy, Csaly) enter A linearly, so
``A(θ) = A0 + Σ_k θ_k A_k`` (:func:`affine_terms`); :func:`build_A_direct` writes the
equations out one by one (the test checks the two agree).  The measurements are the lateral
accelerations of both wheelsets, the bogie and the car body (rows of A, no feed-through since B
only drives d) and the bogie yaw rate: ``H(θ) = S A(θ) + e_ψ̇b`` — also affine.

Fixed quantities (SI units) are the keys of :data:`FIXED_KEYS`: ``mw, mb, mbd`` kg, ``iwz, ib``
kg m², ``kpx`` N/m (as it appears in ``K_px b²``), ``a, b, lbw, l0, r0`` m, ``f11, f22`` N.
"""

from __future__ import annotations

import numba
import numpy as np
from scipy.linalg import expm

from railpaper.discretise import simulate_zoh, zoh
from railpaper.engine import AffineZOH, LinearGaussianBatch, affine_balance, kernel_array

STATE_NAMES = ("vyw1", "yw1", "vpsiw1", "psiw1", "vyw2", "yw2", "vpsiw2", "psiw2",
               "vyb", "yb", "vpsib", "psib", "vybd", "ybd", "d1", "d2")
PARAM_NAMES = ("csy", "lambda", "kpy", "ksy", "csaly")
FIXED_KEYS = ("mw", "iwz", "mb", "ib", "mbd", "kpx", "a", "b", "lbw", "l0", "r0", "f11", "f22")
CHANNELS = ("acc_w1_mps2", "acc_w2_mps2", "acc_b_mps2", "acc_bd_mps2", "yawrate_b_radps")
N_STATES = 16
ACC_ROWS = (0, 4, 8, 12)
YAW_RATE_STATE = 10


def _accelerations(fx: dict, theta, v: float) -> np.ndarray:
    """A written equation by equation (Eqs. 1–9) for one θ; the reference for the affine form."""
    csy, lam, kpy, ksy, csaly = theta
    mw, iwz, mb, ib, mbd = fx["mw"], fx["iwz"], fx["mb"], fx["ib"], fx["mbd"]
    kpx, a, b, lbw, l0, r0 = fx["kpx"], fx["a"], fx["b"], fx["lbw"], fx["l0"], fx["r0"]
    f11, f22 = fx["f11"], fx["f22"]
    A = np.zeros((N_STATES, N_STATES))
    for i in (1, 3, 5, 7, 9, 11, 13):          # displacement' = velocity
        A[i, i - 1] = 1.0
    for w, sgn in ((0, 1.0), (4, -1.0)):        # Eqs. (1)/(3) and (2)/(4)
        A[w, w] = -2 * f22 / v / mw
        A[w, w + 1] = -kpy / mw
        A[w, w + 3] = 2 * f22 / mw
        A[w, 9] = kpy / mw
        A[w, 11] = sgn * kpy * a / mw
        dj = 14 if w == 0 else 15
        A[w + 2, w + 2] = -2 * f11 * l0 ** 2 / v / iwz
        A[w + 2, w + 3] = -kpx * b ** 2 / iwz
        A[w + 2, 11] = kpx * b ** 2 / iwz
        A[w + 2, dj] = -2 * f11 * lam * l0 / r0 / iwz
        A[dj, w] = 1.0                          # Eqs. (8)/(9): d' = ẏw − ẏt
    # Eq. (5): bogie lateral
    A[8, 1] = kpy / mb
    A[8, 5] = kpy / mb
    A[8, 8] = -csy / mb
    A[8, 9] = -(2 * kpy + ksy) / mb
    A[8, 12] = csy / mb
    A[8, 13] = ksy / mb
    # Eq. (6): bogie yaw
    A[10, 1] = a * kpy / ib
    A[10, 3] = kpx * b ** 2 / ib
    A[10, 5] = -a * kpy / ib
    A[10, 7] = kpx * b ** 2 / ib
    A[10, 10] = -csaly * lbw ** 2 / ib
    A[10, 11] = -(2 * a ** 2 * kpy + 2 * kpx * b ** 2) / ib
    # Eq. (7): car body lateral
    A[12, 8] = csy / mbd
    A[12, 9] = ksy / mbd
    A[12, 12] = -csy / mbd
    A[12, 13] = -ksy / mbd
    return A


def build_A_direct(fixed: dict, theta, speed_mps: float) -> np.ndarray:
    """A(θ) (16×16, 1/s) built directly from Eqs. (1)–(9) for one θ = (Csy, λ, Kpy, Ksy, Csaly)."""
    return _accelerations(fixed, np.asarray(theta, float), float(speed_mps))


def affine_terms(fixed: dict, speed_mps: float) -> tuple[np.ndarray, np.ndarray]:
    """``A0`` (16, 16) and ``A_k`` (5, 16, 16) with ``A(θ) = A0 + Σ θ_k A_k``.

    Computed from the direct build by linearity: A0 = A(0), A_k = A(e_k) − A(0).
    """
    A0 = _accelerations(fixed, np.zeros(5), speed_mps)
    Ak = np.stack([_accelerations(fixed, np.eye(5)[k], speed_mps) - A0 for k in range(5)])
    return A0, Ak


def input_matrix() -> np.ndarray:
    """B (16, 2): u = (ẏt1, ẏt2) enters only d1, d2 with −1 (Eqs. 8–9)."""
    B = np.zeros((N_STATES, 2))
    B[14, 0] = B[15, 1] = -1.0
    return B


def measurement_matrix(A: np.ndarray) -> np.ndarray:
    """H (…, 5, 16) from A (…, 16, 16): four lateral accelerations and the bogie yaw rate."""
    A = np.asarray(A, float)
    H = np.zeros(A.shape[:-2] + (5, N_STATES))
    H[..., :4, :] = A[..., ACC_ROWS, :]
    H[..., 4, YAW_RATE_STATE] = 1.0
    return H


def a_of_theta(A0: np.ndarray, Ak: np.ndarray, theta: np.ndarray) -> np.ndarray:
    """A(θ) for θ (N, 5) → (N, 16, 16) by the affine form."""
    theta = np.atleast_2d(theta)
    return A0 + np.einsum("nk,kij->nij", theta, Ak)


def least_damped(A: np.ndarray, zero_tol: float = 1e-6) -> tuple[float, float]:
    """(max real part 1/s, its frequency Hz) of A's eigenvalues, the structural zeros excluded.

    A has two zero eigenvalues (d_j − yw_j is constant without input); they are not modes of
    the vehicle and are left out.
    """
    ev = np.linalg.eigvals(A)
    ev = ev[np.abs(ev) > zero_tol]
    i = int(np.argmax(ev.real))
    return float(ev[i].real), float(abs(ev[i].imag) / (2 * np.pi))


def critical_speed(fixed: dict, theta, speeds_mps: np.ndarray) -> tuple[np.ndarray, float]:
    """Least-damped real part over speeds, and the first speed (m/s) where it crosses 0 (-1: none).

    The crossing is interpolated linearly between grid speeds.
    """
    return first_unstable_speed(lambda v: build_A_direct(fixed, theta, v), speeds_mps)


def first_unstable_speed(matrix_at, speeds_mps: np.ndarray) -> tuple[np.ndarray, float]:
    """:func:`critical_speed` of any system matrix ``matrix_at(speed_mps)``: the least-damped
    real part over ``speeds_mps`` and the first speed (m/s) where it crosses 0 (-1: none),
    interpolated linearly between grid speeds."""
    re = np.array([least_damped(matrix_at(v))[0] for v in speeds_mps])
    above = np.nonzero(re > 0)[0]
    if above.size == 0:
        return re, -1.0
    j = int(above[0])
    if j == 0:
        return re, float(speeds_mps[0])
    v0, v1, r0, r1 = speeds_mps[j - 1], speeds_mps[j], re[j - 1], re[j]
    return re, float(v0 + (v1 - v0) * (-r0) / (r1 - r0))


@numba.njit(fastmath={"contract"}, cache=True)
def _affine_entries(theta, base, terms, entries, out):  # pragma: no cover - compiled
    """``out[i, e] = base[e] + Σ_k θ_ik terms[k, e]`` for the listed entries e (the others are
    left alone): the acceleration rows of H(θ) on their nonzeros, one particle per row of θ.
    The sum runs over k in order from zero: the bits ``θ @ terms`` (OpenBLAS) gave here."""
    N, d = theta.shape
    for i in range(N):
        for t in range(entries.shape[0]):
            e = entries[t]
            v = 0.0
            for k in range(d):
                v += theta[i, k] * terms[k, e]
            out[i, e] = base[e] + v


def lateral_system(fixed: dict, speed_mps: float, dt_s: float, Q: np.ndarray, R: np.ndarray,
                   theta_ref: np.ndarray | None = None):
    """``system(theta (N, 5)) -> LinearGaussianBatch`` for the RBPF (exact ZOH per particle).

    The ZOH is :class:`railpaper.engine.sparse_zoh.AffineZOH` (prepared once per system): Taylor
    on the 45 nonzeros of
    ``[A(θ) dt | B dt]`` formed straight from θ (≈ 5e-16 relative to
    :func:`railpaper.discretise.zoh`'s scipy ``expm``; tests/engine/test_kalman_bank.py and
    tests/engine/test_batch_expm.py check it).  The powers-of-two balancing (an exact similarity: it
    changes only the rounding) is that of ``A(theta_ref)``, fixed when the system is made, so a
    matrix depends on its own θ only — not on the other particles, the order of calls or which
    filter called first; without ``theta_ref`` it is fixed at the first call, from that call's
    first θ.  H(θ) is formed from the same affine terms (four rows of A(θ) and the yaw rate);
    ``system.measurement(theta) -> (H, R)`` gives it without the ZOH.

    Parameters
    ----------
    fixed : dict
        Fixed quantities (:data:`FIXED_KEYS`, SI units).
    speed_mps, dt_s : float
        Vehicle speed, m/s; sample time, s.
    Q, R : ndarray, (16, 16), (5, 5)
        Process- and measurement-noise covariances (state and channel units squared).
    theta_ref : array_like, (5,), optional
        θ whose A(θ) sets the balancing (e.g. the centre of the prior box).
    """
    A0, Ak = affine_terms(fixed, speed_mps)
    B = input_matrix()
    rows = list(ACC_ROWS)
    H0, Hk = A0[rows].ravel(), Ak[:, rows].reshape(len(Ak), -1)  # (64,), (5, 64)
    entries = np.flatnonzero((H0 != 0) | (Hk != 0).any(axis=0))   # 20 of the 64
    prepared = [] if theta_ref is None else [   # the ZOH's pattern and balancing, made once
        AffineZOH(A0, Ak, B, dt_s, affine_balance(theta_ref, A0, Ak, B, dt_s))]

    def measurement(theta: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """H(θ) (N, 5, 16) and R alone, without the ZOH (the Q-GRBPF's update needs only these
        for draws its search may drop)."""
        theta = kernel_array(np.atleast_2d(np.asarray(theta, float)))
        H = np.zeros((len(theta), len(CHANNELS), N_STATES))
        _affine_entries(theta, H0, Hk, entries, H.reshape(len(theta), -1))
        H[:, 4, YAW_RATE_STATE] = 1.0
        return H, R

    def system(theta: np.ndarray) -> LinearGaussianBatch:
        theta = np.atleast_2d(np.asarray(theta, float))
        if not prepared:
            prepared.append(AffineZOH(A0, Ak, B, dt_s, affine_balance(theta[0], A0, Ak, B, dt_s)))
        F, G = prepared[0](theta)
        return LinearGaussianBatch(F, Q, measurement(theta)[0], R, G)

    system.measurement = measurement
    return system


def simulate_truth(fixed: dict, theta, speed_mps: float, dt_fine_s: float, u_fine: np.ndarray,
                   ) -> np.ndarray:
    """States on the fine grid from rest, exact for an input held over each fine step.

    Parameters
    ----------
    fixed : dict
        Fixed quantities (:data:`FIXED_KEYS`, SI units).
    theta : array_like, shape (5,)
        (Csy N s/m, λ, Kpy N/m, Ksy N/m, Csaly N s/m).
    speed_mps : float
        Vehicle speed, m/s.
    dt_fine_s : float
        Fine step, s.
    u_fine : ndarray, shape (K, 2)
        ``u_fine[k-1]`` = (ẏt1, ẏt2), m/s, held over fine step k.

    Returns
    -------
    x : ndarray, shape (K+1, 16)
        ``x[0] = 0`` (rest), ``x[k]`` the state after fine step k (the package's row convention,
        :mod:`railpaper.discretise`).
    """
    A = build_A_direct(fixed, theta, speed_mps)
    F, G = zoh(A, input_matrix(), dt_fine_s)
    return simulate_zoh(F, G, u_fine, np.zeros(N_STATES))


def simulate_truth_with_change(fixed: dict, theta_before, theta_after, change_step: int,
                               speed_mps: float, dt_fine_s: float, u_fine: np.ndarray
                               ) -> np.ndarray:
    """:func:`simulate_truth` with an abrupt parameter change: θ = ``theta_before`` over fine
    steps 1 … ``change_step`` and ``theta_after`` from fine step ``change_step`` + 1 on (a
    failed damper, a softened spring), the state carried across the change.

    Returns ``x`` (K+1, 16) as :func:`simulate_truth`.  A fault that makes the linear model
    unstable at this speed (a lost anti-yaw damper above its critical speed) grows without
    bound; :func:`flange_contact_step` finds where the record must end.
    """
    K = len(u_fine)
    if not 0 <= change_step <= K:
        raise ValueError(f"change_step must lie in 0 … {K} (the record's fine steps), "
                         f"got {change_step}")
    return simulate_truth_schedule(fixed, [theta_before, theta_after], [0, change_step],
                                   speed_mps, dt_fine_s, u_fine)


def simulate_truth_schedule(fixed: dict, thetas, starts, speed_mps: float, dt_fine_s: float,
                            u_fine: np.ndarray) -> np.ndarray:
    """:func:`simulate_truth` with θ piecewise constant: ``thetas[s]`` from fine step
    ``starts[s]`` + 1 on (``starts[0]`` = 0, never decreasing), the state carried across
    every change (a damper failing at once is two pieces; a gradual loss, many).

    Returns ``x`` (K+1, 16) as :func:`simulate_truth`.
    """
    K = len(u_fine)
    starts = [int(s) for s in starts]
    if len(starts) != len(thetas) or not starts or starts[0] != 0 \
            or any(b < a for a, b in zip(starts, starts[1:])) or starts[-1] > K:
        raise ValueError(f"starts must begin at 0 and not decrease up to {K}, one per theta; "
                         f"got {starts}")
    ends = starts[1:] + [K]
    pieces = [simulate_truth(fixed, thetas[0], speed_mps, dt_fine_s, u_fine[:ends[0]])]
    for theta, a, b in zip(thetas[1:], starts[1:], ends[1:]):
        F, G = zoh(build_A_direct(fixed, theta, speed_mps), input_matrix(), dt_fine_s)
        pieces.append(simulate_zoh(F, G, u_fine[a:b], pieces[-1][-1])[1:])
    return np.vstack(pieces)


def flange_contact_step(x: np.ndarray, clearance_m: float) -> int:
    """First row of states ``x`` (K+1, 16) at which either wheelset's lateral displacement
    relative to the track (``d1``, ``d2`` = yw − yt) reaches ``clearance_m`` (m; the flangeway
    clearance, beyond which the linear model without flange contact no longer holds); −1 if
    none."""
    if not clearance_m > 0:
        raise ValueError(f"clearance_m must be > 0, got {clearance_m}")
    lateral = np.abs(x[:, [STATE_NAMES.index("d1"), STATE_NAMES.index("d2")]])
    hits = np.flatnonzero((lateral >= clearance_m).any(axis=1))
    return int(hits[0]) if hits.size else -1


def ekf_model(fixed: dict, speed_mps: float, dt_s: float):
    """``model(theta (5,)) -> (F, G, H, dF, dG, dH)`` for the augmented EKF.

    F, G are the exact ZOH of A(θ), B; their derivatives along each A_k are the upper-right
    blocks of ``expm([[M, M_k], [0, M]])`` (Van Loan), M = [[A, B], [0, 0]] dt.
    """
    A0, Ak = affine_terms(fixed, speed_mps)
    B = input_matrix()
    n, m = N_STATES, B.shape[1]
    Hk = measurement_matrix(Ak)
    Hk[:, 4, YAW_RATE_STATE] = 0.0                  # the yaw-rate row does not depend on θ

    def model(theta):
        A = a_of_theta(A0, Ak, theta)[0]
        M = np.zeros((n + m, n + m))
        M[:n, :n], M[:n, n:] = A * dt_s, B * dt_s
        big = np.zeros((5, 2 * (n + m), 2 * (n + m)))
        big[:, :n + m, :n + m] = M
        big[:, n + m:, n + m:] = M
        big[:, :n, n + m:n + m + n] = Ak * dt_s
        E = expm(big)
        F, G = E[0, :n, :n], E[0, :n, n:n + m]
        dE = E[:, :n + m, n + m:]
        return F, G, measurement_matrix(A), dE[:, :n, :n], dE[:, :n, n:n + m], Hk

    return model
