"""Monte Carlo sweeps on dask.distributed: same numbers locally and on a cluster, resume, failures,
summary statistics, CLI errors.

Samples are quick runs of the cheapest chapter at one speed without its side tables (≈0.2 s each).
"""

import json

import numpy as np
import pandas as pd
import pytest
from conftest import railpaper_cli
from distributed import LocalCluster

from railpaper.cli import main
from railpaper.experiments.reduced_order_observer import experiment as chapter
from railpaper.experiments.reduced_order_observer.spec import SPEC
from railpaper.pipeline.sweep import (
    SINGLE_THREAD_ENV,
    parse_grid_option,
    parse_seeds,
    run_sweep,
)

CHAPTER = "reduced-order-observer"
FIXED = {"speeds_kmh": [60.0], "sweep_speeds_kmh": [60.0], "side_tables": False}
METRICS = ["convergence_time_s_60kmh", "force_rms_error_N_60kmh",
           "force_relative_rms_error_60kmh", "displacement_rms_error_m_60kmh"]


@pytest.fixture(scope="module")
def scheduler():
    """A real dask.distributed cluster on loopback: 2 single-threaded worker processes."""
    with LocalCluster(host="127.0.0.1", n_workers=2, threads_per_worker=1, processes=True,
                      dashboard_address=":0", env=dict(SINGLE_THREAD_ENV)) as cluster:
        yield cluster.scheduler_address


def sweep(out, scheduler=None, grid=None, seeds="0:2", **kwargs):
    return run_sweep(CHAPTER, grid or {"noise_fraction": [0.01, 0.03]}, seeds, out, fixed=FIXED,
                     quick=True, scheduler=scheduler, progress=False, **kwargs)


def test_local_workers_and_cluster_give_identical_metrics(tmp_path, scheduler):
    local = sweep(tmp_path / "local", workers=2)
    remote = sweep(tmp_path / "cluster", scheduler=scheduler)
    assert len(local) == len(remote) == 4
    assert (local.status == "ok").all() and (remote.status == "ok").all()
    assert local[["noise_fraction", "seed"]].equals(remote[["noise_fraction", "seed"]])
    for metric in METRICS:
        assert local[metric].tolist() == remote[metric].tolist()      # bit-identical floats
    # independent reference: the experiment called directly in this process
    direct = chapter.run(SPEC.resolve(dict(FIXED, noise_fraction=0.03, seed=1), True)).metrics
    row = remote[(remote.noise_fraction == 0.03) & (remote.seed == 1)].iloc[0]
    for metric in METRICS:
        assert row[metric] == pytest.approx(direct[metric], rel=1e-9)
    # the CSV reads back bit-identical
    table = pd.read_csv(tmp_path / "cluster" / "results.csv")
    for metric in METRICS:
        assert table[metric].tolist() == remote[metric].tolist()
    record = json.loads((tmp_path / "cluster" / "sweep.json").read_text())
    assert record["seeds"] == [0, 1] and record["fixed"]["side_tables"] is False


def test_resume_skips_completed_rows(tmp_path, scheduler, capsys):
    out = tmp_path / "sweep"
    first = sweep(out, scheduler=scheduler)
    table = pd.read_csv(out / "results.csv")
    table.drop(index=2).to_csv(out / "results.csv", index=False, float_format="%.17g")  # "killed"
    capsys.readouterr()
    again = run_sweep(CHAPTER, {"noise_fraction": [0.01, 0.03]}, "0:3", out, fixed=FIXED,
                      quick=True, scheduler=scheduler)
    assert "6 samples, 3 already done" in capsys.readouterr().err
    assert len(again) == 6 and (again.status == "ok").all()
    kept = again[again["sample"] != first["sample"][2]]
    merged = kept.merge(first, on="sample", suffixes=("", "_first"))
    assert len(merged) == 3                                       # rows 0, 1, 3 of the first run
    assert (merged.wall_time_s == merged.wall_time_s_first).all()  # not recomputed
    redone = again[again["sample"] == first["sample"][2]].iloc[0]
    assert redone[METRICS[1]] == first[METRICS[1]][2]             # recomputed, same number
    assert redone.wall_time_s != first.wall_time_s[2]
    complete = run_sweep(CHAPTER, {"noise_fraction": [0.01, 0.03]}, "0:3", out, fixed=FIXED,
                         quick=True, scheduler=scheduler, progress=False)   # nothing left to do
    pd.testing.assert_frame_equal(complete, again)


