"""Typed results of chapter ``reduced-order-observer`` (SI units): one record, the observers on
it, one speed's runs, the estimators' comparison and the whole run."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import pandas as pd

from railpaper.estimators import reduced_order_observer
from railpaper.experiments.base import ChapterResult
from railpaper.models import single_wheelset


@dataclass(frozen=True)
class Record:
    """One simulated record at one speed: the truth and what the observer is given (SI units).

    Attributes
    ----------
    speed_kmh : float
        Vehicle speed, km/h.
    t_s : ndarray, shape (K,)
        Sample times, s (step ``dt_s``).
    q_m : ndarray, shape (K,)
        True vertical irregularity under the wheelset, m.
    x_true : ndarray, shape (K, 4)
        True state ``[ż_c, z_c, ż_w, z_w]`` (m/s, m, m/s, m).
    y_measured : ndarray, shape (K, 2)
        Measured ``[ż_c, z_c]`` (m/s, m): truth plus sensor noise.
    q_measured_m : ndarray, shape (K,)
        Irregularity given to the estimators, m (plus ``track_noise_fraction`` noise).
    x2_initial : ndarray, shape (2,)
        The observer's initial ``[ż_w, z_w]`` (m/s, m): truth plus ``initial_error_m`` on z_w.
    force_true_N : ndarray, shape (K,)
        Dynamic wheel–rail force of the plant (total minus static load), N.
    """

    speed_kmh: float
    t_s: np.ndarray
    q_m: np.ndarray
    x_true: np.ndarray
    y_measured: np.ndarray
    q_measured_m: np.ndarray
    x2_initial: np.ndarray
    force_true_N: np.ndarray


@dataclass(frozen=True)
class ObserverRun:
    """One discrete reduced-order observer on one :class:`Record`.

    Attributes
    ----------
    z_w_est_m : ndarray, shape (K,)
        Estimated wheelset displacement, m.
    force_est_N : ndarray, shape (K,)
        Estimated dynamic wheel–rail force ``K_r (ẑ_w − q_measured)``, N.
    convergence_time_s : float
        First time after which ``|ẑ_w − z_w|`` stays below the threshold, s (-1: never).
    force_rms_error_N : float
        RMS of ``f̂ − f`` from ``error_window_start_s`` on, N.
    displacement_rms_error_m : float
        RMS of ``ẑ_w − z_w`` over the same window, m.
    """

    z_w_est_m: np.ndarray
    force_est_N: np.ndarray
    convergence_time_s: float
    force_rms_error_N: float
    displacement_rms_error_m: float


@dataclass(frozen=True)
class SpeedRun:
    """A record at one speed with both discretisations of the paper's observer on it.

    Attributes
    ----------
    record : Record
        Truth and measurements.
    z_w_rms_m, force_rms_N : float
        RMS of the true z_w over the run (m) and of the true force over the error window (N).
    predicted_convergence_time_s : float
        Convergence time of the error equation alone, ``e[k+1] = Φ e[k]``, s (-1: never).
    contact_lost_fraction : float
        Fraction of samples where the true force would lift the wheels (total load ≤ 0).
    paper, foh : ObserverRun
        The observer discretised with y and q held over a step (the paper's) or linear between
        samples.
    """

    record: Record
    z_w_rms_m: float
    force_rms_N: float
    predicted_convergence_time_s: float
    contact_lost_fraction: float
    paper: ObserverRun
    foh: ObserverRun

    def observer(self, form: str) -> ObserverRun:
        """The run of the observer discretised as ``form`` (``"paper"`` or ``"foh"``)."""
        return {"paper": self.paper, "foh": self.foh}[form]


@dataclass(frozen=True)
class ForceEstimates:
    """One record (seed ``seed``, the run's noise) with every estimator's force, N.

    Attributes
    ----------
    t_s : ndarray (K,)
    force_true_N, observer_N, kalman_N, smoother_N : ndarray (K,)
    """

    t_s: np.ndarray
    force_true_N: np.ndarray
    observer_N: np.ndarray
    kalman_N: np.ndarray
    smoother_N: np.ndarray


@dataclass(frozen=True)
class KalmanComparison:
    """The estimators on the chapter's Monte Carlo records at several noise levels.

    Attributes
    ----------
    samples : DataFrame
        One row per (seed, speed_kmh, noise_fraction, track_noise_fraction, estimator, sweep):
        ``force_rms_N`` (true force over the error window, N), ``force_rms_error_N`` (N) and
        ``ratio`` (their quotient), ``q_rms_m`` (RMS of the record's q, m); ``sweep`` is ``"sensor"`` (every seed, every sensor noise
        level, the run's track noise) or ``"track"`` (the first seeds, the run's sensor noise,
        every track noise level).
    examples : dict of float to ForceEstimates
        Per speed, the forces of seed ``seed`` at the run's ``noise_fraction``.
    shaping : dict of float to ShapingFilter
        The fitted track shaping filter per speed.
    """

    samples: pd.DataFrame
    examples: dict
    shaping: dict


@dataclass
class ReducedOrderObserverResult(ChapterResult):
    """What :func:`run` returns: the pipeline's :class:`ChapterResult` plus named results.

    Attributes
    ----------
    vehicle : SingleWheelset
        The vehicle of the single runs (reading ``p0_basis``).
    A, B : ndarray
        Continuous ``ẋ = A x + B q`` of the vehicle (Eq. 7, errata fixed), SI units.
    observer : ReducedOrderObserver
        The continuous observer of Eq. (12) with error poles ``observer_poles``.
    error_poles_per_s : ndarray
        Eigenvalues of ``A22 − L A12``, 1/s.
    runs : dict of float to SpeedRun
        The single runs of seed ``seed``, by speed (km/h): ``speeds_kmh`` then the sweep.
    speed_sweep : DataFrame
        One row per sweep speed (``speed_kmh``); the ``observer_form`` observer's convergence
        time (s, -1 never), force and displacement RMS errors (N, m), the force RMS (N), and the
        other discretisation's convergence time and force error (suffix ``_paper``/``_foh``).
    noise_sweep : DataFrame
        Force relative RMS error and displacement RMS error (m) against ``noise_fraction`` at
        the first speed (seed ``seed``, its own noise draws); empty without ``side_tables``.
    plant_comparison : DataFrame
        Linear vs Hertz plant, noise-free, FOH observer: force RMS (N), its RMS error (N), the
        fraction of samples with contact lost; empty without ``side_tables``.
    monte_carlo : DataFrame
        :func:`evidence.monte_carlo` samples (``mc_seeds`` seeds × speeds × readings); empty
        without ``side_tables``.
    estimators : KalmanComparison or None
        :func:`kalman.compare`: the paper's observer, the Kalman filter with a track shaping
        filter and its RTS smoother on the Monte Carlo records at several noise levels; None
        without ``side_tables``.
    """

    vehicle: single_wheelset.SingleWheelset | None = None
    A: np.ndarray | None = None
    B: np.ndarray | None = None
    observer: reduced_order_observer.ReducedOrderObserver | None = None
    error_poles_per_s: np.ndarray | None = None
    runs: dict = field(default_factory=dict)
    speed_sweep: pd.DataFrame = field(default_factory=pd.DataFrame)
    noise_sweep: pd.DataFrame = field(default_factory=pd.DataFrame)
    plant_comparison: pd.DataFrame = field(default_factory=pd.DataFrame)
    monte_carlo: pd.DataFrame = field(default_factory=pd.DataFrame)
    estimators: KalmanComparison | None = None
