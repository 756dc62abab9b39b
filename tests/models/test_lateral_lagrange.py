"""Paper 003's lateral model A(θ) against an independent assembly from Lagrange's equations.

The reference never looks at the model's rows and columns: it writes the vehicle's kinetic
energy T, potential energy V and dissipation function D as scalar functions of the seven
coordinates q = (y_w1, ψ_w1, y_w2, ψ_w2, y_b, ψ_b, y_bd), the wheel-rail creep forces from their
creepages (Kalker's linear theory as in the paper: lateral ξ_y = ẏ/v − ψ, longitudinal
ξ_x = l0 ψ̇/v + λ d/r0), differentiates T, V, D numerically (central differences), and solves
``M q̈ = −∂V/∂q − ∂D/∂q̇ + Q_creep`` for every unit state; ḋ_j = ẏ_wj (Eqs. 8–9).  Stiffness and
damping constants are the paper's effective ones (its Eqs. 1–7 use K_px b² and C_saly L_bw² per
wheelset / bogie), the geometry that of Fig. 1: the front wheelset a ahead of the bogie centre.

Checked at the true θ and at two random θ in the chapter's prior box, at two speeds, both the
direct build and the affine form the filters use; every single entry of A flipped in sign or
scaled by 1.01 is caught by the same comparison.
"""

import numpy as np
import pytest

from railpaper.experiments.rbpf_parameter_estimation import experiment
from railpaper.experiments.rbpf_parameter_estimation import lateral as study
from railpaper.models import lateral_16state

FIXED, THETA = study.vehicle()
PRIOR = experiment.SPEC.resolve({}, False)

#: The paper's state vector X(t), typed from its text (before Eq. 10).
PAPER_STATE = ("vyw1", "yw1", "vpsiw1", "psiw1", "vyw2", "yw2", "vpsiw2", "psiw2",
               "vyb", "yb", "vpsib", "psib", "vybd", "ybd", "d1", "d2")
COORDS = ("yw1", "psiw1", "yw2", "psiw2", "yb", "psib", "ybd")


def energies(fx: dict, theta, v: float):
    """T(q̇), V(q), D(q̇) and the creep forces Q(q, q̇, d) of the 7-DOF vehicle (SI units)."""
    csy, lam, kpy, ksy, csaly = theta
    mw, iwz, mb, ib, mbd = (fx[k] for k in ("mw", "iwz", "mb", "ib", "mbd"))
    kpx, a, b, lbw, l0, r0 = (fx[k] for k in ("kpx", "a", "b", "lbw", "l0", "r0"))
    f11, f22 = fx["f11"], fx["f22"]

    def T(qd):
        vyw1, vpw1, vyw2, vpw2, vyb, vpb, vybd = qd
        return 0.5 * (mw * vyw1 ** 2 + iwz * vpw1 ** 2 + mw * vyw2 ** 2 + iwz * vpw2 ** 2
                      + mb * vyb ** 2 + ib * vpb ** 2 + mbd * vybd ** 2)

    def V(q):
        yw1, pw1, yw2, pw2, yb, pb, ybd = q
        return 0.5 * (kpy * (yw1 - (yb + a * pb)) ** 2        # front primary lateral
                      + kpy * (yw2 - (yb - a * pb)) ** 2      # rear primary lateral
                      + kpx * b ** 2 * (pw1 - pb) ** 2        # primary longitudinal (yaw)
                      + kpx * b ** 2 * (pw2 - pb) ** 2
                      + ksy * (yb - ybd) ** 2)                # secondary lateral

    def D(qd):
        vyw1, vpw1, vyw2, vpw2, vyb, vpb, vybd = qd
        return 0.5 * (csy * (vyb - vybd) ** 2 + csaly * lbw ** 2 * vpb ** 2)

    def creep(q, qd, d):
        Q = np.zeros(7)
        for j, (iy, ip) in enumerate(((0, 1), (2, 3))):
            xi_y = qd[iy] / v - q[ip]                         # lateral creepage
            xi_x = l0 * qd[ip] / v + lam * d[j] / r0          # longitudinal (both wheels)
            Q[iy] = -2 * f22 * xi_y
            Q[ip] = -2 * f11 * l0 * xi_x
        return Q

    return T, V, D, creep


def gradient(f, z, h=1.0):
    """Central-difference gradient (exact up to rounding for a quadratic f)."""
    g = np.zeros(len(z))
    for i in range(len(z)):
        e = np.zeros(len(z))
        e[i] = h
        g[i] = (f(z + e) - f(z - e)) / (2 * h)
    return g


