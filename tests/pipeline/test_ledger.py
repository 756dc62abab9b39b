"""The claims ledger on hand-made claims and metrics: verdict vocabulary, readings, missing
metrics, non-default runs, the shared chapter table and the CSV."""

import csv
import json
import re

import pytest

from railpaper.data import DataError, read_toml
from railpaper.paths import DATA_DIR
from railpaper.pipeline.chapters import book_chapters, paper_chapters
from railpaper.pipeline.ledger import (
    CSV_COLUMNS,
    VERDICTS,
    LedgerRow,
    build_ledger,
    chapter_rows,
    chapter_table,
    judge,
    ledger_counts,
    ledger_markdown,
    write_ledger_csv,
)
from railpaper.pipeline.outputs import chapter_data_dir

CLAIMS_TOML = """
[fast]
claim = "converges in about 0.15 s"
source = "toy paper, p. 1"
kind = "population"
rule = "reproduced if the median is within 0.05 s of 0.15 s"
paper_value = 0.15
unit = "s"
primary = "t_med"
interval = ["t_low", "t_high"]
n_samples = "t_n"
statistic = "median over seeds"
[[fast.cases]]
verdict = "reproduced"
reason = "t = {t_med:.2f} s"
when = [{test = "within_abs", metrics = ["t_med"], tolerance = 0.05}]
[[fast.cases]]
verdict = "artefact"
reason = "only the slow variant: {t_slow:.2f} s"
when = [{test = "within_abs", metrics = ["t_slow"], tolerance = 0.05}]
[fast.otherwise]
reason = "t = {t_med:.2f} s"

[trend]
claim = "error grows with speed"
source = "toy paper, p. 2"
kind = "population"
rule = "reproduced if the rho interval lies above 0"
primary = "rho"
n_samples = "rho_n"
[[trend.cases]]
verdict = "reproduced"
reason = "grows"
when = [{test = "range", metrics = ["rho_low"], above = 0}]

[trend_printed]
claim = "error grows with speed"
group = "trend"
reading = "as printed"
source = "toy paper, p. 2"
kind = "deterministic"
rule = "same, on the printed equation"
primary = "rho_printed"
deterministic = true
[[trend_printed.cases]]
verdict = "reproduced"
reason = "grows"
when = [{test = "range", metrics = ["rho_printed"], above = 0}]

[timing]
claim = "56 % faster"
source = "toy paper, p. 4"
kind = "implementation"
rule = "ratio below 0.6"
paper_value = 56
unit = "%"
primary = "ratio"
n_samples = "ratio_n"
[[timing.cases]]
verdict = "reproduced"
reason = "ratio {ratio:.2f}"
when = [{test = "range", metrics = ["ratio"], below = 0.6}]

[lost]
claim = "agrees with line data"
source = "toy paper, p. 5"
kind = "single-run"
[lost.otherwise]
verdict = "not testable"
reason = "the line data are not published"
"""

DEFAULTS = {"seed": 0, "speeds_kmh": [60.0, 160.0]}


@pytest.fixture
def toy(tmp_path):
    """A chapter 'toy' with claims in tmp_path/data and a run in tmp_path/chapters."""
    (tmp_path / "data" / "toy").mkdir(parents=True)
    (tmp_path / "data" / "toy" / "claims.toml").write_text(CLAIMS_TOML)
    (tmp_path / "chapters" / "toy").mkdir(parents=True)

    def write_run(metrics, parameters=DEFAULTS, timings=None):
        out = tmp_path / "chapters" / "toy"
        run = {"chapter": "toy", "parameters": parameters, "quick": True, "metrics": metrics}
        (out / "metrics.json").write_text(json.dumps(run))
        if timings is not None:
            (out / "timings.json").write_text(json.dumps({"metrics": timings}))
        rows = build_ledger(["toy"], tmp_path / "chapters", tmp_path / "data")
        return {r.key: r for r in rows}
    return write_run


