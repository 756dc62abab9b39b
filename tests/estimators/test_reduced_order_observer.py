"""Paper 001: single-wheelset model and the reduced-order observer against independent references."""

import control
import numpy as np
import pytest

from railpaper.discretise import foh, simulate_foh
from railpaper.estimators import reduced_order_observer
from railpaper.models import single_wheelset


@pytest.fixture(scope="module")
def vehicle():
    return single_wheelset.load_parameters()


def test_state_matrix_is_jacobian_of_nonlinear_hertz_model(vehicle):
    """A and B (corrected Eq. 7) equal the numerical Jacobian of the nonlinear plant at rest."""
    A, B = single_wheelset.state_space(vehicle)
    h = np.array([1e-6, 1e-9, 1e-6, 1e-9])
    jac = np.column_stack([
        (single_wheelset.nonlinear_derivative(vehicle, h[i] * np.eye(4)[i], 0.0)
         - single_wheelset.nonlinear_derivative(vehicle, -h[i] * np.eye(4)[i], 0.0)) / (2 * h[i])
        for i in range(4)])
    np.testing.assert_allclose(jac, A, rtol=1e-5, atol=1e-9)
    dq = 1e-9
    jac_q = (single_wheelset.nonlinear_derivative(vehicle, np.zeros(4), dq)
             - single_wheelset.nonlinear_derivative(vehicle, np.zeros(4), -dq)) / (2 * dq)
    np.testing.assert_allclose(jac_q, B[:, 0], rtol=1e-5)
    np.testing.assert_allclose(single_wheelset.nonlinear_derivative(vehicle, np.zeros(4), 0.0), 0.0,
                               atol=1e-9)


def test_row_three_uses_wheelset_mass(vehicle):
    A, _ = single_wheelset.state_space(vehicle)
    assert A[2, 0] == pytest.approx(vehicle.suspension_damping_Ns_per_m / vehicle.wheelset_mass_kg)
    # modal check: body bounce near 1.1 Hz, wheelset on the contact spring near 243 Hz
    freqs = np.sort(np.abs(np.linalg.eigvals(A))) / (2 * np.pi)
    assert 0.9 < freqs[0] < 1.4 and 200 < freqs[-1] < 300


def test_contact_stiffness_from_hertz(vehicle):
    G = 3.86 * 0.42 ** -0.115 * 1e-8
    P0 = (41800 + 1800) * 9.8 / 2
    assert vehicle.contact_stiffness_N_per_m == pytest.approx(2 * 1.5 / G * P0 ** (1 / 3), rel=1e-12)


def test_p0_readings():
    """P0 per wheelset (Eq. 3's text): one contact at the wheelset's static load."""
    G = 3.86 * 0.42 ** -0.115 * 1e-8
    wheelset = single_wheelset.load_parameters(p0_basis="wheelset")
    assert wheelset.contacts == 1
    assert wheelset.static_wheel_load_N == pytest.approx((41800 + 1800) * 9.8)
    assert wheelset.contact_stiffness_N_per_m == pytest.approx(
        1.5 / G * ((41800 + 1800) * 9.8) ** (1 / 3), rel=1e-12)
    ratio = (wheelset.contact_stiffness_N_per_m
             / single_wheelset.load_parameters().contact_stiffness_N_per_m)
    assert ratio == pytest.approx(2 ** (-2 / 3), rel=1e-12)
    with pytest.raises(ValueError, match="p0_basis"):
        single_wheelset.load_parameters(p0_basis="axle")


def test_wheelset_reading_is_jacobian_of_its_hertz_model():
    vehicle = single_wheelset.load_parameters(p0_basis="wheelset")
    A, B = single_wheelset.state_space(vehicle)
    h = 1e-9
    jac = (single_wheelset.nonlinear_derivative(vehicle, h * np.eye(4)[3], 0.0)
           - single_wheelset.nonlinear_derivative(vehicle, -h * np.eye(4)[3], 0.0)) / (2 * h)
    np.testing.assert_allclose(jac, A[:, 3], rtol=1e-5)
    force = single_wheelset.dynamic_contact_force_N(vehicle, 1e-7, 0.0, "hertz")
    assert force == pytest.approx(vehicle.contact_stiffness_N_per_m * 1e-7, rel=1e-3)


@pytest.mark.parametrize("poles", [[-30.0, -40.0], [-5.0, -80.0], [-150.0, -200.0]])
def test_observer_poles_placed(vehicle, poles):
    A, B = single_wheelset.state_space(vehicle)
    obs = reduced_order_observer.design(A, B, 2, poles)
    np.testing.assert_allclose(np.sort(np.linalg.eigvals(obs.F).real), np.sort(poles), rtol=1e-6)
    # the Gopinath structure: F = A22 − L A12, H = B2 − L B1
    A11, A12, A21, A22, B1, B2 = reduced_order_observer.partition(A, B, 2)
    np.testing.assert_allclose(obs.F, A22 - obs.L @ A12)
    np.testing.assert_allclose(obs.H, B2 - obs.L @ B1)


def test_observability_of_reduced_pair(vehicle):
    A, B = single_wheelset.state_space(vehicle)
    _, A12, _, A22, _, _ = reduced_order_observer.partition(A, B, 2)
    assert np.linalg.matrix_rank(control.obsv(A22, A12)) == 2


def test_foh_observer_error_decays_to_nanometres(vehicle):
    """Noise-free data from the exactly simulated plant: the FOH-discretised observer's error
    decays like exp(p t) to ~1e-9 m; the ZOH (paper) one stalls at its discretisation error."""
    A, B = single_wheelset.state_space(vehicle)
    dt = 1e-4
    t = np.arange(0, 1.0, dt)
    q = 1e-3 * np.sin(2 * np.pi * 3.0 * t) + 5e-4 * np.sin(2 * np.pi * 17.0 * t)
    Phi, G0, G1 = foh(A, B, dt)
    x = simulate_foh(Phi, G0, G1, q[:, None])
    obs = reduced_order_observer.design(A, B, 2, [-30.0, -40.0]).discretise(dt, "foh")
    x2_hat = obs.run(x[:, :2], q[:, None], x[0, 2:] + np.array([0.0, 5e-3]))
    error = np.abs(x2_hat[:, 1] - x[:, 3])
    assert error[0] == pytest.approx(5e-3)
    assert error[-1] < 1e-9
    # decay at the designed rate: slower pole −30 1/s from 0.1 s to 0.2 s → factor e^−3
    k = int(0.1 / dt)
    assert 0.2 * np.exp(-3) < error[2 * k] / error[k] < 5 * np.exp(-3)
    zoh_obs = reduced_order_observer.design(A, B, 2, [-30.0, -40.0]).discretise(dt, "zoh")
    zoh_error = np.abs(zoh_obs.run(x[:, :2], q[:, None], x[0, 2:])[:, 1] - x[:, 3])
    assert zoh_error[-1000:].max() > 100 * error[-1000:].max()


def test_design_rejects_wrong_number_of_poles(vehicle):
    A, B = single_wheelset.state_space(vehicle)
    with pytest.raises(ValueError, match="need 2 observer poles"):
        reduced_order_observer.design(A, B, 2, [-1.0])
