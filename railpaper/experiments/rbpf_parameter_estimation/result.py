"""Typed results of chapter ``rbpf-parameter-estimation``: the toy of Eq. (18) and the lateral
vehicle, record by record.

:func:`railpaper.experiments.rbpf_parameter_estimation.experiment.run` returns a
:class:`RbpfParameterEstimationResult`: the pipeline's :class:`ChapterResult` (metrics, timings,
time series) plus :attr:`~RbpfParameterEstimationResult.toy` (:class:`ToyPart`) and
:attr:`~RbpfParameterEstimationResult.lateral` (:class:`LateralPart`); the notebook reads their
named fields.

The exact posterior (:class:`PosteriorRun`, by IBIS) sits beside the filters: per lateral record in
:attr:`LateralRun.posterior` (the first ``ibis_records``), for the toy's illustrated record in
:attr:`ToyPart.posterior` with the per-record calibration in :attr:`ToyPart.coverage`; the
model-error study in :attr:`RbpfParameterEstimationResult.mismatch`.

Extending: an estimator run on every lateral record is one more field of :class:`LateralRun` with
a default of ``None`` (normalised estimates ``(K, 5)`` like the others, or its own frozen
dataclass), filled where
:func:`~railpaper.experiments.rbpf_parameter_estimation.lateral.run_lateral` builds the records;
:meth:`LateralPart.stack` then serves it by field name (``"posterior.sd"``: a field of a field),
and statistics over records (coverage, rates) go into the run's metrics by
:mod:`~railpaper.experiments.rbpf_parameter_estimation.evidence` and
:mod:`~railpaper.experiments.rbpf_parameter_estimation.posterior`.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import pandas as pd

from railpaper.experiments.base import ChapterResult
from railpaper.experiments.lateral_vehicle import LateralRecord
from railpaper.models.lateral_16state import PARAM_NAMES


# ----------------------------------------------------------------------------- exact posterior
@dataclass(frozen=True)
class PosteriorRun:
    """The exact posterior of the static parameters after every step, by IBIS
    (:func:`railpaper.engine.ibis.run_ibis`: no artificial parameter noise, no tempering).

    Attributes
    ----------
    mean, sd : ndarray, shape (K, d)
        Posterior mean and standard deviation after y_1..y_k (row k − 1), in the unit of the
        part: the toy's x_j (dimensionless) or the lateral θ divided by its true value (1).
    q05, q95 : ndarray, shape (K, d)
        5 % and 95 % posterior quantiles: the 90 % equal-tailed credible interval.
    ess : ndarray, shape (K,)
        Effective sample size of the sampler's weights at each step.
    resample_steps : ndarray of int
        Steps (1-based) after which the particles were resampled and moved.
    particles : int
        IBIS particles N.
    filter_steps : int
        Kalman filter steps the sampler ran in total (its cost).
    """

    mean: np.ndarray
    sd: np.ndarray
    q05: np.ndarray
    q95: np.ndarray
    ess: np.ndarray
    resample_steps: np.ndarray
    particles: int
    filter_steps: int

    @classmethod
    def from_ibis(cls, run, scale=1.0) -> "PosteriorRun":
        """Summaries of an :class:`~railpaper.engine.ibis.IBISRun`, divided by ``scale``
        (the true θ for the lateral model; 1 for the toy)."""
        scale = np.asarray(scale, float)
        return cls(mean=run.mean / scale, sd=run.sd / scale, q05=run.q05 / scale,
                   q95=run.q95 / scale, ess=run.ess, resample_steps=run.resample_steps,
                   particles=int(run.theta.shape[0]), filter_steps=int(run.n_filter_steps))


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
    rbpf_paper_sd, rbpf_working_sd : ndarray, shape (K, 4)
        Weighted standard deviation of each scheme's particles (the spread behind its
        estimate), dimensionless.
    """

    initial_condition: int
    start: np.ndarray
    rbpf_paper: np.ndarray
    rbpf_working: np.ndarray
    ekf: np.ndarray
    ekf_diverged: bool
    ekf_diverged_step: int
    rbpf_paper_sd: np.ndarray | None = None
    rbpf_working_sd: np.ndarray | None = None


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
        stays within ``toy_bias_tol``; K + 1 = never); ``rbpf_covers_x<j>``,
        ``rbpf_working_covers_x<j>``: whether the scheme's final mean ± 1.645 sd holds the true
        x_j (its 90 % interval, Gaussian reading of the particle spread).
    record : Simulation or None
        The illustrated record (``u`` (K, 1), ``y`` (K, 1)).
    posterior : PosteriorRun or None
        The exact posterior on the illustrated record (prior box of initial condition 1).
    coverage : DataFrame or None
        One row per (record, parameter) of the records the exact posterior was computed on:
        ``seed``, ``parameter`` (x1..x4), ``truth``, ``posterior_q05``, ``posterior_q95``,
        ``posterior_covers``, ``paper_covers``, ``tempered_covers`` (initial condition 1).
    rows : DataFrame
        The same records as the study ``toy``'s rows: one wide row per record (``seed``, then
        the columns above suffixed ``_init1``, ``_init2``), as the ledger reads them.
    """

    truth: np.ndarray
    steps: int
    seed: int
    illustrated: dict
    records: pd.DataFrame
    record: object | None = None
    posterior: PosteriorRun | None = None
    coverage: pd.DataFrame | None = None
    rows: pd.DataFrame | None = None

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
class LateralRun:
    """Every estimator on one lateral record; estimates normalised by the true values.

    Attributes
    ----------
    seed : int or None
        The record's seed (None for a user's file).
    rbpf_paper_norm : ndarray, shape (K, 5)
        θ̂/θ after each measurement, RBPF with the paper's Steps 1–2.6 (1 = true value), in the
        order of :data:`~railpaper.models.lateral_16state.PARAM_NAMES` (C_sy, λ, K_py, K_sy,
        C_saly).
    rbpf_working_norm : ndarray, shape (K, 5)
        The same with our working scheme (same prior particles).
    ekf_norm : tuple of ndarray, each (K_ekf, 5)
        The augmented EKF from each initial guess (``ekf_guesses`` on the first record, one on
        the others; empty for a user's file); all NaN if that run diverged numerically.
    rbpf_paper_sd_norm, rbpf_working_sd_norm : ndarray, shape (K, 5)
        Weighted standard deviation of each scheme's particles divided by the true values (1).
    posterior : PosteriorRun or None
        The exact posterior (IBIS, normalised by the true values) on the first
        ``ibis_records`` records; None on the others.
    """

    seed: int | None
    rbpf_paper_norm: np.ndarray
    rbpf_working_norm: np.ndarray
    ekf_norm: tuple = ()
    rbpf_paper_sd_norm: np.ndarray | None = None
    rbpf_working_sd_norm: np.ndarray | None = None
    posterior: PosteriorRun | None = None


@dataclass(frozen=True)
class LateralPart:
    """Part 2: the lateral vehicle, its hunting speed, and the filters on ``n_records`` records.

    Attributes
    ----------
    fixed : dict of str to float
        The vehicle's fixed quantities (SI units, keys
        :data:`~railpaper.models.lateral_16state.FIXED_KEYS`).
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
    paper_scheme_rows : DataFrame
        One row per record filtered by the paper-scheme RBPF (seeds ``seed`` … ``seed +
        paper_records − 1``: those of ``runs``, then the records it filtered alone, its claims
        needing more records than the other estimators): ``seed``, ``within_5pct_from_350``,
        ``within_5pct_at_350``, ``final_relative_error_<param>`` (1) — the rows of the study
        ``lateral_paper_scheme``.  Empty for a user's file.
    working_scheme_rows : DataFrame
        The same for our working scheme (``working_records`` records).
    ekf_rows : DataFrame
        One row per record of ``runs`` for the augmented EKF's first guess: ``seed``,
        ``ekf_converged``, ``ekf_diverged``, ``final_relative_error_<param>`` — the rows of the
        study ``lateral_ekf``.  Empty for a user's file.
    """

    fixed: dict
    theta_true: np.ndarray
    t_s: np.ndarray
    runs: tuple
    critical_speed: pd.DataFrame
    crlb: pd.DataFrame | None = None
    ekf_converged_count: int | None = None
    paper_scheme_rows: pd.DataFrame = field(default_factory=pd.DataFrame)
    working_scheme_rows: pd.DataFrame = field(default_factory=pd.DataFrame)
    ekf_rows: pd.DataFrame = field(default_factory=pd.DataFrame)

    def final_relative_errors(self, scheme: str) -> np.ndarray:
        """θ̂/θ − 1 at the last step of every record the ``scheme`` ('paper' or 'working') RBPF
        filtered, shape (records, 5): from its study's rows, or from ``runs`` on a user's file."""
        rows = self.paper_scheme_rows if scheme == "paper" else self.working_scheme_rows
        if len(rows):
            return rows[[f"final_relative_error_{name}" for name in PARAM_NAMES]].to_numpy(float)
        return self.stack(f"rbpf_{scheme}_norm")[:, -1] - 1.0

    @property
    def illustrated(self) -> LateralRun:
        """The first record's run (seed ``seed``)."""
        return self.runs[0]

    def stack(self, estimator: str) -> np.ndarray:
        """Normalised estimates of every record, shape (records, K, 5), of the
        :class:`LateralRun` field ``estimator`` (e.g. ``"rbpf_paper_norm"``); a dotted name
        reads a field of that field (``"posterior.sd"``) on the records that have it."""
        values = []
        for run in self.runs:
            value = run
            for name in estimator.split("."):
                value = None if value is None else getattr(value, name)
            if value is not None:
                values.append(value)
        return np.array(values)


