"""Typed results of chapter ``quasi-gaussian-rbpf``: one record, the computing times, the run.

:func:`railpaper.experiments.quasi_gaussian_rbpf.experiment.run` returns a :class:`QuasiGaussianRBPFResult`;
the notebook, the figures and the tables read its named fields.  The parameters ``a``, ``b``, the
state ``x`` and the measurements ``y`` of the toy system (Eqs. 20–21) are dimensionless (unit 1);
steps are counted from 1 (step ``k`` is the estimate after ``y_k``).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import pandas as pd

from railpaper.engine.grid_posterior import GridPosterior
from railpaper.engine.rbpf import FilterRun
from railpaper.experiments.base import ChapterResult
from railpaper.experiments.quasi_gaussian_rbpf.readings import ReadingsStudy


@dataclass(frozen=True)
class OneRecord:
    """One simulated record and everything run on it.

    Attributes
    ----------
    index : int
        Record index: its random streams are ``(seed, index)``.
    states : ndarray, shape (K + 1, 2)
        True linear state ``x_0 … x_K`` (1).
    measurements : ndarray, shape (K, 2)
        Measurements ``y_1 … y_K`` (1).
    exact : GridPosterior
        Exact posterior of ``(a, b)`` on the grid after every step: ``exact.mean`` and
        ``exact.std`` have shape (K, 2), columns ``a``, ``b`` (1).
    runs : dict of str to FilterRun
        Every filter of :data:`~railpaper.experiments.quasi_gaussian_rbpf.evidence.FILTERS` on
        the record (``theta_mean``, ``theta_std`` (K, 2) of ``a``, ``b``; ``x_mean`` (K, 2);
        ``ess`` (K,) in particles).
    runs_without_threshold : dict of str to FilterRun
        Both Q-GRBPFs again without their weight threshold, on the same random streams.
    """

    index: int
    states: np.ndarray
    measurements: np.ndarray
    exact: GridPosterior
    runs: dict[str, FilterRun]
    runs_without_threshold: dict[str, FilterRun]

    @property
    def steps(self) -> np.ndarray:
        """Step numbers ``1 … K``."""
        return np.arange(1, len(self.measurements) + 1)


@dataclass(frozen=True)
class ComputingTime:
    """Wall-clock computing times on the main record (not reproducible bit for bit).

    Attributes
    ----------
    curves_s_per_step : DataFrame
        ``filter, n_particles, seconds_per_step``: fastest of ``timing_repeats`` runs of
        ``timing_steps`` steps, per filter and particle count (s per step).
    paired_s_per_step : DataFrame
        One row per paired repeat at ``timing_ratio_particles``: ``repeat`` and the median
        seconds of one step of ``rbpf``, ``qgrbpf``, ``qgrbpf_printed``, then of one systematic
        ``resampling`` of the RBPF's bank (s).
    """

    curves_s_per_step: pd.DataFrame
    paired_s_per_step: pd.DataFrame


@dataclass
class QuasiGaussianRBPFResult(ChapterResult):
    """What :func:`quasi_gaussian_rbpf.run` returns: :class:`ChapterResult` plus named results.

    Attributes
    ----------
    main : OneRecord or None
        The main record (index ``record``), every filter and the exact posterior on it.
    monte_carlo : DataFrame
        One row per Monte Carlo record (column ``replicate`` = record index, the main record
        first) with the per-record metrics of
        :func:`~railpaper.experiments.quasi_gaussian_rbpf.experiment.record_metrics`: settling and
        convergence steps (step, -1 never), final errors and errors at ``short_horizon`` (1),
        final distances from the exact posterior mean in posterior std (``final_z_*``) and
        final spread ratios (filter std / posterior std).
    computing_time : ComputingTime or None
        The computing times; None when ``timing`` is false.
    readings : ReadingsStudy or None
        The exact posterior's settling steps under each reading of the printed noise settings
        and figure horizon (:mod:`~railpaper.experiments.quasi_gaussian_rbpf.readings`); None
        when ``readings_records`` is 0.
    """

    main: OneRecord | None = None
    monte_carlo: pd.DataFrame = field(default_factory=pd.DataFrame)
    computing_time: ComputingTime | None = None
    readings: ReadingsStudy | None = None
