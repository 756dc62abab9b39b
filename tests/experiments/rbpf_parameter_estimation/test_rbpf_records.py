"""Chapter 003's per-record studies: a record's row does not depend on its chunk, the run's
metrics are the same whether its rows come from this process, Dask workers or the store, and
each study's rows reduce to the chapter's metrics."""

from __future__ import annotations

import math

import numpy as np
import pandas as pd
import pytest

from railpaper.experiments.rbpf_parameter_estimation import STUDIES
from railpaper.experiments.rbpf_parameter_estimation import experiment as chapter
from railpaper.experiments.rbpf_parameter_estimation import (
    lateral,
    mismatch,
    posterior,
    soundness,
    spec,
    toy,
)
from railpaper.experiments.records import assert_chunk_invariant
from railpaper.pipeline.evidence_store import EvidenceStore, stored_map

#: Small settings: 3 toy records of 60 steps, 2 lateral records of 400 steps (3 for the paper
#: scheme), few particles, the exact posterior on two toy records and one lateral record.
SMALL = dict(toy_seeds=3, toy_steps=60, toy_particles=30, toy_tempering_steps=10,
             toy_ibis_particles=20, toy_ibis_records=2, n_steps=400, n_particles=20,
             tempering_steps=50, n_records=2, paper_records=3, working_records=2,
             ekf_guesses=1, ekf_steps=50, ibis_records=1, ibis_particles=20, mismatch_records=2)


def small(**changes):
    return chapter.SPEC.resolve(dict(SMALL, **changes), True)


@pytest.fixture(scope="module")
def small_run():
    """One run of the chapter at the small settings, in this process (shared by the tests)."""
    return chapter.run(small())


def test_the_chapter_exposes_its_studies():
    assert [s.name for s in STUDIES] == ["toy", "toy_calibration", "lateral_paper_scheme",
                                         "lateral_working_scheme",
                                         "lateral_ekf", "model_error", "toy_posterior",
                                         "lateral_posterior", "toy_judged_particles",
                                         "lateral_paper_scheme_judged_particles"]


def test_the_judged_toy_is_the_toy_at_the_judged_count():
    """The ledger's count of the paper's RBPF (``JUDGED_PARTICLES``) is the toy study with
    that count, bit for bit, and not the toy at its own count; its records start after the
    ones seen before the count was fixed."""
    settings = small()
    rows = toy.TOY_JUDGED.rows(settings, [3])
    assert toy.TOY_JUDGED.repeats == toy.TOY.name
    pd.testing.assert_frame_equal(
        rows, toy.TOY.rows(settings.replace(toy_particles=spec.JUDGED_PARTICLES), [3]))
    assert not rows.equals(toy.TOY.rows(settings, [3]))
    assert toy.TOY_JUDGED.first(settings) == settings.seed + spec.SEEN_RECORDS == 30


def test_the_judged_lateral_study_runs_the_paper_scheme_at_the_judged_count(monkeypatch):
    """The lateral judged study is the paper scheme's rows with ``n_particles`` replaced (the
    rows themselves, at 1000 particles, are spot-checked against the stored evidence)."""
    calls = []
    monkeypatch.setattr(lateral, "paper_scheme_rows",
                        lambda settings, seeds: calls.append((settings, seeds)) or "rows")
    settings = small()
    assert lateral.PAPER_SCHEME_JUDGED.rows(settings, [3]) == "rows"
    assert calls == [(settings.replace(n_particles=spec.JUDGED_PARTICLES), [3])]
    assert lateral.PAPER_SCHEME_JUDGED.repeats == lateral.PAPER_SCHEME.name
    assert lateral.PAPER_SCHEME_JUDGED.first(settings) == settings.seed + spec.SEEN_RECORDS


@pytest.mark.parametrize("study", [toy.TOY, posterior.TOY_CALIBRATION, lateral.PAPER_SCHEME,
                                   lateral.EKF,
                                   mismatch.MODEL_ERROR, soundness.TOY_POSTERIOR,
                                   soundness.LATERAL_POSTERIOR])
def test_a_record_does_not_depend_on_its_chunk(study):
    assert_chunk_invariant(study, small(), [4, 2])


def test_a_toy_calibration_row_is_the_exact_posterior_of_its_record():
    """A row of the toy's calibration study is the exact posterior of the record the toy study
    filtered (IBIS, computed here again by hand), and it covers x_j exactly when the truth lies
    between its 5 and 95 % quantiles."""
    settings = small()
    row = posterior.toy_calibration_rows(settings, [5]).iloc[0]
    sim = toy.simulate(settings, np.random.default_rng(5))
    post = posterior.toy_posterior(settings, sim, 5)
    truth = toy.truth(settings)
    for j in range(4):
        name = f"x{j + 1}"
        assert row[f"posterior_mean_{name}"] == post.mean[-1, j]
        assert row[f"posterior_q05_{name}"] == post.q05[-1, j]
        assert row[f"posterior_q95_{name}"] == post.q95[-1, j]
        assert row[f"posterior_covers_{name}"] == (post.q05[-1, j] <= truth[j] <= post.q95[-1, j])


