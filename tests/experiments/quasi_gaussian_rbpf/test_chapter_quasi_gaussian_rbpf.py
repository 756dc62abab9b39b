"""The quasi-gaussian-rbpf chapter: its page structure (from the notebook source), its typed
result against an independent Kalman-filter grid, and the chapter end to end through papermill
(quick mode)."""

import json
import re

import numpy as np
import pandas as pd
import pytest

from railpaper.experiments.quasi_gaussian_rbpf import experiment as chapter
from railpaper.experiments.quasi_gaussian_rbpf import tables
from railpaper.paths import BOOK_DIR
from railpaper.pipeline.check import check_chapter

CHAPTER = "quasi-gaussian-rbpf"
NOTEBOOK = BOOK_DIR / "notebooks" / chapter.SPEC.notebook
HIDDEN = {"remove-cell", "remove-input", "hide-input", "parameters", "injected-parameters"}
STRAY = ("PosixPath(", "dtype:", "<Figure size", "…", "-1.000", "NaN")


def _markdown(cells) -> str:
    return "".join("".join(c["source"]) for c in cells if c["cell_type"] == "markdown")


def _tags(cell) -> set:
    return set(cell.get("metadata", {}).get("tags", []))


def test_page_structure():
    """Issue 14's page: title = SPEC.title, claims glued once at the top, rules in the claims
    section at the end, numbered and referenced figures, plumbing hidden, no developer words."""
    cells = json.loads(NOTEBOOK.read_text())["cells"]
    assert "".join(cells[0]["source"]).splitlines()[0] == f"# {chapter.SPEC.title}"
    top = _markdown(cells[:6])
    text = _markdown(cells)
    assert top.count("{glue:md} claims_table") == 1 == text.count("{glue:md} claims_table")
    glue_cells = [c for c in cells if 'glue("claims_table"' in "".join(c["source"])]
    assert len(glue_cells) == 1 and "remove-cell" in _tags(glue_cells[0])
    label = next(i for i, c in enumerate(cells)
                 if "(claims-quasi-gaussian-rbpf)=" in "".join(c["source"]))
    assert label > len(cells) // 2
    rules = [i for i, c in enumerate(cells) if "chapter_rules(CHAPTER)" in "".join(c["source"])
             and "display" in "".join(c["source"])]
    assert rules == [label + 1] and "remove-input" in _tags(cells[label + 1])
    assert "chapter_markdown" not in "".join("".join(c["source"]) for c in cells)
    for word in ("paper 003", "paper 004", "claims.toml", "railpaper.pipeline", "shared/papers",
                 "data/", "tests/", "…"):
        assert word not in text, word
    names = re.findall(r"```\{figure\} (\w+)\.png\n:name: (fig-qgrbpf-[\w-]+)", text)
    assert len(names) >= 6 and len({n for _, n in names}) == len(names)
    for _, name in names:
        assert f"{{numref}}`{name}`" in text, name
    assert not re.search(r"(figure|plot)s? (above|below)", text)
    for cell in cells:
        src = "".join(cell["source"])
        if cell["cell_type"] != "code" or "parameters" in _tags(cell):
            continue
        assert "result.data" not in src and len(cell["source"]) <= 25
        if re.search(r"save_figure\(", src):             # the code of a figure: one click away
            assert {"hide-input", "remove-output"} <= _tags(cell), src
        elif re.search(r"write_outputs\(|glue\(", src):  # plumbing: hidden
            assert {"remove-input", "remove-cell"} & _tags(cell), src
        if not HIDDEN & _tags(cell):
            for name in ("overrides", "out_dir", "quick"):
                assert name not in src, (name, src)


