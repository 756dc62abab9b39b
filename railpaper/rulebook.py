"""The ledger's rulebook: one decision procedure per kind of claim, fixed before the numbers.

A claim is declared as data (its words, kind, word class, metrics, the paper's value); the word
class maps, once for the whole book, to a procedure and its threshold or margin
(``data/vocabulary.toml``).  Each procedure here is a pure function of the evidence and those
book-wide numbers → a :class:`Decision` (verdict, reason, statistic and interval); none reads a
threshold of a claim's own.

* :func:`single_run` — numbers a paper read off one run or figure, judged jointly as one draw:
  the depth of the paper's draw among our records (the smallest two-sided mid-rank tail
  probability over the figure's numbers), its Monte Carlo p-value with a Clopper–Pearson
  interval against α;
* :func:`population_rate` — a rate k/n with its Clopper–Pearson interval against the word's
  threshold (½ for majority words, 1 − ε for absolute ones);
* :func:`paired_change` — a trend or comparison: the paired relative change of the means with
  its interval against the book-wide margin, in the claimed direction;
* :func:`equivalence` — similarity or absence: two one-sided tests against ±margin;
  :func:`departure` — a claimed offset ('biased'), its mirror;
* :func:`deterministic`, :func:`design`, :func:`implementation` — exact values, stated checks
  and rates; :func:`cost_ratio` — a time ratio or share measured on this machine;
* :func:`attainable` (procedure version 4) — a *reproduced* read off a method that is not the
  paper's (declared blind per reading, ``data/<chapter>/methods.toml``) is *attainable*;
  :func:`not_the_papers` (version 5) also makes a *differs* there *not testable*;
* :func:`soundness` (procedure version 2; version 3 applies it only to the estimators a row
  credits) — a *reproduced* read off an estimator that misses the exact posterior on most of
  the same records is an *artefact*.

Sample sizes come from power, before the deciding run (:func:`rate_size`,
:func:`continuous_size`, :func:`single_run_size`).

>>> population_rate(k=58, n=60, threshold=0.5).verdict
'reproduced'
>>> population_rate(k=58, n=60, threshold=0.95).verdict
'undecided'
>>> paired_change([10, 12, 11, 13], [13, 15, 14, 16], direction="increase", margin=0.1).verdict
'reproduced'
"""

from __future__ import annotations

import dataclasses
import math
import tomllib
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Sequence

import numpy as np
from scipy import stats as scipy_stats

from railpaper.paths import DATA_DIR

VOCABULARY_FILE = DATA_DIR / "vocabulary.toml"
VERDICTS = ("reproduced", "attainable", "artefact", "differs", "undecided", "not testable")
PROCEDURES = ("single-run", "population-rate", "paired-change", "equivalence", "departure",
              "deterministic", "design", "implementation")
DIRECTIONS = ("increase", "decrease")


@dataclass(frozen=True)
class Decision:
    """A verdict with the statistic and interval it was read from (None where there is none)."""

    verdict: str
    reason: str
    statistic: float | None = None
    low: float | None = None
    high: float | None = None
    n: int | None = None

    def __post_init__(self) -> None:
        if self.verdict not in VERDICTS:
            raise ValueError(f"verdict {self.verdict!r} is not one of {', '.join(VERDICTS)}")


@dataclass(frozen=True)
class Vocabulary:
    """``data/vocabulary.toml``: the book-wide policy and the word classes."""

    policy: dict[str, Any]
    classes: dict[str, dict[str, Any]]

    @classmethod
    def load(cls, path: Path = VOCABULARY_FILE) -> "Vocabulary":
        data = tomllib.loads(Path(path).read_text())
        vocabulary = cls(policy=data["policy"], classes=data["classes"])
        for name, entry in vocabulary.classes.items():
            if entry["procedure"] not in PROCEDURES:
                raise ValueError(f"{path}: class {name!r} names an unknown procedure "
                                 f"{entry['procedure']!r}")
        return vocabulary

    def entry(self, word_class: str) -> dict[str, Any]:
        """The class's entry; a one-line error naming the classes for an unknown one."""
        if word_class not in self.classes:
            raise KeyError(f"no word class {word_class!r} in the vocabulary; classes: "
                           f"{', '.join(sorted(self.classes))}")
        return self.classes[word_class]


