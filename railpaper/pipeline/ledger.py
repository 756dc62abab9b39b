"""The claims ledger: every claim the papers make about their results, our evidence, a verdict.

``data/<chapter>/claims.toml`` is the only place a verdict is decided (schema and rule tests in
:mod:`railpaper.pipeline.claim_rules`); this module evaluates those rules on a run's
``metrics.json`` (then ``timings.json`` for wall-clock claims) and renders the rows.  The book's
intro and each chapter's claims section call the same :func:`chapter_table`, so they cannot
disagree; ``railpaper build`` also writes ``_generated/claims_ledger.csv``.

Verdicts (defined for readers in the intro): ``reproduced``, ``attainable`` (a method that is
not the paper's shows it), ``artefact``, ``differs``, ``undecided``, ``not testable``; and two states of a run rather than of a claim: ``missing`` (the chapter has
not been run, or its run lacks a metric the rule reads) and, for rows built from a run with
non-default parameters, the verdict is this run's and the table says so.

Rows are readings; the headline counts *claims*: one row per claim (its ``group``), the first row
of the group whose method is the paper's (its default reading).  Rows about a method that is not
the paper's (``method``) are counted apart as *attainable* claims.
"""

from __future__ import annotations

import csv
import dataclasses
import functools
import json
import re
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Callable

import pandas as pd

from railpaper.data import read_toml
from railpaper.experiments.records import RecordStudy
from railpaper.paths import DATA_DIR
from railpaper.pipeline.chapters import chapter_spec
from railpaper.pipeline.claim_rules import (
    RULE_VERDICTS,
    check_row,
    condition_thresholds,
    is_untestable,
    original_rule,
    rule_metrics,
    verdict_as_written,
    verdict_on_run,
)
from railpaper.pipeline.decisive import affordable, allocated_size
from railpaper.pipeline.declarations import (
    Declaration,
    decide,
    first_records,
    load_declarations,
    load_registry,
    procedure_reregistrations,
    revisions,
)
from railpaper.pipeline.evidence_store import EvidenceStore
from railpaper.pipeline.ledger_figure import plot_ledger
from railpaper.pipeline.soundness import (
    estimator_catalogue,
    posterior_study,
    with_soundness,
)
from railpaper import rulebook
from railpaper.rulebook import Decision, Vocabulary
from railpaper.pipeline.outputs import claims

VERDICTS = RULE_VERDICTS + ("missing",)
#: HTML of each verdict in the tables: a coloured badge with an icon (book/_static/verdicts.css).
VERDICT_ICONS = {"reproduced": "✔", "attainable": "◇", "artefact": "⚠", "differs": "✘",
                 "undecided": "?", "not testable": "∅", "missing": "–"}
CSV_COLUMNS = ["chapter", "claim", "reading", "kind", "method", "headline", "paper_value", "ours",
               "ours_low", "ours_high", "n_samples", "min_samples", "verdict", "reason",
               "revised_after_evidence", "verdict_under_original_rule", "procedure", "words",
               "horizon", "central", "fingerprint", "evidence", "verdicts_by_procedure_version"]


@dataclass
class LedgerRow:
    """One paper claim, under one reading, beside our evidence.

    ``ours`` is the display text of the statistic the verdict is decided on (with its interval);
    ``ours_value``, ``ours_low``, ``ours_high`` and ``n_samples`` are the numbers behind it (None
    where the row has none, e.g. not testable or deterministic).
    """

    chapter: str
    key: str
    claim: str
    source: str
    paper: str
    ours: str
    verdict: str
    reason: str
    reading: str = ""
    group: str = ""
    statistic: str = ""
    paper_value: object = None
    ours_value: object = None
    ours_low: object = None
    ours_high: object = None
    n_samples: object = None
    kind: str = ""
    method: str = ""
    min_samples: object = None
    headline: bool = False
    revised: str = ""
    original_verdict: str = ""
    reference: object = None
    procedure: str = ""
    words: str = ""
    horizon: str = ""
    central: bool = False
    fingerprint: str = ""
    evidence: str = ""
    by_version: dict = dataclasses.field(default_factory=dict)


def claims_label(chapter: str) -> str:
    """The MyST target of a chapter's claims section (``(claims-<chapter>)=`` in its notebook)."""
    return f"claims-{chapter}"


def _format(template: str, values: dict) -> str:
    try:
        return template.format_map(values)
    except (KeyError, ValueError, IndexError, TypeError, AttributeError):
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


def _ours(row: dict, values: dict) -> tuple[str, object, object, object, object]:
    """Display text and (value, low, high, n) of the row's statistic on a run:
    ``value [low, high] unit, n = N`` (or ``…, deterministic``)."""
    primary = row.get("primary")
    if primary is None or primary not in values:
        return ("-" if primary else "(no statistic)"), None, None, None, None
    value = values[primary]
    text = _show(value)
    low = high = n = None
    if "interval" in row and all(name in values for name in row["interval"]):
        low, high = (values[name] for name in row["interval"])
        text += f" [{_show(low)}, {_show(high)}]"
    unit = _show("", row.get("primary_unit", row.get("unit", "")))
    text += f" {unit}" if unit else ""
    if "n_samples" in row and row["n_samples"] in values:
        n = values[row["n_samples"]]
        n = int(n) if isinstance(n, float) and n.is_integer() else n     # timings.json: floats
        text += f", n = {n}"
    elif row.get("deterministic"):
        text += ", deterministic"
    return text, value, low, high, n