def _grid_posterior_mean(settings, y):
    """Independent reference: a plain Kalman filter per grid cell centre (the model of
    Eqs. 20-21 typed from the paper), uniform prior, posterior mean of (a, b) after the last y."""
    G = np.array([[-1.0, 0.38], [-1.5, 1.0]])
    H = np.array([[1.0, -0.38], [0.5, 0.7]])
    Q, R = settings.q_var * G @ G.T, settings.r_var * np.eye(2)
    n = settings.grid_size
    a_axis = settings.a_min + (np.arange(n) + 0.5) * (settings.a_max - settings.a_min) / n
    b_axis = settings.b_min + (np.arange(n) + 0.5) * (settings.b_max - settings.b_min) / n
    points, logliks = [], []
    for a in a_axis:
        for b in b_axis:
            F = np.array([[0.0, 1.0], [a, b]])
            x, P, ll = np.zeros(2), settings.p0_std ** 2 * np.eye(2), 0.0
            for yk in y:
                x, P = F @ x, F @ P @ F.T + Q
                S = H @ P @ H.T + R
                v = yk - H @ x
                ll += -0.5 * (v @ np.linalg.solve(S, v) + np.log(np.linalg.det(S))
                              + 2 * np.log(2 * np.pi))
                K = P @ H.T @ np.linalg.inv(S)
                x, P = x + K @ v, (np.eye(2) - K @ H) @ P
            points.append((a, b))
            logliks.append(ll)
    w = np.exp(np.array(logliks) - max(logliks))
    return (w[:, None] * np.array(points)).sum(axis=0) / w.sum()


def test_typed_result_holds_the_record_and_its_exact_posterior():
    settings = chapter.SPEC.resolve(dict(n_particles=60, n_steps=40, grid_size=13,
                                         n_monte_carlo=2, timing=False, readings_records=0), True)
    result = chapter.run(settings)
    main = result.main
    assert main.index == settings.record and main.measurements.shape == (40, 2)
    assert main.states.shape == (41, 2) and list(main.steps) == list(range(1, 41))
    np.testing.assert_allclose(main.exact.mean[-1],
                               _grid_posterior_mean(settings, main.measurements),
                               rtol=1e-8, atol=1e-10)
    for j, par in enumerate("ab"):
        for name in ("rbpf", "qgrbpf"):
            assert result.metrics[f"final_error_{par}_{name}"] == pytest.approx(
                main.runs[name].theta_mean[-1, j] - (settings.a_true, settings.b_true)[j], abs=1e-15)
    assert list(result.monte_carlo.seed) == [0, 1] and result.computing_time is None


def test_tables_show_the_monte_carlo_medians():
    """The page's Monte Carlo table holds numpy's medians of the per-record |final errors|."""
    settings = chapter.SPEC.resolve(dict(n_particles=60, n_steps=40, grid_size=13,
                                         n_monte_carlo=5, timing=False, readings_records=0), True)
    result = chapter.run(settings)
    table = tables.monte_carlo_table(result.metrics, settings)
    row = next(r for r in table.splitlines() if r.startswith("| median abs. final error of a"))
    cells = [c.strip() for c in row.strip("|").split("|")][1:]
    for cell, name in zip(cells, ["posterior", "rbpf", "rbpf_working", "qgrbpf", "qgrbpf_printed"]):
        expected = np.median(np.abs(result.monte_carlo[f"final_error_a_{name}"]))
        assert float(cell.split(" [")[0]) == pytest.approx(expected, rel=5e-3)
    assert "nan" not in table.lower()
    assert not re.search(r"(^|[\s\[|])-1(\.0+)?([\s,\]|]|$)", table)        # no -1 sentinel


@pytest.mark.slow
def test_outputs_complete(quick_chapter_dir):
    out = quick_chapter_dir(CHAPTER)
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
    for name in ("estimates", "errors", "spread_ratio", "monte_carlo_errors",
                 "monte_carlo_settling", "computing_time"):
        assert (out / f"{name}.png").stat().st_size > 10_000


def _outputs(notebook: dict, mime: str) -> str:
    def text(value):
        return value if isinstance(value, str) else "".join(value)
    return "".join(text(o.get("data", {}).get(mime, "")) + text(o.get("text", ""))
                   for c in notebook["cells"] if c["cell_type"] == "code"
                   for o in c.get("outputs", []))