GOOD = {"t_med": 0.12, "t_low": 0.1, "t_high": 0.13, "t_n": 20, "t_slow": 0.5,
        "rho": 0.8, "rho_low": 0.2, "rho_n": 20, "rho_printed": 0.5, "ratio_n": 5}


def test_every_rule_and_vocabulary(toy):
    rows = toy(GOOD, timings={"ratio": 0.44})
    assert {k: r.verdict for k, r in rows.items()} == dict(
        dict.fromkeys(rows, "reproduced"), lost="not testable")
    assert rows["fast"].reason == "t = 0.12 s"
    assert rows["fast"].paper == "0.15 s" and rows["fast"].ours == "0.12 [0.1, 0.13] s, n = 20"
    assert (rows["fast"].ours_low, rows["fast"].ours_high, rows["fast"].n_samples) == (0.1, 0.13, 20)
    assert rows["timing"].reason == "ratio 0.44"   # looked up in timings.json
    assert rows["trend"].paper == "(no number)"
    assert rows["trend_printed"].group == "trend" and rows["trend_printed"].reading == "as printed"
    assert rows["lost"].reason == "the line data are not published"


@pytest.mark.parametrize("change, key, verdict, reason", [
    ({"t_med": 0.2001}, "fast", "differs", "t = 0.20 s"),          # just outside ±0.05
    ({"t_med": 0.21, "t_slow": 0.16}, "fast", "artefact", "only the slow variant: 0.16 s"),
    ({"rho_low": 0.0}, "trend", "differs", ""),                     # 'above' is strict
])
def test_rule_outcomes(toy, change, key, verdict, reason):
    rows = toy(dict(GOOD, **change), timings={"ratio": 0.44})
    assert (rows[key].verdict, rows[key].reason) == (verdict, reason)
    assert all(r.verdict in ("reproduced", "not testable") for k, r in rows.items() if k != key)


def test_missing_metric_and_missing_run(toy, tmp_path):
    rows = toy({k: v for k, v in GOOD.items() if k != "t_slow"}, timings={})
    assert rows["fast"].verdict == "missing" and "t_slow" in rows["fast"].reason
    assert rows["timing"].verdict == "missing" and rows["timing"].ours == "-"
    assert rows["trend"].verdict == "reproduced"
    rows = chapter_rows("toy", read_toml(tmp_path / "data/toy/claims.toml"), None)
    assert {r.verdict for r in rows} == {"missing"}


def test_non_default_parameters_noted_and_judged(monkeypatch, tmp_path):
    from railpaper.pipeline import ledger
    chapter = book_chapters()[0]
    defaults = ledger.chapter_spec(chapter).resolve({}, True).as_dict()
    run = {"parameters": dict(defaults, seed=7), "quick": True}
    assert ledger.non_default_note(chapter, run).startswith("Non-default parameters: seed.")
    assert ledger.non_default_note(chapter, {"parameters": defaults, "quick": True}) == ""


def test_rows_need_a_documented_rule():
    nokind = {"x": {"claim": "x", "source": "p", "rule": "r", "primary": "a", "deterministic": True,
                    "cases": [{"verdict": "reproduced", "reason": ""}]}}
    with pytest.raises(DataError, match="needs 'kind'"):
        chapter_rows("toy", nokind, {"metrics": {"a": 1}})
    bare = {"bare": {"claim": "x", "source": "p", "kind": "population", "rule": "r", "primary": "a", "cases": [
        {"verdict": "reproduced", "reason": "", "when": []}]}}
    with pytest.raises(DataError, match="needs 'n_samples'"):
        chapter_rows("toy", bare, {"metrics": {"a": 1}})
    norule = {"x": {"claim": "x", "source": "p", "kind": "deterministic", "primary": "a", "deterministic": True,
                    "cases": [{"verdict": "reproduced", "reason": ""}]}}
    with pytest.raises(DataError, match="needs 'rule'"):
        chapter_rows("toy", norule, {"metrics": {"a": 1}})
    badverdict = {"x": {"claim": "x", "source": "p", "kind": "deterministic", "rule": "r", "primary": "a",
                        "deterministic": True, "cases": [{"verdict": "reproduced*", "reason": ""}]}}
    with pytest.raises(DataError, match="verdict in reproduced, attainable, artefact, differs, undecided, not"):
        chapter_rows("toy", badverdict, {"metrics": {"a": 1}})
    badtest = {"x": {"claim": "x", "source": "p", "kind": "deterministic", "rule": "r", "primary": "a", "deterministic": True,
                     "cases": [{"verdict": "reproduced", "reason": "",
                                "when": [{"test": "close_to", "metrics": ["a"]}]}]}}
    with pytest.raises(DataError, match="unknown test 'close_to'"):
        chapter_rows("toy", badtest, {"metrics": {"a": 1}})


