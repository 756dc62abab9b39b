"""The fault-detection appendix end to end: its quick run in the session's quick book (outputs,
CI bands, findings at the top of the page).  ``railpaper sweep`` runs the same experiment
function as every chapter's (tests/pipeline/test_sweep.py)."""

import json

import pandas as pd
import pytest

from railpaper.pipeline.check import check_chapter
from railpaper.pipeline.findings import in_force

CHAPTER = "suspension-fault-detection"
pytestmark = pytest.mark.slow


def test_outputs_complete(quick_chapter_dir):
    out = quick_chapter_dir(CHAPTER)
    metrics = json.loads((out / "metrics.json").read_text())["metrics"]
    for det in ("cusum", "chi2", "glr", "bayes", "oracle"):
        assert f"false_alarms_per_hour_{det}_300kmh" in metrics
        assert f"delay_median_reached_{det}_csaly_0_300kmh" in metrics
    assert not [k for k, v in metrics.items()                          # no number for "never"
                if k.startswith(("delay_median_s_", "flange_contact_after_s_")) and v < 0]
    for row in in_force(CHAPTER).values():
        assert {row["metric"], row["n_samples"], *row["interval"]} <= set(metrics)
    ts = pd.read_csv(out / "timeseries.csv")
    assert {"t_s", "statistic_oracle", "statistic_cusum", "statistic_bayes", "statistic_glr",
            "glr_hypothesis"} <= set(ts)
    for fig in ("record_around_fault", "fault_time_posterior", "delay_by_fault", "roc_curves",
                "delay_vs_mtbfa"):
        assert (out / f"{fig}.png").stat().st_size > 10_000


def test_metrics_within_tolerances(quick_chapter_dir):
    rows = check_chapter(CHAPTER, quick_chapter_dir(CHAPTER))
    assert rows and all(r.status == "ok" for r in rows), [(r.metric, r.value, r.status)
                                                           for r in rows if r.status != "ok"]


def test_page_opens_with_the_findings(quick_chapter_dir):
    notebook = json.loads((quick_chapter_dir(CHAPTER) / "suspension_fault_detection.ipynb")
                          .read_text())
    text = "".join("".join(c["source"]) for c in notebook["cells"])
    assert text.index("## Findings") < text.index("## The vehicle and its faults")
    glued = [o for c in notebook["cells"] for o in c.get("outputs", [])
             if "findings_table" in json.dumps(o.get("metadata", {}))]
    assert len(glued) == 1
    shown = glued[0]["data"]["application/papermill.record/text/markdown"]
    shown = shown if isinstance(shown, str) else "".join(shown)
    assert shown.startswith("| finding |")                            # header, then one row each
    assert shown.count("\n| ") == len(in_force(CHAPTER))

