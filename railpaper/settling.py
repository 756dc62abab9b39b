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


def settling_step_to_final(estimate, tolerance: float) -> int:
    """First step (1-based) from which ``estimate`` stays within ``tolerance`` of its own last
    value — what one reads off a plot as "converged at step k".

    Parameters
    ----------
    estimate : array_like, shape (K,)
        The estimate after steps 1 … K (same unit as ``tolerance``).
    tolerance : float
        Half-width of the band around the last value.

    Returns
    -------
    int
        In 1 … K (the last sample is always within its own band).
    """
    estimate = np.asarray(estimate, dtype=float)
    return settled_index(np.abs(estimate - estimate[-1]) <= tolerance) + 1
