"""Same parameters and seed → byte-identical metrics.json, across separate processes.

Two independent quick runs of ``reduced-order-observer`` (the quick book's, on the test
session's one OpenBLAS thread (``conftest.BLAS_THREADS``), and one more in a chapter process of
its own on the machine's default BLAS/OpenMP threads, side by side with
``partial-state-observer`` as ``railpaper build --jobs 2`` runs them) must write the same bytes;
wall-clock figures must be in timings.json, not metrics.json.
"""

import json

import pytest

from railpaper.pipeline.chapter_process import run_chapters

CHAPTER = "reduced-order-observer"
#: Run side by side with CHAPTER (000 once differed from the quick book in 28 metrics' last bits).
BESIDE = "partial-state-observer"
WALL_CLOCK_WORDS = ("seconds", "_s_per", "wall", "time_per", "elapsed", "duration", "run_s")

pytestmark = pytest.mark.slow


@pytest.fixture(scope="module")
def side_by_side(tmp_path_factory):
    """CHAPTER and BESIDE run at once (two chapter processes, each on the machine's default
    BLAS/OpenMP threads, where the quick book had one): their output folders and the progress
    lines."""
    base = tmp_path_factory.mktemp("determinism")
    lines = []
    with pytest.MonkeyPatch.context() as patch:
        for name in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
            patch.delenv(name, raising=False)
        run_chapters([CHAPTER, BESIDE], True, {n: base / n for n in (CHAPTER, BESIDE)}, jobs=2,
                     say=lines.append)
    return base, lines


@pytest.fixture(scope="module")
def two_runs(side_by_side, quick_chapter_dir):
    """The quick book's run of the chapter and the side-by-side one."""
    return [quick_chapter_dir(CHAPTER), side_by_side[0] / CHAPTER]


def test_metrics_json_bit_identical_across_processes(two_runs):
    first, second = ((d / "metrics.json").read_bytes() for d in two_runs)
    assert first == second
    assert json.loads(first)["metrics"], "no metrics written"


def test_two_at_once_give_the_quick_books_bits(side_by_side, quick_chapter_dir):
    """Side by side, and on the machine's default OpenBLAS/OpenMP threads where the quick book
    had one: the same metrics to the last bit, for the chapter run beside it too."""
    base, lines = side_by_side
    for name in (CHAPTER, BESIDE):
        ours = json.loads((base / name / "metrics.json").read_text())
        book = json.loads((quick_chapter_dir(name) / "metrics.json").read_text())
        assert ours["metrics"] == book["metrics"], name
    assert not any(p.name.startswith(".") and "staging" in p.name for p in base.iterdir())
    assert sum("2 running" in line for line in lines) == 1
    assert sum(" done in " in line for line in lines) == 2


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
