"""The tables of a sweep: ``results.csv`` (one row per sample) and ``summary.csv`` (per grid point).

``results.csv`` columns: the grid parameters (lists as JSON text), ``seed``, every metric of the
chapter (all chapter metrics are scalars; a list would become ``name_0, name_1, …``), then
``wall_time_s``, ``status`` (``ok`` / ``error``), ``error`` (one line) and ``sample`` (the JSON key
of the sample's grid values and seed, used to skip completed samples on a re-run).  Floats are
written with 17 significant digits, so they read back bit-identical.

``summary.csv`` is tidy: one row per grid point and numeric metric (booleans count as 0/1, so their
mean is a rate) with ``count``, ``failed`` (error samples at that grid point), ``mean``, ``std``
(sample standard deviation, ddof = 1), and the 5 %, 50 % and 95 % quantiles ``q05, q50, q95``
(linear interpolation, numpy's default).
"""

from __future__ import annotations

import csv
import json
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

#: Columns of results.csv that are not grid parameters or metrics, in their order at the end.
TRAILING_COLUMNS = ("wall_time_s", "status", "error", "sample")
RESERVED_COLUMNS = frozenset(TRAILING_COLUMNS) | {"seed"}
QUANTILES = {"q05": 0.05, "q50": 0.50, "q95": 0.95}


def sample_key(point: dict[str, Any]) -> str:
    """Canonical text of a sample's grid values and seed (JSON, keys sorted)."""
    return json.dumps(point, sort_keys=True)


def load_results(path: Path) -> pd.DataFrame:
    """Rows of an earlier (possibly interrupted) sweep, or an empty frame."""
    if not path.exists() or path.stat().st_size == 0:
        return pd.DataFrame(columns=list(TRAILING_COLUMNS))
    frame = pd.read_csv(path, keep_default_na=True)
    if not set(TRAILING_COLUMNS) <= set(frame.columns):
        raise ValueError(f"{path} is not a railpaper sweep table (columns "
                         f"{', '.join(TRAILING_COLUMNS)} missing); use another --out")
    frame["error"] = frame["error"].astype(object).fillna("").astype(str)
    return frame


def _ordered(frame: pd.DataFrame) -> pd.DataFrame:
    trailing = [c for c in TRAILING_COLUMNS if c in frame.columns]
    return frame[[c for c in frame.columns if c not in trailing] + trailing]


def write_csv_atomic(frame: pd.DataFrame, path: Path) -> None:
    """Write a table to ``path`` through a temporary file and a rename (never half a file)."""
    tmp = path.with_name(f".{path.name}.tmp")
    _ordered(frame).to_csv(tmp, index=False, float_format="%.17g", quoting=csv.QUOTE_MINIMAL)
    tmp.replace(path)


def metric_columns(frame: pd.DataFrame, grid_names: list[str]) -> list[str]:
    """Numeric (or boolean) metric columns of a results frame, in table order."""
    skip = set(grid_names) | RESERVED_COLUMNS
    return [c for c in frame.columns if c not in skip
            and (pd.api.types.is_numeric_dtype(frame[c]) or pd.api.types.is_bool_dtype(frame[c]))]


def summarise(frame: pd.DataFrame, grid_names: list[str]) -> pd.DataFrame:
    """Per grid point and metric: count, failed, mean, std, q05, q50, q95 of the ``ok`` samples."""
    columns = grid_names + ["metric", "count", "failed", "mean", "std", *QUANTILES]
    if frame.empty:
        return pd.DataFrame(columns=columns)
    metrics = metric_columns(frame, grid_names) + ["wall_time_s"]
    groups = frame.groupby(grid_names, sort=False, dropna=False) if grid_names else [((), frame)]
    rows = []
    for point, group in groups:
        point = point if isinstance(point, tuple) else (point,)
        ok = group[group.status == "ok"]
        failed = int((group.status != "ok").sum())
        if ok.empty:                                       # every sample of this point failed
            rows.append([*point, "-", 0, failed] + [float("nan")] * (2 + len(QUANTILES)))
        for metric in metrics:
            values = ok[metric].dropna().astype(float).to_numpy() if metric in ok else np.array([])
            if values.size == 0:
                continue
            std = float(np.std(values, ddof=1)) if values.size > 1 else float("nan")
            quantiles = np.quantile(values, list(QUANTILES.values()))
            rows.append([*point, metric, values.size, failed, float(np.mean(values)), std,
                         *map(float, quantiles)])
    return pd.DataFrame(rows, columns=columns)
