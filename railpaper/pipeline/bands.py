"""CI tolerance bands from disjoint seed batches (``railpaper bands``).

A chapter's default run decides its claims on Monte Carlo samples with seeds ``seed, seed+1, …``.
Batch k re-runs the whole chapter notebook (papermill, so the metrics are exactly the ones a
default run writes) with ``seed = k · stride``; with fewer than ``stride`` samples per run the
batches share no seed.  The band of a metric is the observed [min, max] over the batches, widened
by ``widen`` × the range on each side (a point band when every batch agrees), and the widening
never crosses a threshold of a claim rule that reads the metric: it stops halfway between the
observed extreme and the threshold.  If the observed range itself straddles a threshold, the
band says so in its ``source`` and ``tests/pipeline/test_claims_bands.py`` will fail: the verdict is not
stable at this sample size, which is a finding, not something to tune away.
"""

from __future__ import annotations

import json
import math
import re
import sys
from pathlib import Path

from railpaper.data import read_toml
from railpaper.pipeline.chapters import chapter_spec, run_chapter
from railpaper.pipeline.claim_rules import condition_thresholds, rule_metrics
from railpaper.pipeline.findings import in_force
from railpaper.pipeline.outputs import chapter_data_dir, claims

DEFAULT_STRIDE = 1000
#: The least half-width of a float metric's band: relative 1e-9 of its size, and at least 1e-9
#: absolute.  A statistic that every batch gives to the last bit (456.39365619408477 km/h, a
#: rank correlation of 0.8 stored as 0.7999999999999999) rounds differently on another CPU's BLAS
#: kernels, and a residual at rounding level (3e-13 here, 5e-13 there) has no last bit to keep.
#: Integer-valued metrics (counts, ranks) keep exact bands.
RELATIVE_FLOOR = 1e-9
ABSOLUTE_FLOOR = 1e-9
FLOOR_NOTE = "at least ±max(1e-9, 1e-9·|value|) for rounding on another CPU"


def rule_thresholds(chapter: str) -> dict[str, list[float]]:
    """``{metric: [thresholds]}``: the constants a claim rule compares each metric with (for a
    chapter of our own: each finding's threshold, for both ends of its interval)."""
    out: dict[str, list[float]] = {}
    if not chapter_spec(chapter).paper:
        for row in in_force(chapter).values():
            for metric in row["interval"]:
                out.setdefault(metric, []).append(float(row["threshold"]))
        return out
    for row in claims(chapter).values():
        for case in row.get("cases", []):
            for cond in case.get("when", []):
                # a constant only: a reference metric moves, a flag or text is no threshold
                ref = None if "reference" in cond else cond.get("value", row.get("paper_value"))
                constant = cond["test"] == "range" or (
                    isinstance(ref, (int, float)) and not isinstance(ref, bool))
                ts = condition_thresholds(cond, row, {}) if constant else []
                for metric in cond.get("metrics", []):
                    out.setdefault(metric, []).extend(float(t) for t in ts)
        if "min_samples" in row:
            out.setdefault(row["n_samples"], []).append(row["min_samples"] - 0.5)
    return out


def band(values: list[float], thresholds: list[float], widen: float = 0.25
         ) -> tuple[float, float, str]:
    """(low, high, note) for one metric's batch values (see the module docstring)."""
    lo, hi = min(values), max(values)
    pad = max(widen * (hi - lo), rounding_floor(values))
    return _capped(lo, hi, lo - pad, hi + pad, thresholds)


def rounding_floor(values: list[float]) -> float:
    """The least half-width of a band (:data:`RELATIVE_FLOOR`, :data:`ABSOLUTE_FLOOR`); 0 for
    integer-valued metrics."""
    if all(float(v).is_integer() for v in values):
        return 0.0
    return max(ABSOLUTE_FLOOR, RELATIVE_FLOOR * max(abs(v) for v in values))


def _capped(lo: float, hi: float, low: float, high: float, thresholds: list[float]
            ) -> tuple[float, float, str]:
    """Band [low, high] around the observed [lo, hi], each widening stopped halfway to a rule
    threshold outside [lo, hi]; the note says where."""
    notes = []
    for t in thresholds:
        if lo <= t <= hi and (lo != hi or t == lo):
            notes.append(f"observed range straddles the rule threshold {t:g}")
        elif t < lo and low <= t:
            low = (lo + t) / 2 if (lo + t) / 2 > t else lo        # adjacent floats: no room
            notes.append(f"widening capped halfway to the threshold {t:g}")
        elif t > hi and high >= t:
            high = (hi + t) / 2 if (hi + t) / 2 < t else hi
            notes.append(f"widening capped halfway to the threshold {t:g}")
    return low, high, "; ".join(dict.fromkeys(notes))


def refloor(chapter: str, quick: bool) -> dict[str, tuple[float, float, str]]:
    """The chapter's stored bands of one mode, each widened to at least its rounding floor
    (:func:`rounding_floor` of its own ends; capped at rule thresholds as :func:`band` is),
    without re-running any batch: for bands written before the floor existed."""
    mode = "quick" if quick else "full"
    stored = read_toml(chapter_data_dir(chapter) / "tolerances.toml").get(mode, {})
    thresholds = rule_thresholds(chapter)
    out = {}
    for metric, entry in stored.items():
        lo, hi, source = entry.get("min", -math.inf), entry.get("max", math.inf), entry["source"]
        if not (math.isfinite(lo) and math.isfinite(hi)):
            out[metric] = (lo, hi, source)
            continue
        pad = rounding_floor([lo, hi])
        mid = (lo + hi) / 2
        low, high, note = _capped(lo, hi, min(lo, mid - pad), max(hi, mid + pad),
                                  thresholds.get(metric, []))
        if (low, high) != (lo, hi) and FLOOR_NOTE not in source:
            source += f"; {FLOOR_NOTE}" + (f" ({note})" if note else "")
        out[metric] = (low, high, source)
    return out


