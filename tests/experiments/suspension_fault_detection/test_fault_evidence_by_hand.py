"""The fault appendix's evidence arithmetic on hand-made outcomes."""

from __future__ import annotations

import pytest


def test_delays_as_survival_data_by_hand():
    """Four faulty records: detected after 0.2 s and 0.6 s, one watched 1.5 s without an alarm
    (censored), one that alarmed before the fault (censored at 0, not a detection)."""
    import numpy as np
    import pandas as pd

    from railpaper.experiments.suspension_fault_detection.evidence import survival_delay_metrics

    outcomes = pd.DataFrame({"delay_s": [0.2, 0.6, np.inf, np.inf],
                             "early": [False, False, False, True],
                             "watched_s": [3.0, 3.0, 1.5, 3.0]})
    m = survival_delay_metrics(outcomes, "x")
    # at risk: 3 after the early record leaves at 0; S(0.2) = 2/3, S(0.6) = 2/3 * 1/2 = 1/3
    assert m["km_delay_median_reached_x"] and m["km_delay_median_s_x"] == 0.6
    assert m["km_detected_within_0.5s_x"] == pytest.approx(1 - 2 / 3)
    assert m["km_detected_within_1s_x"] == pytest.approx(1 - 1 / 3)
    assert (m["km_delay_n_x"], m["km_delay_detected_x"]) == (4, 2)
    never = survival_delay_metrics(outcomes.assign(delay_s=np.inf), "y")
    assert not never["km_delay_median_reached_y"] and "km_delay_median_s_y" not in never


def test_cusum_false_alarms_with_restarts_and_their_mean_time_by_hand():
    from railpaper.experiments.suspension_fault_detection.evidence import (
        cusum_false_alarms,
        mean_time_between_false_alarms_metrics,
    )

    # record 1 watched from row 2: path 0.5, 1.5 (> 1: alarm, restart), then +1.0 -> 1.0 (no),
    # then +0.5 -> 1.5 (alarm); record 2 (ended early) never above 1; 0.5 s per row
    paths = [[9.0, 9.0, 0.5, 1.5, 2.5, 3.0], [0.0, 0.0, 0.2, 0.0]]
    alarms, running_s = cusum_false_alarms(paths, 1.0, 2, 0.5)
    assert (alarms, running_s) == (2, 3.0)
    m = mean_time_between_false_alarms_metrics(2, 7200.0, "x")
    assert m["mtbfa_h_x"] == 1.0 and m["false_alarm_running_h_x"] == 2.0
    assert m["mtbfa_h_lower_x"] == pytest.approx(2.0 / 6.295794, rel=1e-6)
    assert "mtbfa_h_y" not in mean_time_between_false_alarms_metrics(0, 7200.0, "y")


def test_fault_free_flange_contacts_counted_by_hand():
    """Five fault-free records at 300 km/h, one of which ends at flange contact: 1/5 with its
    Clopper-Pearson interval (0.00505, 0.716), and the page's sentence."""
    from railpaper.experiments.suspension_fault_detection.evidence import (
        fault_free_flange_metrics,
    )
    from railpaper.experiments.suspension_fault_detection.result import NO_FAULT, RecordRun
    from railpaper.experiments.suspension_fault_detection.tables import fault_free_flange_text

    runs = [RecordRun(NO_FAULT, "evaluation", 300.0, seed, -1.0, 4.0 - (seed == 2), seed == 2,
                      {}, {}, 1.0) for seed in range(5)]
    m = fault_free_flange_metrics(runs, "300kmh")
    assert m["flange_contact_rate_fault_free_300kmh"] == 0.2
    assert m["flange_contacts_fault_free_300kmh"] == 1
    assert m["flange_contact_rate_fault_free_300kmh_n"] == 5
    assert m["flange_contact_rate_fault_free_300kmh_low"] == pytest.approx(0.00505, abs=1e-5)
    assert m["flange_contact_rate_fault_free_300kmh_high"] == pytest.approx(0.71642, abs=1e-5)
    m.update(fault_free_flange_metrics(runs[:2], "200kmh"))
    assert fault_free_flange_text(m, [300.0, 200.0]) == \
        "1 of 5 records at 300 km/h, 0 of 2 at 200 km/h"
    assert fault_free_flange_text({}, [300.0]) == "no fault-free records"


