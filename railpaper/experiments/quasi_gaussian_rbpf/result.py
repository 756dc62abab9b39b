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

from railpaper.engine import FilterRun, GridPosterior
from railpaper.experiments.base import ChapterResult
from railpaper.experiments.quasi_gaussian_rbpf.spec import PAPER_STEPS, PARAMS
from railpaper.stats import prediction_interval


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
    """What :func:`~railpaper.experiments.quasi_gaussian_rbpf.experiment.run` returns:
    :class:`ChapterResult` plus named results.

    Attributes
    ----------
    main : OneRecord or None
        The main record (index ``record``), every filter and the exact posterior on it.
    monte_carlo : DataFrame
        One row per Monte Carlo record (column ``seed`` = record index, the main record first,
        the others in record order) with the per-record metrics of
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


@dataclass(frozen=True)
class Reading:
    """One reading of the printed noise settings (variances of w, e and the state prior std)."""

    key: str
    label: str
    q_var: float
    r_var: float
    p0_std: float
    source: str


@dataclass(frozen=True)
class ReadingsStudy:
    """The exact posterior's pace under every reading.

    Attributes
    ----------
    readings : tuple of Reading
    horizons_steps : tuple of int
        Figure horizons H (steps) the settling step is read against.
    table : pandas.DataFrame
        One row per (reading, horizon, parameter): ``reading``, ``horizon_steps``, ``parameter``,
        ``settling_step`` (median) with ``settling_step_low``/``_high`` (95 %), ``n_records``.
    errors : pandas.DataFrame
        One row per (reading, parameter): median |posterior mean − truth| at step 4
        (``abs_error_step4``) and at the RBPF's step (``abs_error_rbpf_step``), posterior std at
        both (``std_step4``, ``std_rbpf_step``).
    settling_steps : numpy.ndarray, (readings, horizons, parameters, records)
        Per-record settling steps behind ``table``.
    """

    readings: tuple
    horizons_steps: tuple
    table: pd.DataFrame
    errors: pd.DataFrame
    settling_steps: np.ndarray

    def interval_gap(self, reading: str, par: str, step: int) -> float:
        """:func:`interval_gap` of this study (steps)."""
        return interval_gap(self.table, reading, par, step)

    def metrics(self) -> dict:
        """``reading_<key>_settling_step_<p>_h<H>`` (+ ``_low``, ``_high``, ``_n``),
        ``reading_<key>_interval_gap_<p>_<rbpf|qgrbpf>`` (steps from the paper's step ± 5 to the
        nearest interval; 0 = possible at some horizon),
        ``reading_<key>_abs_error_<p>_step{4,<rbpf step>}`` and, at the shortest and the longest
        horizon (the chapter's bracket), the records' 95 % prediction interval of the settling step
        (``reading_<key>_settling_step_<p>_h<H>_p025`` … ``_p975_high``)."""
        m = {}
        for row in self.table.itertuples():
            name = f"reading_{row.reading}_settling_step_{row.parameter}_h{row.horizon_steps}"
            m.update({name: row.settling_step, f"{name}_low": row.settling_step_low,
                      f"{name}_high": row.settling_step_high, f"{name}_n": row.n_records})
        # the chapter's horizon bracket: the shortest figure and the record (first, last)
        for h in (0, len(self.horizons_steps) - 1):
            for i, reading in enumerate(self.readings):
                for j, par in enumerate(PARAMS):
                    name = (f"reading_{reading.key}_settling_step_{par}"
                            f"_h{self.horizons_steps[h]}")
                    m.update(prediction_interval(self.settling_steps[i, h, j]).metrics(name))
        for reading in self.readings:
            for (par, filt), step in PAPER_STEPS.items():
                m[f"reading_{reading.key}_interval_gap_{par}_{filt}"] = self.interval_gap(
                    reading.key, par, step)
        for row in self.errors.itertuples():
            step = PAPER_STEPS[(row.parameter, "rbpf")]
            m[f"reading_{row.reading}_abs_error_{row.parameter}_step4"] = row.abs_error_step4
            m[f"reading_{row.reading}_abs_error_{row.parameter}_step{step}"] = \
                row.abs_error_rbpf_step
        return m


def interval_gap(table: pd.DataFrame, reading: str, par: str, step: int) -> float:
    """Steps between the paper's ``step ± 5`` and the nearest 95 % interval of the posterior's
    median settling step over all horizons (0: some horizon's interval meets it)."""
    rows = table[(table.reading == reading) & (table.parameter == par)]
    low, high = max(step - 5, 1), step + 5
    return float(min(max(0.0, r.settling_step_low - high, low - r.settling_step_high)
                     for r in rows.itertuples()))
