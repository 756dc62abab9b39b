"""The findings of a chapter of our own (no paper): ``data/<chapter>/findings.toml``.

A finding is our statement, not a paper's claim, so it has no ledger verdict; it is decided the
same way, on a statistic's 95 % interval over records against a threshold the statement names::

    [failed_damper_found_fast]
    finding = "At 300 km/h, a lost anti-yaw damping is detected within 0.5 s by the exact
               reference in more than 90 % of records"
    metric = "detected_within_0.5s_exact_csaly_0_300kmh"      # the statistic, from metrics.json
    interval = ["..._low", "..._high"]                          # its 95 % interval
    n_samples = "..._n"                                         # records behind it
    threshold = 0.9
    side = "above"                                              # "above" or "below" the threshold
    unit = ""                                                   # optional
    min_samples = 60          # optional: fewer records than this give "undecided" (the size at
                              # which disjoint seed batches agree on the verdict)
    note = "..."              # optional: what changed after the evidence was seen, and when
    operating_point_mtbfa_h = 100   # optional: the mean time between false alarms (h) whose
                              # thresholds the statistic is read at (its metrics end in _at_100h)
    retired = "..."           # optional: when and why the finding was withdrawn (it is then
                              # shown with its last verdict, not judged)
    last_verdict = "..."      # with retired: its verdict in the last default run before

Verdicts: **holds** (the whole interval on the stated side), **fails** (the whole interval on
the other side), **undecided** (the interval straddles the threshold, or fewer records than
``min_samples``).  The page shows the findings in force in a table and, in a collapsed section
below it, every note and every retired finding with its last verdict.  A band test
(tests/pipeline/test_findings.py) checks that every run passing CI gives the same verdict:
the CI bands of the interval's ends sit on one side of the threshold.
"""

from __future__ import annotations

import re

from railpaper.data import DataError, read_toml
from railpaper.pipeline.outputs import chapter_data_dir

FINDING_KEYS = {"finding", "metric", "interval", "n_samples", "threshold", "side", "unit",
                "min_samples", "note", "retired", "last_verdict", "operating_point_mtbfa_h"}
OPTIONAL_KEYS = {"unit", "min_samples", "note", "retired", "last_verdict",
                 "operating_point_mtbfa_h"}
SIDES = ("above", "below")
FINDING_VERDICTS = ("holds", "fails", "undecided")


def read_findings(chapter: str) -> dict[str, dict]:
    """The chapter's findings, each checked (one-line :class:`DataError`)."""
    path = chapter_data_dir(chapter) / "findings.toml"
    rows = read_toml(path)
    for key, row in rows.items():
        unknown = set(row) - FINDING_KEYS
        missing = FINDING_KEYS - OPTIONAL_KEYS - set(row)
        if unknown or missing:
            raise DataError(f"{path}: finding '{key}': "
                            + (f"unknown key '{sorted(unknown)[0]}'" if unknown
                               else f"needs '{sorted(missing)[0]}'"))
        if row["side"] not in SIDES or len(row["interval"]) != 2:
            raise DataError(f"{path}: finding '{key}': side must be 'above' or 'below' and "
                            "interval two metric names")
        if "operating_point_mtbfa_h" in row:
            point = f"_at_{float(row['operating_point_mtbfa_h']):g}h"
            names = [row["metric"], row["n_samples"], *row["interval"]]
            if not all(re.search(re.escape(point) + "(_|$)", name) for name in names):
                raise DataError(f"{path}: finding '{key}': its metrics must be read at its "
                                f"operating point ('{point}' in every name)")
        if ("retired" in row) != (row.get("last_verdict") in FINDING_VERDICTS):
            raise DataError(f"{path}: finding '{key}': a retired finding needs 'retired' (when "
                            f"and why) and 'last_verdict' (one of {', '.join(FINDING_VERDICTS)})")
    return rows


def in_force(chapter: str) -> dict[str, dict]:
    """The chapter's findings that are not retired."""
    return {k: row for k, row in read_findings(chapter).items() if "retired" not in row}


