"""A run is something to read: `railpaper run` writes DIR/index.html, the executed chapter as a
web page with its figures, typeset math and the claims judged on this run."""

import re
import shutil

import pytest
from test_book import rendered_dom

from railpaper.pipeline.chapters import chapter_spec
from railpaper.pipeline.page import render_run_page

pytestmark = pytest.mark.slow
CHAPTER = "partial-state-observer"


@pytest.fixture(scope="module")
def run_with_page(quick_chapter_dir, tmp_path_factory):
    """The quick book's run of the chapter with its run page rendered, as ``railpaper run``
    renders it once the notebook has executed (:func:`railpaper.pipeline.chapters.run_chapter`)."""
    out = tmp_path_factory.mktemp("page") / "run"
    shutil.copytree(quick_chapter_dir(CHAPTER), out)
    spec = chapter_spec(CHAPTER)
    render_run_page(out, spec.notebook, spec.title)
    return out


def test_run_page_renders_offline(run_with_page, tmp_path):
    out = run_with_page
    index = out / "index.html"
    target = re.search(r'url=([^"]+)"', index.read_text()).group(1)
    page = out / target
    assert page.exists()
    html = page.read_text()
    assert 'class="verdict verdict-' in html           # the claims section, judged on this run
    assert "Non-default parameters" not in html
    dom, errors = rendered_dom(page, tmp_path / "profile")
    assert not errors, errors
    assert dom.count("<mjx-container") >= 1
    for src in re.findall(r'<img[^>]+src="([^"]+)"', dom):
        assert (page.parent / src).resolve().exists(), src
