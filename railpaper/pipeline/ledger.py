"""The claims ledger: every number the papers state, ours beside it, and a verdict.

Each chapter's ``data/<chapter>/claims.toml`` holds, per claim, the paper's statement and how a
run decides it (nothing here is specific to a claim)::

    [convergence_time]
    claim = "the observer converges after about 0.15 s"
    source = "paper 000, abstract"
    paper_value = 0.15
    unit = "s"
    metrics = ["convergence_time_s_60kmh", ...]          # shown by the chapter and `railpaper check`
    primary = "convergence_time_s_60kmh"                  # "ours" in the ledger
    justification = "why this rule and tolerance (paper text, our numbers)"
    [[convergence_time.cases]]                            # tried in order; the first that holds
    verdict = "reproduced"                                # reproduced | differs
    reason = "... {convergence_time_s_60kmh:.3f} s ..."   # str.format over the run's metrics
    when = [{test = "within_abs", metrics = [...], tolerance = 0.05}]
    [convergence_time.otherwise]                          # verdict "differs" unless stated
    reason = "..."

Tests of a condition (all ``metrics`` of it must pass; the reference is ``reference`` (a metric),
else ``value``, else the claim's ``paper_value``):

* ``within_abs``: ``|m - ref| <= tolerance``;
* ``within_factor``: ``m > 0`` and ``ref / factor <= m <= ref * factor``;
* ``range``: ``min <= m <= max`` and ``above < m < below`` (any of the four bounds);
* ``equals``: ``m == ref``;
* ``increasing``: the metrics, in order, strictly increase (``strict = false``: never decrease).

A run whose parameters differ from the chapter's defaults is "not comparable"; a claim whose
metrics the run lacks is "missing".  Metrics are looked up in ``metrics.json``, then in
``timings.json`` (wall-clock claims).
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import pandas as pd

from railpaper.data import DataError, read_toml
from railpaper.pipeline.chapters import chapter_spec

VERDICTS = ("reproduced", "differs", "not comparable (non-default parameters)", "missing")
TESTS = ("within_abs", "within_factor", "range", "equals", "increasing")
LEDGER_COLUMNS = ["chapter", "claim", "source", "paper", "ours", "verdict", "reason"]


@dataclass
class LedgerRow:
    """One paper claim beside our number."""

    chapter: str
    key: str
    claim: str
    source: str
    paper: str
    ours: str
    verdict: str
    reason: str


def claims_label(chapter: str) -> str:
    """The MyST target of a chapter's claims section (``(claims-<chapter>)=`` in its notebook)."""
    return f"claims-{chapter}"


def _referenced(claim: dict) -> list[str]:
    names = [claim["primary"]] if "primary" in claim else []
    for case in claim.get("cases", []):
        for cond in case.get("when", []):
            names += list(cond.get("metrics", []))
            if "reference" in cond:
                names.append(cond["reference"])
    return list(dict.fromkeys(names))


def _check_claim(key: str, claim: dict, where: str) -> None:
    """Raise DataError (one line) for a claim without a usable verdict rule."""
    if "primary" not in claim or not claim.get("cases"):
        raise DataError(f"{where}: claim '{key}' needs 'primary' and at least one [[cases]]")
    for case in claim["cases"]:
        if case.get("verdict") not in ("reproduced", "differs") or "reason" not in case:
            raise DataError(f"{where}: claim '{key}': each case needs verdict "
                            "(reproduced or differs) and a reason")
        for cond in case.get("when", []):
            if cond.get("test") not in TESTS:
                raise DataError(f"{where}: claim '{key}': unknown test {cond.get('test')!r} "
                                f"(expected one of {', '.join(TESTS)})")
            if not cond.get("metrics"):
                raise DataError(f"{where}: claim '{key}': a condition needs 'metrics'")


