"""Particle-filter building blocks: weights, resampling, moments, Gaussian draws, Liu–West move.

All functions are vectorised over particles (axis 0) and draw randomness only from a
``numpy.random.Generator`` passed in.
"""

from __future__ import annotations

import numpy as np

from railpaper.engine.kalman import gaussian_logpdf


def normalise_log_weights(log_weights: np.ndarray) -> tuple[np.ndarray, float, bool]:
    """Normalised weights from log weights by log-sum-exp, without NaN.

    Parameters
    ----------
    log_weights : ndarray, shape (N,)
        Unnormalised log weights (natural log). NaN counts as −inf (a particle the model
        cannot explain).

    Returns
    -------
    weights : ndarray, shape (N,)
        Non-negative, summing to one.
    log_normaliser : float
        ``log Σ exp(log_weights)`` (−inf when every weight is zero, +inf when one is +inf).
    degenerate : bool
        True when the weights could not be normalised in the ordinary way: every weight was
        −inf/NaN (uniform weights are returned) or some were +inf (uniform over those).
    """
    lw = np.asarray(log_weights, dtype=float)
    lw = np.where(np.isnan(lw), -np.inf, lw)
    n = lw.shape[0]
    top = np.max(lw)
    if np.isposinf(top):
        inf = np.isposinf(lw)
        return inf / np.count_nonzero(inf), float("inf"), True
    if np.isneginf(top):
        return np.full(n, 1.0 / n), float("-inf"), True
    with np.errstate(over="ignore"):              # −1e308 − top → −inf → weight 0
        shifted = np.exp(lw - top)                # largest term is exactly 1: no overflow
    total = np.sum(shifted)
    return shifted / total, float(top + np.log(total)), False


def effective_sample_size(weights: np.ndarray) -> float:
    """Kish's effective sample size ``1 / Σ w_i²`` of normalised weights."""
    w = np.asarray(weights, dtype=float)
    return float(1.0 / np.sum(w * w))


def _cumulative(weights: np.ndarray) -> np.ndarray:
    c = np.cumsum(np.asarray(weights, dtype=float))
    return c / c[-1]                              # c[-1] is then exactly 1.0


def systematic_resample(weights: np.ndarray, rng: np.random.Generator,
                        size: int | None = None) -> np.ndarray:
    """Systematic resampling: one uniform offset, M evenly spaced points on the weight CDF.

    Indices are clipped to ``N - 1``, so a cumulative sum that falls short of one by rounding
    (or a point that rounds up to 1.0) can never index past the last particle.

    Parameters
    ----------
    weights : ndarray, (N,)
        Normalised weights.
    rng : numpy.random.Generator
    size : int, optional
        M, the number of draws (default N; a waste-free IBIS event draws N / P chain starts).

    Returns
    -------
    indices : ndarray of int, shape (M,)
        Sorted ancestor indices.
    """
    n = len(weights)
    m = n if size is None else int(size)
    if m < 1:
        raise ValueError(f"systematic_resample: size must be at least 1, got {m}")
    points = (rng.random() + np.arange(m)) / m
    idx = np.searchsorted(_cumulative(weights), points, side="right")
    return np.minimum(idx, n - 1)


def multinomial_search_resample(weights: np.ndarray, rng: np.random.Generator,
                                n_draws: int | None = None) -> np.ndarray:
    """Multinomial resampling by the cumulative-weight search of paper 004, Eq. (17).

    Draw ``M`` independent uniforms ``u_p`` and, for each, the index ``l`` with
    ``Σ_{j<l} q_j < u_p ≤ Σ_{j≤l} q_j`` (binary search on the cumulative weights).

    Returns
    -------
    indices : ndarray of int, shape (M,)
        In draw order (not sorted), clipped to ``N - 1``.
    """
    n = len(weights)
    m = n if n_draws is None else int(n_draws)
    points = rng.random(m)
    idx = np.searchsorted(_cumulative(weights), points, side="left")
    return np.minimum(idx, n - 1)


