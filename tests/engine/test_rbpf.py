"""RBPF engine, Q-GRBPF and the exact grid posterior against independent references."""

import numpy as np
import pytest
from filterpy.kalman import KalmanFilter
from scipy.stats import multivariate_normal

from railpaper.engine.grid_posterior import (
    box_grid,
    grid_posterior,
    kalman_log_likelihoods,
)
from railpaper.engine.qgrbpf import QuasiGaussianRBPF, run_qgrbpf
from railpaper.engine.rbpf import run_rbpf
from railpaper.experiments.base import check_metrics
from railpaper.models.linear_toys import (
    EQ18_G,
    EQ18_H,
    PAPER004_G,
    PAPER004_H,
    eq18_system,
    paper004_system,
    simulate_eq18,
    simulate_paper004,
)

Q_VAR = R_VAR = 0.001
P0 = 0.05 ** 2 * np.eye(2)


@pytest.fixture(scope="module")
def record():
    return simulate_paper004(-0.7, 1.5, Q_VAR, R_VAR, 0.05, 40, np.random.default_rng(11))


def filterpy_states(F, G, H, Qw, R, y, P0, B=None, u=None):
    kf = KalmanFilter(dim_x=2, dim_z=H.shape[0], dim_u=0 if B is None else B.shape[1])
    kf.x, kf.P, kf.F, kf.Q, kf.H, kf.R = np.zeros(2), P0.copy(), F, G @ Qw @ G.T, H, R
    if B is not None:
        kf.B = B
    out = []
    for k in range(len(y)):
        kf.predict(u=None if u is None else u[k])
        kf.update(y[k])
        out.append(kf.x.copy())
    return np.array(out)


@pytest.mark.parametrize("options", [dict(scheme="paper", move=False),
                                     dict(scheme="paper", delta=1.0),
                                     dict(scheme="working", move=False)])
def test_rbpf_at_true_parameters_equals_one_kalman_filter(record, options):
    theta = np.tile([-0.7, 1.5], (25, 1))
    run = run_rbpf(paper004_system(Q_VAR, R_VAR), record.y, theta, np.zeros(2), P0,
                   np.random.default_rng(0), **options)
    F = np.array([[0.0, 1.0], [-0.7, 1.5]])
    ref = filterpy_states(F, PAPER004_G, PAPER004_H, Q_VAR * np.eye(2), R_VAR * np.eye(2),
                          record.y, P0)
    np.testing.assert_allclose(run.x_mean, ref, atol=1e-10, rtol=0)
    np.testing.assert_allclose(run.theta_mean, np.tile([-0.7, 1.5], (len(record.y), 1)), atol=1e-12)
    np.testing.assert_allclose(run.theta_std, 0.0, atol=1e-12)


@pytest.mark.parametrize("engine", ["compiled", "numpy"])
def test_working_scheme_tempers_the_likelihood_by_k_over_T(record, engine):
    """The working scheme's weights are exp(Σ_j min(1, j / T) log p(y_j | y_1..j−1, θ_i)) over
    the first T steps, then the plain likelihood: computed here from one filterpy filter per
    particle.  No resampling (ESS threshold 0) and no move, so the weights carry the whole
    schedule; a changed schedule (j − 1, (j / T)², another T) fails this test."""
    T, K = 15, len(record.y)
    theta = np.column_stack([np.linspace(-0.9, -0.5, 12), np.linspace(1.3, 1.7, 12)])
    run = run_rbpf(paper004_system(Q_VAR, R_VAR), record.y, theta, np.zeros(2), P0,
                   np.random.default_rng(0), scheme="working", move=False, ess_fraction=0.0,
                   tempering_steps=T, engine=engine)
    loglik = np.empty((len(theta), K))
    for i, (a, b) in enumerate(theta):
        kf = KalmanFilter(dim_x=2, dim_z=2)
        kf.x, kf.P, kf.F = np.zeros(2), P0.copy(), np.array([[0.0, 1.0], [a, b]])
        kf.Q, kf.H, kf.R = PAPER004_G @ (Q_VAR * np.eye(2)) @ PAPER004_G.T, PAPER004_H, R_VAR * np.eye(2)
        for k in range(K):
            kf.predict()
            kf.update(record.y[k])
            loglik[i, k] = kf.log_likelihood
    beta = np.minimum(1.0, np.arange(1, K + 1) / T)
    log_w = np.cumsum(beta * loglik, axis=1)                               # (N, K)
    w = np.exp(log_w - log_w.max(axis=0))
    w /= w.sum(axis=0)
    assert not run.resampled.any()
    np.testing.assert_allclose(run.theta_mean, w.T @ theta, rtol=0, atol=1e-9)
    assert np.isnan(run.log_evidence[:T - 1]).all()              # β < 1: no evidence
    assert np.isfinite(run.log_evidence[T - 1:]).all()