def clopper_pearson(k: int, n: int, level: float = 0.95) -> tuple[float, float]:
    """Exact binomial interval of k/n: ``Beta(α/2; k, n−k+1)`` and ``Beta(1−α/2; k+1, n−k)``."""
    if not 0 <= k <= n or n < 1:
        raise ValueError(f"need 0 <= k <= n and n >= 1, got k = {k}, n = {n}")
    alpha = 1.0 - level
    low = 0.0 if k == 0 else float(scipy_stats.beta.ppf(alpha / 2, k, n - k + 1))
    high = 1.0 if k == n else float(scipy_stats.beta.ppf(1 - alpha / 2, k + 1, n - k))
    return low, high


def mid_rank_tail(sample: Sequence[float], x: float) -> float:
    """Two-sided mid-rank tail probability of ``x`` among ``sample``: ``min(1, 2 min(F, 1 − F))``
    with ``F = (#{s < x} + ½ #{s = x}) / n``.  1 at the sample's median, small in its tails."""
    sample = np.asarray(sample, dtype=float)
    below = np.count_nonzero(sample < x)
    equal = np.count_nonzero(sample == x)
    cdf = (below + 0.5 * equal) / sample.size
    return float(min(1.0, 2.0 * min(cdf, 1.0 - cdf)))


def most_favourable(sample: Sequence[float], value: float, resolution: float) -> float:
    """The value within the printed resolution (``value ± resolution / 2``) nearest the sample's
    median: where the tail probability is largest (F is monotone, so that is the clipped
    median)."""
    return float(np.clip(np.median(sample), value - resolution / 2, value + resolution / 2))


def single_run(records: np.ndarray, paper_values: Sequence[float],
               resolution: Sequence[float], alpha: float = 0.05,
               level: float = 0.95) -> Decision:
    """The depth test of numbers a paper read off one run (one figure, one horizon).

    Parameters
    ----------
    records : array (n, k)
        Our records' values of the figure's k numbers, at the declared horizon.
    paper_values, resolution : length k
        The paper's numbers and their printed resolution (a value read as 9 from a plot whose
        ticks are 5 apart has resolution 5: anything in 6.5..11.5 is the same reading).

    For each record r, ``T_r`` = the smallest :func:`mid_rank_tail` of its k numbers among all
    records' (column by column); ``T_paper`` likewise at each number's :func:`most_favourable`
    value.  ``p = (1 + #{T_r ≤ T_paper}) / (n + 1)``.  With the Clopper–Pearson interval of
    ``#{T_r ≤ T_paper} / n``: *differs* when its upper bound is below α (the paper's draw is
    less typical than α of ours), *reproduced* (a plausible draw) when its lower bound is above
    α, else *undecided*.
    """
    records = np.asarray(records, dtype=float)
    if records.ndim != 2 or records.shape[1] != len(paper_values) != 0:
        raise ValueError(f"records must be (n, {len(paper_values)}), got {records.shape}")
    n, k = records.shape
    depth = np.array([min(mid_rank_tail(records[:, j], records[r, j]) for j in range(k))
                      for r in range(n)])
    favourable = [most_favourable(records[:, j], paper_values[j], resolution[j]) for j in range(k)]
    depth_paper = min(mid_rank_tail(records[:, j], favourable[j]) for j in range(k))
    as_extreme = int(np.count_nonzero(depth <= depth_paper))
    p_value = (1 + as_extreme) / (n + 1)
    low, high = clopper_pearson(as_extreme, n, level)
    text = (f"the paper's {k} number(s) jointly as typical as {as_extreme} of our {n} records "
            f"(p = {p_value:.3g}, interval {low:.3g}–{high:.3g}, α = {alpha:g})")
    note = ""
    if np.isin(records, (0.0, 1.0)).all():
        # a yes/no outcome: the depth test asks only whether it happens at all (a blind reader's
        # note, data/rbpf-parameter-estimation/blind/dispute3_reply.md)
        share = np.mean((records == np.asarray(paper_values, dtype=float)[None, :]).all(axis=1))
        note = (f" (on yes/no numbers this asks only whether the paper's outcome happens on more "
                f"than about α of our records, here {share:.3g}, not how often: a rate row "
                "reads that)")
    if high < alpha:
        return Decision("differs", f"{text}: not a plausible draw{note}", p_value, low, high, n)
    if low > alpha:
        return Decision("reproduced", f"{text}: a plausible draw{note}", p_value, low, high, n)
    return Decision("undecided", f"{text}: the interval straddles α{note}", p_value, low, high,
                    n)


