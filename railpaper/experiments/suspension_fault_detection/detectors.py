"""The five detectors of the appendix, each a statistic after every sample of one record
(alarms, thresholds and delays are those of
:mod:`~railpaper.experiments.suspension_fault_detection.evidence`).

* :func:`residual_cusum` (``cusum``) — the classical residual test: the nominal model's Kalman
  filter, its whitened innovations and Page's CUSUM against a growth of their variance
  (:mod:`railpaper.engine.residual_alarms`; Basseville & Nikiforov 1993);
* :func:`windowed_chi2` (``chi2``) — the same innovations' squared norm summed over a sliding
  window (a χ² test: it also sees a change of their mean or direction, which a variance CUSUM
  misses);
* :func:`change_bank` (``glr`` and ``bayes``) — detectors that do not know the fault: any of
  the model's five parameters times any factor of ``[bayes] factors`` in the data file, from any
  sample on, with the exact Kalman likelihood ratio of each hypothesis against no change
  (:func:`railpaper.engine.windowed_change_statistics`); ``glr`` is the largest log-ratio over
  the hypotheses whose change lies in the window (Willsky & Jones 1976; Lai 1998), ``bayes``
  the log of the mixture Shiryaev–Roberts statistic (the sum of the ratios, weighted by a
  uniform prior over parameters and factors);
* :func:`oracle_change_posterior` (``oracle``) — the log posterior odds that a fault has
  happened, for hypotheses that are the catalogue's true post-fault values and change times on
  the grid the truth is drawn from (:mod:`railpaper.engine.changepoint`): it knows the answer
  up to which fault and when, so its gap to ``bayes`` is the value of knowing the fault;
* :func:`hunting_rms` (``hunting``) — no model at all: the bogie frame's lateral acceleration
  band-passed around the frequency at which a failed damper lets the bogie hunt, as a sliding
  RMS over 100 m (the quantity of EN 14363's instability criterion).  It sees hunting, not a
  residual, so a model error cannot raise its threshold; the appendix runs it on the stored
  ladder rungs (:data:`~.spec.STORED_DETECTORS`).

All of them filter with the record's own process noise (the track input's changes, chapter 003)
from the state at rest (:func:`initial_state`; filters that estimate the track start it at its
stationary covariance); the sample time is the run's ``dt_s``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.signal import butter, sosfilt

from railpaper.engine import (LinearGaussianBatch, WindowedChangeStatistics, change_likelihoods,
                              change_posterior, cusum_variance, whitened_innovations,
                              windowed_change_statistics)
from railpaper.experiments.lateral_vehicle import LateralRecord
from railpaper.experiments.suspension_fault_detection.result import Fault
from railpaper.models import lateral_16state

#: Initial state covariance of every filter (the vehicle starts at rest), state units squared.
P0_SCALE = 1e-10


def initial_state(system) -> tuple[np.ndarray, np.ndarray]:
    """Every filter's start: the vehicle at rest (mean 0, covariance ``P0_SCALE`` I on its 16
    states) and, for filters that estimate the track (``system.track_covariance``, see
    :mod:`railpaper.models.lateral_unknown_track`), the track states at their stationary
    covariance."""
    n = lateral_16state.N_STATES
    track = getattr(system, "track_covariance", None)
    size = n + (0 if track is None else len(track))
    P0 = np.zeros((size, size))
    P0[:n, :n] = P0_SCALE * np.eye(n)
    if track is not None:
        P0[n:, n:] = track
    return np.zeros(size), P0


def nominal_innovations(system, theta: np.ndarray, record: LateralRecord) -> np.ndarray:
    """The nominal model's Kalman filter's whitened innovations z_k (K, p) on the record:
    N(0, I) while the vehicle is healthy and the model is right."""
    nominal = system(theta[None])
    one = LinearGaussianBatch(nominal.F[0], nominal.Q, nominal.H[0], nominal.R, nominal.B[0])
    return whitened_innovations(one, record.y, *initial_state(system), u=record.u_mps).z


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


def oracle_hypotheses(faults: list[Fault], theta: np.ndarray) -> tuple[list[str], np.ndarray]:
    """The oracle's post-fault values: one per abrupt fault of the run (names, θ (V, 5))."""
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
class OraclePosterior:
    """The oracle on one record.

    Attributes
    ----------
    p_changed : ndarray, (K,)
        P(the fault has happened by sample k | y_1..k).
    log_odds : ndarray, (K,)
        Its log odds, log P(happened) − log P(not yet), natural log: the alarm statistic
        (the same alarms as ``p_changed`` at the matching threshold, and unbounded, so a
        false-alarm tail can be fitted to it).
    fault_time_posterior : ndarray, (J,)
        P(fault step = grid step j | y_1..K, a fault happened).
    value_posterior : ndarray, (V,)
        P(hypothesis v | y_1..K, a fault happened).
    filter_steps : int
        Kalman filter steps run (the cost).
    """

    p_changed: np.ndarray
    log_odds: np.ndarray
    fault_time_posterior: np.ndarray
    value_posterior: np.ndarray
    filter_steps: int


