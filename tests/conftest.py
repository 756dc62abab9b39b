"""Shared fixtures: the quick book, built once per test session, and the quick runs read from it.

The quick book (:func:`railpaper.pipeline.book.build_book` with ``quick=True``: the four chapters
through papermill, the bench at its smoke size (every key of the Performance page, least work:
its numbers are not what the tests check), ``jupyter-book -W -n``) is what CI must prove builds; its
chapter folders are also the quick runs every chapter test reads.  It is started in a background
process as soon as the tests are collected, so it runs on the second core while the unit tests
run on the first; the modules that read it run last, and the first of them waits for it.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
RAILPAPER = [sys.executable, "-m", "railpaper"]
#: Fixtures that read the session's quick book.
BOOK_FIXTURES = {"quick_book", "quick_chapter_dir", "built_book"}
_BUILD: dict = {}


def railpaper_cli(*args: str, timeout: float = 600) -> subprocess.CompletedProcess:
    """Run the CLI in a subprocess, as a user would."""
    env = dict(os.environ, PYTHONWARNINGS="ignore")
    return subprocess.run(RAILPAPER + list(args), capture_output=True, text=True, timeout=timeout,
                          cwd=REPO, env=env)


def _start_quick_book() -> None:
    """Start building the quick book into a fresh folder, in a process of its own."""
    root = Path(tempfile.mkdtemp(prefix="railpaper-quick-book-"))
    book = root / "book"
    log = open(root / "build.log", "w")
    code = ("import sys; from railpaper.pipeline.book import build_book; "
            "build_book(quick=True, book_dir=sys.argv[1], progress=False, smoke_bench=True)")
    process = subprocess.Popen([sys.executable, "-c", code, str(book)], cwd=REPO, stdout=log,
                               stderr=subprocess.STDOUT,
                               env=dict(os.environ, PYTHONWARNINGS="ignore"))
    _BUILD.update(root=root, book=book, log=log, process=process)


def pytest_collection_modifyitems(session, config, items):
    """Modules that read the quick book run last (each module's own order kept, so its module
    fixtures are set up once): the other tests then fill the first core while the book builds."""
    reads_book = {item.module for item in items
                  if BOOK_FIXTURES & set(getattr(item, "fixturenames", ()))}
    items.sort(key=lambda item: item.module in reads_book)


def pytest_collection_finish(session):
    """Start the quick book at once if any selected test reads it."""
    wanted = any(BOOK_FIXTURES & set(getattr(item, "fixturenames", ())) for item in session.items)
    if wanted and not _BUILD:
        _start_quick_book()


def pytest_sessionfinish(session, exitstatus):
    if _BUILD:
        process = _BUILD["process"]
        if process.poll() is None:
            process.kill()
            process.wait()
        _BUILD["log"].close()
        shutil.rmtree(_BUILD["root"], ignore_errors=True)


@pytest.fixture(scope="session")
def quick_book() -> Path:
    """The session's quick book source folder (``chapters/<name>/`` hold the chapters' quick
    runs, ``_build/html`` the built book); waits for the background build."""
    if not _BUILD:
        _start_quick_book()
    process = _BUILD["process"]
    returncode = process.wait(timeout=3600)
    _BUILD["log"].flush()
    log = (_BUILD["root"] / "build.log").read_text()
    assert returncode == 0, f"quick book build failed (exit {returncode}):\n{log[-4000:]}"
    return _BUILD["book"]


@pytest.fixture(scope="session")
def built_book(quick_book) -> Path:
    """The quick book's HTML (``_build/html``)."""
    return quick_book / "_build" / "html"


@pytest.fixture(scope="session")
def quick_chapter_dir(quick_book):
    """chapter -> the folder of its quick papermill run inside the session's quick book (the
    same outputs as ``railpaper run CHAPTER --quick``, without the run's own page)."""
    def folder(chapter: str) -> Path:
        out = quick_book / "chapters" / chapter
        assert (out / "metrics.json").exists(), f"the quick book has no run of {chapter}"
        return out
    return folder