def test_a_median_beyond_the_record_is_a_field_not_a_number():
    """Nine records' delays, four never alarmed (inf): sorted 0.1 … 0.5, inf × 4; the median is
    the 5th (0.5 s) and the distribution-free 95 % interval the 2nd and 8th order statistics
    (P(2 <= Bin(9, 1/2) <= 7) = 1 - 2 (1 + 9) / 512 = 0.961), so its upper end lies beyond the
    record: no number for it, a False flag instead. With six never alarmed the median itself
    lies beyond."""
    import numpy as np

    from railpaper.experiments.suspension_fault_detection.evidence import censored_median
    from railpaper.experiments.suspension_fault_detection.result import read_censored_median

    inf = np.inf
    median = censored_median([0.3, 0.1, inf, 0.2, inf, 0.5, 0.4, inf, inf])
    assert (median.median, median.low, median.high, median.n) == (0.5, 0.2, None, 9)
    m = median.metrics("delay_median", "x")
    assert m == {"delay_median_reached_x": True, "delay_median_high_bounded_x": False,
                 "delay_median_s_x": 0.5, "delay_median_s_x_low": 0.2}
    assert read_censored_median(dict(m, delay_median_s_x_n=9), "delay_median", "x") == median
    beyond = censored_median([0.3, 0.1, inf, 0.2, inf, inf, inf, inf, inf]).metrics("d", "y")
    assert beyond == {"d_reached_y": False, "d_high_bounded_y": False, "d_s_y_low": 0.2}
    assert read_censored_median({}, "delay_median", "x") is None
    assert censored_median([0.3, 0.2, 0.1, 0.4, 0.5]).metrics("d", "z")["d_s_z"] == 0.3


def _free_run(statistic, seed=0, detector="bayes"):
    import numpy as np

    from railpaper.experiments.suspension_fault_detection.result import NO_FAULT, RecordRun
    return RecordRun(NO_FAULT, "calibration", 300.0, seed, -1.0, 0.5 * len(statistic), False,
                     {detector: np.asarray(statistic, float)}, {}, 1.0)


def test_which_parameter_is_blamed_at_the_alarm_by_hand():
    """Three records of a C_saly fault (parameter 4), rows of 0.5 s: the first alarms at
    1.5 s (row 2), where the GLR's best hypothesis is 9 (parameter 9 // 5 = 1: wrong); the
    second at 1.0 s (row 1), hypothesis 22 (parameter 4: right); the third never: 1 of 2."""
    import numpy as np
    import pandas as pd

    from railpaper.experiments.suspension_fault_detection.evidence import isolation_metrics
    from railpaper.experiments.suspension_fault_detection.result import RecordRun

    runs = [RecordRun("csaly_0", "fault", 300.0, s, 0.5, 2.0, False, {}, {}, 0.0,
                      np.array(hyp)) for s, hyp in enumerate([[0, 3, 9, 9], [0, 22, 22, 1],
                                                              [0, 0, 0, 0]])]
    outcomes = pd.DataFrame({"alarm_s": [1.5, 1.0, np.inf], "delay_s": [1.0, 0.5, np.inf]})
    parameter_of = np.repeat(np.arange(5), 5)                    # 5 parameters x 5 factors
    m = isolation_metrics(runs, outcomes, 0.5, parameter_of, 4, "x")
    assert (m["isolated_x"], m["isolated_x_n"]) == (0.5, 2)