def judge(row: dict, values: dict, as_written: bool = False) -> tuple[str, str]:
    """Verdict and formatted reason of one row on a run's metric values.

    ``("missing", ...)`` when a metric the rule reads is absent.  ``as_written``: the rule's
    cases alone, without the vocabulary check (how an original rule is shown).
    """
    if is_untestable(row):
        return row["otherwise"]["verdict"], _format(row["otherwise"]["reason"], values)
    absent = [name for name in rule_metrics(row) if name not in values]
    if absent:
        return "missing", f"the run has no metric {absent[0]}"
    verdict, reason = (verdict_as_written if as_written else verdict_on_run)(row, values)
    return verdict, _format(reason, values)


def changed_parameters(run: dict, defaults: dict) -> list[str]:
    """Names of the run's parameters whose values differ from ``defaults``."""
    params = run.get("parameters", {})
    return sorted(k for k in set(params) | set(defaults) if params.get(k) != defaults.get(k))


def chapter_rows(chapter: str, claims: dict[str, dict], run: dict | None,
                 timings: dict | None = None) -> list[LedgerRow]:
    """The ledger rows of one chapter on one run.

    Parameters
    ----------
    chapter : str
        Chapter name.
    claims : dict
        The chapter's ``claims.toml`` (each row checked by :func:`claim_rules.check_row`).
    run : dict or None
        The run's ``metrics.json`` (None: the chapter has not been run).
    timings : dict, optional
        The run's ``timings.json``; its metrics are used for keys ``metrics.json`` lacks.
    """
    values = dict((timings or {}).get("metrics", {}))
    values.update((run or {}).get("metrics", {}))
    rows = []
    for key, row in claims.items():
        check_row(key, row, f"data/{chapter}/claims.toml")
        paper = _show(row["paper_value"], row.get("unit", "")) if "paper_value" in row \
            else "(no number)"
        ours, value, low, high, n = _ours(row, values)
        if run is None:
            verdict, reason = "missing", "the chapter has not been run"
        else:
            verdict, reason = judge(row, values)
        before, revised, original_verdict = original_rule(row), "", ""
        if before is not None:
            r = row["revised_after_evidence"]
            revised = f"{r['when']}: {r['what']}. Why: {r['why']}"
            original_verdict = ("missing" if run is None else judge(before, values,
                                                                       as_written=True)[0])
        rows.append(LedgerRow(chapter, key, row["claim"], row.get("source", ""), paper, ours,
                              verdict, reason, row.get("reading", ""), row.get("group", key),
                              row.get("statistic", ""), row.get("paper_value"), value, low,
                              high, n, row["kind"], row.get("method", ""),
                              row.get("min_samples"), False, revised, original_verdict,
                              rule_reference(row, values)))
    mark_headlines(rows)
    return rows


def rule_reference(row: dict, values: dict):
    """What the row's statistic is compared with: the paper's number, else the first threshold
    a condition on the row's interval (or primary) reads; None when neither exists."""
    if isinstance(row.get("paper_value"), (int, float)) and not isinstance(
            row.get("paper_value"), bool):
        return row["paper_value"]
    names = set(row.get("interval", [])) | {row.get("primary")}
    for case in row.get("cases", []):
        for cond in case.get("when", []):
            if names & set(cond.get("metrics", [])):
                try:
                    found = condition_thresholds(cond, row, values)
                except (KeyError, TypeError, ValueError):
                    found = []
                if found:
                    return found[0]
    return None


def mark_headlines(rows: list[LedgerRow]) -> None:
    """Set ``headline`` on the first row of each claim (group) whose method is the paper's (or
    that judges the paper's claim on a design of ours: kind ``design``)."""
    seen = set()
    for r in rows:
        # a design row is the paper's own claim, judged on a design of ours: it heads its claim
        if (not r.method or r.kind == "design") and (r.chapter, r.group) not in seen:
            seen.add((r.chapter, r.group))
            r.headline = True


def _read_json(path: Path) -> dict | None:
    return json.loads(path.read_text()) if path.exists() else None


def run_rows(chapter: str, out_dir: str | Path, data_dir: str | Path | None = None
             ) -> tuple[list[LedgerRow], dict | None]:
    """Ledger rows of the run in ``out_dir`` and its ``metrics.json`` (None if not run): from
    the chapter's declarations under the rulebook where it has them
    (:func:`railpaper.pipeline.verdicts.declared_rows`), else from its v2 rules."""
    data = Path(data_dir) if data_dir else DATA_DIR
    out = Path(out_dir)
    run = _read_json(out / "metrics.json")
    timings = _read_json(out / "timings.json")
    if (data / chapter / "declarations.toml").exists():
        return declared_rows(chapter, out, run, timings, data), run
    rows = chapter_rows(chapter, read_toml(data / chapter / "claims.toml"), run, timings)
    return rows, run


#: Where the decisive evidence of the repository lives (``railpaper evidence --decisive``).
DECISIVE_EVIDENCE_DIR = DATA_DIR / "evidence"


