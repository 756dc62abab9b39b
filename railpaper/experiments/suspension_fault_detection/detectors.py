"""The four detectors of the appendix, each a statistic after every sample of one record
(alarms, thresholds and delays are those of
:mod:`~railpaper.experiments.suspension_fault_detection.evidence`).

* :func:`residual_cusum` — the classical residual test: the nominal model's Kalman filter, its
  whitened innovations and Page's CUSUM against a growth of their variance
  (:mod:`railpaper.engine.residual_alarms`; Basseville & Nikiforov 1993);
* :func:`windowed_chi2` — the same innovations' squared norm summed over a sliding window (a
  χ² test: it also sees a change of their mean or direction, which a variance CUSUM misses);
* :func:`rbpf_departure` — paper 003's RBPF (Liu–West artificial evolution at every step, the
  paper's scheme) over the two parameters a fault may change, K_sy and C_saly; the statistic is
  the larger relative departure of their estimates from nominal;
* :func:`exact_change_posterior` — the exact reference: for every hypothesis (which fault, when)
  on the prior's grid, a Kalman filter gives the likelihood exactly
  (:mod:`railpaper.engine.changepoint`); the statistic is the posterior probability that a
  fault has happened by now.

All of them filter with the record's own process noise (the track input's changes, chapter 003)
from the state at rest; the sample time is the run's ``dt_s``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from railpaper.engine import (LinearGaussianBatch, change_likelihoods, change_posterior,
                              cusum_variance, run_rbpf, whitened_innovations)
from railpaper.experiments.lateral_vehicle import LateralRecord
from railpaper.experiments.suspension_fault_detection.result import Fault
from railpaper.experiments.suspension_fault_detection.spec import TRACKED, Settings
from railpaper.models import lateral_16state

#: Initial state covariance of every filter (the vehicle starts at rest), state units squared.
P0_SCALE = 1e-10


def nominal_innovations(system, theta: np.ndarray, record: LateralRecord) -> np.ndarray:
    """The nominal model's Kalman filter's whitened innovations z_k (K, p) on the record:
    N(0, I) while the vehicle is healthy and the model is right."""
    nominal = system(theta[None])
    one = LinearGaussianBatch(nominal.F[0], nominal.Q, nominal.H[0], nominal.R, nominal.B[0])
    return whitened_innovations(one, record.y, np.zeros(lateral_16state.N_STATES),
                                P0_SCALE * np.eye(lateral_16state.N_STATES), u=record.u_mps).z


def residual_cusum(system, theta: np.ndarray, record: LateralRecord, variance_ratio: float,
                   innovations: np.ndarray | None = None) -> np.ndarray:
    """CUSUM g_k (K,) of the nominal filter's whitened innovations against their variance
    growing ``variance_ratio``-fold (``innovations``: :func:`nominal_innovations`, if already
    computed)."""
    z = nominal_innovations(system, theta, record) if innovations is None else innovations
    return cusum_variance(z, variance_ratio)


def windowed_chi2(innovations: np.ndarray, window: int) -> np.ndarray:
    """The windowed χ² test's statistic (K,): s_k = Σ_{i=k−W+1..k} ‖z_i‖², the squared whitened
    innovations of the last ``window`` samples (fewer at the start), χ²(W p) while healthy.
    Unlike the variance CUSUM it also sees a change of the innovations' mean or direction."""
    energy = np.sum(np.asarray(innovations, float) ** 2, axis=1)
    total = np.cumsum(energy)
    total[window:] = total[window:] - total[:-window]
    return total


def hypotheses(faults: list[Fault], theta: np.ndarray) -> tuple[list[str], np.ndarray]:
    """The exact reference's post-fault values: one per abrupt fault (names, θ (V, 5))."""
    names, values = [], []
    for fault in faults:
        if fault.kind != "abrupt":
            continue
        changed = theta.copy()
        changed[lateral_16state.PARAM_NAMES.index(fault.parameter)] *= fault.factor
        names.append(fault.name)
        values.append(changed)
    return names, np.array(values)