def test_failing_sample_is_recorded_and_the_others_complete(tmp_path, scheduler):
    # error_window_start_s = 5 s passes the parameter check but run() rejects it (quick: 1 s runs)
    frame = sweep(tmp_path / "s", scheduler=scheduler, grid={"error_window_start_s": [0.5, 5.0]})
    failed = frame[frame.error_window_start_s == 5.0]
    ok = frame[frame.error_window_start_s == 0.5]
    assert (failed.status == "error").all() and len(failed) == 2
    assert failed.error.str.contains("must be shorter than 'duration_s'").all()
    assert failed[METRICS].isna().all().all()
    assert (ok.status == "ok").all() and ok[METRICS].notna().all().all()
    summary = pd.read_csv(tmp_path / "s" / "summary.csv")
    bad = summary[summary.error_window_start_s == 5.0]
    assert bad.metric.tolist() == ["-"] and bad["count"].tolist() == [0]
    assert bad.failed.tolist() == [2]


def test_summary_equals_independent_statistics(tmp_path, scheduler):
    sweep(tmp_path / "s", scheduler=scheduler, seeds="0:3")
    results = pd.read_csv(tmp_path / "s" / "results.csv")
    summary = pd.read_csv(tmp_path / "s" / "summary.csv")
    for (noise, metric), row in summary.set_index(["noise_fraction", "metric"]).iterrows():
        values = results.loc[results.noise_fraction == noise, metric]
        assert row["count"] == len(values) == 3
        expected = [values.mean(), values.std(), values.quantile(0.05), values.median(),
                    values.quantile(0.95)]
        assert row[["mean", "std", "q05", "q50", "q95"]].tolist() == pytest.approx(expected,
                                                                                  rel=1e-12)
    assert set(summary.metric) == set(METRICS) | {"wall_time_s"}


def test_cli_sweep_on_a_cluster(tmp_path, scheduler):
    out = tmp_path / "cli"
    result = railpaper_cli("sweep", CHAPTER, "--quick", "--grid", "speeds_kmh=[60],[100]",
                           "-p", "sweep_speeds_kmh", "[60]", "-p", "side_tables", "false",
                           "--seeds", "0:2", "--out", str(out), "--scheduler", scheduler)
    assert result.returncode == 0, result.stderr[-2000:]
    assert "railpaper: sweep 4/4 done, 0 failed, ETA 0m00s" in result.stderr
    table = pd.read_csv(out / "results.csv")
    assert table.speeds_kmh.tolist() == ["[60.0]", "[60.0]", "[100.0]", "[100.0]"]
    assert table.convergence_time_s_100kmh.notna().tolist() == [False, False, True, True]


def test_grid_and_seed_syntax():
    assert parse_seeds("0:50") == list(range(50))
    assert parse_seeds("3,1,7") == [3, 1, 7]
    assert parse_grid_option("speeds_kmh=[60, 80],[100]", json.loads) == \
        ("speeds_kmh", [[60, 80], [100]])
    assert parse_grid_option("noise_fraction=0,0.01", json.loads) == ("noise_fraction", [0, 0.01])


@pytest.mark.parametrize("args, message", [
    (["nope"], "unknown chapter 'nope'"),
    (["reduced-order-observer", "--grid", "speed_kmh=60"], "did you mean 'speeds_kmh'"),
    (["reduced-order-observer", "--grid", "duration_s=1,-2"], "must be > 0"),
    (["reduced-order-observer", "--grid", "duration_s"], "--grid expects NAME=V1,V2"),
    (["reduced-order-observer", "--seeds", "5:2"], "gives no seeds"),
    (["reduced-order-observer", "--seeds", "a:b"], "--seeds expects START:STOP"),
    (["reduced-order-observer", "--scheduler", "tcp://127.0.0.1:9"], "cannot reach dask scheduler"),
])
def test_cli_bad_input_one_line_exit_2(args, message, tmp_path, capsys):
    argv = ["sweep", *args] + ([] if "--seeds" in args else ["--seeds", "0:2"])
    assert main([*argv, "--out", str(tmp_path / "out")]) == 2      # the CLI's own error handling
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("railpaper: error:"), lines
    assert message in lines[0]
    assert not (tmp_path / "out").exists()


def test_refuses_a_directory_of_another_sweep(tmp_path):
    from railpaper.pipeline.chapters import PipelineError
    out = tmp_path / "s"
    out.mkdir()
    record = {"chapter": CHAPTER, "quick": True, "fixed": dict(FIXED, noise_fraction=0.5)}
    (out / "sweep.json").write_text(json.dumps(record))
    with pytest.raises(PipelineError, match="other fixed parameters"):
        sweep(out, grid={"duration_s": [1.0]})
    with pytest.raises(PipelineError, match="holds a sweep of"):
        run_sweep(CHAPTER, {}, "0:1", out, progress=False)            # full, not quick
    assert sorted(p.name for p in out.iterdir()) == ["sweep.json"]