def study_rows(chapter: str, study: str, out: Path, run: dict | None, size: int | None
               ) -> tuple[pd.DataFrame | None, str]:
    """The per-record rows a declared row is decided on, and where they come from: this run's
    ``records_<study>.csv``, or — where the run holds fewer records than the registered
    ``size`` — the stored decisive evidence for the run's settings when it holds enough, or
    for a study the run does not compute (the row is then undecided on what is stored)."""
    path = out / f"records_{study}.csv"
    mine = _read_csv(str(path), path.stat().st_mtime_ns) if path.exists() else None
    if size is None or (mine is not None and len(mine) >= size) or run is None:
        count = 0 if mine is None else len(mine)
        used = f"the first {size} of " if size is not None and count > size else ""
        return first_records(mine, size), f"this run ({used}{count} records)"
    settings = chapter_spec(chapter).resolve(run.get("parameters", {}), bool(run.get("quick")))
    folder = EvidenceStore(DECISIVE_EVIDENCE_DIR).folder(RecordStudy(chapter, study, rows=None),
                                                         settings)
    rows_file = folder / "rows.csv"
    stored = affordable(_read_store(chapter, study, settings,
                                    rows_file.stat().st_mtime_ns if rows_file.exists() else 0),
                        chapter, study, DECISIVE_EVIDENCE_DIR)
    if len(stored) >= size:
        used = f"the first {size} of " if len(stored) > size else ""
        return (first_records(stored.drop(columns="commit"), size),
                f"{folder.relative_to(DATA_DIR.parent)} ({used}{len(stored)} records)")
    if mine is None and len(stored):      # a study only the store holds, short of the size
        return (stored.drop(columns="commit"),
                f"{folder.relative_to(DATA_DIR.parent)} ({len(stored)} records)")
    return mine, f"this run ({0 if mine is None else len(mine)} records)"


def _with_cost(decision: Decision, chapter: str, study: str, size: int | None,
               table: pd.DataFrame | None) -> Decision:
    """An undecided row short of its registered size, beside stored decisive evidence: its
    reason also gives the CPU time the size needs at the rate the stored records cost (the
    decisive run leaves out sizes past its 2-CPU-hour budget)."""
    if (decision.verdict != "undecided" or not study or not size
            or (table is not None and len(table) >= size)):
        return decision
    path = DECISIVE_EVIDENCE_DIR / chapter / "provenance.json"
    entry = (json.loads(path.read_text()).get("studies", {}).get(study)
             if path.exists() else None)
    if not entry or not entry.get("records"):
        return decision
    hours = entry["cpu_s"] / entry["records"] * size / 3600
    paid = allocated_size(chapter, study, DECISIVE_EVIDENCE_DIR)
    held = (f"the stored evidence holds {entry['records']}" if paid is None
            or paid >= entry["records"] else
            f"the 2-CPU-hour budget of the deciding runs, allocated cheapest first, pays for "
            f"{paid} of them; {entry['records']} are stored")
    return dataclasses.replace(decision, reason=(
        f"{decision.reason}; {size} records need about {hours:.2g} CPU-hours at the stored "
        f"records' rate ({held})"))


@functools.lru_cache(maxsize=32)
def _read_csv(path: str, mtime_ns: int) -> pd.DataFrame:  # noqa: ARG001 - part of the cache key
    """A run's per-record rows, read once per file version (a page asks for them per row)."""
    return pd.read_csv(path)


@functools.lru_cache(maxsize=32)
def _read_store(chapter: str, study: str, settings, mtime_ns: int) -> pd.DataFrame:  # noqa: ARG001
    """The stored decisive rows of a study, read once per file version (000's are 17 MB)."""
    return EvidenceStore(DECISIVE_EVIDENCE_DIR).read(RecordStudy(chapter, study, rows=None),
                                                     settings)


def declared_rows(chapter: str, out: Path, run: dict | None, timings: dict | None,
                  data_dir: Path = DATA_DIR, registry: dict | None = None) -> list[LedgerRow]:
    """The ledger rows of a chapter declared under the rulebook: each declaration decided by
    its class's procedure (:func:`railpaper.pipeline.declarations.decide`) at its registered
    size, with the registry's fingerprint and the evidence it read."""
    vocabulary = Vocabulary.load()
    registry = load_registry() if registry is None else registry
    values = dict((timings or {}).get("metrics", {}))
    values.update((run or {}).get("metrics", {}))
    rows = []
    for d in load_declarations(chapter, vocabulary, data_dir / chapter / "declarations.toml"):
        entry = registry.get(d.key, {})
        size = entry.get("size")
        if run is None:
            decision, evidence = Decision("undecided", "the chapter has not been run"), ""
            verdict, by_version = "missing", {}
        else:
            table, evidence = (study_rows(chapter, d.study, out, run, size) if d.study
                               else (None, "this run"))
            table = _with_posterior(chapter, d.study, table, out, run)
            catalogue = estimator_catalogue(chapter, d.study)
            decision, verdict = decide(d, vocabulary, table, values, size,
                                       estimator_of=catalogue), ""
            current = vocabulary.policy["procedure_version"]
            by_version = {version: _verdict_under(d, vocabulary, table, values, size, version,
                                                  catalogue) for version in range(1, current)}
            by_version[current] = decision.verdict          # decided just above
            decision = _with_cost(decision, chapter, d.study, size, table)
        verdict = verdict or decision.verdict
        paper = (", ".join(f"{v:g}" for v in d.paper_value) if d.paper_value
                 else d.direction or "(no number)")
        # a single-run row's statistic is the depth test's p-value, not a number of ours: say so
        label = "depth-test p = " if d.procedure == "single-run" else ""
        ours = ("—" if decision.statistic is None else f"{label}{decision.statistic:.3g}" + (
            f" [{decision.low:.3g}, {decision.high:.3g}]" if decision.low is not None else "")
            + (f", n = {decision.n}" if decision.n else ""))
        revised, original = "", ""
        if entry.get("history") and run is not None:
            before, revised = previous_registration(entry, vocabulary)
            old = Declaration(**{k: tuple(v) if isinstance(v, list) else v
                                 for k, v in before["declaration"].items()})
            old = dataclasses.replace(old, procedure=vocabulary.entry(old.word_class)["procedure"])
            old_rows = (study_rows(chapter, old.study, out, run, before["size"])[0]
                        if old.study else None)
            old_version = before.get("procedure_version", 1)
            if old_version >= 3:               # the soundness columns it was registered with
                old_rows = _with_posterior(chapter, old.study, old_rows, out, run)
            original = decide(old, vocabulary, old_rows, values, before["size"], old_version,
                              estimator_catalogue(chapter, old.study)).verdict
        rows.append(LedgerRow(chapter, d.id, d.claim, d.source, paper, ours, verdict,
                              decision.reason, d.reading, d.id.split("__")[0],
                              f"{d.procedure} ({d.word_class})", list(d.paper_value) or None,
                              decision.statistic, decision.low, decision.high, decision.n,
                              d.kind, "", size, False, revised, original,
                              procedure=d.procedure, words=d.words, horizon=d.horizon,
                              central=d.central, fingerprint=entry.get("fingerprint", ""),
                              evidence=evidence, by_version=by_version))
    mark_headlines(rows)
    return rows


