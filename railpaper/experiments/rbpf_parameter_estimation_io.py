"""A user's lateral record for the ``rbpf-parameter-estimation`` chapter (``measurements_csv``),
and the one-thread context its runs use on a shared machine."""

from __future__ import annotations

from contextlib import contextmanager

import numpy as np
import pandas as pd

from railpaper.experiments.base import ParameterError
from railpaper.experiments.rbpf_parameter_estimation_result import LateralRecord
from railpaper.models import lateral_16state as L

CSV_INPUT = ("ydot_t1_mps", "ydot_t2_mps")


def read_measurements(path: str, p: dict) -> LateralRecord:
    """A user's record: columns ``t_s`` and :data:`L.CHANNELS` (SI units), optionally the track
    lateral velocities ``ydot_t1_mps, ydot_t2_mps`` (m/s); uniform time step = ``dt_s``.  Without
    the track velocities the filters' process noise assumes input changes of 0.04 m/s std."""
    try:
        frame = pd.read_csv(path)
    except (OSError, ValueError) as exc:
        raise ParameterError(f"measurements_csv: cannot read {path!r}: {exc}") from None
    missing = [c for c in ("t_s",) + L.CHANNELS if c not in frame.columns]
    if missing:
        raise ParameterError(f"measurements_csv: missing column(s) {missing}; need t_s, "
                             f"{', '.join(L.CHANNELS)} and optionally {', '.join(CSV_INPUT)}")
    cols = ["t_s", *L.CHANNELS, *[c for c in CSV_INPUT if c in frame.columns]]
    arr = frame[cols].apply(pd.to_numeric, errors="coerce").to_numpy(float)
    if len(arr) < 10:
        raise ParameterError(f"measurements_csv: need >= 10 rows, got {len(arr)}")
    bad = ~np.isfinite(arr)
    if bad.any():
        row, col = np.argwhere(bad)[0]
        raise ParameterError(f"measurements_csv: column {cols[col]} has a NaN, infinite or "
                             f"non-numeric value in data row {row + 1}")
    dt = np.diff(arr[:, 0])
    if np.any(dt <= 0):
        raise ParameterError(f"measurements_csv: t_s is not increasing (data row "
                             f"{int(np.argmax(dt <= 0)) + 2})")
    if np.any(np.abs(dt - p["dt_s"]) > 1e-6 * p["dt_s"] + 1e-9):
        raise ParameterError(f"measurements_csv: t_s must step uniformly by dt_s = {p['dt_s']} s")
    has_u = all(c in frame.columns for c in CSV_INPUT)
    u = arr[:, 6:8] if has_u else None
    y = arr[:, 1:6]
    u_var = np.var(np.diff(u, axis=0), axis=0) if has_u else np.full(2, 0.04 ** 2)
    return LateralRecord(seed=None, y=y, u_mps=None if u is None else np.vstack([u[:1], u[:-1]]),
                         du_var_m2ps2=u_var, u_var_m2ps2=u_var)


# ----------------------------------------------------------------------------- threads
_BLAS_SETTERS = (("numpy.libs", "scipy_openblas_set_num_threads64_",
                  "scipy_openblas_get_num_threads64_"),
                 ("scipy.libs", "scipy_openblas_set_num_threads", "scipy_openblas_get_num_threads"))


def _openblas_handles() -> list:
    """(set, get) of the OpenBLAS libraries bundled with numpy and scipy (none if not found)."""
    import ctypes
    import glob
    import os
    import site

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
    """Run the block on one numba thread and one OpenBLAS thread (restored afterwards).

    On a 2-core machine busy with other processes, threaded small-matrix work waits for its
    threads most of the time: at load 7-9 the lateral EKF (scipy ``expm`` of 36 x 36 stacks)
    took 11.7 s for 600 steps with OpenBLAS threads and 0.9 s on one, and the paper-scheme
    RBPF (numba-parallel Kalman bank and ZOH) about twice as long with two numba threads.
    """
    import numba

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
