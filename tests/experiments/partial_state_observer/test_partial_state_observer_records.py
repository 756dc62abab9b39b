"""Chapter partial-state-observer: its records are a map over seeds and its evidence a reduce.

A record's numbers depend on its seed and the settings only: the same bits whether computed in
one chunk, one seed at a time, in another order, in process or on dask workers."""

import dataclasses
import json

import numpy as np
import pandas as pd
import pytest

from railpaper.experiments.partial_state_observer import evidence as ev
from railpaper.experiments.partial_state_observer import experiment as ch
from railpaper.experiments.partial_state_observer import records
from railpaper.experiments.partial_state_observer.spec import SPEC
from railpaper.experiments.records import assert_chunk_invariant, map_in_process

#: Short runs: a few hundred steps, the error window inside them.
SMALL = {"duration_s": 0.4, "lead_in_s": 0.05, "error_window_start_s": 0.2,
         "alpha_sweep_per_s": [20.0]}
STUDIES = [records.MONTE_CARLO, records.KALMAN_BASELINE["labels"],
           records.KALMAN_BASELINE["symbols"]]


def small(**changes):
    return SPEC.resolve(SMALL | changes, quick=True)


@pytest.mark.parametrize("speeds", [[60.0, 120.0], [80.0]])
@pytest.mark.parametrize("study", STUDIES, ids=lambda s: s.name)
def test_a_record_does_not_depend_on_its_chunk(study, speeds):
    """One chunk, one seed at a time and the reverse order give the same bits (one speed is
    the case where a lone seed would be a one-row matrix product)."""
    settings = small(speeds_kmh=speeds)
    assert_chunk_invariant(study, settings, (7, 3, 12))


def test_map_in_process_chunk_of_one_equals_default():
    settings = small(speeds_kmh=[60.0, 160.0])
    seeds = list(range(4, 16))                       # 12 seeds: chunks of 10 and 2
    one = dataclasses.replace(records.MONTE_CARLO, chunk_records=1)
    pd.testing.assert_frame_equal(map_in_process(one, settings, seeds),
                                  map_in_process(records.MONTE_CARLO, settings, seeds),
                                  check_exact=True)


def test_row_columns_and_runs_table_against_single_runs():
    """The wide row holds every reading, estimator, speed and measure; the reduce's table of
    runs gives back each run's numbers as computed from that run's own estimates."""
    settings = small(speeds_kmh=[60.0, 120.0])
    seeds = (2, 5)
    rows = map_in_process(records.MONTE_CARLO, settings, seeds)
    kalman = map_in_process(records.KALMAN_BASELINE["labels"], settings, seeds[:1])
    n_predicted = 2 * 2 * 2                          # readings × (paper, hb0) × speeds
    assert len(rows.columns) == 1 + 2 * 5 * 2 * len(records.MEASURES) + n_predicted
    assert len(kalman.columns) == 1 + 2 * len(records.MEASURES)
    assert rows["converged_60kmh_paper_labels"].dtype == bool
    mc = ev.runs_table(rows, kalman, settings)
    assert list(mc.columns) == list(ev.RUN_COLUMNS)
    assert len(mc) == 2 * 5 * 2 * 2 + 2            # + the Kalman runs of one seed
    assert set(mc[mc.estimator == "kalman"].reading) == {"labels"}
    for reading in records.READINGS:
        ctx = records.context(settings, reading)
        tr, fixed = records.simulated(settings, reading, list(seeds))
        est = records.monte_carlo_runs(ctx, settings, tr, kalman=reading == "labels")
        for name, zh in est.items():
            for i, seed in enumerate(seeds):
                if name == "kalman" and seed != seeds[0]:
                    continue
                for j, speed in enumerate(tr["speeds"]):
                    want = records.run_measures(tr["t_s"], tr["z_m"][i, j], zh[i, j], fixed[i],
                                           settings.convergence_fraction,
                                           settings.error_window_start_s)
                    got = mc[(mc.reading == reading) & (mc.estimator == name)
                             & (mc.seed == seed) & (mc.speed_kmh == speed)]
                    assert len(got) == 1
                    for key, value in want.items():
                        assert got[key].iloc[0] == pytest.approx(value, rel=1e-12, abs=1e-18)
                    predicted = got.predicted_convergence_s.iloc[0]
                    assert (predicted >= 0) == (name in ("paper", "hb0"))


def test_dask_workers_give_the_same_metrics(tmp_path, dask_client):
    from railpaper.pipeline.evidence_store import EvidenceStore, stored_map
    settings = small(speeds_kmh=[60.0, 120.0], n_seeds=5)
    here = ch.run(settings, record_map=map_in_process)
    there = ch.run(settings, record_map=stored_map(EvidenceStore(tmp_path), client=dask_client))
    assert json.dumps(there.metrics, sort_keys=True) == json.dumps(here.metrics, sort_keys=True)
    pd.testing.assert_frame_equal(there.monte_carlo, here.monte_carlo, check_exact=True)
    stored = EvidenceStore(tmp_path).read(records.MONTE_CARLO, settings)
    assert sorted(stored.seed) == list(range(5))
    assert np.isfinite(here.metrics["mc_convergence_time_s_labels"])
