"""A run's own progress reaches the terminal: the kernel-side callback writes, the pipeline shows."""

import io
import os
import time

from railpaper.experiments.base import PROGRESS_FILE_ENV, default_progress, no_progress
from railpaper.pipeline.progress import TerminalProgress, status_line


def test_without_the_environment_the_callback_is_silent(monkeypatch):
    monkeypatch.delenv(PROGRESS_FILE_ENV, raising=False)
    assert default_progress() is no_progress


def test_reports_reach_the_status_line_and_the_environment_is_restored(tmp_path, monkeypatch):
    monkeypatch.delenv(PROGRESS_FILE_ENV, raising=False)
    stream = io.StringIO()
    path = tmp_path / ".run.progress"
    with TerminalProgress("toy-chapter", path, stream=stream, interval_s=0.01):
        report = default_progress()                  # what the kernel's run() calls
        report(0.25, "lateral   record 3")
        time.sleep(0.1)
        report(0.5, "lateral record 6")
    shown = stream.getvalue()
    assert "railpaper: toy-chapter   50 %  lateral record 6" in shown
    assert "lateral record 3" in shown and shown.endswith("\n") and shown.count("\r") >= 2
    assert PROGRESS_FILE_ENV not in os.environ and not path.exists()


def test_time_left_is_extrapolated_from_the_fraction_done():
    assert status_line("c", 0.25, "m", 30.0) == "railpaper: c   25 %  m  (about 1 min 30 s left)"
    assert status_line("c", 1.0, "done", 30.0) == "railpaper: c  100 %  done"
    assert "left" not in status_line("c", 0.01, "start", 1.0)