@dataclass
class RbpfParameterEstimationResult(ChapterResult):
    """What :func:`~railpaper.experiments.rbpf_parameter_estimation.experiment.run` returns:
    :class:`ChapterResult` plus the two parts.

    Attributes
    ----------
    toy : ToyPart or None
        Part 1, the toy of Eq. (18).
    lateral : LateralPart or None
        Part 2, the lateral vehicle (None when ``lateral`` is false: a sweep sample of the toy).
    mismatch : MismatchResult or None
        The EKF and our tempered RBPF on the truth plant with model error
        (:func:`railpaper.experiments.rbpf_parameter_estimation.mismatch.run_mismatch`, the
        first ``mismatch_records`` seeds, mismatch plant only: the matched records are Part 2's);
        None without Part 2 or on a user's record.
    """

    toy: ToyPart | None = None
    lateral: LateralPart | None = None
    mismatch: object | None = None


STEPS = (100, 350, 1000)           # the steps the issue reports, besides the last


def steps_reported(K: int) -> list[int]:
    """The steps of :data:`STEPS` inside a record of K steps, then K (sorted, no repeats)."""
    return sorted({k for k in STEPS if k <= K} | {K})


__all__ = ["LateralPart", "LateralRecord", "LateralRun", "PosteriorRun",
           "RbpfParameterEstimationResult", "ToyPart", "ToyRun"]
