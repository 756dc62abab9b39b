"""Exact parameter posterior on a grid, for linear-Gaussian models with static parameters.

For fixed θ the model is linear and Gaussian, so one Kalman filter gives the exact likelihood
``p(y_1..k | θ) = Π_j N(y_j; H x⁻_j, S_j)``.  Stacking one filter per grid point (the compiled
bank :func:`railpaper.engine.kalman_bank.kalman_run`, all steps in one call) and a uniform
prior on a box gives the posterior of θ on the grid after every step; its mean and standard deviation are integrals evaluated by the midpoint
rule on cell centres (very accurate while the grid spacing is below the posterior std; check
:attr:`GridPosterior.min_std_over_spacing`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numba
import numpy as np

from railpaper.engine.kalman_bank import kalman_run
from railpaper.engine.particles import normalise_log_weights


def box_grid(lower, upper, n_points: int) -> tuple[np.ndarray, list[np.ndarray]]:
    """Cell centres of a regular grid on the box [lower, upper] (midpoint rule).

    Returns
    -------
    points : ndarray, (n_points**d, d)
        Grid points, first parameter varying slowest (``indexing="ij"``).
    axes : list of ndarray
        The 1-D centres along each parameter.
    """
    lower, upper = np.atleast_1d(lower).astype(float), np.atleast_1d(upper).astype(float)
    axes = [lo + (np.arange(n_points) + 0.5) * (hi - lo) / n_points for lo, hi in zip(lower, upper)]
    mesh = np.meshgrid(*axes, indexing="ij")
    return np.stack([m.ravel() for m in mesh], axis=1), axes


def kalman_log_likelihoods(system, y: np.ndarray, theta: np.ndarray, x0, P0,
                           u: np.ndarray | None = None) -> np.ndarray:
    """Per-step predictive log-likelihoods ``log p(y_k | y_1..k-1, θ_g)`` for every θ_g.

    Parameters
    ----------
    system : callable
        ``system(theta (G, d)) -> LinearGaussianBatch``.
    y : ndarray, (K, p)
    theta : ndarray, (G, d)
    x0, P0 : ndarray
        Initial state mean (n,) and covariance (n, n).
    u : ndarray, (K, m), optional

    Returns
    -------
    loglik : ndarray, (K, G)
    """
    return _loglik_steps(system, y, theta, x0, P0, u)


def _loglik_steps(system, y, theta, x0, P0, u) -> np.ndarray:
    """(K, G) log-likelihoods: one compiled Kalman bank over all K steps (fixed matrices)."""
    theta = np.atleast_2d(theta)
    s = system(theta)
    x0, P0 = np.asarray(x0, float), np.asarray(P0, float)
    x = np.broadcast_to(x0, (theta.shape[0], x0.shape[-1]))
    P = np.broadcast_to(P0, (theta.shape[0],) + P0.shape[-2:])
    _, _, loglik = kalman_run(x, P, s, np.asarray(y, float), u)
    return loglik.T


@dataclass
class GridPosterior:
    """Exact posterior summaries after every step.

    Attributes
    ----------
    mean, std : ndarray, (K, d)
        Posterior mean and standard deviation of θ after y_1..k.
    axes : list of ndarray
        Grid centres per parameter.
    log_posterior : ndarray, (n_points,)*d
        Final normalised log posterior mass per cell.
    spacing : ndarray, (d,)
    min_std_over_spacing : float
        Smallest posterior std over all steps and parameters, in grid spacings (≳ 1: the
        midpoint rule is accurate).
    edge_mass : float
        Final posterior mass in the outermost cells (≈ 0 unless the box truncates it).
    """

    mean: np.ndarray
    std: np.ndarray
    axes: list
    log_posterior: np.ndarray
    spacing: np.ndarray
    min_std_over_spacing: float
    edge_mass: float


@numba.njit(cache=True)
def _step_summaries(loglik, points, mean, std):  # pragma: no cover - compiled
    """Posterior mean and std (K, d) after every step from the per-step log-likelihoods
    (K, G) of the grid points (G, d): cumulative log-likelihood, log-sum-exp weights, weighted
    mean and variance (clipped at 0).  Returns the final cumulative log-likelihood (G,)."""
    K, G = loglik.shape
    d = points.shape[1]
    cumulative, w = np.zeros(G), np.empty(G)
    for k in range(K):
        top = -np.inf
        for g in range(G):
            cumulative[g] += loglik[k, g]
            if cumulative[g] > top:
                top = cumulative[g]
        total = 0.0
        for g in range(G):                            # as normalise_log_weights: all −inf
            if top == np.inf:                         # -> uniform, some +inf -> those alone
                w[g] = 1.0 if cumulative[g] == np.inf else 0.0
            elif top == -np.inf:
                w[g] = 1.0
            else:
                w[g] = np.exp(cumulative[g] - top)
            total += w[g]
        for j in range(d):
            acc = 0.0
            for g in range(G):
                acc += w[g] * points[g, j]
            mean[k, j] = acc / total
        for j in range(d):
            acc = 0.0
            for g in range(G):
                c = points[g, j] - mean[k, j]
                acc += w[g] * c * c
            std[k, j] = np.sqrt(max(acc / total, 0.0))
    return cumulative


def grid_posterior(system, y: np.ndarray, lower, upper, n_points: int, x0, P0,
                   u: np.ndarray | None = None) -> GridPosterior:
    """Exact posterior of θ under a uniform prior on the box [lower, upper], after every step."""
    points, axes = box_grid(lower, upper, n_points)
    d = points.shape[1]
    loglik = np.ascontiguousarray(_loglik_steps(system, np.asarray(y, float), points, x0, P0, u))
    means, stds = np.empty((len(loglik), d)), np.empty((len(loglik), d))
    cumulative = _step_summaries(np.where(np.isnan(loglik), -np.inf, loglik), points, means,
                                 stds)
    w, log_norm, _ = normalise_log_weights(cumulative)
    shape = (n_points,) * d
    grid_w = w.reshape(shape)
    interior = grid_w[(slice(1, -1),) * d].sum() if n_points > 2 else 0.0
    spacing = np.array([ax[1] - ax[0] if len(ax) > 1 else np.inf for ax in axes])
    std = stds
    return GridPosterior(mean=means, std=std, axes=axes,
                         log_posterior=(cumulative - log_norm).reshape(shape), spacing=spacing,
                         min_std_over_spacing=float(np.min(std / spacing)),
                         edge_mass=float(1.0 - interior))
