"""Claims as data, and the registry that makes every later change of one visible.

A chapter's ``data/<chapter>/declarations.toml`` holds one ``[[claim]]`` table per claim and
reading::

    [[claim]]
    id = "convergence_longer_with_speed"
    claim = "convergence takes longer as the speed rises"      # in English
    words = "the convergence time becomes longer as the speed increases"   # the paper's, quoted
    source = "paper 001, abstract"
    kind = "population"        # single-run | population | deterministic | design | implementation
    word_class = "trend"       # a class of data/vocabulary.toml: it fixes the procedure
    study = "monte_carlo"      # the per-record study whose rows decide (not for deterministic,
                               # design and implementation rows, which read the run's metrics)
    metrics = ["convergence_time_s_60kmh", "convergence_time_s_200kmh"]
    direction = "increase"     # trends and comparisons: from metrics[0] to metrics[1]
    paper_value = [55.0]       # single-run and deterministic rows: the paper's numbers
    resolution = [5.0]         # ... and their printed resolution
    horizon = "step 300"       # single-run rows: where the figure's numbers are read
    central = true             # from the abstract or conclusion
    reading = "default"        # optional: the reading of the paper this row takes

and nothing else: no threshold, margin or case of its own (:data:`FORBIDDEN_KEYS`).  Each row is
decided by :mod:`railpaper.rulebook` from its class's procedure and the vocabulary's numbers.

The registry (``data/claims_registry.json``) holds each row's fingerprint — a hash of the
canonical parsed declaration, the vocabulary entries it uses, the procedures' version and its
registered sample size — with the date it was registered.  :func:`check_registry` reports every
row whose fingerprint no longer matches (``railpaper check`` fails on it); :func:`register`
records a new fingerprint and keeps the previous declaration in the row's history, so the ledger
can show the old verdict beside the new one and the intro counts revisions from the registry.
"""

from __future__ import annotations

import dataclasses
import functools
import hashlib
import json
import tomllib
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any, Callable, Sequence

import numpy as np
import pandas as pd

from railpaper import rulebook
from railpaper.data import DataError
from railpaper.paths import DATA_DIR
from railpaper.rulebook import (
    DIRECTIONS,
    Decision,
    Vocabulary,
    continuous_size,
    rate_size,
    single_run_size,
)

KINDS = ("single-run", "population", "deterministic", "design", "implementation")
#: The procedures each kind may use (a population claim is a rate, a change or an equivalence).
KIND_PROCEDURES = {"single-run": ("single-run",),
                   "population": ("population-rate", "paired-change", "equivalence",
                                  "departure"),
                   "deterministic": ("deterministic",), "design": ("design",),
                   "implementation": ("implementation",)}
REQUIRED_KEYS = ("id", "claim", "words", "source", "kind", "word_class", "metrics", "central")
OPTIONAL_KEYS = ("study", "direction", "paper_value", "resolution", "horizon", "reading",
                 "paper_rate_hz", "note")
#: Keys of the old per-row rules that a declaration may not carry: its thresholds come from
#: the vocabulary, its procedure from its class.
FORBIDDEN_KEYS = ("threshold", "margin", "cases", "otherwise", "rule", "min_samples", "deciding",
                  "when", "tolerance", "alpha", "epsilon")
REGISTRY_FILE = DATA_DIR / "claims_registry.json"


@dataclass(frozen=True)
class Declaration:
    """One claim under one reading, as data (see the module docstring for the fields)."""

    chapter: str
    id: str
    claim: str
    words: str
    source: str
    kind: str
    word_class: str
    metrics: tuple[str, ...]
    central: bool
    study: str = ""
    direction: str = ""
    paper_value: tuple[float, ...] = ()
    resolution: tuple[float, ...] = ()
    horizon: str = ""
    reading: str = ""
    paper_rate_hz: float | None = None
    note: str = ""
    procedure: str = field(default="", compare=False)

    @property
    def key(self) -> str:
        """``chapter/id``: the row's name in the registry."""
        return f"{self.chapter}/{self.id}"

    def canonical(self) -> dict[str, Any]:
        """The parsed declaration as plain data, in a fixed order (what the fingerprint hashes)."""
        data = asdict(self)
        data.pop("procedure")
        return {k: list(v) if isinstance(v, tuple) else v for k, v in sorted(data.items())}


