"""Monte Carlo evidence of the ``rbpf-parameter-estimation`` chapter (paper 003).

The chapter filters many independent records (seeds ``seed``, ``seed + 1``, …): ``toy_seeds``
records of the Eq. (18) toy and ``n_records`` records of the lateral vehicle.  These functions turn
the per-record results into the metrics the claim rules of
``data/rbpf-parameter-estimation/claims.toml`` read: rates with Clopper–Pearson intervals, medians
of paired differences with order-statistic intervals, and the largest bias over the five lateral
parameters with a simultaneous (Bonferroni) t interval.  Every interval comes from
:mod:`railpaper.stats`; nothing here decides a verdict.
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from railpaper.models.lateral_16state import PARAM_NAMES
from railpaper.stats import Estimate, mean_interval, median_interval, proportion_interval

LEVEL = 0.95


# ----------------------------------------------------------------------------- per record
def settle_step(abs_error: np.ndarray, tol: float) -> int:
    """First step (1-based) from which ``abs_error <= tol`` holds to the end of the record.

    Parameters
    ----------
    abs_error : ndarray, shape (K,)
        Error of one record at steps 1..K (NaN counts as outside).
    tol : float
        Threshold, in the unit of the error.

    Returns
    -------
    int
        1 if it always holds, ``K + 1`` if it fails at the last step (never settles), so that
        a record that never settles ranks after every record that does.
    """
    with np.errstate(invalid="ignore"):
        bad = np.flatnonzero(~(np.asarray(abs_error, float) <= tol))
    return 1 if bad.size == 0 else int(bad[-1]) + 2


def within_from(norm: np.ndarray, start: int, tol: float) -> bool:
    """Whether every parameter of one record stays within ``tol`` of 1 at every step from
    ``start`` (1-based) to the record's end.

    Parameters
    ----------
    norm : ndarray, shape (K, d)
        Normalised estimates θ̂/θ (1 = true value) at steps 1..K.
    start : int
        First step checked; must be <= K.
    tol : float
        Relative tolerance (0.05 = 5 %).
    """
    norm = np.asarray(norm, float)
    if not 1 <= start <= len(norm):
        raise ValueError(f"within_from: start step {start} outside the record (1..{len(norm)})")
    with np.errstate(invalid="ignore"):
        return bool(np.all(np.abs(norm[start - 1:] - 1.0) <= tol))


# ----------------------------------------------------------------------------- statistics
def rate(hits, level: float = LEVEL) -> Estimate:
    """Rate of True among the records' flags with its Clopper–Pearson interval."""
    hits = np.asarray(hits, bool).ravel()
    return proportion_interval(int(hits.sum()), hits.size, level)


def max_abs_bias(errors, level: float = LEVEL) -> Estimate:
    """Largest |mean| over the columns of ``errors`` with a simultaneous interval.

    Each column's mean gets a Student t interval at level ``1 − (1 − level)/d`` (Bonferroni), so
    all d intervals hold together with probability >= ``level``; the interval of
    ``max_j |μ_j|`` is then [max_j distance of interval j from 0, max_j largest |end| of
    interval j].

    Parameters
    ----------
    errors : array_like, shape (n, d)
        One row per record, one column per parameter (e.g. final relative errors).
    level : float
        Simultaneous confidence level.
    """
    x = np.asarray(errors, float)
    if x.ndim != 2 or x.shape[0] < 2:
        raise ValueError(f"max_abs_bias needs shape (n >= 2, d), got {x.shape}")
    per = [mean_interval(col, 1.0 - (1.0 - level) / x.shape[1]) for col in x.T]
    return Estimate(max(abs(e.value) for e in per),
                    max(max(0.0, e.low, -e.high) for e in per),
                    max(max(abs(e.low), abs(e.high)) for e in per), x.shape[0], level)


