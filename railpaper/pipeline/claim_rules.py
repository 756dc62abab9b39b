"""The verdict rules of ``data/<chapter>/claims.toml``: schema, evaluation on a run, and
evaluation over tolerance bands (is the verdict the same for every run that passes CI?).

One table of a claims file is one ledger row: one claim of a paper under one reading::

    [convergence_slower_with_speed]
    claim = "convergence takes longer as speed rises"     # the paper's wording
    source = "paper 001, abstract; section 3 (2); Figs 4-5"
    group = "..."             # optional: rows that are readings of one claim share it (default: key)
    reading = "..."           # optional: the reading's name; the default reading's row comes first
    reading_parameter = "..." # optional: the chapter parameter value that selects the reading
    rule = "..."              # the rule in words, fixed from the paper's wording
    justification = "..."     # why this statistic and threshold
    paper_value = 55          # optional, with unit = "..."
    primary = "metric"        # the statistic the verdict is decided on ("ours")
    statistic = "median over records of ..."   # what primary is, in words
    interval = ["metric_low", "metric_high"]   # its 95 % interval
    n_samples = "metric_n"    # Monte Carlo samples behind it ... or: deterministic = true
    min_samples = 110         # optional: fewer samples than this give "undecided" (the size at
                              # which disjoint seed batches agree on the verdict)
    kind = "population"       # single-run | population | deterministic | design | implementation
    method = "..."            # optional: the method that is not the paper's (exact posterior, our
                              # scheme, a matched design); such a row says "attainable", never
                              # "reproduced", and the headline does not count it
    deciding = [["a_low", "a_high"], ...]      # optional: the deciding intervals (default: interval)
    [convergence_slower_with_speed.revised_after_evidence]   # a rule changed after its numbers
    what = "..."; when = "2026-12-01"; why = "..."           # were seen, and the original rule:
    original = {min_samples = 0, cases = [...], otherwise = {...}}   # missing keys: as revised
                              # (but ``deciding``: the original reads its own interval)
    [[convergence_slower_with_speed.cases]]    # tried in order; the first whose conditions hold
    verdict = "reproduced"    # reproduced | artefact | differs | undecided | not testable
    reason = "... {metric:.3g} ..."            # str.format over the run's metrics
    when = [{test = "range", metrics = ["metric_low"], above = 0}]
    [convergence_slower_with_speed.otherwise]  # no case holds (verdict "differs" unless stated)
    reason = "..."

A row that cannot be tested has only ``[key.otherwise] verdict = "not testable"`` and a reason;
one whose verdict flips between disjoint seed batches at the book's sample size may state
``verdict = "undecided"`` the same way.

Kinds fix the statistic (the intro defines them for readers): *single-run* (a number the paper
read off one run: is it a plausible draw from our records? decided on a prediction interval over
records, see :func:`railpaper.stats.prediction_interval`), *population* (a rate, trend or absolute
word: a Monte Carlo statistic and its confidence interval), *deterministic* (exact),
*design* (a number our own design choice sets: not a finding) and *implementation* (timing: an
operation count decides, the wall clock is shown beside it).

The vocabulary is enforced here, not left to each rule: a row whose rule would say a decided
verdict while one of its deciding intervals straddles a threshold the deciding conditions read
(:func:`straddled_thresholds`) says ``undecided`` instead, with the interval and the threshold in
its reason.

Condition tests (every metric of ``metrics`` must pass; the reference is ``reference`` (a metric),
else ``value``, else the row's ``paper_value``): ``within_abs`` (|m − ref| ≤ tolerance),
``within_factor`` (m > 0 and ref/factor ≤ m ≤ ref·factor), ``range`` (min ≤ m ≤ max and
above < m < below), ``equals`` (m == ref), ``increasing`` (the metrics in order strictly increase;
``strict = false``: never decrease).
"""

from __future__ import annotations

import math
from numbers import Real

from railpaper.data import DataError

