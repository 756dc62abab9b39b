"""The decisive evidence in data/evidence is still what this code computes: a few stored records
of every study (drawn with a fixed seed) are recomputed and must match bit for bit."""

from __future__ import annotations

import json

import pytest

from railpaper.experiments.records import RecordStudy
from railpaper.pipeline.chapters import chapter_spec
from railpaper.pipeline.decisive import (
    DECISIVE_DIR,
    chapter_studies,
    check_provenance,
    stored_verdicts,
)
from railpaper.pipeline.evidence_store import EvidenceStore

STORED = sorted((path.parent.name, study) for path in DECISIVE_DIR.glob("*/provenance.json")
                for study in json.loads(path.read_text())["studies"])


#: CPU seconds per stored record above which the spot check recomputes one record, not two.
EXPENSIVE_CPU_S = 1.5


def _cpu_s_per_record(chapter: str, study: str) -> float:
    entry = json.loads((DECISIVE_DIR / chapter / "provenance.json").read_text())["studies"][study]
    return entry["cpu_s"] / entry["records"]


def test_there_is_stored_evidence_to_check():
    assert STORED, f"no decisive evidence under {DECISIVE_DIR}"


@pytest.mark.parametrize("chapter, study", STORED)
def test_stored_records_are_reproduced_bit_for_bit(chapter, study):
    assert check_provenance(chapter) == []
    settings = chapter_spec(chapter).resolve({}, False)
    store = EvidenceStore(DECISIVE_DIR)
    rows = store.read(RecordStudy(chapter, study, rows=None), settings)
    # "(this checkout)" is no commit: every stored row counts as another commit's, so the
    # store's own spot check recomputes two drawn rows and raises, in one line naming the folder
    # and 'railpaper evidence', if any bit differs
    # two drawn records, or one where a record costs more than EXPENSIVE_CPU_S (the lateral
    # exact posterior: about 2 CPU-s a record)
    n_records = 1 if _cpu_s_per_record(chapter, study) > EXPENSIVE_CPU_S else 2
    checked = store.verify(chapter_studies(chapter)[study], settings, rows, "(this checkout)",
                           n_records=n_records)
    assert len(checked) == n_records


@pytest.mark.parametrize("chapter", sorted({chapter for chapter, _ in STORED}))
def test_stored_verdicts_are_what_the_evidence_decides(chapter):
    """The verdicts the stored evidence gives each declared row at its registered size — the
    default book's verdicts — are the ones recorded beside it (verdicts.json): a change to the
    rulebook, the vocabulary, a declaration or the evidence that moves one fails here, and
    'railpaper evidence --decisive' rewrites the file after a registered revision."""
    recorded = json.loads((DECISIVE_DIR / chapter / "verdicts.json").read_text())
    assert stored_verdicts(chapter) == recorded
