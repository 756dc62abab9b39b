"""A chapter's own progress, shown in the terminal while its notebook runs.

A notebook cell that calls a chapter's ``run`` can compute for minutes with the cell counter
frozen.  While :class:`TerminalProgress` is active, the kernel's ``run`` reports to a file
(:func:`railpaper.experiments.base.default_progress` reads its name from the environment the
kernel inherits) and a thread here turns the file's last line into one status line on stderr,
rewritten in place: ``rbpf-parameter-estimation  45 %  lateral record 12  (about 2 min left)``.
Nothing is shown, and nothing is written, when stderr is not a terminal: logs stay clean.
"""

from __future__ import annotations

import os
import sys
import threading
import time
from pathlib import Path

from railpaper.experiments.base import PROGRESS_FILE_ENV


def _duration(seconds: float) -> str:
    if seconds < 60:
        return f"{seconds:.0f} s"
    return f"{seconds // 60:.0f} min {seconds % 60:02.0f} s"


def status_line(name: str, fraction: float, message: str, elapsed_s: float) -> str:
    """The status line of a run ``fraction`` done after ``elapsed_s`` seconds."""
    left = ""
    if 0.02 <= fraction < 1.0:
        left = f"  (about {_duration(elapsed_s * (1.0 - fraction) / fraction)} left)"
    return f"railpaper: {name}  {100 * fraction:3.0f} %  {message}{left}"


class TerminalProgress:
    """Context manager: while active, the chapter run inside the notebook kernel reports its
    progress to ``path`` and it is shown on ``stream`` (default stderr) every ``interval_s``."""

    def __init__(self, name: str, path: Path, stream=None, interval_s: float = 0.5):
        self.name, self.path, self.interval_s = name, Path(path), interval_s
        self.stream = stream if stream is not None else sys.stderr
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._show, daemon=True)
        self._previous = None
        self._width = 0

    def __enter__(self) -> "TerminalProgress":
        self.path.write_text("")
        self._previous = os.environ.get(PROGRESS_FILE_ENV)
        os.environ[PROGRESS_FILE_ENV] = str(self.path)
        self._start = time.monotonic()
        self._thread.start()
        return self

    def __exit__(self, *exc) -> None:
        self._stop.set()
        self._thread.join()
        self._draw()
        if self._width:
            self.stream.write("\n")
            self.stream.flush()
        if self._previous is None:
            os.environ.pop(PROGRESS_FILE_ENV, None)
        else:
            os.environ[PROGRESS_FILE_ENV] = self._previous
        self.path.unlink(missing_ok=True)

    def _show(self) -> None:
        while not self._stop.wait(self.interval_s):
            self._draw()

    def _draw(self) -> None:
        try:
            lines = self.path.read_text().splitlines()
        except OSError:
            return
        if not lines or "\t" not in lines[-1]:
            return
        fraction, message = lines[-1].split("\t", 1)
        line = status_line(self.name, float(fraction), message, time.monotonic() - self._start)
        self.stream.write("\r" + line.ljust(self._width))
        self.stream.flush()
        self._width = max(self._width, len(line))