#: Verdicts a rule can give, in the order the ledger counts them.  ``undecided``: our evidence at
#: the book's sample size cannot decide (the interval straddles the rule's threshold, or the
#: verdict flips between disjoint seed batches); ``not testable``: the evidence needed is lost.
#: ``attainable``: a method that is not the paper's (a row with ``method``) shows the claim.
RULE_VERDICTS = ("reproduced", "attainable", "artefact", "differs", "undecided", "not testable")
#: Verdicts that decide (the rest say the evidence cannot).
DECIDED_VERDICTS = ("reproduced", "attainable", "artefact", "differs")
KINDS = ("single-run", "population", "deterministic", "design", "implementation")
REVISION_KEYS = {"what", "when", "why", "original"}
ORIGINAL_KEYS = {"cases", "otherwise", "min_samples", "primary", "interval", "n_samples",
                 "deciding"}
#: Verdicts a row may state without any case (a fixed outcome, said why in its reason).
FIXED_VERDICTS = ("undecided", "not testable")
TESTS = ("within_abs", "within_factor", "range", "equals", "increasing")
ROW_KEYS = {"claim", "source", "group", "reading", "reading_parameter", "rule", "justification",
            "paper_value", "unit", "primary", "primary_unit", "statistic", "interval",
            "n_samples", "min_samples", "deterministic", "metrics", "cases", "otherwise",
            "kind", "method", "deciding", "revised_after_evidence"}


def is_untestable(row: dict) -> bool:
    """A row without cases whose only outcome is fixed (``not testable`` or ``undecided``):
    no rule decides it, so no band guards it."""
    return not row.get("cases") and row.get("otherwise", {}).get("verdict") in FIXED_VERDICTS


def check_row(key: str, row: dict, where: str) -> None:
    """Raise :class:`DataError` (one line) for a row without a usable, documented rule."""
    def fail(message: str):
        raise DataError(f"{where}: claim '{key}': {message}")

    unknown = set(row) - ROW_KEYS
    if unknown:
        fail(f"unknown key '{sorted(unknown)[0]}'")
    for needed in ("claim", "source"):
        if not row.get(needed):
            fail(f"needs '{needed}'")
    if row.get("kind") not in KINDS:
        fail(f"needs 'kind', one of {', '.join(KINDS)}")
    if row["kind"] == "deterministic" and not (row.get("deterministic") or is_untestable(row)):
        fail("kind 'deterministic' needs 'deterministic = true'")
    verdicts = [c.get("verdict") for c in row.get("cases", [])] + [
        row.get("otherwise", {}).get("verdict", "differs")]
    if row.get("method") and "reproduced" in verdicts:
        fail("a row about a method that is not the paper's ('method') says 'attainable', "
             "never 'reproduced'")
    if row["kind"] == "design" and set(verdicts) - {"attainable", "not testable", "undecided"}:
        fail("a design row (a number our own choice sets) says 'attainable', 'not testable' or "
             "'undecided', never a finding")
    if not row.get("method") and "attainable" in verdicts:
        fail("'attainable' is for a method that is not the paper's: name it in 'method'")
    revision = row.get("revised_after_evidence")
    if revision is not None:
        if not isinstance(revision, dict) or set(revision) - REVISION_KEYS or not all(
                revision.get(k) for k in ("what", "when", "why")):
            fail("'revised_after_evidence' needs 'what', 'when', 'why' (and 'original')")
        original = revision.get("original", {})
        if not isinstance(original, dict) or not original or set(original) - ORIGINAL_KEYS:
            fail("'revised_after_evidence.original' states the original rule: some of "
                 f"{', '.join(sorted(ORIGINAL_KEYS))}")
    deciding = row.get("deciding")
    if deciding is not None and (not isinstance(deciding, list) or not all(
            isinstance(p, list) and len(p) == 2 for p in deciding)):
        fail("'deciding' must be a list of [low_metric, high_metric]")
    otherwise = row.get("otherwise", {})
    if otherwise.get("verdict", "differs") not in RULE_VERDICTS or (
            otherwise and "reason" not in otherwise):
        fail(f"'otherwise' needs a reason and a verdict in {', '.join(RULE_VERDICTS)}")
    if is_untestable(row):
        return
    if not row.get("rule"):
        fail("needs 'rule' (the rule in words, fixed from the paper's wording)")
    if "primary" not in row or not row.get("cases"):
        fail("needs 'primary' and at least one [[cases]] (or only otherwise = not testable)")
    if not row.get("deterministic") and "n_samples" not in row:
        fail("needs 'n_samples' (the metric counting its Monte Carlo samples) or "
             "'deterministic = true'")
    if "min_samples" in row and ("n_samples" not in row or not isinstance(
            row["min_samples"], int) or row["min_samples"] < 1):
        fail("'min_samples' needs 'n_samples' and must be a positive integer")
    interval = row.get("interval")
    if interval is not None and (not isinstance(interval, list) or len(interval) != 2):
        fail("'interval' must be [low_metric, high_metric]")
    for case in row["cases"]:
        if case.get("verdict") not in RULE_VERDICTS or "reason" not in case:
            fail(f"each case needs a reason and a verdict in {', '.join(RULE_VERDICTS)}")
        for cond in case.get("when", []):
            if cond.get("test") not in TESTS:
                fail(f"unknown test {cond.get('test')!r} (expected one of {', '.join(TESTS)})")
            if not cond.get("metrics"):
                fail("a condition needs 'metrics'")


