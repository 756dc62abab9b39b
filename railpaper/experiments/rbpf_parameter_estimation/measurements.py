"""A user's lateral record for the ``rbpf-parameter-estimation`` chapter (``measurements_csv``)."""

from __future__ import annotations

import numpy as np
import pandas as pd

from railpaper.experiments.base import ParameterError
from railpaper.experiments.rbpf_parameter_estimation.result import LateralRecord
from railpaper.models import lateral_16state

CSV_INPUT = ("ydot_t1_mps", "ydot_t2_mps")


def read_measurements(path: str, dt_s: float) -> LateralRecord:
    """A user's record: columns ``t_s`` and
    :data:`~railpaper.models.lateral_16state.CHANNELS` (SI units), optionally the track lateral
    velocities ``ydot_t1_mps, ydot_t2_mps`` (m/s); uniform time step = ``dt_s`` (s).
    Without the track velocities the filters' process noise assumes input changes of 0.04 m/s
    std."""
    try:
        frame = pd.read_csv(path)
    except (OSError, ValueError) as exc:
        raise ParameterError(f"measurements_csv: cannot read {path!r}: {exc}") from None
    missing = [c for c in ("t_s",) + lateral_16state.CHANNELS if c not in frame.columns]
    if missing:
        raise ParameterError(f"measurements_csv: missing column(s) {missing}; need t_s, "
                             f"{', '.join(lateral_16state.CHANNELS)} and optionally "
                             f"{', '.join(CSV_INPUT)}")
    cols = ["t_s", *lateral_16state.CHANNELS, *[c for c in CSV_INPUT if c in frame.columns]]
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
    if np.any(np.abs(dt - dt_s) > 1e-6 * dt_s + 1e-9):
        raise ParameterError(f"measurements_csv: t_s must step uniformly by dt_s = {dt_s} s")
    has_u = all(c in frame.columns for c in CSV_INPUT)
    u = arr[:, 6:8] if has_u else None
    y = arr[:, 1:6]
    u_var = np.var(np.diff(u, axis=0), axis=0) if has_u else np.full(2, 0.04 ** 2)
    return LateralRecord(seed=None, y=y, u_mps=None if u is None else np.vstack([u[:1], u[:-1]]),
                         du_var_m2ps2=u_var, u_var_m2ps2=u_var)