def parse(chapter: str, table: dict[str, Any], vocabulary: Vocabulary) -> Declaration:
    """A declaration from its TOML table, checked: one-line :class:`DataError` naming the row."""
    where = f"{chapter} claim {table.get('id', '?')!r}"
    bad = sorted(set(table) & set(FORBIDDEN_KEYS))
    if bad:
        raise DataError(f"{where}: {', '.join(bad)} belong to the rulebook and the vocabulary, "
                        "not to a claim")
    unknown = sorted(set(table) - set(REQUIRED_KEYS) - set(OPTIONAL_KEYS))
    if unknown:
        raise DataError(f"{where}: unknown keys {', '.join(unknown)}")
    missing = [k for k in REQUIRED_KEYS if k not in table]
    if missing:
        raise DataError(f"{where}: missing {', '.join(missing)}")
    if table["kind"] not in KINDS:
        raise DataError(f"{where}: kind {table['kind']!r} is not one of {', '.join(KINDS)}")
    try:
        entry = vocabulary.entry(table["word_class"])
    except KeyError as exc:
        raise DataError(f"{where}: {exc.args[0]}") from None
    procedure = entry["procedure"]
    if procedure not in KIND_PROCEDURES[table["kind"]]:
        raise DataError(f"{where}: word class {table['word_class']!r} (procedure {procedure}) "
                        f"does not decide a {table['kind']} claim")
    metrics = tuple(table["metrics"]) if isinstance(table["metrics"], list) else (table["metrics"],)
    values = dict(table, metrics=metrics,
                  paper_value=tuple(float(v) for v in _as_list(table.get("paper_value", []))),
                  resolution=tuple(float(v) for v in _as_list(table.get("resolution", []))))
    declaration = Declaration(chapter=chapter, procedure=procedure, **values)
    _check_shape(declaration, where)
    return declaration


def _as_list(value) -> list:
    return value if isinstance(value, list) else [value]


def _check_shape(d: Declaration, where: str) -> None:
    """What each procedure needs of a row."""
    needs_study = d.procedure in ("single-run", "population-rate", "paired-change")
    if needs_study and not d.study:
        raise DataError(f"{where}: a {d.procedure} row names the study whose records decide it")
    if d.procedure == "equivalence" and not d.study and len(d.metrics) != 1:
        raise DataError(f"{where}: an equivalence without a study reads one exact run metric")
    if d.procedure == "paired-change":
        if len(d.metrics) != 2 or d.direction not in DIRECTIONS:
            raise DataError(f"{where}: a paired change needs metrics [baseline, other] and "
                            f"direction {' or '.join(DIRECTIONS)}")
    if d.procedure == "population-rate" and len(d.metrics) != 1:
        raise DataError(f"{where}: a rate reads one per-record yes/no column")
    if d.procedure in ("equivalence", "departure") and d.study and len(d.metrics) not in (1, 2):
        raise DataError(f"{where}: an equivalence reads deviations, or [baseline, other]")
    if d.procedure in ("single-run", "deterministic"):
        if not d.paper_value or len(d.paper_value) != len(d.metrics):
            raise DataError(f"{where}: paper_value needs one number per metric")
        if d.resolution and len(d.resolution) != len(d.metrics):
            raise DataError(f"{where}: resolution needs one number per metric")
    if d.procedure == "single-run" and not d.horizon:
        raise DataError(f"{where}: a single-run row declares its horizon (the paper's, or the "
                        "vocabulary's default)")


def load_declarations(chapter: str, vocabulary: Vocabulary | None = None,
                      path: Path | None = None) -> list[Declaration]:
    """The chapter's declarations (empty where it has no declarations file yet)."""
    path = path or DATA_DIR / chapter / "declarations.toml"
    if not path.exists():
        return []
    vocabulary = vocabulary or Vocabulary.load()
    rows = [parse(chapter, table, vocabulary) for table in tomllib.loads(path.read_text())
            .get("claim", [])]
    seen = set()
    for row in rows:
        if row.id in seen:
            raise DataError(f"{path}: claim id {row.id!r} twice")
        seen.add(row.id)
    return rows


