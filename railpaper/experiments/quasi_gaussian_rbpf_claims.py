"""Paper 004's claims beside the ``quasi-gaussian-rbpf`` chapter's results, with verdicts.

Split from :mod:`railpaper.experiments.quasi_gaussian_rbpf` (which re-exports
:func:`claims_table`); the verdicts are computed from a run's own metrics, timings and time series.
"""

from __future__ import annotations

import pandas as pd

from railpaper.experiments.base import ChapterResult


def _step_verdict(ours: int, paper: int) -> bool:
    """A settling step 'reproduces' a printed one when within a factor 3 of it."""
    return 0 < ours and paper / 3 <= ours <= 3 * paper


def claims_table(result: ChapterResult, params: dict) -> pd.DataFrame:
    """Paper 004's claims beside ours, with verdicts computed from this run."""
    m, t, tol = result.metrics, result.timings, params["tolerance_to_truth"]
    step4 = result.timeseries.step == min(4, params["n_steps"])
    rows = []
    for par, paper_qg, paper_rb in (("a", 4, 55), ("b", 4, 53)):
        post_std_4 = float(result.timeseries.loc[step4, f"{par}_post_std"].iloc[0])
        qg, pr, rb, post = (m[f"mc_median_settling_step_{par}_{f}"]
                            for f in ("qgrbpf", "qgrbpf_printed", "rbpf", "posterior"))
        outside = 1.0 - m[f"mc_within_2std_fraction_{par}_qgrbpf_printed"]
        if _step_verdict(qg, paper_qg):
            verdict = "reproduced"
        elif _step_verdict(pr, paper_qg):
            verdict = (f"reproduced only by Eq. (10) as printed, as a collapse: it ends more than 2 "
                       f"posterior std from the posterior mean in {outside:.0%} of records")
        else:
            verdict = "not reproduced"
        rows.append((f"{par}: Q-GRBPF converges at step {paper_qg}",
                     f"median settling step (±{tol:g}) over {m['mc_records']} records: Q-GRBPF {qg}, "
                     f"Q-GRBPF as printed {pr}, exact posterior mean {post}; posterior std at step 4 "
                     f"= {post_std_4:.2f}; 2σ-rule step (record 0): Q-GRBPF "
                     f"{m[f'convergence_step_{par}_qgrbpf']}, as printed "
                     f"{m[f'convergence_step_{par}_qgrbpf_printed']}", verdict))
        rows.append((f"{par}: RBPF converges at step {paper_rb}",
                     f"median settling step: RBPF {rb}, exact posterior mean {post}; 2σ-rule step "
                     f"(record 0): {m[f'convergence_step_{par}_rbpf']}, never converged in "
                     f"{m[f'mc_never_converged_fraction_{par}_rbpf']:.0%} of records",
                     ("reproduced (same order; the exact posterior mean settles as late)"
                      if _step_verdict(rb, paper_rb) and _step_verdict(post, rb) else
                      "reproduced (same order)" if _step_verdict(rb, paper_rb) else
                      "not reproduced")))
    for par, true, e_qg, e_rb in (("a", params["a_true"], 0.066, 0.167),
                                  ("b", params["b_true"], -0.055, -0.067)):
        med = {f: m[f"mc_median_abs_final_error_{par}_{f}"]
               for f in ("qgrbpf", "qgrbpf_printed", "rbpf", "posterior")}
        rows.append((
            f"{par}: final error Q-GRBPF {e_qg:+.3f}, RBPF {e_rb:+.3f} (accuracy gain "
            f"{100 * (abs(e_rb) - abs(e_qg)) / abs(true):.1f} %)",
            f"record 0: Q-GRBPF {m[f'final_error_{par}_qgrbpf']:+.3f}, RBPF "
            f"{m[f'final_error_{par}_rbpf']:+.3f} (gain {m[f'paper_accuracy_gain_{par}_percent']:.1f} %), "
            f"exact posterior {m[f'final_error_{par}_posterior']:+.3f} ± "
            f"{m[f'final_std_{par}_posterior']:.3f}; median |error|: Q-GRBPF {med['qgrbpf']:.3f}, "
            f"as printed {med['qgrbpf_printed']:.3f}, RBPF {med['rbpf']:.3f}, posterior "
            f"{med['posterior']:.3f}",
            "reproduced" if min(med["qgrbpf"], med["qgrbpf_printed"]) < med["rbpf"] else
            "not reproduced: the RBPF is the more accurate; errors of this size are the "
            "posterior's own uncertainty"))
    ratio = t.get("time_ratio_qgrbpf_over_rbpf", float("nan"))
    share = t.get(f"resampling_share_of_rbpf_step_N{params['n_particles']}", float("nan"))
    rows.append((
        "Q-GRBPF needs about 56 % less computing time",
        f"Q-GRBPF / RBPF time per step at N = {params['n_particles']}: {ratio:.2f} "
        f"({100 * (1 - ratio):+.0f} % saving); systematic resampling is {100 * share:.0f} % of an "
        "RBPF step",
        "reproduced" if ratio < 0.6 else "not reproduced: resampling is cheap when vectorised; "
        "both filters cost one Kalman update per particle and step"))
    return pd.DataFrame(rows, columns=["paper claim (paper 004, Section IV)", "ours", "verdict"])
