"""A chapter declared under the rulebook: its ledger rows come from the declarations, the run's
per-record rows and the registry (size, fingerprint, the previous declaration's verdict)."""

from __future__ import annotations

import csv
import dataclasses
import json

import numpy as np
import pandas as pd

from railpaper import rulebook
from railpaper.pipeline import ledger
from railpaper.pipeline.chapters import chapter_spec
from railpaper.pipeline.declarations import parse, register
from railpaper.rulebook import Vocabulary

CHAPTER = "reduced-order-observer"
ROW = {"id": "error_grows", "claim": "the force error grows with speed",
       "words": "the wheel-rail force error increases", "source": "paper 001, abstract",
       "kind": "population", "word_class": "trend", "study": "monte_carlo",
       "metrics": ["error_60kmh", "error_100kmh"], "direction": "increase", "central": True}


def _toml(row: dict) -> str:
    lines = ["[[claim]]"]
    for key, value in row.items():
        lines.append(f"{key} = {json.dumps(value)}".replace("true", "true"))
    return "\n".join(lines) + "\n"


def _setup(tmp_path, row=ROW):
    data = tmp_path / "data"
    (data / CHAPTER).mkdir(parents=True)
    (data / CHAPTER / "declarations.toml").write_text(_toml(row))
    out = tmp_path / "run"
    out.mkdir()
    settings = chapter_spec(CHAPTER).resolve({}, False)
    (out / "metrics.json").write_text(json.dumps({"parameters": settings.as_dict(),
                                                  "quick": False, "metrics": {}}))
    rng = np.random.default_rng(4)
    base = 1.0 + 0.1 * rng.standard_normal(60)
    pd.DataFrame({"seed": range(60), "error_60kmh": base, "error_100kmh": base * 1.5}).to_csv(
        out / "records_monte_carlo.csv", index=False)
    return data, out


def test_declared_rows_are_decided_by_the_rulebook(tmp_path):
    data, out = _setup(tmp_path)
    run = json.loads((out / "metrics.json").read_text())
    rows = ledger.declared_rows(CHAPTER, out, run, None, data, registry={})
    (row,) = rows
    assert row.verdict == "reproduced" and row.procedure == "paired-change"
    assert row.evidence == "this run (60 records)" and row.central and row.headline
    path = ledger.write_ledger_csv(rows, tmp_path / "ledger.csv")
    written = next(csv.DictReader(path.open()))
    assert written["procedure"] == "paired-change" and written["central"] == "true"
    assert written["words"] == "the wheel-rail force error increases"
    assert "holds on our evidence" in ledger.central_claims(rows)


def test_a_revision_shows_the_previous_declarations_verdict(tmp_path):
    vocabulary = Vocabulary.load()
    old = parse(CHAPTER, dict(ROW, direction="decrease"), vocabulary)
    registry, _ = register([old], vocabulary, {}, {old.key: 30}, "2026-12-01")
    new = parse(CHAPTER, ROW, vocabulary)
    registry, revised = register([new], vocabulary, registry, {new.key: 30}, "2026-12-06")
    assert revised == [new.key]
    data, out = _setup(tmp_path)
    run = json.loads((out / "metrics.json").read_text())
    (row,) = ledger.declared_rows(CHAPTER, out, run, None, data, registry=registry)
    assert row.verdict == "reproduced" and row.original_verdict == "differs"
    assert "re-registered on 2026-12-06" in row.revised
    assert row.fingerprint == registry[new.key]["fingerprint"]


def test_too_few_records_and_no_stored_evidence_is_undecided(tmp_path):
    data, out = _setup(tmp_path)
    run = json.loads((out / "metrics.json").read_text())
    vocabulary = Vocabulary.load()
    row = parse(CHAPTER, ROW, vocabulary)
    registry, _ = register([row], vocabulary, {}, {row.key: 5000}, "2026-12-06")
    (decided,) = ledger.declared_rows(CHAPTER, out, run, None, data, registry=registry)
    assert decided.verdict == "undecided"
    assert "60 records of the 5000 registered" in decided.reason   # the store holds fewer too