@dataclass(frozen=True)
class ExactPosterior:
    """The exact reference on one record.

    Attributes
    ----------
    p_changed : ndarray, (K,)
        P(the fault has happened by sample k | y_1..k).
    fault_time_posterior : ndarray, (J,)
        P(fault step = grid step j | y_1..K, a fault happened).
    value_posterior : ndarray, (V,)
        P(hypothesis v | y_1..K, a fault happened).
    filter_steps : int
        Kalman filter steps run (the cost).
    """

    p_changed: np.ndarray
    fault_time_posterior: np.ndarray
    value_posterior: np.ndarray
    filter_steps: int


def exact_change_posterior(system, theta: np.ndarray, record: LateralRecord,
                           values: np.ndarray, fault_steps: np.ndarray, p_no_fault: float
                           ) -> ExactPosterior:
    """The posterior of (which fault, when) given the record, uniform prior over ``values``
    (V, 5) and the grid ``fault_steps`` (1-based first post-fault steps) that lie inside the
    record, and ``p_no_fault`` on no fault."""
    K = len(record.y)
    inside = fault_steps[fault_steps <= K]
    if inside.size == 0:                          # the record ended before any fault time
        return ExactPosterior(np.zeros(K), np.zeros(len(fault_steps)),
                              np.full(len(values), 1.0 / len(values)), 0)
    lik = change_likelihoods(system, record.y, theta, values, inside,
                             np.zeros(lateral_16state.N_STATES),
                             P0_SCALE * np.eye(lateral_16state.N_STATES), u=record.u_mps)
    # the prior's mass on grid steps past the record's end is still "not yet changed"
    prior = np.ones((len(values), inside.size))
    p_none = p_no_fault + (1.0 - p_no_fault) * (1.0 - inside.size / len(fault_steps))
    post = change_posterior(lik, p_no_change=p_none, prior=prior)
    tau = np.zeros(len(fault_steps))
    tau[:inside.size] = post.tau_posterior
    return ExactPosterior(post.p_changed, tau, post.value_posterior, lik.filter_steps)


def tracked_system(system, theta: np.ndarray):
    """``system`` of the two tracked parameters (:data:`TRACKED`, in their units), the others
    held at ``theta``."""
    columns = [lateral_16state.PARAM_NAMES.index(name) for name in TRACKED]

    def reduced(tracked: np.ndarray) -> LinearGaussianBatch:
        tracked = np.atleast_2d(tracked)
        full = np.repeat(theta[None], len(tracked), axis=0)
        full[:, columns] = tracked
        return system(full)

    return reduced


def rbpf_estimates(settings: Settings, system, theta: np.ndarray, record: LateralRecord,
                   seed: int) -> np.ndarray:
    """The RBPF's estimates of the tracked parameters after every sample, fraction of nominal
    (K, 2): ``n_particles`` particles from nominal × U(``prior_low``, ``prior_high``) (generator
    ``[seed, 11]``), the paper's scheme (resample and Liu–West move every step,
    δ = ``paper_delta``)."""
    columns = [lateral_16state.PARAM_NAMES.index(name) for name in TRACKED]
    nominal = theta[columns]
    rng = np.random.default_rng([seed, 11])
    cloud = nominal * rng.uniform(settings.prior_low, settings.prior_high,
                                  (settings.n_particles, 2))
    run = run_rbpf(tracked_system(system, theta), record.y, cloud,
                   np.zeros(lateral_16state.N_STATES), P0_SCALE * np.eye(lateral_16state.N_STATES),
                   rng, u=record.u_mps, scheme="paper",
                   delta=settings.paper_delta)
    return run.theta_mean / nominal


def rbpf_departure(relative: np.ndarray) -> np.ndarray:
    """The RBPF detector's statistic (K,): max over the tracked parameters of |θ̂/θ − 1|."""
    return np.max(np.abs(relative - 1.0), axis=1)


__all__ = ["ExactPosterior", "exact_change_posterior", "hypotheses", "nominal_innovations",
           "rbpf_departure", "rbpf_estimates", "residual_cusum", "tracked_system",
           "windowed_chi2"]