@pytest.mark.slow
def test_claims_glued_at_the_top_rules_at_the_end(quick_chapter_dir, built_book):
    """The ledger rows of this run (the declarations under the rulebook) are glued once (shown
    at the top); a sampled row reads this run's records or says how many its registered size
    needs; the rows without a study are the computing-cost and real-time ones; the claims section
    shows the rules; the page shows each claim once and each row once beneath."""
    from railpaper.pipeline.declarations import load_declarations
    from railpaper.pipeline.ledger import chapter_claims, chapter_rules, run_rows
    out = quick_chapter_dir(CHAPTER)
    rows, _ = run_rows(CHAPTER, out)
    assert [r.verdict for r in rows if r.verdict == "missing"] == []
    unsampled = [d.id for d in load_declarations(CHAPTER) if not d.study]
    assert unsampled and all(key.startswith(("computing_time", "less_time", "less_complexity",
                                             "resampling", "real_time")) for key in unsampled)
    for r in rows:
        if r.key not in unsampled and r.verdict == "undecided" and "registered" in r.reason:
            assert r.evidence.startswith("this run") or r.evidence.startswith("data/evidence")
    notebook = json.loads((out / "quasi_gaussian_rbpf.ipynb").read_text())
    glued = [o["data"]["application/papermill.record/text/markdown"]
             for c in notebook["cells"] if c["cell_type"] == "code" for o in c.get("outputs", [])
             if o.get("metadata", {}).get("scrapbook", {}).get("name") == "claims_table"]
    assert len(glued) == 1 and "".join(glued[0]) == chapter_claims(CHAPTER, out)
    shown = _outputs(notebook, "text/markdown")
    assert chapter_rules(CHAPTER) in shown and chapter_claims(CHAPTER, out) not in shown
    page = (built_book / "chapters" / CHAPTER / "quasi_gaussian_rbpf.html").read_text()
    # one line per claim, then every row in the dropdown (and the original rule's verdict where
    # the rule was revised after its numbers were seen)
    from railpaper.pipeline.ledger import central_claims, claim_groups, fold_inert_readings
    shown_rows = [r for g in claim_groups(rows) for r in fold_inert_readings(g)]
    central = central_claims(rows).count('class="verdict verdict-')      # the page's top section
    assert central >= 1
    assert page.count('class="verdict verdict-') == central + len(claim_groups(rows)) + \
        len(shown_rows) + sum(bool(r.revised) for r in shown_rows)


@pytest.mark.slow
def test_page_has_no_stray_output(quick_chapter_dir, built_book):
    out = quick_chapter_dir(CHAPTER)
    notebook = json.loads((out / "quasi_gaussian_rbpf.ipynb").read_text())
    from railpaper.pipeline.ledger import chapter_rules
    # the rules quote the paper's words, whose ellipses are the paper's, not a cut-off output
    text = (_outputs(notebook, "text/plain") + _outputs(notebook, "text/markdown")).replace(
        chapter_rules(CHAPTER), "")
    page = (built_book / "chapters" / CHAPTER / "quasi_gaussian_rbpf.html").read_text()
    for stray in STRAY:
        assert stray not in text, stray
    for stray in ("PosixPath(", "dtype:", "<Figure size", "NaN"):
        assert stray not in page, stray


@pytest.mark.slow
def test_final_errors_are_the_timeseries_last_row(quick_chapter_dir):
    out = quick_chapter_dir(CHAPTER)
    run = json.loads((out / "metrics.json").read_text())
    written, metrics = run["parameters"], run["metrics"]
    last = pd.read_csv(out / "timeseries.csv").iloc[-1]
    for filt in ("rbpf", "qgrbpf"):
        assert metrics[f"final_error_a_{filt}"] == pytest.approx(last[f"a_est_{filt}"] - written["a_true"],
                                                                 abs=1e-12)
        assert metrics[f"final_error_b_{filt}"] == pytest.approx(last[f"b_est_{filt}"] - written["b_true"],
                                                                 abs=1e-12)
    # the exact posterior concentrates: its last std is well below the prior box's std
    assert last.a_post_std < (written["a_max"] - written["a_min"]) / np.sqrt(12) / 3


@pytest.mark.slow
def test_metrics_within_tolerances(quick_chapter_dir):
    rows = check_chapter(CHAPTER, quick_chapter_dir(CHAPTER))
    assert rows and all(r.status == "ok" for r in rows), [(r.metric, r.value, r.status) for r in rows
                                                          if r.status != "ok"]