def test_the_toy_rows_are_the_long_records_side_by_side():
    settings = small()
    wide = toy.toy_rows(settings, (7,))
    long = toy.long_records(wide)
    assert long.init.tolist() == [1, 2] and long.seed.tolist() == [7, 7]
    for ic in (1, 2):
        assert long.iloc[ic - 1].rbpf_err_max == wide[f"rbpf_err_max_init{ic}"].iloc[0]
    runs = toy.record_runs(settings, 7)                     # the same record, by hand
    final = np.abs(runs[1].rbpf_paper[-1] - toy.truth(settings)).max()
    assert long.iloc[1].rbpf_err_max == final


def test_a_scheme_row_is_its_definition():
    norm = np.ones((400, 5))
    norm[:360, 0] = 1.2                      # Csy outside 5 % until step 360
    norm[-1, 3] = 0.97
    row = lateral.scheme_row(3, norm)
    assert row["seed"] == 3 and row["within_5pct_from_350"] is False
    assert row["within_5pct_at_350"] is False
    assert row["final_relative_error_" + lateral.lateral_16state.PARAM_NAMES[3]] == pytest.approx(
        -0.03)
    norm[:360, 0] = 1.0
    assert lateral.scheme_row(3, norm)["within_5pct_from_350"] is True


def _same(a: dict, b: dict) -> bool:
    return a.keys() == b.keys() and all(
        a[k] == b[k] or (isinstance(a[k], float) and math.isnan(a[k]) and math.isnan(b[k]))
        for k in a)


def test_dask_workers_and_the_store_give_the_same_metrics(tmp_path, dask_client, small_run):
    settings = small()
    here = small_run
    store = EvidenceStore(tmp_path)
    there = chapter.run(settings, record_map=stored_map(store, client=dask_client))
    assert _same(here.metrics, there.metrics)
    pd.testing.assert_frame_equal(here.toy.records, there.toy.records, check_exact=True)
    assert sorted(store.read(toy.TOY, settings).seed) == [1, 2]          # after the illustrated
    assert sorted(store.read(lateral.PAPER_SCHEME, settings).seed) == [2]
    assert sorted(store.read(posterior.TOY_CALIBRATION, settings).seed) == [1]
    pd.testing.assert_frame_equal(here.toy.coverage, there.toy.coverage, check_exact=True)
    for name in ("records_toy", "records_lateral_paper_scheme", "records_lateral_ekf",
                 "records_model_error"):
        assert name in here.extra_tables
    assert here.extra_tables["records_toy"].seed.tolist() == [0, 1, 2]


@pytest.mark.parametrize("study, table", [(lateral.EKF, "records_lateral_ekf"),
                                          (mismatch.MODEL_ERROR, "records_model_error")])
def test_the_rows_kept_by_the_run_are_the_study_s_rows(study, table, small_run):
    """The first records of the EKF and model-error studies are computed inside the chapter run
    (with more EKF guesses on the first record); their rows equal the study's own."""
    settings = small()
    kept = small_run.extra_tables[table]
    pd.testing.assert_frame_equal(kept, study.rows(settings, tuple(kept.seed)).pipe(
        lambda frame: frame[kept.columns]).astype(kept.dtypes.to_dict()), check_exact=True)


def test_soundness_columns_by_hand():
    # toy: truth (-0.4, 0.5, 0.5, 1); record 0's RBPF ends 0.1 off in x1 where the posterior sd
    # is 0.04 (|z| = 2.5 > 2: not sound), record 1 exactly at the posterior mean; the EKF of
    # record 1 diverged (NaN: not sound); record 2 has no posterior (NaN: not known)
    settings = small()
    rows = pd.DataFrame({"seed": [0, 1, 2]})
    for m in ("rbpf", "ekf"):
        for ic in (1, 2):
            for j in range(1, 5):
                rows[f"{m}_final_error_x{j}_init{ic}"] = 0.0
    rows.loc[0, "rbpf_final_error_x1_init1"] = 0.1
    rows.loc[1, "ekf_final_error_x3_init2"] = np.nan
    posterior = pd.DataFrame({"seed": [0, 1]})
    truth = toy.truth(settings)
    for ic in (1, 2):
        for j in range(1, 5):
            posterior[f"posterior_mean_x{j}_init{ic}"] = truth[j - 1]
            posterior[f"posterior_sd_x{j}_init{ic}"] = 0.04
    out = soundness.soundness_columns("toy", rows, posterior, settings)
    np.testing.assert_array_equal(out.satisfactory_rbpf_init1, [0.0, 1.0, np.nan])
    np.testing.assert_array_equal(out.satisfactory_rbpf_both_inits, [0.0, 1.0, np.nan])
    np.testing.assert_array_equal(out.satisfactory_ekf_init2, [1.0, 0.0, np.nan])
    np.testing.assert_array_equal(out.satisfactory_ekf_both_inits, [1.0, 0.0, np.nan])
    # lateral: estimate 1 + relative error against the normalised posterior; no posterior at all
    lateral_rows = pd.DataFrame({"seed": [5], **{f"final_relative_error_{p}": [0.01]
                                                 for p in ("csy", "lambda", "kpy", "ksy",
                                                           "csaly")}})
    unknown = soundness.soundness_columns("lateral_paper_scheme", lateral_rows, None, settings)
    assert np.isnan(unknown.satisfactory.iloc[0])
    with pytest.raises(ValueError, match="has no exact posterior"):
        soundness.soundness_columns("model_error", lateral_rows, None, settings)
