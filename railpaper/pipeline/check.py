"""Checking a run's metrics.json against the chapter's CI tolerances (data/<chapter>/tolerances.toml).

Tolerance file::

    [meta]
    parameters = "defaults"
    [full.convergence_time_s_60kmh]
    min = 0.05
    max = 0.25
    source = "seeds 0-9: 0.09-0.16 s, band widened by 50 %"
    [quick.convergence_time_s_60kmh]
    ...

A metric outside its band fails the check; an unreproduced paper claim never does (claims are
shown beside the metrics for information).  A band for a metric that ``metrics.json`` lacks is
checked against ``timings.json`` (wall-clock evidence, e.g. a time ratio).  A run whose parameters differ from the defaults the
tolerances were set for is "not comparable".
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

from railpaper.data import DataError, read_toml
from railpaper.pipeline.chapters import chapter_spec, default_output_dir
from railpaper.pipeline.claim_rules import rule_metrics
from railpaper.pipeline.decisive import check_provenance
from railpaper.pipeline.declarations import check_registry, load_declarations, load_registry
from railpaper.pipeline.findings import in_force
from railpaper.pipeline.outputs import chapter_data_dir, claims
from railpaper.rulebook import Vocabulary


@dataclass
class CheckRow:
    chapter: str
    metric: str
    value: object
    band: str
    status: str
    claim: str = ""


def load_tolerances(chapter: str) -> dict:
    """Tolerance bands ``{"full": {metric: (min, max, source)}, "quick": {...}}``."""
    path = chapter_data_dir(chapter) / "tolerances.toml"
    document = read_toml(path)
    unknown = set(document) - {"meta", "full", "quick"}
    if unknown:
        raise DataError(f"{path}: unknown key '{sorted(unknown)[0]}' (expected meta, full, quick)")
    bands = {}
    for mode in ("full", "quick"):
        bands[mode] = {}
        for metric, band in document.get(mode, {}).items():
            if set(band) - {"min", "max", "source"} or "source" not in band:
                raise DataError(f"{path}: key '{mode}.{metric}': needs min and/or max and a source")
            bands[mode][metric] = (band.get("min", float("-inf")), band.get("max", float("inf")),
                                   band["source"])
    return bands


def _claims_by_metric(chapter: str) -> dict[str, str]:
    out = {}
    if not chapter_spec(chapter).paper:                  # a chapter of our own: its findings
        for key, row in in_force(chapter).items():
            for metric in [row["metric"], *row["interval"]]:
                out.setdefault(metric, f"finding '{key}'")
        return out
    for table in claims(chapter).values():
        text = table.get("claim", "")
        if table.get("reading"):
            text += f" [{table['reading']}]"
        if "paper_value" in table:
            text += f" (paper: {table['paper_value']} {table.get('unit', '')})".rstrip()
        for metric in rule_metrics(table):
            out.setdefault(metric, text)
    return out


def read_metrics(path: Path, chapter: str) -> dict:
    """A run's metrics.json, or a one-line :class:`DataError` if it is not one of ``chapter``."""
    try:
        run = json.loads(path.read_text())
    except (UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise DataError(f"{path}: corrupt metrics.json ({exc}); re-run the chapter") from None
    if not isinstance(run, dict) or not isinstance(run.get("metrics"), dict):
        raise DataError(f"{path}: corrupt metrics.json (no 'metrics' table); re-run the chapter")
    if run.get("chapter") != chapter:
        raise DataError(f"{path} holds a run of {run.get('chapter')!r}, not of {chapter!r}")
    return run


def registry_rows(chapter: str) -> list[CheckRow]:
    """FAIL rows for the chapter's declarations the registry does not hold as they are now
    (a revision not registered) and for stored decisive evidence that does not match its
    provenance or the chapter's settings."""
    vocabulary = Vocabulary.load()
    problems = check_registry(load_declarations(chapter, vocabulary), vocabulary, load_registry())
    problems += check_provenance(chapter)
    return [CheckRow(chapter, "registry", "-", "-", f"FAIL: {line}") for line in problems]


def check_chapter(chapter: str, out_dir: str | Path | None = None) -> list[CheckRow]:
    """Rows of the check table for one chapter's last run, after :func:`registry_rows`."""
    registry = registry_rows(chapter)
    return registry + _check_run(chapter, out_dir)


def _check_run(chapter: str, out_dir: str | Path | None = None) -> list[CheckRow]:
    spec = chapter_spec(chapter)
    path = Path(out_dir or default_output_dir(chapter)) / "metrics.json"
    if not path.exists():
        if out_dir is not None:                   # the user named a run directory: it must hold one
            raise DataError(f"{path} not found: no run of {chapter} in {out_dir}")
        return [CheckRow(chapter, "-", "-", "-", f"no run: {path} missing")]
    run = read_metrics(path, chapter)
    quick = bool(run.get("quick"))
    if run.get("parameters") != spec.resolve({}, quick).as_dict():
        return [CheckRow(chapter, "-", "-", "-",
                         "not comparable: parameters differ from the defaults of the tolerances")]
    bands = load_tolerances(chapter)["quick" if quick else "full"]
    claim_text = _claims_by_metric(chapter)
    timings_path = path.with_name("timings.json")
    values = dict(json.loads(timings_path.read_text()).get("metrics", {})) \
        if timings_path.exists() else {}
    values.update(run["metrics"])
    rows = []
    for metric, (low, high, _source) in sorted(bands.items()):
        value = values.get(metric)
        band = f"[{low:g}, {high:g}]"
        if value is None:
            status = "FAIL (missing)"
        elif isinstance(value, (bool, int, float)):
            status = "ok" if low <= float(value) <= high else "FAIL"
        else:
            status = "FAIL (not a number)"
        rows.append(CheckRow(chapter, metric, value, band, status, claim_text.get(metric, "")))
    return rows


def format_rows(rows: list[CheckRow]) -> str:
    """A plain-text table of check rows."""
    header = ("chapter", "metric", "value", "band", "status", "paper claim")
    table = [header] + [(r.chapter, r.metric, f"{r.value:.6g}" if isinstance(r.value, float)
                         else str(r.value), r.band, r.status, r.claim) for r in rows]
    widths = [max(len(row[i]) for row in table) for i in range(len(header) - 1)]
    lines = ["  ".join(c.ljust(w) for c, w in zip(row[:-1], widths)) + "  " + row[-1]
             for row in table]
    return "\n".join(lines)
