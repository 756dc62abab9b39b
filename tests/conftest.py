"""Shared fixtures: the quick book, built once per test session, and the quick runs read from it.

The quick book (:func:`railpaper.pipeline.book.build_book` with ``quick=True``: the four chapters
through papermill, the bench at its smoke size (every key of the Performance page, least work:
its numbers are not what the tests check), ``jupyter-book -W -n``) is what CI must prove builds; its
chapter folders are also the quick runs every chapter test reads.  It is built once per test
session in a background process, started as soon as a worker has collected a test that reads it,
so it runs beside the unit tests; the modules that read it run last, and the first of them waits
for it.

``make test`` runs the tests on two pytest-xdist workers (``-n 2 --dist loadfile
--no-loadscope-reorder``: a module stays on one worker, with its module fixtures, and the modules
are handed out in the order below), so the unit tests fill both cores around the book.  The
workers share one book through a folder the controlling process makes (``RAILPAPER_QUICK_BOOK``):
the first worker to claim it starts the build; every worker waits for the build's exit code file;
the controlling process removes the folder (and stops a build still running) at the end.  A plain
``pytest`` without workers does the same in its one process.
"""

from __future__ import annotations

import os
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
RAILPAPER = [sys.executable, "-m", "railpaper"]
#: Fixtures that read the session's quick book, or wait for it (``after_quick_book``).
BOOK_FIXTURES = {"quick_book", "quick_chapter_dir", "built_book", "after_quick_book"}
#: The environment variable that hands the shared book folder to the workers.
SHARED = "RAILPAPER_QUICK_BOOK"


def railpaper_cli(*args: str, timeout: float = 600) -> subprocess.CompletedProcess:
    """Run the CLI in a subprocess, as a user would."""
    env = dict(os.environ, PYTHONWARNINGS="ignore")
    return subprocess.run(RAILPAPER + list(args), capture_output=True, text=True, timeout=timeout,
                          cwd=REPO, env=env)


def _is_worker() -> bool:
    return "PYTEST_XDIST_WORKER" in os.environ


#: How much lower the test workers' scheduling priority is than the quick book's: on two cores the
#: book then gets a core of its own while the workers share the other, and it is done before the
#: modules that read it would wait for it.  Only where the book's process may take its priority
#: back (root, or CAP_SYS_NICE); otherwise every process keeps the priority it had.  Where Linux
#: groups CPU time by session (``/proc/sys/kernel/sched_autogroup_enabled``, on here), niceness
#: only orders processes within a session: the book runs in a session of its own, and so does
#: every notebook kernel (jupyter_client starts each in a new session), so a kernel a test starts
#: while the book builds competes with the book's kernel as an equal, whatever its niceness.
WORKER_NICENESS = 5


def _book_priority() -> None:
    """In the quick book's process before it starts: the priority the workers gave up."""
    try:
        os.nice(-WORKER_NICENESS)
    except PermissionError:
        pass


#: OpenBLAS threads per process in the test session (unless the caller set
#: ``OPENBLAS_NUM_THREADS``): the workers, the quick book and every process they start inherit
#: it.  An idle OpenBLAS thread spins before it sleeps, and with the two workers, the book and
#: their children competing for two cores that spinning is paid for: the whole suite took
#: 515 CPU-s (266 s) with the machine's default of two threads and 446 CPU-s (233 s) with one
#: (warm caches, this 2-core machine).  Results do not depend on it (``test_determinism.py``
#: runs two chapters on the machine's default threads and compares them with the quick book's).
BLAS_THREADS = "1"


def pytest_configure(config):
    """The controlling process (or a run without workers) makes the shared book folder and sets
    :data:`BLAS_THREADS` for the processes it starts; a worker lowers its priority below the
    book's where the book can take its own back."""
    if not _is_worker():
        os.environ.setdefault("OPENBLAS_NUM_THREADS", BLAS_THREADS)
        os.environ[SHARED] = tempfile.mkdtemp(prefix="railpaper-quick-book-")
    elif _may_raise_priority():
        os.nice(WORKER_NICENESS)


def _may_raise_priority() -> bool:
    """Whether a process here may lower its niceness (root, or CAP_SYS_NICE)."""
    if os.geteuid() == 0:
        return True
    try:
        capabilities = Path("/proc/self/status").read_text()
    except OSError:
        return False
    effective = next((line.split()[1] for line in capabilities.splitlines()
                      if line.startswith("CapEff:")), "0")
    return bool(int(effective, 16) & (1 << 23))           # CAP_SYS_NICE


