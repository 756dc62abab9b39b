"""The quick book builds strictly and reads offline: figures and typeset math in headless Chromium."""

import os
import re
import shutil
import subprocess
import tempfile
from pathlib import Path

import pytest

from railpaper.experiments import load_chapter
from railpaper.pipeline.chapters import book_chapters, paper_chapters

pytestmark = pytest.mark.slow
CHROMIUM_FLAGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
                  "--disable-background-networking", "--disable-component-update", "--disable-sync"]


#: Appended to the copy of a page that :func:`rendered_dom` opens: after load, the width of
#: every table in the article and of the box that shows it (the theme scrolls a wider table in
#: that box, so its right edge is cut off).
TABLE_PROBE = """<script>window.addEventListener('load', () => {
  const typeset = (window.MathJax && MathJax.startup && MathJax.startup.promise) || null;
  Promise.all([document.fonts.ready, typeset]).then(() => {
    const sizes = [...document.querySelectorAll('article table')].map(t => {
      const box = t.closest('.pst-scrollable-table-container') || t.parentElement;
      return t.getBoundingClientRect().width.toFixed(1) + '/' + box.clientWidth; });
    document.body.setAttribute('data-table-widths', sizes.join(',')); }); });</script>"""
PROBE_PREFIX = ".probe-"              # hidden copies of a page, skipped by the page scans


def rendered_dom(page: Path, profile: Path, window_px: int = 1280) -> tuple[str, list[str]]:
    """The DOM after scripts ran in a ``window_px``-wide window, and the page's uncaught errors
    / failed loads from the console (the page is opened as a copy beside it, with
    :data:`TABLE_PROBE`)."""
    chromium = shutil.which("chromium") or shutil.which("chromium-browser")
    assert chromium, "Debian chromium is required for the rendering test (`make test` installs it)"
    handle, name = tempfile.mkstemp(prefix=PROBE_PREFIX, suffix=".html", dir=page.parent)
    os.close(handle)
    probe = Path(name)
    probe.write_text(page.read_text().replace("</body>", TABLE_PROBE + "</body>"))
    try:
        result = subprocess.run([chromium, *CHROMIUM_FLAGS, f"--user-data-dir={profile}",
                                 "--enable-logging=stderr", "--v=0",
                                 f"--window-size={window_px},1000",
                                 "--virtual-time-budget=20000", "--dump-dom", probe.as_uri()],
                                capture_output=True, text=True, timeout=120)
    finally:
        probe.unlink()
    errors = [line.split("] ", 1)[-1] for line in result.stderr.splitlines()
              if ":CONSOLE" in line and ("Uncaught" in line or "Failed to load" in line)]
    return result.stdout, errors


def cut_tables(dom: str) -> list[str]:
    """The "width/box" pixels of every table of a :func:`rendered_dom` wider than the box that
    shows it (by more than a pixel: the box's width is rounded)."""
    found = re.search(r'data-table-widths="([^"]*)"', dom)
    assert found, "the page's tables were not measured"
    pairs = [pair.split("/") for pair in found.group(1).split(",") if pair]
    return [f"{a}/{b}" for a, b in pairs if float(a) > float(b) + 1.0]


def ledger_rows(html: str) -> list[str]:
    """Text of the table rows that carry a verdict badge, in page order."""
    rows = re.findall(r"<tr[^>]*>(.*?)</tr>", html, re.S)
    text = [re.sub(r"\s+", " ", re.sub(r"<[^>]+>", " ", row)).strip() for row in rows
            if 'class="verdict verdict-' in row]
    return text


@pytest.mark.parametrize("chapter", book_chapters())
def test_chapter_page_has_figures_and_typeset_math(built_book, chapter, tmp_path):
    stem = Path(load_chapter(chapter).SPEC.notebook).stem
    page = built_book / "chapters" / chapter / f"{stem}.html"
    assert page.exists()
    dom, errors = rendered_dom(page, tmp_path / "profile")
    assert not errors, f"uncaught errors in {page.name}: {errors}"
    cut = cut_tables(dom)
    assert not cut, f"tables wider than the text column: {cut}"
    for stray in ("PosixPath(", "dtype: ", "&lt;Figure size", "<Figure size"):
        assert stray not in page.read_text(), f"{page.name} shows {stray!r} output"
    # MathJax 3 (served from _static, no network) replaced the TeX by mjx-container elements
    assert dom.count("<mjx-container") >= 3, "math was not typeset"
    assert "math display" not in dom or "<mjx-container" in dom
    images = re.findall(r'<img[^>]+src="([^"]+\.png)"', dom)
    assert len(images) >= 2, "no figures on the page"
    for src in images:
        assert (page.parent / src).resolve().exists(), f"figure {src} missing from the build"


