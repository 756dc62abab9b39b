"""The exact change-time posterior against brute force: every hypothesis's likelihood computed
one filter at a time with its own time-varying matrices (a textbook Kalman loop written here),
and the posterior by direct enumeration."""

import numpy as np
import pytest

from railpaper.engine.changepoint import change_likelihoods, change_posterior
from railpaper.engine.linear_gaussian import LinearGaussianBatch

Q_VAR, R_VAR = 1.0, 0.1


def system(theta):
    """x_k = a x_{k−1} + b u_k + w, y_k = c x_k + e; θ = (a, c), b = 0.5."""
    theta = np.atleast_2d(theta)
    a, c = theta[:, 0], theta[:, 1]
    return LinearGaussianBatch(a[:, None, None], [[Q_VAR]], c[:, None, None], [[R_VAR]],
                               np.full((1, 1), 0.5))


def loglik_by_hand(y, u, thetas_per_step):
    """log p(y_1..k) for k = 1..K with θ of step k = thetas_per_step[k−1] (scalar filter)."""
    m, P, total, out = 0.0, 1.0, 0.0, []
    for yk, uk, (a, c) in zip(y[:, 0], u[:, 0], thetas_per_step):
        m, P = a * m + 0.5 * uk, a * a * P + Q_VAR
        S, v = c * c * P + R_VAR, yk - c * m
        total += -0.5 * (np.log(2 * np.pi * S) + v * v / S)
        K = P * c / S
        m, P = m + K * v, (1 - K * c) * P
        out.append(total)
    return np.array(out)


def record(K=80, tau=41, seed=0):
    rng = np.random.default_rng(seed)
    u = rng.standard_normal((K, 1))
    x, y = 0.0, np.empty((K, 1))
    for k in range(1, K + 1):
        a, c = (0.9, 1.0) if k < tau else (0.3, 0.6)
        x = a * x + 0.5 * u[k - 1, 0] + rng.standard_normal()
        y[k - 1] = c * x + np.sqrt(R_VAR) * rng.standard_normal()
    return y, u


def test_every_hypothesis_likelihood_equals_its_own_filter():
    y, u = record()
    before, after = np.array([0.9, 1.0]), np.array([[0.3, 0.6], [0.5, 1.0]])
    taus = np.array([2, 10, 41, 60, 80])
    lik = change_likelihoods(system, y, before, after, taus, np.zeros(1), np.eye(1), u=u)
    K = len(y)
    np.testing.assert_allclose(lik.no_change, loglik_by_hand(y, u, [before] * K), rtol=1e-12)
    for v, th in enumerate(after):
        for j, tau in enumerate(taus):
            steps = [before if k < tau else th for k in range(1, K + 1)]
            np.testing.assert_allclose(lik.changed[v, j], loglik_by_hand(y, u, steps),
                                       rtol=1e-12, atol=1e-9)
    assert lik.filter_steps == K + sum(2 * (K - tau + 1) for tau in taus)


def test_posterior_equals_direct_enumeration_and_finds_the_change():
    y, u = record()
    before, after = np.array([0.9, 1.0]), np.array([[0.3, 0.6], [0.5, 1.0]])
    taus = np.arange(5, 76, 3)
    lik = change_likelihoods(system, y, before, after, taus, np.zeros(1), np.eye(1), u=u)
    post = change_posterior(lik, p_no_change=0.3)
    V, J, K = lik.changed.shape
    prior = 0.7 / (V * J)
    for k in (4, 20, 40, 45, 79):                           # P(τ ≤ k | y_1..k) by enumeration
        num = sum(prior * np.exp(lik.changed[v, j, k - 1]) for v in range(V) for j in range(J)
                  if taus[j] <= k)
        den = num + (0.3 + prior * V * np.sum(taus > k)) * np.exp(lik.no_change[k - 1])
        assert post.p_changed[k - 1] == pytest.approx(num / den, rel=1e-9, abs=1e-300)
    joint = np.exp(lik.changed[:, :, -1] - lik.changed[:, :, -1].max())
    np.testing.assert_allclose(post.tau_posterior, joint.sum(axis=0) / joint.sum(), rtol=1e-12)
    assert post.p_changed[20] < 0.5 < post.p_changed[-1]
    assert abs(taus[np.argmax(post.tau_posterior)] - 41) <= 3
    assert np.argmax(post.value_posterior) == 0


def test_bad_grids_are_refused():
    y, u = record(K=20)
    for taus in ([1, 5], [5, 5], [3, 21], []):
        with pytest.raises(ValueError, match="tau_steps"):
            change_likelihoods(system, y, [0.9, 1.0], [[0.3, 0.6]], taus, np.zeros(1),
                               np.eye(1), u=u)
    lik = change_likelihoods(system, y, [0.9, 1.0], [[0.3, 0.6]], [5], np.zeros(1), np.eye(1),
                             u=u)
    with pytest.raises(ValueError, match="p_no_change"):
        change_posterior(lik, p_no_change=1.0)
