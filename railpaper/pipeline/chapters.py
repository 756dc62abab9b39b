"""Executing chapter notebooks with papermill into an output directory, atomically."""

from __future__ import annotations

import contextlib
import fcntl
import json
import logging
import os
import shutil
import signal
import sys
import threading
from contextlib import contextmanager
from pathlib import Path

from railpaper.experiments import CHAPTER_MODULES, available_chapters, load_chapter
from railpaper.experiments.base import ChapterSettings, ChapterSpec, ParameterError
from railpaper.paths import BOOK_DIR, NOTEBOOK_DIR
from railpaper.pipeline.page import render_run_page
from railpaper.pipeline.progress import TerminalProgress

KERNEL_NAME = "railpaper-venv"


class PipelineError(RuntimeError):
    """A pipeline step failed; the message is one line."""


def chapter_spec(name: str) -> ChapterSpec:
    """The :class:`ChapterSpec` of a chapter, or a one-line error naming the known chapters."""
    if name not in CHAPTER_MODULES or name not in available_chapters():
        import difflib
        known = available_chapters()
        close = difflib.get_close_matches(name, known, n=1)
        hint = f" (did you mean '{close[0]}'?)" if close else ""
        raise ParameterError(f"unknown chapter '{name}'{hint}; chapters: {', '.join(known)}")
    return load_chapter(name).SPEC


def resolve_parameters(name: str, overrides: dict | None = None,
                       quick: bool = False) -> ChapterSettings:
    """A chapter's checked settings: types and ranges (:meth:`ChapterSpec.resolve`), then the
    chapter's own ``validate`` (consistency, sample time, input files) — before any kernel."""
    spec = chapter_spec(name)
    settings = spec.resolve(overrides or {}, quick)
    validate = getattr(load_chapter(name), "validate", None)
    if validate is not None:
        validate(settings)
    return settings


def book_chapters() -> list[str]:
    """Chapters with both an experiment module and a notebook, in book order."""
    return [name for name in available_chapters()
            if (NOTEBOOK_DIR / load_chapter(name).SPEC.notebook).exists()]


def paper_chapters() -> list[str]:
    """The book's chapters that rebuild a paper (each with a claims ledger), in book order; the
    others (``SPEC.paper`` empty) are studies of our own with findings instead of claims."""
    return [name for name in book_chapters() if chapter_spec(name).paper]


def default_output_dir(name: str) -> Path:
    """Where the book takes a chapter's executed notebook and outputs from."""
    return BOOK_DIR / "chapters" / name


def ensure_kernel() -> str:
    """Register a kernel of *this* interpreter and put it first on JUPYTER_PATH.

    Chapter notebooks then execute on the interpreter that runs the pipeline (the project's
    ``.venv``), whatever kernels the user has registered elsewhere.
    """
    root = Path(sys.prefix) / "share" / "jupyter"
    spec_dir = root / "kernels" / KERNEL_NAME
    spec = {"argv": [sys.executable, "-m", "ipykernel_launcher", "-f", "{connection_file}"],
            "display_name": "railpaper (.venv)", "language": "python"}
    spec_file = spec_dir / "kernel.json"
    if not spec_file.exists() or json.loads(spec_file.read_text()) != spec:
        spec_dir.mkdir(parents=True, exist_ok=True)
        spec_file.write_text(json.dumps(spec, indent=1))
    paths = [str(root)] + [p for p in os.environ.get("JUPYTER_PATH", "").split(os.pathsep) if p]
    os.environ["JUPYTER_PATH"] = os.pathsep.join(dict.fromkeys(paths))
    return KERNEL_NAME


@contextmanager
def signals_deferred():
    """SIGINT and SIGTERM arriving inside the block take effect when it ends (main thread only)."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    received = []
    previous = {s: signal.signal(s, lambda signum, frame: received.append(signum))
                for s in (signal.SIGINT, signal.SIGTERM)}
    try:
        yield
    finally:
        for s, handler in previous.items():
            signal.signal(s, handler)
        if received:
            signal.raise_signal(received[0])


@contextmanager
def chapter_lock(out_dir: Path):
    """Exclusive lock per output directory: two runs of the same chapter at once are refused."""
    out_dir.parent.mkdir(parents=True, exist_ok=True)
    lock_path = out_dir.parent / f".{out_dir.name}.lock"
    with open(lock_path, "w") as handle:
        try:
            fcntl.flock(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            raise PipelineError(f"another run is writing {out_dir}; wait for it to finish") from None
        try:
            yield
        finally:
            fcntl.flock(handle, fcntl.LOCK_UN)


def _logging_kernel_manager(log_path: Path):
    """A kernel manager class whose kernel writes its stderr to ``log_path``, not to ours: an
    interrupted run ends in one line, not in the kernel's tracebacks about closed sockets."""
    from jupyter_client import AsyncKernelManager

    class LoggingKernelManager(AsyncKernelManager):
        async def start_kernel(self, **kw):
            with open(log_path, "a") as log:           # the child keeps its own copy of the fd
                kw.setdefault("stderr", log)
                return await super().start_kernel(**kw)

    return LoggingKernelManager


# Loggers that report on the notebook's execution.  Left alone they print to our stderr through
# logging's last-resort handler; on an interrupt that is "Kernel died while waiting for execute
# reply" and, at exit, asyncio's "Task exception was never retrieved" traceback of the cell that
# was running.
_NOTEBOOK_LOGGERS = ("papermill", "nbclient", "traitlets", "asyncio")


