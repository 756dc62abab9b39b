"""Lateral 16-state model (paper 003, Eqs. 1-9) and the Kalman-likelihood CRLB."""

import numpy as np
import pytest
from filterpy.kalman import KalmanFilter
from scipy.integrate import solve_ivp
from scipy.linalg import expm

from railpaper.data import load_quantities
from railpaper.discretise import zoh
from railpaper.engine import LinearGaussianBatch, crlb_std, fisher_information, run_rbpf
from railpaper.models import lateral_16state
from railpaper.paths import DATA_DIR

PARAMS = load_quantities(DATA_DIR / "rbpf-parameter-estimation" / "parameters.toml")
FIXED = {k: PARAMS[k].value for k in lateral_16state.FIXED_KEYS}
THETA = np.array([PARAMS[k].value for k in lateral_16state.PARAM_NAMES])
V = 300 / 3.6


def test_affine_equals_direct_build():
    A0, Ak = lateral_16state.affine_terms(FIXED, V)
    rng = np.random.default_rng(0)
    thetas = THETA * rng.uniform(0.3, 2.0, (6, 5))
    affine = lateral_16state.a_of_theta(A0, Ak, thetas)
    for t, A in zip(thetas, affine):
        np.testing.assert_allclose(A, lateral_16state.build_A_direct(FIXED, t, V),
                                   rtol=1e-9, atol=1e-9)


def test_equations_by_hand():
    A = lateral_16state.build_A_direct(FIXED, THETA, V)
    csy, lam, kpy, ksy, csaly = THETA
    # Eq. (2): yaw of the front wheelset, coefficient of d1
    assert A[2, 14] == pytest.approx(-2 * FIXED["f11"] * lam * FIXED["l0"] / FIXED["r0"]
                                     / FIXED["iwz"])
    # Eq. (7): body lateral
    assert A[12, 9] == pytest.approx(ksy / FIXED["mbd"])
    # Eq. (6): yaw damping
    assert A[10, 10] == pytest.approx(-csaly * FIXED["lbw"] ** 2 / FIXED["ib"])
    # structural zeros: exactly two eigenvalues at 0 (d_j - yw_j constant)
    ev = np.linalg.eigvals(A)
    assert np.sum(np.abs(ev) < 1e-6) == 2


def test_zoh_matches_scipy_and_stable_at_300():
    A = lateral_16state.build_A_direct(FIXED, THETA, V)
    B = lateral_16state.input_matrix()
    F, G = zoh(A, B, 1e-3)
    M = np.zeros((18, 18))
    M[:16, :16], M[:16, 16:] = A, B
    E = expm(M * 1e-3)
    np.testing.assert_allclose(F, E[:16, :16], atol=1e-13)
    np.testing.assert_allclose(G, E[:16, 16:], atol=1e-13)
    assert lateral_16state.least_damped(A)[0] < 0


def test_rbpf_at_truth_equals_filterpy_kalman():
    """Parameters fixed at the truth, no move: every particle's KF equals filterpy's KF."""
    rng = np.random.default_rng(1)
    Q = 1e-10 * np.eye(16)
    R = np.diag([0.1, 0.1, 0.1, 0.01, 0.001]) ** 2
    system = lateral_16state.lateral_system(FIXED, V, 1e-3, Q, R)
    s = system(THETA[None])
    K = 60
    u = rng.standard_normal((K, 2)) * 0.04
    x = np.zeros(16)
    y = np.zeros((K, 5))
    for k in range(K):
        x = s.F[0] @ x + s.B[0] @ u[k]
        y[k] = s.H[0] @ x + rng.standard_normal(5) * np.sqrt(np.diag(R))
    run = run_rbpf(system, y, np.repeat(THETA[None], 3, axis=0), np.zeros(16), 1e-8 * np.eye(16),
                   np.random.default_rng(2), u=u, scheme="paper", move=False)
    kf = KalmanFilter(dim_x=16, dim_z=5, dim_u=2)
    kf.x, kf.P, kf.F, kf.B, kf.H, kf.Q, kf.R = (np.zeros((16, 1)), 1e-8 * np.eye(16), s.F[0],
                                               s.B[0], s.H[0], Q, R)
    for k in range(K):
        kf.predict(u=u[k][:, None])
        kf.update(y[k][:, None])
        np.testing.assert_allclose(run.x_mean[k], kf.x[:, 0], rtol=1e-10, atol=1e-10)