def population_rate(k: int, n: int, threshold: float, direction: str = "at least",
                    level: float = 0.95) -> Decision:
    """A rate claimed at least (or at most) ``threshold``: *reproduced* when its
    Clopper–Pearson interval lies wholly on the claimed side, *differs* when wholly on the
    other, *undecided* when it contains the threshold."""
    low, high = clopper_pearson(k, n, level)
    rate = k / n
    text = f"rate {k}/{n} = {rate:.3g} [{low:.3g}, {high:.3g}] against {threshold:g}"
    if direction == "at least":
        claimed, other = low > threshold, high < threshold
    elif direction == "at most":
        claimed, other = high < threshold, low > threshold
    else:
        raise ValueError(f"direction must be 'at least' or 'at most', got {direction!r}")
    if claimed:
        return Decision("reproduced", f"{text}: wholly {direction} it", rate, low, high, n)
    if other:
        return Decision("differs", f"{text}: wholly on the other side", rate, low, high, n)
    return Decision("undecided", f"{text}: the interval contains it", rate, low, high, n)


def _delta_terms(baseline: Sequence[float], other: Sequence[float]) -> tuple[float, float, float]:
    """``r = mean(B − A) / mean(A)``, ``sd(u)`` of ``u_i = (B_i − A_i) − r A_i`` and ``mean(A)``."""
    a, b = np.asarray(baseline, dtype=float), np.asarray(other, dtype=float)
    if a.shape != b.shape or a.ndim != 1 or a.size < 2:
        raise ValueError(f"need two paired samples of at least 2 values, got {a.shape}, {b.shape}")
    mean_a = float(np.mean(a))
    if mean_a == 0.0:
        raise ValueError("the baseline's mean is 0: a relative change is undefined")
    r = float(np.mean(b - a)) / mean_a
    return r, float(np.std((b - a) - r * a, ddof=1)), mean_a


def relative_change_sd(baseline: Sequence[float], other: Sequence[float]) -> tuple[float, float]:
    """``r`` and the per-record standard deviation of its delta-method linearisation,
    ``sd(u) / |mean(A)|`` (the σ a size by power reads)."""
    r, sd_u, mean_a = _delta_terms(baseline, other)
    return r, sd_u / abs(mean_a)


def relative_change(baseline: Sequence[float], other: Sequence[float],
                    level: float = 0.95) -> tuple[float, float, float]:
    """Paired relative change of the means, ``r = mean(B − A) / mean(A)``, with the
    delta-method interval: ``u_i = (B_i − A_i) − r A_i``, ``se = sd(u) / (√n |mean(A)|)``,
    ``r ± t_{n−1} se``."""
    r, sd_u, mean_a = _delta_terms(baseline, other)
    n = len(baseline)
    se = sd_u / (math.sqrt(n) * abs(mean_a))
    t = float(scipy_stats.t.ppf(0.5 + level / 2, n - 1))
    return r, r - t * se, r + t * se


def paired_change(baseline: Sequence[float], other: Sequence[float], direction: str,
                  margin: float, level: float = 0.95) -> Decision:
    """A trend or comparison: the paired relative change from ``baseline`` to ``other`` in the
    claimed ``direction`` ('increase' or 'decrease'), against the margin m: *reproduced* when
    its interval lies beyond +m, *differs* when wholly below +m (no visible effect, or the
    opposite), *undecided* when it straddles +m."""
    if direction not in DIRECTIONS:
        raise ValueError(f"direction must be one of {DIRECTIONS}, got {direction!r}")
    r, low, high = relative_change(baseline, other, level)
    sign = 1.0 if direction == "increase" else -1.0
    e_low, e_high = min(sign * low, sign * high), max(sign * low, sign * high)
    text = (f"relative change {r:+.3g} [{low:+.3g}, {high:+.3g}] (n = {len(baseline)}); claimed "
            f"{direction} beyond {margin:g}")
    # the statistic shown is the signed relative change r itself (a reader compares it with the
    # claimed direction); the verdict reads its interval turned into the claimed direction
    if e_low > margin:
        return Decision("reproduced", f"{text}: wholly beyond it", r, low, high, len(baseline))
    if e_high < margin:
        return Decision("differs", f"{text}: wholly short of it", r, low, high, len(baseline))
    return Decision("undecided", f"{text}: the interval straddles it", r, low, high,
                    len(baseline))