def rule_metrics(row: dict) -> list[str]:
    """Every metric a row's verdict and its "ours" read: primary, interval, n_samples, conditions."""
    names = [row["primary"]] if "primary" in row else []
    names += list(row.get("interval", []))
    for pair in row.get("deciding", []):
        names += list(pair)
    if "n_samples" in row:
        names.append(row["n_samples"])
    names += condition_metrics(row)
    return list(dict.fromkeys(names))


def condition_metrics(row: dict) -> list[str]:
    """The metrics the verdict's conditions read (the ones whose bands must decide it)."""
    names = []
    for case in row.get("cases", []):
        for cond in case.get("when", []):
            names += list(cond.get("metrics", []))
            if "reference" in cond:
                names.append(cond["reference"])
    return list(dict.fromkeys(names))


def _reference(cond: dict, row: dict, values: dict):
    if "reference" in cond:
        return values[cond["reference"]]
    return cond.get("value", row.get("paper_value"))


def holds(cond: dict, row: dict, values: dict) -> bool:
    """Whether one condition holds on a run's metric values."""
    xs = [values[name] for name in cond["metrics"]]
    test = cond["test"]
    if test == "increasing":
        pairs = list(zip(xs, xs[1:]))
        return all(b > a if cond.get("strict", True) else b >= a for a, b in pairs)
    if test == "range":
        return all(cond.get("min", -math.inf) <= x <= cond.get("max", math.inf)
                   and cond.get("above", -math.inf) < x < cond.get("below", math.inf) for x in xs)
    ref = _reference(cond, row, values)
    if test == "equals":
        return all(x == ref for x in xs)
    if test == "within_abs":
        return all(abs(x - ref) <= cond["tolerance"] for x in xs)
    factor = cond["factor"]
    return all(x > 0 and ref / factor <= x <= ref * factor for x in xs)


def too_few_samples(row: dict, n) -> str:
    """The reason template of a row decided on fewer samples than its ``min_samples``."""
    return (f"{n} samples are fewer than the {row['min_samples']} this rule needs: below that, "
            "disjoint batches of seeds disagree on the verdict; this run's statistic is shown")


def deciding_intervals(row: dict, values: dict | None = None) -> list[tuple[str, str]]:
    """The row's deciding intervals as (low metric, high metric): ``deciding`` (else
    ``interval``), and every ``<x>_low``/``<x>_high`` pair a condition reads (a mechanism or
    collapse test decides too); the pairs need both ends in ``values`` when it is given."""
    pairs = [tuple(p) for p in row["deciding"]] if "deciding" in row else (
        [tuple(row["interval"])] if "interval" in row else [])
    for name in condition_metrics(row):
        for end in ("_low", "_high"):
            if name.endswith(end):
                stem = name[:-len(end)]
                pair = (stem + "_low", stem + "_high")
                if pair not in pairs and (values is None or all(m in values for m in pair)):
                    pairs.append(pair)
    return pairs


