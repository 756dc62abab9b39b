"""Evidence of chapter quasi-gaussian-rbpf (railpaper.experiments.quasi_gaussian_rbpf.evidence and
_timing) against independent references: hand-computed paired statistics, the binomial order
statistics of the median interval counted with math.comb, scipy's exact (Clopper-Pearson)
binomial interval; and the chapter's pairing (no threshold = same stream)."""

import math
import time

import numpy as np
import pandas as pd
import pytest
from scipy import stats

from railpaper.experiments.quasi_gaussian_rbpf import computing_time as tm
from railpaper.experiments.quasi_gaussian_rbpf import evidence as ev
from railpaper.experiments.quasi_gaussian_rbpf import experiment as chapter

TRUTH = {"a": -0.7, "b": 1.5}


def _median_ci_by_counting(x):
    """95 % order-statistic interval of the median: the largest r with
    P(Binomial(n, 1/2) <= r - 1) <= 0.025, counted with exact integers."""
    x, n = np.sort(np.asarray(x, float)), len(x)
    r = 0
    while sum(math.comb(n, i) for i in range(r + 1)) * 40 <= 2 ** n:   # P(B <= r) <= 1/40
        r += 1
    r = max(r, 1)
    return float(x[r - 1]), float(x[n - r])


def _table(n=25, seed=3):
    """A synthetic Monte Carlo table with every column the evidence reads."""
    rng = np.random.default_rng(seed)
    cols = {}
    for par in ev.PARAMS:
        for name in ev.FILTERS + ("posterior",):
            cols[f"settling_step_{par}_{name}"] = rng.integers(1, 300, n)
            cols[f"final_error_{par}_{name}"] = rng.normal(0, 0.1, n)
            cols[f"short_error_{par}_{name}"] = rng.normal(0, 0.2, n)
            cols[f"short_settling_step_{par}_{name}"] = rng.integers(1, 60, n)
        for name in ev.FILTERS + tuple(q + ev.NO_THRESHOLD for q in ev.QGRBPF_READINGS):
            cols[f"final_z_{par}_{name}"] = rng.normal(0, 1.5, n)
        for name in ev.FILTERS:
            cols[f"final_std_ratio_{par}_{name}"] = rng.uniform(0.1, 1.5, n)
    return pd.DataFrame(cols)


def test_accuracy_gain_gives_the_papers_percentages():
    # (0.167 - 0.066) / 0.7 = 14.43 %, (0.067 - 0.055) / 1.5 = 0.8 % (signs do not matter)
    assert ev.accuracy_gain([0.167], [0.066], -0.7)[0] == pytest.approx(14.428571, rel=1e-6)
    assert ev.accuracy_gain([-0.067], [-0.055], 1.5)[0] == pytest.approx(0.8, rel=1e-12)
    assert ev.accuracy_gain([0.01], [-0.02], 0.5)[0] == pytest.approx(-2.0)


def test_paired_statistics_by_hand():
    t = pd.DataFrame({
        "settling_step_a_rbpf": [100, 50], "settling_step_b_rbpf": [80, 60],
        "settling_step_a_qgrbpf": [4, 70], "settling_step_b_qgrbpf": [6, 20],
        "final_z_a_qgrbpf": [0.5, -3.0], "final_z_b_qgrbpf": [-1.0, 1.0],
        "final_z_a_qgrbpf_nothreshold": [0.4, 2.5], "final_z_b_qgrbpf_nothreshold": [-2.5, 0.0]})
    np.testing.assert_allclose(ev.settling_advantage(t, "qgrbpf"), [(96 + 74) / 2, (-20 + 40) / 2])
    np.testing.assert_allclose(ev.worst_abs_z(t, "qgrbpf"), [1.0, 3.0])
    np.testing.assert_allclose(ev.threshold_effect(t, "qgrbpf"), [2.5 - 1.0, 2.5 - 3.0])
    assert ev.satisfactory_count(t, "qgrbpf") == 1          # record 2: |z_a| = 3 > 2
    assert ev.satisfactory_count(t, "qgrbpf_nothreshold") == 0


