"""The rulebook's procedures on hand-made evidence: every branch and boundary against a hand
computation or a closed form."""

from __future__ import annotations

import math

import numpy as np
import pytest

from railpaper import rulebook
from railpaper.rulebook import (
    Vocabulary,
    clopper_pearson,
    continuous_size,
    cost_ratio,
    deterministic,
    design,
    equivalence,
    implementation,
    mid_rank_tail,
    most_favourable,
    paired_change,
    population_rate,
    rate_size,
    relative_change,
    single_run,
    single_run_size,
)


def test_clopper_pearson_closed_forms():
    # k = 0: upper = 1 − (α/2)^(1/n); k = n: lower = (α/2)^(1/n)
    assert clopper_pearson(0, 10) == (0.0, pytest.approx(1 - 0.025 ** 0.1, rel=1e-12))
    assert clopper_pearson(10, 10) == (pytest.approx(0.025 ** 0.1, rel=1e-12), 1.0)
    low, high = clopper_pearson(5, 10)
    assert low == pytest.approx(1 - high, rel=1e-12)          # symmetric at k = n/2
    with pytest.raises(ValueError, match="0 <= k <= n"):
        clopper_pearson(11, 10)


def test_mid_rank_tail_by_hand():
    sample = [1.0, 2.0, 3.0, 4.0]
    assert mid_rank_tail(sample, 2.0) == 0.75                 # F = (1 + ½)/4
    assert mid_rank_tail(sample, 1.0) == 0.25                 # F = ½/4
    assert mid_rank_tail(sample, 2.5) == 1.0                  # the median
    assert mid_rank_tail(sample, 0.0) == 0.0 == mid_rank_tail(sample, 9.0)


def test_most_favourable_is_the_clipped_median():
    sample = [1.0, 2.0, 3.0, 4.0, 5.0]
    assert most_favourable(sample, 10.0, 4.0) == 8.0          # 10 ± 2, median 3 below
    assert most_favourable(sample, 4.0, 4.0) == 3.0           # the median is within 4 ± 2
    assert most_favourable(sample, 0.0, 2.0) == 1.0


@pytest.mark.parametrize("n, verdict", [(71, "undecided"), (72, "differs"), (73, "differs")])
def test_single_run_boundary_at_alpha(n, verdict):
    # A paper value beyond every record: #{T_r <= 0} = 0 and the upper bound 1 − 0.025^(1/n)
    # crosses α = 0.05 between n = 71 (0.0506) and n = 72 (0.0499).
    records = np.arange(n, dtype=float)[:, None]
    decision = single_run(records, [1e6], [0.0])
    assert decision.verdict == verdict
    assert decision.statistic == pytest.approx(1 / (n + 1))
    assert decision.high == pytest.approx(1 - 0.025 ** (1 / n), rel=1e-12)


def test_single_run_plausible_draw_and_resolution():
    records = np.arange(1.0, 201.0)[:, None]                  # 1..200
    assert single_run(records, [100.0], [0.0]).verdict == "reproduced"
    # 260 read to ±70 could have been 190: as typical as about 10 % of the records
    far = single_run(records, [260.0], [140.0])
    assert far.verdict == "reproduced"
    assert single_run(records, [260.0], [0.0]).verdict == "differs"


def test_single_run_judges_the_numbers_jointly():
    # Two numbers, each typical alone (the 15th percentile of its column), are one draw only
    # if a record shows both: here the columns run in opposite directions, so T_paper is the
    # smaller tail, 0.3, and 30 % of records are as extreme.
    n = 100
    first = np.arange(n, dtype=float)
    records = np.column_stack([first, first[::-1]])
    joint = single_run(records, [14.5, 14.5], [0.0, 0.0])
    assert joint.statistic == pytest.approx((1 + 30) / (n + 1))
    assert joint.verdict == "reproduced"
    with pytest.raises(ValueError, match=r"records must be \(n, 2\)"):
        single_run(first[:, None], [1.0, 2.0], [0.0, 0.0])


def test_single_run_on_a_yes_no_number_says_it_asks_only_whether_it_happens():
    # 31 of 100 records show the paper's outcome (1): T = 2 (1 − 0.845) = 0.31 for them and
    # 0.69 for the rest, so 31 records are as extreme: p = 32 / 101, a plausible draw, and the
    # reason gives the share 0.31 and points to a rate row.
    records = np.array([[1.0]] * 31 + [[0.0]] * 69)
    decision = single_run(records, [1.0], [0.0])
    assert decision.verdict == "reproduced"
    assert decision.statistic == pytest.approx(32 / 101)
    assert "here 0.31, not how often" in decision.reason
    # 2 of 100: the interval of 2/100 straddles α; 0 of 100: differs
    assert single_run(np.array([[1.0]] * 2 + [[0.0]] * 98), [1.0], [0.0]).verdict == "undecided"
    assert single_run(np.zeros((100, 1)), [1.0], [0.0]).verdict == "differs"
    assert "yes/no" not in single_run(np.arange(100.0)[:, None], [50.0], [0.0]).reason


