"""Claims as data: parsing refuses thresholds of a row's own, the fingerprint catches every
change a verdict could feel and nothing else, the registry keeps the previous declaration, and
each procedure decides a hand-made table."""

from __future__ import annotations

import copy
import dataclasses

import numpy as np
import pandas as pd
import pytest

from railpaper.data import DataError
from railpaper.pipeline import declarations
from railpaper.pipeline.declarations import (
    check_registry,
    decide,
    estimators_read,
    fingerprint,
    parse,
    register,
    procedure_reregistrations,
    registered_size,
    revisions,
)
from railpaper.rulebook import Vocabulary

VOCABULARY = Vocabulary.load()
TREND = {"id": "longer_with_speed", "claim": "convergence takes longer as the speed rises",
         "words": "the convergence time becomes longer as the speed increases",
         "source": "paper 001, abstract", "kind": "population", "word_class": "trend",
         "study": "monte_carlo", "metrics": ["time_s_60kmh", "time_s_200kmh"],
         "direction": "increase", "central": True}


def declaration(**changes):
    return parse("demo", dict(TREND, **changes), VOCABULARY)


def test_a_row_carries_no_threshold_of_its_own():
    with pytest.raises(DataError, match="margin belong to the rulebook"):
        declaration(margin=0.2)
    with pytest.raises(DataError, match="cases, rule belong"):
        declaration(rule="reproduced if ...", cases=[])
    with pytest.raises(DataError, match="unknown keys colour"):
        declaration(colour="red")


def test_the_class_must_decide_the_kind_and_the_row_must_fit_the_procedure():
    with pytest.raises(DataError, match="does not decide a single-run claim"):
        declaration(kind="single-run")
    with pytest.raises(DataError, match="no word class 'often'"):
        declaration(word_class="often")
    with pytest.raises(DataError, match="direction increase or decrease"):
        declaration(direction="up")
    with pytest.raises(DataError, match="names the study"):
        declaration(study="")
    with pytest.raises(DataError, match="declares its horizon"):
        declaration(kind="single-run", word_class="value", metrics=["a"], paper_value=[1.0])


def test_fingerprint_sees_the_declaration_the_vocabulary_it_reads_and_the_size():
    d = declaration()
    base = fingerprint(d, VOCABULARY, 785)
    assert fingerprint(declaration(), VOCABULARY, 785) == base          # deterministic
    assert fingerprint(declaration(claim="convergence is slower at speed"), VOCABULARY, 785) != base
    assert fingerprint(d, VOCABULARY, 800) != base
    wider = copy.deepcopy(VOCABULARY)
    wider.classes["trend"]["margin"] = 0.2
    assert fingerprint(d, wider, 785) != base
    other_class = copy.deepcopy(VOCABULARY)
    other_class.classes["majority"]["threshold"] = 0.6                 # not read by this row
    assert fingerprint(d, other_class, 785) == base
    newer = dataclasses.replace(VOCABULARY, policy=dict(VOCABULARY.policy, procedure_version=7))
    assert fingerprint(d, newer, 785) != base


def test_registry_catches_a_change_and_keeps_the_old_declaration():
    d = declaration()
    registry, revised = register([d], VOCABULARY, {}, {d.key: 785}, "2026-12-06")
    assert revised == [] and check_registry([d], VOCABULARY, registry) == []
    changed = declaration(direction="decrease")
    problems = check_registry([changed], VOCABULARY, registry)
    assert len(problems) == 1 and "changed since 2026-12-06" in problems[0]
    assert "data/claims_registry.json" in problems[0]
    again, revised = register([changed], VOCABULARY, registry, {d.key: 785}, "2026-12-07")
    assert revised == ["demo/longer_with_speed"]
    assert again[d.key]["history"][0]["declaration"]["direction"] == "increase"
    assert check_registry([changed], VOCABULARY, again) == []
    assert revisions(again) == 1 and revisions(registry) == 0
    assert "not registered" in check_registry([declaration(id="new")], VOCABULARY, again)[0]


