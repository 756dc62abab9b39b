"""The form in which arrays reach the compiled kernels: C-contiguous, writable, of one dtype.

numba compiles a kernel once per argument type, and a read-only array (a frozen result's field,
``np.broadcast_to``'s view, which ``np.ascontiguousarray`` passes through) is a type of its own:
one read-only argument compiles the whole kernel again, seconds of a first run.  The wrappers
of the Kalman bank, the smoother, the one-pass filters and the ZOHs hand their kernels
:func:`kernel_array`\\ s, so each of those kernels has one signature::

    >>> import numpy as np
    >>> view = np.broadcast_to(np.eye(2), (3, 2, 2))     # read-only
    >>> kernel_array(view).flags.writeable
    True
    >>> a = np.zeros((3, 2))
    >>> kernel_array(a) is a                              # already in form: no copy
    True
"""

from __future__ import annotations

import numpy as np


def kernel_array(a, dtype=float) -> np.ndarray:
    """``a`` as a C-contiguous, writable array of ``dtype`` (copied only when it is not)."""
    a = np.ascontiguousarray(a, dtype=dtype)
    return a if a.flags.writeable else a.copy()
