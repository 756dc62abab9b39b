"""Functional observer (Darouach 2000), pole-region LMI and the Kalman baseline."""

import control
import numpy as np
import pytest
from scipy import integrate, signal
from scipy.linalg import expm

from railpaper.estimators import functional_observer
from railpaper.estimators import kalman_baseline as kb
from railpaper.estimators.lmi_region import LMIInfeasible, in_region, region_gain
from railpaper.models import vertical_10dof


@pytest.fixture(scope="module")
def model():
    return vertical_10dof.build_model(vertical_10dof.load_parameters())


@pytest.fixture(scope="module")
def paper_observer(model):
    return functional_observer.design(model.A, model.B, model.output_matrix("both"), model.L,
                                      10.0, 2.0)


def test_existence_rank_table(model):
    expected = {"displacements": (16, 20, False), "accelerations": (16, 20, False),
                "both": (20, 20, True)}
    for name, (r_base, r_ext, ok) in expected.items():
        ex = functional_observer.existence(model.A, model.output_matrix(name), model.L)
        assert (ex["rank_CA_C_L"], ex["rank_LA_CA_C_L"], ex["exists"]) == (r_base, r_ext, ok)
    assert functional_observer.existence(model.A, model.output_matrix("both"),
                                         model.L)["condition2"]


def test_condition2_fails_on_hidden_unstable_mode():
    """z = x1 with x1 unstable and invisible in y: condition 1 holds, 2 fails at s = 1."""
    A = np.diag([1.0, -1.0, -2.0])
    C = np.array([[0.0, 1.0, 0.0]])
    L = np.array([[1.0, 0.0, 0.0]])
    ex = functional_observer.existence(A, C, L)
    assert ex["condition1"] and not ex["condition2"]
    np.testing.assert_allclose(ex["pencil_zeros"], [1.0], atol=1e-9)
    with pytest.raises(LMIInfeasible):
        functional_observer.design(A, np.zeros((3, 1)), C, L, 1.0, 3.0)


def test_observer_identities(model, paper_observer):
    ob, C, A, L = paper_observer, model.output_matrix("both"), model.A, model.L
    assert ob.residual < 1e-10 and ob.residual_scaled < 1e-10
    HA = ob.H @ A
    np.testing.assert_allclose(ob.N @ ob.H + ob.J @ C, HA, atol=1e-9 * np.abs(HA).max())
    np.testing.assert_allclose(ob.H, L - ob.E @ C, atol=1e-12)
    assert in_region(ob.poles, 10.0, 2.0, rtol=1e-5)
    np.testing.assert_allclose(np.sort(np.linalg.eigvals(ob.N).real), np.sort(ob.poles.real))


def test_random_systems_design():
    rng = np.random.default_rng(3)
    for _ in range(5):
        n = 6
        A = rng.standard_normal((n, n)) - 3 * np.eye(n)
        C = rng.standard_normal((4, n))
        L = rng.standard_normal((2, n))
        ob = functional_observer.design(A, rng.standard_normal((n, 1)), C, L, 2.0, 3.0)
        assert ob.residual < 1e-9
        assert in_region(ob.poles, 2.0, 3.0, rtol=1e-5)


def test_noise_free_error_follows_expm(model):
    """Joint plant + observer, simulated exactly (scipy lsim, input linear between samples):
    ε(t) = ẑ − z equals e^{N t} ε(0) from any initial state."""
    C = model.output_matrix("both")
    ob = functional_observer.design(model.A, model.B, C, model.L, 10.0, 2.0)
    n, p = 20, 4
    Aj = np.block([[model.A, np.zeros((n, p))], [ob.J @ C, ob.N]])
    Bj = np.vstack([model.B, ob.HB])
    Cj = np.hstack([ob.E @ C - model.L, np.eye(p)])            # ε = w + E C x − L x
    t = np.arange(0, 0.4, 1e-3)
    rng = np.random.default_rng(0)
    q = 1e-3 * np.sin(2 * np.pi * 2.0 * t[:, None] + rng.uniform(0, 6, 4))
    sysj = (Aj, Bj, Cj, np.zeros((p, 4)))
    for _ in range(3):                                       # several initial states
        x0 = -np.linalg.solve(model.A, model.B @ q[0]) + 1e-4 * rng.standard_normal(n)
        w0 = rng.standard_normal(p) * 1e-3
        _, eps, _ = signal.lsim(sysj, q, t, np.concatenate([x0, w0]), interp=True)
        eps0 = eps[0]
        expected = np.array([expm(ob.N * tk) @ eps0 for tk in t[::50]])
        np.testing.assert_allclose(eps[::50], expected, atol=1e-6 * np.abs(eps0).max())
        # at least the designed decay rate α = 10 1/s (transient factor ≤ 10)
        norms = np.linalg.norm(eps, axis=1)
        assert np.all(norms <= 10 * np.exp(-10.0 * t) * norms[0] + 1e-12)