def test_context_sentences_are_filled_from_the_run_and_follow_the_central_claims(tmp_path):
    (tmp_path / "demo").mkdir()
    (tmp_path / "demo" / "context.toml").write_text(
        '[[context]]\ntext = """The baseline is {base_mm:.3g}\n mm."""\n'
        '[context.values]\nbase_mm = { metric = "base_m", scale = 1000.0 }\n'
        '[[context]]\ntext = "Left out: {x}"\n[context.values]\nx = { metric = "absent" }\n')
    text = ledger.context_sentences("demo", {"metrics": {"base_m": 0.0167}}, tmp_path)
    assert text == ("- *Context (ours, not a claim of the paper's):* The baseline is 16.7 mm.\n")
    assert ledger.context_sentences("demo", None, tmp_path) == ""
    assert ledger.central_claims([], text).endswith(text)


def test_the_version_table_counts_each_version_and_the_rows_that_moved():
    rows = [ledger.LedgerRow("demo", f"r{i}", "c", "s", "", "", verdict, "",
                             by_version=dict(enumerate(history, start=1)))
            for i, (verdict, history) in enumerate([
                ("attainable", ("reproduced", "reproduced", "reproduced", "attainable")),
                ("artefact", ("reproduced", "artefact", "artefact", "artefact")),
                ("differs", ("differs", "differs", "differs", "differs"))])]
    table = ledger.version_table(rows).splitlines()
    assert table[0] == "| verdict | v1 | v2 | v3 | v4 |"
    assert table[2] == "| reproduced | 2 | 1 | 1 | 0 |"
    assert table[3] == "| attainable | 0 | 0 | 0 | 1 |"
    assert table[4] == "| artefact | 0 | 1 | 1 | 1 |"
    assert table[-1] == "| *moved* | — | 1 | 0 | 1 |"
    assert ledger.version_table([]) == ""


def test_a_central_sentence_says_which_version_of_the_procedures_moved_it():
    row = ledger.LedgerRow("demo", "k", "the filter converges", "abstract", "", "", "artefact",
                           "", central=True, procedure="population-rate", headline=True,
                           by_version={1: "reproduced", 2: "reproduced", 3: "artefact",
                                       4: "artefact"})
    assert ledger.central_claims([row]).endswith(
        "It read reproduced under version 2 of the decision procedures; version 3 changed it "
        "(the table of versions).\n")
    still = dataclasses.replace(row, verdict="differs", by_version={1: "differs", 2: "differs"})
    assert "It read" not in ledger.central_claims([still])
    # a move by the current version is named before an earlier revision of the declaration
    moved = dataclasses.replace(row, verdict="not testable", revised="re-registered",
                                original_verdict="artefact",
                                by_version={4: "artefact", 5: "reproduced", 6: "not testable"})
    assert "It read reproduced under version 5" in ledger.central_claims([moved])
    older = dataclasses.replace(moved, by_version={4: "artefact", 5: "not testable",
                                                   6: "not testable"})
    assert "It read artefact before: re-registered" in ledger.central_claims([older])
    # a row not testable for lack of measured data says so in its sentence
    lacking = dataclasses.replace(moved, reason=rulebook.MEASURED_ONLY + " (a line record)")
    assert "the paper's only evidence is data measured" in ledger.central_claims([lacking])


def test_the_headline_counts_a_declared_attainable_as_attainable():
    rows = [ledger.LedgerRow("demo", "a", "c", "s", "", "", "attainable", "", group="a",
                             procedure="population-rate", headline=True),
            ledger.LedgerRow("demo", "b", "c", "s", "", "", "reproduced", "", group="b",
                             procedure="population-rate", headline=True)]
    assert ledger.headline(rows) == "2 claims of the paper's methods: 1 reproduced, 1 attainable"