def verdict(row: dict, low: float, high: float, n: float | None = None) -> str:
    """The verdict of a finding whose interval is [low, high] over ``n`` records."""
    if n is not None and n < row.get("min_samples", 0):
        return "undecided"
    t = row["threshold"]
    above = low > t if row["side"] == "above" else high < t
    other = high < t if row["side"] == "above" else low > t
    return "holds" if above else "fails" if other else "undecided"


def verdicts_over_bands(row: dict, bands: dict[str, tuple[float, float]]) -> set[str]:
    """Every verdict a run inside the CI bands could give (one element: the bands decide)."""
    (lo_min, lo_max), (hi_min, hi_max) = (bands[m] for m in row["interval"])
    if "min_samples" in row:
        n_min, n_max = bands[row["n_samples"]]
        if n_max < row["min_samples"]:
            return {"undecided"}
        if n_min < row["min_samples"]:
            return {"undecided"} | verdicts_over_bands(
                {k: v for k, v in row.items() if k != "min_samples"}, bands)
    t, out = row["threshold"], set()
    if row["side"] == "above":
        if lo_max > t:
            out.add("holds")
        if hi_min < t:
            out.add("fails")
        if lo_min <= t <= hi_max:
            out.add("undecided")
    else:
        if hi_min < t:
            out.add("holds")
        if lo_max > t:
            out.add("fails")
        if lo_min <= t <= hi_max:
            out.add("undecided")
    return out


#: The verdict of a finding whose statistic this run did not compute (a speed, fault or
#: detector the user's parameters left out).
NOT_IN_RUN = "not in this run"


def judged(chapter: str, metrics: dict) -> list[dict]:
    """Each finding in force with this run's statistic, interval, sample size and verdict
    (:data:`NOT_IN_RUN`, with no numbers, where the run lacks one of its metrics)."""
    out = []
    for key, row in in_force(chapter).items():
        needed = [row["metric"], *row["interval"], row["n_samples"]]
        if any(m not in metrics for m in needed):
            out.append(dict(row, key=key, value=None, low=None, high=None, n=None,
                            verdict=NOT_IN_RUN))
            continue
        low, high = (metrics[m] for m in row["interval"])
        n = metrics[row["n_samples"]]
        out.append(dict(row, key=key, value=metrics[row["metric"]], low=low, high=high, n=n,
                        verdict=verdict(row, low, high, n)))
    return out


def findings_markdown(chapter: str, metrics: dict) -> str:
    """The findings table of a chapter page (MyST markdown), then a collapsed section with the
    notes of what changed after the evidence was seen and the retired findings."""
    lines = ["| finding | threshold | ours (95 % interval, records) | verdict |",
             "|---|---|---|---|"]
    for f in judged(chapter, metrics):
        unit = f" {f['unit']}" if f.get("unit") else ""
        word = "more than" if f["side"] == "above" else "less than"
        if f["verdict"] == NOT_IN_RUN:
            lines.append(f"| {f['finding']} | {word} {f['threshold']:g}{unit} | — (its speed, "
                         f"fault or detector is not in this run's parameters) | "
                         f"*{NOT_IN_RUN}* |")
            continue
        needs = (f" (needs {f['min_samples']:g} records to be decided)"
                 if f["n"] < f.get("min_samples", 0) else "")
        lines.append(f"| {f['finding']} | {word} {f['threshold']:g}{unit} | "
                     f"{f['value']:.3g} [{f['low']:.3g}, {f['high']:.3g}], n = {f['n']:g} | "
                     f"**{f['verdict']}**{needs} |")
    history = []
    for key, row in read_findings(chapter).items():
        if "retired" in row:
            history.append(f"* **{key}** (retired; last verdict **{row['last_verdict']}**): "
                           f"{row['finding']}. *{row['retired']}*"
                           + (f" {row['note']}" if row.get("note") else ""))
        elif row.get("note"):
            history.append(f"* **{key}**: {row['note']}")
    if history:
        lines += ["", "````{dropdown} Revisions: what changed after the evidence was seen, and "
                  "retired findings", ""] + history + ["````"]
    return "\n".join(lines) + "\n"


__all__ = ["FINDING_VERDICTS", "NOT_IN_RUN", "findings_markdown", "in_force", "judged",
           "read_findings", "verdict", "verdicts_over_bands"]
