"""Monte Carlo evidence of the ``rbpf-parameter-estimation`` chapter (paper 003).

The chapter filters many independent records (seeds ``seed``, ``seed + 1``, …): ``toy_seeds``
records of the Eq. (18) toy and ``n_records`` records of the lateral vehicle.  These functions turn
the toy's per-record results into the metrics the claim rules of
``data/rbpf-parameter-estimation/claims.toml`` read (rates with Clopper–Pearson intervals, medians
of paired differences with order-statistic intervals) and the evidence table of the page; the
metrics of a stack of lateral runs are
:func:`railpaper.experiments.rbpf_parameter_estimation.lateral.lateral_metrics`.  Every interval
comes from :mod:`railpaper.stats`; nothing here decides a verdict.
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from railpaper.stats import max_abs_median, median_interval, rate


# ----------------------------------------------------------------------------- toy, Eq. (18)
def toy_metrics(stats: pd.DataFrame) -> dict:
    """Evidence metrics of the toy from its per-record table.

    Parameters
    ----------
    stats : DataFrame
        One row per (record, initial condition) with columns ``seed``, ``init`` (1 or 2),
        ``ekf_converged``, ``ekf_diverged``, ``rbpf_converged`` (bool), ``ekf_err_max``,
        ``rbpf_err_max`` (final max |error| over x1..x4), ``ekf_settle``, ``rbpf_settle``
        (steps, see :func:`railpaper.settling.settling_step`).

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


def toy_offset_metrics(records: pd.DataFrame, coverage: pd.DataFrame, truth) -> dict:
    """How far the EKF's final estimate lies from the exact posterior mean on the toy, typically.

    From initial condition 2 (where the EKF converges), on the records with an exact posterior
    (``coverage``) where it converged
    (``ekf_converged``: final |error| within ``toy_bias_tol`` in every x_j, so a failed run is not
    read as an offset): per record and parameter the offset (x̂_j − E[x_j | y]) / |x_j| from the
    exact posterior mean (IBIS, ``coverage.posterior_mean``); per parameter its median with a
    distribution-free interval at the Bonferroni level 1 − 0.05/4, so the four hold together at
    95 %; the statistic is the largest |median| over x1..x4
    (:func:`railpaper.stats.max_abs_median`): ``toy_ekf_max_abs_offset_init2``.
    The same for the paper-scheme RBPF on the same records: ``toy_rbpf_max_abs_offset_init2``.
    Each with ``_low``, ``_high``, ``_n``."""
    scale = np.abs(np.asarray(truth, float))
    names = [f"x{j + 1}" for j in range(len(scale))]
    two = records[(records.init == 2) & records.ekf_converged].set_index("seed").sort_index()
    mean = coverage.pivot(index="seed", columns="parameter", values="posterior_mean")
    two = two[two.index.isin(mean.index)]                    # the records with a posterior
    mean = mean.loc[two.index, names].to_numpy(float)
    out = {}
    if len(two) < 2:
        return out
    for key in ("ekf", "rbpf"):
        estimate = two[[f"{key}_final_error_{c}" for c in names]].to_numpy(float) + truth
        out.update(max_abs_median((estimate - mean) / scale)
                   .metrics(f"toy_{key}_max_abs_offset_init2"))
    return out


# ----------------------------------------------------------------------------- lateral vehicle
def evidence_table(metrics: dict, names: dict[str, str]) -> pd.DataFrame:
    """The statistics ``names`` (metric -> description) with their 95 % intervals and sample
    counts, one row each, from a run's metrics (``<m>``, ``<m>_low``, ``<m>_high``, ``<m>_n``)."""
    rows = [dict(statistic=text, value=metrics[m], low=metrics[f"{m}_low"],
                 high=metrics[f"{m}_high"], n=int(metrics[f"{m}_n"]), metric=m)
            for m, text in names.items()]
    return pd.DataFrame(rows, columns=["statistic", "value", "low", "high", "n", "metric"])


__all__ = ["evidence_table", "toy_metrics", "toy_offset_metrics"]
