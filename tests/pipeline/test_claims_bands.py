"""Bands that can fail: every claim rule's metrics have CI bands in data/<chapter>/tolerances.toml
that decide its verdict, so a change that flips a verdict fails ``railpaper check``; and no
verdict rests on fewer Monte Carlo samples than the chapter promises (>= 20 full, >= 5 quick)."""

import pytest

from railpaper.data import read_toml
from railpaper.pipeline.chapters import paper_chapters
from railpaper.pipeline.check import load_tolerances
from railpaper.pipeline.claim_rules import (
    is_untestable,
    rule_metrics,
    verdicts_over_bands,
)
from railpaper.pipeline.outputs import chapter_data_dir

MIN_SAMPLES = {"full": 20, "quick": 5}


def _rows(chapter):
    return read_toml(chapter_data_dir(chapter) / "claims.toml")


@pytest.mark.parametrize("mode", ["full", "quick"])
@pytest.mark.parametrize("chapter", paper_chapters())
def test_bands_decide_every_verdict(chapter, mode):
    bands = {m: (lo, hi) for m, (lo, hi, _) in load_tolerances(chapter)[mode].items()}
    problems = []
    for key, row in _rows(chapter).items():
        if is_untestable(row):
            continue
        unbanded = [m for m in rule_metrics(row) if m not in bands]
        if unbanded:
            problems.append(f"{key}: no {mode} band for {', '.join(unbanded)}")
            continue
        verdicts = verdicts_over_bands(row, bands)
        if len(verdicts) != 1:
            problems.append(f"{key}: {mode} bands allow {sorted(verdicts)}")
        if "n_samples" in row and bands[row["n_samples"]][0] < MIN_SAMPLES[mode] \
                and verdicts != {"undecided"}:
            problems.append(f"{key}: {mode} band of {row['n_samples']} admits fewer than "
                            f"{MIN_SAMPLES[mode]} samples")
    assert not problems, "\n".join(problems)


def test_min_samples_gives_undecided_below_it():
    from railpaper.pipeline.ledger import judge
    row = {"rule": "r", "primary": "rate", "n_samples": "n", "min_samples": 100, "cases": [
        {"verdict": "differs", "reason": "low", "when": [
            {"test": "range", "metrics": ["rate"], "below": 0.5}]}],
           "otherwise": {"verdict": "reproduced", "reason": "high"}}
    assert judge(row, {"rate": 0.3, "n": 30})[0] == "undecided"
    assert "30 samples are fewer than the 100" in judge(row, {"rate": 0.3, "n": 30})[1]
    assert judge(row, {"rate": 0.3, "n": 100}) == ("differs", "low")
    assert verdicts_over_bands(row, {"n": (30, 30), "rate": (0.2, 0.6)}) == {"undecided"}
    assert verdicts_over_bands(row, {"n": (100, 100), "rate": (0.2, 0.4)}) == {"differs"}
    assert verdicts_over_bands(row, {"n": (50, 150), "rate": (0.2, 0.4)}) == {"undecided", "differs"}


def test_three_valued_band_logic_on_hand_cases():
    row = {"paper_value": 350, "cases": [
        {"verdict": "reproduced", "when": [{"test": "range", "metrics": ["s"], "max": 350}]},
        {"verdict": "artefact", "when": [{"test": "within_abs", "metrics": ["t"], "tolerance": 10}]}],
        "otherwise": {"verdict": "differs"}}
    assert verdicts_over_bands(row, {"s": (100, 350), "t": (0, 1)}) == {"reproduced"}
    assert verdicts_over_bands(row, {"s": (100, 351), "t": (0, 1)}) == {"reproduced", "differs"}
    assert verdicts_over_bands(row, {"s": (351, 400), "t": (345, 355)}) == {"artefact"}
    assert verdicts_over_bands(row, {"s": (351, 400), "t": (339, 355)}) == {"artefact", "differs"}
    trend = {"cases": [{"verdict": "reproduced",
                        "when": [{"test": "increasing", "metrics": ["a", "b"]}]}]}
    assert verdicts_over_bands(trend, {"a": (0, 1), "b": (1.5, 2)}) == {"reproduced"}
    assert verdicts_over_bands(trend, {"a": (0, 1), "b": (0.5, 2)}) == {"reproduced", "differs"}
    ref = {"cases": [{"verdict": "reproduced", "when": [
        {"test": "within_abs", "metrics": ["a"], "reference": "b", "tolerance": 1}]}]}
    assert verdicts_over_bands(ref, {"a": (0, 0.5), "b": (0.2, 0.9)}) == {"reproduced"}
    assert verdicts_over_bands(ref, {"a": (0, 0.5), "b": (1.2, 3)}) == {"reproduced", "differs"}
    assert verdicts_over_bands(ref, {"a": (0, 0.5), "b": (1.6, 3)}) == {"differs"}


STRADDLE = {"rule": "r", "primary": "rho", "interval": ["rho_low", "rho_high"], "n_samples": "n",
            "cases": [{"verdict": "reproduced", "reason": "rises",
                       "when": [{"test": "range", "metrics": ["rho_low"], "above": 0}]}],
            "otherwise": {"verdict": "differs", "reason": "does not rise"}}