def vocabulary_entries(declaration: Declaration, vocabulary: Vocabulary) -> dict[str, Any]:
    """The vocabulary a row's verdict reads: its class's entry and the policy."""
    return {"class": vocabulary.entry(declaration.word_class), "policy": vocabulary.policy}


def registered_size(declaration: Declaration, vocabulary: Vocabulary,
                    pilot_sigma: float | None = None) -> int | None:
    """The sample size by power, fixed before the deciding run: rates at the word's threshold
    (σ² = τ(1 − τ)) and the policy's rate margin; single-run rows at α and the policy's
    resolution; paired changes and equivalences from a pilot's per-record σ of the relative
    effect (None until one is given); never fewer than the policy's ``min_records``; None for
    rows that take no sample."""
    policy, entry = vocabulary.policy, vocabulary.entry(declaration.word_class)
    level, power, floor = policy["level"], policy["power"], policy["min_records"]
    if declaration.procedure == "population-rate":
        return max(floor, rate_size(entry["threshold"], policy["rate_margin"], level, power))
    if declaration.procedure == "single-run":
        return max(floor, single_run_size(policy["alpha_single_run"],
                                          policy["single_run_resolution"], level, power))
    if declaration.procedure in ("paired-change", "equivalence", "departure") \
            and declaration.study:
        return None if pilot_sigma is None else max(floor, continuous_size(
            pilot_sigma, entry["margin"], level, power))
    return None


def fingerprint(declaration: Declaration, vocabulary: Vocabulary, size: int | None) -> str:
    """SHA-256 (first 16 hex digits) of the canonical declaration, the vocabulary entries it
    reads, the procedures' version, the registered size and (from version 4) whether its
    reading's method is not the paper's (:func:`method_not_the_papers`), (from version 5)
    whether that reading is a yardstick (:func:`chapter_yardsticks`) and (from version 6)
    whether the claim rests only on measured data the book lacks (:func:`chapter_measured`)."""
    payload = {"declaration": declaration.canonical(),
               "vocabulary": vocabulary_entries(declaration, vocabulary),
               "procedure_version": vocabulary.policy["procedure_version"], "size": size}
    if vocabulary.policy["procedure_version"] >= 4:     # whose method the reading is
        payload["method_not_the_papers"] = method_not_the_papers(declaration)
    if vocabulary.policy["procedure_version"] >= 5:     # ... and whether it is a yardstick
        payload["yardstick"] = is_yardstick(declaration)
    if vocabulary.policy["procedure_version"] >= 6:     # ... and whether it rests on data we lack
        payload["measured_only"] = measured_evidence(declaration)
    text = json.dumps(payload, sort_keys=True, separators=(",", ":"), ensure_ascii=False)
    return hashlib.sha256(text.encode()).hexdigest()[:16]


def load_registry(path: Path = REGISTRY_FILE) -> dict[str, dict[str, Any]]:
    """``{chapter/id: {fingerprint, size, date, declaration, history: [...]}}``."""
    return json.loads(path.read_text()) if path.exists() else {}


def check_registry(declarations: list[Declaration], vocabulary: Vocabulary,
                   registry: dict[str, dict[str, Any]],
                   registry_name: str = "data/claims_registry.json") -> list[str]:
    """One line per problem: a row not registered, or whose fingerprint no longer matches (its
    declaration, a vocabulary entry it reads or the procedures changed since it was
    registered)."""
    problems = []
    for d in declarations:
        entry = registry.get(d.key)
        if entry is None:
            problems.append(f"{d.key}: not registered in {registry_name} (railpaper register)")
            continue
        now = fingerprint(d, vocabulary, entry.get("size"))
        if now != entry["fingerprint"]:
            problems.append(f"{d.key}: its declaration or the vocabulary it reads changed since "
                            f"{entry['date']} (fingerprint {entry['fingerprint']} in "
                            f"{registry_name}, now {now}): a revision; register it to keep the "
                            "old verdict beside the new")
    return problems