def _with_posterior(chapter: str, study: str, table: pd.DataFrame | None, out: Path,
                    run: dict | None) -> pd.DataFrame | None:
    """``table`` with its filters' soundness columns, where the chapter keeps the exact
    posterior of ``study``'s records in a study of its own: that study's rows of the same
    records, from this run or the stored decisive evidence (:func:`study_rows`)."""
    posterior = posterior_study(chapter, study) if study and table is not None else None
    if posterior is None or run is None or table.empty:
        return table
    settings = chapter_spec(chapter).resolve(run.get("parameters", {}), bool(run.get("quick")))
    # the posterior's records up to the table's last seed (a study may start later than its
    # posterior: chapter 003's judged studies skip records seen before their policy), joined
    # by seed
    through = int(table["seed"].max()) - posterior.first(settings) + 1
    rows, _ = study_rows(chapter, posterior.name, out, run, through)
    return with_soundness(chapter, study, table, rows, settings)


def _verdict_under(d: Declaration, vocabulary: Vocabulary, table, values: dict, size,
                   version: int, catalogue) -> str:
    """The row's verdict under an earlier version of the procedures, on the same declaration,
    size and evidence (version 1 raised where a baseline's mean is 0: undecided here)."""
    try:
        return decide(d, vocabulary, table, values, size, version, catalogue).verdict
    except ValueError:
        return "undecided"


def previous_registration(entry: dict, vocabulary: Vocabulary) -> tuple[dict, str]:
    """The registration a row's earlier verdict is shown under, and a sentence saying what
    changed: the last one with another declaration or size (a revision of the claim), else the
    last one (the same declaration under earlier decision procedures)."""
    history = entry["history"]
    changed = [h for h in history
               if (h["declaration"], h["size"]) != (entry["declaration"], entry["size"])]
    if changed:
        before = changed[-1]
        return before, (f"declaration re-registered on {entry['date']} (previous of "
                        f"{before['date']}, fingerprint {before['fingerprint']})")
    before = history[-1]
    return before, (f"the same declaration re-registered on {entry['date']} under decision "
                    f"procedures version {vocabulary.policy['procedure_version']} (registered "
                    f"under version {before.get('procedure_version', 1)} on {before['date']})")


def build_ledger(chapters: list[str], chapters_dir: str | Path,
                 data_dir: str | Path | None = None) -> list[LedgerRow]:
    """Ledger rows of several chapters from ``chapters_dir/<chapter>/{metrics,timings}.json``."""
    rows = []
    for chapter in chapters:
        rows += run_rows(chapter, Path(chapters_dir) / chapter, data_dir)[0]
    return rows


# ---- rendering ----------------------------------------------------------------------------

def _cell(text: str) -> str:
    return str(text).replace("|", "\\|").replace("\n", " ").replace("$", "\\$")


def reader_source(source: str) -> str:
    """Where in the paper, without our file number ("paper 001, section 3" -> "section 3"):
    the table stands under the paper's own name."""
    return re.sub(r"^paper \d{3}[,;:]?\s*", "", source) or source


def verdict_badge(verdict: str) -> str:
    """Inline HTML of a verdict: icon and word in a coloured badge."""
    css = verdict.replace(" ", "-")
    return (f'<span class="verdict verdict-{css}">{VERDICT_ICONS.get(verdict, "")} '
            f"{verdict}</span>")


def summary(rows: list[LedgerRow]) -> str:
    """``"3 reproduced, 1 differs"``: verdict counts of these rows in vocabulary order."""
    counts = {v: sum(r.verdict == v for r in rows) for v in VERDICTS}
    return ", ".join(f"{n} {v}" for v, n in counts.items() if n)