# ----------------------------------------------------------------------------- toy, Eq. (18)
def toy_metrics(stats: pd.DataFrame) -> dict:
    """Evidence metrics of the toy from its per-record table.

    Parameters
    ----------
    stats : DataFrame
        One row per (record, initial condition) with columns ``seed``, ``init`` (1 or 2),
        ``ekf_converged``, ``ekf_diverged``, ``rbpf_converged`` (bool), ``ekf_err_max``,
        ``rbpf_err_max`` (final max |error| over x1..x4), ``ekf_settle``, ``rbpf_settle``
        (steps, see :func:`settle_step`).

    Returns
    -------
    dict
        ``toy_ekf_fail_rate_init1``, ``toy_ekf_blowup_rate_init1``,
        ``toy_ekf_converge_rate_init2``, ``toy_ekf_outcome_differs_rate``,
        ``toy_rbpf_converge_rate_init1``, ``toy_rbpf_converge_both_rate``,
        ``toy_error_gap_ekf_minus_rbpf_init1``, ``toy_settle_gap_ekf_minus_rbpf_init1``, each
        with ``_low``, ``_high``, ``_n``.
    """
    one = stats[stats.init == 1].set_index("seed").sort_index()
    two = stats[stats.init == 2].set_index("seed").sort_index()
    if len(one) == 0 or not one.index.equals(two.index):
        raise ValueError("toy_metrics needs every record filtered from both initial conditions")
    out = {}
    out.update(rate(~one.ekf_converged).metrics("toy_ekf_fail_rate_init1"))
    out.update(rate(one.ekf_diverged).metrics("toy_ekf_blowup_rate_init1"))
    out.update(rate(two.ekf_converged).metrics("toy_ekf_converge_rate_init2"))
    out.update(rate(one.ekf_converged.to_numpy() != two.ekf_converged.to_numpy())
               .metrics("toy_ekf_outcome_differs_rate"))
    out.update(rate(one.rbpf_converged).metrics("toy_rbpf_converge_rate_init1"))
    out.update(rate(one.rbpf_converged.to_numpy() & two.rbpf_converged.to_numpy())
               .metrics("toy_rbpf_converge_both_rate"))
    out.update(median_interval(one.ekf_err_max - one.rbpf_err_max)
               .metrics("toy_error_gap_ekf_minus_rbpf_init1"))
    out.update(median_interval(one.ekf_settle - one.rbpf_settle)
               .metrics("toy_settle_gap_ekf_minus_rbpf_init1"))
    return out


# ----------------------------------------------------------------------------- lateral vehicle
def lateral_metrics(runs: list[np.ndarray], suffix: str, start: int = 350,
                    tol: float = 0.05) -> dict:
    """Evidence metrics of one RBPF scheme on the lateral records.

    Parameters
    ----------
    runs : list of ndarray, each (K, d)
        Normalised estimates θ̂/θ of every record (same K).
    suffix : str
        Appended to every metric name (e.g. ``"_paper_scheme"``).
    start, tol : int, float
        The paper's claim: every parameter within ``tol`` after ``start`` steps.

    Returns
    -------
    dict
        ``lateral_within_5pct_from_350_rate``: records with every parameter within ``tol`` at
        every step from ``start`` to the end; ``lateral_within_5pct_at_350_rate``: at step
        ``start`` alone; ``lateral_bias_max_abs``: largest |mean final relative error| over the
        parameters (simultaneous interval, :func:`max_abs_bias`); ``lateral_median_final_abs_
        error_max``: median over records of the largest final |relative error| — each with
        ``_low``, ``_high``, ``_n`` — and per parameter ``lateral_bias_<j>`` (mean final
        relative error, 95 % t interval).
    """
    stack = np.array(runs, float)
    finals = stack[:, -1] - 1.0
    out = {}
    out.update(rate([within_from(r, start, tol) for r in stack])
               .metrics(f"lateral_within_5pct_from_350_rate{suffix}"))
    with np.errstate(invalid="ignore"):
        at = np.all(np.abs(stack[:, start - 1] - 1.0) <= tol, axis=1)
    out.update(rate(at).metrics(f"lateral_within_5pct_at_350_rate{suffix}"))
    out.update(max_abs_bias(finals).metrics(f"lateral_bias_max_abs{suffix}"))
    out.update(median_interval(np.abs(finals).max(axis=1))
               .metrics(f"lateral_median_final_abs_error_max{suffix}"))
    for j, name in enumerate(PARAM_NAMES):
        out.update(mean_interval(finals[:, j]).metrics(f"lateral_bias_{name}{suffix}"))
    return out


def evidence_table(metrics: dict, names: dict[str, str]) -> pd.DataFrame:
    """The statistics ``names`` (metric -> description) with their 95 % intervals and sample
    counts, one row each, from a run's metrics (``<m>``, ``<m>_low``, ``<m>_high``, ``<m>_n``)."""
    rows = [dict(statistic=text, value=metrics[m], low=metrics[f"{m}_low"],
                 high=metrics[f"{m}_high"], n=int(metrics[f"{m}_n"]), metric=m)
            for m, text in names.items()]
    return pd.DataFrame(rows, columns=["statistic", "value", "low", "high", "n", "metric"])


__all__ = ["evidence_table", "lateral_metrics", "max_abs_bias", "rate", "settle_step",
           "toy_metrics", "within_from"]
