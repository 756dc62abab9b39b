"""Paper 000's claims beside the ``partial-state-observer`` chapter's results, with verdicts.

Split from :mod:`railpaper.experiments.partial_state_observer` (which re-exports
:func:`claims_table`); the verdicts are computed from a run's own metrics and Monte Carlo table.
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from railpaper.experiments.base import ChapterResult

ESTIMATORS = ("paper", "hb0", "kalman", "q")


def _label(speed_kmh: float) -> str:
    return f"{speed_kmh:g}kmh"


def _median_by_speed(mc: pd.DataFrame, estimator: str, column: str) -> pd.Series:
    sub = mc[mc.estimator == estimator]
    return sub.groupby("speed_kmh")[column].median()


def _increasing(values) -> bool:
    values = list(values)
    return all(b > a for a, b in zip(values, values[1:]))


def claims_table(result: ChapterResult, params: dict) -> pd.DataFrame:
    """Paper 000's claims beside ours, with a verdict computed from this run's own data.

    Trends are judged on the Monte Carlo medians over seeds (strictly increasing with speed).
    """
    m, mc = result.metrics, result.data["monte_carlo"]
    speeds = params["speeds_kmh"]
    labs = [_label(s) for s in speeds]
    conv = [m[f"convergence_time_s_{lab}"] for lab in labs]
    conv_hb0 = [m[f"convergence_time_s_{lab}_hb0"] for lab in labs]
    conv_kf = [m[f"convergence_time_s_{lab}_kalman"] for lab in labs]
    med_conv = _median_by_speed(mc, "paper", "convergence_time_s")
    med_pred = _median_by_speed(mc, "paper", "predicted_convergence_s")
    gap_ms = 1e3 * float(np.max(np.abs(mc[mc.estimator == "paper"].convergence_time_s
                                       - mc[mc.estimator == "paper"].predicted_convergence_s)))
    med_err = {e: _median_by_speed(mc, e, "max_error_after_1s_m") for e in ESTIMATORS}
    clean = [m[f"max_error_after_1s_m_{lab}_noisefree"] for lab in labs]
    top = labs[-1]
    rel = m[f"mean_relative_error_{top}"]
    fmt = lambda xs, scale=1.0, f="{:.3f}": ", ".join(f.format(x * scale) for x in xs)  # noqa: E731
    near = lambda xs: all(abs(x - 0.15) <= 0.05 for x in xs)  # noqa: E731
    rows = [
        ("the observer converges in about 0.15 s (abstract; Figs 8-10)",
         f"paper observer (poles {m['observer_slowest_rate_per_s']:.0f}-"
         f"{m['observer_fastest_rate_per_s']:.0f} 1/s): {fmt(conv)} s; H B = 0 variant (poles "
         f"{m['hb0_fixed_pole_per_s']:.2f} 1/s, fixed): {fmt(conv_hb0)} s; Kalman: {fmt(conv_kf)} s",
         "reproduced" if near(conv) else
         ("not reproduced by our design (a design choice: see the α sweep); the input-free "
          "variant, whose poles cannot move, gives it" if near(conv_hb0) else "not reproduced")),
        ("convergence takes slightly longer as speed rises (Figs 8-10)",
         f"Monte Carlo median {fmt(med_conv.values)} s; error dynamics alone against the same "
         f"threshold {fmt(med_pred.values)} s (largest gap {gap_ms:.0f} ms)",
         ("trend present, but the error dynamics alone reproduce it: it comes from the threshold "
          "(5 % of the RMS of z_w over the run), not from the observer"
          if _increasing(med_conv.values) and gap_ms <= 10 else
          "reproduced" if _increasing(med_conv.values) else
          "not reproduced: the medians do not increase; single runs scatter with their threshold "
          "(5 % of the RMS of z_w over the run), which the error dynamics alone follow")),
        ("the max error after 1 s grows with speed (Fig. 11)",
         f"Monte Carlo median, mm: paper {fmt(med_err['paper'].values, 1e3)}; Kalman "
         f"{fmt(med_err['kalman'].values, 1e3)}; noise-free paper observer {fmt(clean, 1e3, '{:.4f}')}",
         ("reproduced" if _increasing(med_err["paper"].values) else
          "not reproduced with sensor noise (the noise dominates); reproduced noise-free, where "
          "the ZOH discretisation error grows with speed" if _increasing(clean) else
          "not reproduced")),
        ("the mean error stays below 0.1 % at 160 km/h (Fig. 11)",
         f"mean relative error at {speeds[-1]:g} km/h: paper observer {rel:.2%}, Kalman "
         f"{m[f'mean_relative_error_{top}_kalman']:.2%}, z = q {m[f'mean_relative_error_{top}_q']:.2%}",
         "reproduced" if rel < 1e-3 else
         "not reproduced with the sensor noise; below 0.1 % only: " + (", ".join(
             name for name, key in (("noise-free ZOH observer", "_noisefree"),
                                    ("noise-free FOH observer", "_noisefree_foh"),
                                    ("Kalman", "_kalman"), ("z = q", "_q"))
             if m[f"mean_relative_error_{top}{key}"] < 1e-3) or "none")),
    ]
    return pd.DataFrame(rows, columns=["paper claim (paper 000)", "ours", "verdict"])
