"""The findings of chapters of our own (``data/<chapter>/findings.toml``): each is decided on its
interval against its threshold, and the CI bands keep every verdict, so a change that flips a
finding fails ``railpaper check``."""

import pytest

from railpaper.data import DataError
from railpaper.pipeline.chapters import book_chapters, paper_chapters
from railpaper.pipeline.check import load_tolerances
from railpaper.pipeline.findings import in_force, read_findings, verdict, verdicts_over_bands

OURS = [c for c in book_chapters() if c not in paper_chapters()]


def test_verdict_reads_the_whole_interval():
    above = {"threshold": 0.5, "side": "above", "interval": ["lo", "hi"]}
    below = dict(above, side="below")
    assert verdict(above, 0.6, 0.9) == "holds" and verdict(above, 0.1, 0.4) == "fails"
    assert verdict(above, 0.4, 0.9) == "undecided" and verdict(above, 0.5, 0.9) == "undecided"
    assert verdict(below, 0.1, 0.4) == "holds" and verdict(below, 0.6, 0.9) == "fails"
    assert verdict(below, 0.1, 0.5) == "undecided"
    # every (low, high) inside these bands gives "holds"; widen the low band across 0.5: no
    assert verdicts_over_bands(above, {"lo": (0.6, 0.8), "hi": (0.9, 1.0)}) == {"holds"}
    assert verdicts_over_bands(above, {"lo": (0.4, 0.8), "hi": (0.9, 1.0)}) == {"holds",
                                                                                 "undecided"}
    assert verdicts_over_bands(below, {"lo": (0.0, 0.1), "hi": (0.2, 0.4)}) == {"holds"}
    assert verdicts_over_bands(below, {"lo": (0.0, 0.6), "hi": (0.7, 0.9)}) == {"fails",
                                                                                 "undecided"}


def test_fewer_records_than_the_minimum_give_undecided():
    row = {"threshold": 0.5, "side": "above", "interval": ["lo", "hi"], "n_samples": "n",
           "min_samples": 60}
    assert verdict(row, 0.6, 0.9, n=30) == "undecided" and verdict(row, 0.6, 0.9, n=60) == "holds"
    bands = {"lo": (0.6, 0.8), "hi": (0.9, 1.0)}
    assert verdicts_over_bands(row, dict(bands, n=(30, 30))) == {"undecided"}
    assert verdicts_over_bands(row, dict(bands, n=(60, 60))) == {"holds"}
    assert verdicts_over_bands(row, dict(bands, n=(30, 60))) == {"holds", "undecided"}


@pytest.mark.parametrize("mode", ["full", "quick"])
@pytest.mark.parametrize("chapter", OURS)
def test_bands_decide_every_finding(chapter, mode):
    bands = {m: (lo, hi) for m, (lo, hi, _) in load_tolerances(chapter)[mode].items()}
    problems = []
    for key, row in in_force(chapter).items():
        missing = [m for m in [row["metric"], row["n_samples"], *row["interval"]] if m not in bands]
        if missing:
            problems.append(f"{key}: no {mode} band for {', '.join(missing)}")
            continue
        verdicts = verdicts_over_bands(row, bands)
        if len(verdicts) != 1:
            problems.append(f"{key}: {mode} bands allow {sorted(verdicts)}")
    assert not problems, "\n".join(problems)


def test_a_finding_without_a_threshold_is_refused(tmp_path, monkeypatch):
    import railpaper.pipeline.findings as findings
    (tmp_path / "x").mkdir()
    (tmp_path / "x" / "findings.toml").write_text(
        '[f]\nfinding = "a"\nmetric = "m"\ninterval = ["l", "h"]\nn_samples = "n"\n'
        'side = "above"\n')
    monkeypatch.setattr(findings, "chapter_data_dir", lambda chapter: tmp_path / chapter)
    with pytest.raises(DataError, match="finding 'f': needs 'threshold'"):
        read_findings("x")