def test_a_context_sentence_can_read_a_run_parameter(tmp_path):
    (tmp_path / "demo").mkdir()
    (tmp_path / "demo" / "context.toml").write_text(
        '[[context]]\ntext = "Poles {poles} 1/s."\n[context.values]\n'
        'poles = { parameter = "observer_poles" }\n')
    run = {"metrics": {}, "parameters": {"observer_poles": [-30.0, -40.0]}}
    assert ledger.context_sentences("demo", run, tmp_path).endswith("Poles -30, -40 1/s.\n")


def test_the_csv_gives_each_row_s_verdict_under_every_version(tmp_path):
    row = ledger.LedgerRow("demo", "k", "c", "s", "", "", "attainable", "", procedure="x",
                           by_version={2: "reproduced", 1: "reproduced", 4: "attainable"})
    path = ledger.write_ledger_csv([row], tmp_path / "ledger.csv")
    with path.open() as handle:
        table = list(csv.DictReader(handle))
    assert table[0]["verdicts_by_procedure_version"] == "v1 reproduced; v2 reproduced; v4 attainable"


def test_a_study_only_the_store_holds_is_read_short_of_its_size(tmp_path, monkeypatch):
    """A study the run does not compute (chapter 003's judged studies) is read from the stored
    evidence even short of a row's size, so that the row says how many records it has; no more
    of them than the budget's allocation paid for."""
    from railpaper.experiments.records import RecordStudy
    from railpaper.pipeline.decisive import write_allocation
    from railpaper.pipeline.evidence_store import EvidenceStore

    store_root = tmp_path / "evidence"
    monkeypatch.setattr(ledger, "DECISIVE_EVIDENCE_DIR", store_root)
    monkeypatch.setattr(ledger, "DATA_DIR", tmp_path / "data")
    settings = chapter_spec(CHAPTER).resolve({}, False)
    study = RecordStudy(CHAPTER, "only_stored", rows=None)
    EvidenceStore(store_root).append(study, settings, pd.DataFrame(
        {"seed": [5, 3, 4], "x": [1.0, 2.0, 3.0]}), "abc")
    out = tmp_path / "run"
    out.mkdir()
    run = {"parameters": settings.as_dict(), "quick": False}
    rows, source = ledger.study_rows(CHAPTER, "only_stored", out, run, 10)
    assert sorted(rows.seed) == [3, 4, 5] and "commit" not in rows
    assert source.startswith("evidence/") and source.endswith("(3 records)")
    write_allocation(store_root, {(CHAPTER, "only_stored"): (2, "sizes 10 left out")})
    rows, source = ledger.study_rows(CHAPTER, "only_stored", out, run, 10)
    assert rows.seed.tolist() == [3, 4] and source.endswith("(2 records)")


def test_a_row_short_of_its_size_says_what_the_budget_pays_for(tmp_path, monkeypatch):
    """Its reason gives the CPU time the size needs at the stored rate (2 CPU-s a record: 5000
    records, 2.8 CPU-hours) and, where the allocation pays for fewer records than are stored,
    says so instead of counting the stored ones."""
    from railpaper.pipeline.decisive import write_allocation
    from railpaper.rulebook import Decision

    monkeypatch.setattr(ledger, "DECISIVE_EVIDENCE_DIR", tmp_path)
    (tmp_path / CHAPTER).mkdir()
    (tmp_path / CHAPTER / "provenance.json").write_text(json.dumps(
        {"studies": {"monte_carlo": {"records": 1000, "cpu_s": 2000.0}}}))
    short = Decision("undecided", "60 records of the 5000 registered")
    reason = ledger._with_cost(short, CHAPTER, "monte_carlo", 5000, None).reason
    assert reason.endswith("need about 2.8 CPU-hours at the stored records' rate (the stored "
                           "evidence holds 1000)")
    write_allocation(tmp_path, {(CHAPTER, "monte_carlo"): (400, "sizes 5000 left out")})
    reason = ledger._with_cost(short, CHAPTER, "monte_carlo", 5000, None).reason
    assert reason.endswith("pays for 400 of them; 1000 are stored)")
