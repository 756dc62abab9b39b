"""Shared fixtures: one quick papermill run of each chapter per test session."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
RAILPAPER = [sys.executable, "-m", "railpaper"]


def railpaper_cli(*args: str, timeout: float = 600) -> subprocess.CompletedProcess:
    """Run the CLI in a subprocess, as a user would."""
    env = dict(os.environ, PYTHONWARNINGS="ignore")
    return subprocess.run(RAILPAPER + list(args), capture_output=True, text=True, timeout=timeout,
                          cwd=REPO, env=env)


@pytest.fixture(scope="session")
def quick_run_dir(tmp_path_factory):
    """Run a chapter through papermill in quick mode once; returns a function chapter -> dir."""
    cache: dict[str, Path] = {}

    def run(chapter: str) -> Path:
        if chapter not in cache:
            out = tmp_path_factory.mktemp(chapter) / "run"
            result = railpaper_cli("run", chapter, "--quick", "--out", str(out))
            assert result.returncode == 0, result.stderr[-2000:]
            cache[chapter] = out
        return cache[chapter]

    return run
