"""railpaper compare: parameters and metrics that differ, verdicts side by side, bad input."""

import json

import pandas as pd
import pytest

from railpaper.cli import main
from railpaper.pipeline.chapters import chapter_spec
from railpaper.pipeline.compare import compare_runs

CHAPTER = "reduced-order-observer"


def write_run(directory, seed, metrics):
    directory.mkdir()
    settings = chapter_spec(CHAPTER).resolve({"seed": seed}, True)
    (directory / "metrics.json").write_text(json.dumps(
        {"chapter": CHAPTER, "parameters": settings.as_dict(), "quick": True, "metrics": metrics}))
    return directory


def test_compare_lists_differences(tmp_path):
    a = write_run(tmp_path / "a", 0, {"x": 1.0, "same": 2, "flag": True})
    b = write_run(tmp_path / "b", 5, {"x": 1.5, "same": 2, "flag": False, "only_b": 3.0})
    result = compare_runs(a, b)
    assert result["parameters"].values.tolist() == [["seed", "0", "5"]]
    m = result["metrics"].set_index("metric")
    assert m.loc["x", "B_minus_A"] == 0.5 and bool(m.loc["x", "differs"])
    assert not bool(m.loc["same", "differs"]) and bool(m.loc["only_b", "differs"])
    assert pd.isna(m.loc["flag", "B_minus_A"])              # booleans: no difference
    assert len(result["claims"]) > 0          # every claim of the chapter, judged on each run


def test_compare_cli_csv_and_errors(tmp_path, capsys):
    a = write_run(tmp_path / "a", 0, {"x": 1.0})
    b = write_run(tmp_path / "b", 1, {"x": 2.0})
    assert main(["compare", str(a), str(b), "--out", str(tmp_path / "m.csv")]) == 0
    out = capsys.readouterr().out
    assert "seed" in out and "metrics: 1 of 1 differ" in out
    assert (tmp_path / "m.csv").read_text().splitlines()[0] == "metric,A,B,B_minus_A,differs"
    assert main(["compare", str(a), str(tmp_path / "nowhere")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("railpaper: error:") and "metrics.json" in err[0]
    other = tmp_path / "c"
    other.mkdir()
    (other / "metrics.json").write_text(json.dumps({"chapter": "quasi-gaussian-rbpf",
                                                    "metrics": {}}))
    assert main(["compare", str(a), str(other)]) == 2
    assert "cannot compare" in capsys.readouterr().err