def oracle_change_posterior(system, theta: np.ndarray, record: LateralRecord,
                            values: np.ndarray, fault_steps: np.ndarray, p_no_fault: float
                            ) -> OraclePosterior:
    """The posterior of (which fault, when) given the record, uniform prior over ``values``
    (V, 5) and the grid ``fault_steps`` (1-based first post-fault steps) that lie inside the
    record, and ``p_no_fault`` on no fault."""
    K = len(record.y)
    inside = fault_steps[fault_steps <= K]
    if inside.size == 0:                          # the record ended before any fault time
        return OraclePosterior(np.zeros(K), np.full(K, -np.inf), np.zeros(len(fault_steps)),
                               np.full(len(values), 1.0 / len(values)), 0)
    lik = change_likelihoods(system, record.y, theta, values, inside, *initial_state(system),
                             u=record.u_mps)
    # the prior's mass on grid steps past the record's end is still "not yet changed"
    prior = np.ones((len(values), inside.size))
    p_none = p_no_fault + (1.0 - p_no_fault) * (1.0 - inside.size / len(fault_steps))
    post = change_posterior(lik, p_no_change=p_none, prior=prior)
    tau = np.zeros(len(fault_steps))
    tau[:inside.size] = post.tau_posterior
    return OraclePosterior(post.p_changed, post.log_odds_changed, tau, post.value_posterior,
                           lik.filter_steps)


@dataclass(frozen=True)
class BankHypotheses:
    """The post-fault values of the detectors that do not know the fault: every model parameter
    (``lateral_16state.PARAM_NAMES``) times every factor, one at a time.

    Attributes
    ----------
    parameter : ndarray of int, (V,)
        Index of the changed parameter in ``PARAM_NAMES``.
    factor : ndarray, (V,)
        Its value after the change, fraction of nominal.
    values : ndarray, (V, 5)
        θ after the change (the parameters' units).
    """

    parameter: np.ndarray
    factor: np.ndarray
    values: np.ndarray


def bank_hypotheses(theta: np.ndarray, factors: np.ndarray) -> BankHypotheses:
    """Parameter by parameter, factor by factor (parameter-major order)."""
    names = lateral_16state.PARAM_NAMES
    parameter = np.repeat(np.arange(len(names)), len(factors))
    factor = np.tile(np.asarray(factors, float), len(names))
    values = np.repeat(theta[None], len(parameter), axis=0)
    values[np.arange(len(parameter)), parameter] *= factor
    return BankHypotheses(parameter=parameter, factor=factor, values=values)


def change_bank(system, theta: np.ndarray, record: LateralRecord, hypotheses: BankHypotheses,
                window_steps: int, first_change_step: int) -> WindowedChangeStatistics:
    """``glr`` and ``bayes`` on one record: the window-limited GLR and log mixture
    Shiryaev–Roberts statistic over ``hypotheses`` (uniform prior) and every change step from
    ``first_change_step`` on, the last ``window_steps`` of them at each step.  A record that
    ends before ``first_change_step`` gets statistics of −inf throughout."""
    K = len(record.y)
    if K < first_change_step:
        none = np.full(K, -np.inf)
        return WindowedChangeStatistics(none, none.copy(), np.full(K, -1), np.full(K, -1),
                                        window_steps, 0)
    return windowed_change_statistics(system, record.y, theta, hypotheses.values, window_steps,
                                      *initial_state(system), u=record.u_mps,
                                      first_change_step=first_change_step)


#: Half-width of the hunting detector's band around its frequency, Hz (EN 14363: f0 ± 2 Hz).
HUNTING_HALF_BAND_HZ = 2.0
#: Length of track over which the hunting detector's RMS runs, m (EN 14363: 100 m).
HUNTING_TRACK_M = 100.0
#: Oscillatory modes below this frequency are car-body modes, not hunting, Hz.
HUNTING_MIN_HZ = 2.0


def hunting_frequency_hz(fixed: dict, theta: np.ndarray, speed_mps: float) -> float:
    """The band centre of :func:`hunting_rms`, Hz: the frequency of the least-damped mode above
    :data:`HUNTING_MIN_HZ` of the model with its anti-yaw damping lost, at the speed — the
    hunting a failed damper lets grow (6.4 Hz at 300 km/h).  A monitor's designer knows it
    from the vehicle's stability analysis; it is the only use of the model in this detector."""
    lost = np.array(theta, float)
    lost[lateral_16state.PARAM_NAMES.index("csaly")] = 0.0
    ev = np.linalg.eigvals(lateral_16state.build_A_direct(fixed, lost, speed_mps))
    frequency = np.abs(ev.imag) / (2 * np.pi)
    oscillating = frequency > HUNTING_MIN_HZ
    return float(frequency[oscillating][np.argmax(ev.real[oscillating])])


def hunting_rms(record: LateralRecord, dt_s: float, speed_mps: float,
                frequency_hz: float) -> np.ndarray:
    """The hunting detector's statistic (K,), m/s²: the bogie's lateral acceleration channel
    band-passed at ``frequency_hz`` ± :data:`HUNTING_HALF_BAND_HZ` (4th-order Butterworth,
    causal from rest), then its RMS over the last :data:`HUNTING_TRACK_M` of track
    (``round(100 m / (v dt))`` samples; fewer at the start)."""
    y = record.y[:, lateral_16state.CHANNELS.index("acc_b_mps2")]
    band = (frequency_hz - HUNTING_HALF_BAND_HZ, frequency_hz + HUNTING_HALF_BAND_HZ)
    filtered = sosfilt(butter(2, band, btype="bandpass", fs=1.0 / dt_s, output="sos"), y)
    window = max(1, int(round(HUNTING_TRACK_M / (speed_mps * dt_s))))
    energy = np.concatenate([[0.0], np.cumsum(filtered ** 2)])
    k = np.arange(1, len(filtered) + 1)
    first = np.maximum(0, k - window)
    return np.sqrt(np.maximum(energy[k] - energy[first], 0.0) / (k - first))


__all__ = ["HUNTING_HALF_BAND_HZ", "HUNTING_MIN_HZ", "HUNTING_TRACK_M", "BankHypotheses",
           "OraclePosterior", "bank_hypotheses", "change_bank", "hunting_frequency_hz",
           "hunting_rms", "initial_state", "nominal_innovations", "oracle_change_posterior",
           "oracle_hypotheses", "residual_cusum", "windowed_chi2"]