def _batch_metrics(chapter: str, quick: bool, seed: int, work: Path) -> dict:
    out = work / f"seed-{seed}"
    path = out / "metrics.json"
    params = chapter_spec(chapter).resolve({"seed": seed}, quick).as_dict()
    if path.exists():
        run = json.loads(path.read_text())
        if run.get("parameters") == params:                # a finished batch: resume
            return _values(out)
    run_chapter(chapter, {"seed": seed}, quick, out, progress=False, page=False)
    return _values(out)


def _values(out: Path) -> dict:
    values = {}
    timings = out / "timings.json"
    if timings.exists():
        values.update(json.loads(timings.read_text()).get("metrics", {}))
    values.update(json.loads((out / "metrics.json").read_text())["metrics"])
    return values


def compute_bands(chapter: str, quick: bool, batches: int = 10, stride: int = DEFAULT_STRIDE,
                  work_dir: str | Path | None = None, metrics: list[str] | None = None,
                  widen: float = 0.25) -> dict[str, tuple[float, float, str]]:
    """Bands of ``metrics`` (default: every metric a claim rule reads, and every metric already
    banded for this mode; for a chapter of our own, every metric of its metrics.json) from
    ``batches``
    chapter runs with seeds 0, stride, 2·stride, …"""
    if batches < 2:
        raise ValueError(f"bands need at least 2 batches, got {batches}")
    mode = "quick" if quick else "full"
    work = Path(work_dir or f"runs/bands-{chapter}-{mode}")
    if metrics is None:
        tolerances = read_toml(chapter_data_dir(chapter) / "tolerances.toml").get(mode, {})
        metrics = list(tolerances)
        for row in claims(chapter).values() if chapter_spec(chapter).paper else ():
            metrics += rule_metrics(row)
    seeds = [k * stride for k in range(batches)]
    runs = []
    for i, seed in enumerate(seeds):
        print(f"railpaper: bands of {chapter} ({mode}): batch {i + 1}/{batches}, seed {seed}",
              file=sys.stderr, flush=True)
        runs.append(_batch_metrics(chapter, quick, seed, work))
    if not chapter_spec(chapter).paper and not list(metrics):
        # a chapter of our own: every metric of metrics.json (not the wall clock of timings.json)
        first = json.loads((work / f"seed-{seeds[0]}" / "metrics.json").read_text())
        metrics = sorted(first["metrics"])
    metrics = list(dict.fromkeys(metrics))
    thresholds = rule_thresholds(chapter)
    out = {}
    seed_text = f"{batches} disjoint seed batches (seed = {seeds[0]}, {seeds[1]}, …, {seeds[-1]})"
    for metric in metrics:
        values = [r[metric] for r in runs if metric in r]
        if len(values) < len(runs):
            print(f"railpaper: {metric}: missing in {len(runs) - len(values)} batches; no band",
                  file=sys.stderr)
            continue
        values = [float(v) for v in values]
        low, high, note = band(values, thresholds.get(metric, []), widen)
        source = (f"{seed_text}: observed {min(values):.6g} to {max(values):.6g}, widened "
                  f"{widen:.0%} of the range" + (f"; {note}" if note else ""))
        out[metric] = (low, high, source)
    return out


def _number(x: float) -> str:
    if math.isinf(x):
        return "inf" if x > 0 else "-inf"
    return repr(float(x)) if not float(x).is_integer() else repr(int(x)) if abs(x) < 1e15 \
        else repr(float(x))


def write_bands(chapter: str, quick: bool, bands: dict[str, tuple[float, float, str]],
                path: str | Path | None = None) -> Path:
    """Write bands as a tolerances file: this mode replaced, the other mode and meta kept.

    ``path`` defaults to the chapter's ``data/<chapter>/tolerances.toml``.
    """
    target = Path(path) if path else chapter_data_dir(chapter) / "tolerances.toml"
    existing = read_toml(target) if target.exists() else \
        read_toml(chapter_data_dir(chapter) / "tolerances.toml")
    mode = "quick" if quick else "full"
    doc = {"full": existing.get("full", {}), "quick": existing.get("quick", {})}
    doc[mode] = {m: {"min": lo, "max": hi, "source": src} for m, (lo, hi, src) in bands.items()}
    lines = [f"# CI tolerance bands of chapter {chapter} for its default parameters; generated by",
             "# `railpaper bands` from disjoint seed batches (see railpaper/pipeline/bands.py);",
             "# each band's source says how it was set.",
             "[meta]", 'parameters = "defaults"', ""]
    for m in ("full", "quick"):
        for metric, entry in doc[m].items():
            bare = re.fullmatch(r"[A-Za-z0-9_-]+", metric)     # else a quoted TOML key
            lines.append(f"[{m}.{metric if bare else json.dumps(metric)}]")
            for key in ("min", "max"):
                if key in entry:
                    lines.append(f"{key} = {_number(entry[key])}")
            lines.append(f"source = {json.dumps(entry['source'], ensure_ascii=False)}")
            lines.append("")
    target.write_text("\n".join(lines))
    return target
