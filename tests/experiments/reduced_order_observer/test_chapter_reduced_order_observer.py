"""The reduced-order-observer chapter end to end through papermill (quick mode)."""

import json
import re

import numpy as np
import pandas as pd
import pytest
from conftest import railpaper_cli
from scipy.linalg import expm

from railpaper.estimators import reduced_order_observer
from railpaper.experiments.reduced_order_observer import experiment as chapter
from railpaper.experiments.reduced_order_observer.spec import SPEC
from railpaper.models import single_wheelset
from railpaper.pipeline.check import check_chapter
from railpaper.settling import settling_time_s

CHAPTER = "reduced-order-observer"
pytestmark = pytest.mark.slow


def test_outputs_complete(quick_chapter_dir):
    out = quick_chapter_dir(CHAPTER)
    metrics = json.loads((out / "metrics.json").read_text())
    assert metrics["chapter"] == CHAPTER and metrics["quick"] is True
    for lab in ("60kmh", "100kmh"):
        for key in ("convergence_time_s", "force_rms_error_N"):
            assert f"{key}_{lab}" in metrics["metrics"]
    ts = pd.read_csv(out / "timeseries.csv")
    assert ts.columns[0] == "t_s"
    for lab in ("60kmh", "100kmh"):
        for col in ("wheelset_displacement_true_m", "wheelset_displacement_est_m",
                    "wheel_rail_force_true_N", "wheel_rail_force_est_N"):
            assert f"{col}_{lab}" in ts.columns
    for fig in ("wheelset_displacement", "wheel_rail_force", "trends_vs_speed", "force_error_vs_noise",
                "monte_carlo_vs_speed", "force_estimates"):
        assert (out / f"{fig}.png").stat().st_size > 10_000
    assert "metrics" in json.loads((out / "timings.json").read_text())
    samples = pd.read_csv(out / "estimator_samples.csv")
    assert set(samples.estimator) == {"observer", "kalman", "smoother"}
    for lab in ("60kmh", "100kmh"):
        for est in ("kalman", "smoother"):
            assert f"force_rms_error_ratio_{est}_{lab}" in metrics["metrics"]
            assert f"mc_force_rms_error_ratio_{est}_{lab}_high" in metrics["metrics"]


def test_metrics_within_tolerances(quick_chapter_dir):
    rows = check_chapter(CHAPTER, quick_chapter_dir(CHAPTER))
    assert rows and all(r.status == "ok" for r in rows), [(r.metric, r.value, r.status) for r in rows]


def test_force_error_recomputed_from_timeseries(quick_chapter_dir):
    out = quick_chapter_dir(CHAPTER)
    metrics = json.loads((out / "metrics.json").read_text())
    ts = pd.read_csv(out / "timeseries.csv")
    window = ts.t_s >= metrics["parameters"]["error_window_start_s"]
    for lab in ("60kmh", "100kmh"):
        err = (ts[f"wheel_rail_force_est_N_{lab}"] - ts[f"wheel_rail_force_true_N_{lab}"])[window]
        assert np.sqrt(np.mean(err**2)) == pytest.approx(metrics["metrics"][f"force_rms_error_N_{lab}"],
                                                         rel=1e-12)


def test_convergence_time_matches_error_dynamics(quick_chapter_dir):
    """Independent expectation: e(t) = expm(F t) e0 against 5 % of the RMS of the true z_w."""
    out = quick_chapter_dir(CHAPTER)
    metrics = json.loads((out / "metrics.json").read_text())
    settings = SPEC.resolve(metrics["parameters"], quick=True)
    ts = pd.read_csv(out / "timeseries.csv")
    A, B = single_wheelset.state_space(single_wheelset.load_parameters())
    F = reduced_order_observer.design(A, B, 2, settings.observer_poles).F
    t = ts.t_s.to_numpy()
    e = np.array([expm(F * tk) @ [0.0, settings.initial_error_m] for tk in t[::10]])[:, 1]
    for lab in ("60kmh", "100kmh"):
        z = ts[f"wheelset_displacement_true_m_{lab}"]
        predicted = settling_time_s(t[::10], np.abs(e) < 0.05 * np.sqrt(np.mean(z**2)))
        assert metrics["metrics"][f"convergence_time_s_{lab}"] == pytest.approx(predicted, abs=0.01)


def test_notebook_and_library_give_identical_metrics(quick_chapter_dir):
    """The notebook adds nothing: every metric, the Monte Carlo evidence included, is the
    library's (``chapter.run``), so ``railpaper bands`` and the claims read the same numbers."""
    out = quick_chapter_dir(CHAPTER)
    metrics = json.loads((out / "metrics.json").read_text())
    direct = json.loads(json.dumps(chapter.run(SPEC.resolve({}, True)).metrics))
    assert metrics["metrics"] == direct
    assert direct["mc_convergence_time_s_worst_wheel_n"] == 40         # quick: 40 seeds
    assert {"mc_trend_force_rms_rho_wheel", "mc_trend_force_rms_rho_wheelset",
            "rank_Q0_Q1_exact_min"} <= set(direct)