def _root() -> Path:
    return Path(os.environ[SHARED])


def _start_quick_book() -> None:
    """Start building the quick book into the shared folder, unless a worker already did: a
    process of its own (its own session, so that a worker that finishes early does not stop it),
    which writes its exit code to ``exit_code`` when done."""
    root = _root()
    try:
        os.close(os.open(root / "claimed", os.O_CREAT | os.O_EXCL))
    except FileExistsError:
        return
    code = ("import sys; from railpaper.pipeline.book import build_book; "
            "build_book(quick=True, book_dir=sys.argv[1], progress=False, smoke_bench=True)")
    script = '"$0" -c "$1" "$2" > "$3/build.log" 2>&1; echo $? > "$3/exit_code.part"; ' \
             'mv "$3/exit_code.part" "$3/exit_code"'
    process = subprocess.Popen(["sh", "-c", script, sys.executable, code, str(root / "book"),
                                str(root)], cwd=REPO, start_new_session=True,
                               preexec_fn=_book_priority if _is_worker() else None,
                               env=dict(os.environ, PYTHONWARNINGS="ignore"))
    (root / "pid").write_text(str(process.pid))


def pytest_collection_modifyitems(session, config, items):
    """Modules that read the quick book, or wait for it, run last (each module's own order kept,
    so its module fixtures are set up once): the other tests then fill the cores while the book
    builds.  ``make test`` passes ``--no-loadscope-reorder`` so that the workers take the modules
    in this order (xdist would otherwise start with the modules that have the most tests, and a
    worker would wait for the book from the start)."""
    reads_book = {getattr(item, "module", None) for item in items    # a doctest has none
                  if BOOK_FIXTURES & set(getattr(item, "fixturenames", ()))}
    items.sort(key=lambda item: getattr(item, "module", None) in reads_book)


def pytest_collection_finish(session):
    """Start the quick book at once if any collected test reads it."""
    if any(BOOK_FIXTURES & set(getattr(item, "fixturenames", ())) for item in session.items):
        _start_quick_book()


def pytest_unconfigure(config):
    """The controlling process stops a build still running and removes the shared folder."""
    if _is_worker() or SHARED not in os.environ:
        return
    root = _root()
    pid = root / "pid"
    if pid.exists() and not (root / "exit_code").exists():
        try:
            os.killpg(int(pid.read_text()), signal.SIGKILL)
        except (ProcessLookupError, PermissionError, ValueError):
            pass
    shutil.rmtree(root, ignore_errors=True)


@pytest.fixture(scope="session")
def quick_book() -> Path:
    """The session's quick book source folder (``chapters/<name>/`` hold the chapters' quick
    runs, ``_build/html`` the built book); waits for the background build."""
    _start_quick_book()                        # no-op if this or another worker started it
    root, deadline = _root(), time.monotonic() + 3600
    while not (root / "exit_code").exists():
        assert time.monotonic() < deadline, "the quick book build did not finish within an hour"
        time.sleep(1.0)
    returncode = int((root / "exit_code").read_text())
    log = (root / "build.log").read_text()
    assert returncode == 0, f"quick book build failed (exit {returncode}):\n{log[-4000:]}"
    return root / "book"


@pytest.fixture(scope="session")
def after_quick_book(quick_book) -> None:
    """Wait for the quick book: for tests that start notebook kernels of their own.  Each
    kernel is a session of its own, which the scheduler weighs as much as both test workers
    together (see :data:`WORKER_NICENESS`), so kernels started while the book builds slow the
    book, the suite's longest chain."""


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


@pytest.fixture(scope="session")
def dask_client():
    """One dask ``LocalCluster`` of two single-threaded worker processes per test process, shared
    by the tests that check a record map on workers (each cluster costs its workers' start-up:
    imports and numba's cache, a few CPU-seconds apiece)."""
    from distributed import Client, LocalCluster
    cluster = LocalCluster(n_workers=2, threads_per_worker=1, processes=True, host="127.0.0.1",
                           dashboard_address=":0")
    client = Client(cluster)
    yield client
    client.close()
    cluster.close()