def test_rbpf_with_known_input_eq18_equals_kalman_filter():
    truth = np.array([-0.3, 0.6, 0.5, -0.4])
    sim = simulate_eq18(truth, 0.1, 0.1, 30, np.random.default_rng(2), p0_std=0.1)
    P0_18 = 0.01 * np.eye(2)
    run = run_rbpf(eq18_system(0.1, 0.1), sim.y, np.tile(truth, (10, 1)), np.zeros(2), P0_18,
                   np.random.default_rng(0), move=False, u=sim.u)
    F = np.array([[0.0, 1.5], [truth[0], truth[1]]])
    B = truth[2:, None]
    ref = filterpy_states(F, EQ18_G, EQ18_H, np.array([[0.1]]), np.array([[0.1]]), sim.y,
                          P0_18, B=B, u=sim.u)
    np.testing.assert_allclose(run.x_mean, ref, atol=1e-10, rtol=0)


@pytest.mark.parametrize("runner, options", [(run_rbpf, dict(scheme="paper")),
                                             (run_rbpf, dict(scheme="working")),
                                             (run_qgrbpf, dict()),
                                             (run_qgrbpf, dict(weighting="printed"))])
def test_filters_bit_identical_for_the_same_seed(record, runner, options):
    system = paper004_system(Q_VAR, R_VAR)
    theta0 = np.random.default_rng(3).uniform([-1.0, 1.0], [0.4, 2.8], (50, 2))
    a = runner(system, record.y, theta0, np.zeros(2), P0, np.random.default_rng(7), **options)
    b = runner(system, record.y, theta0, np.zeros(2), P0, np.random.default_rng(7), **options)
    for field in ("theta_mean", "theta_std", "x_mean", "ess", "theta", "weights"):
        np.testing.assert_array_equal(getattr(a, field), getattr(b, field))


def test_qgrbpf_moment_step_is_weighted_mean_and_cov(record):
    theta0 = np.random.default_rng(4).uniform([-1.0, 1.0], [0.4, 2.8], (60, 2))
    filt = QuasiGaussianRBPF(paper004_system(Q_VAR, R_VAR), theta0, np.zeros(2), P0,
                             np.random.default_rng(5), weight_threshold=0.0)
    out = filt.step(record.y[0])
    loglik = []
    for a, b in theta0:                    # Eqs. 3-5 per particle with scipy
        F = np.array([[0.0, 1.0], [a, b]])
        P_prior = F @ P0 @ F.T + PAPER004_G @ PAPER004_G.T * Q_VAR
        S = PAPER004_H @ P_prior @ PAPER004_H.T + R_VAR * np.eye(2)
        loglik.append(multivariate_normal(np.zeros(2), S).logpdf(record.y[0]))
    w = np.exp(np.array(loglik) - max(loglik))
    w /= w.sum()
    np.testing.assert_allclose(out.theta_mean, np.average(theta0, axis=0, weights=w),
                               atol=1e-12)
    cov = np.cov(theta0.T, aweights=w, bias=True)
    np.testing.assert_allclose(out.theta_std, np.sqrt(np.diag(cov)), atol=1e-12)


def joint_log_likelihood(theta, y, x0_cov):
    """log p(y_1..K | θ) from the stacked joint Gaussian of all measurements (no Kalman filter)."""
    a, b = theta
    F = np.array([[0.0, 1.0], [a, b]])
    Qx = PAPER004_G @ (Q_VAR * np.eye(2)) @ PAPER004_G.T
    K = len(y)
    powers = [np.linalg.matrix_power(F, k) for k in range(K + 1)]
    cov_x = np.zeros((2 * K, 2 * K))          # Cov(x_k, x_l), k, l = 1..K
    for k in range(1, K + 1):
        for l in range(1, K + 1):
            c = powers[k] @ x0_cov @ powers[l].T
            for j in range(1, min(k, l) + 1):
                c = c + powers[k - j] @ Qx @ powers[l - j].T
            cov_x[2 * k - 2: 2 * k, 2 * l - 2: 2 * l] = c
    Hs = np.kron(np.eye(K), PAPER004_H)
    cov_y = Hs @ cov_x @ Hs.T + R_VAR * np.eye(2 * K)
    return multivariate_normal(np.zeros(2 * K), cov_y).logpdf(y.ravel())