def test_discrete_observer_matches_lsim_and_hold(model):
    C = model.output_matrix("both")
    ob = functional_observer.design(model.A, model.B, C, model.L, 10.0, 2.0)
    d = ob.discretise(1e-3, "zoh")
    Phi, Gam, *_ = signal.cont2discrete((ob.N, np.hstack([ob.J, ob.HB]), np.eye(4),
                                         np.zeros((4, 16))), 1e-3, method="zoh")
    np.testing.assert_allclose(d.Phi, Phi, rtol=1e-10, atol=1e-14)
    np.testing.assert_allclose(d.Gamma_now, Gam, rtol=1e-8, atol=1e-12 * np.abs(Gam).max())
    # batched run == single runs
    rng = np.random.default_rng(1)
    y = rng.standard_normal((2, 50, 12))
    u = rng.standard_normal((2, 50, 4))
    z0 = rng.standard_normal((2, 4))
    both = d.run(y, u, z0)
    np.testing.assert_allclose(both[1], d.run(y[1], u[1], z0[1]))
    np.testing.assert_allclose(both[0, 0], z0[0])
    with pytest.raises(ValueError):
        ob.discretise(1e-3, "tustin")


def test_hb_zero_variant_poles_fixed_at_primary_corner(model):
    """Without the track input, N has four fixed poles at −K_p/C_p (bogie-wheelset damper corner)."""
    v = model.parameters
    corner = -v.primary_stiffness_N_per_m / v.primary_damping_Ns_per_m
    C = model.output_matrix("both")
    ob = functional_observer.design(model.A, model.B, C, model.L, -corner / np.sqrt(2), 2.0,
                                    hb_zero=True)
    np.testing.assert_allclose(ob.fixed_poles.real, corner, rtol=1e-6)
    np.testing.assert_allclose(ob.poles.real, corner, rtol=1e-5)
    assert ob.residual < 1e-10
    HB = (model.L - ob.E @ C) @ model.B
    assert np.abs(HB).max() < 1e-9 * np.abs(paper_hb(model)).max()
    with pytest.raises(LMIInfeasible):          # a region that excludes the corner
        functional_observer.design(model.A, model.B, C, model.L, -2 * corner, 2.0, hb_zero=True)


def paper_hb(model):
    ob = functional_observer.design(model.A, model.B, model.output_matrix("both"), model.L, 10.0,
                                    2.0)
    return ob.HB


def test_region_lmi_infeasible_for_unobservable_mode():
    N1 = np.diag([-1.0, -3.0])
    N2 = np.array([[0.0, 1.0]])                  # the −1 mode cannot be moved
    Z, _ = region_gain(N1, N2, 0.5, 4.0)         # region [0.5, 2] holds −1: feasible
    assert in_region(np.linalg.eigvals(N1 - Z @ N2), 0.5, 4.0, rtol=1e-6)
    with pytest.raises(LMIInfeasible):
        region_gain(N1, N2, 2.0, 2.0)            # region [2, 4] does not
    with pytest.raises(ValueError):
        region_gain(N1, N2, 1.0, 1.0)


def test_region_lmi_sector():
    rng = np.random.default_rng(5)
    N1 = rng.standard_normal((3, 3))
    N2 = rng.standard_normal((2, 3))
    Z, _ = region_gain(N1, N2, 1.0, 5.0, sector_deg=30.0)
    assert in_region(np.linalg.eigvals(N1 - Z @ N2), 1.0, 5.0, sector_deg=30.0, rtol=1e-6)


