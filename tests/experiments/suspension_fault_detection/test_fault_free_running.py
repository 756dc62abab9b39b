"""The appendix's stored fault-free running: a map over records whose rows do not depend on
their chunk, sized by power before it ran."""

from __future__ import annotations

import math

import numpy as np
import pandas as pd
import pytest

from railpaper.experiments.records import assert_chunk_invariant, map_in_process
from railpaper.experiments.suspension_fault_detection import SPEC, STUDIES, stored_sizes, tables
from railpaper.experiments.suspension_fault_detection.evidence import (
    long_running_check,
    poisson_check,
)
from railpaper.experiments.suspension_fault_detection.experiment import (
    FAULT_FREE_RUNNING,
    RUNNING_SEED_OFFSET,
    monitored_s,
)
from railpaper.experiments.suspension_fault_detection.result import RecordRun
from railpaper.monitoring import poisson_excess_power, poisson_two_sided_power

ONE_SPEED = {"speeds_kmh": [300.0]}


def test_the_study_is_the_chapters_and_starts_far_from_the_runs_seeds():
    settings = SPEC.resolve({}, False)
    assert FAULT_FREE_RUNNING in STUDIES
    assert FAULT_FREE_RUNNING.first(settings) == settings.seed + RUNNING_SEED_OFFSET
    assert RUNNING_SEED_OFFSET > 900 + settings.seed     # the run uses seed ... seed + 899


def test_size_by_power_at_the_defaults():
    # a 4 s record watched from the prior's first fault time (1 s) in 0.5 s blocks: 3 s
    settings = SPEC.resolve({}, False)
    assert monitored_s(settings) == 3.0
    size = stored_sizes(settings)["fault_free_running"]
    assert size == 1088
    assert poisson_excess_power(size * 3.0 / 3600.0 / 0.1, 2.0) >= 0.8


def test_rows_do_not_depend_on_their_chunk_and_hold_whole_blocks():
    settings = SPEC.resolve(ONE_SPEED, False)
    assert_chunk_invariant(FAULT_FREE_RUNNING, settings, (100_003, 100_001))
    rows = map_in_process(FAULT_FREE_RUNNING, settings, [100_001])
    blocks = [c for c in rows.columns if c.startswith("block_max_bayes_300kmh_")]
    assert len(blocks) == 6                             # (800 - 199) // 100 whole blocks
    finite = np.isfinite(rows[blocks].to_numpy())
    assert rows["running_s_300kmh"].iloc[0] == 0.5 * finite.sum()


def _rows(maxima_per_record):
    """Rows of the study at one speed (300 km/h) with the same block maxima for every
    detector."""
    rows = []
    for i, maxima in enumerate(maxima_per_record):
        row = {"seed": i, "running_s_300kmh": 0.5 * np.isfinite(maxima).sum(),
               "flange_contact_300kmh": bool(np.isnan(maxima).any())}
        for detector in ("cusum", "chi2", "glr", "bayes", "oracle"):
            row.update({f"block_max_{detector}_300kmh_{b}": v for b, v in enumerate(maxima)})
        rows.append(row)
    return pd.DataFrame(rows)


#: Two records' block maxima at 300 km/h: six whole blocks, then four (cut at flange contact).
TWO_RECORDS = [[4.0, 3.0, 1.0, 0.5, 0.2, 0.1], [2.0, 1.0, 0.0, 0.0, np.nan, np.nan]]


def _cusum_tail(blocks: int = 100) -> dict:
    """The run's metrics of a cusum tail at 300 km/h: P(block max > h) = 0.5 exp(-h) in 0.5 s
    blocks, fitted on ``blocks`` blocks."""
    return {"tail_level_cusum_300kmh": 0.0, "tail_scale_cusum_300kmh": 1.0,
            "tail_exceed_cusum_300kmh": 0.5, "tail_blocks_cusum_300kmh": blocks}