def equivalence(deviations: Sequence[float] | None = None, margin: float = 0.1,
                level: float = 0.95, *, baseline: Sequence[float] | None = None,
                other: Sequence[float] | None = None) -> Decision:
    """Similarity or absence by two one-sided tests at α = (1 − level) / 2 each.

    Either relative ``deviations`` (e.g. each record's bias over the true value; their mean
    with Student's t interval) or a paired ``baseline`` and ``other`` (their
    :func:`relative_change`).  *reproduced* when the (2 level − 1) interval — 90 % at 95 % —
    lies within ±m; *differs* when the ``level`` interval lies wholly outside ±m; else
    *undecided*.
    """
    tost_level = 2 * level - 1
    if deviations is not None:
        d = np.asarray(deviations, dtype=float)
        if d.ndim != 1 or d.size < 2:
            raise ValueError("need at least 2 deviations")
        mean, sd, n = float(np.mean(d)), float(np.std(d, ddof=1)), d.size

        def interval(lev):
            half = float(scipy_stats.t.ppf(0.5 + lev / 2, n - 1)) * sd / math.sqrt(n)
            return mean - half, mean + half
        statistic = mean
    else:
        n = len(baseline)
        statistic = relative_change(baseline, other, level)[0]

        def interval(lev):
            return relative_change(baseline, other, lev)[1:]
    t_low, t_high = interval(tost_level)
    low, high = interval(level)
    what = "mean relative deviation" if deviations is not None else "relative difference"
    text = (f"{what} {statistic:+.3g}, {tost_level:.0%} interval [{t_low:+.3g}, "
            f"{t_high:+.3g}] (n = {n}) against ±{margin:g}")
    if -margin < t_low and t_high < margin:
        return Decision("reproduced", f"{text}: within it", statistic, t_low, t_high, n)
    if low > margin or high < -margin:
        return Decision("differs", f"{text}: the {level:.0%} interval [{low:+.3g}, {high:+.3g}] "
                        "wholly beyond it", statistic, low, high, n)
    return Decision("undecided", f"{text}: not within it", statistic, t_low, t_high, n)


def departure(deviations: Sequence[float] | None = None, margin: float = 0.1,
              level: float = 0.95, *, baseline: Sequence[float] | None = None,
              other: Sequence[float] | None = None) -> Decision:
    """A claimed offset ('biased'): the mirror of :func:`equivalence` on the same intervals.
    *reproduced* when the ``level`` interval lies wholly beyond ±m (an offset a reader would
    see), *differs* when the (2 level − 1) interval lies within ±m (no visible offset), else
    *undecided*.

    >>> departure([0.30, 0.32, 0.31, 0.29], margin=0.1).verdict
    'reproduced'
    >>> departure([0.01, -0.01, 0.0, 0.005], margin=0.1).verdict
    'differs'
    """
    mirror = equivalence(deviations, margin, level, baseline=baseline, other=other)
    verdict = {"reproduced": "differs", "differs": "reproduced"}.get(mirror.verdict,
                                                                    "undecided")
    reason = mirror.reason.replace(": within it", ": within it, no visible offset").replace(
        ": not within it", ": neither wholly beyond nor within it")
    return Decision(verdict, f"claimed offset beyond ±{margin:g}; {reason}", mirror.statistic,
                    mirror.low, mirror.high, mirror.n)


def soundness(decision: Decision, estimator: str, sound: int, n: int, threshold: float = 0.5,
              level: float = 0.95) -> Decision:
    """A verdict read off an estimator's output, checked against that estimator's soundness
    on the same records: ``sound`` of ``n`` records where its final estimate lies within two
    standard deviations of the *exact* posterior of the record from that posterior's mean, for
    every parameter (it computes, up to its noise, the answer it is meant to approximate).  A
    *reproduced* becomes an *artefact* when the Clopper–Pearson interval of ``sound / n`` lies
    wholly below ``threshold``: the claimed number (a convergence step, an error, a gain) comes
    from a filter that misses the exact posterior on most records.  Every other verdict, and a
    sound estimator's, keeps its verdict (a passed check says so in the reason).  Only studies
    whose records have their exact posterior carry the columns this reads (chapter 004's in the
    filters' own rows; chapter 003's joined from its posterior studies); which estimators a row
    is checked against is the caller's
    (:func:`railpaper.pipeline.declarations.estimators_credited`, version 3).

    >>> soundness(Decision("reproduced", "settles at step 4"), "qgrbpf", 8, 150).verdict
    'artefact'
    >>> soundness(Decision("reproduced", "settles at step 4"), "qgrbpf", 70, 150).verdict
    'reproduced'
    """
    if decision.verdict != "reproduced":
        return decision
    low, high = clopper_pearson(sound, n, level)
    if high >= threshold:                       # checked and passed: the reason says so
        return dataclasses.replace(decision, reason=(
            f"{decision.reason}; the {estimator} ends within two exact-posterior standard "
            f"deviations of the exact posterior mean on {sound}/{n} of these records "
            f"[{low:.3g}, {high:.3g}], not wholly below {threshold:g}: checked"))
    return dataclasses.replace(decision, verdict="artefact", reason=(
        f"{decision.reason}; but the {estimator} ends within two exact-posterior standard "
        f"deviations of the exact posterior mean on only {sound}/{n} of these records "
        f"[{low:.3g}, {high:.3g}], wholly below {threshold:g}: the number comes from a filter "
        "that misses the posterior it approximates"))