def _holds(cond: dict, claim: dict, values: dict) -> bool:
    xs = [values[name] for name in cond["metrics"]]
    test = cond["test"]
    if test == "increasing":
        pairs = list(zip(xs, xs[1:]))
        return all(b > a if cond.get("strict", True) else b >= a for a, b in pairs)
    if test == "range":
        return all(cond.get("min", -math.inf) <= x <= cond.get("max", math.inf)
                   and cond.get("above", -math.inf) < x < cond.get("below", math.inf) for x in xs)
    ref = values[cond["reference"]] if "reference" in cond else cond.get(
        "value", claim.get("paper_value"))
    if test == "equals":
        return all(x == ref for x in xs)
    if test == "within_abs":
        return all(abs(x - ref) <= cond["tolerance"] for x in xs)
    factor = cond["factor"]
    return all(x > 0 and ref / factor <= x <= ref * factor for x in xs)


def _format(template: str, values: dict) -> str:
    try:
        return template.format_map(values)
    except (KeyError, ValueError, IndexError, TypeError):
        return template


def _show(value, unit: str = "") -> str:
    unit = "" if unit == "1" else unit[2:] if unit.startswith("1 (") else unit
    if isinstance(value, bool):
        text = str(value).lower()
    elif isinstance(value, float):
        text = f"{value:.4g}"
    else:
        text = str(value)
    return f"{text} {unit}".strip()


def judge(claim: dict, values: dict) -> tuple[str, str]:
    """Verdict and reason of one claim on a run's metrics (no parameter check here).

    Returns
    -------
    tuple[str, str]
        ``("missing", ...)`` when a referenced metric is absent, else the first case that holds,
        else the claim's ``otherwise`` (verdict "differs" unless it says otherwise).
    """
    absent = [name for name in _referenced(claim) if name not in values]
    if absent:
        return "missing", f"the run has no metric {absent[0]}"
    for case in claim["cases"]:
        if all(_holds(cond, claim, values) for cond in case.get("when", [])):
            return case["verdict"], _format(case["reason"], values)
    fallback = claim.get("otherwise", {})
    return fallback.get("verdict", "differs"), _format(fallback.get("reason", ""), values)


def _changed_parameters(run: dict, defaults: dict) -> list[str]:
    params = run.get("parameters", {})
    return sorted(k for k in set(params) | set(defaults) if params.get(k) != defaults.get(k))


def chapter_rows(chapter: str, claims: dict[str, dict], run: dict | None,
                 timings: dict | None = None,
                 defaults: Callable[[bool], dict] | None = None) -> list[LedgerRow]:
    """The ledger rows of one chapter.

    Parameters
    ----------
    chapter : str
        Chapter name.
    claims : dict
        The chapter's ``claims.toml`` (checked: each claim needs ``primary`` and ``cases``).
    run : dict or None
        The run's ``metrics.json`` (None: no run).
    timings : dict, optional
        The run's ``timings.json``; its metrics are used for keys ``metrics.json`` lacks.
    defaults : callable, optional
        ``defaults(quick) -> parameters`` of a default run; default: the chapter's SPEC.
    """
    defaults = defaults or (lambda quick: chapter_spec(chapter).resolve({}, quick))
    values = dict((timings or {}).get("metrics", {}))
    values.update((run or {}).get("metrics", {}))
    changed = _changed_parameters(run, defaults(bool(run.get("quick")))) if run else []
    rows = []
    for key, claim in claims.items():
        _check_claim(key, claim, f"data/{chapter}/claims.toml")
        paper = _show(claim["paper_value"], claim.get("unit", "")) if "paper_value" in claim \
            else "(no number)"
        primary = claim["primary"]
        ours = _show(values[primary], claim.get("primary_unit", claim.get("unit", ""))) \
            if primary in values else "-"
        if run is None:
            verdict, reason = "missing", "the chapter has not been run"
        else:
            verdict, reason = judge(claim, values)
            if changed and verdict != "missing":
                verdict = VERDICTS[2]
                reason = f"run with non-default {', '.join(changed)}; " + reason
        rows.append(LedgerRow(chapter, key, claim["claim"], claim.get("source", ""), paper, ours,
                              verdict, reason))
    return rows


def _read_json(path: Path) -> dict | None:
    return json.loads(path.read_text()) if path.exists() else None


