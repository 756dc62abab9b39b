"""Augmented-state EKF against filterpy's ExtendedKalmanFilter (independent reference)."""

import numpy as np
from filterpy.kalman import ExtendedKalmanFilter

from railpaper.estimators.ekf import eq18_model, run_augmented_ekf
from railpaper.models.linear_toys import EQ18_G, simulate_eq18


class _AugmentedEKF(ExtendedKalmanFilter):
    """filterpy EKF with the nonlinear augmented transition of Eq. (18)."""

    def predict_x(self, u=0):
        x, th = self.x[:2, 0], self.x[2:, 0]
        F, B, _, _, _, _ = eq18_model(th)
        self.x = np.concatenate([F @ x + B[:, 0] * u, th])[:, None]


def test_augmented_ekf_matches_filterpy():
    theta_true = np.array([-0.4, 0.5, 0.5, 1.0])
    sim = simulate_eq18(theta_true, 0.1, 0.1, 200, np.random.default_rng(3))
    theta0 = np.array([-0.26, 1.0, 0.24, -0.5])
    Q = 0.1 * EQ18_G @ EQ18_G.T
    R = np.array([[0.1]])
    q_theta = 1e-5
    ours = run_augmented_ekf(eq18_model, sim.y, theta0, np.zeros(2), np.eye(2), 0.5, Q, R,
                             q_theta, u=sim.u)
    ref = _AugmentedEKF(dim_x=6, dim_z=1)
    ref.x = np.concatenate([np.zeros(2), theta0])[:, None]
    ref.P = np.diag([1.0, 1.0, 0.5, 0.5, 0.5, 0.5])
    ref.Q = np.zeros((6, 6))
    ref.Q[:2, :2] = Q
    ref.Q[2:, 2:] = q_theta * np.eye(4)
    ref.R = R
    for k in range(len(sim.y)):
        x, th = ref.x[:2, 0], ref.x[2:, 0]
        u = sim.u[k, 0]
        J = np.eye(6)
        J[:2, :2] = [[0.0, 1.5], [th[0], th[1]]]
        J[1, 2], J[1, 3] = x[0], x[1]          # ∂(x1 X1 + x2 X2)/∂(x1, x2)
        J[0, 4], J[1, 5] = u, u                # ∂(x3 u, x4 u)/∂(x3, x4)
        ref.F = J
        ref.predict(u=u)
        ref.update(sim.y[k][:, None], lambda z: np.array([[1.0, 0, 0, 0, 0, 0]]),
                   lambda z: z[:1])
        np.testing.assert_allclose(ours.theta[k], ref.x[2:, 0], rtol=1e-9, atol=1e-10)
        np.testing.assert_allclose(ours.x[k], ref.x[:2, 0], rtol=1e-9, atol=1e-10)
    assert not ours.diverged


def test_divergence_is_flagged_not_nan():
    sim = simulate_eq18(np.array([-0.4, 0.5, 0.5, 1.0]), 0.1, 0.1, 50,
                        np.random.default_rng(0))
    run = run_augmented_ekf(eq18_model, sim.y * 1e8, np.zeros(4), np.zeros(2), np.eye(2), 1e6,
                            np.eye(2), np.array([[1e-12]]), 1.0, u=sim.u, divergence_bound=10.0)
    assert np.all(np.isfinite(run.theta))
    assert run.diverged and run.diverged_step >= 1
