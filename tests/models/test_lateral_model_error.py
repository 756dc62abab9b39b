"""The fault appendix's truth with model error (models/lateral_model_error.py).

References: scipy's matrix exponential of the linearised plant (exact ZOH), the linear 16-state
model (its damper force in steady state, and as the series stiffness grows), the Maxwell
element's equation written out here, and the critical speeds the data file states.
"""

import numpy as np
import pytest
from scipy.linalg import expm

from railpaper.experiments.lateral_vehicle import vehicle
from railpaper.experiments.suspension_fault_detection import faults
from railpaper.models import lateral_16state, lateral_model_error
from railpaper.models.lateral_truth import TruthPlant, WheelRail

FIXED, THETA = vehicle()
V = 300 / 3.6
K_S = 2.0e7
CSALY = lateral_16state.PARAM_NAMES.index("csaly")
YAW = lateral_16state.YAW_RATE_STATE
F = lateral_model_error.DAMPER_FORCE_STATE


def _state(seed):
    x = np.random.default_rng(seed).standard_normal(lateral_model_error.N_STATES)
    return x * np.r_[np.full(16, 1e-3), 1e3]


def test_the_damper_in_steady_state_is_the_linear_models():
    # with F = C_saly L_bw psi_b' (the Maxwell element's steady state) and linear contact, the
    # 16 states move as the linear model's with its damper term
    x = _state(1)
    x[F] = THETA[CSALY] * FIXED["lbw"] * x[YAW]
    u = np.array([1e-3, -2e-3])
    plant = lateral_model_error.ModelErrorPlant(FIXED, THETA, V, WheelRail.linear(), K_S)
    linear = TruthPlant(FIXED, THETA, V, WheelRail.linear()).derivative(x[:16], u)
    np.testing.assert_allclose(plant.derivative(x, u)[:16], linear, rtol=1e-12, atol=1e-12)


def test_the_maxwell_element_by_hand():
    x = _state(2)
    plant = lateral_model_error.ModelErrorPlant(FIXED, THETA, V, WheelRail.linear(), K_S)
    force_rate = K_S * (FIXED["lbw"] * x[YAW] - x[F] / THETA[CSALY])
    assert plant.derivative(x, np.zeros(2))[F] == pytest.approx(force_rate, rel=1e-12)
    lost = THETA.copy()
    lost[CSALY] = 0.0
    gone = lateral_model_error.ModelErrorPlant(FIXED, lost, V, WheelRail.linear(), K_S)
    assert gone.derivative(x, np.zeros(2))[F] == 0.0


def test_linear_matrix_is_the_derivative_with_linear_contact():
    plant = lateral_model_error.ModelErrorPlant(FIXED, THETA, V, WheelRail.linear(), K_S)
    A = lateral_model_error.linear_matrix(FIXED, THETA, V, K_S)
    x = _state(3)
    np.testing.assert_allclose(plant.derivative(x, np.zeros(2)), A @ x, rtol=1e-10, atol=1e-9)


def test_linear_matrix_tends_to_the_linear_model_as_the_series_stiffness_grows():
    stiff = np.linalg.eigvals(lateral_model_error.linear_matrix(FIXED, THETA, V, 1e13))
    model = np.linalg.eigvals(lateral_16state.build_A_direct(FIXED, THETA, V))
    # the slow modes (|lambda| < 1000 1/s) agree, to about |lambda| C / K_s; the damper adds
    # one very fast one (K_s / C)
    slow = np.sort_complex(stiff[np.abs(stiff) < 1e3])
    np.testing.assert_allclose(slow, np.sort_complex(model[np.abs(model) < 1e3]), rtol=1e-3,
                               atol=1e-3)


def test_simulation_with_linear_contact_is_the_exact_zoh():
    rng = np.random.default_rng(4)
    u = rng.standard_normal((400, 2)) * 1e-2
    h = 5e-4
    th2 = THETA.copy()
    th2[CSALY] *= 0.5
    thetas, starts = [THETA, th2], [0, 250]
    x = lateral_model_error.simulate_schedule(FIXED, thetas, starts, V, h, u,
                                              WheelRail.linear(), K_S)
    ref = np.zeros_like(x)
    n, m = lateral_model_error.N_STATES, 2
    B = np.zeros((n, m))
    B[:16] = lateral_16state.input_matrix()
    for k in range(len(u)):
        A = lateral_model_error.linear_matrix(FIXED, thetas[k >= 250], V, K_S)
        block = expm(np.block([[A, B], [np.zeros((m, n + m))]]) * h)
        ref[k + 1] = block[:n, :n] @ ref[k] + block[:n, n:] @ u[k]
    scale = np.abs(ref).max(axis=0) + 1e-12
    assert np.max(np.abs(x - ref) / scale) < 1e-5           # RK4 at the chapter's step


def test_a_lost_damper_carries_no_force_from_its_loss():
    u = np.random.default_rng(5).standard_normal((200, 2)) * 1e-2
    lost = THETA.copy()
    lost[CSALY] = 0.0
    x = lateral_model_error.simulate_schedule(FIXED, [THETA, lost], [0, 100], V, 5e-4, u,
                                              WheelRail.linear(), K_S)
    assert np.any(x[:100, F] != 0.0)
    assert np.all(x[100:, F] == 0.0)


def _first_unstable_kmh(theta, stiffness):
    for speed in np.arange(50.0, 700.0, 2.0):
        A = lateral_model_error.linear_matrix(FIXED, theta, speed / 3.6, stiffness)
        if np.linalg.eigvals(A).real.max() > 1e-6:
            return speed
    return np.inf


def test_the_critical_speeds_the_data_file_states():
    error = faults.model_error()
    truth = error.truth_theta(THETA)
    assert truth[1] == pytest.approx(0.2)
    assert _first_unstable_kmh(truth, error.series_stiffness_N_per_m) == 376.0
    half = truth.copy()
    half[CSALY] *= 0.5
    assert _first_unstable_kmh(half, error.series_stiffness_N_per_m) == 288.0


def test_bad_series_stiffness_is_refused():
    with pytest.raises(ValueError, match="series stiffness"):
        lateral_model_error.ModelErrorPlant(FIXED, THETA, V, WheelRail.linear(), 0.0)


def test_a_damping_too_small_for_the_step_is_refused():
    weak = THETA.copy()
    weak[CSALY] = K_S * 5e-4 / 3.0                     # K_s h / C = 3 > RK4_STABLE_STEP
    with pytest.raises(ValueError, match="too small for RK4"):
        lateral_model_error.simulate_schedule(FIXED, [weak], [0], V, 5e-4, np.zeros((3, 2)),
                                              WheelRail.linear(), K_S)


def test_the_summary_of_the_model_error_on_the_page():
    summary = faults.model_error_summary(FIXED, THETA, faults.model_error())
    # the interpolated crossings lie within the 2 km/h grid step below the grid's first
    # unstable speed (376 and 288 km/h)
    assert 374.0 < summary["critical_speed_kmh"] <= 376.0
    assert 286.0 < summary["critical_speed_csaly_half_kmh"] <= 288.0
    assert summary["critical_speed_kmh_stiffness_x1"] == summary["critical_speed_kmh"]
    assert summary["critical_speed_kmh_stiffness_x0.5"] < summary["critical_speed_kmh"] \
        < summary["critical_speed_kmh_stiffness_x2"]
    assert summary["maxwell_time_s"] == pytest.approx(THETA[CSALY] / 2.0e7)