def register(declarations: list[Declaration], vocabulary: Vocabulary,
             registry: dict[str, dict[str, Any]], sizes: dict[str, int | None], date: str
             ) -> tuple[dict[str, dict[str, Any]], list[str]]:
    """A new registry with every row's current fingerprint and size (``sizes`` by key): an
    unchanged row keeps its entry; a changed one moves its previous entry to ``history`` and is
    marked a revision; a registered row of the same chapters that is no longer declared is kept,
    marked ``dropped``.  Returns the registry and the keys revised."""
    new, revised = dict(registry), []
    for d in declarations:
        size = sizes.get(d.key)
        current = fingerprint(d, vocabulary, size)
        old = registry.get(d.key)
        if old is not None and old["fingerprint"] == current:
            continue
        history = list(old.get("history", [])) if old else []
        if old is not None:
            history.append({k: old[k] for k in ("fingerprint", "size", "date", "declaration")}
                           | {"procedure_version": old.get("procedure_version", 1)})
            revised.append(d.key)
        new[d.key] = {"fingerprint": current, "size": size, "date": date,
                      "declaration": d.canonical(), "history": history,
                      "procedure_version": vocabulary.policy["procedure_version"]}
    chapters = {d.chapter for d in declarations}
    kept = {d.key for d in declarations}
    for key, entry in registry.items():          # a row no longer declared: kept, marked
        if key.split("/")[0] in chapters and key not in kept and "dropped" not in entry:
            new[key] = dict(entry, dropped=date)
            revised.append(key)
    return new, revised


def write_registry(registry: dict[str, dict[str, Any]], path: Path = REGISTRY_FILE) -> Path:
    path.write_text(json.dumps(registry, indent=1, sort_keys=True, ensure_ascii=False) + "\n")
    return path


def revisions(registry: dict[str, dict[str, Any]]) -> int:
    """Rows whose declaration or registered size changed after registration, or that were
    dropped: the intro's revision count.  A row re-registered only because the decision
    procedures' version changed (the same declaration, the same size) is not a revision of the
    claim: :func:`procedure_reregistrations` counts those."""
    def states(entry):
        return {json.dumps([h["declaration"], h["size"]], sort_keys=True)
                for h in [*entry.get("history", []), entry]}
    return sum(1 for entry in registry.values() if entry.get("dropped") or len(states(entry)) > 1)


def procedure_reregistrations(registry: dict[str, dict[str, Any]]) -> int:
    """Rows registered again under a new version of the decision procedures."""
    return sum(1 for entry in registry.values()
               if len({h.get("procedure_version", 1)
                       for h in [*entry.get("history", []), entry]}) > 1)


def first_records(rows: pd.DataFrame | None, size: int | None) -> pd.DataFrame | None:
    """The records a row is decided on: the first ``size`` by seed (its registered size, fixed
    before the deciding run), all of them without a size.  A run with more records than that
    and the stored decisive evidence thus decide on the same records, the same bits."""
    if rows is None or size is None:
        return rows
    return rows.sort_values("seed", kind="stable").head(size).reset_index(drop=True)


#: Per chapter, ``data/<chapter>/methods.toml``: which readings' numbers come from a method that
#: is not the paper's (declared blind, ``data/blind/methods_brief.md``), and why.
METHODS_FILE = "methods.toml"
#: The reading of a row declared without one.
AS_STATED = "as stated"


@functools.lru_cache(maxsize=16)
def _methods_table(chapter: str, data_dir: Path) -> dict[str, Any]:
    """The chapter's parsed methods file (empty without one), read once."""
    path = Path(data_dir) / chapter / METHODS_FILE
    return tomllib.loads(path.read_text()) if path.exists() else {}


def _listed_with_reasons(chapter: str, data_dir: Path, listed: str, reasons: str, what: str,
                         as_what: str) -> dict[str, str]:
    """``{name: reason}`` of the names in the methods file's list ``listed``, each with its
    reason in the table ``reasons``; a listed name without one is a one-line error."""
    table = _methods_table(chapter, data_dir)
    why = table.get(reasons, {})
    missing = [name for name in table.get(listed, []) if name not in why]
    if missing:
        raise DataError(f"{data_dir / chapter / METHODS_FILE}: {what} {missing[0]!r} is listed "
                        f"as {as_what} without a '{reasons}'")
    return {name: why[name] for name in table.get(listed, [])}


def chapter_methods(chapter: str, data_dir: Path = DATA_DIR) -> dict[str, str]:
    """``{reading: why}`` of the chapter's readings whose method is not the paper's (empty
    without a methods file)."""
    return _listed_with_reasons(chapter, Path(data_dir), "ours", "why", "reading", "ours")