def attainable(decision: Decision, why: str) -> Decision:
    """A verdict read off a method or design that is not the paper's (procedure version 4): a
    *reproduced* becomes *attainable* — the claim holds, but with our method, not the paper's,
    so it is never counted as reproduced.  ``why`` says whose method it is.  Every other
    verdict is returned as it is (a *differs* from our method still says the claim does not
    hold there).

    >>> attainable(Decision("reproduced", "settles at step 4"), "our observer").verdict
    'attainable'
    >>> attainable(Decision("differs", "settles at step 40"), "our observer").verdict
    'differs'
    """
    if decision.verdict != "reproduced":
        return decision
    return dataclasses.replace(decision, verdict="attainable", reason=(
        f"{decision.reason}; but the numbers come from a method that is not the paper's ({why})"))


def not_the_papers(decision: Decision, why: str) -> Decision:
    """A verdict read off a method or design that is not the paper's (procedure version 5,
    symmetric to :func:`attainable`): a *reproduced* becomes *attainable*, and a *differs*
    becomes *not testable* — our method failing to show a claim says nothing about the paper's
    method, just as its showing it proves nothing for the paper.  Every other verdict is
    returned as it is.

    >>> not_the_papers(Decision("differs", "settles at step 40"), "our observer").verdict
    'not testable'
    >>> not_the_papers(Decision("reproduced", "settles at step 4"), "our observer").verdict
    'attainable'
    """
    if decision.verdict == "differs":
        return dataclasses.replace(decision, verdict="not testable", reason=(
            f"{decision.reason}; but the numbers come from a method that is not the paper's "
            f"({why}): that it does not show the claim says nothing about the paper's method"))
    return attainable(decision, why)


def measured_only(decision: Decision, why: str) -> Decision:
    """A claim whose only evidence in the paper is data measured on a physical vehicle, line or
    rig that the book cannot obtain or regenerate (procedure version 6): *not testable*,
    whatever our simulated records give; their statistic stays shown, and the readings that
    simulate the claim are rows of their own beside it.

    >>> measured_only(Decision("reproduced", "within 5 % on 597 of 597"), "one line record"
    ...               ).verdict
    'not testable'
    """
    return dataclasses.replace(decision, verdict="not testable", reason=(
        f"{MEASURED_ONLY} ({why}); our simulated records, beside it, gave: {decision.verdict}, "
        f"{decision.reason}"))


#: How :func:`measured_only`'s reason opens (the ledger's plain sentence reads it).
MEASURED_ONLY = "the paper's only evidence is measured data the book cannot obtain or regenerate"


def deterministic(value: float, paper_value: float, resolution: float = 0.0) -> Decision:
    """An exact quantity: *reproduced* when ``|value − paper_value| ≤ resolution / 2`` (the
    paper's printed precision), else *differs*."""
    gap = abs(float(value) - float(paper_value))
    text = f"ours {value:g}, the paper's {paper_value:g} (printed to ±{resolution / 2:g})"
    return Decision("reproduced" if gap <= resolution / 2 else "differs", text, float(value))


def design(check: bool, what: str) -> Decision:
    """A statement of what the authors built, checked by a stated boolean ``what``."""
    return Decision("reproduced" if check else "differs", f"{what}: {'yes' if check else 'no'}")