def test_shaping_filter_fit_to_fra5():
    """The FRA class-5 vertical PSD (one-sided, cm² → m²) at 30 m/s: the fit recovers the
    high-frequency corner V Ω_c and the spectrum inside the band."""
    k, Av, Oc, V = 0.25, 0.2095e-4, 0.8245, 30.0
    S = lambda Om: k * Av * Oc**2 / (Om**2 * (Om**2 + Oc**2))  # noqa: E731
    Om = np.logspace(np.log10(2 * np.pi / 304.8), np.log10(2 * np.pi / 1.524), 200)
    w, St = Om * V, S(Om) / V
    var, _ = integrate.quad(S, Om[0], Om[-1], limit=200)
    f = kb.fit_shaping_filter(w, St, var)
    assert f.b == pytest.approx(V * Oc, rel=0.1)
    assert f.variance() == pytest.approx(var, rel=0.05)
    mid = (Om > 10 * Om[0]) & (Om < Om[-1] / 2)
    ratio = f.psd(w[mid]) / St[mid]
    assert np.all((ratio > 0.7) & (ratio < 1.3))
    # high-frequency asymptote: g²/π = k A Ω_c² V³
    assert f.gain**2 / np.pi == pytest.approx(k * Av * Oc**2 * V**3, rel=0.15)


def test_van_loan_noise_matches_quadrature():
    A = np.array([[0.0, 1.0], [-4.0, -0.5]])
    G = np.array([[0.0], [2.0]])
    Phi, Qd = kb.discretise_noise(A, G, np.eye(1), 0.1)
    integrand = lambda s: (expm(A * s) @ G @ G.T @ expm(A.T * s)).ravel()  # noqa: E731
    ref = integrate.quad_vec(integrand, 0.0, 0.1)[0].reshape(2, 2)
    np.testing.assert_allclose(Qd, ref, rtol=1e-9)
    np.testing.assert_allclose(Phi, expm(A * 0.1))


def test_steady_state_kalman_matches_python_control():
    rng = np.random.default_rng(2)
    A = np.array([[0.9, 0.2, 0.0], [-0.1, 0.8, 0.1], [0.0, 0.0, 0.95]])
    C = rng.standard_normal((2, 3))
    Q = np.diag([1e-2, 1e-3, 1e-4])
    R = np.diag([1e-2, 4e-2])
    kf = kb.steady_state_kalman(A, Q, C, R)
    L, P, _ = control.dlqe(A, np.eye(3), C, Q, R)
    # python-control's L is the predictor-form gain A P Cᵀ (C P Cᵀ + R)⁻¹ = A K
    np.testing.assert_allclose(kf.P_prior, P, rtol=1e-8)
    np.testing.assert_allclose(A @ kf.K, L, rtol=1e-8)


def test_kalman_on_vehicle_solves_dare(model):
    C = model.output_matrix("both")
    f = kb.ShapingFilter(0.5, 0.5, 25.0)
    Aa, Ga, Ca = kb.augment(model.A, model.B, C, [f] * 4)
    Phi, Qd = kb.discretise_noise(Aa, Ga, np.eye(4), 1e-3)
    R = np.diag((5e-3 * np.array([2e-2, 1e-3, 2e-2, 1e-3, 2e-2, 1e-3, 0.2, 0.03, 1, 1, 1, 1])) ** 2)
    kf = kb.steady_state_kalman(Phi, Qd, Ca, R)
    P = kf.P_prior
    S = Ca @ P @ Ca.T + R
    rhs = Phi @ (P - P @ Ca.T @ np.linalg.solve(S, Ca @ P)) @ Phi.T + Qd
    d = np.sqrt(np.diag(P))
    np.testing.assert_allclose((rhs - P) / np.outer(d, d), 0, atol=1e-6)
    assert np.max(np.abs(np.linalg.eigvals((np.eye(28) - kf.K @ Ca) @ Phi))) < 1