@contextmanager
def _notebook_logs_to(log_path: Path):
    """Send the notebook machinery's log records to ``log_path`` (appended) while the block runs.

    On an interrupt the redirection stays in place: asyncio reports the killed cell's pending
    task only when the process exits, after our one-line message.
    """
    handler = logging.FileHandler(log_path, mode="a", delay=True)
    handler.setFormatter(logging.Formatter("%(asctime)s %(name)s %(levelname)s: %(message)s"))
    loggers = [logging.getLogger(name) for name in _NOTEBOOK_LOGGERS]
    saved = [(logger.propagate, logger.handlers[:]) for logger in loggers]
    for logger in loggers:
        logger.handlers = [handler]
        logger.propagate = False

    def restore():
        for logger, (propagate, handlers) in zip(loggers, saved):
            logger.handlers, logger.propagate = handlers, propagate
        handler.close()

    try:
        yield
    except KeyboardInterrupt:
        raise                                    # keep the redirection: the process is ending
    except BaseException:
        restore()
        raise
    restore()


def hide_parameter_cells(notebook_path: Path) -> None:
    """Tag papermill's parameter cells ``remove-cell`` so the book shows the parameter table the
    notebook prints instead of raw assignments with a staging path."""
    import nbformat

    notebook = nbformat.read(notebook_path, as_version=4)
    for cell in notebook.cells:
        tags = cell.metadata.setdefault("tags", [])
        if ("parameters" in tags or "injected-parameters" in tags) and "remove-cell" not in tags:
            tags.append("remove-cell")
    nbformat.write(notebook, notebook_path)


def run_chapter(name: str, overrides: dict | None = None, quick: bool = False,
                out_dir: str | Path | None = None, progress: bool = True,
                page: bool = True) -> Path:
    """Execute a chapter notebook with papermill; outputs land in ``out_dir`` only on success.

    Parameters are checked before any kernel starts.  The notebook runs in a staging directory
    beside ``out_dir``; on success the staging directory replaces ``out_dir``, on failure
    (error, interrupt) it is removed and the previous good outputs stay untouched.  The kernel's
    stderr goes to ``.<out_dir name>.kernel.log`` beside ``out_dir``.  With ``page``, the executed
    notebook is also rendered as a web page, ``out_dir/index.html`` (see
    :mod:`railpaper.pipeline.page`; the book renders its chapters itself).  With ``progress``
    (the CLI sets it when stderr is a terminal), the chapter's own progress is shown on one
    status line (:class:`railpaper.pipeline.progress.TerminalProgress`).

    Returns
    -------
    Path
        The output directory (holding the executed notebook, metrics.json, timings.json, CSV
        files and PNG figures).
    """
    import papermill

    spec = chapter_spec(name)
    settings = resolve_parameters(name, overrides, quick)
    spec.check_notebook_values(settings)
    out = Path(out_dir) if out_dir else default_output_dir(name)
    out = out.resolve()
    if out.exists() and not out.is_dir():
        raise PipelineError(f"--out {out} is a file, not a directory")
    if out.is_dir() and any(out.iterdir()) and not (out / "metrics.json").exists():
        # the swap replaces out_dir as a whole: never a directory that holds something else
        raise PipelineError(f"--out {out} holds files but no previous run (no metrics.json); "
                            "use a new or empty directory")
    source = NOTEBOOK_DIR / spec.notebook
    if not source.exists():
        raise PipelineError(f"notebook {source} is missing")
    kernel = ensure_kernel()
    with chapter_lock(out):
        staging = out.parent / f".{out.name}.staging-{os.getpid()}"
        shutil.rmtree(staging, ignore_errors=True)
        staging.mkdir(parents=True)
        kernel_log = out.parent / f".{out.name}.kernel.log"
        kernel_log.write_text("")                 # this run's log only; kernel and loggers append
        try:
            shown = (TerminalProgress(name, out.parent / f".{out.name}.progress")
                     if progress else contextlib.nullcontext())
            with _notebook_logs_to(kernel_log), shown:
                papermill.execute_notebook(
                    str(source), str(staging / spec.notebook),
                    parameters={"overrides": settings.as_dict(), "quick": quick, "out_dir": str(staging)},
                    kernel_name=kernel, cwd=str(staging), progress_bar=False,
                    request_save_on_cell_execute=False,
                    kernel_manager_class=_logging_kernel_manager(kernel_log))
            if not (staging / "metrics.json").exists():
                raise PipelineError(f"chapter '{name}' ran but wrote no metrics.json")
            hide_parameter_cells(staging / spec.notebook)
            if page:
                render_run_page(staging, spec.notebook, spec.title)
        except BaseException as exc:
            shutil.rmtree(staging, ignore_errors=True)
            if isinstance(exc, papermill.PapermillExecutionError):
                raise PipelineError(
                    f"chapter '{name}' failed in cell {exc.exec_count}: {exc.ename}: "
                    f"{exc.evalue}".splitlines()[0]) from None
            if type(exc).__name__ == "DeadKernelError":          # nbclient: e.g. out of memory
                raise PipelineError(f"chapter '{name}': the notebook kernel died (out of memory? "
                                    f"see {kernel_log})") from None
            raise
        previous = out.parent / f".{out.name}.previous-{os.getpid()}"
        with signals_deferred():                  # never between the renames: out would be gone
            if out.exists():
                out.rename(previous)
            staging.rename(out)
            shutil.rmtree(previous, ignore_errors=True)
    return out
