"""When a signal has settled: the one definition behind every chapter's convergence metric.

A run has *settled* at the first sample from which a condition (``|error| < threshold``, an
estimate within a band of the truth or of its own final value) holds to the end of the record.
Chapters build the boolean condition themselves and ask one of these for where it settled::

    >>> import numpy as np
    >>> ok = np.array([False, True, False, True, True])
    >>> settled_index(ok), settling_step(ok), settling_time_s(np.arange(5) * 0.1, ok)
    (3, 4, 0.30000000000000004)
    >>> holds_from(ok, 4), first_step(ok)
    (True, 2)

Every function works along one axis of the condition (``axis``, default 0: samples first), so
a batch of runs is one call.  Steps are 1-based (step ``k`` is the estimate after measurement
``k``); indices are 0-based.
"""

from __future__ import annotations

import numpy as np


def settled_index(ok, axis: int = 0):
    """Index of the first sample from which ``ok`` holds to the end.

    Parameters
    ----------
    ok : array_like of bool, shape (K,) or with K along ``axis``
        Whether the condition holds at each sample.
    axis : int
        The samples' axis.

    Returns
    -------
    int or ndarray of int
        0 if it always holds, -1 if it fails at the last sample (never settled); an int for a
        1-D ``ok``, else an array of the other axes' shape.
    """
    ok = np.moveaxis(np.asarray(ok, dtype=bool), axis, 0)
    failing = ~ok
    last = ok.shape[0] - 1 - np.argmax(failing[::-1], axis=0)      # last failing index
    index = np.where(failing.any(axis=0), last + 1, 0)
    index = np.where(failing[-1], -1, index)
    return int(index) if index.ndim == 0 else index


def settling_step(ok, never: int = -1, axis: int = 0):
    """First step (1-based) from which ``ok`` holds to the end; ``never`` where it fails at the
    last step (-1, or ``K + 1`` so that a run that never settles ranks after every one that does).
    """
    index = np.asarray(settled_index(ok, axis))
    step = np.where(index < 0, never, index + 1)
    return int(step) if step.ndim == 0 else step


def settling_time_s(t_s, ok, axis: int = 0):
    """Time (s, from ``t_s`` of shape (K,)) of the first sample from which ``ok`` holds to the
    end; -1.0 where it fails at the last sample."""
    index = np.asarray(settled_index(ok, axis))
    time = np.where(index < 0, -1.0, np.asarray(t_s, dtype=float)[np.maximum(index, 0)])
    return float(time) if time.ndim == 0 else time


def holds_from(ok, start: int, axis: int = 0):
    """Whether ``ok`` holds at every step from ``start`` (1-based, ``1 <= start <= K``) to the end."""
    ok = np.moveaxis(np.asarray(ok, dtype=bool), axis, 0)
    if not 1 <= start <= ok.shape[0]:
        raise ValueError(f"holds_from: start step {start} outside the record (1..{ok.shape[0]})")
    held = np.all(ok[start - 1:], axis=0)
    return bool(held) if held.ndim == 0 else held


def first_step(ok, axis: int = 0):
    """First step (1-based) at which ``ok`` holds (it may fail again later); -1 if never."""
    ok = np.moveaxis(np.asarray(ok, dtype=bool), axis, 0)
    step = np.where(ok.any(axis=0), np.argmax(ok, axis=0) + 1, -1)
    return int(step) if step.ndim == 0 else step