def _outputs(notebook: dict, mime: str) -> str:
    def text(value):
        return value if isinstance(value, str) else "".join(value)
    return "".join(text(o.get("data", {}).get(mime, "")) for c in notebook["cells"]
                   if c["cell_type"] == "code" for o in c.get("outputs", []))


def test_page_opens_with_reference_claims_and_rerun_box(quick_chapter_dir):
    """Issue 14's page top: title, reference, claims table (glued once, shown at the top), re-run
    box; the rules at the end; no code cell needs a name the page does not explain."""
    from railpaper.pipeline.header import reference_markdown, rerun_markdown
    from railpaper.pipeline.ledger import chapter_claims, chapter_rules
    out = quick_chapter_dir(CHAPTER)
    notebook = json.loads((out / "reduced_order_observer.ipynb").read_text())
    cells = notebook["cells"]
    assert "".join(cells[0]["source"]).startswith(f"# {SPEC.title}\n")
    shown = _outputs(notebook, "text/markdown")
    glued = [o["data"]["application/papermill.record/text/markdown"] for c in cells
             if c["cell_type"] == "code" for o in c.get("outputs", [])
             if o.get("metadata", {}).get("scrapbook", {}).get("name") == "claims_table"]
    assert len(glued) == 1
    assert "".join(glued[0]) == chapter_claims(CHAPTER, out)
    assert reference_markdown(CHAPTER) in shown and rerun_markdown(CHAPTER) in shown
    assert chapter_rules(CHAPTER) in shown and chapter_claims(CHAPTER, out) not in shown
    top = "".join("".join(c["source"]) for c in cells[:6] if c["cell_type"] == "markdown")
    assert top.count("{glue:md} claims_table") == 1
    markdown = "".join("".join(c["source"]) for c in cells if c["cell_type"] == "markdown")
    assert "(claims-reduced-order-observer)=" in markdown
    for word in ("paper 001", "claims.toml", "railpaper.pipeline", "shared/papers"):
        assert word not in markdown
    visible = [c for c in cells if c["cell_type"] == "code"
               and not {"remove-cell", "remove-input", "hide-input", "parameters",
                        "injected-parameters"} & set(c["metadata"].get("tags", []))]
    for cell in visible:
        for name in ("overrides", "out_dir", "quick"):
            assert name not in "".join(cell["source"]).replace("quick_", ""), cell["source"]
    assert not hasattr(chapter, "claims_table")


def test_page_has_numbered_figures_and_no_stray_output(quick_chapter_dir):
    out = quick_chapter_dir(CHAPTER)
    notebook = json.loads((out / "reduced_order_observer.ipynb").read_text())
    markdown = "".join("".join(c["source"]) for c in notebook["cells"] if c["cell_type"] == "markdown")
    figures = re.findall(r"```\{figure\} (\w+)\.png\n:name: (fig-roo-[\w-]+)", markdown)
    assert len(figures) >= 6
    for name, label in figures:
        assert (out / f"{name}.png").exists()
        assert f"{{numref}}`{label}`" in markdown, label
    text = _outputs(notebook, "text/plain") + _outputs(notebook, "text/markdown")
    text += "".join(o.get("text", "") if isinstance(o.get("text", ""), str) else "".join(o["text"])
                    for c in notebook["cells"] if c["cell_type"] == "code"
                    for o in c.get("outputs", []))
    for stray in ("PosixPath(", "dtype:", "<Figure size", "…", "-1.000", "NaN"):
        assert stray not in text, stray


def test_rerun_with_other_speeds_keys_metrics_by_speed(tmp_path):
    out = tmp_path / "run"
    result = railpaper_cli("run", CHAPTER, "--quick", "-p", "speeds_kmh", "[80, 140]",
                           "-p", "sweep_speeds_kmh", "[80]", "-p", "mc_seeds", "2",
                           "--out", str(out))
    assert result.returncode == 0, result.stderr[-2000:]
    metrics = json.loads((out / "metrics.json").read_text())["metrics"]
    assert "convergence_time_s_80kmh" in metrics and "force_rms_error_N_140kmh" in metrics
    check = railpaper_cli("check", CHAPTER, "--out", str(out))
    assert "not comparable" in check.stdout


def test_failed_run_keeps_previous_output(quick_chapter_dir, tmp_path):
    import shutil
    out = tmp_path / "kept"
    shutil.copytree(quick_chapter_dir(CHAPTER), out)
    before = (out / "metrics.json").read_bytes()
    result = railpaper_cli("run", CHAPTER, "--quick", "-p", "dt_s", "0.002", "--out", str(out))
    assert result.returncode == 2
    assert "too coarse" in result.stderr and "Traceback" not in result.stderr
    assert (out / "metrics.json").read_bytes() == before
    assert not list(tmp_path.glob(".kept.staging-*"))
