"""Truth plant of paper 003 (issue 13, part 5): creep law, rolling-radius difference, plant.

References: numerical derivatives, the Vermeulen–Johnson cubic and the harmonic-balance
conicity typed here, and the exact ZOH simulation of the linear model.
"""

import numpy as np
import pytest

from railpaper import contact
from railpaper.models import lateral_16state
from railpaper.models import lateral_truth

F11, F22, N, MU = 1.2e7, 1.1e7, 62293.5, 0.4
FIXED = dict(mw=1900.0, iwz=1100.0, mb=2600.0, ib=2000.0, mbd=19000.0, kpx=2.0e7, a=1.25,
             b=1.0, lbw=1.3, l0=0.7465, r0=0.46, f11=F11, f22=F22)
THETA = np.array([3.0e4, 0.15, 6.0e6, 3.0e5, 5.0e5])
V = 300 / 3.6


def vj_closed_form(xi_x, xi_y):
    """Shen–Hedrick–Elkins / Vermeulen–Johnson, written out independently."""
    lin = np.array([-F11 * xi_x, -F22 * xi_y])
    mag = np.sqrt(lin @ lin)
    if mag == 0:
        return lin
    b = mag / (MU * N)
    sat = MU * N * (b - b * b / 3 + b ** 3 / 27) if b < 3 else MU * N
    return lin / mag * sat


@pytest.mark.parametrize("xi", [(1e-5, 0.0), (0.0, -2e-4), (1e-3, 2e-3), (-4e-3, 1e-3),
                                (5e-2, -1e-2), (0.0, 3 * MU * N / F22)])
def test_creep_forces_equal_closed_form(xi):
    fx, fy = contact.creep_forces(xi[0], xi[1], F11, F22, N, MU)
    np.testing.assert_allclose([fx, fy], vj_closed_form(*xi), rtol=1e-12, atol=1e-9)


def test_creep_slope_at_zero_is_the_linear_law():
    h = 1e-9
    fx_p, fy_p = contact.creep_forces(h, 0.0, F11, F22, N, MU)
    fx_m, fy_m = contact.creep_forces(-h, 0.0, F11, F22, N, MU)
    assert (fx_p - fx_m) / (2 * h) == pytest.approx(-F11, rel=1e-6)
    assert abs(fy_p - fy_m) < 1e-12
    fx_p, fy_p = contact.creep_forces(0.0, h, F11, F22, N, MU)
    fx_m, fy_m = contact.creep_forces(0.0, -h, F11, F22, N, MU)
    assert (fy_p - fy_m) / (2 * h) == pytest.approx(-F22, rel=1e-6)
    # no saturation: the linear law exactly
    xi = np.array([0.3, -0.02])
    np.testing.assert_array_equal(np.array(contact.creep_forces(xi, xi[::-1], F11, F22, N,
                                                                np.inf)),
                                  [-F11 * xi, -F22 * xi[::-1]])


def test_creep_saturates_at_mu_n_and_keeps_direction():
    xi_y = np.geomspace(1e-6, 1.0, 400)
    fx, fy = contact.creep_forces(0.5 * xi_y, xi_y, F11, F22, N, MU)
    mag = np.hypot(fx, fy)
    assert np.all(np.diff(mag) >= -1e-9)                   # never decreases
    assert mag.max() == pytest.approx(MU * N, rel=1e-12)   # full sliding
    assert np.all(mag <= MU * N * (1 + 1e-12))
    np.testing.assert_allclose(fy / fx, F22 / (0.5 * F11), rtol=1e-12)  # linear direction
    assert contact.vermeulen_johnson_ratio(3.0) == pytest.approx(1.0, abs=1e-15)
    h = 1e-6                                                # smooth: slope 0 into sliding
    assert (contact.vermeulen_johnson_ratio(3.0) - contact.vermeulen_johnson_ratio(3 - h)) / h \
        == pytest.approx(0.0, abs=1e-5)


