"""When a signal has settled: the one definition behind every chapter's convergence metric."""

from __future__ import annotations

import numpy as np


def settled_index(ok) -> int:
    """Index of the first sample from which ``ok`` holds to the end.

    Parameters
    ----------
    ok : array_like of bool, shape (K,)
        Whether the condition (e.g. ``|error| < threshold``) holds at each sample.

    Returns
    -------
    int
        0 if it always holds, -1 if it fails at the last sample (never settled).
    """
    ok = np.asarray(ok, dtype=bool)
    failing = np.flatnonzero(~ok)
    if failing.size == 0:
        return 0
    if failing[-1] == len(ok) - 1:
        return -1
    return int(failing[-1]) + 1