def _interval_metrics(row: dict, pair: tuple[str, str]) -> set[str]:
    """The metrics one deciding interval stands for: its ends, and the primary statistic when
    the pair is the row's ``interval``."""
    names = set(pair)
    if tuple(row.get("interval", ())) == tuple(pair) and "primary" in row:
        names.add(row["primary"])
    return names


def condition_thresholds(cond: dict, row: dict, values: dict) -> list[float]:
    """The values at which one condition changes: range bounds, reference ± tolerance,
    reference ÷× factor, the reference of ``equals``; none for ``increasing`` (it compares
    metrics with each other)."""
    test = cond["test"]
    if test == "increasing":
        return []
    if test == "range":
        return [float(cond[k]) for k in ("min", "max", "above", "below")
                if k in cond and math.isfinite(cond[k])]
    ref = float(_reference(cond, row, values))
    if test == "equals":
        return [ref]
    if test == "within_abs":
        return [ref - cond["tolerance"], ref + cond["tolerance"]]
    return [ref / cond["factor"], ref * cond["factor"]]


def _pair_thresholds(row: dict, pair: tuple[str, str], values: dict) -> list[float]:
    names = _interval_metrics(row, pair)
    out = []
    for case in row.get("cases", []):
        for cond in case.get("when", []):
            if names & set(cond["metrics"]):
                try:
                    out += condition_thresholds(cond, row, values)
                except (KeyError, TypeError, ValueError):
                    pass
    return sorted(set(out))


def _collapsed_points(low: float, high: float, thresholds: list[float]) -> list[float]:
    """The interval's ends and, for every threshold inside or at an end, the threshold and its
    neighbouring floats: the points where a verdict can change."""
    points = {low, high}
    for t in thresholds:
        if low <= t <= high:
            points |= {t, math.nextafter(t, -math.inf), math.nextafter(t, math.inf)}
    return sorted(x for x in points if low <= x <= high)


def straddled_thresholds(row: dict, values: dict) -> list[tuple[str, str, float]]:
    """(low metric, high metric, point) for every deciding interval across which the rule's
    verdict changes on this run.

    Each deciding interval (:func:`deciding_intervals`) is collapsed in turn to points across
    it (its ends, and either side of every threshold it holds), the other metrics kept; if the
    rule gives more than one verdict over those points, a value of the statistic inside its own
    interval would be judged otherwise: the intro calls that *undecided*.
    """
    out = []
    for pair in deciding_intervals(row, values):
        low, high = values[pair[0]], values[pair[1]]
        if not all(_finite_number(v) for v in (low, high)):
            continue
        names = _interval_metrics(row, pair)
        thresholds = _pair_thresholds(row, pair, values)
        first = None
        for x in _collapsed_points(low, high, thresholds):
            verdict = rule_verdict(row, dict(values, **dict.fromkeys(names, x)))[0]
            if first is None:
                first = verdict
            elif verdict != first:
                # the threshold where the verdict changes: the nearest one to this point
                near = min(thresholds, key=lambda t: abs(t - x)) if thresholds else x
                out.append((pair[0], pair[1], near))
                break
    return out


def _finite_number(value) -> bool:
    return isinstance(value, Real) and not isinstance(value, bool) and math.isfinite(value)


def straddle_reason(row: dict, values: dict, found: list[tuple[str, str, float]],
                    verdict: str) -> str:
    """The reason template of a row made undecided because its interval straddles a threshold."""
    low_name, high_name, t = found[0]
    low, high = values[low_name], values[high_name]
    n = f", n = {{{row['n_samples']}}}" if "n_samples" in row else ""
    text = (f"cannot tell: the 95 % interval [{low:.4g}, {high:.4g}]{n} straddles the rule's "
            f"threshold {t:.4g} (the rule alone would say {verdict})")
    samples = values.get(row.get("n_samples"))
    centre = values.get(row.get("primary"))
    # the estimate holds for a confidence interval of the row's own statistic; a prediction
    # interval's ends do not narrow with n, and another pair's centre is not the primary
    own = tuple(row.get("interval", ())) == (low_name, high_name) and row.get("kind") != \
        "single-run"
    if own and _finite_number(samples) and _finite_number(centre) and centre != t \
            and low <= centre <= high:
        # an interval narrows as 1/sqrt(n): the size at which it would clear t if the statistic
        # stayed where it is (an estimate, said as such)
        half = (high - low) / 2
        needed = math.ceil(samples * (half / abs(centre - t)) ** 2)
        text += (f"; about {needed} samples would decide it if the statistic stayed at "
                 f"{centre:.4g} (the interval narrows as 1/√n)")
    return text