def claim_groups(rows: list[LedgerRow]) -> list[list[LedgerRow]]:
    """The rows of each claim (chapter, group), in ledger order."""
    groups: dict[tuple[str, str], list[LedgerRow]] = {}
    for r in rows:
        groups.setdefault((r.chapter, r.group), []).append(r)
    return list(groups.values())


def headline(rows: list[LedgerRow]) -> str:
    """``"17 claims: 5 reproduced, 8 differs, …; attainable by other methods: 3"``.

    Counts claims, each once, by its headline row (default reading, the paper's method; under
    the v2 rules a claim our design attains counts as not testable for the paper, under the
    rulebook it is counted as attainable, never as reproduced); claims shown attainable by another
    method (its first row, i.e. its default reading) and claims of our own methods are counted
    apart.
    """
    groups = claim_groups(rows)
    heads = [r for g in groups for r in g if r.headline]
    others = [g for g in groups if not any(r.headline for r in g)]
    # under the v2 rules a claim our design attains is not testable for the paper's method
    # (listed apart below); under the rulebook (a declared row) 'attainable' is its verdict
    counted = [replace(r, verdict="not testable")
               if r.verdict == "attainable" and not r.procedure else r for r in heads]
    # attainable by another method: that method's first row (its default reading) says so
    attainable = sum(next((r.verdict for r in g if r.method), "") == "attainable"
                     for g in groups if any(r.headline for r in g))
    text = f"{len(heads)} claims of the paper's methods: {summary(counted) or 'none'}"
    if attainable:
        text += (f"; {attainable} shown attainable by a method or a design that is not the "
                 "paper's (counted apart, never as reproduced)")
    if others:
        text += f"; {len(others)} claims of our own methods"
    return text


def _readings_badges(group: list[LedgerRow], shown: LedgerRow) -> str:
    """The verdicts of a claim's other rows, as small badges (``+ 2 readings: ✘ 1, ◇ 1``)."""
    rest = [r for r in group if r is not shown]
    if not rest:
        return ""
    counts = {v: sum(r.verdict == v for r in rest) for v in VERDICTS}
    text = ", ".join(f"{VERDICT_ICONS[v]} {n}" for v, n in counts.items() if n)
    return f"<br><small>+ {len(rest)} other reading{'s' * (len(rest) > 1)}: {text}</small>"


def _row_detail(r: LedgerRow) -> str:
    reading = f"*{r.reading}*" if r.reading else "*as stated*"
    method = f" (method: {r.method})" if r.method else ""
    line = (f"  - {reading}{method}, {r.kind}: paper {r.paper}; ours {r.ours} — "
            f"{verdict_badge(r.verdict)} {r.reason}")
    if r.revised and r.procedure:
        line += f" *Registered before: {r.revised}; then:* {verdict_badge(r.original_verdict)}"
    elif r.revised:
        line += (f" *Rule revised after its numbers were seen ({r.revised}); under the original "
                 f"rule:* {verdict_badge(r.original_verdict)}")
    return line.replace("\n", " ").replace("$", "\\$")


def fold_inert_readings(group: list[LedgerRow]) -> list[LedgerRow]:
    """The rows of one claim with readings that change nothing folded together: rows with the
    same paper value, statistic, verdict, reason and rule history become one row naming every
    reading (``a = b``)."""
    out: dict[tuple, LedgerRow] = {}
    for r in group:
        key = (r.verdict, r.reason, r.method, r.original_verdict, r.paper, r.ours, r.revised)
        name = r.reading or "as stated"
        if key in out:
            first = out[key]
            merged = (first.reading.replace(" (the readings", f" = {name} (the readings")
                      if "change nothing" in first.reading else
                      f"{first.reading or 'as stated'} = {name} (the readings change nothing here)")
            out[key] = replace(first, reading=merged)
        else:
            out[key] = r
    return list(out.values())


def chapter_table(rows: list[LedgerRow]) -> str:
    """The MyST ledger of one chapter's rows, the same text in the intro and in the chapter:
    a table of one line per claim (its headline row: default reading, the paper's method; or its
    first row), the other readings counted under its verdict, and below it a dropdown with every
    row's reading, statistic, verdict and reason."""
    lines = ["| paper claim (where) | kind | paper | ours: statistic [95 % interval], n "
             "| verdict |", "|---|---|---|---|---|"]
    groups = claim_groups(rows)
    for group in groups:
        r = next((x for x in group if x.headline), group[0])
        reading = f"; *{_cell(r.reading)}*" if r.reading and len(group) > 1 else ""
        lines.append(f"| {_cell(r.claim)} ({_cell(reader_source(r.source))}{reading}) "
                     f"| {r.kind} | {_cell(r.paper)} | {_cell(r.ours)} "
                     f"| {verdict_badge(r.verdict)}{_readings_badges(group, r)} |")
    lines += ["", "````{dropdown} Every reading, its statistic, verdict and reason", ""]
    for group in groups:
        lines.append(f"- **{group[0].claim}**")
        lines += [_row_detail(r) for r in fold_inert_readings(group)]
    lines += ["````", ""]
    return "\n".join(lines) + "\n"


def non_default_note(chapter: str, run: dict | None) -> str:
    """One sentence when the run's parameters are not the chapter's defaults, else ''."""
    if not run:
        return ""
    defaults = chapter_spec(chapter).resolve({}, bool(run.get("quick"))).as_dict()
    changed = changed_parameters(run, defaults)
    if not changed:
        return ""
    return (f"Non-default parameters: {', '.join(changed)}. The verdicts below are this run's; "
            "the book's ledger is judged on a default run.\n\n")


