"""Parts of :mod:`railpaper.engine.ibis`: weights over many steps, weighted quantiles and
per-step summaries, merging model batches, a jittered Cholesky factor."""

from __future__ import annotations

import numpy as np

from railpaper.engine.linear_gaussian import LinearGaussianBatch


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


def merge_systems(old: LinearGaussianBatch, new: LinearGaussianBatch, take_new: np.ndarray
                  ) -> LinearGaussianBatch:
    """Per-model matrices: ``new``'s where ``take_new`` (N,) is True, else ``old``'s."""
    n = take_new.shape[0]

    def pick(a, b):
        if a is None:
            return None
        if a.ndim == 2 and b.ndim == 2 and np.array_equal(a, b):
            return a                                                      # shared, unchanged
        a = np.broadcast_to(a, (n,) + a.shape[-2:])
        b = np.broadcast_to(b, (n,) + b.shape[-2:])
        return np.where(take_new[:, None, None], b, a)
    return LinearGaussianBatch(*(pick(getattr(old, k), getattr(new, k))
                                 for k in ("F", "Q", "H", "R", "B")))


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


def jittered_cholesky(cov: np.ndarray, box_width: np.ndarray) -> np.ndarray:
    """Lower Cholesky factor of Σ; if Σ is singular (e.g. one distinct particle), of Σ plus the
    smallest diagonal jitter (10⁻⁹, 10⁻⁸, … × box width)² that factorises."""
    jitter = 0.0
    for _ in range(8):
        try:
            return np.linalg.cholesky(cov + np.diag(jitter * box_width ** 2))
        except np.linalg.LinAlgError:
            jitter = 1e-18 if jitter == 0.0 else 100.0 * jitter
    return np.diag(1e-3 * box_width)


def append_summaries(rows: dict, theta, W, log_norm, prev_log_norm, ess) -> None:
    """Append per-step mean, sd, quantiles, ESS and incremental log evidence (W: (J, N))."""
    mean = W @ theta                                                # (J, d)
    centred = theta[None] - mean[:, None]                           # (J, N, d)
    var = np.einsum("jn,jnd->jd", W, centred * centred)
    q = weighted_quantiles(theta, W, (0.05, 0.95))
    rows["mean"].extend(mean)
    rows["sd"].extend(np.sqrt(np.clip(var, 0.0, None)))
    rows["q05"].extend(q[0])
    rows["q95"].extend(q[1])
    rows["ess"].extend(ess)
    rows["log_evidence"].extend(log_norm - prev_log_norm)