def test_retired_findings_and_notes_go_below_the_table(tmp_path, monkeypatch):
    """A finding in force is judged in the table (its note is not in the row); a retired one is
    not judged and, like every note, is listed in the collapsed section with its last verdict;
    a retired finding without its last verdict is refused."""
    import railpaper.pipeline.findings as findings
    (tmp_path / "x").mkdir()
    row = ('finding = "{0}"\nmetric = "m"\ninterval = ["l", "h"]\nn_samples = "n"\n'
           'threshold = 0.5\nside = "above"\n')
    path = tmp_path / "x" / "findings.toml"
    path.write_text("[kept]\n" + row.format("kept one") + 'note = "raised on day 2"\n'
                    "[gone]\n" + row.format("gone one") + 'retired = "dropped on day 3"\n'
                    'last_verdict = "holds"\n')
    monkeypatch.setattr(findings, "chapter_data_dir", lambda chapter: tmp_path / chapter)
    assert list(findings.in_force("x")) == ["kept"]
    page = findings.findings_markdown("x", {"m": 0.8, "l": 0.6, "h": 0.9, "n": 20})
    table, history = page.split("````{dropdown}")
    assert table.count("\n| ") == 1 and "kept one" in table and "**holds**" in table
    assert "gone one" not in table and "raised on day 2" not in table
    assert "**kept**: raised on day 2" in history
    assert "**gone** (retired; last verdict **holds**): gone one. *dropped on day 3*" in history
    path.write_text("[gone]\n" + row.format("gone one") + 'retired = "dropped"\n')
    with pytest.raises(DataError, match="'last_verdict'"):
        findings.read_findings("x")


def test_a_finding_whose_metrics_the_run_lacks_is_not_in_this_run(tmp_path, monkeypatch):
    """A run with other speeds (no metric of the finding) gets a row that says so, not a
    KeyError; a run with the metrics is judged as before."""
    import railpaper.pipeline.findings as findings
    (tmp_path / "x").mkdir()
    (tmp_path / "x" / "findings.toml").write_text(
        '[f]\nfinding = "at 300 km/h"\nmetric = "m_300"\ninterval = ["l_300", "h_300"]\n'
        'n_samples = "n_300"\nthreshold = 0.5\nside = "above"\n')
    monkeypatch.setattr(findings, "chapter_data_dir", lambda chapter: tmp_path / chapter)
    absent = findings.judged("x", {"m_250": 0.8})
    assert [f["verdict"] for f in absent] == [findings.NOT_IN_RUN] and absent[0]["value"] is None
    assert "*not in this run*" in findings.findings_markdown("x", {"m_250": 0.8})
    present = findings.judged("x", {"m_300": 0.8, "l_300": 0.6, "h_300": 0.9, "n_300": 20})
    assert [f["verdict"] for f in present] == ["holds"]


def test_an_operating_point_must_be_the_metrics_own(tmp_path, monkeypatch):
    """A finding at 100 h between false alarms reads metrics at 100 h (``_at_100h`` in the
    statistic, its interval's ends and its count), or is refused in one line."""
    import railpaper.pipeline.findings as findings
    (tmp_path / "x").mkdir()
    path = tmp_path / "x" / "findings.toml"
    text = ('[f]\nfinding = "at 100 h"\nmetric = "d_at_{0}h"\ninterval = ["d_at_{0}h_low", '
            '"d_at_{0}h_high"]\nn_samples = "d_at_{0}h_n"\nthreshold = 0.5\nside = "above"\n'
            'operating_point_mtbfa_h = 100\n')
    monkeypatch.setattr(findings, "chapter_data_dir", lambda chapter: tmp_path / chapter)
    path.write_text(text.format("100"))
    assert findings.read_findings("x")["f"]["operating_point_mtbfa_h"] == 100
    for wrong in ("10", "1000"):
        path.write_text(text.format(wrong))
        with pytest.raises(DataError, match="operating point \\('_at_100h'"):
            findings.read_findings("x")
