"""The stored ladder rungs: a statistic kept as its peaks, by hand; which record is which; the
rows read back as records."""

import numpy as np
import pandas as pd

from railpaper.experiments.suspension_fault_detection import SPEC
from railpaper.experiments.suspension_fault_detection.evidence import (
    alarm_time_s,
    statistic_from_peaks,
    statistic_peaks,
    window_max,
)
from railpaper.experiments.suspension_fault_detection.experiment import (
    STORED_LADDER,
    STUDIES,
    stored_ladder_item,
    stored_ladder_records,
    stored_ladder_size,
    stored_sizes,
)
from railpaper.experiments.suspension_fault_detection.faults import catalogue
from railpaper.experiments.suspension_fault_detection.result import NO_FAULT
from railpaper.experiments.suspension_fault_detection.spec import DETECTORS, STORED_RUNGS
from railpaper.experiments.suspension_fault_detection.tables import found_within_2s
from railpaper.monitoring import block_maxima


def test_peaks_by_hand():
    # window from row 1: 1, 2, 0, 3, 2.5, 4, 1; new maxima at rows 1, 2, 4, 6; blocks of 3:
    # (1, 2, 0) largest at row 2, (3, 2.5, 4) at row 6; the partial block (1) is dropped
    x = [5.0, 1.0, 2.0, 0.0, 3.0, 2.5, 4.0, 1.0]
    assert statistic_peaks(x, 1, 3) == "1:1.0 2:2.0 4:3.0 6:4.0"
    # a block maximum that is no new maximum is kept too: (0, 3) at row 1, (1, 2) at row 3
    assert statistic_peaks([0.0, 3.0, 1.0, 2.0, 0.0], 0, 2) == "0:0.0 1:3.0 3:2.0"
    # −inf is no new maximum and reads back as itself; values keep every bit
    assert statistic_peaks([-np.inf, 0.1 + 0.2], 0, 5) == "1:0.30000000000000004"


def test_peaks_read_back_with_minus_infinity_elsewhere():
    np.testing.assert_array_equal(statistic_from_peaks("1:1.0 4:3.5", 6),
                                  [-np.inf, 1.0, -np.inf, -np.inf, 3.5, -np.inf])
    assert statistic_from_peaks("", 3).tolist() == [-np.inf] * 3


def test_peaks_keep_every_alarm_time_block_maximum_and_window_maximum():
    rng = np.random.default_rng(3)
    for _ in range(20):
        x = np.cumsum(rng.standard_normal(400))
        first_row, block_rows = int(rng.integers(0, 100)), int(rng.integers(1, 60))
        y = statistic_from_peaks(statistic_peaks(x, first_row, block_rows), x.size)
        np.testing.assert_array_equal(block_maxima(y, first_row, block_rows),
                                      block_maxima(x, first_row, block_rows))
        assert window_max(y, first_row) == window_max(x, first_row)
        for h in np.quantile(x[first_row:], np.linspace(0, 1, 25)):
            assert alarm_time_s(y, h, first_row, 0.005) == alarm_time_s(x, h, first_row, 0.005)


def test_which_record_is_which():
    settings = SPEC.resolve({"seed": 10}, False)
    # five faults and two fault-free roles per rung, rungs in turn, then the next seed
    assert stored_ladder_item(settings, 10) == ("track_unknown", "csaly_half", "fault", 10)
    assert stored_ladder_item(settings, 15) == ("track_unknown", "calibration", "calibration",
                                                310)
    assert stored_ladder_item(settings, 16) == ("track_unknown", "evaluation", "evaluation", 610)
    assert stored_ladder_item(settings, 17) == ("model_error", "csaly_half", "fault", 10)
    assert stored_ladder_item(settings, 10 + 14 + 3) == ("track_unknown", "ksy_70", "fault", 11)
    assert stored_ladder_size(settings) == 20 * len(STORED_RUNGS) * 7
    assert stored_sizes(settings)[STORED_LADDER.name] == 280
    assert STORED_LADDER in STUDIES and STORED_LADDER.first(settings) == 10


def test_rows_read_back_as_records():
    settings = SPEC.resolve({}, False)
    peaks = {f"{d}_peaks": "200:1.5 300:2.5" for d in DETECTORS}
    rows = pd.DataFrame([
        dict(seed=0, rung="model_error", record="ksy_70", record_seed=0, fault_time_s=1.5,
             end_s=2.0, flange_contact=True, **dict(peaks, glr_peaks=np.nan)),
        dict(seed=5, rung="model_error", record="calibration", record_seed=300,
             fault_time_s=-1.0, end_s=4.0, flange_contact=False, **peaks),
        dict(seed=7, rung="track_unknown", record="ksy_70", record_seed=0, fault_time_s=1.5,
             end_s=4.0, flange_contact=False, **peaks)])
    fault, free = stored_ladder_records(rows, settings, "model_error")
    assert (fault.fault, fault.role, fault.seed, fault.end_s) == ("ksy_70", "fault", 0, 2.0)
    assert fault.flange_contact and fault.statistics["glr"].size == 400
    assert np.all(fault.statistics["glr"] == -np.inf)         # an empty cell reads back as NaN
    assert fault.statistics["bayes"][300] == 2.5 and fault.statistics["bayes"][299] == -np.inf
    assert (free.fault, free.role, free.seed) == (NO_FAULT, "calibration", 300)
    assert free.statistics["oracle"].size == 800


def test_faults_found_within_2s_by_hand():
    chosen = [catalogue()[0][n] for n in ("csaly_0", "ksy_70")]
    rows = pd.DataFrame([
        # the lost damper: GLR on half the records (counts), the oracle on all (never counts)
        dict(fault="csaly_0", detector="glr", detected_within_2s=0.5),
        dict(fault="csaly_0", detector="cusum", detected_within_2s=0.45),
        dict(fault="csaly_0", detector="oracle", detected_within_2s=1.0),
        dict(fault="ksy_70", detector="oracle", detected_within_2s=1.0)])
    assert found_within_2s(rows, chosen) == "C_saly 0 % (GLR)"
    assert found_within_2s(rows[rows.fault == "ksy_70"], chosen) == "none"