def test_rolling_radius_difference_and_equivalent_conicity():
    lam, yc = 0.15, 0.009
    h = 1e-9
    slope = (contact.rolling_radius_difference(h, lam, yc)
             - contact.rolling_radius_difference(-h, lam, yc)) / (2 * h)
    assert slope == pytest.approx(2 * lam, rel=1e-9)
    y = np.linspace(-0.012, 0.012, 25)
    np.testing.assert_allclose(contact.rolling_radius_difference(-y, lam, yc),
                               -contact.rolling_radius_difference(y, lam, yc))
    np.testing.assert_array_equal(contact.rolling_radius_difference(y, lam, np.inf), 2 * lam * y)
    A = np.array([1e-4, 1e-3, 3e-3, 6e-3, 9e-3])
    lam_eq = contact.equivalent_conicity(A, lam, yc)
    np.testing.assert_allclose(lam_eq, lam * (1 + 0.75 * (A / yc) ** 2), rtol=1e-12)
    assert np.all(np.diff(lam_eq) > 0)
    # first Fourier coefficient by a brute-force quadrature independent of the code's grid
    phi = np.linspace(0, 2 * np.pi, 20001)
    dr = contact.rolling_radius_difference(3e-3 * np.sin(phi), lam, yc)
    assert np.trapezoid(dr / 2 * np.sin(phi), phi) / (np.pi * 3e-3) == pytest.approx(
        lam_eq[2], rel=1e-8)


def track_like_input(n: int, dt: float, seed: int = 3) -> np.ndarray:
    """A smooth random (ẏt1, ẏt2), m/s, of a few mm/s, the rear one delayed by 2a/V."""
    t = np.arange(n + 400) * dt
    rng = np.random.default_rng(seed)
    f = rng.uniform(2, 60, 12)
    ph = rng.uniform(0, 2 * np.pi, 12)
    q = (0.02 * np.sin(2 * np.pi * f[None] * t[:, None] + ph)).sum(axis=1) / 12
    lag = int(round(2 * FIXED["a"] / V / dt))
    return np.column_stack([q[lag:lag + n], q[:n]])


def test_linear_contact_reproduces_the_linear_model():
    dt = 1e-4
    u = track_like_input(3000, dt)
    ref = lateral_16state.simulate_truth(FIXED, THETA, V, dt, u)
    x = lateral_truth.simulate_truth(FIXED, THETA, V, dt, u, lateral_truth.WheelRail.linear())
    assert x.shape == ref.shape == (3001, 16)
    scale = np.abs(ref).max(axis=0)
    assert np.max(np.abs(x - ref) / scale) < 1e-8           # RK4 at |λ| h ≈ 0.015
    plant = lateral_truth.TruthPlant(FIXED, THETA, V, lateral_truth.WheelRail.linear())
    H = lateral_16state.measurement_matrix(lateral_16state.build_A_direct(FIXED, THETA, V))
    np.testing.assert_allclose(plant.measurements(ref), ref @ H.T, rtol=1e-9,
                               atol=1e-12 * np.abs(ref @ H.T).max())


def test_nonlinear_plant_forces_by_hand():
    wr = lateral_truth.WheelRail(MU, N, 0.009)
    plant = lateral_truth.TruthPlant(FIXED, THETA, V, wr)
    rng = np.random.default_rng(5)
    x = rng.standard_normal(16) * np.tile([0.05, 4e-3, 0.05, 2e-3], 4)
    A_free = lateral_16state.build_A_direct(dict(FIXED, f11=0.0, f22=0.0), THETA, V)
    extra = plant.derivative(x, np.zeros(2)) - A_free @ x
    for iv, ipsi, ivpsi, idd in ((0, 3, 2, 14), (4, 7, 6, 15)):
        lam, l0, r0 = THETA[1], FIXED["l0"], FIXED["r0"]
        d = x[idd]
        xi_x = l0 * x[ivpsi] / V + 2 * lam * d * (1 + (d / 0.009) ** 2) / (2 * r0)
        xi_y = x[iv] / V - x[ipsi]
        fx, fy = vj_closed_form(xi_x, xi_y)
        assert extra[iv] == pytest.approx(2 * fy / FIXED["mw"], rel=1e-10)
        assert extra[ivpsi] == pytest.approx(2 * l0 * fx / FIXED["iwz"], rel=1e-10)
    rest = np.delete(extra, [0, 2, 4, 6])
    np.testing.assert_array_equal(rest, 0.0)


def test_nonlinear_plant_is_linear_for_small_motion():
    plant = lateral_truth.TruthPlant(FIXED, THETA, V, lateral_truth.WheelRail(MU, N, 0.009))
    A = lateral_16state.build_A_direct(FIXED, THETA, V)
    x = np.random.default_rng(2).standard_normal(16)

    def deviation(eps):
        return (np.abs(plant.derivative(eps * x, np.zeros(2)) - A @ (eps * x)).max()
                / (eps * np.abs(A @ x).max()))

    # relative deviation O(β) (the cubic's β/3 and the conicity's (d/y_c)²): it vanishes
    # in proportion to the amplitude
    assert deviation(1e-7) < 1e-3
    assert deviation(1e-9) / deviation(1e-7) == pytest.approx(1e-2, rel=0.05)
