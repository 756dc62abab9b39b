"""A chapter's Monte Carlo as a map over records and a reduce.

A study's expensive work is one function, ``rows(settings, seeds) -> DataFrame``: one row per
seed, in the order given, a column ``seed`` and numbers with their units in the column names.
A record's numbers depend only on its seed and the settings, so the rows of seeds 0..99 are the
same bits whether they were computed as one chunk, as a hundred, on one worker or on many; the
chapter's evidence (the reduce) is a function of the table of rows and never sees the chunking.

>>> import pandas as pd
>>> def squares(settings, seeds):
...     return pd.DataFrame({"seed": list(seeds), "square_m2": [float(s * s) for s in seeds]})
>>> study = RecordStudy("demo", "squares", squares, chunk_records=2)
>>> study.chunks([5, 1, 2])
[(5, 1), (2,)]
>>> map_in_process(study, None, [5, 1, 2]).square_m2.tolist()
[25.0, 1.0, 4.0]

Where the rows are computed is the caller's choice: a chapter's ``run`` takes a
:data:`RecordMap` (default :func:`map_in_process`); the pipeline passes one that reads and
extends the evidence store and computes the missing records on Dask workers
(:mod:`railpaper.pipeline.evidence_store`).  Every map returns :func:`normalised` rows (the
CSV round trip of the store, exact for floats), so a reduce sees the same table either way.
"""

from __future__ import annotations

import io
from dataclasses import dataclass
from typing import Any, Callable, Sequence

import pandas as pd

from railpaper.experiments.base import ProgressCallback, no_progress

#: ``rows(settings, seeds)``: one row per seed, in order, with a ``seed`` column.
RowsFunction = Callable[[Any, tuple[int, ...]], pd.DataFrame]


@dataclass(frozen=True)
class RecordStudy:
    """One chapter study's per-record work.

    Attributes
    ----------
    chapter : str
        The chapter's name (``reduced-order-observer``).
    name : str
        The study's name within the chapter (``monte_carlo``): with the settings that change a
        record's numbers and the seed, the key of a row in the evidence store.
    rows : callable
        ``rows(settings, seeds)`` → DataFrame, one row per seed in the order given, column
        ``seed``; a module-level function (workers receive it by reference).
    chunk_records : int
        Records per task: the batch size at which the rows function is efficient.  It changes
        no number.
    first_record : callable, optional
        ``first_record(settings)`` → the seed of the study's first record in the chapter's run
        (default: ``settings.seed``); a larger sample extends it with the seeds that follow.
    repeats : str, optional
        The name of the chapter's study whose rows this one computes under other settings (a
        larger particle count): the same columns and the same compiled kernels.
    """

    chapter: str
    name: str
    rows: RowsFunction
    chunk_records: int = 1
    first_record: Callable[[Any], int] | None = None
    repeats: str | None = None

    def first(self, settings: Any) -> int:
        """The seed of the study's first record under ``settings``."""
        return int(self.first_record(settings) if self.first_record else settings.seed)

    def chunks(self, seeds: Sequence[int]) -> list[tuple[int, ...]]:
        """``seeds`` in consecutive chunks of :attr:`chunk_records`."""
        seeds = [int(s) for s in seeds]
        step = max(1, int(self.chunk_records))
        return [tuple(seeds[i:i + step]) for i in range(0, len(seeds), step)]


#: ``record_map(study, settings, seeds, progress)`` → the rows of ``seeds``, in that order.
RecordMap = Callable[[RecordStudy, Any, Sequence[int], ProgressCallback], pd.DataFrame]


def column_types(frame: pd.DataFrame) -> dict[str, str]:
    """Each column's dtype by name (``float64``, ``int64``, ``bool``, ``object``)."""
    return {name: str(dtype) for name, dtype in frame.dtypes.items()}


def read_rows(text: str, types: dict[str, str]) -> pd.DataFrame:
    """Rows written by :func:`normalised`'s CSV (or the store's), with their column ``types``:
    a float column whose values are all whole numbers stays float."""
    frame = pd.read_csv(io.StringIO(text),
                        dtype={k: (str if v == "object" else v) for k, v in types.items()})
    return frame.copy()              # one block per dtype (read_csv with dtypes leaves hundreds)


def normalised(frame: pd.DataFrame) -> pd.DataFrame:
    """``frame`` as the evidence store gives it back: written as CSV (floats at ``%.17g``, which
    round-trips every float64 exactly) and read again with its column types, so in-process rows
    and stored rows reach a reduce with the same values and dtypes."""
    return read_rows(frame.to_csv(index=False, float_format="%.17g"), column_types(frame))


def checked_rows(study: RecordStudy, seeds: Sequence[int], frame: pd.DataFrame) -> pd.DataFrame:
    """``frame`` if it holds one row per seed of ``seeds`` in order, else a one-line error."""
    if "seed" not in frame.columns:
        raise ValueError(f"{study.chapter} {study.name}: rows without a 'seed' column")
    got = [int(s) for s in frame["seed"]]
    if got != [int(s) for s in seeds]:
        raise ValueError(f"{study.chapter} {study.name}: rows for seeds {got[:5]}… where "
                         f"{list(seeds)[:5]}… were asked")
    return frame


def map_in_process(study: RecordStudy, settings: Any, seeds: Sequence[int],
                   progress: ProgressCallback = no_progress) -> pd.DataFrame:
    """The rows of ``seeds`` computed here, chunk after chunk (:func:`normalised`)."""
    seeds = [int(s) for s in seeds]
    frames, done = [], 0
    for chunk in study.chunks(seeds):
        frames.append(checked_rows(study, chunk, study.rows(settings, chunk)))
        done += len(chunk)
        progress(done / max(len(seeds), 1), f"{study.name}: {done}/{len(seeds)} records")
    if not frames:
        return no_rows()
    return normalised(pd.concat(frames, ignore_index=True))


def no_rows() -> pd.DataFrame:
    """The rows of no record: an empty table with its ``seed`` column."""
    return pd.DataFrame({"seed": pd.Series([], dtype="int64")})


def assert_chunk_invariant(study: RecordStudy, settings: Any, seeds: Sequence[int]) -> None:
    """Check that a record's numbers do not depend on its chunk: the rows of ``seeds`` computed
    as one chunk, one seed at a time and in reverse order must be equal bit for bit (raises
    ``AssertionError`` naming the first column that differs).  A batch over records that goes
    through BLAS or numpy's pairwise sums can fail this for a chunk of one record."""
    seeds = tuple(int(s) for s in seeds)
    together = study.rows(settings, seeds)
    alone = pd.concat([study.rows(settings, (s,)) for s in seeds], ignore_index=True)
    reverse = study.rows(settings, seeds[::-1]).iloc[::-1].reset_index(drop=True)
    if [int(s) for s in together["seed"]] != list(seeds):
        raise AssertionError(f"{study.name}: rows for seeds {list(together['seed'])}, "
                             f"asked {list(seeds)}")
    for name, other in (("one seed at a time", alone), ("reverse order", reverse)):
        pd.testing.assert_frame_equal(together, other, check_exact=True,
                                      obj=f"{study.name} rows, {name}")


__all__ = ["RecordMap", "RecordStudy", "RowsFunction", "assert_chunk_invariant", "checked_rows",
           "column_types", "map_in_process", "no_rows", "normalised", "read_rows"]
