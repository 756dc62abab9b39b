"""The evidence store and the record maps: exact round trip, reuse, extension, the spot check of
another commit's rows, interrupted writes, chunking and workers that change no bit."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from railpaper.experiments.base import ChapterSpec, Parameter
from railpaper.experiments.records import RecordStudy, map_in_process, normalised
from railpaper.pipeline.evidence_store import (
    EvidenceStore,
    EvidenceStoreError,
    key_digest,
    stored_map,
)

SPEC = ChapterSpec("demo", "Demo", "", "demo.ipynb", [
    Parameter("scale_m", 1.0, "float", "scale, m"),
    Parameter("n_records", 5, "int", "records", changes_records=False)])
Settings = SPEC.settings_type          # pickle finds the class here (the workers' test)
CALLS: list[tuple[int, ...]] = []


def awkward_rows(settings, seeds):
    """Floats that a short format would round, whole-valued floats, ints, bools, strings."""
    CALLS.append(tuple(seeds))
    rows = []
    for seed in seeds:
        draw = np.random.default_rng([seed, 1]).standard_normal()
        rows.append({"seed": seed, "value_m": settings.scale_m * draw / 3.0,
                     "whole_m": float(seed), "tiny_m": 1e-300 * (seed + 1) / 7,
                     "count": seed * 2, "flag": bool(seed % 2), "label": f"r{seed}"})
    return pd.DataFrame(rows)


STUDY = RecordStudy("demo", "awkward", awkward_rows, chunk_records=2)


def test_normalised_keeps_every_bit_and_dtype():
    frame = awkward_rows(SPEC.resolve(), range(6))
    again = normalised(frame)
    assert list(again.dtypes) == list(frame.dtypes)           # whole floats stay float
    for column in frame.columns:
        if frame[column].dtype == float:
            assert np.array_equal(frame[column].to_numpy().view(np.int64),
                                  again[column].to_numpy().view(np.int64))
        else:
            assert frame[column].tolist() == again[column].tolist()


def test_chunking_changes_nothing():
    settings = SPEC.resolve()
    one = map_in_process(RecordStudy("demo", "a", awkward_rows, 1), settings, [4, 0, 7, 2])
    three = map_in_process(RecordStudy("demo", "a", awkward_rows, 3), settings, [4, 0, 7, 2])
    pd.testing.assert_frame_equal(one, three)
    assert one.seed.tolist() == [4, 0, 7, 2]                   # the order asked for


def test_rows_for_other_seeds_are_refused():
    bad = RecordStudy("demo", "bad", lambda s, seeds: awkward_rows(s, seeds[::-1]), 2)
    with pytest.raises(ValueError, match="rows for seeds"):
        map_in_process(bad, SPEC.resolve(), [0, 1])


def test_store_reuses_and_extends(tmp_path):
    store, settings = EvidenceStore(tmp_path), SPEC.resolve()
    record_map = stored_map(store, commit="c1")
    CALLS.clear()
    first = record_map(STUDY, settings, [0, 1, 2])
    assert CALLS == [(0, 1), (2,)]
    CALLS.clear()
    more = record_map(STUDY, settings, [3, 0, 1, 2])           # only seed 3 is new
    assert CALLS == [(3,)]
    pd.testing.assert_frame_equal(more.iloc[1:].reset_index(drop=True), first)
    assert store.read(STUDY, settings)["commit"].tolist() == ["c1"] * 4
    fresh = map_in_process(STUDY, settings, [3, 0, 1, 2])
    pd.testing.assert_frame_equal(more, fresh)                 # stored rows = computed rows


def test_key_holds_only_the_fields_that_change_records(tmp_path):
    store = EvidenceStore(tmp_path)
    a, b = SPEC.resolve(), SPEC.resolve({"n_records": 50})
    c = SPEC.resolve({"scale_m": 2.0})
    assert store.folder(STUDY, a) == store.folder(STUDY, b)
    assert store.folder(STUDY, a) != store.folder(STUDY, c)
    assert key_digest({"scale_m": 1.0}) == store.folder(STUDY, a).name


def test_rows_of_another_commit_are_spot_checked(tmp_path):
    store, settings = EvidenceStore(tmp_path), SPEC.resolve()
    stored_map(store, commit="old")(STUDY, settings, range(10))
    CALLS.clear()
    rows = stored_map(store, commit="new")(STUDY, settings, range(10))
    assert len(CALLS) == 1 and len(CALLS[0]) == 3                  # three rows recomputed
    checked = CALLS[0]
    CALLS.clear()
    stored_map(store, commit="new")(STUDY, settings, range(10))
    assert CALLS == [checked]                                      # the same three every time
    assert len(rows) == 10
    CALLS.clear()
    stored_map(store, commit="old")(STUDY, settings, range(10))    # its own rows: no check
    assert CALLS == []


def test_a_changed_bit_refuses_the_store(tmp_path):
    store, settings = EvidenceStore(tmp_path), SPEC.resolve()
    stored_map(store, commit="old")(STUDY, settings, range(4))
    path = store.folder(STUDY, settings) / "rows.csv"
    frame = pd.read_csv(path)
    frame["value_m"] = np.nextafter(frame["value_m"], np.inf)     # one ulp on every row
    frame.to_csv(path, index=False, float_format="%.17g")
    with pytest.raises(EvidenceStoreError, match=r"seed \d's value_m is .* in the rows of commit old"):
        stored_map(store, commit="new")(STUDY, settings, range(4))


def test_an_interrupted_write_keeps_the_finished_rows(tmp_path):
    store, settings = EvidenceStore(tmp_path), SPEC.resolve()
    stored_map(store, commit="c1")(STUDY, settings, [0, 1])
    path = store.folder(STUDY, settings) / "rows.csv"
    path.write_text(path.read_text() + "2,0.12")                   # cut short by a kill
    assert store.read(STUDY, settings).seed.tolist() == [0, 1]
    CALLS.clear()
    rows = stored_map(store, commit="c1")(STUDY, settings, [0, 1, 2])
    assert CALLS == [(2,)]
    assert store.read(STUDY, settings).seed.tolist() == [0, 1, 2]
    pd.testing.assert_frame_equal(rows, map_in_process(STUDY, settings, [0, 1, 2]))


def test_workers_give_the_same_bits(tmp_path, dask_client):
    settings = SPEC.resolve({"scale_m": 3.0})
    seen = []
    on_workers = stored_map(EvidenceStore(tmp_path), client=dask_client, commit="c1")(
        STUDY, settings, range(7), lambda fraction, message: seen.append(message))
    pd.testing.assert_frame_equal(on_workers, map_in_process(STUDY, settings, range(7)))
    assert seen[0] == "awkward: 0/7 records" and seen[-1] == "awkward: 7/7 records"


def test_extreme_floats_round_trip():
    rng = np.random.default_rng(3)
    values = np.concatenate([rng.standard_normal(20_000) * 10.0 ** rng.integers(-300, 300, 20_000),
                             [5e-324, 2.2250738585072014e-308, 1.7976931348623157e308, -0.0]])
    frame = pd.DataFrame({"seed": np.arange(len(values)), "x_m": values})
    again = normalised(frame)
    assert np.array_equal(frame.x_m.to_numpy().view(np.int64), again.x_m.to_numpy().view(np.int64))


def test_records_on_hands_the_kernels_a_cluster_and_a_store_then_restores(tmp_path, monkeypatch):
    import os

    from distributed import Client

    from railpaper.pipeline import evidence_store
    monkeypatch.delenv(evidence_store.SCHEDULER_VARIABLE, raising=False)
    monkeypatch.delenv(evidence_store.STORE_VARIABLE, raising=False)
    with evidence_store.records_on(workers=1, store=tmp_path) as address:
        assert os.environ[evidence_store.SCHEDULER_VARIABLE] == address
        assert os.environ[evidence_store.STORE_VARIABLE] == str(tmp_path.resolve())
        with Client(address) as client:                 # what a notebook kernel connects to
            assert len(client.scheduler_info()["workers"]) == 1
    assert evidence_store.SCHEDULER_VARIABLE not in os.environ
    assert evidence_store.STORE_VARIABLE not in os.environ
    with evidence_store.records_on() as address:        # nothing asked: nothing changes
        assert address is None and evidence_store.SCHEDULER_VARIABLE not in os.environ
    with pytest.raises(ValueError, match="not both"):
        with evidence_store.records_on(workers=2, scheduler="tcp://127.0.0.1:1"):
            pass
    with pytest.raises(ValueError, match="--workers must be >= 1"):
        with evidence_store.records_on(workers=0):
            pass


def test_usage_counts_computed_records_only(tmp_path):
    record_map = stored_map(EvidenceStore(tmp_path), commit="c1")
    record_map(STUDY, SPEC.resolve(), range(5))
    assert record_map.usage["records"] == 5 and record_map.usage["cpu_s"] >= 0.0
    record_map(STUDY, SPEC.resolve(), range(6))                    # five reused, one computed
    assert record_map.usage["records"] == 6


def test_assert_chunk_invariant_catches_a_batch_that_changes_bits():
    from railpaper.experiments.records import assert_chunk_invariant

    def batch_mean(settings, seeds):          # each row's value depends on its chunk
        values = [float(s) for s in seeds]
        return pd.DataFrame({"seed": list(seeds), "x_m": [v - np.mean(values) for v in values]})
    assert_chunk_invariant(STUDY, SPEC.resolve(), (4, 1, 9))
    with pytest.raises(AssertionError, match="one seed at a time"):
        assert_chunk_invariant(RecordStudy("demo", "bad", batch_mean), None, (4, 1, 9))


def test_the_commit_is_dirty_for_code_changes_not_for_the_stored_evidence(tmp_path):
    """A run writing or removing rows under data/evidence keeps the commit clean; any other
    tracked change marks it +dirty."""
    import subprocess

    from railpaper.pipeline.evidence_store import current_commit

    def git(*args):
        subprocess.run(["git", "-C", str(tmp_path), *args], check=True, capture_output=True)
    (tmp_path / "data" / "evidence").mkdir(parents=True)
    (tmp_path / "data" / "evidence" / "rows.csv").write_text("seed\n0\n")
    (tmp_path / "code.py").write_text("x = 1\n")
    git("init", "-q")
    git("add", ".")
    git("-c", "user.name=t", "-c", "user.email=t@t", "commit", "-q", "-m", "c")
    head = current_commit(tmp_path)
    assert len(head) == 40 and not head.endswith("+dirty")
    (tmp_path / "data" / "evidence" / "rows.csv").unlink()
    assert current_commit(tmp_path) == head
    (tmp_path / "code.py").write_text("x = 2\n")
    assert current_commit(tmp_path) == head + "+dirty"
