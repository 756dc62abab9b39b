"""``railpaper compare DIR_A DIR_B``: two runs of one chapter side by side.

Prints the parameters that differ, every metric whose value differs (with B − A), and each
claim's verdict and evidence in both runs (judged by the same rules as the book's ledger, on each
run's own metrics); ``--out FILE.csv`` writes every metric of both runs.
"""

from __future__ import annotations

import json
from pathlib import Path

import pandas as pd

from railpaper.data import DataError
from railpaper.pipeline.ledger import run_rows


def _run(directory: Path) -> dict:
    path = Path(directory) / "metrics.json"
    if not path.exists():
        raise DataError(f"{path} not found: {directory} holds no chapter run")
    try:
        run = json.loads(path.read_text())
    except (UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise DataError(f"{path}: corrupt metrics.json ({exc})") from None
    if not isinstance(run, dict) or not isinstance(run.get("metrics"), dict) \
            or "chapter" not in run:
        raise DataError(f"{path}: corrupt metrics.json (no chapter or metrics)")
    return run


def _text(value) -> str:
    if isinstance(value, float):
        return f"{value:.6g}"
    if isinstance(value, bool):
        return str(value).lower()
    return "-" if value is None else str(value)


def compare_runs(dir_a: str | Path, dir_b: str | Path) -> dict[str, pd.DataFrame]:
    """Tables ``parameters``, ``metrics`` (all, with ``differs``), ``claims`` of two runs."""
    a, b = _run(Path(dir_a)), _run(Path(dir_b))
    if a["chapter"] != b["chapter"]:
        raise DataError(f"cannot compare a run of {a['chapter']!r} with one of {b['chapter']!r}")
    chapter = a["chapter"]
    pa, pb = a.get("parameters", {}), b.get("parameters", {})
    params = pd.DataFrame([(k, _text(pa.get(k)), _text(pb.get(k))) for k in sorted(set(pa) | set(pb))
                           if pa.get(k) != pb.get(k)], columns=["parameter", "A", "B"])
    ma, mb = a["metrics"], b["metrics"]
    rows = []
    for k in sorted(set(ma) | set(mb)):
        va, vb = ma.get(k), mb.get(k)
        numeric = all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in (va, vb))
        rows.append((k, va, vb, vb - va if numeric else None, va != vb))
    metrics = pd.DataFrame(rows, columns=["metric", "A", "B", "B_minus_A", "differs"])
    ra, rb = run_rows(chapter, dir_a)[0], run_rows(chapter, dir_b)[0]
    claims = pd.DataFrame([(x.claim, x.reading or "as stated", x.verdict, y.verdict, x.ours, y.ours)
                           for x, y in zip(ra, rb)],
                          columns=["claim", "reading", "verdict A", "verdict B", "ours A", "ours B"])
    return {"chapter": chapter, "parameters": params, "metrics": metrics, "claims": claims}


def _table(frame: pd.DataFrame) -> str:
    cells = [list(frame.columns)] + [[_text(v) for v in row] for row in frame.itertuples(index=False)]
    widths = [max(len(r[i]) for r in cells) for i in range(len(cells[0]))]
    return "\n".join("  ".join(c.ljust(w) for c, w in zip(r, widths)).rstrip() for r in cells)


def format_comparison(result: dict, dir_a, dir_b) -> str:
    """Plain-text report of :func:`compare_runs`."""
    params, metrics, claims = result["parameters"], result["metrics"], result["claims"]
    differ = metrics[metrics.differs].drop(columns="differs")
    lines = [f"chapter {result['chapter']}:  A = {dir_a}   B = {dir_b}", "",
             "parameters that differ:" if len(params) else "parameters: identical"]
    if len(params):
        lines += [_table(params)]
    lines += ["", f"metrics: {len(differ)} of {len(metrics)} differ"]
    if len(differ):
        lines += [_table(differ)]
    changed = int((claims["verdict A"] != claims["verdict B"]).sum())
    lines += ["", f"claims: {changed} of {len(claims)} verdicts differ", _table(claims)]
    return "\n".join(lines)