def chapter_yardsticks(chapter: str, data_dir: Path = DATA_DIR) -> frozenset[str]:
    """The readings (or row ids) of the chapter's methods file listed as a ``yardstick``: not a
    competing method but a computation of what the data allow (the exact posterior), whose
    failure to show a claim bears on every estimator (declared blind,
    ``data/blind/yardstick_brief.md``)."""
    return frozenset(_methods_table(chapter, Path(data_dir)).get("yardstick", []))


def chapter_measured(chapter: str, data_dir: Path = DATA_DIR) -> dict[str, str]:
    """``{row id: why}`` of the chapter's rows whose claim rests only on data measured on a
    physical vehicle, line or rig that the book cannot obtain or regenerate (the list
    ``measured`` of its methods file, with ``[measured_why]``; declared blind,
    ``data/rbpf-parameter-estimation/blind/conditions_brief.md``)."""
    return _listed_with_reasons(chapter, Path(data_dir), "measured", "measured_why", "row",
                                "measured")


def measured_evidence(d: Declaration, measured: dict[str, str] | None = None) -> str:
    """Why the row's claim rests only on measured data the book lacks ('' when it does not):
    its id looked up in ``measured`` (the chapter's :func:`chapter_measured` by default)."""
    measured = chapter_measured(d.chapter) if measured is None else measured
    return measured.get(d.id, "")


def method_not_the_papers(d: Declaration, methods: dict[str, str] | None = None) -> str:
    """Why the row's numbers come from a method that is not the paper's ('' when they come from
    the paper's own): its id, else its reading (``as stated`` when it has none), looked up in
    ``methods`` (the chapter's :func:`chapter_methods` by default; a methods file lists
    readings, and row ids where one row of a reading differs from the rest)."""
    methods = chapter_methods(d.chapter) if methods is None else methods
    return methods.get(d.id) or methods.get(d.reading or AS_STATED, "")


def is_yardstick(d: Declaration, yardsticks: frozenset[str] | None = None) -> bool:
    """Whether the row's id or reading is a yardstick (``yardsticks``: the chapter's
    :func:`chapter_yardsticks` by default)."""
    yardsticks = chapter_yardsticks(d.chapter) if yardsticks is None else yardsticks
    return bool({d.id, d.reading or AS_STATED} & yardsticks)


def decide(declaration: Declaration, vocabulary: Vocabulary, rows: pd.DataFrame | None,
           metrics: dict[str, Any], size: int | None = None,
           procedure_version: int | None = None,
           estimator_of: Callable[[str], str | None] | None = None,
           methods: dict[str, str] | None = None,
           yardsticks: frozenset[str] | None = None,
           measured: dict[str, str] | None = None) -> Decision:
    """The row's verdict by its class's procedure (:func:`decide_procedure`); from version 6 a
    row whose claim rests only on measured data the book lacks (``measured``: the chapter's
    :func:`chapter_measured` by default) is *not testable* (:func:`railpaper.rulebook.measured_only`);
    from version 4 a
    *reproduced* whose numbers come from a method that is not the paper's (``methods``: the
    chapter's :func:`chapter_methods` by default) is *attainable*
    (:func:`railpaper.rulebook.attainable`), and from version 5 a *differs* there is *not
    testable* (:func:`railpaper.rulebook.not_the_papers`) unless the reading is a yardstick
    (``yardsticks``: the chapter's :func:`chapter_yardsticks` by default), whose failure bears
    on every estimator and stays *differs*."""
    version = (vocabulary.policy["procedure_version"] if procedure_version is None
               else procedure_version)
    decision = decide_procedure(declaration, vocabulary, rows, metrics, size, version,
                                estimator_of)
    lacking = measured_evidence(declaration, measured) if version >= 6 else ""
    if lacking:
        return rulebook.measured_only(decision, lacking)
    why = method_not_the_papers(declaration, methods) if version >= 4 else ""
    if not why:
        return decision
    if version >= 5 and not is_yardstick(declaration, yardsticks):
        return rulebook.not_the_papers(decision, why)
    return rulebook.attainable(decision, why)