def weighted_mean_cov(values: np.ndarray, weights: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Weighted mean ``Σ w θ`` and covariance ``Σ w (θ-θ̄)(θ-θ̄)ᵀ`` (no bias correction).

    Parameters
    ----------
    values : ndarray, shape (N, d)
    weights : ndarray, shape (N,)
        Normalised weights.

    Returns
    -------
    mean : ndarray, shape (d,)
    cov : ndarray, shape (d, d)
        Symmetric (paper 004, Eqs. 7–8; paper 003's V_n with uniform weights).
    """
    values = np.asarray(values, dtype=float)
    w = np.asarray(weights, dtype=float)
    mean = w @ values
    centred = values - mean
    cov = (centred * w[:, None]).T @ centred
    return mean, 0.5 * (cov + cov.T)


def gaussian_draws(mean: np.ndarray, cov: np.ndarray, n: int, rng: np.random.Generator
                   ) -> np.ndarray:
    """``n`` draws from ``N(mean, cov)`` for a possibly singular PSD ``cov``.

    Uses the symmetric square root from ``eigh`` (negative round-off eigenvalues clipped to 0),
    so a zero covariance gives ``n`` copies of the mean.  ``mean`` may be (d,) or (n, d).
    """
    mean = np.asarray(mean, dtype=float)
    d = mean.shape[-1]
    eigval, eigvec = np.linalg.eigh(np.asarray(cov, dtype=float))
    root = eigvec * np.sqrt(np.clip(eigval, 0.0, None))          # cov = root rootᵀ
    return mean + rng.standard_normal((n, d)) @ root.T


def gaussian_log_density(values: np.ndarray, mean: np.ndarray, cov: np.ndarray) -> np.ndarray:
    """``log N(values; mean, cov)`` per row, via Cholesky (``cov`` must be positive definite)."""
    logpdf, _, _ = gaussian_logpdf(np.asarray(values, float) - mean, np.asarray(cov, float))
    return logpdf


def liu_west_shrinkage(delta: float) -> tuple[float, float]:
    """Liu–West kernel constants from the discount factor δ ∈ (0, 1].

    ``a = (3δ − 1) / (2δ)`` and ``h² = 1 − a²`` (paper 003, Eq. 12), so that the move keeps
    the mean and covariance of the particle cloud: ``a² + h² = 1``.
    """
    if not 1.0 / 3.0 < delta <= 1.0:
        raise ValueError(f"Liu-West discount delta must be in (1/3, 1], got {delta!r}")
    a = (3.0 * delta - 1.0) / (2.0 * delta)
    return a, 1.0 - a * a


def liu_west_move(theta: np.ndarray, weights: np.ndarray, delta: float, rng: np.random.Generator,
                  offset: np.ndarray | None = None, scale: np.ndarray | None = None,
                  log_mask: np.ndarray | None = None) -> np.ndarray:
    """Liu–West kernel-shrinkage move of parameter particles.

    ``m_i = a θ_i + (1 − a) θ̄``,  ``θ_i' ~ N(m_i, h² V)``, with θ̄ and V the weighted mean and
    covariance of the cloud.  Optionally the move is made on transformed parameters
    ``z = (g(θ) − offset) / scale`` with ``g = log`` on the coordinates in ``log_mask``
    (positive parameters stay positive) and identity elsewhere; the full-covariance move is
    affine-equivariant, so offset/scale only improve the conditioning of V.

    Parameters
    ----------
    theta : ndarray, shape (N, d)
    weights : ndarray, shape (N,)
        Normalised weights (uniform right after resampling).
    delta : float
        Discount factor δ (0.95–0.99 is usual).
    rng : numpy.random.Generator
    offset, scale : ndarray, shape (d,), optional
        Normalisation of the (log-)parameters.
    log_mask : ndarray of bool, shape (d,), optional
        Coordinates moved in log space.

    Returns
    -------
    theta_new : ndarray, shape (N, d)
    """
    a, h2 = liu_west_shrinkage(delta)
    z = np.array(theta, dtype=float)
    if log_mask is not None:
        z[:, log_mask] = np.log(z[:, log_mask])
    off = np.zeros(z.shape[1]) if offset is None else np.asarray(offset, float)
    sc = np.ones(z.shape[1]) if scale is None else np.asarray(scale, float)
    z = (z - off) / sc
    mean, cov = weighted_mean_cov(z, weights)
    shrunk = a * z + (1.0 - a) * mean                            # m_i = a θ_i + (1−a) θ̄
    z_new = gaussian_draws(shrunk, h2 * cov, z.shape[0], rng)   # θ_i' ~ N(m_i, h² V)
    theta_new = z_new * sc + off
    if log_mask is not None:
        theta_new[:, log_mask] = np.exp(theta_new[:, log_mask])
    return theta_new


def weighted_quantiles(values: np.ndarray, weights: np.ndarray, probs) -> np.ndarray:
    """Weighted quantiles per column for one or several weight vectors.

    The quantile p is the smallest value whose cumulative weight reaches p (inverse of the
    weighted empirical CDF; with equal weights, numpy's ``method="inverted_cdf"``).

    Parameters
    ----------
    values : ndarray, (N, d)
    weights : ndarray, (N,) or (J, N)
        Normalised weights (J sets, e.g. J steps).
    probs : sequence of float in (0, 1)

    Returns
    -------
    quantiles : ndarray, (len(probs), d) or (len(probs), J, d)
    """
    values = np.asarray(values, float)
    W = np.atleast_2d(np.asarray(weights, float))
    order = np.argsort(values, axis=0, kind="stable")                    # (N, d)
    out = np.empty((len(probs), W.shape[0], values.shape[1]))
    for j in range(values.shape[1]):
        cw = np.cumsum(W[:, order[:, j]], axis=1)                       # (J, N)
        cw /= cw[:, -1:]
        for i, prob in enumerate(probs):
            first = np.argmax(cw >= prob * (1.0 - 1e-12), axis=1)        # rounding-safe
            out[i, :, j] = values[order[first, j], j]
    return out if np.ndim(weights) == 2 else out[:, 0]


def normalise_log_weight_columns(LW: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Column-wise log-sum-exp of (N, J) log weights: normalised weights (J, N) and log norms."""
    LW = np.where(np.isnan(LW), -np.inf, LW)
    top = np.max(LW, axis=0)
    finite = np.isfinite(top)
    with np.errstate(over="ignore", invalid="ignore"):
        shifted = np.exp(LW - np.where(finite, top, 0.0))
    total = shifted.sum(axis=0)
    W = np.where(finite, shifted / np.where(finite, total, 1.0), 1.0 / LW.shape[0])
    with np.errstate(divide="ignore"):
        log_norm = np.where(finite, top + np.log(total), -np.inf)
    return W.T, log_norm