def test_sizes_by_power_from_the_vocabulary():
    rate = declaration(word_class="absolute", metrics=["converged"], direction="")
    assert registered_size(rate, VOCABULARY) == 150    # ceil(2.8016² · 0.95 · 0.05 / 0.05²) = ceil(149.1)
    majority = declaration(word_class="majority", metrics=["converged"], direction="")
    assert registered_size(majority, VOCABULARY) == 785
    assert registered_size(declaration(), VOCABULARY) is None       # needs a pilot's σ
    assert registered_size(declaration(), VOCABULARY, pilot_sigma=0.5) == 197
    assert registered_size(declaration(), VOCABULARY, pilot_sigma=0.01) == 30     # the floor


def test_decide_reads_the_study_rows():
    rng = np.random.default_rng(0)
    base = 1.0 + 0.1 * rng.standard_normal(200)
    rows = pd.DataFrame({"time_s_60kmh": base, "time_s_200kmh": base * 1.3,
                         "converged": rng.random(200) < 0.99})
    assert decide(declaration(), VOCABULARY, rows, {}).verdict == "reproduced"
    assert decide(declaration(direction="decrease"), VOCABULARY, rows, {}).verdict == "differs"
    assert decide(declaration(), VOCABULARY, rows, {}).reason.startswith(   # which is the baseline
        "time_s_200kmh against the baseline time_s_60kmh: relative change +0.3 ")
    small = decide(declaration(), VOCABULARY, rows.iloc[:50], {}, size=197)
    assert small.verdict == "undecided" and "50 records of the 197 registered" in small.reason
    rate = declaration(word_class="absolute", metrics=["converged"], direction="")
    assert decide(rate, VOCABULARY, rows, {}).statistic == rows.converged.mean()
    absent = decide(declaration(metrics=["nope", "time_s_60kmh"]), VOCABULARY, rows, {})
    assert absent.verdict == "undecided" and "has no column 'nope'" in absent.reason


def test_decide_reads_the_run_metrics_for_exact_design_and_speed_rows():
    exact = declaration(kind="deterministic", word_class="exact", metrics=["rank"],
                        paper_value=[4.0], study="", direction="")
    assert decide(exact, VOCABULARY, None, {"rank": 4}).verdict == "reproduced"
    assert decide(exact, VOCABULARY, None, {"rank": 3}).verdict == "differs"
    assert decide(exact, VOCABULARY, None, {}).verdict == "undecided"
    fast = declaration(kind="implementation", word_class="real-time", metrics=["steps_per_s"],
                       study="", direction="")
    assert decide(fast, VOCABULARY, None, {"steps_per_s": 900.0}).verdict == "not testable"
    timed = declaration(kind="implementation", word_class="real-time", metrics=["steps_per_s"],
                        study="", direction="", paper_rate_hz=1000.0)
    assert decide(timed, VOCABULARY, None, {"steps_per_s": 900.0}).verdict == "differs"


def test_declarations_file_round_trip(tmp_path):
    path = tmp_path / "declarations.toml"
    path.write_text('[[claim]]\nid = "a"\nclaim = "c"\nwords = "w"\nsource = "s"\n'
                    'kind = "design"\nword_class = "design"\nmetrics = ["poles_placed"]\n'
                    'central = false\n\n[[claim]]\nid = "a"\nclaim = "c"\nwords = "w"\n'
                    'source = "s"\nkind = "design"\nword_class = "design"\n'
                    'metrics = ["poles_placed"]\ncentral = false\n')
    with pytest.raises(DataError, match="claim id 'a' twice"):
        declarations.load_declarations("demo", VOCABULARY, path)


