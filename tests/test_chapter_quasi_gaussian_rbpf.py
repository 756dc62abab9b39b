"""The quasi-gaussian-rbpf chapter end to end through papermill (quick mode)."""

import json

import numpy as np
import pandas as pd
import pytest

from railpaper.pipeline.check import check_chapter

CHAPTER = "quasi-gaussian-rbpf"
pytestmark = pytest.mark.slow


def test_outputs_complete(quick_run_dir):
    out = quick_run_dir(CHAPTER)
    metrics = json.loads((out / "metrics.json").read_text())["metrics"]
    for key in ("convergence_step_a_rbpf", "convergence_step_a_qgrbpf", "convergence_step_b_rbpf",
                "convergence_step_b_qgrbpf", "final_error_a_rbpf", "final_error_a_qgrbpf",
                "final_error_b_rbpf", "final_error_b_qgrbpf"):
        assert key in metrics
    ts = pd.read_csv(out / "timeseries.csv")
    assert ts.columns[0] == "step" and len(ts) >= 200
    for col in ("y1", "y2", "a_est_rbpf", "b_est_rbpf", "a_est_qgrbpf", "b_est_qgrbpf",
                "a_post_mean", "b_post_mean", "a_post_std", "b_post_std"):
        assert col in ts.columns
    timings = json.loads((out / "timings.json").read_text())["metrics"]
    assert "time_ratio_qgrbpf_over_rbpf" in timings
    assert timings["time_ratio_paired_qgrbpf_over_rbpf_n"] == len(
        pd.read_csv(out / "timing_samples.csv")) >= 5
    assert len(list(out.glob("*.png"))) >= 4


def test_claims_section_is_the_ledger(quick_run_dir):
    """The notebook's claims section renders the ledger rows of this run (no chapter-specific
    verdicts), every row of claims.toml judged, none missing, each on >= 5 Monte Carlo samples."""
    from railpaper.pipeline.ledger import chapter_markdown, run_rows
    out = quick_run_dir(CHAPTER)
    rows, run = run_rows(CHAPTER, out)
    assert [r.verdict for r in rows if r.verdict == "missing"] == []
    assert all(r.n_samples is not None and r.n_samples >= 5 for r in rows if r.ours != "-")
    cells = json.loads((out / "quasi_gaussian_rbpf.ipynb").read_text())["cells"]
    assert not any("claims_table" in "".join(c["source"]) for c in cells)
    shown = ["".join(o["data"]["text/markdown"]) for c in cells for o in c.get("outputs", [])
             if "text/markdown" in o.get("data", {})]
    assert chapter_markdown(CHAPTER, out) in shown


def test_final_errors_are_the_timeseries_last_row(quick_run_dir):
    out = quick_run_dir(CHAPTER)
    run = json.loads((out / "metrics.json").read_text())
    params, metrics = run["parameters"], run["metrics"]
    last = pd.read_csv(out / "timeseries.csv").iloc[-1]
    for filt in ("rbpf", "qgrbpf"):
        assert metrics[f"final_error_a_{filt}"] == pytest.approx(last[f"a_est_{filt}"] - params["a_true"],
                                                                 abs=1e-12)
        assert metrics[f"final_error_b_{filt}"] == pytest.approx(last[f"b_est_{filt}"] - params["b_true"],
                                                                 abs=1e-12)
    # the exact posterior concentrates: its last std is well below the prior box's std
    assert last.a_post_std < (params["a_max"] - params["a_min"]) / np.sqrt(12) / 3


def test_metrics_within_tolerances(quick_run_dir):
    rows = check_chapter(CHAPTER, quick_run_dir(CHAPTER))
    assert rows and all(r.status == "ok" for r in rows), [(r.metric, r.value, r.status) for r in rows
                                                          if r.status != "ok"]
