"""The batched linear-Gaussian engine: Kalman filters of many models at once, and the
parameter samplers built on them.

A model is a callable ``system(theta) -> LinearGaussianBatch`` (:class:`LinearGaussianSystem`):
given N parameter vectors it returns their matrices.  Everything below takes such a callable and
never a vehicle, so the same code runs paper 004's toy and paper 003's 16-state lateral model::

    >>> import numpy as np
    >>> from railpaper.engine import LinearGaussianBatch, grid_posterior, run_rbpf
    >>> def system(theta):                    # x_k = a x_(k-1) + w,  y_k = x_k + e;  θ = (a,)
    ...     return LinearGaussianBatch(F=theta[:, :, None], Q=[[0.1]], H=[[1.0]], R=[[0.5]])
    >>> rng = np.random.default_rng(0)
    >>> x = np.zeros(301)
    >>> for k in range(1, 301):
    ...     x[k] = 0.8 * x[k - 1] + rng.normal(0, 0.1 ** 0.5)
    >>> y = (x[1:] + rng.normal(0, 0.5 ** 0.5, 300))[:, None]
    >>> rbpf = run_rbpf(system, y, rng.uniform(0, 1, (400, 1)), np.zeros(1), np.eye(1), rng)
    >>> exact = grid_posterior(system, y, [0.0], [1.0], 401, np.zeros(1), np.eye(1))
    >>> bool(abs(rbpf.theta_mean[-1, 0] - exact.mean[-1, 0]) < 2 * exact.std[-1, 0])
    True

``run_rbpf`` is paper 003's Rao–Blackwellised particle filter (a Kalman filter per parameter
particle, Liu–West moves); ``grid_posterior`` the exact posterior of a low-dimensional θ on a
grid; ``run_ibis`` the exact posterior of any θ by IBIS; ``run_qgrbpf`` paper 004's
quasi-Gaussian RBPF; ``change_likelihoods`` and ``change_posterior`` the exact posterior of an
abrupt parameter change (when, and to which value), ``change_statistics`` its mixture
Shiryaev–Roberts statistic and window-limited GLR, ``windowed_change_statistics`` the same two
with a change possible at every step (a ring of filters that live while their change is in the
window); ``whitened_innovations``,
``cusum_variance`` and ``glr_mean_shift`` the classical residual test of one
(:mod:`~railpaper.engine.residual_alarms`).  The parts: :mod:`~railpaper.engine.kalman` (the
numpy reference step, Joseph update), :mod:`~railpaper.engine.kalman_bank` (the compiled bank
of N filters),
:mod:`~railpaper.engine.affine_pass` (the RBPF and Q-GRBPF over a whole record in one compiled
pass, for models affine in θ such as both toys),
:mod:`~railpaper.engine.batch_expm` and :mod:`~railpaper.engine.sparse_zoh` (exact ZOH of stacks
of models), :mod:`~railpaper.engine.particles` (weights, resampling, Liu–West),
:mod:`~railpaper.engine.mcmc` (adaptive Metropolis on the Kalman likelihood) and
:mod:`~railpaper.engine.crlb` (Fisher information, Cramér–Rao bound).

This module is the engine's only door: outside ``railpaper/engine/`` the package imports every
name from here, never from a submodule (``tests/test_layers.py`` fails on such an import).  Two
names are renamed on the way out: the cost models ``multiply_adds`` of the Kalman bank and of
the sparse ZOH are ``bank_multiply_adds`` and ``zoh_multiply_adds``, and the sparse ZOH's
block length ``BLOCK`` is ``ZOH_BLOCK``.
"""

from railpaper.engine.batch_expm import zoh_stack
from railpaper.engine.changepoint import (ChangeLikelihoods, ChangePosterior,
                                         ChangeStatistics, WindowedChangeStatistics,
                                         change_likelihoods, change_posterior,
                                         change_statistics, windowed_change_statistics)
from railpaper.engine.crlb import crlb_std, fisher_information
from railpaper.engine.grid_posterior import GridPosterior, grid_posterior
from railpaper.engine.ibis import IBISRun, credible_interval_covers, run_ibis
from railpaper.engine.kalman import LOG_2PI, predict, update
from railpaper.engine.kalman_bank import kalman_run, kalman_step, measurement_pattern
from railpaper.engine.kalman_bank import multiply_adds as bank_multiply_adds
from railpaper.engine.kernel_arrays import kernel_array
from railpaper.engine.linear_gaussian import (AffineSystem, LinearGaussianBatch,
                                              LinearGaussianSystem)
from railpaper.engine.mcmc import adaptive_metropolis, kalman_log_posterior
from railpaper.engine.particles import (effective_sample_size, liu_west_move,
                                        normalise_log_weights, systematic_resample,
                                        weighted_mean_cov)
from railpaper.engine.qgrbpf import QuasiGaussianRBPF, run_qgrbpf
from railpaper.engine.rbpf import (FilterRun, RaoBlackwellisedPF, StepEstimate, mixture_moments,
                                   run_filter, run_rbpf)
from railpaper.engine.residual_alarms import (Innovations, cusum_variance, first_alarm,
                                              glr_mean_shift, whitened_innovations)
from railpaper.engine.sparse_zoh import BLOCK as ZOH_BLOCK
from railpaper.engine.sparse_zoh import AffineZOH, affine_balance, term_counts, zoh_sparse
from railpaper.engine.sparse_zoh import multiply_adds as zoh_multiply_adds

__all__ = ["AffineSystem", "AffineZOH", "ChangeLikelihoods", "ChangePosterior", "ChangeStatistics",
           "FilterRun", "GridPosterior", "IBISRun", "Innovations", "LOG_2PI",
           "LinearGaussianBatch", "LinearGaussianSystem", "QuasiGaussianRBPF",
           "RaoBlackwellisedPF", "StepEstimate", "WindowedChangeStatistics", "ZOH_BLOCK",
           "adaptive_metropolis", "affine_balance", "bank_multiply_adds", "change_likelihoods",
           "change_posterior", "change_statistics", "credible_interval_covers", "crlb_std",
           "cusum_variance", "effective_sample_size", "first_alarm", "fisher_information",
           "glr_mean_shift", "grid_posterior", "kalman_log_posterior", "kalman_run", "kalman_step",
           "kernel_array", "liu_west_move", "measurement_pattern", "mixture_moments",
           "normalise_log_weights", "predict", "run_filter", "run_ibis", "run_qgrbpf", "run_rbpf",
           "systematic_resample", "term_counts", "update", "weighted_mean_cov",
           "whitened_innovations", "windowed_change_statistics", "zoh_multiply_adds", "zoh_sparse",
           "zoh_stack"]