def test_never_happened_is_left_out_and_counted_or_undecides():
    rng = np.random.default_rng(1)
    base = 1.0 + 0.1 * rng.standard_normal(100)
    rows = pd.DataFrame({"time_s_60kmh": base, "time_s_200kmh": base * 1.3})
    rows.loc[:3, "time_s_200kmh"] = -1.0                     # 4 % never converged: left out
    decision = decide(declaration(), VOCABULARY, rows, {})
    assert decision.verdict == "reproduced" and decision.n == 96
    assert "4 record(s) where it never happened (coded -1 or not a number) left out" \
        in decision.reason
    rows.loc[:5, "time_s_60kmh"] = -1.0                      # 6 %: a selected subset
    decision = decide(declaration(), VOCABULARY, rows, {})
    assert decision.verdict == "undecided" and "6 of 100 records" in decision.reason


def test_a_speed_claim_without_a_metric_is_undecided_or_not_testable():
    row = declaration(kind="implementation", word_class="real-time", metrics=[], study="",
                      direction="", paper_rate_hz=10000.0)
    assert decide(row, VOCABULARY, None, {}).verdict == "undecided"


def test_an_exact_value_against_the_similarity_margin():
    row = declaration(word_class="similarity", metrics=["ratio_deviation"], study="",
                      direction="")
    assert registered_size(row, VOCABULARY) is None
    assert decide(row, VOCABULARY, None, {"ratio_deviation": 0.04}).verdict == "reproduced"
    assert decide(row, VOCABULARY, None, {"ratio_deviation": -0.3}).verdict == "differs"
    with pytest.raises(DataError, match="reads one exact run metric"):
        declaration(word_class="similarity", metrics=["a", "b"], study="", direction="")


def test_a_dropped_row_stays_in_the_registry_marked():
    a, b = declaration(), declaration(id="other")
    registry, _ = register([a, b], VOCABULARY, {}, {}, "2026-12-06")
    registry, revised = register([a], VOCABULARY, registry, {}, "2026-12-07")
    assert revised == ["demo/other"] and registry["demo/other"]["dropped"] == "2026-12-07"
    assert revisions(registry) == 1 and check_registry([a], VOCABULARY, registry) == []


def test_railpaper_check_fails_on_an_unregistered_or_changed_declaration(monkeypatch):
    from railpaper.pipeline import check
    assert check.registry_rows("reduced-order-observer") == []        # as committed
    monkeypatch.setattr(check, "load_registry", lambda: {})
    rows = check.registry_rows("reduced-order-observer")
    assert rows and all(r.status.startswith("FAIL: reduced-order-observer/") for r in rows)
    assert "not registered in data/claims_registry.json" in rows[0].status


# ---- procedure version 2: soundness, a diverged run, yes/no design checks ---------------------

def _settling_rows(n=150, sound_qg=8, seed=3):
    """A single-run row's study: settling steps of two filters and their soundness columns."""
    rng = np.random.default_rng(seed)
    return pd.DataFrame({"settling_step_a_qgrbpf": rng.integers(3, 8, n).astype(float),
                         "settling_step_a_rbpf": rng.integers(40, 70, n).astype(float),
                         "satisfactory_qgrbpf": np.arange(n) < sound_qg,
                         "satisfactory_rbpf": np.ones(n, bool)})


SETTLES = dict(kind="single-run", word_class="value", direction="",
               metrics=["settling_step_a_qgrbpf", "settling_step_a_rbpf"],
               paper_value=[5.0, 55.0], resolution=[1.0, 5.0], horizon="step 300")


def test_estimators_read_take_the_longest_name_with_a_soundness_column():
    columns = ["satisfactory_rbpf", "satisfactory_qgrbpf", "satisfactory_qgrbpf_printed"]
    row = declaration(metrics=["settling_step_a_qgrbpf_printed", "settling_step_a_rbpf"])
    assert estimators_read(row, columns, "satisfactory_") == ["qgrbpf_printed", "rbpf"]
    assert estimators_read(declaration(metrics=["satisfactory_qgrbpf"], word_class="absolute",
                                       direction=""), columns, "satisfactory_") == ["qgrbpf"]
    assert estimators_read(declaration(), columns, "satisfactory_") == []    # no filter's column