def test_population_rate_boundaries():
    # lower bound of 72/72 = 0.025^(1/72) = 0.95006 > 0.95; of 71/71 = 0.94937
    assert population_rate(72, 72, 0.95).verdict == "reproduced"
    assert population_rate(71, 71, 0.95).verdict == "undecided"
    assert population_rate(0, 72, 0.05, direction="at most").verdict == "reproduced"
    assert population_rate(20, 100, 0.5).verdict == "differs"
    assert population_rate(52, 100, 0.5).verdict == "undecided"
    with pytest.raises(ValueError, match="direction"):
        population_rate(1, 2, 0.5, direction="about")


def test_relative_change_by_hand():
    a, b = [10.0, 12.0, 11.0, 13.0], [13.0, 15.0, 14.0, 16.0]
    r, low, high = relative_change(a, b)
    assert r == pytest.approx(3 / 11.5)
    # u = (3/11.5)(11.5 − A) = (3/11.5)[1.5, −0.5, 0.5, −1.5]; sd = (3/11.5)√(5/3)
    se = (3 / 11.5) * math.sqrt(5 / 3) / (2 * 11.5)
    half = 3.182446305284263 * se                             # t(0.975, 3)
    assert (low, high) == (pytest.approx(r - half), pytest.approx(r + half))
    with pytest.raises(ValueError, match="mean is 0"):
        relative_change([1.0, -1.0], [2.0, 2.0])


def test_paired_change_every_branch():
    a = np.array([10.0, 12.0, 11.0, 13.0])
    assert paired_change(a, a + 3, "increase", 0.1).verdict == "reproduced"   # [0.21, 0.31]
    assert paired_change(a + 3, a, "decrease", 0.1).verdict == "reproduced"
    assert paired_change(a, a + 3, "decrease", 0.1).verdict == "differs"      # the opposite
    assert paired_change(a, a + 0.2, "increase", 0.1).verdict == "differs"    # too small
    assert paired_change(a, a + [0.0, 2.5, 0.5, 3.0], "increase", 0.1).verdict == "undecided"
    with pytest.raises(ValueError, match="direction"):
        paired_change(a, a, "up", 0.1)


def test_equivalence_every_branch():
    close = [0.01, -0.01, 0.02, 0.0, 0.005, -0.004]
    assert equivalence(close, 0.1).verdict == "reproduced"
    assert equivalence([0.5, 0.52, 0.49, 0.51], 0.1).verdict == "differs"
    assert equivalence([0.0, 0.2, -0.1, 0.15], 0.1).verdict == "undecided"
    a = np.array([10.0, 12.0, 11.0, 13.0])
    assert equivalence(baseline=a, other=a * 1.01, margin=0.1).verdict == "reproduced"
    assert equivalence(baseline=a, other=a + 3, margin=0.1).verdict == "differs"
    # the 90 % interval of the deviations [0.08, 0.09, 0.085, 0.095] lies within ±0.1
    d = np.array([0.08, 0.09, 0.085, 0.095])
    half90 = 2.3533634348018264 * d.std(ddof=1) / 2          # t(0.95, 3)
    decision = equivalence(d, 0.1)
    assert decision.high == pytest.approx(d.mean() + half90)
    assert decision.verdict == ("reproduced" if d.mean() + half90 < 0.1 else "undecided")


def test_exact_design_implementation():
    assert deterministic(5, 5).verdict == "reproduced"
    assert deterministic(20, 5).verdict == "differs"
    assert deterministic(0.431, 0.43, 0.01).verdict == "reproduced"
    assert design(True, "poles placed at -30, -40").verdict == "reproduced"
    assert design(False, "poles placed at -30, -40").verdict == "differs"
    assert implementation(1200.0, None).verdict == "not testable"
    assert implementation(1200.0, 1000.0, "sample rate").verdict == "reproduced"
    assert implementation(800.0, 1000.0).verdict == "differs"
    assert implementation(None, 1000.0).verdict == "undecided"