def chapter_claims(chapter: str, out_dir: str | Path) -> str:
    """A chapter's ledger rows judged on the run in ``out_dir``: a note when the parameters are
    not the defaults, the verdict counts, and the same :func:`chapter_table` as the intro."""
    rows, run = run_rows(chapter, out_dir)
    return (non_default_note(chapter, run) + f"{headline(rows)} ({len(rows)} rows with the "
            "readings).\n\n" + chapter_table(rows))


def chapter_central_claims(chapter: str, out_dir: str | Path) -> str:
    """A chapter's central claims judged on the run in ``out_dir`` (:func:`central_claims`),
    with its context sentences."""
    rows, run = run_rows(chapter, out_dir)
    return central_claims(rows, context_sentences(chapter, run))


def chapter_claims_figure(chapter: str, out_dir: str | Path) -> Path:
    """Draw the chapter's claims (each paper value against our interval, marked by verdict)
    from the run in ``out_dir`` into ``out_dir/claims_ledger.png``, the figure the chapter's
    claims section shows above its table."""
    rows, _ = run_rows(chapter, out_dir)
    return plot_ledger(rows, {chapter: chapter_spec(chapter).title},
                       Path(out_dir) / "claims_ledger.png")


def declared_rules(chapter: str) -> str:
    """How each declared row is decided: the paper's words, the word class they commit to and
    its procedure and number from the vocabulary, the study's columns, the registered size and
    fingerprint, and the blind reader's note."""
    vocabulary, registry = Vocabulary.load(), load_registry()
    lines = [f"Each row below was declared blind, from the paper alone (brief and reply in "
             f"`data/{chapter}/blind/`), and is decided by the rulebook's procedure for its word "
             "class, with the book-wide number of `data/vocabulary.toml`; no row carries a "
             "threshold of its own. Sizes were registered by power before the deciding run.", ""]
    for d in load_declarations(chapter, vocabulary):
        entry, registered = vocabulary.entry(d.word_class), registry.get(d.key, {})
        number = (f"threshold {entry['threshold']:g}" if "threshold" in entry else
                  f"margin {entry['margin']:g}" if "margin" in entry else "no number")
        reading = f" — reading: {d.reading}" if d.reading else ""
        metrics = ", ".join(f"`{m}`" for m in d.metrics) or "none"
        size = registered.get("size")
        lines.append(
            f"- **{d.claim}**{reading}. *Words:* “{d.words}” ({d.source}). *Class:* "
            f"{d.word_class} → {d.procedure}, {number}"
            + (f", direction {d.direction}" if d.direction else "")
            + f". *Reads:* {metrics}" + (f" of study `{d.study}`" if d.study else "")
            + (f"; registered size {size} records" if size else "")
            + (f"; fingerprint `{registered['fingerprint']}`" if registered else "; not registered")
            + (f". *Reader's note:* {d.note}" if d.note else ".")
            .replace("\n", " "))
    return "\n".join(lines).replace("$", "\\$") + "\n"


def chapter_rules(chapter: str) -> str:
    """How each of a chapter's verdicts is decided: for a declared chapter its declarations
    (:func:`declared_rules`); else the rule, fixed from the paper's wording, and why (a Markdown
    list: one item per claim, one sub-item per reading; a rule or a reason already given on the
    page is referred to, not repeated)."""
    if (DATA_DIR / chapter / "declarations.toml").exists():
        return declared_rules(chapter)
    lines = ["How each verdict is decided (the rule, fixed from the paper's wording, and why):", ""]
    groups: dict[str, list[tuple[str, dict]]] = {}
    for key, row in claims(chapter).items():
        check_row(key, row, f"data/{chapter}/claims.toml")
        groups.setdefault(row.get("group", key), []).append((key, row))
    shown: dict[str, tuple] = {}   # text already on the page -> (group, (elsewhere, in group))

    def once(text: str, group: str, where: tuple[str, str]) -> str:
        if text in shown:
            first_group, first_where = shown[text]
            return (f"as for {first_where[1]} above" if first_group == group
                    else f"as for {first_where[0]}")
        shown[text] = (group, where)
        return text

    for group, rows in groups.items():
        claim = rows[0][1]["claim"]
        lines.append(f"- **{claim}**")
        for key, row in rows:
            where = (f"“{claim}”" + (f" ({row['reading']})" if row.get("reading") else ""),
                     f"the reading “{row['reading']}”" if row.get("reading") else "the rule")
            what = row.get("rule") or row.get("otherwise", {}).get("reason", "")
            head = f"reading: {row['reading']}" if row.get("reading") else "rule"
            if row["claim"] != claim:                 # a reading that words the claim anew
                head = f"**{row['claim']}** — {head}"
            selects = (f" (selected by `{row['reading_parameter']}`)"
                       if row.get("reading_parameter") else "")
            ours = f" *Ours:* {row['statistic']}." if row.get("statistic") else ""
            ours = f" *Kind:* {row['kind']}" + (f" (method: {row['method']})"
                                                 if row.get("method") else "") + "." + ours
            revision = row.get("revised_after_evidence")
            if revision:
                ours += (f" *Revised after its numbers were seen* ({revision['when']}): "
                         f"{revision['what']}.")
            why = (f" *Why:* {once(row['justification'], group, where)}"
                   if row.get("justification") else "")
            lines.append(f"  - {head}{selects}: {once(what, group, where)}{ours}{why}"
                         .replace("\n", " "))
    return "\n".join(lines) + "\n"