def test_a_plausible_draw_from_an_unsound_filter_is_an_artefact_under_version_2():
    rows = _settling_rows(sound_qg=8)           # 8/150 sound: upper bound 0.102 < 0.5
    row = declaration(**SETTLES)
    first = decide(row, VOCABULARY, rows, {}, procedure_version=1)
    assert first.verdict == "reproduced"
    second = decide(row, VOCABULARY, rows, {}, procedure_version=2)
    assert second.verdict == "artefact" and "qgrbpf" in second.reason
    assert "only 8/150" in second.reason and second.statistic == first.statistic
    # at the threshold's boundary: 63/150 has upper bound 0.5024 (>= 0.5), 62/150 has 0.4959
    assert decide(row, VOCABULARY, _settling_rows(sound_qg=63), {}).verdict == "reproduced"
    assert decide(row, VOCABULARY, _settling_rows(sound_qg=62), {}).verdict == "artefact"


def test_a_diverged_run_counts_as_never_happened_under_version_2():
    rng = np.random.default_rng(1)
    base = 1.0 + 0.1 * rng.standard_normal(100)
    rows = pd.DataFrame({"time_s_60kmh": base, "time_s_200kmh": base * 1.3})
    rows.loc[:2, "time_s_200kmh"] = np.nan                 # 3 % diverged
    assert decide(declaration(), VOCABULARY, rows, {}, procedure_version=1).verdict \
        == "undecided"                                       # NaN interval under version 1
    decision = decide(declaration(), VOCABULARY, rows, {}, procedure_version=2)
    assert decision.verdict == "reproduced" and decision.n == 97
    rows.loc[:5, "time_s_60kmh"] = np.nan                    # 6 %: a selected subset
    assert decide(declaration(), VOCABULARY, rows, {}).verdict == "undecided"


def test_a_design_row_reads_yes_no_checks_only_under_version_2():
    row = declaration(kind="design", word_class="design", metrics=["observer_dimension"],
                      study="", direction="")
    assert decide(row, VOCABULARY, None, {"observer_dimension": 6}, procedure_version=1
                  ).verdict == "reproduced"                  # version 1: any non-zero number
    assert decide(row, VOCABULARY, None, {"observer_dimension": 6}).verdict == "undecided"
    assert decide(row, VOCABULARY, None, {"observer_dimension": True}).verdict == "reproduced"
    assert decide(row, VOCABULARY, None, {"observer_dimension": 0.0}).verdict == "differs"


def test_a_new_procedure_version_is_a_reregistration_not_a_revision_of_the_claim():
    d = declaration()
    first, _ = register([d], VOCABULARY.__class__(
        policy=dict(VOCABULARY.policy, procedure_version=1), classes=VOCABULARY.classes),
        {}, {d.key: 785}, "2026-12-01")
    again, revised = register([d], VOCABULARY, first, {d.key: 785}, "2026-12-06")
    assert revised == [d.key] and again[d.key]["history"][0]["procedure_version"] == 1
    assert revisions(again) == 0 and procedure_reregistrations(again) == 1
    changed, _ = register([declaration(direction="decrease")], VOCABULARY, again,
                          {d.key: 785}, "2026-12-07")
    assert revisions(changed) == 1 and procedure_reregistrations(changed) == 1


def test_a_change_from_a_baseline_that_never_happens_is_undecided_under_version_2():
    rows = pd.DataFrame({"time_s_60kmh": np.zeros(40), "time_s_200kmh": np.ones(40)})
    decision = decide(declaration(), VOCABULARY, rows, {})
    assert decision.verdict == "undecided" and "undefined" in decision.reason
    with pytest.raises(ValueError, match="baseline's mean is 0"):
        decide(declaration(), VOCABULARY, rows, {}, procedure_version=1)


def test_a_rate_counts_a_record_without_an_answer_as_no_under_version_2():
    rows = pd.DataFrame({"converged": [1.0] * 38 + [np.nan] * 2})
    rate = declaration(word_class="absolute", metrics=["converged"], direction="")
    assert decide(rate, VOCABULARY, rows, {}, procedure_version=1).statistic == 1.0
    assert decide(rate, VOCABULARY, rows, {}).statistic == 38 / 40


