"""Model error in the chapter run: the EKF and our tempered RBPF on the truth plant of
:mod:`railpaper.experiments.rbpf_parameter_estimation.mismatch`, paired with Part 2's records.

The truth plant (saturating creep, cubic rolling-radius difference, the paper's 40 Hz low-pass)
is simulated for the first ``mismatch_records`` seeds (at most ``n_records``) on the same track
profiles and sensor-noise draws as Part 2's records of those seeds.  Part 2 has already filtered
those linear-plant records with the same filters (same generators), so they are the matched
twins: the ``_matched`` metrics are computed from Part 2's runs instead of filtering them twice
(``tests/experiments/rbpf_parameter_estimation/test_rbpf_parameter_estimation_model_error.py`` checks they equal
:func:`~railpaper.experiments.rbpf_parameter_estimation.mismatch.run_mismatch`'s own matched
records).
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from railpaper.experiments.rbpf_parameter_estimation import lateral
from railpaper.experiments.rbpf_parameter_estimation.mismatch import (
    START,
    MismatchResult,
    plant_metrics,
    run_mismatch,
)
from railpaper.experiments.rbpf_parameter_estimation.result import LateralPart
from railpaper.experiments.rbpf_parameter_estimation.spec import Settings
from railpaper.settling import holds_from


def matched_rows(part: LateralPart, n_records: int) -> pd.DataFrame:
    """Part 2's first ``n_records`` records as :class:`MismatchResult` rows of the matched
    plant: ``seed``, ``ekf_converged`` (first EKF guess within 5 % at the end),
    ``rbpf_all_within`` (tempered RBPF, every parameter within 5 % from step 350 on)."""
    runs = part.runs[:n_records]
    return pd.DataFrame(dict(
        plant="matched", seed=[r.seed for r in runs],
        ekf_converged=[lateral.ekf_converged(r.ekf_norm[0]) for r in runs],
        rbpf_all_within=[bool(holds_from(np.abs(r.rbpf_working_norm - 1.0) <= lateral.WITHIN,
                                         START).all()) for r in runs]))


def run_model_error(settings: Settings, part: LateralPart, progress=None
                    ) -> tuple[MismatchResult, dict]:
    """The truth plant with model error on the first ``mismatch_records`` seeds
    (:func:`run_mismatch`, mismatch plant only), and the metrics of both plants.

    Returns
    -------
    result : MismatchResult
        The mismatch plant's records, runs and the EKF guesses on the first record.
    metrics : dict
        ``run_mismatch``'s ``_mismatch`` metrics (``ekf_lateral_converged_of_10_mismatch``,
        ``lateral_ekf_converge_rate_mismatch``, ``lateral_all_within_5pct_fraction_mismatch``
        …), the same with ``_matched`` from Part 2's records, and the paired counts
        ``rbpf_within_lost_mismatch`` / ``_gained_`` and ``ekf_converged_lost_mismatch`` /
        ``_gained_`` (records whose outcome flips from the linear plant to the truth plant).
    """
    n = min(settings.mismatch_records, settings.n_records)
    result = run_mismatch(settings, n, matched=False, progress=progress)
    metrics = dict(result.metrics)
    matched = matched_rows(part, n)
    metrics.update(plant_metrics(matched, [r.rbpf_working_norm for r in part.runs[:n]],
                                 list(part.runs[0].ekf_norm), "_matched",
                                 settings.ekf_guesses))
    mm = result.records.set_index("seed")
    ma = matched.set_index("seed")
    for col, name in (("rbpf_all_within", "rbpf_within"), ("ekf_converged", "ekf_converged")):
        a, b = ma[col].to_numpy(bool), mm.loc[ma.index, col].to_numpy(bool)
        metrics[f"{name}_lost_mismatch"] = int(np.sum(a & ~b))
        metrics[f"{name}_gained_mismatch"] = int(np.sum(~a & b))
    return result, metrics


__all__ = ["matched_rows", "run_model_error"]
