"""A run's own web page: ``railpaper run`` renders the executed chapter as ``DIR/index.html``.

The page is the book's chapter page for this run — same theme, offline MathJax, the figures
(numbered), the references, and the claims section judged on this run's metrics (marked when the
parameters are not the defaults) — built as a small Jupyter Book whose root is the executed
notebook, beside the book's References and Reproducibility pages, with the book's configuration.  MathJax is loaded from this checkout (``book/_mathjax``, a ``file://`` address)
rather than copied into every run.
"""

from __future__ import annotations

import shutil
import subprocess
import sys
from pathlib import Path

from railpaper.paths import BOOK_DIR

PAGE_DIR = "page"


def _config(title: str) -> str:
    mathjax = (BOOK_DIR / "_mathjax/node_modules/mathjax/es5/tex-chtml.js").resolve().as_uri()
    return "\n".join([
        f"title: {title!r}",
        "only_build_toc_files: true",
        "execute:",
        "  execute_notebooks: 'off'",
        "parse:",
        "  myst_enable_extensions: [dollarmath, amsmath]",
        "bibtex_bibfiles:",
        f"  - {str((BOOK_DIR / 'references.bib').resolve())!r}",
        "sphinx:",
        "  local_extensions:",
        f"    unique_scripts: {str((BOOK_DIR / '_ext').resolve())!r}",
        "  config:",
        f"    mathjax_path: {mathjax!r}",
        f"    html_static_path: [{str((BOOK_DIR / '_static').resolve())!r}]",
        "    html_css_files: [verdicts.css]",
        "    nb_execution_mode: 'off'",
        "    nb_render_markdown_format: 'myst'",
        "    bibtex_reference_style: author_year",
        "    suppress_warnings: ['mystnb.unknown_mime_type']",
        ""])


def render_run_page(run_dir: Path, notebook: str, title: str) -> Path | None:
    """Build ``run_dir/page/`` from the executed ``run_dir/notebook`` and write
    ``run_dir/index.html`` pointing at it.  Returns the index, or None (with one line on
    stderr) when Jupyter Book could not build the page — the run's results stand without it."""
    run_dir = Path(run_dir)
    work = run_dir / ".page-build"
    shutil.rmtree(work, ignore_errors=True)
    source = work / "src"
    source.mkdir(parents=True)
    stem = Path(notebook).stem
    shutil.copy2(run_dir / notebook, source / notebook)
    for figure in run_dir.glob("*.png"):              # the notebook's {figure} files
        shutil.copy2(figure, source / figure.name)
    for page_name in ("references.md", "reproducibility.md"):
        if (BOOK_DIR / page_name).exists():
            shutil.copy2(BOOK_DIR / page_name, source / page_name)
    (source / "_config.yml").write_text(_config(title))
    (source / "_toc.yml").write_text(
        f"format: jb-book\nroot: {stem}\nchapters:\n- file: reproducibility\n"
        "- file: references\n")
    jupyter_book = Path(sys.executable).parent / "jupyter-book"
    result = subprocess.run(
        [str(jupyter_book), "build", str(source), "--path-output", str(work)],
        capture_output=True, text=True, check=False)
    html = work / "_build" / "html"
    if result.returncode != 0 or not (html / f"{stem}.html").exists():
        tail = (result.stderr or result.stdout).strip().splitlines()[-1:] or ["no output"]
        print(f"railpaper: note: the run's web page could not be built ({tail[0]}); "
              "its results are complete", file=sys.stderr)
        shutil.rmtree(work, ignore_errors=True)
        return None
    page = run_dir / PAGE_DIR
    shutil.rmtree(page, ignore_errors=True)
    shutil.move(str(html), str(page))
    shutil.rmtree(work, ignore_errors=True)
    index = run_dir / "index.html"
    index.write_text(
        "<!DOCTYPE html>\n<html><head><meta charset=\"utf-8\">"
        f"<meta http-equiv=\"refresh\" content=\"0; url={PAGE_DIR}/{stem}.html\">"
        f"<title>{title}</title></head>\n<body><a href=\"{PAGE_DIR}/{stem}.html\">"
        f"{title}</a></body></html>\n")
    return index
