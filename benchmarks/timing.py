"""Honest timing: interleaved repeats, medians with their spread, the machine's load alongside.

Two engines timed one after the other see different machines (another process starts, the CPU
clocks down, caches are warm for the second); timed interleaved, A B A B …, both see the same
disturbances, and the ratio of each alternation pair is taken before the median.
"""

from __future__ import annotations

import math
import os
import time
from typing import Callable

import numpy as np


def interleaved(runs: dict[str, Callable[[], object]], repeats: int) -> dict[str, list]:
    """Call every run once per alternation, in the dict's order, ``repeats`` alternations.

    Returns
    -------
    dict
        Each run's results in alternation order.
    """
    if repeats < 1:
        raise ValueError(f"repeats must be >= 1, got {repeats}")
    out = {name: [] for name in runs}
    for _ in range(repeats):
        for name, run in runs.items():
            out[name].append(run())
    return out


def rates(seconds_per_step) -> list[float]:
    """Steps per second of each timing (s per step)."""
    return [1.0 / s for s in seconds_per_step]


def summary(values) -> dict:
    """Median, min and max of the values (the spread over the alternations)."""
    v = np.asarray(values, float)
    return dict(median=float(np.median(v)), min=float(v.min()), max=float(v.max()), n=len(v))


def paired_ratio(numerator, denominator) -> dict:
    """:func:`summary` of the per-alternation ratios numerator[i] / denominator[i]."""
    if len(numerator) != len(denominator):
        raise ValueError("paired timings need the same number of alternations")
    return summary(np.asarray(numerator, float) / np.asarray(denominator, float))


LOAD_TAU_S = 60.0       # time constant of the kernel's 1-minute load average (an EMA)


def _own_cpu_s() -> float:
    """CPU seconds of this process (every thread) and its waited-for children."""
    t = os.times()
    return t.user + t.system + t.children_user + t.children_system


class LoadLog:
    """1-, 5- and 15-minute load averages at labelled moments of a benchmark, and how much of
    the 1-minute load is the benchmark itself.

    The 1-minute load average is an exponential average (time constant 60 s) of the number of
    runnable threads.  The benchmark's own share is the same average of its own CPU use (CPU
    seconds per second, from ``os.times``, constant between samples), started at zero at the
    first sample; ``other`` = load − own share is the work of everything else (including the
    decaying tail of work that ended before the benchmark started).
    """

    def __init__(self, clock: Callable[[], float] = time.monotonic,
                 load: Callable[[], tuple] = os.getloadavg,
                 cpu: Callable[[], float] = _own_cpu_s):
        self.clock, self.load, self.cpu, self.t0 = clock, load, cpu, clock()
        self.samples: list[dict] = []
        self._last: tuple[float, float] | None = None
        self._own = 0.0

    def sample(self, label: str) -> None:
        t, cpu = self.clock(), self.cpu()
        if self._last is not None:
            dt = t - self._last[0]
            if dt > 0:
                rate = (cpu - self._last[1]) / dt                 # cores used since last sample
                decay = math.exp(-dt / LOAD_TAU_S)
                self._own = self._own * decay + rate * (1.0 - decay)
        self._last = (t, cpu)
        load = [float(x) for x in self.load()]
        self.samples.append(dict(label=label, t_s=round(t - self.t0, 3), load=load,
                                 own_1min=round(self._own, 3),
                                 other_1min=round(load[0] - self._own, 3)))

    def as_dict(self) -> dict:
        """``load_before``, ``load_after`` (the first and last samples, 1/5/15 min), every sample,
        the largest 1-minute load seen (the bench's own threads count in it) and the largest
        1-minute load of other work (``other_max_1min``)."""
        if not self.samples:
            return {}
        return dict(load_before=self.samples[0]["load"], load_after=self.samples[-1]["load"],
                    load_samples=self.samples,
                    load_max_1min=max(s["load"][0] for s in self.samples),
                    other_max_1min=max(s["other_1min"] for s in self.samples))
