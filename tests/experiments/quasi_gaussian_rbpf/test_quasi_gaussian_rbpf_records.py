"""Chapter quasi-gaussian-rbpf's Monte Carlo as a map over records and a reduce: a record's row
does not depend on the chunk it is computed in or on where it is computed."""

import dataclasses
import math

import pandas as pd
import pytest

from railpaper.experiments.quasi_gaussian_rbpf import experiment as chapter
from railpaper.experiments.quasi_gaussian_rbpf.readings import load_readings
from railpaper.experiments.records import assert_chunk_invariant, map_in_process
from railpaper.pipeline.evidence_store import EvidenceStore, stored_map

#: Small settings: three Monte Carlo records (2, 3, 4), no timing, no readings study.
SMALL = dict(n_particles=40, n_steps=30, grid_size=11, n_monte_carlo=3, record=2, timing=False,
             readings_records=0)


def small(**changes):
    return chapter.SPEC.resolve(dict(SMALL, **changes), True)


@pytest.mark.parametrize("study, changes", [(chapter.MONTE_CARLO, {}),
                                            (chapter.READINGS, dict(grid_size=5))],
                         ids=["monte_carlo", "readings"])
def test_a_record_does_not_depend_on_its_chunk(study, changes):
    settings = small(**changes)
    seeds = [3, 5, 4]
    assert_chunk_invariant(study, settings, seeds)
    one = map_in_process(dataclasses.replace(study, chunk_records=1), settings, seeds)
    pd.testing.assert_frame_equal(one, map_in_process(study, settings, seeds), check_exact=True)
    pd.testing.assert_frame_equal(
        one, map_in_process(dataclasses.replace(study, chunk_records=2), settings, seeds),
        check_exact=True)


def test_rows_have_units_in_their_names_and_one_row_per_record():
    settings = small()
    rows = chapter.MONTE_CARLO.rows(settings, (2,))
    assert rows.columns[0] == "seed" and len(rows) == 1
    assert "final_error_a_rbpf" in rows and "convergence_step_b_qgrbpf" in rows
    readings, horizons = load_readings()
    wide = chapter.READINGS.rows(small(grid_size=5), (0,))
    assert len(wide.columns) == 1 + len(readings) * 2 * (len(horizons) + 4)
    assert f"settling_step_printed_a_h{horizons[0]}" in wide


def test_the_run_reduces_the_mapped_rows_and_each_row_is_that_record_alone():
    settings = small()
    result = chapter.run(settings)
    assert result.monte_carlo.seed.tolist() == [2, 3, 4]
    alone = chapter.run(settings.replace(record=4, n_monte_carlo=1)).metrics
    row = result.monte_carlo.iloc[2]
    assert all(row[k] == alone[k] for k in row.index if k != "seed")

    def other_columns(study, settings, seeds, progress):
        return map_in_process(study, settings, seeds, progress).drop(columns="final_error_a_rbpf")

    with pytest.raises(ValueError, match="other columns"):
        chapter.run(settings, record_map=other_columns)


def _same(a: dict, b: dict) -> bool:
    return a.keys() == b.keys() and all(
        a[k] == b[k] or (isinstance(a[k], float) and math.isnan(a[k]) and math.isnan(b[k]))
        for k in a)


def test_dask_workers_and_the_store_give_the_same_metrics(tmp_path, dask_client):
    settings = small(n_monte_carlo=4, readings_records=3, grid_size=7)
    here = chapter.run(settings)
    store = EvidenceStore(tmp_path)
    there = chapter.run(settings, record_map=stored_map(store, client=dask_client))
    again = chapter.run(settings, record_map=stored_map(store, client=dask_client))
    assert _same(here.metrics, there.metrics) and _same(here.metrics, again.metrics)
    pd.testing.assert_frame_equal(here.monte_carlo, there.monte_carlo, check_exact=True)
    pd.testing.assert_frame_equal(here.readings.table, there.readings.table, check_exact=True)
    assert sorted(store.read(chapter.MONTE_CARLO, settings).seed) == [3, 4, 5]
    assert sorted(store.read(chapter.READINGS, settings).seed) == [0, 1, 2]