def _row(**extra):
    row = {"claim": "x", "source": "p", "kind": "deterministic", "rule": "r", "primary": "a",
           "deterministic": True, "cases": [{"verdict": "reproduced", "reason": "",
                                             "when": [{"test": "range", "metrics": ["a"],
                                                       "above": 0}]}]}
    row.update(extra)
    return row


def test_other_methods_say_attainable_and_revisions_state_the_original():
    with pytest.raises(DataError, match="says 'attainable', never 'reproduced'"):
        chapter_rows("toy", {"x": _row(method="exact posterior")}, {"metrics": {"a": 1}})
    attain = _row(cases=[{"verdict": "attainable", "reason": "",
                          "when": [{"test": "range", "metrics": ["a"], "above": 0}]}])
    with pytest.raises(DataError, match="name it in 'method'"):
        chapter_rows("toy", {"x": attain}, {"metrics": {"a": 1}})
    row = chapter_rows("toy", {"x": dict(attain, method="exact posterior")},
                       {"metrics": {"a": 1}})[0]
    assert row.verdict == "attainable" and not row.headline      # counted apart
    with pytest.raises(DataError, match="needs 'what', 'when', 'why'"):
        chapter_rows("toy", {"x": _row(revised_after_evidence={"what": "w"})}, {"metrics": {"a": 1}})
    with pytest.raises(DataError, match="states the original rule"):
        chapter_rows("toy", {"x": _row(revised_after_evidence={
            "what": "w", "when": "2026-12-03", "why": "y"})}, {"metrics": {"a": 1}})
    revised = _row(revised_after_evidence={
        "what": "threshold 0 instead of 2", "when": "2026-12-03", "why": "y",
        "original": {"cases": [{"verdict": "reproduced", "reason": "",
                                "when": [{"test": "range", "metrics": ["a"], "above": 2}]}]}})
    row = chapter_rows("toy", {"x": revised}, {"metrics": {"a": 1}})[0]
    assert (row.verdict, row.original_verdict) == ("reproduced", "differs")
    assert row.revised.startswith("2026-12-03: threshold 0 instead of 2")


def test_equals_reference_metric_and_non_strict_increasing():
    claim = {"paper_value": True, "primary": "a", "deterministic": True, "cases": [
        {"verdict": "reproduced", "reason": "eq", "when": [{"test": "equals", "metrics": ["flag"]}]},
        {"verdict": "reproduced", "reason": "near b",
         "when": [{"test": "within_factor", "metrics": ["a"], "reference": "b", "factor": 2}]},
        {"verdict": "differs", "reason": "ordered",
         "when": [{"test": "increasing", "metrics": ["a", "b"], "strict": False}]}]}
    assert judge(claim, {"flag": True, "a": 1.0, "b": 9.0}) == ("reproduced", "eq")
    assert judge(claim, {"flag": False, "a": 5.0, "b": 9.0}) == ("reproduced", "near b")
    assert judge(claim, {"flag": False, "a": 4.0, "b": 9.0}) == ("differs", "ordered")
    assert judge(claim, {"flag": False, "a": 9.0, "b": 9.0}) == ("reproduced", "near b")
    assert judge(claim, {"flag": False, "a": 90.0, "b": 9.0}) == ("differs", "")