# ---- procedure version 3: only the estimators a row credits, a study's catalogue, unknowns --

def _toy_like_rows(n=100, sound_rbpf=10, sound_ekf=100):
    """A toy-like study: the RBPF converges on 90 records, the EKF diverges on 95; soundness
    columns named by estimator and initial condition (one NaN-free draw)."""
    return pd.DataFrame({"seed": np.arange(n),
                         "rbpf_converged_init1": np.arange(n) < 90,
                         "ekf_converged_init1": np.arange(n) < 5,
                         "ekf_diverged_init1": np.arange(n) >= 5,
                         "satisfactory_rbpf_init1": (np.arange(n) < sound_rbpf).astype(float),
                         "satisfactory_ekf_init1": (np.arange(n) < sound_ekf).astype(float)})


def _catalogue(column):
    for m in ("rbpf", "ekf"):
        if column.startswith(m + "_") and column.endswith("_init1"):
            return m + "_init1"
    return None


MAJORITY = dict(word_class="majority", direction="", kind="population")


def test_version_3_reads_the_study_catalogue_and_checks_a_credited_estimator():
    rows = _toy_like_rows(sound_rbpf=10)          # 10/100 sound: upper bound 0.176 < 0.5
    row = declaration(metrics=["rbpf_converged_init1"], study="toy", **MAJORITY)
    assert decide(row, VOCABULARY, rows, {}, procedure_version=2).verdict == "reproduced"
    third = decide(row, VOCABULARY, rows, {}, estimator_of=_catalogue)
    assert third.verdict == "artefact" and "rbpf_init1" in third.reason
    # no catalogue: version 2's suffix rule finds no estimator in 'rbpf_converged_init1'
    assert decide(row, VOCABULARY, rows, {}).verdict == "reproduced"


def test_version_3_does_not_check_an_estimator_through_its_failure():
    rows = _toy_like_rows(sound_ekf=0)            # the EKF never agrees with the posterior
    fails = declaration(metrics=["ekf_diverged_init1"], study="toy", **MAJORITY)
    assert decide(fails, VOCABULARY, rows, {}, estimator_of=_catalogue).verdict == "reproduced"
    # a single-run 'it did not converge' (paper value 0 on a yes/no column) credits nobody
    nope = declaration(metrics=["ekf_converged_init1"], study="toy", kind="single-run",
                       word_class="value", direction="", paper_value=[0.0], resolution=[0.0],
                       horizon="record end")
    assert decide(nope, VOCABULARY, rows, {}, estimator_of=_catalogue).verdict == "reproduced"
    # a departure (a claimed offset) credits nobody either
    rng = np.random.default_rng(2)
    offset = pd.DataFrame({"seed": np.arange(40), "ekf_final_error_x1_init1":
                           0.5 + 0.01 * rng.standard_normal(40),
                           "satisfactory_ekf_init1": np.zeros(40)})
    biased = declaration(metrics=["ekf_final_error_x1_init1"], study="toy", kind="population",
                         word_class="departure", direction="")
    assert decide(biased, VOCABULARY, offset, {}, estimator_of=_catalogue).verdict \
        == "reproduced"


