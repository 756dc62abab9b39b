"""Typed results of chapter ``rbpf-parameter-estimation``: the toy of Eq. (18) and the lateral
vehicle, record by record.

:func:`railpaper.experiments.rbpf_parameter_estimation.run` returns a
:class:`RbpfParameterEstimationResult`: the pipeline's :class:`ChapterResult` (metrics, timings,
time series) plus :attr:`~RbpfParameterEstimationResult.toy` (:class:`ToyPart`) and
:attr:`~RbpfParameterEstimationResult.lateral` (:class:`LateralPart`); the notebook reads their
named fields.

Extending: an estimator run on every lateral record (e.g. an exact posterior) is one more field
of :class:`LateralRun` with a default of ``None`` (normalised estimates ``(K, 5)`` like the
others, or its own frozen dataclass), filled where :func:`rbpf_parameter_estimation.run_lateral`
builds the records; :meth:`LateralPart.stack` then serves it by field name, and statistics over
records (coverage, rates) go into the run's metrics by
:mod:`~railpaper.experiments.rbpf_parameter_estimation_mc`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd

from railpaper.experiments.base import ChapterResult


# ----------------------------------------------------------------------------- Part 1: toy
@dataclass(frozen=True)
class ToyRun:
    """The three filters on one toy record from one initial condition (Eq. 18).

    Attributes
    ----------
    initial_condition : int
        1 = (0, 0, 0, 0) or 2 = (−0.26, 1, 0.24, −0.5), the paper's two initial values.
    start : ndarray, shape (4,)
        That initial value of (x1, x2, x3, x4) (dimensionless): the centre of the RBPF prior box
        and the EKF's initial estimate.
    rbpf_paper : ndarray, shape (K, 4)
        Estimates of x1..x4 after each measurement by the RBPF with the paper's Steps 1–2.6.
    rbpf_working : ndarray, shape (K, 4)
        The same by the RBPF with our working scheme (same prior particles).
    ekf : ndarray, shape (K, 4)
        The same by the augmented-state EKF (rows after a numerical divergence repeat the last).
    ekf_diverged : bool
        Whether the EKF diverged numerically (an estimate beyond ±1000).
    ekf_diverged_step : int
        First step (1-based) at which it diverged; −1 if it did not.
    """

    initial_condition: int
    start: np.ndarray
    rbpf_paper: np.ndarray
    rbpf_working: np.ndarray
    ekf: np.ndarray
    ekf_diverged: bool
    ekf_diverged_step: int


@dataclass(frozen=True)
class ToyPart:
    """Part 1: Eq. (18) filtered on ``toy_seeds`` records from both initial conditions.

    Attributes
    ----------
    truth : ndarray, shape (4,)
        True (x1, x2, x3, x4), dimensionless.
    steps : int
        Measurements per record (K).
    seed : int
        Seed of the illustrated record (the first).
    illustrated : dict of int to ToyRun
        The illustrated record's runs by initial condition (1, 2).
    records : DataFrame
        One row per (record, initial condition): ``seed``, ``init`` (1 or 2), final largest
        absolute error over x1..x4 of each filter (``rbpf_err_max``, ``rbpf_working_err_max``,
        ``ekf_err_max``; an EKF that diverged counts 1000), ``ekf_diverged``, ``ekf_converged``,
        ``rbpf_converged`` (final largest error <= ``toy_bias_tol``; the EKF also not diverged)
        and the settle steps ``rbpf_settle``, ``ekf_settle`` (first step from which the error
        stays within ``toy_bias_tol``; K + 1 = never).
    """

    truth: np.ndarray
    steps: int
    seed: int
    illustrated: dict
    records: pd.DataFrame

    def table(self) -> pd.DataFrame:
        """The illustrated record's estimates per step: column ``step`` (1..K), then
        ``x<j>_<filter>_init<i>`` for filters ``rbpf`` (paper scheme), ``rbpfworking``, ``ekf``
        (the chapter's ``toy_timeseries.csv``)."""
        out = pd.DataFrame({"step": np.arange(1, self.steps + 1)})
        for ic, run in self.illustrated.items():
            for key, arr in (("rbpf", run.rbpf_paper), ("rbpfworking", run.rbpf_working),
                             ("ekf", run.ekf)):
                for j in range(4):
                    out[f"x{j + 1}_{key}_init{ic}"] = arr[:, j]
        return out


# ----------------------------------------------------------------------------- Part 2: lateral
@dataclass(frozen=True)
class LateralRecord:
    """One lateral record: what the filters are given.

    Attributes
    ----------
    seed : int or None
        Seed of the simulated record (track profile and sensor noise); None for a user's file.
    y : ndarray, shape (K, 5)
        Measurements at steps 1..K: lateral accelerations of wheelsets 1, 2, the bogie and the
        car body (m/s²) and the bogie yaw rate (rad/s) (:data:`lateral_16state.CHANNELS`).
    u_mps : ndarray, shape (K, 2) or None
        Track lateral velocity under wheelsets 1 and 2 (m/s), held over each filter step
        (``u_k`` = value at step k − 1); None when a user's file has none.
    du_var_m2ps2 : ndarray, shape (2,)
        Variance of the input's change over one filter step, (m/s)²: the filters' process noise.
    u_var_m2ps2 : ndarray, shape (2,)
        Variance of the input itself, (m/s)²: the process noise when the input is not known.
    """

    seed: int | None
    y: np.ndarray
    u_mps: np.ndarray | None
    du_var_m2ps2: np.ndarray
    u_var_m2ps2: np.ndarray


@dataclass(frozen=True)
class LateralRun:
    """Every estimator on one lateral record; estimates normalised by the true values.

    Attributes
    ----------
    seed : int or None
        The record's seed (None for a user's file).
    rbpf_paper_norm : ndarray, shape (K, 5)
        θ̂/θ after each measurement, RBPF with the paper's Steps 1–2.6 (1 = true value), in the
        order of :data:`lateral_16state.PARAM_NAMES` (C_sy, λ, K_py, K_sy, C_saly).
    rbpf_working_norm : ndarray, shape (K, 5)
        The same with our working scheme (same prior particles).
    ekf_norm : tuple of ndarray, each (K_ekf, 5)
        The augmented EKF from each initial guess (``ekf_guesses`` on the first record, one on
        the others; empty for a user's file); all NaN if that run diverged numerically.
    """

    seed: int | None
    rbpf_paper_norm: np.ndarray
    rbpf_working_norm: np.ndarray
    ekf_norm: tuple = ()


@dataclass(frozen=True)
class LateralPart:
    """Part 2: the lateral vehicle, its hunting speed, and the filters on ``n_records`` records.

    Attributes
    ----------
    fixed : dict of str to float
        The vehicle's fixed quantities (SI units, keys :data:`lateral_16state.FIXED_KEYS`).
    theta_true : ndarray, shape (5,)
        True (C_sy N s/m, λ 1, K_py N/m, K_sy N/m, C_saly N s/m).
    t_s : ndarray, shape (K,)
        Time of each filter step from the first measurement, s.
    runs : tuple of LateralRun
        One per record, seeds ``seed``, ``seed + 1`` …; the first is the illustrated one.
    critical_speed : DataFrame
        ``speed_kmh`` and, per reading of the "half" masses (``chosen``, ``all_halved``,
        ``wheelset_bogie_doubled``), the largest real part of the eigenvalues of A, 1/s.
    crlb : DataFrame or None
        Relative Cramér–Rao standard deviations on the first record: column ``parameter`` and
        ``<known|unknown>_<steps>`` (input known / unknown, after 350 and K steps); None for a
        user's file.
    ekf_converged_count : int or None
        How many of the first record's EKF guesses end within 5 % of every parameter.
    """

    fixed: dict
    theta_true: np.ndarray
    t_s: np.ndarray
    runs: tuple
    critical_speed: pd.DataFrame
    crlb: pd.DataFrame | None = None
    ekf_converged_count: int | None = None

    @property
    def illustrated(self) -> LateralRun:
        """The first record's run (seed ``seed``)."""
        return self.runs[0]

    def stack(self, estimator: str) -> np.ndarray:
        """Normalised estimates of every record, shape (records, K, 5), of the
        :class:`LateralRun` field ``estimator`` (e.g. ``"rbpf_paper_norm"``)."""
        return np.array([getattr(run, estimator) for run in self.runs])


@dataclass
class RbpfParameterEstimationResult(ChapterResult):
    """What :func:`rbpf_parameter_estimation.run` returns: :class:`ChapterResult` plus the two
    parts.

    Attributes
    ----------
    toy : ToyPart or None
        Part 1, the toy of Eq. (18).
    lateral : LateralPart or None
        Part 2, the lateral vehicle (None when ``lateral`` is false: a sweep sample of the toy).
    """

    toy: ToyPart | None = None
    lateral: LateralPart | None = None


__all__ = ["LateralPart", "LateralRecord", "LateralRun", "RbpfParameterEstimationResult",
           "ToyPart", "ToyRun"]
