"""Honest timing: interleaved repeats, medians with their spread, the machine's load alongside.

Two engines timed one after the other see different machines (another process starts, the CPU
clocks down, caches are warm for the second); timed interleaved, A B A B …, both see the same
disturbances, and the ratio of each alternation pair is taken before the median.
"""

from __future__ import annotations

import math
import os
import platform
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


def steps_per_second(run_once: Callable[[], object], n_steps: int, repeats: int = 5,
                     clock: Callable[[], float] = time.perf_counter) -> float:
    """The rate (Hz) at which ``run_once`` — a filter or observer over ``n_steps`` steps —
    processes steps: ``n_steps`` over the median wall time of ``repeats`` calls (the median
    ignores a call the operating system interrupted).  What an on-line estimator sustains on
    this machine, to set against the sample rate its problem needs."""
    seconds = []
    for _ in range(max(1, int(repeats))):
        start = clock()
        run_once()
        seconds.append(clock() - start)
    return float(n_steps / np.median(seconds))


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


def machine() -> dict:
    """What the numbers were measured on: cores, CPU model, Python, numpy and its BLAS, numba and
    its threads (a benchmark's payload, the decisive evidence's provenance)."""
    import numba                                 # only where a machine is described
    blas = np.show_config(mode="dicts").get("Build Dependencies", {}).get("blas", {})
    cpu = platform.processor()
    if os.path.exists("/proc/cpuinfo"):
        with open("/proc/cpuinfo") as f:
            cpu = next((ln.split(":", 1)[1].strip() for ln in f if ln.startswith("model name")),
                       cpu)
    return dict(cores=os.cpu_count(), cpu=cpu, python=platform.python_version(),
                numpy=np.__version__, blas=f"{blas.get('name', '?')} {blas.get('version', '')}",
                numba=numba.__version__, numba_threads=numba.get_num_threads())


def _own_cpu_s() -> float:
    """CPU seconds of this process (every thread) and its waited-for children."""
    t = os.times()
    return t.user + t.system + t.children_user + t.children_system


def machine_busy_s() -> float | None:
    """CPU seconds the whole machine spent busy (all cores; user, nice, system, irq, softirq and
    steal — time the hypervisor gave to others), from /proc/stat; None where not available."""
    try:
        with open("/proc/stat") as f:
            fields = [int(v) for v in f.readline().split()[1:9]]
    except (OSError, ValueError):
        return None
    user, nice, system, _idle, _iowait, irq, softirq, steal = fields
    return (user + nice + system + irq + softirq + steal) / os.sysconf("SC_CLK_TCK")


class LoadLog:
    """Load averages at labelled moments of a benchmark and the work of everything else.

    ``other`` (cores) between two samples is what the machine spent busy (/proc/stat) minus what
    this process spent (``os.times``), divided by the wall time: the CPU that other processes, the
    kernel and the hypervisor (steal) took while the benchmark ran.  Where /proc/stat is not
    available it is estimated from the 1-minute load average instead: load minus the process's
    own CPU use averaged the same way (60-s exponential average), which also counts the decaying
    tail of work that ended before the benchmark started.
    """

    def __init__(self, clock: Callable[[], float] = time.monotonic,
                 load: Callable[[], tuple] = os.getloadavg,
                 cpu: Callable[[], float] = _own_cpu_s,
                 busy: Callable[[], float | None] = machine_busy_s):
        self.clock, self.load, self.cpu, self.busy, self.t0 = clock, load, cpu, busy, clock()
        self.samples: list[dict] = []
        self._last: tuple[float, float, float | None] | None = None
        self._own = 0.0

    def sample(self, label: str) -> None:
        t, cpu, busy = self.clock(), self.cpu(), self.busy()
        load = [float(x) for x in self.load()]
        other = None
        if self._last is not None:
            dt = t - self._last[0]
            if dt > 0:
                rate = (cpu - self._last[1]) / dt                 # cores used since last sample
                decay = math.exp(-dt / LOAD_TAU_S)
                self._own = self._own * decay + rate * (1.0 - decay)
                if busy is not None and self._last[2] is not None:
                    other = max(0.0, (busy - self._last[2]) / dt - rate)
        if other is None and busy is None:
            other = load[0] - self._own
        self._last = (t, cpu, busy)
        self.samples.append(dict(label=label, t_s=round(t - self.t0, 3), load=load,
                                 own_1min=round(self._own, 3),
                                 other_cores=None if other is None else round(other, 3)))

    def as_dict(self) -> dict:
        """``load_before``, ``load_after`` (the first and last samples, 1/5/15 min), every sample,
        the largest 1-minute load seen (the bench's own threads count in it) and the most cores
        other work took between two samples (``other_max_cores``)."""
        if not self.samples:
            return {}
        others = [s["other_cores"] for s in self.samples if s["other_cores"] is not None]
        out = dict(load_before=self.samples[0]["load"], load_after=self.samples[-1]["load"],
                   load_samples=self.samples,
                   load_max_1min=max(s["load"][0] for s in self.samples))
        if others:
            out["other_max_cores"] = max(others)
        return out