def implementation(measured_rate_hz: float | None, required_rate_hz: float | None,
                   source: str = "") -> Decision:
    """A speed claim: *not testable* without a rate the paper states or implies for its own
    problem; else *reproduced* when our measured rate meets it."""
    if required_rate_hz is None:
        return Decision("not testable", "the paper states no rate its problem needs")
    if measured_rate_hz is None:
        return Decision("undecided", f"no measured rate against {required_rate_hz:g} Hz")
    met = measured_rate_hz >= required_rate_hz
    return Decision("reproduced" if met else "differs",
                    f"{measured_rate_hz:.4g} Hz measured on this machine against the "
                    f"{required_rate_hz:g} Hz {source or 'required'}", measured_rate_hz)


def cost_ratio(ratio: float, low: float, high: float, direction: str, margin: float,
               share: bool = False) -> Decision:
    """A computing-cost claim measured on this machine: a time ratio (other / baseline) or a
    share of a time (part / whole) with its interval [``low``, ``high``] from paired repeats.

    A ratio is read like a trend on r − 1: for 'decrease', *reproduced* when ``high`` < 1 − m,
    *differs* when ``low`` ≥ 1 − m, else *undecided*; 'increase' mirrors it about 1 + m.  A
    ``share`` ('most of the cost') is read like a majority rate: *reproduced* when ``low`` > ½,
    *differs* when ``high`` ≤ ½, else *undecided*.

    >>> cost_ratio(0.5, 0.45, 0.55, "decrease", 0.1).verdict
    'reproduced'
    >>> cost_ratio(0.95, 0.92, 0.98, "decrease", 0.1).verdict
    'differs'
    >>> cost_ratio(0.2, 0.15, 0.25, "increase", 0.1, share=True).verdict
    'differs'
    """
    if direction not in DIRECTIONS:
        raise ValueError(f"direction must be one of {DIRECTIONS}, got {direction!r}")
    text = (f"{ratio:.3g} (an exact count)" if low == high == ratio else
            f"{ratio:.3g} [{low:.3g}, {high:.3g}] on this machine")
    if share:
        bar, beyond, short = 0.5, low > 0.5, high <= 0.5
        text += "; claimed: more than one half"
    elif direction == "decrease":
        bar = 1.0 - margin
        beyond, short = high < bar, low >= bar
        text += f"; claimed: below {bar:g}"
    else:
        bar = 1.0 + margin
        beyond, short = low > bar, high <= bar
        text += f"; claimed: above {bar:g}"
    verdict = "reproduced" if beyond else "differs" if short else "undecided"
    tail = {"reproduced": "wholly beyond it", "differs": "wholly short of it",
            "undecided": "the interval straddles it"}[verdict]
    return Decision(verdict, f"{text}: {tail}", float(ratio), float(low), float(high))


def _z_sum(level: float, power: float) -> float:
    return float(scipy_stats.norm.ppf(0.5 + level / 2) + scipy_stats.norm.ppf(power))


def continuous_size(sigma: float, margin: float, level: float = 0.95, power: float = 0.8) -> int:
    """Records for a continuous statistic: ``n = ((z_{1−α/2} + z_{power}) σ / m)²``, rounded
    up, σ the per-record standard deviation of the effect (from pilot seeds kept apart from the
    deciding seeds), m the margin."""
    if sigma < 0 or margin <= 0:
        raise ValueError(f"need sigma >= 0 and margin > 0, got {sigma}, {margin}")
    return max(2, math.ceil((_z_sum(level, power) * sigma / margin) ** 2))


def rate_size(threshold: float, margin: float, level: float = 0.95, power: float = 0.8) -> int:
    """Records for a rate against ``threshold``: :func:`continuous_size` with σ² = τ(1 − τ), the
    binomial variance at the threshold (¼ for majority words)."""
    return continuous_size(math.sqrt(threshold * (1 - threshold)), margin, level, power)


def single_run_size(alpha: float, resolution: float, level: float = 0.95,
                    power: float = 0.8) -> int:
    """Records for the depth test: the p-value is a rate, resolved to ±``resolution`` around α
    (:func:`rate_size` at τ = α)."""
    return rate_size(alpha, resolution, level, power)


__all__ = ["DIRECTIONS", "Decision", "MEASURED_ONLY", "PROCEDURES", "VERDICTS", "VOCABULARY_FILE",
           "Vocabulary", "clopper_pearson", "continuous_size", "cost_ratio", "departure",
           "deterministic", "design", "equivalence", "implementation", "measured_only",
           "mid_rank_tail", "most_favourable", "paired_change", "population_rate", "rate_size",
           "relative_change", "relative_change_sd", "single_run", "single_run_size", "soundness"]