def test_an_interval_across_the_threshold_is_undecided_on_a_run_and_over_bands():
    """The intro's definition, applied by the rule code: the rule alone would say 'differs'
    for rho = 0.38 [-0.43, 0.92]; its interval holds the threshold 0, so the row is undecided."""
    from railpaper.pipeline.ledger import judge
    verdict, reason = judge(STRADDLE, {"rho": 0.38, "rho_low": -0.43, "rho_high": 0.92, "n": 20})
    assert verdict == "undecided"
    assert "[-0.43, 0.92], n = 20 straddles the rule's threshold 0" in reason
    assert "would say differs" in reason
    assert judge(STRADDLE, {"rho": 0.5, "rho_low": 0.1, "rho_high": 0.9, "n": 20})[0] == "reproduced"
    assert judge(STRADDLE, {"rho": -0.5, "rho_low": -0.9, "rho_high": -0.1, "n": 20})[0] == "differs"
    assert judge(STRADDLE, {"rho": -0.5, "rho_low": -0.9, "rho_high": 0.0, "n": 20})[0] == "differs"
    bands = {"n": (20, 20), "rho": (0.3, 0.5)}
    assert verdicts_over_bands(STRADDLE, dict(bands, rho_low=(-0.6, -0.2), rho_high=(0.8, 1))) \
        == {"undecided"}
    assert verdicts_over_bands(STRADDLE, dict(bands, rho_low=(-0.6, -0.2), rho_high=(-0.1, 1))) \
        == {"differs", "undecided"}
    assert verdicts_over_bands(STRADDLE, dict(bands, rho_low=(0.1, 0.2), rho_high=(0.8, 1))) \
        == {"reproduced"}


def test_single_run_rows_read_the_ends_of_their_prediction_interval():
    """A paper's single run against our records: inside even the narrowest interval the
    quantiles allow is a plausible draw; outside the widest, it differs; between, undecided."""
    from railpaper.pipeline.ledger import judge
    row = {"rule": "r", "primary": "med", "interval": ["q1", "q2"], "n_samples": "n",
           "paper_value": 55, "deciding": [["q1_low", "q1_high"], ["q2_low", "q2_high"]],
           "cases": [{"verdict": "reproduced", "reason": "plausible", "when": [
               {"test": "range", "metrics": ["q1_high"], "max": 55},
               {"test": "range", "metrics": ["q2_low"], "min": 55}]},
               {"verdict": "differs", "reason": "below", "when": [
                   {"test": "range", "metrics": ["q1_low"], "above": 55}]}],
           "otherwise": {"verdict": "undecided", "reason": "cannot tell"}}
    run = {"med": 100, "q1": 40, "q2": 170, "q1_low": 30, "q1_high": 50, "q2_low": 160,
           "q2_high": 180, "n": 100}
    assert judge(row, run)[0] == "reproduced"          # the median 100 alone would "differ"
    assert judge(row, dict(run, q1_low=60, q1_high=70))[0] == "differs"
    assert judge(row, dict(run, q1_low=50, q1_high=60))[0] == "undecided"


def test_straddle_is_judged_by_the_verdict_not_by_any_threshold_inside():
    """The referee's cases: a threshold of a case that cannot hold either side does not make a
    row undecided; an interval touching the threshold does; so does a mechanism metric's
    interval across its own threshold."""
    from railpaper.pipeline.ledger import judge
    row = {"rule": "r", "primary": "q", "interval": ["q_low", "q_high"], "n_samples": "n",
           "cases": [
               {"verdict": "reproduced", "reason": "r",
                "when": [{"test": "range", "metrics": ["q_low"], "above": 0},
                         {"test": "range", "metrics": ["size_low"], "above": 1.1}]},
               {"verdict": "artefact", "reason": "a",
                "when": [{"test": "range", "metrics": ["p_low"], "above": 0}]}],
           "otherwise": {"verdict": "differs", "reason": "d"}}
    run = {"q": 0.2, "q_low": -0.1, "q_high": 0.5, "size_low": 1.0, "size_high": 1.01,
           "p_low": 0.3, "p_high": 0.9, "n": 20}
    assert judge(row, run)[0] == "artefact"       # artefact on both sides of q = 0
    assert judge(row, dict(run, p_low=0.0))[0] == "undecided"    # touches 0: artefact or not
    assert judge(row, dict(run, p_low=-0.2))[0] == "undecided"   # straddles 0
    assert judge(row, dict(run, p_low=-0.5, p_high=-0.2))[0] == "differs"


def test_the_original_rule_is_shown_as_written_and_the_changing_threshold_is_named():
    """An original rule is judged by its cases alone (the vocabulary check is the revised
    rule's); the straddle reason names the threshold where the verdict changes, not the first
    one inside; the sample estimate is given only for the row's own confidence interval."""
    from railpaper.pipeline.claim_rules import straddled_thresholds, verdict_as_written
    row = {"rule": "r", "primary": "m", "interval": ["m_low", "m_high"], "n_samples": "n",
           "kind": "population",
           "cases": [{"verdict": "reproduced", "reason": "meets",
                      "when": [{"test": "range", "metrics": ["m_low"], "max": 9},
                               {"test": "range", "metrics": ["m_high"], "min": 1}]}],
           "otherwise": {"verdict": "differs", "reason": "no"}}
    run = {"m": 5.0, "m_low": 3.0, "m_high": 20.0, "n": 100}
    assert verdict_as_written(row, run)[0] == "reproduced"        # the overlap rule as written
    found = straddled_thresholds(row, run)
    assert [t for _, _, t in found] == [9.0]                      # changes at 9, not at 1
    row2 = dict(row, cases=[{"verdict": "reproduced", "reason": "r", "when": [
        {"test": "range", "metrics": ["m_low"], "above": 2},
        {"test": "range", "metrics": ["m_high"], "below": 10}]}])
    from railpaper.pipeline.ledger import judge
    reason = judge(row2, {"m": 8.0, "m_low": 3.0, "m_high": 12.0, "n": 100})[1]
    assert "threshold 10" in reason and "samples would decide" in reason
    single = dict(row2, kind="single-run")
    assert "samples would decide" not in judge(single, {"m": 8.0, "m_low": 3.0, "m_high": 12.0,
                                                        "n": 100})[1]
