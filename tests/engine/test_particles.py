"""Particle building blocks against closed forms and numpy references."""

import numpy as np
import pytest

from railpaper.engine.particles import (
    effective_sample_size,
    gaussian_draws,
    liu_west_move,
    liu_west_shrinkage,
    multinomial_search_resample,
    normalise_log_weights,
    systematic_resample,
    weighted_mean_cov,
)


def test_systematic_resample_never_indexes_past_last():
    rng = np.random.default_rng(0)
    n = 1000
    w = np.full(n, 1.0 / n)
    w[-1] = 0.0                           # cumsum < 1 and a zero-weight last particle
    w *= 1 - 1e-12                        # total short of one, as by rounding
    assert np.cumsum(w)[-1] < 1.0
    for _ in range(200):
        idx = systematic_resample(w, rng)
        assert idx.min() >= 0 and idx.max() <= n - 1 and len(idx) == n
        idx = multinomial_search_resample(w, rng)
        assert idx.max() <= n - 1


class AlmostOne:
    """A generator stub whose uniforms are the largest double below 1."""

    def random(self, size=None):
        u = np.nextafter(1.0, 0.0)
        return u if size is None else np.full(size, u)


def test_resample_clips_points_rounding_to_one():
    w = np.array([0.3, 0.3, 0.4 - 1e-15])
    assert systematic_resample(w, AlmostOne()).max() == 2
    assert multinomial_search_resample(w, AlmostOne()).max() == 2


def test_systematic_resample_counts_are_floor_or_ceil():
    rng = np.random.default_rng(1)
    w = rng.random(50)
    w /= w.sum()
    counts = np.bincount(systematic_resample(w, rng), minlength=50)
    assert np.all(np.abs(counts - 50 * w) < 1 + 1e-9)


def test_systematic_resample_of_fewer_draws_keeps_floor_or_ceil_counts():
    """M < N draws (waste-free chain starts): each count is floor or ceil of M w_i."""
    rng = np.random.default_rng(3)
    w = rng.random(200)
    w /= w.sum()
    for m in (1, 40, 125):
        counts = np.bincount(systematic_resample(w, rng, m), minlength=200)
        assert counts.sum() == m and np.all(np.abs(counts - m * w) < 1 + 1e-9)
    with pytest.raises(ValueError, match="size"):
        systematic_resample(w, rng, 0)


def test_multinomial_search_follows_cdf_rule():
    w = np.array([0.1, 0.0, 0.6, 0.3])
    rng = np.random.default_rng(2)
    idx = multinomial_search_resample(w, rng, n_draws=20000)
    assert not np.any(idx == 1)
    np.testing.assert_allclose(np.bincount(idx, minlength=4) / 20000, w, atol=0.015)


@pytest.mark.parametrize("log_w, expected_flag", [
    (np.array([-np.inf, -np.inf, -np.inf]), True),
    (np.array([np.nan, np.nan, np.nan]), True),
    (np.array([1e308, -1e308, 0.0]), False),
    (np.array([-1e5, -1e5 - 1, np.nan]), False),
    (np.array([np.inf, 0.0, np.inf]), True),
])
def test_normalise_log_weights_never_nan(log_w, expected_flag):
    w, log_norm, flag = normalise_log_weights(log_w)
    assert not np.any(np.isnan(w)) and not np.isnan(log_norm)
    assert w.sum() == pytest.approx(1.0)
    assert flag is expected_flag


def test_normalise_log_weights_matches_direct_and_ess():
    lw = np.log(np.array([1.0, 2.0, 3.0, 4.0])) - 700.0
    w, log_norm, flag = normalise_log_weights(lw)
    np.testing.assert_allclose(w, np.array([1, 2, 3, 4]) / 10.0, rtol=1e-13)
    assert log_norm == pytest.approx(np.log(10.0) - 700.0, rel=1e-14)
    assert not flag
    assert effective_sample_size(w) == pytest.approx(1.0 / np.sum((np.array([1, 2, 3, 4]) / 10) ** 2))
    assert effective_sample_size(np.full(8, 1 / 8)) == pytest.approx(8.0)


def test_weighted_mean_cov_equals_numpy_cov_with_aweights():
    rng = np.random.default_rng(3)
    theta = rng.standard_normal((40, 3))
    w = rng.random(40)
    w /= w.sum()
    mean, cov = weighted_mean_cov(theta, w)
    np.testing.assert_allclose(mean, np.average(theta, axis=0, weights=w), atol=1e-14)
    np.testing.assert_allclose(cov, np.cov(theta.T, aweights=w, bias=True), atol=1e-14)


def test_liu_west_constants():
    for delta in (0.9, 0.95, 0.98, 0.99, 1.0):
        a, h2 = liu_west_shrinkage(delta)
        assert a == pytest.approx((3 * delta - 1) / (2 * delta))
        assert a ** 2 + h2 == pytest.approx(1.0)


def test_liu_west_preserves_weighted_mean_and_covariance_in_expectation():
    rng = np.random.default_rng(4)
    theta = rng.standard_normal((200, 2)) @ np.array([[1.0, 0.5], [0.0, 0.3]]) + [2.0, -1.0]
    w = rng.random(200)
    w /= w.sum()
    mean, cov = weighted_mean_cov(theta, w)
    moved = np.stack([liu_west_move(theta, w, 0.9, rng) for _ in range(2000)])  # (R, N, d)
    # E[θ'] = a θ_i + (1−a) θ̄ for every particle, so the weighted mean is kept
    np.testing.assert_allclose(np.einsum("n,rnd->d", w, moved) / 2000, mean, atol=3e-3)
    # E[Σ w (θ'−θ̄)(θ'−θ̄)ᵀ] = a² V + h² V = V
    centred = moved - mean
    cov_moved = np.einsum("n,rnd,rne->de", w, centred, centred) / 2000
    np.testing.assert_allclose(cov_moved, cov, rtol=0.03, atol=1e-3)


def test_liu_west_delta_one_is_identity_and_transform_is_equivariant():
    rng = np.random.default_rng(5)
    theta = rng.random((30, 2)) + 1.0
    w = np.full(30, 1 / 30)
    np.testing.assert_allclose(liu_west_move(theta, w, 1.0, rng), theta, atol=1e-15)
    plain = liu_west_move(theta, w, 0.95, np.random.default_rng(9))
    scaled = liu_west_move(theta, w, 0.95, np.random.default_rng(9),
                           offset=np.array([1.5, 1.5]), scale=np.array([0.3, 0.3]))
    np.testing.assert_allclose(plain, scaled, atol=1e-12)
    positive = liu_west_move(theta * 1e-3, w, 0.6, rng, log_mask=np.array([True, True]))
    assert np.all(positive > 0)


def test_gaussian_draws_singular_covariance():
    rng = np.random.default_rng(6)
    draws = gaussian_draws(np.array([1.0, 2.0]), np.zeros((2, 2)), 5, rng)
    np.testing.assert_array_equal(draws, np.tile([1.0, 2.0], (5, 1)))
    cov = np.array([[2.0, 0.6], [0.6, 0.5]])
    many = gaussian_draws(np.zeros(2), cov, 200000, rng)
    np.testing.assert_allclose(np.cov(many.T), cov, rtol=0.02)
