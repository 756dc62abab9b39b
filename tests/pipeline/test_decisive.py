"""The decisive evidence's pieces that need no chapter run: the pilot σ behind a registered
size, and the provenance check."""

from __future__ import annotations

import json
import math

import numpy as np
import pandas as pd
import pytest

from railpaper.pipeline import decisive
from railpaper.pipeline.declarations import parse
from railpaper.rulebook import Vocabulary, relative_change

VOCABULARY = Vocabulary.load()
ROW = {"id": "x", "claim": "c", "words": "w", "source": "s", "kind": "population",
       "word_class": "trend", "study": "monte_carlo", "metrics": ["a", "b"],
       "direction": "increase", "central": False}


def test_pilot_sigma_is_the_delta_methods_per_record_sd():
    a, b = np.array([10.0, 12.0, 11.0, 13.0]), np.array([13.0, 15.0, 14.0, 16.0])
    sigma = decisive.pilot_sigma(parse("demo", ROW, VOCABULARY), pd.DataFrame({"a": a, "b": b}))
    assert sigma == pytest.approx((3 / 11.5) * math.sqrt(5 / 3) / 11.5)       # by hand
    r, low, high = relative_change(a, b)        # the same σ makes the interval's half-width
    assert (high - low) / 2 == pytest.approx(3.182446305284263 * sigma / math.sqrt(4))
    one = parse("demo", dict(ROW, word_class="similarity", metrics=["d"], direction=""),
                VOCABULARY)
    assert decisive.pilot_sigma(one, pd.DataFrame({"d": [0.1, 0.3]})) == pytest.approx(
        math.sqrt(0.02))


def test_provenance_must_match_the_defaults(tmp_path):
    chapter = "reduced-order-observer"
    assert decisive.check_provenance(chapter, tmp_path) == []             # nothing stored
    (tmp_path / chapter).mkdir()
    path = tmp_path / chapter / "provenance.json"
    path.write_text(json.dumps({"settings": {"seed": 3}, "studies": {
        "monte_carlo": {"records": 5, "seeds": [0, 5]}}}))
    problems = decisive.check_provenance(chapter, tmp_path)
    assert "not the chapter's defaults" in problems[0]
    assert "holds 0 of its 5 records" in problems[1]


def test_sizes_are_allocated_cheapest_first_across_studies_within_the_budget():
    from railpaper.pipeline.decisive import allocate_sizes

    # costs: a30 = 30, b30 = 60, b600 = 1200, a5000 = 5000: a's large size would starve b's
    got = allocate_sizes({"a": (1.0, (30, 5000)), "b": (2.0, (30, 600))}, 1500.0)
    assert got["b"] == (600, "") and got["a"][0] == 30
    assert "5000" in got["a"][1] and "1.39 CPU-hours" in got["a"][1]          # 5000 s / 3600
    assert allocate_sizes({"a": (1.0, (30, 5000))}, 5030.0)["a"] == (5000, "")  # exactly at it
    assert allocate_sizes({"a": (2.0, (30,))}, 59.0)["a"][0] == 0


def test_an_extended_study_adds_its_cost_and_a_recomputed_one_replaces_it(tmp_path):
    import json

    from railpaper.experiments.partial_state_observer import SPEC
    from railpaper.pipeline.decisive import StudyPlan, _write_provenance

    settings = SPEC.resolve({}, False)
    _write_provenance(tmp_path, StudyPlan("c", "s", 100, 0), settings, "a", 2, 10.0, 20.0, 100)
    _write_provenance(tmp_path, StudyPlan("c", "s", 150, 0), settings, "b", 2, 5.0, 8.0, 50)
    study = json.loads((tmp_path / "provenance.json").read_text())["studies"]["s"]
    assert (study["records"], study["wall_s"], study["cpu_s"]) == (150, 15.0, 28.0)
    assert study["seeds"] == [0, 150]
    _write_provenance(tmp_path, StudyPlan("c", "s", 150, 0), settings, "c", 2, 1.0, 2.0, 150)
    study = json.loads((tmp_path / "provenance.json").read_text())["studies"]["s"]
    assert (study["wall_s"], study["cpu_s"]) == (1.0, 2.0)
    # 20 of the 150 stored records replaced (removed, then recomputed): the 130 kept cost
    # 130/150 of the 2.0 CPU-s recorded for them, plus this run's 0.6
    _write_provenance(tmp_path, StudyPlan("c", "s", 150, 30), settings, "d", 2, 0.3, 0.6, 20)
    study = json.loads((tmp_path / "provenance.json").read_text())["studies"]["s"]
    assert study["cpu_s"] == round(130 / 150 * 2.0 + 0.6, 1) == 2.3
    assert study["seeds"] == [30, 180]


def test_allocation_caps_the_stored_rows_a_reader_may_use(tmp_path):
    """Rows stored under an earlier, larger allocation decide nothing today's budget would not
    pay for: a reader takes the first allocated records by seed; a study without an entry
    keeps all of its rows; a later run's chapters replace only their own entries."""
    import pandas as pd

    from railpaper.pipeline.decisive import affordable, allocated_size, write_allocation

    write_allocation(tmp_path, {("c", "s"): (3, "sizes 5 left out"), ("d", "t"): (7, "")})
    rows = pd.DataFrame({"seed": [4, 0, 3, 1, 2], "x": [40.0, 0.0, 30.0, 10.0, 20.0]})
    assert affordable(rows, "c", "s", tmp_path).seed.tolist() == [0, 1, 2]
    assert affordable(rows, "c", "other", tmp_path) is rows
    assert allocated_size("c", "s", tmp_path) == 3
    write_allocation(tmp_path, {("c", "s"): (5, "")})
    assert (allocated_size("c", "s", tmp_path), allocated_size("d", "t", tmp_path)) == (5, 7)
    assert affordable(rows, "c", "s", tmp_path) is rows


def test_stored_rows_and_provenance_for_a_page(tmp_path):
    """A page reads a study's stored rows (sorted by seed, no commit column, capped by the
    allocation) and what they cost; nothing stored is None and an empty provenance."""
    from railpaper.experiments.records import RecordStudy
    from railpaper.pipeline.chapters import chapter_spec
    from railpaper.pipeline.evidence_store import EvidenceStore

    chapter = "suspension-fault-detection"
    settings = chapter_spec(chapter).resolve({}, True)
    assert decisive.stored_rows(chapter, "fault_free_running", settings, tmp_path) is None
    assert decisive.stored_provenance(chapter, "fault_free_running", tmp_path) == {}
    study = RecordStudy(chapter, "fault_free_running", rows=None)
    EvidenceStore(tmp_path).append(study, settings, pd.DataFrame(
        {"seed": [7, 5, 6], "x_m": [0.7, 0.5, 0.6]}), "abc")
    rows = decisive.stored_rows(chapter, "fault_free_running", settings, tmp_path)
    assert rows.seed.tolist() == [5, 6, 7] and "commit" not in rows.columns
    decisive.write_allocation(tmp_path, {(chapter, "fault_free_running"): (2, "")})
    assert decisive.stored_rows(chapter, "fault_free_running", settings,
                                tmp_path).x_m.tolist() == [0.5, 0.6]
    (tmp_path / chapter).mkdir(exist_ok=True)
    (tmp_path / chapter / "provenance.json").write_text(json.dumps(
        {"commit": "abc", "date": "2026-12-06",
         "studies": {"fault_free_running": {"records": 3, "cpu_s": 3.3}}}))
    assert decisive.stored_provenance(chapter, "fault_free_running", tmp_path) == {
        "records": 3, "cpu_s": 3.3, "commit": "abc", "date": "2026-12-06"}
