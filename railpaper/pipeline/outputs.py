"""Writing a chapter run's outputs: metrics.json, timings.json, time series, figures, tables.

Called from the chapter notebooks (the notebook writes its own outputs) and from sweeps.
"""

from __future__ import annotations

import csv
import json
from pathlib import Path
from typing import Any

import pandas as pd

from railpaper.data import read_toml

from railpaper.paths import DATA_DIR
from railpaper.experiments.base import ChapterResult, ChapterSettings, ChapterSpec, check_metrics


def _json_ready(value: Any) -> Any:
    if isinstance(value, dict):
        return {k: _json_ready(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_json_ready(v) for v in value]
    if hasattr(value, "item"):
        return value.item()
    return value


def write_outputs(out_dir: str | Path, spec: ChapterSpec, settings: ChapterSettings, quick: bool,
                  result: ChapterResult) -> None:
    """Write ``metrics.json``, ``timings.json``, ``timeseries.csv``, extra tables and extra text
    files (:attr:`ChapterResult.extra_files`, verbatim) into out_dir.

    ``metrics.json`` = ``{"chapter", "parameters", "quick", "metrics"}`` with keys sorted, so the
    same parameters and seed give a byte-identical file.  Floats in CSV files are written with
    ``repr`` precision (round-trip exact).
    """
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    base = {"chapter": spec.name, "parameters": _json_ready(settings.as_dict()), "quick": bool(quick)}
    metrics = dict(base, metrics=check_metrics(result.metrics))
    (out / "metrics.json").write_text(json.dumps(metrics, indent=2, sort_keys=True) + "\n")
    timings = dict(base, metrics={k: float(v) for k, v in result.timings.items()})
    (out / "timings.json").write_text(json.dumps(timings, indent=2, sort_keys=True) + "\n")
    tables = dict(result.extra_tables)
    if result.timeseries is not None:
        tables["timeseries"] = result.timeseries
    for name, frame in tables.items():
        frame.to_csv(out / f"{name}.csv", index=False, float_format="%.17g",
                     quoting=csv.QUOTE_MINIMAL)
    for name, text in result.extra_files.items():
        (out / name).write_text(text)


def save_figure(fig, out_dir: str | Path, name: str) -> Path:
    """Save a matplotlib figure as ``out_dir/name.png`` (150 dpi) and return the path."""
    path = Path(out_dir) / f"{name}.png"
    fig.savefig(path, dpi=150, bbox_inches="tight")
    return path


def parameter_table(spec: ChapterSpec, parameters: dict) -> pd.DataFrame:
    """The run's parameters with their meaning, marking those that differ from the defaults."""
    rows = [(p.name, parameters[p.name], "" if parameters[p.name] == p.default else "changed",
             p.meaning) for p in spec.parameters]
    return pd.DataFrame(rows, columns=["parameter", "value", "vs default", "meaning"])


def chapter_data_dir(chapter: str) -> Path:
    """``data/<chapter>/``: parameters, claims, tolerances and errata of one chapter."""
    return DATA_DIR / chapter


def errata_table(chapter: str) -> pd.DataFrame:
    """The chapter's errata (``data/<chapter>/errata.csv``: location, printed, correction, reason)."""
    return pd.read_csv(chapter_data_dir(chapter) / "errata.csv")


def claims(chapter: str) -> dict[str, dict]:
    """The chapter's paper claims (``data/<chapter>/claims.toml``), one table per claim."""
    return read_toml(chapter_data_dir(chapter) / "claims.toml")
