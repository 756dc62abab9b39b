"""Chapters run side by side (``railpaper build --jobs 2``): a failure named with its log (the
same bits as the session's quick book: tests/pipeline/test_determinism.py)."""

import pytest

from railpaper.pipeline.chapter_process import run_chapters
from railpaper.pipeline.chapters import PipelineError


def test_a_failed_chapter_names_its_log_and_leaves_no_output(tmp_path):
    with pytest.raises(PipelineError, match=r"chapter 'no-such-chapter' failed .*build\.log"):
        run_chapters(["no-such-chapter"], True, {"no-such-chapter": tmp_path / "x"}, jobs=2,
                     say=lambda line: None)
    assert not (tmp_path / "x").exists()
    assert "no-such-chapter" in (tmp_path / ".x.build.log").read_text()
