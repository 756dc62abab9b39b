"""Chapters run side by side (``railpaper build --jobs 2``): each in its own process, the same
bits as the session's quick book (run one after another), and a failure named with its log."""

import json

import pytest

from railpaper.pipeline.chapter_process import run_chapters
from railpaper.pipeline.chapters import PipelineError


@pytest.mark.slow
def test_two_at_once_give_the_quick_books_bits(tmp_path, quick_chapter_dir, monkeypatch):
    """Side by side, and on one OpenBLAS/OpenMP thread where the quick book had the machine's
    default: the same metrics to the last bit (000 once differed in 28 metrics' last bits)."""
    for name in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
        monkeypatch.setenv(name, "1")
    names = ["reduced-order-observer", "partial-state-observer"]
    lines = []
    run_chapters(names, True, {n: tmp_path / n for n in names}, jobs=2, say=lines.append)
    for name in names:
        ours = json.loads((tmp_path / name / "metrics.json").read_text())
        book = json.loads((quick_chapter_dir(name) / "metrics.json").read_text())
        assert ours["metrics"] == book["metrics"], name
        assert not any(p.name.startswith(".") and "staging" in p.name for p in tmp_path.iterdir())
    assert sum("2 running" in line for line in lines) == 1
    assert sum(" done in " in line for line in lines) == 2


def test_a_failed_chapter_names_its_log_and_leaves_no_output(tmp_path):
    with pytest.raises(PipelineError, match=r"chapter 'no-such-chapter' failed .*build\.log"):
        run_chapters(["no-such-chapter"], True, {"no-such-chapter": tmp_path / "x"}, jobs=2,
                     say=lambda line: None)
    assert not (tmp_path / "x").exists()
    assert "no-such-chapter" in (tmp_path / ".x.build.log").read_text()
