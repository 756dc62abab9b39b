"""Chapter reduced-order-observer: its records are a map over seeds and its evidence a reduce.

A record's numbers depend on its seed and the settings only: the same bits whether computed in
one chunk, one seed at a time, in another order, in process or on dask workers."""

import dataclasses

import numpy as np
import pandas as pd
import pytest

from railpaper.experiments.records import assert_chunk_invariant, map_in_process
from railpaper.experiments.reduced_order_observer import evidence as ev
from railpaper.experiments.reduced_order_observer import experiment as chapter
from railpaper.experiments.reduced_order_observer import kalman as rk
from railpaper.experiments.reduced_order_observer.spec import READINGS, SPEC

#: Short runs: 3000 steps, the error window inside them.
SMALL = {"speeds_kmh": [60.0, 100.0], "sweep_speeds_kmh": [40.0, 100.0], "duration_s": 0.3,
         "error_window_start_s": 0.15, "mc_seeds": 3}
STUDIES = [ev.MONTE_CARLO, ev.HERTZ, rk.ESTIMATOR_RECORDS, rk.TRACK_NOISE_RECORDS]


def small(**changes):
    return SPEC.resolve(SMALL | changes, quick=True)


@pytest.mark.parametrize("speeds", [[60.0, 100.0], [80.0]])
@pytest.mark.parametrize("study", STUDIES, ids=lambda s: s.name)
def test_a_record_does_not_depend_on_its_chunk(study, speeds):
    """One chunk, one seed at a time and the reverse order give the same bits (one speed is the
    case where a lone seed is a one-column batch: padded, or numpy would sum its means pairwise
    and step its plant with a matrix-vector product)."""
    settings = small(speeds_kmh=speeds, sweep_speeds_kmh=speeds)
    assert_chunk_invariant(study, settings, (7, 3, 12))


@pytest.mark.parametrize("study", [ev.MONTE_CARLO, rk.ESTIMATOR_RECORDS], ids=lambda s: s.name)
def test_map_in_process_chunk_of_one_equals_default(study):
    settings = small()
    seeds = list(range(5, 9))
    one = dataclasses.replace(study, chunk_records=1)
    pd.testing.assert_frame_equal(map_in_process(one, settings, seeds),
                                  map_in_process(study, settings, seeds), check_exact=True)


def test_rows_are_wide_and_the_reduce_gives_back_the_long_tables():
    """One row per seed, every reading × speed × quantity a column; the long tables of the
    reduce hold those numbers at their (seed, speed, reading), Hertz only on its seeds."""
    settings = small(mc_seeds=3)
    rows = ev.monte_carlo_records(settings)
    speeds = [60.0, 100.0, 40.0]
    mc, hertz = rows[ev.MONTE_CARLO.name], rows[ev.HERTZ.name]
    assert len(mc.columns) == 1 + len(READINGS) * len(speeds) * len(ev.MC_QUANTITIES)
    assert len(hertz.columns) == 1 + len(READINGS) * 2 * len(ev.HERTZ_QUANTITIES)
    table = ev.samples_table(mc, hertz.iloc[:2], settings)          # Hertz on two seeds only
    assert list(table.columns) == ["seed", "speed_kmh", "reading", *ev.SAMPLE_COLUMNS]
    assert len(table) == 3 * len(speeds) * len(READINGS)
    row = table[(table.seed == 1) & (table.speed_kmh == 100.0) & (table.reading == "wheelset")]
    assert row.force_rms_error_N.iloc[0] == mc.force_rms_error_N_wheelset_100kmh.iloc[1]
    assert row.force_relative_rms_error_hertz.iloc[0] == \
        hertz.force_relative_rms_error_hertz_wheelset_100kmh.iloc[1]
    assert table[table.seed == 2].force_relative_rms_error_hertz.isna().all()
    assert table[table.speed_kmh == 40.0].force_relative_rms_error_hertz.isna().all()
    records = rk.comparison_records(settings)
    estimators = records[rk.ESTIMATOR_RECORDS.name]
    n_levels = len(rk.noise_levels(settings))
    assert len(estimators.columns) == 1 + 2 * (2 + 3 * n_levels)
    samples = rk.samples_table(records, settings)
    at = samples[(samples.sweep == "sensor") & (samples.seed == 2) & (samples.speed_kmh == 60.0)
                 & (samples.estimator == "kalman") & (samples.noise_fraction == 1e-3)]
    assert at.force_rms_error_N.iloc[0] == \
        estimators[rk.error_column("kalman", "sensor", 1e-3, 60.0)].iloc[2]


def test_dask_workers_give_the_same_metrics(tmp_path, dask_client):
    from railpaper.pipeline.evidence_store import EvidenceStore, stored_map
    settings = small()
    here = chapter.run(settings, record_map=map_in_process)
    there = chapter.run(settings, record_map=stored_map(EvidenceStore(tmp_path),
                                                        client=dask_client))
    again = chapter.run(settings, record_map=stored_map(EvidenceStore(tmp_path)))   # reused
    assert there.metrics == here.metrics == again.metrics
    for name in ("monte_carlo_samples", "estimator_samples",
                 *(f"records_{s.name}" for s in STUDIES)):
        pd.testing.assert_frame_equal(there.extra_tables[name], here.extra_tables[name],
                                      check_exact=True)
    stored = EvidenceStore(tmp_path).read(ev.MONTE_CARLO, settings)
    assert sorted(stored.seed) == [0, 1, 2]
    assert np.isfinite(here.metrics["mc_convergence_time_s_worst_wheel"])