def test_mathjax_served_locally_as_one_script(built_book):
    assert (built_book / "mathjax/es5/tex-chtml.js").exists()
    for page in built_book.rglob("*.html"):
        if page.name.startswith(PROBE_PREFIX):
            continue
        html = page.read_text()
        scripts = re.findall(r'<script[^>]*src="([^"]*)"', html)
        assert "cdn.jsdelivr" not in html and not any("node_modules" in s for s in scripts), page
        assert sum("mathjax" in s for s in scripts) <= 1, f"{page}: MathJax loaded twice"


def test_intro_page_renders_without_errors(built_book, tmp_path):
    dom, errors = rendered_dom(built_book / "intro.html", tmp_path / "profile")
    assert not errors, f"uncaught errors in intro.html: {errors}"
    cut = cut_tables(dom)
    assert not cut, f"tables wider than the text column: {cut}"
    assert dom.count("<mjx-container") >= 1


def test_chapter_claims_equal_the_intro_ledger(built_book):
    """Each chapter's claims section shows exactly its rows of the intro's ledger."""
    intro = ledger_rows((built_book / "intro.html").read_text())
    chapters = []
    for chapter in paper_chapters():
        stem = Path(load_chapter(chapter).SPEC.notebook).stem
        rows = ledger_rows((built_book / "chapters" / chapter / f"{stem}.html").read_text())
        assert rows, f"{chapter}: no ledger rows on the chapter page"
        chapters += rows
    assert chapters == intro


def test_ledger_csv_written(built_book):
    import csv

    from railpaper.pipeline.ledger import CSV_COLUMNS
    path = built_book.parent.parent / "_generated" / "claims_ledger.csv"
    with path.open() as handle:
        table = list(csv.DictReader(handle))
    assert table and list(table[0]) == CSV_COLUMNS
    assert not any("{" in row["reason"] for row in table), "a reason template did not format"


def test_no_decided_verdict_while_its_interval_straddles_a_threshold(built_book):
    """The intro's vocabulary on every row of the quick book, checked from outside the rule
    code: a row that says a decided verdict must get that same verdict wherever inside its
    deciding interval the statistic lies (each interval collapsed to points across it)."""
    import json

    import numpy as np

    from railpaper.pipeline.claim_rules import DECIDED_VERDICTS, deciding_intervals, rule_verdict
    from railpaper.pipeline.ledger import build_ledger
    from railpaper.pipeline.outputs import claims
    book = built_book.parent.parent
    problems, checked = [], 0
    for row in build_ledger(paper_chapters(), book / "chapters"):
        # a declared row's procedure reads its interval's bounds itself (tests/test_rulebook.py)
        if row.verdict not in DECIDED_VERDICTS or row.procedure:
            continue
        rule = claims(row.chapter)[row.key]
        out = book / "chapters" / row.chapter
        values = json.loads((out / "timings.json").read_text()).get("metrics", {}) \
            if (out / "timings.json").exists() else {}
        values.update(json.loads((out / "metrics.json").read_text())["metrics"])
        for low, high in deciding_intervals(rule, values):
            names = [low, high] + ([rule["primary"]] if [low, high] == rule.get("interval") else [])
            seen = set()
            for x in np.linspace(values[low], values[high], 201):
                seen.add(rule_verdict(rule, dict(values, **dict.fromkeys(names, x)))[0])
            checked += 1
            if len(seen) > 1:
                problems.append(f"{row.chapter} {row.key}: says {row.verdict} while its interval "
                                f"[{values[low]:.4g}, {values[high]:.4g}] holds {sorted(seen)}")
    v2_rows = [r for r in build_ledger(paper_chapters(), book / "chapters") if not r.procedure]
    assert not problems, "\n".join(problems)
    assert checked > 30 or not v2_rows      # every paper's rows are declared: the rulebook's
                                            # own tests pin its procedures at every boundary


def test_performance_page_tables_fit_the_text_column(built_book, tmp_path):
    """Every table of the Performance page fits the text column of a 1280-pixel window (its
    results table had eight columns and was cut at the right edge)."""
    dom, errors = rendered_dom(built_book / "performance.html", tmp_path / "profile")
    assert not errors and "data-table-widths" in dom
    cut = cut_tables(dom)
    assert dom.count("<table") >= 3 and not cut, cut
