"""Experiments: one module per chapter, the whole computation as a function of its parameters.

Every chapter module defines ``SPEC`` (a :class:`railpaper.experiments.base.ChapterSpec`) and a
function ``run(**parameters) -> ChapterResult``.  A chapter whose ``SPEC.paper`` is empty is an
appendix chapter of our own (no paper, no claims ledger: findings instead).  The registry below maps chapter names to
module paths; modules are imported lazily so that a CLI call does not import cvxpy for a chapter
that does not need it.
"""

from __future__ import annotations

import importlib
import importlib.util

CHAPTER_MODULES = {
    "reduced-order-observer": "railpaper.experiments.reduced_order_observer",
    "partial-state-observer": "railpaper.experiments.partial_state_observer",
    "rbpf-parameter-estimation": "railpaper.experiments.rbpf_parameter_estimation",
    "quasi-gaussian-rbpf": "railpaper.experiments.quasi_gaussian_rbpf",
    "suspension-fault-detection": "railpaper.experiments.suspension_fault_detection",
}


def available_chapters() -> list[str]:
    """Chapters whose experiment module exists in this installation, in book order."""
    names = []
    for name, module in CHAPTER_MODULES.items():
        if importlib.util.find_spec(module) is not None:
            names.append(name)
    return names


def load_chapter(name: str):
    """Import a chapter's experiment module by chapter name."""
    return importlib.import_module(CHAPTER_MODULES[name])
