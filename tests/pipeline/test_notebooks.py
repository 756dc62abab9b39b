"""What every chapter notebook shares: the chapter imported in one line, each figure's code one
click away (``hide-input``), its output left to the numbered figure."""

import json
import re

import pytest

from railpaper.paths import NOTEBOOK_DIR
from railpaper.pipeline.chapters import book_chapters, chapter_spec


def _code_cells(chapter):
    notebook = json.loads((NOTEBOOK_DIR / chapter_spec(chapter).notebook).read_text())
    return [("".join(c["source"]), set(c.get("metadata", {}).get("tags", [])))
            for c in notebook["cells"] if c["cell_type"] == "code"]


@pytest.mark.parametrize("chapter", book_chapters())
def test_the_chapter_is_imported_in_one_line(chapter):
    package = chapter.replace("-", "_")
    lines = [line for source, _ in _code_cells(chapter) for line in source.splitlines()
             if re.match(rf"from railpaper\.experiments(\.{package})?( import|\.)", line)]
    assert len(lines) == 1 and lines[0].startswith(
        f"from railpaper.experiments.{package} import "), lines


@pytest.mark.parametrize("chapter", book_chapters())
def test_figure_code_is_one_click_away(chapter):
    figures = [(source, tags) for source, tags in _code_cells(chapter)
               if "save_figure(" in source]
    assert len(figures) >= 4
    for source, tags in figures:
        assert {"hide-input", "remove-output"} <= tags and "remove-input" not in tags, source