def test_version_3_checks_only_the_estimator_a_comparison_favours():
    rows = _toy_like_rows(sound_rbpf=100, sound_ekf=0)
    # 'the EKF converges less often than the RBPF' (baseline RBPF, decrease of a
    # higher-is-better rate): it credits the RBPF, which is sound; the unsound EKF is the one
    # the claim says fails
    better = declaration(metrics=["rbpf_converged_init1", "ekf_converged_init1"], study="toy",
                         direction="decrease")
    assert decide(better, VOCABULARY, rows, {}, estimator_of=_catalogue).verdict == "reproduced"
    assert decide(better, VOCABULARY, rows, {}, procedure_version=2,
                  estimator_of=_catalogue).verdict == "reproduced"   # v2 found no name either
    # the favoured RBPF unsound: artefact
    rows = _toy_like_rows(sound_rbpf=0, sound_ekf=100)
    assert decide(better, VOCABULARY, rows, {}, estimator_of=_catalogue).verdict == "artefact"
    # a lower-is-better metric: a decrease of metrics[1] favours metrics[1]
    settles = _settling_rows(sound_qg=8)
    faster = declaration(metrics=["settling_step_a_rbpf", "settling_step_a_qgrbpf"],
                         direction="decrease")
    assert declarations.estimators_credited(faster, settles, VOCABULARY.policy) == ["qgrbpf"]
    slower = declaration(metrics=["settling_step_a_rbpf", "settling_step_a_qgrbpf"],
                         direction="increase")
    assert declarations.estimators_credited(slower, settles, VOCABULARY.policy) == ["rbpf"]


def test_version_3_counts_soundness_on_the_records_whose_posterior_is_known():
    rows = _toy_like_rows(sound_rbpf=10)
    rows.loc[40:, "satisfactory_rbpf_init1"] = np.nan       # known on 40: 10/40, high 0.41
    row = declaration(metrics=["rbpf_converged_init1"], study="toy", **MAJORITY)
    decision = decide(row, VOCABULARY, rows, {}, estimator_of=_catalogue)
    assert decision.verdict == "artefact" and "10/40" in decision.reason
    rows["satisfactory_rbpf_init1"] = np.nan                 # known nowhere: not checked
    unknown = decide(row, VOCABULARY, rows, {}, estimator_of=_catalogue)
    assert unknown.verdict == "reproduced" and "not checked" in unknown.reason


def test_a_study_s_one_filter_reads_the_bare_soundness_column():
    rows = pd.DataFrame({"seed": np.arange(100), "within_5pct_from_350": np.ones(100, bool),
                         "satisfactory": np.zeros(100)})
    row = declaration(metrics=["within_5pct_from_350"], study="lateral", **MAJORITY)
    decision = decide(row, VOCABULARY, rows, {}, estimator_of=lambda column: "")
    assert decision.verdict == "artefact" and "the filter ends within" in decision.reason


# ---- procedure version 4: a method that is not the paper's ---------------------------------

def test_version_4_makes_a_reproduced_from_our_method_attainable():
    rows = _toy_like_rows()
    ours = declaration(metrics=["rbpf_converged_init1"], study="toy", reading="working_scheme",
                       **MAJORITY)
    methods = {"working_scheme": "our tempered RBPF"}
    third = decide(ours, VOCABULARY, rows, {}, procedure_version=3, methods=methods)
    assert third.verdict == "reproduced"
    fourth = decide(ours, VOCABULARY, rows, {}, procedure_version=4, methods=methods)
    assert fourth.verdict == "attainable" and "our tempered RBPF" in fourth.reason
    assert fourth.statistic == third.statistic
    # the paper's own reading, or a row that does not hold, stays as it is
    paper = dataclasses.replace(ours, reading="")
    assert decide(paper, VOCABULARY, rows, {}, procedure_version=4, methods=methods
                  ).verdict == "reproduced"
    fails = declaration(metrics=["ekf_converged_init1"], study="toy", reading="working_scheme",
                        **MAJORITY)
    assert decide(fails, VOCABULARY, rows, {}, procedure_version=4, methods=methods
                  ).verdict == "differs"
    # a row without a reading is looked up as 'as stated'
    assert declarations.method_not_the_papers(paper, {"as stated": "our observer"}) \
        == "our observer"