def test_grid_likelihood_equals_joint_gaussian(record):
    y = record.y[:6]
    points = np.array([[-0.7, 1.5], [0.2, 2.5], [-0.95, 1.05], [0.35, 2.75]])
    ll = kalman_log_likelihoods(paper004_system(Q_VAR, R_VAR), y, points, np.zeros(2), P0)
    assert ll.shape == (6, 4)
    for g, theta in enumerate(points):
        assert ll[:, g].sum() == pytest.approx(joint_log_likelihood(theta, y, P0), abs=1e-9)


def test_grid_posterior_moments_equal_brute_force(record):
    y = record.y[:5]
    lower, upper = np.array([-1.0, 1.0]), np.array([0.4, 2.8])
    post = grid_posterior(paper004_system(Q_VAR, R_VAR), y, lower, upper, 5, np.zeros(2), P0)
    points, _ = box_grid(lower, upper, 5)
    logp = np.array([joint_log_likelihood(t, y, P0) for t in points])
    w = np.exp(logp - logp.max())
    w /= w.sum()
    np.testing.assert_allclose(post.mean[-1], w @ points, atol=1e-10)
    np.testing.assert_allclose(post.std[-1], np.sqrt(w @ (points - w @ points) ** 2), atol=1e-10)


def test_working_rbpf_agrees_with_exact_posterior():
    sim = simulate_paper004(-0.7, 1.5, Q_VAR, R_VAR, 0.05, 120, np.random.default_rng(21))
    lower, upper = np.array([-1.0, 1.0]), np.array([0.4, 2.8])
    system = paper004_system(Q_VAR, R_VAR)
    post = grid_posterior(system, sim.y, lower, upper, 41, np.zeros(2), P0)
    theta0 = np.random.default_rng(22).uniform(lower, upper, (400, 2))
    run = run_rbpf(system, sim.y, theta0, np.zeros(2), P0, np.random.default_rng(23),
                   scheme="working")
    z = (run.theta_mean[-1] - post.mean[-1]) / post.std[-1]
    assert np.all(np.abs(z) < 1.5)
    assert np.all(np.abs(run.theta_std[-1] / post.std[-1] - 1) < 0.5)


def test_experiment_smoke():
    from railpaper.experiments.quasi_gaussian_rbpf import experiment as chapter

    settings = chapter.SPEC.resolve(dict(n_particles=30, n_steps=12, grid_size=9, n_monte_carlo=2,
                                         timing_particles=[10, 20], timing_steps=3), quick=True)
    a = chapter.run(settings)
    b = chapter.run(settings)
    assert check_metrics(a.metrics) == check_metrics(b.metrics)
    required = ["step", "y1", "y2", "a_est_rbpf", "b_est_rbpf", "a_est_qgrbpf", "b_est_qgrbpf",
                "a_post_mean", "b_post_mean", "a_post_std", "b_post_std"]
    assert list(a.timeseries.columns[: len(required)]) == required
    assert len(a.timeseries) == 12
    for key in ("convergence_step_a_rbpf", "convergence_step_a_qgrbpf", "final_error_b_qgrbpf",
                "final_z_a_rbpf", "mc_median_convergence_step_b_qgrbpf"):
        assert key in a.metrics
    assert "time_ratio_qgrbpf_over_rbpf" in a.timings
    assert a.timings["seconds_per_step_qgrbpf_N20"] > 0
    with pytest.raises(chapter.ParameterError):
        chapter.run(settings.replace(a_true=0.9))


def test_parameters_toml_matches_spec_defaults():
    from railpaper.data import data_path, load_quantities
    from railpaper.experiments.quasi_gaussian_rbpf import experiment as chapter

    quantities = load_quantities(data_path("quasi-gaussian-rbpf/parameters.toml"))
    defaults = chapter.SPEC.defaults()
    for key, quantity in quantities.items():
        assert defaults[key] == pytest.approx(quantity.value), key