def chapter_markdown(chapter: str, out_dir: str | Path) -> str:
    """A chapter's claims section: :func:`chapter_claims` followed by :func:`chapter_rules`."""
    return chapter_claims(chapter, out_dir) + "\n" + chapter_rules(chapter)


def ledger_markdown(rows: list[LedgerRow], titles: dict[str, str] | None = None) -> str:
    """The intro's ledger: one table per chapter, each headed by a link to the chapter's claims."""
    titles = titles or {}
    v2 = [r for r in rows if not r.procedure]
    revised = sum(bool(r.revised) for r in v2)
    registry = load_registry()
    declared = sum(1 for key in registry if key.split("/")[0] in {r.chapter for r in rows})
    older = [f"Of the {len(v2)} rows still under v2 rules, {revised} were revised after "
             "their numbers were seen. "] if v2 else []
    moved = [r for r in rows if r.procedure and r.revised and r.original_verdict
             and r.original_verdict != r.verdict]
    lines = [f"{headline(rows)} ({len(rows)} rows with the readings). " + "".join(older)
             + f"Of the {declared} rows ever declared under the rulebook, {revisions(registry)} "
             "had their declaration revised or were dropped since their first registration; "
             f"{procedure_reregistrations(registry)} were registered again with the same "
             f"declaration under version {Vocabulary.load().policy['procedure_version']} of the "
             "decision procedures, which was written after the evidence had been seen. "
             f"{len(moved)} rows of this run read otherwise than under their registration "
             "before: each is a revision after the evidence, shown beside its earlier verdict "
             "(data/claims_registry.json keeps every earlier declaration).", ""]
    for chapter in dict.fromkeys(r.chapter for r in rows):
        mine = [r for r in rows if r.chapter == chapter]
        link = f"{{ref}}`{_cell(titles.get(chapter, chapter))} <{claims_label(chapter)}>`"
        lines += [f"**{link}** — {headline(mine)}", "", chapter_table(mine)]
    return "\n".join(lines)


#: What a verdict means, in the words of one plain sentence.
VERDICT_SENTENCES = {
    "reproduced": "holds on our evidence",
    "attainable": "holds only with a method or design that is not the paper's",
    "artefact": ("holds only as an artefact: the numbers come from our build of the paper's "
                 "estimator, which misses what the data say (the exact posterior)"),
    "differs": "does not hold on our evidence",
    "undecided": "cannot be decided yet: our evidence is not enough either way",
    "not testable": ("cannot be tested on the paper's own method: it cannot be run as printed, "
                     "or the paper gives nothing to test it against"),
    "missing": "has not been judged: the chapter has not been run",
}
#: The plain sentence of a row *not testable* because its only evidence is measured data we lack.
MEASURED_SENTENCE = ("cannot be tested: the paper's only evidence is data measured on a real "
                     "vehicle or line, which the book cannot obtain (our simulated records are "
                     "shown beside it, not counted)")


def is_central(row: LedgerRow) -> bool:
    """A claim a reader who reads nothing else should know: declared central (from the
    abstract or the conclusion), or — for a chapter still on its v2 rules — a headline row whose
    source is the abstract or the conclusion."""
    if row.procedure:
        return row.central
    where = row.source.lower()
    return row.headline and ("abstract" in where or "conclusion" in where)


#: Per chapter, ``data/<chapter>/context.toml``: sentences of ours that a reader of the central
#: claims should have beside them (a baseline, not a claim of the paper's), filled from the run.
CONTEXT_FILE = "context.toml"


def context_sentences(chapter: str, run: dict | None, data_dir: Path = DATA_DIR) -> str:
    """The chapter's context sentences (``[[context]]`` tables: ``text`` with ``{name}``
    fields, and ``[context.values]`` naming each field's ``metric`` or run ``parameter`` (a
    list is written comma-separated) and ``scale``), filled from the run; a sentence whose
    value the run lacks is left out."""
    path = Path(data_dir) / chapter / CONTEXT_FILE
    if run is None or not path.exists():
        return ""
    metrics, parameters, lines = run.get("metrics", {}), run.get("parameters", {}), []
    for entry in read_toml(path).get("context", []):
        fields = {}
        for name, spec in entry["values"].items():
            value = (metrics.get(spec["metric"]) if "metric" in spec
                     else parameters.get(spec["parameter"]))
            if value is None:
                break
            scale = spec.get("scale", 1.0)
            fields[name] = (", ".join(f"{float(x) * scale:g}" for x in value)
                            if isinstance(value, list) else float(value) * scale)
        else:
            lines.append(f"- *Context (ours, not a claim of the paper's):* "
                         f"{' '.join(entry['text'].split()).format(**fields)}")
    return "\n".join(lines) + "\n" if lines else ""


