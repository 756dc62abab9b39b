"""The exact change-time posterior against brute force: every hypothesis's likelihood computed
one filter at a time with its own time-varying matrices (a textbook Kalman loop written here),
and the posterior by direct enumeration."""

import math

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


# ---- the on-line statistics: mixture Shiryaev-Roberts and window-limited GLR ------------------

def _random_likelihoods(seed=0, V=3, J=5, K=12):
    """Cumulative log-likelihoods that obey the definition: equal to no-change before τ_j, then
    no-change plus a random log-likelihood ratio accumulated from τ_j on."""
    from railpaper.engine import ChangeLikelihoods
    rng = np.random.default_rng(seed)
    no_change = np.cumsum(rng.normal(-1.0, 0.3, K))
    tau = np.sort(rng.choice(np.arange(1, K + 1), J, replace=False))
    steps = np.arange(1, K + 1)
    changed = np.empty((V, J, K))
    for v in range(V):
        for j, t in enumerate(tau):
            gain = np.cumsum(np.where(steps >= t, rng.normal(0.2, 0.5, K), 0.0))
            changed[v, j] = no_change + gain
    return ChangeLikelihoods(no_change, changed, tau, np.zeros((V, 1)), 0)


@pytest.mark.parametrize("window", [None, 1, 3, 7, 100])
def test_shiryaev_roberts_and_glr_equal_their_brute_force_sums(window):
    from railpaper.engine import change_statistics
    lik = _random_likelihoods()
    V, J, K = lik.changed.shape
    prior = np.array([0.5, 0.3, 0.2])
    stats = change_statistics(lik, window, prior)
    for k in range(1, K + 1):
        terms, ratios = [], []
        for j, t in enumerate(lik.tau_steps):
            if t <= k and (window is None or t > k - window):
                for v in range(V):
                    ratio = lik.changed[v, j, k - 1] - lik.no_change[k - 1]
                    terms.append(prior[v] * math.exp(ratio))
                    ratios.append(ratio)
        if terms:
            assert stats.log_shiryaev_roberts[k - 1] == pytest.approx(math.log(sum(terms)),
                                                                     rel=1e-12)
            assert stats.glr[k - 1] == max(ratios)
        else:
            assert stats.log_shiryaev_roberts[k - 1] == -math.inf and stats.glr[k - 1] == -math.inf


def test_the_window_only_drops_old_changes():
    """Windowed R_k <= full R_k at every step, equal while k <= W; W >= K is the full statistic;
    the GLR likewise (a maximum over fewer hypotheses)."""
    from railpaper.engine import change_statistics
    lik = _random_likelihoods(seed=4, K=20)
    full = change_statistics(lik)
    for window in (2, 5, 9):
        part = change_statistics(lik, window)
        assert np.all(part.log_shiryaev_roberts <= full.log_shiryaev_roberts + 1e-12)
        assert np.all(part.glr <= full.glr)
        np.testing.assert_array_equal(part.log_shiryaev_roberts[:window],
                                      full.log_shiryaev_roberts[:window])
    np.testing.assert_array_equal(change_statistics(lik, 20).glr, full.glr)
    with pytest.raises(ValueError, match="window_steps"):
        change_statistics(lik, 0)


