"""Monte Carlo evidence of chapter ``quasi-gaussian-rbpf``: the statistics its claim rules read.

Input is the chapter's Monte Carlo table: one row per record (the rows of the study
:data:`~railpaper.experiments.quasi_gaussian_rbpf.experiment.MONTE_CARLO`, column ``seed`` =
record index), with the per-record metrics of
:func:`railpaper.experiments.quasi_gaussian_rbpf.experiment.record_metrics` (settling steps, final errors and
errors at the chapter's ``short_horizon`` step, final distances from the exact posterior mean in
posterior standard deviations ``final_z``, final spread ratios).  Every statistic is a median with its distribution-free 95 % interval or a rate
with its Clopper–Pearson interval (:mod:`railpaper.stats`), written as ``name``, ``name_low``,
``name_high`` and ``name_n`` (records).  No verdict is decided here: ``data/quasi-gaussian-rbpf/
claims.toml`` does that.

Paired statistics compare two filters (or one filter with and without its weight threshold) on
the same record, so the record's own difficulty cancels:

* accuracy gain (paper 004's own measure, see the errata):
  ``100 (|e_RBPF| − |e_Q-GRBPF|) / |true value|`` in percentage points, per parameter and averaged
  over a and b;
* settling advantage: ``settling step of the RBPF − settling step of the Q-GRBPF`` (steps),
  averaged over a and b;
* threshold effect: ``worst |z| without the threshold − worst |z| with it`` (posterior std), where
  worst |z| = max(|z_a|, |z_b|) is the final distance from the exact posterior mean.
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from railpaper.experiments.quasi_gaussian_rbpf.spec import (
    FILTERS,
    NO_THRESHOLD,
    PARAMS,
    QGRBPF_READINGS,
    Settings,
    true_values,
)
from railpaper.stats import median_interval, prediction_interval, proportion_interval

#: |z| at or below which a final estimate is "within 2 posterior std" (satisfactory).
Z_SATISFACTORY = 2.0


def quantile_steps(steps, n_steps: int, q: float) -> int:
    """Quantile of convergence steps with 'never' (−1) counted as later than the last step.

    Returns −1 when the quantile is 'never'.
    """
    steps = np.asarray(steps)
    value = np.quantile(np.where(steps < 0, n_steps + 1, steps), q, method="inverted_cdf")
    return -1 if value > n_steps else int(value)


def accuracy_gain(error_reference, error_new, true_value: float) -> np.ndarray:
    """Paper 004's accuracy gain of ``new`` over ``reference``, percentage points of the truth.

    ``100 (|e_reference| − |e_new|) / |true_value|`` per record: positive when ``new`` ends
    closer to the truth.  (0.167 − 0.066) / 0.7 gives the paper's 14.4 %.
    """
    return 100.0 * (np.abs(np.asarray(error_reference, float))
                    - np.abs(np.asarray(error_new, float))) / abs(true_value)


def worst_abs_z(table: pd.DataFrame, name: str) -> np.ndarray:
    """Per record, max(|z_a|, |z_b|) of filter ``name``: its final distance from the exact
    posterior mean in posterior std, worst parameter."""
    return np.max(np.abs(np.stack([table[f"final_z_{par}_{name}"].to_numpy(float)
                                   for par in PARAMS])), axis=0)


def satisfactory_count(table: pd.DataFrame, name: str) -> int:
    """Records in which filter ``name`` ends within 2 posterior std on both a and b."""
    return int(np.sum(worst_abs_z(table, name) <= Z_SATISFACTORY))


def settling_advantage(table: pd.DataFrame, name: str) -> np.ndarray:
    """Per record, mean over a and b of (RBPF settling step − ``name``'s settling step)."""
    return np.mean([table[f"settling_step_{par}_rbpf"].to_numpy(float)
                    - table[f"settling_step_{par}_{name}"].to_numpy(float) for par in PARAMS],
                   axis=0)


def threshold_effect(table: pd.DataFrame, name: str) -> np.ndarray:
    """Per record, worst |z| without the weight threshold minus worst |z| with it (positive:
    the threshold brought the final estimate closer to the exact posterior mean)."""
    return worst_abs_z(table, name + NO_THRESHOLD) - worst_abs_z(table, name)


def _per_record(table: pd.DataFrame, par: str, name: str):
    """(column, metric stem, per-record values) of the settling steps and |errors| of filter
    ``name`` (the posterior has no step-60 settling column)."""
    columns = [("settling_step", "mc_settling_step", False),
               ("short_settling_step", "mc_short_settling_step", False),
               ("final_error", "mc_abs_final_error", True),
               ("short_error", "mc_abs_short_error", True)]
    for column, stem, absolute in columns:
        if name == "posterior" and column == "short_settling_step":
            continue
        values = table[f"{column}_{par}_{name}"]
        yield column, f"{stem}_{par}_{name}", np.abs(values) if absolute else values


def descriptive_metrics(table: pd.DataFrame, n_steps: int) -> dict:
    """Monte Carlo summaries shown by the chapter (no claim rule reads them)."""
    m = {"mc_records": len(table)}
    for par in PARAMS:
        for name in FILTERS:
            steps = table[f"convergence_step_{par}_{name}"].to_numpy()
            for label, q in (("q10", 0.1), ("median", 0.5), ("q90", 0.9)):
                m[f"mc_{label}_convergence_step_{par}_{name}"] = quantile_steps(steps, n_steps, q)
            m[f"mc_never_converged_fraction_{par}_{name}"] = float(np.mean(steps < 0))
            m[f"mc_median_first_within_{par}_{name}"] = quantile_steps(
                table[f"first_within_{par}_{name}"].to_numpy(), n_steps, 0.5)
            m[f"mc_median_abs_final_z_{par}_{name}"] = float(
                np.median(np.abs(table[f"final_z_{par}_{name}"])))
        for name in FILTERS + ("posterior",):
            err = table[f"final_error_{par}_{name}"].to_numpy(float)
            m[f"mc_rms_final_error_{par}_{name}"] = float(np.sqrt(np.mean(err ** 2)))
        m[f"mc_median_final_std_{par}_posterior"] = float(
            np.median(table[f"final_std_{par}_posterior"]))
    return m


def evidence_metrics(table: pd.DataFrame, truth: dict[str, float]) -> dict:
    """The statistics the chapter's claim rules read, each with its 95 % interval and n.

    Parameters
    ----------
    table : DataFrame
        Monte Carlo records (one row each), columns as in the module docstring.
    truth : dict
        ``{"a": a_true, "b": b_true}`` (1).

    Returns
    -------
    dict
        ``mc_settling_step_<p>_<f>`` (step), ``mc_abs_final_error_<p>_<f>`` and
        ``mc_abs_short_error_<p>_<f>`` (|error| at the last step and at ``short_horizon``, 1),
        ``mc_within_2std_rate_<p>_<f>``, ``mc_final_std_ratio_<p>_<f>`` (1),
        ``mc_satisfactory_rate_<f>``, ``mc_accuracy_gain_<p>_<q>`` and ``mc_accuracy_gain_ab_<q>``
        (percentage points), ``mc_settling_advantage_<q>`` (steps), ``mc_threshold_effect_<q>``
        (posterior std), ``mc_large_error_rate_<q>[_nothreshold]``; each with ``_low``,
        ``_high`` and ``_n``.  The settling steps and |final errors| of the filters and the
        accuracy gains also carry the records' 95 % prediction interval (``_p025``, ``_p975``,
        each with ``_low``/``_high`` and ``_clipped``; :func:`railpaper.stats.prediction_interval`),
        at our last step and at step ``short_horizon`` (``mc_short_settling_step_…``,
        ``mc_abs_short_error_…``, ``mc_short_accuracy_gain_…``): the two ends of the chapter's
        bracket for the lost figure horizon.  ``<f>`` runs over the filters (and ``posterior``
        for settling steps and errors), ``<q>`` over the two readings of Eq. (10).
    """
    n = len(table)
    m = {}
    for par in PARAMS:
        for name in FILTERS + ("posterior",):
            for column, metric, values in _per_record(table, par, name):
                if column != "short_settling_step":       # the median: every column but this
                    m.update(median_interval(values).metrics(metric))
                if name in FILTERS:   # where one run falls (single-run rows, both bracket ends)
                    m.update(prediction_interval(values).metrics(metric))
        for name in FILTERS:
            inside = int(np.sum(np.abs(table[f"final_z_{par}_{name}"]) <= Z_SATISFACTORY))
            m.update(proportion_interval(inside, n).metrics(f"mc_within_2std_rate_{par}_{name}"))
            m.update(median_interval(table[f"final_std_ratio_{par}_{name}"]).metrics(
                f"mc_final_std_ratio_{par}_{name}"))
    for name in FILTERS:
        m.update(proportion_interval(satisfactory_count(table, name), n).metrics(
            f"mc_satisfactory_rate_{name}"))
    for q in QGRBPF_READINGS:
        gains = [accuracy_gain(table[f"final_error_{par}_rbpf"], table[f"final_error_{par}_{q}"],
                               truth[par]) for par in PARAMS]
        for par, gain in zip(PARAMS, gains):
            m.update(median_interval(gain).metrics(f"mc_accuracy_gain_{par}_{q}"))
            m.update(prediction_interval(gain).metrics(f"mc_accuracy_gain_{par}_{q}"))
            short_gain = accuracy_gain(table[f"short_error_{par}_rbpf"],
                                       table[f"short_error_{par}_{q}"], truth[par])
            m.update(prediction_interval(short_gain).metrics(f"mc_short_accuracy_gain_{par}_{q}"))
        m.update(median_interval(np.mean(gains, axis=0)).metrics(f"mc_accuracy_gain_ab_{q}"))
        m.update(median_interval(settling_advantage(table, q)).metrics(
            f"mc_settling_advantage_{q}"))
        m.update(median_interval(threshold_effect(table, q)).metrics(f"mc_threshold_effect_{q}"))
        for variant in (q, q + NO_THRESHOLD):
            large = int(np.sum(worst_abs_z(table, variant) > Z_SATISFACTORY))
            m.update(proportion_interval(large, n).metrics(f"mc_large_error_rate_{variant}"))
    return m


def monte_carlo_metrics(table: pd.DataFrame, settings: Settings) -> dict:
    """The reduce of the Monte Carlo study: :func:`descriptive_metrics` and
    :func:`evidence_metrics` of the table of records (one row each, in record order: the means
    are summed in that order)."""
    return dict(descriptive_metrics(table, settings.n_steps),
                **evidence_metrics(table, true_values(settings)))