def rule_verdict(row: dict, values: dict) -> tuple[str, str, int | None]:
    """(verdict, reason template, index of the deciding case or None) of the rule alone: the
    first case that holds, else ``otherwise``; before the vocabulary is applied."""
    for index, case in enumerate(row.get("cases", [])):
        if all(holds(cond, row, values) for cond in case.get("when", [])):
            return case["verdict"], case["reason"], index
    fallback = row.get("otherwise", {})
    return fallback.get("verdict", "differs"), fallback.get("reason", ""), None


def verdict_on_run(row: dict, values: dict) -> tuple[str, str]:
    """(verdict, reason template) of a row on a run's metric values.

    ``undecided`` when the run has fewer samples than the row's ``min_samples``, or when the
    rule's verdict is decided but a deciding interval straddles one of its thresholds
    (:func:`straddled_thresholds`); else the rule's own verdict.
    """
    if "min_samples" in row and values[row["n_samples"]] < row["min_samples"]:
        return "undecided", too_few_samples(row, values[row["n_samples"]])
    verdict, reason, _ = rule_verdict(row, values)
    if verdict in DECIDED_VERDICTS:
        found = straddled_thresholds(row, values)
        if found:
            return "undecided", straddle_reason(row, values, found, verdict)
    return verdict, reason


def verdict_as_written(row: dict, values: dict) -> tuple[str, str]:
    """(verdict, reason template) of the rule as its cases say, with its ``min_samples`` but
    without the vocabulary check of :func:`verdict_on_run`: what an original rule said."""
    if "min_samples" in row and values[row["n_samples"]] < row["min_samples"]:
        return "undecided", too_few_samples(row, values[row["n_samples"]])
    return rule_verdict(row, values)[:2]


def original_rule(row: dict) -> dict | None:
    """The row as it stood before ``revised_after_evidence`` (None if never revised): the
    original's ``cases``, ``otherwise``, statistic (``primary``, ``interval``, ``n_samples``,
    ``deciding``) and ``min_samples`` (0 = none) replace the row's."""
    revision = row.get("revised_after_evidence")
    if not revision:
        return None
    before = {k: v for k, v in row.items() if k != "revised_after_evidence"}
    original = revision.get("original", {})
    for key in ("cases", "otherwise", "primary", "interval", "n_samples"):
        if key in original:
            before[key] = original[key]
    before.pop("deciding", None)                   # the original read its own interval
    if "deciding" in original:
        before["deciding"] = original["deciding"]
    if "min_samples" in original:
        before.pop("min_samples", None)
        if original["min_samples"]:
            before["min_samples"] = original["min_samples"]
    return before


# ---- over tolerance bands: three-valued logic (True, False, None = depends on where in the band)

def _tri_all(values) -> bool | None:
    values = list(values)
    if any(v is False for v in values):
        return False
    return True if all(v is True for v in values) else None


def _range_box(lo: float, hi: float, cond: dict) -> bool | None:
    mn, mx = cond.get("min", -math.inf), cond.get("max", math.inf)
    above, below = cond.get("above", -math.inf), cond.get("below", math.inf)
    if mn <= lo and hi <= mx and above < lo and hi < below:
        return True
    if hi < mn or lo > mx or hi <= above or lo >= below:
        return False
    return None