def test_statistics_rise_after_a_real_change_of_an_ar1():
    """The module's AR(1) example (0.9 -> -0.5 at step 60): before the change both statistics
    stay low; inside the window after it the GLR passes 10 (nats) and R_k grows by more than
    e^5."""
    from railpaper.engine import change_likelihoods, change_statistics
    from railpaper.engine.linear_gaussian import LinearGaussianBatch

    def system(theta):
        a = np.atleast_2d(theta)[:, 0]
        return LinearGaussianBatch(a[:, None, None], [[1.0]], [[1.0]], [[0.1]])
    rng = np.random.default_rng(3)
    x, y = 0.0, []
    for k in range(1, 121):
        x = (0.9 if k < 60 else -0.5) * x + rng.standard_normal()
        y.append(x + np.sqrt(0.1) * rng.standard_normal())
    lik = change_likelihoods(system, np.array(y)[:, None], [0.9], [[-0.5], [0.0]],
                             np.arange(2, 121), np.zeros(1), np.eye(1))
    stats = change_statistics(lik, window_steps=30)
    before, after = slice(0, 55), slice(62, 89)         # steps 1-55; 63-89, inside the window
    assert stats.glr[before].max() < 5.0 < 10.0 < stats.glr[after].min()
    assert stats.log_shiryaev_roberts[after].min() - stats.log_shiryaev_roberts[before].max() > 5
    # 60 steps after the change it has left the 30-step window; the full statistic keeps it
    assert stats.glr[-1] < change_statistics(lik).glr[-1]


def _two_state_system(theta):
    """A two-state model whose transition's first row is θ (a, b), with an input: enough
    structure for the bank's ring of restarted filters to be tested against the full bank."""
    from railpaper.engine.linear_gaussian import LinearGaussianBatch
    th = np.atleast_2d(theta)
    F = np.zeros((len(th), 2, 2))
    F[:, 0, 0], F[:, 0, 1], F[:, 1, 1] = th[:, 0], th[:, 1], 0.5
    return LinearGaussianBatch(F, 0.3 * np.eye(2), [[1.0, 0.2]], [[0.1]],
                               np.ones((len(th), 2, 1)))


@pytest.mark.parametrize("window,first", [(1, 2), (4, 2), (7, 10), (60, 10)])
def test_windowed_bank_equals_the_full_bank_with_its_window(window, first):
    """windowed_change_statistics (V W filters in a ring, restarted from the no-change filter)
    against change_likelihoods over every step from ``first`` on followed by
    change_statistics with the same window and prior: the same log R_k and g_k (1e-10 nats);
    the GLR's argmax (value and change step) is the brute-force one; −inf before ``first``."""
    from railpaper.engine import change_likelihoods, change_statistics, windowed_change_statistics
    rng = np.random.default_rng(3)
    K = 60
    y, u = rng.standard_normal((K, 1)), rng.standard_normal((K, 1))
    after = np.array([[0.5, 0.1], [-0.3, 0.4], [0.9, -0.2]])
    prior = np.array([0.5, 0.3, 0.2])
    bank = windowed_change_statistics(_two_state_system, y, [0.8, 0.0], after, window,
                                      np.zeros(2), np.eye(2), u=u, first_change_step=first,
                                      prior=prior)
    lik = change_likelihoods(_two_state_system, y, [0.8, 0.0], after, np.arange(first, K + 1),
                             np.zeros(2), np.eye(2), u=u)
    full = change_statistics(lik, window, prior)
    rows = slice(first - 1, K)
    np.testing.assert_allclose(bank.log_shiryaev_roberts[rows], full.log_shiryaev_roberts[rows],
                               rtol=0, atol=1e-10)
    np.testing.assert_allclose(bank.glr[rows], full.glr[rows], rtol=0, atol=1e-10)
    assert np.all(np.isneginf(bank.glr[:first - 1])) and np.all(bank.glr_value[:first - 1] == -1)
    for k in (first, K // 2 + 3, K):                     # the maximum's (v, τ) by enumeration
        ratio = lik.changed[:, :, k - 1] - lik.no_change[k - 1]
        live = (lik.tau_steps <= k) & (lik.tau_steps > k - window)
        v, j = np.unravel_index(np.argmax(np.where(live[None], ratio, -np.inf)), ratio.shape)
        assert (bank.glr_value[k - 1], bank.glr_change_step[k - 1]) == (v, lik.tau_steps[j])
    assert bank.filter_steps == 3 * window * (K - first + 1) + K
    with pytest.raises(ValueError, match="window_steps"):
        windowed_change_statistics(_two_state_system, y, [0.8, 0.0], after, 0, np.zeros(2),
                                   np.eye(2))