def test_evidence_metrics_equal_independent_computation():
    t = _table()
    m = ev.evidence_metrics(t, TRUTH)
    n = len(t)
    # a median with its order-statistic interval
    steps = t["settling_step_b_rbpf"]
    assert m["mc_settling_step_b_rbpf"] == np.median(steps)
    assert (m["mc_settling_step_b_rbpf_low"], m["mc_settling_step_b_rbpf_high"]) == \
        _median_ci_by_counting(steps)
    assert m["mc_settling_step_b_rbpf_n"] == n
    err = np.abs(t["final_error_a_posterior"])
    assert (m["mc_abs_final_error_a_posterior_low"], m["mc_abs_final_error_a_posterior_high"]) \
        == _median_ci_by_counting(err)
    # a rate with the exact binomial interval
    k = int(np.sum(np.maximum(np.abs(t.final_z_a_qgrbpf_printed),
                              np.abs(t.final_z_b_qgrbpf_printed)) <= 2))
    ci = stats.binomtest(k, n).proportion_ci(confidence_level=0.95, method="exact")
    assert m["mc_satisfactory_rate_qgrbpf_printed"] == k / n
    assert m["mc_satisfactory_rate_qgrbpf_printed_low"] == pytest.approx(ci.low, abs=1e-12)
    assert m["mc_satisfactory_rate_qgrbpf_printed_high"] == pytest.approx(ci.high, abs=1e-12)
    inside = int(np.sum(np.abs(t.final_z_b_rbpf) <= 2))
    assert m["mc_within_2std_rate_b_rbpf"] == inside / n
    # paired gains, written out
    gain_a = 100 * (np.abs(t.final_error_a_rbpf) - np.abs(t.final_error_a_qgrbpf)) / 0.7
    gain_b = 100 * (np.abs(t.final_error_b_rbpf) - np.abs(t.final_error_b_qgrbpf)) / 1.5
    assert m["mc_accuracy_gain_a_qgrbpf"] == pytest.approx(np.median(gain_a), abs=1e-12)
    assert m["mc_accuracy_gain_ab_qgrbpf"] == pytest.approx(np.median((gain_a + gain_b) / 2),
                                                            abs=1e-12)
    low, high = _median_ci_by_counting((gain_a + gain_b) / 2)
    assert m["mc_accuracy_gain_ab_qgrbpf_low"] == pytest.approx(low, abs=1e-12)
    assert m["mc_accuracy_gain_ab_qgrbpf_high"] == pytest.approx(high, abs=1e-12)
    ratio = t["final_std_ratio_a_qgrbpf"]
    assert m["mc_final_std_ratio_a_qgrbpf_high"] == _median_ci_by_counting(ratio)[1]
    # where one record falls: the 2.5 % and 97.5 % record of 25 (ranks 1 and 25 by the
    # inverted cdf), each quantile's interval clipped at the sample's ends at this n
    short = np.sort(t["short_settling_step_b_rbpf"].to_numpy())
    assert m["mc_short_settling_step_b_rbpf_p025"] == short[0]
    assert m["mc_short_settling_step_b_rbpf_p975"] == short[-1]
    assert m["mc_short_settling_step_b_rbpf_p025_clipped"] == 1
    gains = np.sort(gain_a)
    assert m["mc_accuracy_gain_a_qgrbpf_p975_high"] == pytest.approx(gains[-1], abs=1e-12)
    # every statistic comes with its interval and n
    for name in [k for k in m if k.endswith("_n")]:
        base = name[:-2]
        assert m[f"{base}_low"] <= m[base] <= m[f"{base}_high"] and m[name] == n


def test_paired_timing_metrics_are_ratios_within_a_repeat():
    s = pd.DataFrame({"rbpf": [1.0, 2.0, 4.0], "qgrbpf": [0.5, 1.0, 4.0],
                      "qgrbpf_printed": [2.0, 2.0, 2.0], "resampling": [0.1, 0.4, 0.4]})
    m = tm.paired_metrics(s)
    assert m["time_ratio_paired_qgrbpf_over_rbpf"] == 0.5          # ratios 0.5, 0.5, 1
    assert m["time_ratio_paired_qgrbpf_printed_over_rbpf"] == 1.0  # ratios 2, 1, 0.5
    assert (m["resampling_share_of_rbpf_step_low"], m["resampling_share_of_rbpf_step_high"]) \
        == (0.1, 0.2)                                              # n = 3: [min, max]
    assert m["resampling_share_of_rbpf_step_n"] == 3


def test_median_step_time_ignores_an_interrupted_step():
    class Filter:
        calls = 0

        def step(self, y):
            Filter.calls += 1
            time.sleep(0.05 if Filter.calls == 3 else 0.001)

    seconds = tm.median_step_seconds(lambda name, n, r: Filter(), "x", 10, np.zeros((9, 2)), 0)
    assert 0.0005 < seconds < 0.02


def test_without_threshold_is_the_same_stream():
    """With weight_threshold = 0 the 'no threshold' runs repeat the thresholded ones exactly, so
    the paired threshold effect is exactly zero: the pairing shares the random stream."""
    settings = chapter.SPEC.resolve(dict(n_particles=40, n_steps=25, grid_size=9, n_monte_carlo=3,
                                         timing=False, weight_threshold=0.0, readings_records=0),
                                    quick=True)
    m = chapter.run(settings).metrics
    for q in ev.QGRBPF_READINGS:
        assert m[f"final_z_a_{q}"] == m[f"final_z_a_{q}{ev.NO_THRESHOLD}"]
        assert m[f"mc_threshold_effect_{q}_low"] == m[f"mc_threshold_effect_{q}_high"] == 0.0
    biting = settings.replace(weight_threshold=0.5)  # a threshold that bites changes the run
    m = chapter.run(biting).metrics
    assert m["final_z_a_qgrbpf"] != m["final_z_a_qgrbpf_nothreshold"]


def test_eq10_reading_is_checked():
    with pytest.raises(chapter.ParameterError, match="eq10_reading"):
        chapter.run(chapter.SPEC.resolve(dict(eq10_reading="literal"), True))
