"""railpaper.timing's arithmetic on a fake clock (no test here times anything)."""

from __future__ import annotations

import itertools

from railpaper.timing import steps_per_second


def test_steps_per_second_is_steps_over_the_median_call():
    # three calls lasting 2, 1 and 4 s: median 2 s, so 500 steps -> 250 Hz
    ticks = itertools.chain([0.0, 2.0, 10.0, 11.0, 20.0, 24.0])
    calls = []
    rate = steps_per_second(lambda: calls.append(1), 500, repeats=3, clock=lambda: next(ticks))
    assert rate == 250.0 and len(calls) == 3