def decide_procedure(declaration: Declaration, vocabulary: Vocabulary,
                     rows: pd.DataFrame | None, metrics: dict[str, Any],
                     size: int | None = None, procedure_version: int | None = None,
                     estimator_of: Callable[[str], str | None] | None = None) -> Decision:
    """The row's verdict by its class's procedure: from the per-record ``rows`` of its study
    (single-run, rates, changes, equivalences) or the run's ``metrics`` (deterministic, design,
    implementation).  A sampled row with fewer records than its registered ``size`` is
    *undecided* and says how many it needs.

    ``procedure_version`` (the vocabulary's by default) selects the procedures a row was
    registered under, so that an earlier verdict can be shown beside today's.  Version 2 adds
    the estimator's soundness (:func:`railpaper.rulebook.soundness`), counts a per-record NaN
    as never happened in a paired change, equivalence or departure and as "no" in a rate, reads
    design rows as yes/no checks only, and makes a paired change from a baseline of mean 0
    undecided (version 1 raised).  Version 3 checks only the estimators a row credits
    (:func:`estimators_credited`), names them from the study's catalogue ``estimator_of``
    (column → estimator, where the chapter gives one) and counts soundness on the records
    whose exact posterior is known."""
    d, policy = declaration, vocabulary.policy
    version = policy["procedure_version"] if procedure_version is None else procedure_version
    entry = vocabulary.entry(d.word_class)
    if d.procedure == "equivalence" and not d.study:       # one exact value of the run
        value = metrics.get(d.metrics[0])
        if value is None:
            return Decision("undecided", f"the run has no metric {d.metrics[0]!r}")
        inside = abs(float(value)) < entry["margin"]
        return Decision("reproduced" if inside else "differs",
                        f"exact deviation {float(value):+.3g} {'within' if inside else 'beyond'} "
                        f"±{entry['margin']:g}", float(value))
    if d.procedure in ("single-run", "population-rate", "paired-change", "equivalence",
                       "departure"):
        if rows is None or len(rows) == 0:
            return Decision("undecided", f"no records of study {d.study!r}")
        missing = [m for m in d.metrics if m not in rows.columns]
        if missing:                    # e.g. a run at other speeds than the declaration reads
            return Decision("undecided", f"this run's study {d.study!r} has no column "
                            f"{missing[0]!r} (its settings do not compute it)", n=len(rows))
        if size is not None and len(rows) < size:
            return Decision("undecided", f"{len(rows)} records of the {size} registered for it "
                            "(sizes by power, before the deciding run)", n=len(rows))
    left_out = ""
    if d.procedure in ("paired-change", "equivalence", "departure"):
        values = rows[list(d.metrics)].to_numpy(float)
        never = values == policy["never_code"]
        if version >= 2:               # a filter that diverged gave no number: never happened
            never |= np.isnan(values)
        never = never.any(axis=1)
        coded = (f"coded {policy['never_code']:g}" if version < 2
                 else f"coded {policy['never_code']:g} or not a number")
        if never.mean() > policy["never_share_max"]:
            return Decision("undecided", f"on {int(never.sum())} of {len(rows)} records it never "
                            f"happened ({coded}), more than "
                            f"{policy['never_share_max']:.0%}: the rest would be a selected subset",
                            n=len(rows))
        if never.any():
            rows = rows[~never]
            left_out = f"; {int(never.sum())} record(s) where it never happened ({coded}) left out"
    decision = _sampled(d, entry, policy, rows, version)
    if decision is not None:
        if left_out:
            decision = dataclasses.replace(decision, reason=decision.reason + left_out)
        return _sound(d, decision, rows, policy, version, estimator_of) if version >= 2 \
            else decision
    values = [metrics.get(m) for m in d.metrics]
    if d.procedure == "implementation":
        if d.paper_rate_hz is not None or not d.direction:
            return rulebook.implementation(values[0] if values else None, d.paper_rate_hz)
        if values[0] is None:
            return Decision("undecided", f"the run has no metric {d.metrics[0]!r}")
        bounds = [metrics.get(f"{d.metrics[0]}_{end}", values[0]) for end in ("low", "high")]
        # an exact metric (a count of operations) has no interval: its value is both ends
        return rulebook.cost_ratio(float(values[0]), float(bounds[0]), float(bounds[1]),
                                   d.direction, entry.get("margin", 0.0),
                                   share="share" in d.metrics[0])
    if any(v is None for v in values):
        return Decision("undecided", f"the run has no metric {d.metrics[values.index(None)]!r}")
    if d.procedure == "design":
        if version >= 2 and not all(_is_yes_no(v) for v in values):
            return Decision("undecided", f"a design row reads yes/no checks; {d.metrics[0]!r} "
                            "is a number (declare it as an exact value)")
        return rulebook.design(all(bool(v) for v in values), d.claim)
    resolution = d.resolution or (0.0,) * len(d.metrics)
    decisions = [rulebook.deterministic(v, p, r) for v, p, r in
                 zip(values, d.paper_value, resolution)]
    differing = [x for x in decisions if x.verdict == "differs"]
    return differing[0] if differing else decisions[0]


