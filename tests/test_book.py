"""The quick book builds strictly and reads offline: figures and typeset math in headless Chromium."""

import re
import shutil
import subprocess
from pathlib import Path

import pytest

from railpaper.experiments import load_chapter
from railpaper.pipeline.book import build_book
from railpaper.pipeline.chapters import book_chapters

pytestmark = pytest.mark.slow
CHROMIUM_FLAGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
                  "--disable-background-networking", "--disable-component-update", "--disable-sync"]


@pytest.fixture(scope="module")
def built_book(tmp_path_factory):
    book = tmp_path_factory.mktemp("book") / "book"
    return build_book(quick=True, book_dir=book, progress=False)


def rendered_dom(page: Path, profile: Path) -> str:
    chromium = shutil.which("chromium") or shutil.which("chromium-browser")
    assert chromium, "Debian chromium is required for the rendering test (.ci/run installs it)"
    result = subprocess.run([chromium, *CHROMIUM_FLAGS, f"--user-data-dir={profile}",
                             "--virtual-time-budget=20000", "--dump-dom", page.as_uri()],
                            capture_output=True, text=True, timeout=120)
    return result.stdout


@pytest.mark.parametrize("chapter", book_chapters())
def test_chapter_page_has_figures_and_typeset_math(built_book, chapter, tmp_path):
    stem = Path(load_chapter(chapter).SPEC.notebook).stem
    page = built_book / "chapters" / chapter / f"{stem}.html"
    assert page.exists()
    dom = rendered_dom(page, tmp_path / "profile")
    # MathJax 3 (served from _static, no network) replaced the TeX by mjx-container elements
    assert dom.count("<mjx-container") >= 3, "math was not typeset"
    assert "math display" not in dom or "<mjx-container" in dom
    images = re.findall(r'<img[^>]+src="([^"]+\.png)"', dom)
    assert len(images) >= 2, "no figures on the page"
    for src in images:
        assert (page.parent / src).resolve().exists(), f"figure {src} missing from the build"


def test_mathjax_served_locally(built_book):
    html = (built_book / "intro.html").read_text()
    assert "cdn.jsdelivr" not in html and "mathjax/node_modules/mathjax/es5/tex-chtml.js" in html
    assert (built_book / "_static/mathjax/node_modules/mathjax/es5/tex-chtml.js").exists()