def holds_over_bands(cond: dict, row: dict, bands: dict[str, tuple[float, float]]) -> bool | None:
    """Whether a condition holds for every (True), no (False) or some (None) point of the bands.

    ``bands[metric] = (low, high)``: every value a run passing ``railpaper check`` can have.
    """
    boxes = [bands[name] for name in cond["metrics"]]
    test = cond["test"]
    if test == "increasing":
        strict = cond.get("strict", True)
        out = []
        for (alo, ahi), (blo, bhi) in zip(boxes, boxes[1:]):
            if (ahi < blo) if strict else (ahi <= blo):
                out.append(True)
            elif (bhi <= alo) if strict else (bhi < alo):
                out.append(False)
            else:
                out.append(None)
        return _tri_all(out)
    if test == "range":
        return _tri_all(_range_box(lo, hi, cond) for lo, hi in boxes)
    rlo, rhi = bands[cond["reference"]] if "reference" in cond else (
        (_reference(cond, row, {}),) * 2)
    out = []
    for lo, hi in boxes:
        if test == "equals":
            out.append(True if lo == hi == rlo == rhi else False if (hi < rlo or lo > rhi) else None)
        elif test == "within_abs":
            dlo, dhi, tol = lo - rhi, hi - rlo, cond["tolerance"]
            out.append(True if max(abs(dlo), abs(dhi)) <= tol else
                       False if (dlo > tol or dhi < -tol) else None)
        else:                                                   # within_factor, ref > 0
            f = cond["factor"]
            out.append(True if (lo > 0 and rhi / f <= lo and hi <= rlo * f) else
                       False if (hi <= 0 or hi < rlo / f or lo > rhi * f) else None)
    return _tri_all(out)


def _straddle_over_bands(row: dict, bands: dict[str, tuple[float, float]]) -> bool | None:
    """Whether a deciding interval holds a threshold across which the verdict changes for every
    (True), no (False) or some (None) point of the bands (the run-level test is
    :func:`straddled_thresholds`)."""
    states = []
    mid = {m: (lo + hi) / 2 for m, (lo, hi) in bands.items()}
    for pair in deciding_intervals(row, bands):
        names = _interval_metrics(row, pair)
        if not names <= set(bands):
            continue
        (low_min, low_max), (high_min, high_max) = bands[pair[0]], bands[pair[1]]
        for t in _pair_thresholds(row, pair, mid):
            sides = [verdicts_over_bands(row, dict(bands, **dict.fromkeys(names, (x, x))),
                                         straddle=False)
                     for x in (math.nextafter(t, -math.inf), t, math.nextafter(t, math.inf))]
            if sides[0] == sides[1] == sides[2]:
                continue                          # the same verdicts on both sides of t
            states.append(True if low_max < t < high_min else
                          None if low_min <= t <= high_max else False)
    if any(state is True for state in states):
        return True
    return None if any(state is None for state in states) else False


def verdicts_over_bands(row: dict, bands: dict[str, tuple[float, float]],
                        straddle: bool = True) -> set[str]:
    """Every verdict a run whose condition metrics lie anywhere in ``bands`` can get.

    One element: the bands decide the verdict, so a change that flips it fails the check.
    A decided verdict whose deciding interval may straddle a threshold adds ``undecided``
    (:func:`verdict_on_run` applies the same vocabulary on a run).
    """
    possible = set()
    if "min_samples" in row:
        n_low, n_high = bands[row["n_samples"]]
        if n_high < row["min_samples"]:
            return {"undecided"}
        if n_low < row["min_samples"]:
            possible.add("undecided")

    straddles = []                                # computed once, on the first decided verdict

    def add(verdict: str) -> None:
        if straddle and verdict in DECIDED_VERDICTS and not straddles:
            straddles.append(_straddle_over_bands(row, bands))
        state = straddles[0] if straddle and verdict in DECIDED_VERDICTS else False
        if state is not True:
            possible.add(verdict)
        if state is not False:
            possible.add("undecided")

    for case in row.get("cases", []):
        state = _tri_all(holds_over_bands(c, row, bands) for c in case.get("when", []))
        if state is False:
            continue
        add(case["verdict"])
        if state is True:
            return possible
    add(row.get("otherwise", {}).get("verdict", "differs"))
    return possible