def test_markdown_counts_badges_and_chapter_table_shared(toy):
    rows = list(toy(dict(GOOD, rho_low=-0.1), timings={"ratio": 0.44}).values())
    text = ledger_markdown(rows, {"toy": "Toy chapter"})
    # four claims (trend has two readings): the headline counts claims by their default reading
    assert text.startswith("4 claims of the paper's methods: 2 reproduced, 1 differs, "
                           "1 not testable (5 rows with the readings).")
    assert ("**{ref}`Toy chapter <claims-toy>`** — 4 claims of the paper's methods: 2 reproduced, "
            "1 differs, 1 not testable") in text
    assert chapter_table(rows) in text                 # the chapter renders the very same table
    assert text.count('<span class="verdict verdict-reproduced">') == 2 + 3   # table + dropdown
    assert "+ 1 other reading: ✔ 1" in text            # trend_printed, folded under trend
    assert '<span class="verdict verdict-not-testable">∅ not testable</span>' in text
    assert ledger_counts(rows)["toy"] == dict(zip(VERDICTS, (3, 0, 0, 1, 0, 1, 0)))


def test_markdown_escapes_table_breakers():
    row = LedgerRow("toy", "k", "a | b", "s", "$1", "2", "differs", "x | y")
    table = chapter_table([row]).splitlines()
    line = table[2]
    assert len(re.findall(r"(?<!\\)\|", line)) == 6     # five columns, pipes inside escaped
    assert "a \\| b" in line and "\\$1" in line
    assert any("x | y" in text for text in table[3:])   # the reason, in the dropdown below


def test_ledger_csv_columns_and_numbers(toy, tmp_path):
    rows = list(toy(GOOD, timings={"ratio": 0.44}).values())
    path = write_ledger_csv(rows, tmp_path / "ledger.csv")
    with path.open() as handle:
        table = list(csv.DictReader(handle))
    assert list(table[0]) == CSV_COLUMNS and len(table) == 5
    fast = table[0]
    assert (fast["claim"], fast["reading"], fast["verdict"]) == (
        "converges in about 0.15 s", "as stated", "reproduced")
    assert float(fast["ours"]) == 0.12 and float(fast["ours_high"]) == 0.13
    assert int(fast["n_samples"]) == 20 and float(fast["paper_value"]) == 0.15
    assert table[4]["verdict"] == "not testable" and table[4]["ours"] == ""
    assert [t["headline"] for t in table] == ["true", "true", "false", "true", "true"]
    assert [t["kind"] for t in table][:3] == ["population", "population", "deterministic"]


@pytest.mark.parametrize("chapter", paper_chapters())
def test_repository_claims_all_have_rules(chapter):
    """Every row of the four chapters can be judged (a run without metrics: 'missing')."""
    claims = read_toml(chapter_data_dir(chapter) / "claims.toml")
    rows = chapter_rows(chapter, claims, {"metrics": {}, "parameters": {}, "quick": True})
    assert len(rows) == len(claims)
    assert {r.verdict for r in rows} <= {"missing", "not testable", "undecided"}
    for row in claims.values():
        assert row.get("justification") or row.get("otherwise", {}).get("verdict") == "not testable"


def test_toc_numbers_chapters_and_lists_appendix_pages_that_exist(tmp_path):
    import yaml

    from railpaper.pipeline.book import write_toc
    (tmp_path / "reproducibility.md").write_text("# R\n")
    chapters = book_chapters()
    ours = [c for c in chapters if c not in paper_chapters()]
    toc = yaml.safe_load(write_toc(tmp_path, chapters).read_text())
    main, beyond, appendix = toc["parts"] if ours else (*toc["parts"][:1], None, toc["parts"][1])
    assert main["numbered"] is True and "numbered" not in appendix
    assert [c["file"].split("/")[1] for c in main["chapters"]] == paper_chapters()
    if ours:
        assert beyond["caption"] == "Beyond the papers"
        assert [c["file"].split("/")[1] for c in beyond["chapters"]] == ours
    assert appendix["chapters"] == [{"file": "reproducibility"}]
    (tmp_path / "performance.md").write_text("# P\n")
    toc = yaml.safe_load(write_toc(tmp_path, chapters).read_text())
    assert toc["parts"][-1]["chapters"] == [{"file": "reproducibility"}, {"file": "performance"}]


