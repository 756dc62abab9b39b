"""The claims ledger on hand-made claims and metrics: verdict rules, missing metrics, non-default runs."""

import json
import re

import pytest

from railpaper.data import DataError, read_toml
from railpaper.pipeline.chapters import book_chapters
from railpaper.pipeline.outputs import chapter_data_dir
from railpaper.pipeline.ledger import (VERDICTS, build_ledger, chapter_rows, judge, ledger_counts,
                                       ledger_markdown)

CLAIMS_TOML = """
[fast]
claim = "converges in about 0.15 s"
source = "toy paper, p. 1"
paper_value = 0.15
unit = "s"
metrics = ["t_60", "t_160"]
primary = "t_160"
[[fast.cases]]
verdict = "reproduced"
reason = "t = {t_60:.2f}-{t_160:.2f} s"
when = [{test = "within_abs", metrics = ["t_60", "t_160"], tolerance = 0.05}]
[[fast.cases]]
verdict = "differs"
reason = "only the slow variant: {t_slow:.2f} s"
when = [{test = "within_abs", metrics = ["t_slow"], tolerance = 0.05}]
[fast.otherwise]
reason = "t = {t_160:.2f} s"

[trend]
claim = "error grows with speed"
source = "toy paper, p. 2"
metrics = ["e_60", "e_160"]
primary = "e_160"
[[trend.cases]]
verdict = "reproduced"
reason = "grows"
when = [{test = "increasing", metrics = ["e_60", "e_160"]}]

[step]
claim = "converges at step 4"
source = "toy paper, p. 3"
paper_value = 4
unit = "step"
metrics = ["step"]
primary = "step"
[[step.cases]]
verdict = "reproduced"
reason = "step {step}"
when = [{test = "within_factor", metrics = ["step"], factor = 3}]

[timing]
claim = "56 % faster"
source = "toy paper, p. 4"
paper_value = 56
unit = "%"
metrics = ["ratio"]
primary = "ratio"
[[timing.cases]]
verdict = "reproduced"
reason = "ratio {ratio:.2f}"
when = [{test = "range", metrics = ["ratio"], below = 0.6}]
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
        rows = build_ledger(["toy"], tmp_path / "chapters", tmp_path / "data",
                            defaults=lambda chapter, quick: DEFAULTS)
        return {r.key: r for r in rows}
    return write_run


GOOD = {"t_60": 0.12, "t_160": 0.19, "t_slow": 0.5, "e_60": 1.0, "e_160": 2.0, "step": 11}


def test_every_rule_reproduced_with_reasons_formatted(toy):
    rows = toy(GOOD, timings={"ratio": 0.44})
    assert {k: r.verdict for k, r in rows.items()} == dict.fromkeys(rows, "reproduced")
    assert rows["fast"].reason == "t = 0.12-0.19 s"
    assert rows["fast"].paper == "0.15 s" and rows["fast"].ours == "0.19 s"
    assert rows["timing"].reason == "ratio 0.44"   # looked up in timings.json
    assert rows["trend"].paper == "(no number)"


@pytest.mark.parametrize("change, key, reason", [
    ({"t_160": 0.2001}, "fast", "t = 0.20 s"),                   # just outside ±0.05
    ({"t_160": 0.21, "t_slow": 0.16}, "fast", "only the slow variant: 0.16 s"),  # second case
    ({"e_160": 1.0}, "trend", ""),                                 # equal is not increasing
    ({"step": 13}, "step", ""),                                     # 13 > 3 * 4
    ({"step": -1}, "step", ""),                                     # never converged
])
def test_differs_when_a_rule_fails(toy, change, key, reason):
    rows = toy(dict(GOOD, **change), timings={"ratio": 0.44})
    assert rows[key].verdict == "differs"
    assert rows[key].reason == reason
    assert all(r.verdict == "reproduced" for k, r in rows.items() if k != key)


def test_bounds_are_inclusive_or_strict_as_named(toy):
    assert toy(dict(GOOD, step=12), timings={"ratio": 0.6})["step"].verdict == "reproduced"
    assert toy(dict(GOOD, step=12), timings={"ratio": 0.6})["timing"].verdict == "differs"


def test_missing_metric_and_missing_run(toy, tmp_path):
    rows = toy({k: v for k, v in GOOD.items() if k != "t_slow"}, timings={})
    assert rows["fast"].verdict == "missing" and "t_slow" in rows["fast"].reason
    assert rows["timing"].verdict == "missing" and rows["timing"].ours == "-"
    assert rows["step"].verdict == "reproduced"
    rows = chapter_rows("toy", read_toml(tmp_path / "data/toy/claims.toml"), None,
                        defaults=lambda quick: DEFAULTS)
    assert {r.verdict for r in rows} == {"missing"}


def test_non_default_parameters_are_not_comparable(toy):
    rows = toy(GOOD, parameters=dict(DEFAULTS, seed=3), timings={"ratio": 0.44})
    assert {r.verdict for r in rows.values()} == {VERDICTS[2]}
    assert rows["fast"].reason.startswith("run with non-default seed;")
    assert rows["fast"].ours == "0.19 s"  # still shown


def test_claim_without_rule_is_a_data_error(tmp_path):
    claims = {"bare": {"claim": "x", "metrics": ["a"]}}
    with pytest.raises(DataError, match="claim 'bare' needs 'primary'"):
        chapter_rows("toy", claims, {"metrics": {"a": 1}, "parameters": {}},
                     defaults=lambda quick: {})
    claims = {"bad": {"claim": "x", "primary": "a",
                      "cases": [{"verdict": "reproduced", "reason": "",
                                 "when": [{"test": "close_to", "metrics": ["a"]}]}]}}
    with pytest.raises(DataError, match="unknown test 'close_to'"):
        chapter_rows("toy", claims, {"metrics": {"a": 1}, "parameters": {}},
                     defaults=lambda quick: {})


def test_equals_reference_metric_and_non_strict_increasing():
    claim = {"paper_value": True, "primary": "a", "cases": [
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


def test_markdown_links_every_row_and_counts(toy):
    rows = list(toy(dict(GOOD, step=13), timings={"ratio": 0.44}).values())
    text = ledger_markdown(rows, {"toy": "Toy chapter"})
    assert text.startswith("4 claims: 3 reproduced, 1 differs.")
    assert "**{ref}`Toy chapter <claims-toy>`** — 3 reproduced, 1 differs" in text
    assert text.count("({ref}`chapter <claims-toy>`) |") == 4      # every reason links
    assert ledger_counts(rows) == {"toy": dict(zip(VERDICTS, (3, 1, 0, 0)))}


def test_markdown_escapes_table_breakers():
    from railpaper.pipeline.ledger import LedgerRow
    row = LedgerRow("toy", "k", "a | b", "s", "$1", "2", "differs", "x | y")
    line = ledger_markdown([row]).splitlines()[-1]
    assert len(re.findall(r"(?<!\\)\|", line)) == 6     # five columns, pipes inside escaped
    assert "a \\| b" in line and "x \\| y" in line and "\\$1" in line


@pytest.mark.parametrize("chapter", book_chapters())
def test_repository_claims_all_have_rules(chapter):
    """Every claim of the four chapters can be judged (a run without metrics: all 'missing')."""
    claims = read_toml(chapter_data_dir(chapter) / "claims.toml")
    rows = chapter_rows(chapter, claims, {"metrics": {}, "parameters": {}, "quick": True},
                        defaults=lambda quick: {})
    assert len(rows) == len(claims) and {r.verdict for r in rows} == {"missing"}
    for claim in claims.values():
        assert claim.get("justification"), claim["claim"]
        assert claim["primary"] in claim["metrics"]


def test_toc_lists_appendix_pages_that_exist(tmp_path):
    from railpaper.pipeline.book import write_toc
    (tmp_path / "reproducibility.md").write_text("# R\n")
    chapters = book_chapters()
    toc = write_toc(tmp_path, chapters).read_text().splitlines()
    assert toc[-1] == "- file: reproducibility" and "- file: performance" not in toc
    (tmp_path / "performance.md").write_text("# P\n")
    toc = write_toc(tmp_path, chapters).read_text().splitlines()
    assert toc[-2:] == ["- file: reproducibility", "- file: performance"]
    assert len(toc) == 3 + len(chapters) + 2


def test_environment_table_matches_the_installed_packages(tmp_path):
    """The generated table holds the lock's pins; the venv built from the lock has them installed."""
    from importlib.metadata import version

    from railpaper.pipeline.book import KEY_PACKAGES, REPO_DIR, locked_versions, write_environment
    pins = locked_versions(REPO_DIR / "environment.lock")
    text = write_environment(tmp_path).read_text()
    for name in KEY_PACKAGES:
        assert f"| {name} | {pins[name]} |" in text
        assert version(name) == pins[name], name
    assert "| python | 3.11 " in text