def build_ledger(chapters: list[str], chapters_dir: str | Path, data_dir: str | Path | None = None,
                 defaults: Callable[[str, bool], dict] | None = None) -> list[LedgerRow]:
    """Ledger rows of several chapters from ``chapters_dir/<chapter>/{metrics,timings}.json``.

    ``data_dir`` holds ``<chapter>/claims.toml`` (default: the repository's ``data/``);
    ``defaults(chapter, quick)`` gives a default run's parameters (default: the chapter's SPEC).
    """
    from railpaper.data import DATA_DIR
    data = Path(data_dir) if data_dir else DATA_DIR
    rows = []
    for chapter in chapters:
        out = Path(chapters_dir) / chapter
        chapter_defaults = (lambda quick, c=chapter: defaults(c, quick)) if defaults else None
        rows += chapter_rows(chapter, read_toml(data / chapter / "claims.toml"),
                             _read_json(out / "metrics.json"), _read_json(out / "timings.json"),
                             chapter_defaults)
    return rows


def ledger_frame(rows: list[LedgerRow]) -> pd.DataFrame:
    """The ledger as a table (columns ``LEDGER_COLUMNS``), e.g. for a chapter notebook."""
    return pd.DataFrame([[getattr(r, c) for c in LEDGER_COLUMNS] for r in rows],
                        columns=LEDGER_COLUMNS)


def _cell(text: str) -> str:
    return str(text).replace("|", "\\|").replace("\n", " ").replace("$", "\\$")


def _summary(rows: list[LedgerRow]) -> str:
    counts = {v: sum(r.verdict == v for r in rows) for v in VERDICTS}
    return ", ".join(f"{n} {v}" for v, n in counts.items() if n)


def ledger_markdown(rows: list[LedgerRow], titles: dict[str, str] | None = None) -> str:
    """MyST tables of the ledger, one per chapter; every reason links to the chapter's claims."""
    titles = titles or {}
    lines = [f"{len(rows)} claims: {_summary(rows)}."]
    for chapter in dict.fromkeys(r.chapter for r in rows):
        mine = [r for r in rows if r.chapter == chapter]
        link = f"{{ref}}`{_cell(titles.get(chapter, chapter))} <{claims_label(chapter)}>`"
        lines += ["", f"**{link}** — {_summary(mine)}", "",
                  "| paper claim | paper | ours | verdict | why |", "|---|---|---|---|---|"]
        for r in mine:
            lines.append(f"| {_cell(r.claim)} ({_cell(r.source)}) | {_cell(r.paper)} | "
                         f"{_cell(r.ours)} | **{r.verdict}** | {_cell(r.reason)} "
                         f"({{ref}}`chapter <{claims_label(chapter)}>`) |")
    return "\n".join(lines) + "\n"


def ledger_counts(rows: list[LedgerRow]) -> dict[str, dict[str, int]]:
    """``{chapter: {verdict: count}}``."""
    out: dict[str, dict[str, int]] = {}
    for r in rows:
        out.setdefault(r.chapter, {v: 0 for v in VERDICTS})[r.verdict] += 1
    return out


def write_ledger(book_dir: str | Path, chapters: list[str]) -> Path:
    """Write ``book_dir/_generated/claims_ledger.md`` from the runs in ``book_dir/chapters``."""
    rows = build_ledger(chapters, Path(book_dir) / "chapters")
    titles = {c: chapter_spec(c).title for c in chapters}
    path = Path(book_dir) / "_generated" / "claims_ledger.md"
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(ledger_markdown(rows, titles))
    return path


def run_ledger(chapter: str, out_dir: str | Path) -> pd.DataFrame:
    """The ledger rows of one run in ``out_dir`` (its metrics.json and timings.json).

    A chapter notebook shows this as its claims verdicts, so that the chapter and the book's
    ledger cannot disagree.
    """
    from railpaper.pipeline.outputs import claims
    out = Path(out_dir)
    rows = chapter_rows(chapter, claims(chapter), _read_json(out / "metrics.json"),
                        _read_json(out / "timings.json"))
    return ledger_frame(rows)[["claim", "paper", "ours", "verdict", "reason"]]
