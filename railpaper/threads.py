"""One thread for a block of work: numba's parallel loops and OpenBLAS both, restored afterwards.

Why: the chapters' small-matrix work (Kalman banks of 16 states, stacks of 36 x 36 exponentials)
gains nothing from a second thread on a 2-core machine and, when other processes compete for
the cores, waits for its threads most of the time; one thread per process is also what the
sweep's workers run.  Results do not depend on the thread count (the kernels' sums run in a fixed
order), so this changes time only.
"""

from __future__ import annotations

import ctypes
import glob
import os
import site
from contextlib import contextmanager

import numba
import numpy as np

_BLAS_SETTERS = (("numpy.libs", "scipy_openblas_set_num_threads64_",
                  "scipy_openblas_get_num_threads64_"),
                 ("scipy.libs", "scipy_openblas_set_num_threads", "scipy_openblas_get_num_threads"))


def _openblas_handles() -> list:
    """(set, get) of the OpenBLAS libraries bundled with numpy and scipy (none if not found)."""
    handles = []
    roots = site.getsitepackages() + [os.path.dirname(os.path.dirname(np.__file__))]
    for folder, set_name, get_name in _BLAS_SETTERS:
        for root in dict.fromkeys(roots):
            for path in glob.glob(os.path.join(root, folder, "libscipy_openblas*.so*")):
                try:
                    lib = ctypes.CDLL(path)
                    handles.append((getattr(lib, set_name), getattr(lib, get_name)))
                except (OSError, AttributeError):
                    continue
    return handles


@contextmanager
def one_thread():
    """Run the block on one numba thread and one OpenBLAS thread (restored afterwards)."""
    threads = numba.get_num_threads()
    blas = [(setter, getter()) for setter, getter in _openblas_handles()]
    numba.set_num_threads(1)
    for setter, _ in blas:
        setter(1)
    try:
        yield
    finally:
        numba.set_num_threads(threads)
        for setter, old in blas:
            setter(old)