def test_environment_table_matches_the_installed_packages(tmp_path):
    """The generated table holds the lock's pins; the venv built from the lock has them installed."""
    from importlib.metadata import version

    from railpaper.paths import REPO_DIR
    from railpaper.pipeline.book import KEY_PACKAGES, locked_versions, write_environment
    pins = locked_versions(REPO_DIR / "environment.lock")
    text = write_environment(tmp_path).read_text()
    for name in KEY_PACKAGES:
        assert f"| {name} | {pins[name]} |" in text
        assert version(name) == pins[name], name
    assert "| python | 3.11 " in text


V2_CHAPTERS = [c for c in ["reduced-order-observer", "partial-state-observer",
                            "rbpf-parameter-estimation", "quasi-gaussian-rbpf"]
               if not (DATA_DIR / c / "declarations.toml").exists()]
DECLARED_CHAPTERS = [c for c in ["reduced-order-observer", "partial-state-observer",
                                 "rbpf-parameter-estimation", "quasi-gaussian-rbpf"]
                     if (DATA_DIR / c / "declarations.toml").exists()]


@pytest.mark.parametrize("chapter", DECLARED_CHAPTERS)
def test_declared_chapter_rules_list_every_declaration(chapter):
    from railpaper.pipeline.declarations import load_declarations
    from railpaper.pipeline.ledger import chapter_rules
    text = chapter_rules(chapter)
    for d in load_declarations(chapter):
        assert f"**{d.claim}**" in text and f"“{d.words}”" in text.replace("\\$", "$")
        assert f"{d.word_class} → {d.procedure}" in text
    assert "no row carries a threshold of its own" in text


@pytest.mark.parametrize("chapter", V2_CHAPTERS)
def test_chapter_rules_gives_each_rule_and_reason_once_and_every_reading(chapter):
    from railpaper.pipeline.ledger import chapter_rules
    from railpaper.pipeline.outputs import claims
    text = chapter_rules(chapter)
    rows = claims(chapter).values()
    for row in rows:
        if row.get("reading"):
            assert f"reading: {row['reading']}" in text
        lines = text.splitlines()
        if row.get("justification"):
            j = " ".join(row["justification"].split("\n"))
            assert sum(line.endswith(f"*Why:* {j}") for line in lines) == 1, row["claim"]
        if row.get("rule"):
            r = " ".join(row["rule"].split("\n"))
            assert sum(f": {r} *" in line or line.endswith(f": {r}") for line in lines) == 1, r
    # every claim heads exactly one item
    for claim in {row["claim"] for row in rows}:
        assert text.count(f"**{claim}**") >= 1


def test_ledger_figure_places_the_paper_value_on_our_interval(tmp_path):
    """The common scale: our interval is [-1, 1]; the paper's value lands where it falls (by
    hand: interval [1, 3], value 2 -> 0, value 5 -> 3), clipped beyond ±4; a deterministic row
    is 0 when exact; the figure is written."""
    from railpaper.pipeline.ledger_figure import CLIP, claim_position, plot_ledger

    def row(reference, low=1.0, high=3.0, value=2.0, kind="population", paper=None):
        r = LedgerRow("toy", "k", "c", "s", "p", "o", "differs", "why", kind=kind,
                      ours_value=value, ours_low=low, ours_high=high, paper_value=paper)
        r.reference, r.headline = reference, True
        return r
    assert claim_position(row(2.0)) == 0.0 and claim_position(row(5.0)) == 3.0
    assert claim_position(row(0.0)) == -2.0 and claim_position(row(100.0)) == CLIP
    assert claim_position(row(4, low=None, high=None, value=4, paper=4)) == 0.0
    assert claim_position(row(4, low=None, high=None, value=6, paper=4)) == CLIP
    assert claim_position(row(None)) is None
    path = plot_ledger([row(2.0), row(9.0)], {"toy": "Toy"}, tmp_path / "ledger.png")
    assert path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
