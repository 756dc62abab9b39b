"""The soundness columns a chapter gives its filters' studies (decision procedures version 3).

A chapter whose exact posterior is a per-record study of its own (chapter 003's IBIS) exposes
``POSTERIOR_OF`` (filters' study → the study of its records' exact posterior),
``soundness_columns(study, rows, posterior_rows, settings)`` (the rows with their
``satisfactory_*`` columns) and ``estimator_of(study, column)`` (the estimator behind a column).
The ledger and the stored verdicts join the two studies' rows by seed here, so that
:func:`railpaper.pipeline.declarations.decide` sees one table, as it does for a chapter whose
filters' study carries the columns itself (chapter 004).
"""

from __future__ import annotations

import functools
from typing import Any, Callable

import pandas as pd

from railpaper.experiments import load_chapter
from railpaper.experiments.records import RecordStudy


def posterior_study(chapter: str, study: str) -> RecordStudy | None:
    """The study holding the exact posterior of ``study``'s records, or None."""
    return getattr(load_chapter(chapter), "POSTERIOR_OF", {}).get(study)


def estimator_catalogue(chapter: str, study: str) -> Callable[[str], str | None] | None:
    """``column → estimator`` of ``study`` where the chapter names it (None: the procedures'
    own name rule)."""
    catalogue = getattr(load_chapter(chapter), "estimator_of", None)
    return None if catalogue is None else functools.partial(catalogue, study)


def with_soundness(chapter: str, study: str, rows: pd.DataFrame | None,
                   posterior: pd.DataFrame | None, settings: Any) -> pd.DataFrame | None:
    """``rows`` with the soundness columns the chapter derives from the ``posterior`` rows of
    the same seeds (NaN where none is known); ``rows`` unchanged for a study without a
    posterior study."""
    if rows is None or posterior_study(chapter, study) is None:
        return rows
    return load_chapter(chapter).soundness_columns(study, rows, posterior, settings)


__all__ = ["estimator_catalogue", "posterior_study", "with_soundness"]
