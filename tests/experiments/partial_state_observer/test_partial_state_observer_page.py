"""The chapter page's structure (issue 14), read from the notebook source: no kernel needed."""

import json
import re

from railpaper.experiments.partial_state_observer.spec import SPEC
from railpaper.paths import BOOK_DIR

NOTEBOOK = BOOK_DIR / "notebooks" / SPEC.notebook


def _cells():
    return json.loads(NOTEBOOK.read_text())["cells"]


def test_title_equals_spec_title_and_claims_glued_once():
    cells = _cells()
    assert "".join(cells[0]["source"]).splitlines()[0] == f"# {SPEC.title}"
    text = "".join("".join(c["source"]) for c in cells)
    assert text.count("{glue:md} claims_table") == 1
    assert text.count('glue("claims_table"') == 1
    assert "(claims-partial-state-observer)=" in text


def test_every_figure_is_numbered_and_referenced():
    text = "".join("".join(c["source"]) for c in _cells() if c["cell_type"] == "markdown")
    names = re.findall(r":name: (fig-pso-[\w-]+)", text)
    assert len(names) >= 7 and len(set(names)) == len(names)
    for name in names:
        assert f"{{numref}}`{name}`" in text, name


def test_plumbing_hidden_and_no_string_keyed_results():
    for cell in _cells():
        src = "".join(cell["source"])
        tags = cell.get("metadata", {}).get("tags", [])
        if cell["cell_type"] != "code" or "parameters" in tags:
            continue
        assert "result.data" not in src
        assert len(cell["source"]) <= 25
        if "save_figure(fig" in src:                   # the code of a figure: one click away
            assert {"hide-input", "remove-output"} <= set(tags), src
        elif "write_outputs(out_dir" in src or "glue(\"" in src:   # plumbing: hidden
            assert {"remove-input", "remove-cell"} & set(tags), src
        if "overrides" in src:
            assert "hide-input" in tags or "remove-input" in tags