def central_claims(rows: list[LedgerRow], context: str = "") -> str:
    """The paper's central claims, one plain sentence each with its verdict (the first row of
    each central claim: its default reading), then the chapter's ``context`` sentences."""
    lines = []
    for group in claim_groups(rows):
        head = next((r for r in group if r.headline), group[0])
        if not is_central(head):
            continue
        claim = head.claim.rstrip(". ")
        versions = sorted(head.by_version)
        earlier = [v for v in versions[:-1] if head.by_version[v] != head.by_version[v + 1]]
        by_version = (f" It read {head.by_version[earlier[-1]]} under version {earlier[-1]} of "
                      f"the decision procedures; version {earlier[-1] + 1} changed it (the table "
                      "of versions)." if earlier else "")
        changed = by_version
        current_moved = bool(earlier) and earlier[-1] == versions[-2]
        if (not current_moved and head.revised and head.original_verdict
                and head.original_verdict != head.verdict):      # a revision of the declaration
            changed = (f" It read {head.original_verdict} before: {head.revised}; the change "
                       "came after the evidence had been seen.")
        meaning = VERDICT_SENTENCES[head.verdict]
        if head.verdict == "not testable" and head.reason.startswith(rulebook.MEASURED_ONLY):
            meaning = MEASURED_SENTENCE
        lines.append(f"- The paper's claim that {claim} {meaning} "
                     f"({verdict_badge(head.verdict)}).{changed}")
    text = "\n".join(lines) + "\n" if lines else "No claim of the abstract or conclusion.\n"
    return text + context


def central_claims_page(rows: list[LedgerRow], titles: dict[str, str],
                        contexts: dict[str, str] | None = None) -> str:
    """The intro's section: each paper in one paragraph of its central claims (and the
    chapter's context sentences, :func:`context_sentences`)."""
    lines = []
    for chapter in dict.fromkeys(r.chapter for r in rows):
        mine = [r for r in rows if r.chapter == chapter]
        lines += [f"**{_cell(titles.get(chapter, chapter))}**", "",
                  central_claims(mine, (contexts or {}).get(chapter, ""))]
    return "\n".join(lines)


def version_table(rows: list[LedgerRow]) -> str:
    """Markdown: every declared row's verdict counted under each version of the decision
    procedures (one column per version), on the same declarations, sizes and evidence, so that
    what each version changed is computed, not typed; the last line counts the rows whose
    verdict differs from the version before."""
    declared = [r for r in rows if r.by_version]
    if not declared:
        return ""
    versions = sorted({v for r in declared for v in r.by_version})
    lines = ["| verdict | " + " | ".join(f"v{v}" for v in versions) + " |",
             "|---|" + "---:|" * len(versions)]
    for verdict in RULE_VERDICTS:
        counts = [sum(r.by_version.get(v) == verdict for r in declared) for v in versions]
        lines.append(f"| {verdict} | " + " | ".join(map(str, counts)) + " |")
    moved = ["—"] + [str(sum(r.by_version.get(v) != r.by_version.get(v - 1) for r in declared))
                     for v in versions[1:]]
    lines.append("| *moved* | " + " | ".join(moved) + " |")
    return "\n".join(lines) + "\n"


def ledger_counts(rows: list[LedgerRow]) -> dict[str, dict[str, int]]:
    """``{chapter: {verdict: count}}``."""
    out: dict[str, dict[str, int]] = {}
    for r in rows:
        out.setdefault(r.chapter, {v: 0 for v in VERDICTS})[r.verdict] += 1
    return out


def write_ledger_csv(rows: list[LedgerRow], path: str | Path) -> Path:
    """``claims_ledger.csv``: one row per claim and reading (columns :data:`CSV_COLUMNS`)."""
    path = Path(path)
    with path.open("w", newline="") as handle:
        writer = csv.writer(handle)
        writer.writerow(CSV_COLUMNS)
        for r in rows:
            writer.writerow([r.chapter, r.claim, r.reading or "as stated", r.kind, r.method,
                             str(r.headline).lower(),
                             "" if r.paper_value is None else r.paper_value,
                             *("" if v is None else repr(v) if isinstance(v, float) else v
                               for v in (r.ours_value, r.ours_low, r.ours_high, r.n_samples)),
                             "" if r.min_samples is None else r.min_samples,
                             r.verdict, r.reason, r.revised, r.original_verdict,
                             r.procedure or "v2 rule", r.words, r.horizon,
                             str(r.central).lower(), r.fingerprint, r.evidence,
                             "; ".join(f"v{v} {verdict}"
                                       for v, verdict in sorted(r.by_version.items()))])
    return path


def write_ledger(book_dir: str | Path, chapters: list[str],
                 titles: Callable[[str], str] | None = None) -> Path:
    """Write ``_generated/claims_ledger.md``, ``claims_ledger.csv`` and the figure
    ``claims_ledger.png`` from ``book_dir/chapters``."""
    rows = build_ledger(chapters, Path(book_dir) / "chapters")
    title = titles or (lambda c: chapter_spec(c).title)
    path = Path(book_dir) / "_generated" / "claims_ledger.md"
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(ledger_markdown(rows, {c: title(c) for c in chapters}))
    contexts = {c: context_sentences(c, _read_json(Path(book_dir) / "chapters" / c /
                                                   "metrics.json")) for c in chapters}
    path.with_name("central_claims.md").write_text(
        central_claims_page(rows, {c: title(c) for c in chapters}, contexts))
    path.with_name("procedure_versions.md").write_text(version_table(rows))
    write_ledger_csv(rows, path.with_suffix(".csv"))
    plot_ledger(rows, {c: title(c) for c in chapters}, path.with_suffix(".png"))
    return path
