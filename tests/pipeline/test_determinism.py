"""Same parameters and seed → byte-identical metrics.json, across two separate processes.

Two independent quick runs of ``reduced-order-observer`` (the quick book's, and a ``railpaper
run`` on one BLAS thread) must write the same bytes; wall-clock figures must be in timings.json, not metrics.json.
"""

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]
CHAPTER = "reduced-order-observer"
WALL_CLOCK_WORDS = ("seconds", "_s_per", "wall", "time_per", "elapsed", "duration", "run_s")

pytestmark = pytest.mark.slow


def run_in_own_process(out_dir: Path) -> None:
    env = dict(os.environ, OMP_NUM_THREADS="1", OPENBLAS_NUM_THREADS="1", MKL_NUM_THREADS="1",
               PYTHONWARNINGS="ignore")
    railpaper = Path(sys.executable).parent / "railpaper"
    result = subprocess.run([str(railpaper), "run", CHAPTER, "--quick", "--out", str(out_dir)],
                            capture_output=True, text=True, timeout=600, cwd=REPO, env=env)
    assert result.returncode == 0, result.stderr[-2000:]


@pytest.fixture(scope="module")
def two_runs(tmp_path_factory, quick_chapter_dir):
    """The quick book's run of the chapter (its own kernel process, default threads) and one
    more ``railpaper run`` in a process of its own on one BLAS/OpenMP thread."""
    out = tmp_path_factory.mktemp("determinism") / "run"
    run_in_own_process(out)
    return [quick_chapter_dir(CHAPTER), out]


def test_metrics_json_bit_identical_across_processes(two_runs):
    first, second = ((d / "metrics.json").read_bytes() for d in two_runs)
    assert first == second
    assert json.loads(first)["metrics"], "no metrics written"


def test_wall_clock_lives_in_timings_only(two_runs):
    metrics = json.loads((two_runs[0] / "metrics.json").read_text())
    timings = json.loads((two_runs[0] / "timings.json").read_text())
    assert timings["metrics"], "timings.json holds no wall-clock figure"
    assert not set(timings["metrics"]) & set(metrics["metrics"])
    clocky = [k for k in metrics["metrics"] if any(w in k for w in WALL_CLOCK_WORDS)]
    assert not clocky, f"wall-clock-like metric(s) in metrics.json: {clocky}"
    # the timings really differ between the processes or are at least positive wall-clock times
    assert all(v > 0 for v in timings["metrics"].values())
    assert metrics["parameters"] == timings["parameters"] and metrics["quick"] is True
