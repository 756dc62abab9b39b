"""The package's simulators share one row convention (see :mod:`railpaper.discretise`).

K steps give states (K+1, n) with x[0] = x0 and x[k] the state after step k; held inputs (K, m)
with u[k-1] acting over step k; measurements (K, p) with y[k-1] measuring x[k].  Each simulator
is checked against an independent computation: an ODE solve of the continuous lateral model,
and the toy recursions written out by hand from the same random draws.
"""

import numpy as np
from scipy.integrate import solve_ivp

from railpaper.data import load_quantities
from railpaper.models import lateral_16state
from railpaper.models import linear_toys as toys
from railpaper.paths import DATA_DIR

PARAMS = load_quantities(DATA_DIR / "rbpf-parameter-estimation" / "parameters.toml")
FIXED = {k: PARAMS[k].value for k in lateral_16state.FIXED_KEYS}
THETA = np.array([PARAMS[k].value for k in lateral_16state.PARAM_NAMES])


def test_lateral_truth_rows_follow_the_ode_with_held_input():
    v, dt = 300 / 3.6, 1e-4
    u = np.random.default_rng(0).standard_normal((5, 2)) * 0.01          # m/s
    x = lateral_16state.simulate_truth(FIXED, THETA, v, dt, u)
    assert x.shape == (6, 16) and not x[0].any()
    A, B = lateral_16state.build_A_direct(FIXED, THETA, v), lateral_16state.input_matrix()
    ref = np.zeros(16)
    for k in range(len(u)):                   # x[k+1] is reached by holding u[k] over step k+1
        ref = solve_ivp(lambda t, z: A @ z + B @ u[k], (0, dt), ref, method="DOP853",
                        rtol=1e-12, atol=1e-16).y[:, -1]
        np.testing.assert_allclose(x[k + 1], ref, rtol=1e-7, atol=1e-14)


def test_linear_toy_rows_by_hand():
    """simulate_eq18 redone by hand from the same draws: u, x0, w, e in the documented order."""
    theta, w_var, v_var, K = np.array([-0.4, 0.5, 0.5, 1.0]), 0.1, 0.2, 7
    sim = toys.simulate_eq18(theta, w_var, v_var, K, np.random.default_rng(5), p0_std=0.3)
    rng = np.random.default_rng(5)
    u = rng.standard_normal((K, 1))
    x = [0.3 * rng.standard_normal(2)]
    w = np.sqrt(w_var) * rng.standard_normal((K, 1))
    e = np.sqrt(v_var) * rng.standard_normal((K, 1))
    F = np.array([[0.0, 1.5], [theta[0], theta[1]]])
    for k in range(1, K + 1):                 # X(n) = F X(n-1) + b u(n-1) + g W(n-1)
        x.append(F @ x[-1] + theta[2:] * u[k - 1, 0] + np.array([-1.0, -1.3]) * w[k - 1, 0])
    x = np.array(x)
    assert sim.x.shape == (K + 1, 2) and sim.y.shape == (K, 1) and sim.u.shape == (K, 1)
    np.testing.assert_allclose(sim.x, x, rtol=1e-12, atol=1e-14)
    np.testing.assert_allclose(sim.y[:, 0], x[1:, 0] + e[:, 0], rtol=1e-12, atol=1e-14)
    np.testing.assert_array_equal(sim.u, u)
