"""Every resampling scheme is unbiased: E[offspring count of particle i] = M w_i.

Over R independent resamplings (one generator, fixed seed) each particle's mean offspring count
is compared with M w_i by a z statistic with the counts' own standard error (the schemes have
different variances: systematic counts are ⌊M w_i⌋ or ⌈M w_i⌉, multinomial ones binomial).  The
family-wise false-alarm level is ALPHA over all particles (Bonferroni): an unbiased scheme fails
with probability < ALPHA for a random seed.  For multinomial draws the pooled counts are exactly
Multinomial(R M, w), so Pearson's χ² with N−1 degrees of freedom is checked as well.  Each test
also runs deliberately biased resamplers and requires the same statistics to reject them.
"""

import numpy as np
import pytest
from scipy import stats

from railpaper.engine.particles import multinomial_search_resample, systematic_resample

ALPHA = 1e-3                       # family-wise false-alarm level of each check
R = 20_000                         # resamplings per check
N = 40                             # particles


def weights(seed: int = 3) -> np.ndarray:
    """Uneven weights (Dirichlet(0.7)), none with an integer M w_i (then systematic is exact)."""
    w = np.random.default_rng(seed).dirichlet(np.full(N, 0.7))
    return w / w.sum()


def offspring(resampler, w: np.ndarray, seed: int) -> np.ndarray:
    """(R, N) offspring counts of R resamplings."""
    rng = np.random.default_rng(seed)
    return np.stack([np.bincount(resampler(w, rng), minlength=len(w)) for _ in range(R)])


def z_rejects(counts: np.ndarray, expected: np.ndarray) -> bool:
    """Bonferroni z test of mean counts == expected at family-wise level ALPHA."""
    mean, se = counts.mean(axis=0), counts.std(axis=0, ddof=1) / np.sqrt(len(counts))
    z = np.abs(mean - expected) / np.where(se > 0, se, np.inf)
    exact_miss = (se == 0) & (mean != expected)          # a never-varying count must be exact
    return bool(np.any(z > stats.norm.isf(ALPHA / (2 * counts.shape[1]))) or exact_miss.any())


def chi2_rejects(counts: np.ndarray, w: np.ndarray) -> bool:
    """Pearson χ² of the pooled counts against Multinomial(total, w) at level ALPHA."""
    pooled = counts.sum(axis=0)
    return bool(stats.chisquare(pooled, pooled.sum() * w).pvalue < ALPHA)


# --- deliberately biased resamplers (each must be rejected) ---------------------------------

def tempered_systematic(w, rng):                 # resamples w^1.1: favours heavy particles
    return systematic_resample(w ** 1.1 / np.sum(w ** 1.1), rng)


def short_offset_systematic(w, rng):             # offset U(0, 0.9) instead of U(0, 1)
    n = len(w)
    points = (0.9 * rng.random() + np.arange(n)) / n
    return np.minimum(np.searchsorted(np.cumsum(w), points, side="right"), n - 1)


def shifted_multinomial(w, rng, n_draws=None):    # off by one on the CDF (uses w_{i-1})
    return np.minimum(multinomial_search_resample(np.roll(w, 1), rng, n_draws), len(w) - 1)


def tempered_multinomial(w, rng, n_draws=None):
    return multinomial_search_resample(w ** 1.05 / np.sum(w ** 1.05), rng, n_draws)


def test_systematic_is_unbiased_and_the_test_has_power():
    w = weights()
    assert not z_rejects(offspring(systematic_resample, w, 1), N * w)
    for biased in (tempered_systematic, short_offset_systematic):
        assert z_rejects(offspring(biased, w, 1), N * w), biased.__name__


@pytest.mark.parametrize("n_draws", [None, 3 * N])
def test_multinomial_search_is_unbiased_and_the_test_has_power(n_draws):
    w = weights()
    M = N if n_draws is None else n_draws

    def scheme(f):
        return lambda w, rng: f(w, rng, n_draws)

    counts = offspring(scheme(multinomial_search_resample), w, 2)
    assert counts.sum(axis=1).tolist() == [M] * R
    assert not z_rejects(counts, M * w)
    assert not chi2_rejects(counts, w)
    for biased in (shifted_multinomial, tempered_multinomial):
        wrong = offspring(scheme(biased), w, 2)
        assert z_rejects(wrong, M * w), biased.__name__
        assert chi2_rejects(wrong, w), biased.__name__


def test_a_single_heavy_particle_and_tiny_weights():
    """Extreme weights: one particle of weight 1 − 1e-9 gets all offspring (systematic: exactly
    N; multinomial: mean N up to its binomial error); the rest almost never."""
    w = np.full(N, 1e-9 / (N - 1))
    w[7] = 1.0 - 1e-9
    rng = np.random.default_rng(5)
    for _ in range(200):
        assert np.bincount(systematic_resample(w, rng), minlength=N)[7] == N
        assert np.bincount(multinomial_search_resample(w, rng), minlength=N)[7] >= N - 1
