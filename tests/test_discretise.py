"""Exact discretisation against scipy.signal.cont2discrete and a fine Runge-Kutta reference."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.integrate import solve_ivp
from scipy.signal import cont2discrete

from railpaper.discretise import foh, simulate_foh, simulate_zoh, zoh


def random_stable_system(seed, n=4, m=2):
    rng = np.random.default_rng(seed)
    A = rng.standard_normal((n, n))
    A -= (np.max(np.linalg.eigvals(A).real) + 0.5) * np.eye(n)
    return A, rng.standard_normal((n, m))


@settings(max_examples=25, deadline=None)
@given(seed=st.integers(0, 10_000), dt=st.floats(1e-4, 0.5))
def test_zoh_matches_cont2discrete(seed, dt):
    A, B = random_stable_system(seed)
    Phi, Gamma = zoh(A, B, dt)
    Ad, Bd, *_ = cont2discrete((A, B, np.eye(4), np.zeros((4, 2))), dt, method="zoh")
    np.testing.assert_allclose(Phi, Ad, rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(Gamma, Bd, rtol=1e-10, atol=1e-12)


def test_foh_matches_cont2discrete():
    A, B = random_stable_system(3)
    dt = 0.05
    Phi, G0, G1 = foh(A, B, dt)
    Ad, Bd, *_ = cont2discrete((A, B, np.eye(4), np.zeros((4, 2))), dt, method="foh")
    # scipy's FOH form is x̃[k+1] = Ad x̃[k] + Bd u[k] with x̃ = x − (G1) u; compare the
    # one-step response to a ramp instead, which both must get exactly.
    assert np.allclose(Phi, Ad)
    u = np.array([[0.3, -1.0], [1.1, 0.4]])
    x1 = simulate_foh(Phi, G0, G1, u)[1]
    ref = solve_ivp(lambda t, x: A @ x + B @ (u[0] + (u[1] - u[0]) * t / dt), (0, dt),
                    np.zeros(4), rtol=1e-12, atol=1e-14).y[:, -1]
    np.testing.assert_allclose(x1, ref, rtol=1e-8, atol=1e-12)


def test_zoh_stacked_equals_one_by_one():
    systems = [random_stable_system(s) for s in range(5)]
    A = np.stack([s[0] for s in systems])
    B = np.stack([s[1] for s in systems])
    Phi, Gamma = zoh(A, B, 0.01)
    for i, (a, b) in enumerate(systems):
        p, g = zoh(a, b, 0.01)
        np.testing.assert_array_equal(Phi[i], p)
        np.testing.assert_array_equal(Gamma[i], g)


def test_simulate_zoh_matches_scipy_dlsim():
    """K held inputs give K+1 states (x[0] = x0, x[k] after step k); dlsim returns the states
    before each input, so it is given one more (unused) input row to reach x[K]."""
    from scipy.signal import dlsim
    A, B = random_stable_system(7)
    Phi, Gamma = zoh(A, B, 0.02)
    u = np.random.default_rng(0).standard_normal((50, 2))
    x0 = np.ones(4)
    _, _, x_ref = dlsim((Phi, Gamma, np.eye(4), np.zeros((4, 2)), 0.02),
                        np.vstack([u, np.zeros((1, 2))]), x0=x0)
    x = simulate_zoh(Phi, Gamma, u, x0)
    assert x.shape == (51, 4)
    np.testing.assert_allclose(x, x_ref, rtol=1e-12, atol=1e-12)


def test_simulate_zoh_is_the_continuous_response_to_a_held_input():
    """x[K] against a Runge-Kutta solution of ẋ = A x + B u with u piecewise constant."""
    A, B = random_stable_system(11)
    dt, u = 0.05, np.random.default_rng(1).standard_normal((6, 2))
    x = simulate_zoh(*zoh(A, B, dt), u)
    ref = np.zeros(4)
    for k in range(len(u)):
        ref = solve_ivp(lambda t, z: A @ z + B @ u[k], (0, dt), ref, rtol=1e-12,
                        atol=1e-14).y[:, -1]
        np.testing.assert_allclose(x[k + 1], ref, rtol=1e-8, atol=1e-12)
    assert x.shape == (7, 4) and not x[0].any()


def test_simulate_foh_has_a_row_per_input_sample():
    A, B = random_stable_system(5)
    u = np.random.default_rng(2).standard_normal((8, 2))
    assert simulate_foh(*foh(A, B, 0.01), u).shape == (8, 4)
    assert simulate_foh(*foh(A, B, 0.01), u[:1], np.ones(4)).tolist() == [[1.0] * 4]


def test_non_positive_step_rejected():
    A, B = random_stable_system(0)
    with pytest.raises(ValueError, match="dt_s must be > 0"):
        zoh(A, B, 0.0)