def test_crlb_matches_closed_form_ar1():
    """AR(1) x_k = a x_{k-1} + w observed almost exactly: I(a) = Σ y_{k-1}² / q."""
    a, q, K = 0.7, 0.5, 2000
    rng = np.random.default_rng(4)
    x = np.zeros(K + 1)
    for k in range(K):
        x[k + 1] = a * x[k] + np.sqrt(q) * rng.standard_normal()
    y = x[1:, None]

    def system(theta):
        return LinearGaussianBatch(np.atleast_2d(theta)[:, :, None], np.array([[q]]),
                                   np.array([[1.0]]), np.array([[1e-10]]))

    info = fisher_information(system, np.array([a]), y, np.zeros(1), np.array([[1e-10]]))[K]
    closed = np.sum(x[:K] ** 2) / q           # x_0 = 0 enters with weight 0
    assert info[0, 0] == pytest.approx(closed, rel=1e-4)
    assert crlb_std(info)[0] == pytest.approx(1 / np.sqrt(closed), rel=1e-4)


def test_ekf_model_derivatives_match_finite_differences():
    model = lateral_16state.ekf_model(FIXED, V, 1e-3)
    F, G, H, dF, dG, dH = model(THETA)
    for k in (0, 2, 4):
        h = 1e-6 * THETA[k]
        tp, tm = THETA.copy(), THETA.copy()
        tp[k] += h
        tm[k] -= h
        Fp, Gp, Hp, *_ = model(tp)
        Fm, Gm, Hm, *_ = model(tm)
        np.testing.assert_allclose(dF[k], (Fp - Fm) / (2 * h), rtol=1e-4, atol=1e-10)
        np.testing.assert_allclose(dG[k], (Gp - Gm) / (2 * h), rtol=1e-4, atol=1e-12)
        np.testing.assert_allclose(dH[k], (Hp - Hm) / (2 * h), rtol=1e-5, atol=1e-9)


def test_lateral_measurement_alone_is_the_systems_H_and_R():
    """``system.measurement(θ)`` (what the Q-GRBPF's update reads before its search) is, bit
    for bit, the H and R of ``system(θ)``, and H's acceleration rows are those of A(θ) from
    :func:`railpaper.models.lateral_16state.measurement_matrix`."""
    R = np.diag([0.1, 0.1, 0.1, 0.01, 0.001]) ** 2
    system = lateral_16state.lateral_system(FIXED, V, 1e-3, 1e-10 * np.eye(16), R)
    theta = THETA * np.random.default_rng(4).uniform(0.5, 1.7, (7, 5))
    H, R_alone = system.measurement(theta)
    s = system(theta)
    assert np.array_equal(H, s.H) and np.array_equal(R_alone, s.R)
    A0, Ak = lateral_16state.affine_terms(FIXED, V)
    np.testing.assert_allclose(
        H, lateral_16state.measurement_matrix(lateral_16state.a_of_theta(A0, Ak, theta)),
        rtol=1e-13, atol=1e-13)


def test_truth_with_change_equals_the_switching_ode_integrated_by_scipy():
    """A failed anti-yaw damper (Csaly × 0) at fine step 300 of 600: the states equal the
    continuous model dx/dt = A(θ(t)) x + B u(t), u held over each fine step and A switching at
    the change, integrated by scipy's solve_ivp (an independent reference, not the ZOH);
    with θ_after = θ_before the record is simulate_truth's, bit for bit."""
    dt, K, c = 1e-4, 600, 300
    u = 0.02 * np.random.default_rng(6).standard_normal((K, 2))
    after = THETA.copy()
    after[lateral_16state.PARAM_NAMES.index("csaly")] = 0.0
    x = lateral_16state.simulate_truth_with_change(FIXED, THETA, after, c, V, dt, u)
    A0, A1 = (lateral_16state.build_A_direct(FIXED, th, V) for th in (THETA, after))
    Bc = lateral_16state.input_matrix()
    state = np.zeros(16)
    for k in range(K):
        A = A0 if k < c else A1
        state = solve_ivp(lambda t, s: A @ s + Bc @ u[k], (0.0, dt), state, method="DOP853",
                          rtol=1e-11, atol=1e-16).y[:, -1]
        if k + 1 in (c, c + 1, K):
            np.testing.assert_allclose(x[k + 1], state, rtol=1e-7, atol=1e-13)
    same = lateral_16state.simulate_truth_with_change(FIXED, THETA, THETA, c, V, dt, u)
    assert np.array_equal(same, lateral_16state.simulate_truth(FIXED, THETA, V, dt, u))


def test_flange_contact_step_reads_the_relative_displacements():
    x = np.zeros((6, 16))
    x[3, lateral_16state.STATE_NAMES.index("d2")] = -0.008
    x[4, lateral_16state.STATE_NAMES.index("yw1")] = 0.02   # absolute, not relative to the track
    assert lateral_16state.flange_contact_step(x, 0.008) == 3
    assert lateral_16state.flange_contact_step(x, 0.009) == -1
    with pytest.raises(ValueError, match="clearance_m"):
        lateral_16state.flange_contact_step(x, 0.0)
    with pytest.raises(ValueError, match="change_step"):
        lateral_16state.simulate_truth_with_change(FIXED, THETA, THETA, 7, V, 1e-4,
                                                   np.zeros((5, 2)))