def _is_yes_no(value: Any) -> bool:
    """A boolean, or a number that is exactly 0 or 1 (a yes/no stored in JSON or CSV)."""
    return isinstance(value, (bool, np.bool_)) or (
        isinstance(value, (int, float, np.integer, np.floating)) and float(value) in (0.0, 1.0))


def _suffix_estimator(metric: str, estimators: Sequence[str], prefix: str) -> str | None:
    """Version 2's reading of a metric's estimator: the longest ``<m>`` with a soundness column
    such that the metric is that column or ends in ``_<m>``."""
    matching = [m for m in estimators if metric == prefix + m or metric.endswith("_" + m)]
    return max(matching, key=len) if matching else None


def estimators_read(d: Declaration, columns: Sequence[str], prefix: str) -> list[str]:
    """The estimators whose output a row reads (version 2): for each metric, the longest
    ``<m>`` with a soundness column ``<prefix><m>`` among ``columns`` such that the metric is
    that column or ends in ``_<m>`` (``settling_step_a_qgrbpf_printed`` reads
    ``qgrbpf_printed``, not ``rbpf``)."""
    estimators = [c[len(prefix):] for c in columns if c.startswith(prefix)]
    read = [_suffix_estimator(metric, estimators, prefix) for metric in d.metrics]
    return list(dict.fromkeys(m for m in read if m is not None))


def soundness_column(estimator: str, prefix: str) -> str:
    """The yes/no column of an estimator's soundness: ``<prefix><estimator>``, or the bare
    ``satisfactory`` of a study's one filter (``estimator == ""``)."""
    return prefix + estimator if estimator else prefix.rstrip("_")


def estimators_credited(d: Declaration, rows: pd.DataFrame, policy: dict[str, Any],
                        estimator_of: Callable[[str], str | None] | None = None) -> list[str]:
    """Version 3: the estimators whose success a row asserts, which its soundness check reads.

    Each metric's estimator is the study's catalogue's (``estimator_of(metric)``) where the
    chapter gives one, else version 2's name rule; it counts only when the study has its
    soundness column.  Then a row credits no estimator

    * through a metric that records a failure (a token of the policy's ``failure_tokens`` in
      its name, ``ekf_diverged_init1``): a filter that misses the posterior still fails;
    * in a claimed offset (``departure``): a bias is a failure;
    * through a single-run yes/no number the paper says did not happen (paper value 0);

    and a paired change between two estimators credits only the one the claimed direction
    favours: the second metric's when the change is an increase of a higher-is-better metric
    (a token of ``higher_is_better_tokens``: converged, within, accuracy, ...) or a decrease of
    a lower-is-better one (an error, a step, a time), else the first's (its baseline).
    """
    prefix = policy["soundness_prefix"]
    failure = set(policy["failure_tokens"])
    if d.procedure == "departure":
        return []
    named = [c[len(prefix):] for c in rows.columns if c.startswith(prefix)]

    def estimator(metric: str) -> str | None:
        if failure & set(metric.split("_")):
            return None
        found = (estimator_of(metric) if estimator_of is not None
                 else _suffix_estimator(metric, named, prefix))
        return found if found is not None and soundness_column(found, prefix) in rows.columns \
            else None

    read = [estimator(m) for m in d.metrics]
    if d.procedure == "single-run" and d.paper_value:
        read = [None if value == 0 and rows[m].dropna().isin((0, 1)).all() else e
                for e, m, value in zip(read, d.metrics, d.paper_value)]
    if d.procedure == "paired-change" and len(read) == 2 and read[0] != read[1]:
        higher = bool(set(policy["higher_is_better_tokens"]) & set(d.metrics[1].split("_")))
        read = [read[1] if (d.direction == "increase") == higher else read[0]]
    return list(dict.fromkeys(e for e in read if e is not None))


