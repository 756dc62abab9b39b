"""Keep freed memory in the process, so the filters' per-step arrays are not faulted in anew.

A particle filter at N = 1000 on the 16-state lateral model allocates a few megabytes per step
(the moved particles' F and G, H, the Kalman bank's x and P) and frees as much.  glibc's malloc
serves arrays above its mmap threshold with fresh ``mmap`` pages and returns freed memory at
the top of the heap to the system, so every step touches new pages: about 600 page faults per
paper-scheme step (2.5 MB of first touches), 15–20 % of the step's time on the benchmark
machine.  :func:`keep_freed_memory` raises both thresholds (``mallopt``), so those arrays come
from memory the process already holds: no faults, the same bits (the arithmetic does not
change).  The cost: memory freed after a large run stays with the process (up to
:data:`TRIM_THRESHOLD_BYTES` at the top of the heap) instead of going back to the system.

The filters call it when they are made (:class:`railpaper.engine.rbpf.RaoBlackwellisedPF`,
:class:`railpaper.engine.qgrbpf.QuasiGaussianRBPF`, :func:`railpaper.engine.ibis.run_ibis`);
on a C library without ``mallopt`` it does nothing::

    >>> from railpaper.memory import keep_freed_memory
    >>> keep_freed_memory() in (True, False)
    True
"""

from __future__ import annotations

import ctypes
import ctypes.util

M_TRIM_THRESHOLD, M_MMAP_THRESHOLD = -1, -3        # glibc's mallopt parameters (malloc.h)
MMAP_THRESHOLD_BYTES = 32 * 1024 * 1024            # glibc's largest: arrays below it reuse the heap
TRIM_THRESHOLD_BYTES = 1 << 30                     # free memory kept at the heap's top, at most

_state = {"applied": None}


def keep_freed_memory() -> bool:
    """Set glibc's mmap and trim thresholds once per process; True where they are set (glibc),
    False where the C library has no ``mallopt`` (nothing changes there)."""
    if _state["applied"] is None:
        try:
            libc = ctypes.CDLL(ctypes.util.find_library("c"))
            mallopt = libc.mallopt
        except (OSError, AttributeError, TypeError):
            _state["applied"] = False
        else:
            _state["applied"] = bool(mallopt(M_MMAP_THRESHOLD, MMAP_THRESHOLD_BYTES)
                                     and mallopt(M_TRIM_THRESHOLD, TRIM_THRESHOLD_BYTES))
    return _state["applied"]
