"""Building the book: run every chapter, then ``jupyter-book build -W -n --keep-going``."""

from __future__ import annotations

import platform
import re
import shutil
import subprocess
import sys
from pathlib import Path

from railpaper.bench.report import write_performance
from railpaper.paths import BOOK_DIR, REPO_DIR
from railpaper.pipeline.chapter_process import run_chapters
from railpaper.pipeline.chapters import (
    PipelineError,
    book_chapters,
    chapter_spec,
    run_chapter,
)
from railpaper.pipeline.ledger import write_ledger

MATHJAX_SCRIPT = Path("_mathjax/node_modules/mathjax/es5/tex-chtml.js")
APPENDIX_PAGES = ("reproducibility", "performance", "references")
KEY_PACKAGES = ("numpy", "scipy", "cvxpy", "clarabel", "control", "filterpy", "numba", "dask",
                "distributed", "matplotlib", "pandas", "papermill", "jupyter-book")


def write_toc(book_dir: Path, chapters: list[str]) -> Path:
    """Write ``_toc.yml``: introduction, the papers' chapters numbered in book order, the
    chapters of our own (no paper) under "Beyond the papers", then the appendix pages that
    exist (unnumbered)."""
    lines = ["format: jb-book", "root: intro", "parts:", "- caption: Chapters", "  numbered: true",
             "  chapters:"]
    ours = [name for name in chapters if not chapter_spec(name).paper]
    for name in [name for name in chapters if name not in ours]:
        stem = Path(chapter_spec(name).notebook).stem
        lines.append(f"  - file: chapters/{name}/{stem}")
    if ours:
        lines += ["- caption: Beyond the papers", "  chapters:"]
        lines += [f"  - file: chapters/{name}/{Path(chapter_spec(name).notebook).stem}"
                  for name in ours]
    appendix = [page for page in APPENDIX_PAGES if (book_dir / f"{page}.md").exists()]
    if appendix:
        lines += ["- caption: Appendix", "  chapters:"]
        lines += [f"  - file: {page}" for page in appendix]
    path = book_dir / "_toc.yml"
    path.write_text("\n".join(lines) + "\n")
    return path


def locked_versions(lock_path: str | Path) -> dict[str, str]:
    """``{package: version}`` of every ``name==version`` pin in a uv/pip lock file."""
    pins = re.findall(r"^([A-Za-z0-9_.-]+)==([^ \\\n]+)", Path(lock_path).read_text(), re.M)
    return {name.lower(): version for name, version in pins}


def write_environment(book_dir: Path, lock_path: Path = REPO_DIR / "environment.lock") -> Path:
    """Write ``_generated/environment.md``: the key packages' pinned versions from the lock."""
    pins = locked_versions(lock_path)
    header = Path(lock_path).read_text().splitlines()[:3]
    python = next((m.group(1) for line in header
                   if (m := re.search(r"--python-version (\S+)", line))), "see pyproject.toml")
    lines = ["| package | pinned version |", "|---|---|",
             f"| python | {python} (this build: {platform.python_version()}) |"]
    for name in KEY_PACKAGES:
        lines.append(f"| {name} | {pins.get(name, 'not in the lock')} |")
    lines += ["", f"{len(pins)} packages are pinned with hashes in `environment.lock`."]
    path = book_dir / "_generated" / "environment.md"
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text("\n".join(lines) + "\n")
    return path


def build_book(quick: bool = False, book_dir: str | Path | None = None,
               progress: bool = True, smoke_bench: bool = False, jobs: int = 1) -> Path:
    """Run every chapter into ``book_dir/chapters`` and build the HTML book strictly.

    ``book_dir`` defaults to the repository's ``book/``; another directory gets a copy of the
    book sources first (the tests build into a temporary directory).  ``smoke_bench``: the
    Performance page from the smoke-sized bench (the test suite, which tests the page's
    structure, not its numbers).  ``jobs``: chapters run at once, each in its own process on
    one core (:mod:`railpaper.pipeline.chapter_process`; same metrics, bit for bit); the bench
    runs after them, alone, as it needs a quiet machine.

    Returns
    -------
    Path
        ``book_dir/_build/html``.
    """
    book = Path(book_dir) if book_dir else BOOK_DIR
    if book.resolve() != BOOK_DIR.resolve():
        shutil.copytree(BOOK_DIR, book, dirs_exist_ok=True,
                        ignore=shutil.ignore_patterns("_build", "chapters", "_generated", ".*"))
    if not (book / MATHJAX_SCRIPT).exists():
        raise PipelineError(f"MathJax is not installed at {book / MATHJAX_SCRIPT}; run `make venv`")
    chapters = book_chapters()
    if jobs > 1:
        run_chapters(chapters, quick, {name: book / "chapters" / name for name in chapters}, jobs)
    else:
        for name in chapters:
            print(f"railpaper: running chapter {name}{' (quick)' if quick else ''}",
                  file=sys.stderr)
            run_chapter(name, {}, quick, book / "chapters" / name, progress=progress, page=False)
    write_ledger(book, [name for name in chapters if chapter_spec(name).paper])
    write_environment(book)
    if (book / "performance.md").exists():
        print("railpaper: engine benchmark (quick) for the performance page", file=sys.stderr)
        write_performance(book, smoke=smoke_bench)
    write_toc(book, chapters)
    jupyter_book = Path(sys.executable).parent / "jupyter-book"
    command = [str(jupyter_book), "build", str(book), "-W", "-n", "--keep-going"]
    result = subprocess.run(command, check=False)
    if result.returncode != 0:
        raise PipelineError(f"jupyter-book build failed (exit {result.returncode}); see above")
    return book / "_build" / "html"
