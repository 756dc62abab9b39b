"""Where the checkout's parts are: the one root every other path is built from.

The package is installed editable from a checkout (``make venv``), so the repository root is two
levels above this file; data, the book's sources and the recorded bench payloads sit under it.
"""

from __future__ import annotations

from pathlib import Path

REPO_DIR = Path(__file__).resolve().parents[1]
DATA_DIR = REPO_DIR / "data"
BOOK_DIR = REPO_DIR / "book"
NOTEBOOK_DIR = BOOK_DIR / "notebooks"
