"""Residual alarms (railpaper.engine.residual_alarms) against independent references: the
whitened innovations against filterpy's innovation and its covariance, the CUSUM recursion
against Page's maximum over every change time by brute force, the GLR against a plain double
loop, and the innovations' law under the nominal model (N(0, I), white)."""

import numpy as np
import pytest
from filterpy.kalman import KalmanFilter
from scipy import stats

from railpaper.engine.linear_gaussian import LinearGaussianBatch
from railpaper.engine.residual_alarms import (cusum_variance, first_alarm, glr_mean_shift,
                                              whitened_innovations)

F = np.array([[0.9, 0.2, 0.0], [-0.3, 0.8, 0.1], [0.0, 0.0, 0.95]])
B = np.array([[0.0], [1.0], [0.5]])
H = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
Q = np.diag([0.02, 0.05, 0.01])
R = np.array([[0.1, 0.02], [0.02, 0.2]])
NOMINAL = LinearGaussianBatch(F, Q, H, R, B)


def simulate(K, rng, F_after=F, change=None):
    x, y, u = np.zeros(3), np.empty((K, 2)), rng.standard_normal((K, 1))
    for k in range(K):
        Fk = F_after if change is not None and k >= change else F
        x = Fk @ x + B @ u[k] + rng.multivariate_normal(np.zeros(3), Q)
        y[k] = H @ x + rng.multivariate_normal(np.zeros(2), R)
    return y, u


def test_whitened_innovations_equal_filterpys_innovations_whitened():
    rng = np.random.default_rng(0)
    y, u = simulate(80, rng)
    x0, P0 = np.array([0.1, -0.2, 0.0]), 0.5 * np.eye(3)
    res = whitened_innovations(NOMINAL, y, x0, P0, u)
    kf = KalmanFilter(dim_x=3, dim_z=2, dim_u=1)
    kf.x, kf.P, kf.F, kf.B, kf.H, kf.Q, kf.R = x0[:, None], P0.copy(), F, B, H, Q, R
    for k in range(80):
        kf.predict(u=u[k][:, None])
        kf.update(y[k][:, None])
        L = np.linalg.cholesky(kf.S)
        np.testing.assert_allclose(res.z[k], np.linalg.solve(L, kf.y[:, 0]), rtol=1e-9,
                                   atol=1e-12)
        np.testing.assert_allclose(res.log_likelihood[k], kf.log_likelihood, rtol=1e-10)


def test_innovations_of_the_nominal_model_are_standard_normal_and_white():
    rng = np.random.default_rng(1)
    y, u = simulate(4000, rng)
    z = whitened_innovations(NOMINAL, y, np.zeros(3), 1e-6 * np.eye(3), u).z[200:]
    for j in range(2):                                        # each channel N(0, 1)
        assert stats.kstest(z[:, j], "norm").pvalue > 1e-3
    np.testing.assert_allclose(np.cov(z.T), np.eye(2), atol=0.08)
    lag1 = np.mean(z[1:] * z[:-1], axis=0)                    # white: lag-1 products ≈ 0
    assert np.all(np.abs(lag1) < 4 / np.sqrt(len(z)))


def test_cusum_equals_pages_maximum_over_every_change_time():
    rng = np.random.default_rng(2)
    z = rng.standard_normal((150, 2)) * np.where(np.arange(150) < 90, 1.0, 1.6)[:, None]
    sigma2 = 2.5
    s = -np.log(sigma2) + 0.5 * (1 - 1 / sigma2) * np.sum(z * z, axis=1)     # p = 2
    brute = [max(0.0, max(s[j:k + 1].sum() for j in range(k + 1))) for k in range(150)]
    np.testing.assert_allclose(cusum_variance(z, sigma2), brute, rtol=1e-12, atol=1e-12)


def test_glr_equals_a_double_loop_over_windows():
    rng = np.random.default_rng(3)
    z = rng.standard_normal((60, 3)) + np.where(np.arange(60) >= 40, 0.8, 0.0)[:, None]
    W = 12
    brute = [max(np.sum(z[j:k + 1].sum(axis=0) ** 2) / (2 * (k - j + 1))
                 for j in range(max(0, k - W + 1), k + 1)) for k in range(60)]
    np.testing.assert_allclose(glr_mean_shift(z, W), brute, rtol=1e-12)


def test_a_changed_transition_is_alarmed_after_the_change_not_before():
    """F's first entry 0.9 → −0.5 at step 300: with the threshold of max(GLR, CUSUM) set above
    20 fault-free records of 300 steps, the alarm comes after the change on every one of 20
    changed records, and before it on at most 2 of them."""
    F_after = F.copy()
    F_after[0, 0] = -0.5
    rng = np.random.default_rng(4)
    def statistic(y, u):
        z = whitened_innovations(NOMINAL, y, np.zeros(3), np.eye(3), u).z
        return np.maximum(glr_mean_shift(z, 20), cusum_variance(z, 3.0))

    clean = [statistic(*simulate(300, rng)) for _ in range(20)]
    threshold = 1.2 * max(c.max() for c in clean)
    early, delays = 0, []
    for _ in range(20):
        g = statistic(*simulate(600, rng, F_after, change=300))
        early += first_alarm(g[:300], threshold) >= 0
        delays.append(first_alarm(g[300:], threshold))
    assert early <= 2 and all(d >= 0 for d in delays)


@pytest.mark.parametrize("bad", [dict(variance_ratio=1.0), dict(variance_ratio=0.5)])
def test_cusum_refuses_a_ratio_that_is_not_a_growth(bad):
    with pytest.raises(ValueError, match="variance_ratio"):
        cusum_variance(np.zeros((3, 1)), **bad)


def test_first_alarm_and_glr_window_and_one_model_checks():
    assert first_alarm(np.array([0.0, 1.0, 3.0, 5.0]), 3.0) == 2
    assert first_alarm(np.zeros(5), 1.0) == -1
    with pytest.raises(ValueError, match="window"):
        glr_mean_shift(np.zeros((3, 1)), 0)
    batch = LinearGaussianBatch(np.stack([F, F]), Q, H, R)
    with pytest.raises(ValueError, match="one nominal model"):
        whitened_innovations(batch, np.zeros((2, 2)), np.zeros(3), np.eye(3))
