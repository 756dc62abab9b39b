"""Honest timing: interleaved repeats, medians with their spread, the machine's load alongside.

Two engines timed one after the other see different machines (another process starts, the CPU
clocks down, caches are warm for the second); timed interleaved, A B A B …, both see the same
disturbances, and the ratio of each alternation pair is taken before the median.
"""

from __future__ import annotations

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


class LoadLog:
    """1-, 5- and 15-minute load averages at labelled moments of a benchmark."""

    def __init__(self, clock: Callable[[], float] = time.monotonic,
                 load: Callable[[], tuple] = os.getloadavg):
        self.clock, self.load, self.t0 = clock, load, clock()
        self.samples: list[dict] = []

    def sample(self, label: str) -> None:
        self.samples.append(dict(label=label, t_s=round(self.clock() - self.t0, 3),
                                 load=[float(x) for x in self.load()]))

    def as_dict(self) -> dict:
        """``load_before``, ``load_after`` (the first and last samples, 1/5/15 min), every sample
        and the largest 1-minute load seen (the bench's own threads count in it)."""
        if not self.samples:
            return {}
        return dict(load_before=self.samples[0]["load"], load_after=self.samples[-1]["load"],
                    load_samples=self.samples,
                    load_max_1min=max(s["load"][0] for s in self.samples))
