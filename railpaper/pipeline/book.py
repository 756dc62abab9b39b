"""Building the book: run every chapter, then ``jupyter-book build -W -n --keep-going``."""

from __future__ import annotations

import shutil
import subprocess
import sys
from pathlib import Path

from railpaper.pipeline.chapters import (BOOK_DIR, PipelineError, book_chapters, chapter_spec,
                                         run_chapter)

MATHJAX_SCRIPT = Path("_static/mathjax/node_modules/mathjax/es5/tex-chtml.js")


def write_toc(book_dir: Path, chapters: list[str]) -> Path:
    """Write ``_toc.yml``: introduction, the chapters in book order, the appendix pages."""
    lines = ["format: jb-book", "root: intro", "chapters:"]
    for name in chapters:
        stem = Path(chapter_spec(name).notebook).stem
        lines.append(f"- file: chapters/{name}/{stem}")
    for page in ("reproducibility",):
        if (book_dir / f"{page}.md").exists():
            lines.append(f"- file: {page}")
    path = book_dir / "_toc.yml"
    path.write_text("\n".join(lines) + "\n")
    return path


def build_book(quick: bool = False, book_dir: str | Path | None = None,
               progress: bool = True) -> Path:
    """Run every chapter into ``book_dir/chapters`` and build the HTML book strictly.

    ``book_dir`` defaults to the repository's ``book/``; another directory gets a copy of the
    book sources first (the tests build into a temporary directory).

    Returns
    -------
    Path
        ``book_dir/_build/html``.
    """
    book = Path(book_dir) if book_dir else BOOK_DIR
    if book.resolve() != BOOK_DIR.resolve():
        shutil.copytree(BOOK_DIR, book, dirs_exist_ok=True,
                        ignore=shutil.ignore_patterns("_build", "chapters", ".*"))
    if not (book / MATHJAX_SCRIPT).exists():
        raise PipelineError(f"MathJax is not installed at {book / MATHJAX_SCRIPT}; run `make venv`")
    chapters = book_chapters()
    for name in chapters:
        print(f"railpaper: running chapter {name}{' (quick)' if quick else ''}", file=sys.stderr)
        run_chapter(name, {}, quick, book / "chapters" / name, progress=progress)
    write_toc(book, chapters)
    jupyter_book = Path(sys.executable).parent / "jupyter-book"
    command = [str(jupyter_book), "build", str(book), "-W", "-n", "--keep-going"]
    result = subprocess.run(command, check=False)
    if result.returncode != 0:
        raise PipelineError(f"jupyter-book build failed (exit {result.returncode}); see above")
    return book / "_build" / "html"
