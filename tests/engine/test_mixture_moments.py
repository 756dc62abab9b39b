"""``rbpf.mixture_moments*`` against the Gaussian mixture itself and the law of total variance.

Two independent references: (1) a brute-force sample of Σ w_i N(x_i, P_i) (pick a component by
its weight, then draw from it), whose mean and standard deviation must agree within 5 standard
errors (false alarm ≈ 6e-7 per coordinate); (2) the law of total variance written in its raw
form, Var = Σ w_i (P_i,jj + x_i,j²) − (Σ w_i x_i,j)², summed with ``math.fsum`` in well-scaled
cases.  Deliberately wrong moment functions (weights ignored, the between-component spread left
out, std taken as the weighted mean of the component stds) are rejected by the same checks.
"""

import math

import numpy as np
import pytest

from railpaper.engine.rbpf import (
    mixture_moments,
    mixture_moments_steps,
    mixture_moments_var,
)


def mixture(seed: int, n_comp: int = 6, dim: int = 3):
    rng = np.random.default_rng(seed)
    w = rng.dirichlet(np.ones(n_comp))
    x = rng.normal(0.0, 2.0, (n_comp, dim))
    roots = rng.normal(0.0, 0.7, (n_comp, dim, dim))
    P = roots @ np.swapaxes(roots, 1, 2) + 0.05 * np.eye(dim)
    return w, x, P


def sample(w, x, P, size: int, seed: int) -> np.ndarray:
    """``size`` draws of the mixture: component by weight, then its Gaussian."""
    rng = np.random.default_rng(seed)
    comp = rng.choice(len(w), size=size, p=w)
    L = np.linalg.cholesky(P)
    z = rng.standard_normal((size, x.shape[1]))
    return x[comp] + np.einsum("kij,kj->ki", L[comp], z)


def total_variance(w, x, P) -> tuple[np.ndarray, np.ndarray]:
    """Mean and std by the raw law of total variance, each sum exactly rounded (fsum)."""
    d = x.shape[1]
    mean = np.array([math.fsum(w * x[:, j]) for j in range(d)])
    second = np.array([math.fsum(np.concatenate([w * P[:, j, j], w * x[:, j] ** 2]))
                       for j in range(d)])
    return mean, np.sqrt(second - mean ** 2)


def agrees_with_sample(moments, draws) -> bool:
    """Mean and std within 5 standard errors of the sample's (std's se ≈ √((m4 − s⁴)/n) / 2s)."""
    mean, std = moments
    n = len(draws)
    m, s = draws.mean(axis=0), draws.std(axis=0)
    m4 = np.mean((draws - m) ** 4, axis=0)
    se_std = np.sqrt((m4 - s ** 4) / n) / (2 * s)
    return bool(np.all(np.abs(mean - m) < 5 * s / np.sqrt(n))
                and np.all(np.abs(std - s) < 5 * se_std))


def wrong_unweighted(x, P, w):
    return mixture_moments(x, P, np.full(len(w), 1.0 / len(w)))


def wrong_no_spread(x, P, w):
    return w @ x, np.sqrt(w @ np.diagonal(P, axis1=1, axis2=2))


def wrong_mean_of_stds(x, P, w):
    return w @ x, w @ np.sqrt(np.diagonal(P, axis1=1, axis2=2))


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_mixture_moments_equal_a_brute_force_sample(seed):
    w, x, P = mixture(seed)
    draws = sample(w, x, P, 400_000, seed + 100)
    assert agrees_with_sample(mixture_moments(x, P, w), draws)
    for wrong in (wrong_unweighted, wrong_no_spread, wrong_mean_of_stds):
        assert not agrees_with_sample(wrong(x, P, w), draws), wrong.__name__


@pytest.mark.parametrize("seed", [3, 4, 5, 6])
def test_mixture_moments_equal_the_law_of_total_variance(seed):
    w, x, P = mixture(seed, n_comp=50, dim=4)
    mean, std = total_variance(w, x, P)
    got = mixture_moments(x, P, w)
    np.testing.assert_allclose(got[0], mean, rtol=1e-13, atol=1e-13)
    np.testing.assert_allclose(got[1], std, rtol=1e-12)
    got = mixture_moments_var(x, np.diagonal(P, axis1=1, axis2=2), w)
    np.testing.assert_allclose(got[1], std, rtol=1e-12)
    for wrong in (wrong_unweighted, wrong_no_spread, wrong_mean_of_stds):
        assert not np.allclose(wrong(x, P, w)[1], std, rtol=1e-6), wrong.__name__


def test_steps_at_once_equal_each_step_and_huge_states():
    """J steps with their own weights equal J separate mixtures; states of 1e160 (squares
    overflow) give the same moments as the mixture scaled down by 1e160 and back up."""
    rng = np.random.default_rng(7)
    J, N, d = 5, 30, 3
    x, var = rng.normal(0, 1, (N, J, d)), rng.uniform(0.1, 2.0, (N, J, d))
    w = rng.dirichlet(np.ones(N), size=J)
    mean, std = mixture_moments_steps(x, var, w)
    for j in range(J):
        P = np.stack([np.diag(v) for v in var[:, j]])
        m_ref, s_ref = total_variance(w[j], x[:, j], P)
        np.testing.assert_allclose(mean[j], m_ref, rtol=1e-12, atol=1e-13)
        np.testing.assert_allclose(std[j], s_ref, rtol=1e-12)
    big = 1e160                                    # (x - x̄)² overflows; variances 1e300
    mean_big, std_big = mixture_moments_steps(x * big, var * 1e300, w)
    assert np.all(np.isfinite(std_big))
    for j in range(J):
        P = np.stack([np.diag(v) for v in var[:, j] * 1e-20])       # = var 1e300 / big²
        m_ref, s_ref = total_variance(w[j], x[:, j], P)
        np.testing.assert_allclose(mean_big[j] / big, m_ref, rtol=1e-12, atol=1e-13)
        np.testing.assert_allclose(std_big[j] / big, s_ref, rtol=1e-12)
    # at 1e154 both the squares and the variances matter (var/scale² must not become var/inf)
    big = 2e154
    mean_big, std_big = mixture_moments_steps(x * big, var * (1e308 / var.max()), w)
    for j in range(J):
        P = np.stack([np.diag(v) for v in var[:, j] * (1e308 / var.max() / big / big)])
        m_ref, s_ref = total_variance(w[j], x[:, j], P)
        np.testing.assert_allclose(std_big[j] / big, s_ref, rtol=1e-12)