def hessian(f, n, h=1.0):
    """Central-difference Hessian at 0 (exact up to rounding for a quadratic f)."""
    H = np.zeros((n, n))
    eye = h * np.eye(n)
    for i in range(n):
        for j in range(n):
            H[i, j] = (f(eye[i] + eye[j]) - f(eye[i] - eye[j]) - f(-eye[i] + eye[j])
                       + f(-eye[i] - eye[j])) / (4 * h * h)
    return H


def lagrange_A(fx: dict, theta, v: float) -> np.ndarray:
    """A (16×16) in the paper's state order, column j = Ẋ for X = e_j."""
    T, V, D, creep = energies(fx, theta, v)
    M = hessian(T, 7)
    A = np.zeros((16, 16))
    for j in range(16):
        X = dict(zip(PAPER_STATE, np.eye(16)[j]))
        q = np.array([X[c] for c in COORDS])
        qd = np.array([X["v" + c] for c in COORDS])
        d = np.array([X["d1"], X["d2"]])
        qdd = np.linalg.solve(M, -gradient(V, q) - gradient(D, qd) + creep(q, qd, d))
        Xd = {"d1": qd[0], "d2": qd[2]}                      # Eqs. (8)-(9) without input
        for c, acc, vel in zip(COORDS, qdd, qd):
            Xd["v" + c], Xd[c] = acc, vel
        A[:, j] = [Xd[s] for s in PAPER_STATE]
    return A


def mismatch(A: np.ndarray, ref: np.ndarray, rtol: float = 1e-9) -> list[tuple[int, int]]:
    """Entries where A differs from ref by more than rtol of the entry (or 1e-13 of its row)."""
    row = np.abs(ref).max(axis=1, keepdims=True)
    bad = np.abs(A - ref) > rtol * np.abs(ref) + 1e-13 * row
    return [tuple(ij) for ij in np.argwhere(bad)]


def thetas():
    rng = np.random.default_rng(2024)
    box = rng.uniform(PRIOR.prior_low, PRIOR.prior_high, (2, 5))
    return [THETA, THETA * box[0], THETA * box[1]]


@pytest.mark.parametrize("speed_kmh", [300.0, 200.0])
@pytest.mark.parametrize("which", [0, 1, 2])
def test_A_equals_lagrange_assembly(speed_kmh, which):
    assert lateral_16state.STATE_NAMES == PAPER_STATE
    v, theta = speed_kmh / 3.6, thetas()[which]
    ref = lagrange_A(FIXED, theta, v)
    assert mismatch(lateral_16state.build_A_direct(FIXED, theta, v), ref) == []
    A0, Ak = lateral_16state.affine_terms(FIXED, v)
    assert mismatch(lateral_16state.a_of_theta(A0, Ak, theta)[0], ref) == []
    H = lateral_16state.measurement_matrix(lateral_16state.build_A_direct(FIXED, theta, v))
    acc_rows = [PAPER_STATE.index(s) for s in ("vyw1", "vyw2", "vyb", "vybd")]
    np.testing.assert_allclose(H[:4], ref[acc_rows], rtol=1e-9, atol=1e-13 * np.abs(ref).max())
    assert H[4].tolist() == np.eye(16)[PAPER_STATE.index("vpsib")].tolist()


def test_B_is_minus_track_velocity_into_d():
    B = np.zeros((16, 2))
    B[PAPER_STATE.index("d1"), 0] = B[PAPER_STATE.index("d2"), 1] = -1.0   # Eqs. (8)-(9)
    assert lateral_16state.input_matrix().tolist() == B.tolist()


def test_every_wrong_sign_or_factor_is_caught():
    """The comparison is sharp: flip any one nonzero entry, or scale it by 1.01 -> mismatch."""
    v = 300 / 3.6
    A = lateral_16state.build_A_direct(FIXED, THETA, v)
    ref = lagrange_A(FIXED, THETA, v)
    entries = np.argwhere(A != 0)
    assert len(entries) == 43
    for i, j in entries:
        for factor in (-1.0, 1.01):
            wrong = A.copy()
            wrong[i, j] *= factor
            assert mismatch(wrong, ref) == [(i, j)]
    for i, j in np.argwhere(A == 0)[:: 7]:             # a spurious entry is caught too
        wrong = A.copy()
        wrong[i, j] = 1e-6 * np.abs(A[i]).max()
        assert mismatch(wrong, ref) == [(i, j)]