def test_tail_check_and_operating_points_by_hand():
    """Calibration: one record whose 0.5 s blocks (one sample each) have maxima 1..10, the
    tail of the monitoring's hand test (level 8, scale 1.5, 2 of 10 above: a mean time of
    2.5 s at the level). Check record: 25 blocks (12.5 s), 5 of them at 100 (above any
    threshold), the rest 0: the threshold for 5 expected exceedances is the level itself
    (12.5 s / 5 = 2.5 s), 5 are counted (two-sided Poisson p = 1). At 100 h the
    tail's threshold is 8 + 1.5 ln(0.2 * 100 * 3600 / 0.5), and the Shiryaev-Roberts bound at it
    is e^h * dt."""
    import math

    import numpy as np

    from railpaper.experiments.suspension_fault_detection.evidence import (
        false_alarm_tail,
        operating_point_metrics,
        tail_check,
    )
    tail = false_alarm_tail([_free_run(np.arange(1.0, 11.0))], "bayes", 0, 1, 0.5)
    assert (tail.level, tail.scale, tail.exceed, tail.blocks) == (8.0, 1.5, 0.2, 10)
    check = tail_check(tail, [_free_run(np.r_[np.full(5, 100.0), np.zeros(20)])], "bayes", 0, 1,
                       "x")
    assert check["tail_check_mtbfa_h_x"] * 3600 == pytest.approx(2.5)
    assert check["tail_check_expected_x"] == pytest.approx(5.0)
    assert check["tail_check_alarms_x"] == 5
    assert check["tail_check_p_x"] == 1.0
    m = operating_point_metrics(tail, {}, "bayes", 0, 0.5, "300kmh")
    h = 8.0 + 1.5 * math.log(0.2 * 100 * 3600 / 0.5)
    assert m["threshold_at_100h_bayes_300kmh"] == pytest.approx(h)
    assert m["sr_bound_mtbfa_h_at_100h_bayes_300kmh"] == pytest.approx(math.exp(h) * 0.5 / 3600)


def test_a_critical_speed_beyond_the_search_is_a_field_not_a_number():
    """A fault whose model is stable up to the search's top writes critical_speed_found_<fault>
    False and no speed; the faults table says "above 600" for it, the speed for a found one and
    "—" for a fault without either field."""
    from types import SimpleNamespace

    from railpaper.experiments.suspension_fault_detection.result import Fault
    from railpaper.experiments.suspension_fault_detection.tables import faults_table
    faults = (Fault("stiff", "kpy", 3.0, "abrupt", "stiffer"), Fault("soft", "ksy", 0.7,
                                                                     "abrupt", "softer"),
              Fault("odd", "csy", 0.5, "abrupt", "odd"))
    metrics = {"critical_speed_found_none": True, "critical_speed_kmh_none": 456.4,
               "critical_speed_found_stiff": False, "critical_speed_found_soft": True,
               "critical_speed_kmh_soft": 451.4}
    table = faults_table(SimpleNamespace(metrics=metrics, faults=faults, critical_speeds=None))
    rows = [line for line in table.splitlines() if line.startswith("| ")][1:]
    assert rows[0].endswith("| 456.4 |") and rows[1].endswith("| above 600 |")
    assert rows[2].endswith("| 451.4 |") and rows[3].endswith("| — |")


def test_paired_comparison_of_two_detectors_on_the_same_records_by_hand():
    """Five records: A earlier on the first, a tie (same sample) on the second, A never on the
    third where B detects, both never on the fourth (a tie), B earlier on the fifth."""
    import numpy as np
    from scipy.stats import beta

    from railpaper.experiments.suspension_fault_detection.evidence import paired_metrics

    inf = np.inf
    m = paired_metrics([0.005, 0.01, inf, inf, 0.02], [0.01, 0.01, 0.5, inf, 0.01], "x")
    assert m["paired_earlier_x"] == pytest.approx(1 / 5)
    assert m["paired_later_x"] == pytest.approx(2 / 5)
    # Clopper-Pearson for 1 of 5: the beta quantiles
    assert m["paired_earlier_x_low"] == pytest.approx(beta.ppf(0.025, 1, 5))
    assert m["paired_earlier_x_high"] == pytest.approx(beta.ppf(0.975, 2, 4))
    # the sign test: 3 records differ, A earlier on 1 of them
    assert m["paired_sign_share_x"] == pytest.approx(1 / 3) and m["paired_sign_share_x_n"] == 3
    # both detect records 1, 2 and 5: B - A = 0.005, 0, -0.01; median 0, and with three records
    # the distribution-free interval is [min, max]
    assert m["paired_both_detected_x"] == 3
    assert m["paired_difference_median_s_x"] == pytest.approx(0.0)
    assert (m["paired_difference_median_s_x_low"], m["paired_difference_median_s_x_high"]) == \
        pytest.approx((-0.01, 0.005))
    none = paired_metrics([inf, inf], [inf, inf], "y")
    assert none["paired_both_detected_y"] == 0 and "paired_difference_median_s_y" not in none
    assert "paired_sign_share_y" not in none
