"""The appendix's stored fault-free running: a map over records whose rows do not depend on
their chunk, sized by power before it ran."""

from __future__ import annotations

import numpy as np

from railpaper.experiments.records import assert_chunk_invariant, map_in_process
from railpaper.experiments.suspension_fault_detection import SPEC, STUDIES, stored_sizes
from railpaper.experiments.suspension_fault_detection.experiment import (
    FAULT_FREE_RUNNING,
    RUNNING_SEED_OFFSET,
    monitored_s,
)
from railpaper.monitoring import poisson_excess_power

ONE_SPEED = {"speeds_kmh": [300.0]}


def test_the_study_is_the_chapters_and_starts_far_from_the_runs_seeds():
    settings = SPEC.resolve({}, False)
    assert STUDIES == (FAULT_FREE_RUNNING,)
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