def test_a_methods_file_needs_a_reason_for_every_reading_it_calls_ours(tmp_path):
    (tmp_path / "demo").mkdir()
    (tmp_path / "demo" / "methods.toml").write_text(
        'ours = ["hb0"]\npaper = ["labels"]\n[why]\nhb0 = "a variant of ours"\n')
    assert declarations.chapter_methods("demo", tmp_path) == {"hb0": "a variant of ours"}
    assert declarations.chapter_yardsticks("demo", tmp_path) == frozenset()
    (tmp_path / "exact").mkdir()
    (tmp_path / "exact" / "methods.toml").write_text(
        'ours = ["printed"]\nyardstick = ["printed"]\n[why]\nprinted = "the exact posterior"\n')
    assert declarations.chapter_yardsticks("exact", tmp_path) == frozenset({"printed"})
    (tmp_path / "other").mkdir()
    (tmp_path / "other" / "methods.toml").write_text('ours = ["hb0"]\n')
    with pytest.raises(DataError, match="'hb0' is listed as ours without a 'why'"):
        declarations.chapter_methods("other", tmp_path)


def test_version_5_makes_a_differs_from_our_method_not_testable():
    rows = _toy_like_rows()
    methods = {"working_scheme": "our tempered RBPF"}
    fails = declaration(metrics=["ekf_converged_init1"], study="toy", reading="working_scheme",
                        **MAJORITY)
    assert decide(fails, VOCABULARY, rows, {}, procedure_version=4, methods=methods
                  ).verdict == "differs"
    fifth = decide(fails, VOCABULARY, rows, {}, procedure_version=5, methods=methods)
    assert fifth.verdict == "not testable" and "says nothing about the paper's" in fifth.reason
    holds = dataclasses.replace(fails, metrics=("rbpf_converged_init1",))
    assert decide(holds, VOCABULARY, rows, {}, procedure_version=5, methods=methods
                  ).verdict == "attainable"
    paper = dataclasses.replace(fails, reading="")
    assert decide(paper, VOCABULARY, rows, {}, procedure_version=5, methods=methods
                  ).verdict == "differs"
    # a yardstick's failure (the exact posterior) bears on every estimator: it stays differs
    assert decide(fails, VOCABULARY, rows, {}, procedure_version=5, methods=methods,
                  yardsticks=frozenset({"working_scheme"})).verdict == "differs"


def test_version_6_makes_a_row_on_measured_data_we_lack_not_testable(tmp_path):
    """A row listed as resting only on measured data reads 'not testable' from version 6,
    whatever the simulated records give (their verdict and statistic stay in the reason and the
    row); an unlisted row, and the same row under version 5, are decided as before."""
    rows = _toy_like_rows()
    held = declaration(id="within", metrics=["rbpf_converged_init1"], study="toy", **MAJORITY)
    measured = {"within": "one line record the book lacks"}
    fifth = decide(held, VOCABULARY, rows, {}, procedure_version=5, measured=measured)
    assert fifth.verdict == "reproduced"
    sixth = decide(held, VOCABULARY, rows, {}, procedure_version=6, measured=measured)
    assert sixth.verdict == "not testable" and sixth.statistic == fifth.statistic
    assert "one line record the book lacks" in sixth.reason and "reproduced" in sixth.reason
    other = dataclasses.replace(held, id="elsewhere")
    assert decide(other, VOCABULARY, rows, {}, procedure_version=6, measured=measured
                  ).verdict == "reproduced"
    # before the methods rules: a measured row is not testable even if its reading is ours
    ours = dataclasses.replace(held, reading="working_scheme")
    assert decide(ours, VOCABULARY, rows, {}, procedure_version=6, measured=measured,
                  methods={"working_scheme": "our RBPF"}).verdict == "not testable"
    (tmp_path / "demo").mkdir()
    (tmp_path / "demo" / "methods.toml").write_text(
        'ours = []\nmeasured = ["within"]\n[measured_why]\nwithin = "a line record"\n')
    assert declarations.chapter_measured("demo", tmp_path) == {"within": "a line record"}
    (tmp_path / "bare").mkdir()
    (tmp_path / "bare" / "methods.toml").write_text('ours = []\nmeasured = ["within"]\n')
    with pytest.raises(DataError, match="'within' is listed as measured without"):
        declarations.chapter_measured("bare", tmp_path)