@pytest.mark.parametrize("ratio, low, high, direction, share, verdict", [
    (0.50, 0.45, 0.55, "decrease", False, "reproduced"),     # wholly below 1 - 0.1
    (0.88, 0.85, 0.8999, "decrease", False, "reproduced"),   # high just below 0.9
    (0.92, 0.90, 0.95, "decrease", False, "differs"),        # low exactly at 0.9: short of it
    (0.90, 0.85, 0.95, "decrease", False, "undecided"),      # straddles 0.9
    (1.30, 1.20, 1.40, "decrease", False, "differs"),        # the opposite direction
    (1.20, 1.1001, 1.3, "increase", False, "reproduced"),
    (1.05, 1.00, 1.10, "increase", False, "differs"),        # high exactly at 1.1
    (0.60, 0.5001, 0.7, "increase", True, "reproduced"),     # a share above one half
    (0.40, 0.30, 0.50, "increase", True, "differs"),         # high exactly at one half
    (0.50, 0.40, 0.60, "increase", True, "undecided"),
])
def test_cost_ratio_boundaries(ratio, low, high, direction, share, verdict):
    decision = cost_ratio(ratio, low, high, direction, 0.1, share=share)
    assert decision.verdict == verdict
    assert (decision.statistic, decision.low, decision.high) == (ratio, low, high)
    with pytest.raises(ValueError):
        cost_ratio(0.5, 0.4, 0.6, "sideways", 0.1)


def test_sizes_from_power_by_hand():
    z = 1.959963984540054 + 0.8416212335729143             # z(0.975) + z(0.8)
    assert rate_size(0.5, 0.05) == math.ceil((z * 0.5 / 0.05) ** 2) == 785
    assert continuous_size(1.0, 0.1) == 785
    assert rate_size(0.95, 0.05) == math.ceil((z * math.sqrt(0.95 * 0.05) / 0.05) ** 2)
    assert single_run_size(0.05, 0.025) == math.ceil((z * math.sqrt(0.0475) / 0.025) ** 2) == 597
    with pytest.raises(ValueError):
        continuous_size(1.0, 0.0)


def test_vocabulary_is_one_map_for_the_book():
    vocabulary = Vocabulary.load()
    seen = {}
    for name, entry in vocabulary.classes.items():
        assert entry["procedure"] in rulebook.PROCEDURES
        assert len(entry["justification"].split()) >= 15
        for word in entry["words"]:
            assert word not in seen, f"'{word}' is in both {seen[word]} and {name}"
            seen[word] = name
    assert vocabulary.entry("absolute")["threshold"] == 0.95
    assert vocabulary.entry("majority")["threshold"] == 0.5
    assert vocabulary.entry("trend")["margin"] == vocabulary.entry("similarity")["margin"]
    with pytest.raises(KeyError, match="no word class 'often'"):
        vocabulary.entry("often")


@pytest.mark.parametrize("deviations, verdict", [
    ([0.30, 0.32, 0.31, 0.29], "reproduced"),       # wholly beyond +0.1
    ([-0.30, -0.32, -0.31, -0.29], "reproduced"),   # wholly beyond -0.1
    ([0.01, -0.01, 0.0, 0.005], "differs"),         # the 90 % interval within ±0.1
    ([0.0, 0.2, -0.1, 0.3], "undecided"),
])
def test_departure_is_the_mirror_of_equivalence(deviations, verdict):
    from railpaper.rulebook import departure
    mirror = {"reproduced": "differs", "differs": "reproduced", "undecided": "undecided"}
    decision = departure(deviations, margin=0.1)
    assert decision.verdict == verdict == mirror[equivalence(deviations, margin=0.1).verdict]
    assert decision.statistic == pytest.approx(np.mean(deviations))


def test_paired_change_shows_the_signed_change_whatever_the_claimed_direction():
    # the other is 3.24 times the baseline: +2.24, a "decrease" claim differs, its number stays +
    decision = paired_change([1.0, 1.0, 1.0, 1.0], [3.2, 3.3, 3.2, 3.26], "decrease", 0.1)
    assert decision.verdict == "differs"
    assert decision.statistic == pytest.approx(2.24) and decision.low < 2.24 < decision.high


def test_measured_only_is_not_testable_and_keeps_what_the_simulation_gave():
    simulated = rulebook.Decision("reproduced", "597 of 597 within 5 %", 1.0, 0.99, 1.0, 597)
    decision = rulebook.measured_only(simulated, "one line record")
    assert decision.verdict == "not testable"
    assert (decision.statistic, decision.low, decision.high, decision.n) == (1.0, 0.99, 1.0, 597)
    assert "one line record" in decision.reason and "reproduced, 597 of 597" in decision.reason