def _sound(d: Declaration, decision: Decision, rows: pd.DataFrame, policy: dict[str, Any],
           version: int = 2, estimator_of: Callable[[str], str | None] | None = None
           ) -> Decision:
    """The decision checked against the soundness of each estimator it reads (version 2) or
    credits (version 3), on the same records (:func:`railpaper.rulebook.soundness`).  Version 3
    counts only the records whose exact posterior is known (the column is a number) and says
    so when none is."""
    prefix = policy["soundness_prefix"]
    estimators = (estimators_read(d, list(rows.columns), prefix) if version < 3
                  else estimators_credited(d, rows, policy, estimator_of))
    for estimator in estimators:
        column = rows[soundness_column(estimator, prefix)]
        name = estimator or "filter"
        if version >= 3:
            column = column.dropna()
            if column.empty:
                if decision.verdict == "reproduced":
                    decision = dataclasses.replace(decision, reason=(
                        f"{decision.reason}; the {name}'s agreement with the exact posterior "
                        "is not known on these records (not checked)"))
                continue
        sound = column.astype(bool)
        decision = rulebook.soundness(decision, name, int(sound.sum()), len(sound),
                                      policy["soundness_threshold"], policy["level"])
    return decision


def _sampled(d: Declaration, entry: dict[str, Any], policy: dict[str, Any],
             rows: pd.DataFrame | None, version: int) -> Decision | None:
    """The procedures that read per-record rows (None for the others)."""
    level = policy["level"]
    if d.procedure == "single-run":
        resolution = d.resolution or (0.0,) * len(d.metrics)
        return rulebook.single_run(rows[list(d.metrics)].to_numpy(dtype=float), d.paper_value,
                                   resolution, policy["alpha_single_run"], level)
    if d.procedure == "population-rate":
        column = rows[d.metrics[0]]
        hits = column.astype(bool)
        if version >= 2:                   # no answer (a diverged filter) is not a success
            hits &= column.notna()
        return rulebook.population_rate(int(hits.sum()), len(hits), entry["threshold"],
                                        entry.get("direction", "at least"), level)
    if d.procedure == "paired-change":
        baseline_mean = float(np.mean(rows[d.metrics[0]].to_numpy(float)))
        if baseline_mean == 0.0 and version >= 2:
            return Decision("undecided", f"the baseline {d.metrics[0]!r} has mean 0: a change "
                            "relative to it is undefined", n=len(rows))
        return _named_pair(d, rulebook.paired_change(rows[d.metrics[0]].to_numpy(float),
                                                     rows[d.metrics[1]].to_numpy(float),
                                                     d.direction, entry["margin"], level))
    if d.procedure in ("equivalence", "departure"):
        procedure = rulebook.equivalence if d.procedure == "equivalence" else rulebook.departure
        if len(d.metrics) == 1:
            return procedure(rows[d.metrics[0]].to_numpy(float), entry["margin"], level)
        return _named_pair(d, procedure(margin=entry["margin"], level=level,
                                        baseline=rows[d.metrics[0]].to_numpy(float),
                                        other=rows[d.metrics[1]].to_numpy(float)))
    return None


def _named_pair(d: Declaration, decision: Decision) -> Decision:
    """``decision`` of a paired row, its reason opening with the two columns compared (the
    change is from the first, the baseline, to the second): a reader sees which is which."""
    return dataclasses.replace(decision, reason=f"{d.metrics[1]} against the baseline "
                                                f"{d.metrics[0]}: {decision.reason}")


__all__ = ["Declaration", "FORBIDDEN_KEYS", "KINDS", "REGISTRY_FILE", "chapter_measured",
           "chapter_methods", "chapter_yardsticks", "check_registry", "decide", "decide_procedure",
           "estimators_credited", "estimators_read", "fingerprint", "first_records", "is_yardstick",
           "load_declarations", "load_registry", "measured_evidence", "method_not_the_papers",
           "parse", "procedure_reregistrations", "register", "registered_size", "revisions",
           "soundness_column", "write_registry"]