def test_long_running_check_by_hand():
    # the cusum's tail: P(block max > h) = 0.5 exp(-h) in 0.5 s blocks, so the mean time
    # between false alarms at h is e^h / 3600 h and the threshold for T hours is ln(3600 T)
    metrics = _cusum_tail()
    settings = SPEC.resolve(ONE_SPEED, False)
    rows = _rows(TWO_RECORDS)
    check = long_running_check(rows, metrics, settings)
    running_h = 5.0 / 3600.0                          # 10 whole blocks of 0.5 s
    assert check.running_h == {300.0: running_h} and check.flange_contacts == {300.0: 1}
    assert check.maxima[("cusum", 300.0)].tolist() == [4.0, 3.0, 2.0, 1.0, 1.0, 0.5, 0.2, 0.1,
                                                       0.0, 0.0]
    assert set(check.checks["detector"]) == {"cusum"}          # the others have no tail
    at = check.checks.set_index("mtbfa_h").loc[0.01]
    assert at["threshold"] == pytest.approx(math.log(36.0))    # 3.58: only 4.0 exceeds it
    assert at["expected_alarms"] == pytest.approx(running_h / 0.01)
    assert at["alarms"] == 1 and at["mtbfa_direct_h"] == pytest.approx(running_h)
    mu = running_h / 0.01                                      # P(X >= 1) = 1 - e^-mu
    assert at["p_value"] == pytest.approx(2 * (1 - math.exp(-mu)))
    assert at["outcome"] == "consistent"
    assert at["mtbfa_low_h"] == pytest.approx(running_h / (11.143287 / 2), rel=1e-6)
    assert at["mtbfa_high_h"] == pytest.approx(running_h / (0.0506356 / 2), rel=1e-5)
    many = long_running_check(_rows([[9.0] * 6, [9.0] * 6]), metrics, settings).checks
    assert set(many["outcome"]) == {"more alarms"} and set(many["alarms"]) == {12}
    # the tail refitted to the running: k = 2 largest of 10 above the third (2.0), mean excess
    # 1.5, exceed 0.2; the run's threshold for 100 h, ln(360000) = 12.79, then has a mean time
    # of 0.5 / 0.2 / 3600 exp((12.79 - 2) / 1.5) h
    refit = check.refits.set_index("mtbfa_h").loc[100.0]
    assert refit["threshold"] == pytest.approx(math.log(360_000.0))
    assert refit["mtbfa_h_of_run_threshold"] == pytest.approx(
        0.5 / 0.2 / 3600.0 * math.exp((math.log(360_000.0) - 2.0) / 1.5))


def test_poisson_check_outcomes_by_hand():
    # 0 alarms where 5 were expected: p = 2 e^-5 = 0.0135 -> fewer alarms; 3 where 5: p > 0.05
    none = poisson_check(0, 5.0, 1.0)
    assert none["p_value"] == pytest.approx(2 * math.exp(-5.0))
    assert none["outcome"] == "fewer alarms" and none["mtbfa_direct_h"] == np.inf
    assert none["mtbfa_low_h"] == pytest.approx(1.0 / (-math.log(0.025)), rel=1e-9)
    assert poisson_check(3, 5.0, 1.0)["outcome"] == "consistent"


def test_delays_at_both_tails_thresholds_by_hand():
    # one record of csaly_0 at 300 km/h, fault at 1.5 s; its cusum is 15 from 1.6 s and 25 from
    # 2.0 s.  The run's threshold for 100 h is ln(360000) = 12.8 (delay 0.1 s); the tail
    # refitted to the running of test_long_running_check_by_hand, 2 + 1.5 ln(0.2 * 360000 /
    # 0.5) = 19.8, is first reached at 2.0 s (delay 0.5 s)
    metrics = _cusum_tail()
    settings = SPEC.resolve(ONE_SPEED, False)
    statistic = np.zeros(800)
    statistic[319:] = 15.0                    # row k - 1 is the value after sample k (k dt)
    statistic[399:] = 25.0
    run = RecordRun(fault="csaly_0", role="fault", speed_kmh=300.0, seed=0, fault_time_s=1.5,
                    end_s=4.0, flange_contact=False, statistics={"cusum": statistic},
                    post_fault_estimate={}, true_factor_end=0.0)
    rows = _rows(TWO_RECORDS)
    check = long_running_check(rows, metrics, settings, (run,), monitor_from_s=1.0)
    row = check.delays.set_index("detector").loc["cusum"]
    assert row["fault"] == "csaly_0"
    assert row["km_delay_median_s_run"] == pytest.approx(0.1)
    assert row["km_delay_median_s_running"] == pytest.approx(0.5)
    assert row["km_detected_within_2s_run"] == row["km_detected_within_2s_running"] == 1.0


def test_long_running_facts_by_hand():
    # 20 calibration blocks of 0.5 s (10 s = 1/360 h): 100 h is log10(36000) = 4.56 orders
    # away; the running of test_long_running_check_by_hand (10 blocks, 5 s) log10(72000) =
    # 4.86; half as many blocks
    metrics = _cusum_tail(20)
    settings = SPEC.resolve(ONE_SPEED, False)
    rows = _rows(TWO_RECORDS)
    facts = tables.long_running_facts(long_running_check(rows, metrics, settings), metrics,
                                      settings)
    assert facts["orders_run"] == "4.6" and facts["orders_refit"] == "4.9"
    assert facts["block_ratio"] == "0.5"
    assert facts["power"] == (f"{poisson_two_sided_power(5 / 3600 / 0.1, 2.0):.2f} at "
                              "300 km/h")
