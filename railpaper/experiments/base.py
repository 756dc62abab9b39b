"""The contract every chapter's experiment module follows.

A chapter's ``spec`` module defines::

    SPEC = ChapterSpec(
        name="reduced-order-observer",
        title="...",
        paper="001_b49ad810fb7b323c.txt",
        notebook="reduced_order_observer.ipynb",   # in book/notebooks/
        parameters=[Parameter("speeds_kmh", [60, 100], "list[float]", "simulated speeds, km/h",
                              quick=None, positive=True), ...],
    )
    Settings = SPEC.settings_type      # the chapter's frozen, typed settings

and its experiment module::

    def run(settings: Settings, *, progress=None) -> ChapterResult: ...

``SPEC.resolve(overrides, quick)`` gives a checked ``Settings``: the defaults (the chapter's
stated quick sizes with ``quick``) updated by the user's values.  Every metric key, time-series
column and figure of a full run also exists in a quick run.  ``progress`` is an optional callable
``progress(fraction: float, message: str)`` for long runs.

>>> from railpaper.experiments.base import ChapterSpec, Parameter
>>> spec = ChapterSpec("demo", "Demo", "", "demo.ipynb", [
...     Parameter("speeds_kmh", [60, 100], "list[float]", "speeds, km/h", quick=[60]),
...     Parameter("n_records", 200, "int", "records", quick=40, changes_records=False)])
>>> settings = spec.resolve({}, quick=True)
>>> settings.speeds_kmh, settings.n_records
((60.0,), 40)
>>> settings.record_key()
{'speeds_kmh': [60.0]}
>>> settings.replace(n_records=0.5)
Traceback (most recent call last):
...
railpaper.experiments.base.ParameterError: parameter 'n_records' expects an integer, got 0.5
"""

from __future__ import annotations

import dataclasses
import difflib
import math
import os
import sys
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, ClassVar

import numpy as np
import pandas as pd

TYPE_NAMES = ("int", "float", "bool", "str", "list[float]", "list[int]")


class ParameterError(ValueError):
    """A chapter parameter is unknown, of the wrong type or non-physical (one-line message)."""


@dataclass(frozen=True)
class Parameter:
    """One chapter parameter.

    Attributes
    ----------
    name : str
        Python identifier with its unit in the name (``speed_kmh``, ``duration_s``).
    default : Any
        Default of a full run.
    type : str
        One of ``TYPE_NAMES``.
    meaning : str
        One sentence for ``railpaper list`` and the chapter's parameter table.
    quick : Any, optional
        Value used by ``--quick`` when the user did not set the parameter (None: same as default).
    positive : bool
        Numbers (or every list element) must be > 0.
    minimum : float, optional
        Numbers (or every list element) must be >= minimum.
    path : bool
        A ``str`` naming a file: a non-empty value is made absolute against the caller's working
        directory (the notebook kernel runs in a staging directory, elsewhere).
    changes_records : bool
        Whether the value changes the numbers of a Monte Carlo record of a given seed (the
        model, the noise, a filter's tuning: True) or only which records are run and what is
        shown of them (sample sizes, figure choices, timing: False).  The evidence store keys
        its rows by the fields that do; the safe default is True.
    """

    name: str
    default: Any
    type: str
    meaning: str
    quick: Any = None
    positive: bool = False
    minimum: float | None = None
    path: bool = False
    changes_records: bool = True

    @property
    def annotation(self) -> Any:
        """The field type of :class:`ChapterSettings` (lists are held as tuples: frozen)."""
        return {"int": int, "float": float, "bool": bool, "str": str,
                "list[float]": tuple[float, ...], "list[int]": tuple[int, ...]}[self.type]

    def settle(self, value: Any) -> Any:
        """:meth:`coerce`, with a list held as a tuple (the settings are frozen)."""
        value = self.coerce(value)
        return tuple(value) if isinstance(value, list) else value

    def coerce(self, value: Any) -> Any:
        """Check and convert a user value; raise :class:`ParameterError` with one line."""
        def number(v, kind):
            if isinstance(v, bool) or not isinstance(v, (int, float)):
                raise ParameterError(
                    f"parameter '{self.name}' expects {self.type}, got {type(v).__name__} {v!r}")
            if kind == "int":
                if isinstance(v, float) and not v.is_integer():
                    raise ParameterError(f"parameter '{self.name}' expects an integer, got {v!r}")
                v = int(v)
            else:
                v = float(v)
            if not math.isfinite(v):
                raise ParameterError(f"parameter '{self.name}' must be finite, got {v!r}")
            if self.positive and v <= 0:
                raise ParameterError(f"parameter '{self.name}' must be > 0, got {v!r}")
            if self.minimum is not None and v < self.minimum:
                raise ParameterError(f"parameter '{self.name}' must be >= {self.minimum}, got {v!r}")
            return v

        if self.type in ("int", "float"):
            return number(value, self.type)
        if self.type == "bool":
            if not isinstance(value, bool):
                raise ParameterError(f"parameter '{self.name}' expects true or false, got {value!r}")
            return value
        if self.type == "str":
            if not isinstance(value, str):
                raise ParameterError(f"parameter '{self.name}' expects a string, got {value!r}")
            return str(Path(value).expanduser().resolve()) if self.path and value else value
        if self.type in ("list[float]", "list[int]"):
            if not isinstance(value, (list, tuple)) or len(value) == 0:
                raise ParameterError(
                    f"parameter '{self.name}' expects a non-empty list like [60, 100], got {value!r}")
            return [number(v, self.type[5:-1]) for v in value]
        raise AssertionError(self.type)


class ChapterSettings:
    """Base of every chapter's settings: a frozen dataclass made by :class:`ChapterSpec` from its
    parameters (one field per parameter, its type, default, meaning and whether it changes a
    record's numbers in the field's ``metadata``).  Every value is checked when made, by
    :meth:`Parameter.coerce`: a wrong type or a non-physical value is one line of
    :class:`ParameterError`, whether the settings come from :meth:`ChapterSpec.resolve`,
    ``Settings(...)`` or :meth:`replace`."""

    spec: ClassVar["ChapterSpec"]

    def __post_init__(self) -> None:
        for parameter in self.spec.parameters:
            object.__setattr__(self, parameter.name, parameter.settle(getattr(self, parameter.name)))

    def replace(self, **changes: Any) -> "ChapterSettings":
        """A copy with ``changes`` (checked; an unknown name is one line, with the closest)."""
        for name in changes:
            self.spec.parameter(name)
        return dataclasses.replace(self, **changes)

    def as_dict(self) -> dict[str, Any]:
        """The values as plain JSON-ready Python (tuples as lists): ``metrics.json``'s
        ``parameters``, a notebook's overrides, a sweep's row."""
        return {f.name: list(value) if isinstance(value := getattr(self, f.name), tuple) else value
                for f in dataclasses.fields(self)}

    def record_key(self) -> dict[str, Any]:
        """The values that change a Monte Carlo record's numbers (``changes_records``): with the
        chapter, the study and the seed, the key of a record in the evidence store."""
        values = self.as_dict()
        return {f.name: values[f.name] for f in dataclasses.fields(self)
                if f.metadata["changes_records"]}


def _camel(name: str) -> str:
    return "".join(part.capitalize() for part in name.replace("_", "-").split("-"))


@dataclass(frozen=True)
class ChapterSpec:
    """What the pipeline needs to know about a chapter, and the type of its settings
    (:attr:`settings_type`, a frozen dataclass of :class:`ChapterSettings`)."""

    name: str
    title: str
    paper: str
    notebook: str
    parameters: list[Parameter]
    quick_sizes: str = ""
    #: Parameter values the chapter's notebook needs; other values of these parameters are
    #: for Monte Carlo samples of ``railpaper sweep`` only (e.g. a sample without side studies).
    notebook_requires: dict[str, Any] = field(default_factory=dict)
    #: The chapter's settings: a frozen dataclass, one typed field per parameter, made here; the
    #: chapter's ``spec`` module binds it as ``Settings`` (pickle finds it there by name).
    settings_type: type = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        fields = [(p.name, p.annotation,
                   field(default=tuple(p.default) if isinstance(p.default, list) else p.default,
                         metadata={"meaning": p.meaning, "changes_records": p.changes_records}))
                  for p in self.parameters]
        settings_type = dataclasses.make_dataclass(
            f"{_camel(self.name)}Settings", fields, bases=(ChapterSettings,), frozen=True,
            namespace={"spec": self, "__doc__": f"Settings of chapter ``{self.name}``: "
                       + "; ".join(f"``{p.name}`` {p.meaning}" for p in self.parameters)})
        # Where the spec is made (its module binds it as ``Settings``), as namedtuple does.
        settings_type.__module__ = sys._getframe(2).f_globals.get("__name__", __name__)
        settings_type.__qualname__ = "Settings"
        object.__setattr__(self, "settings_type", settings_type)

    def parameter(self, name: str) -> Parameter:
        for p in self.parameters:
            if p.name == name:
                return p
        close = difflib.get_close_matches(name, [p.name for p in self.parameters], n=1)
        hint = f" (did you mean '{close[0]}'?)" if close else ""
        raise ParameterError(f"chapter '{self.name}' has no parameter '{name}'{hint}")

    def resolve(self, overrides: dict[str, Any] | None = None,
                quick: bool = False) -> ChapterSettings:
        """The chapter's checked settings: defaults (quick values when ``quick``) updated by the
        user's ``overrides`` (names checked, one line with the closest name otherwise)."""
        values = {}
        for p in self.parameters:
            values[p.name] = p.quick if (quick and p.quick is not None) else p.default
        for name, value in (overrides or {}).items():
            values[self.parameter(name).name] = value
        return self.settings_type(**values)

    def check_notebook_values(self, settings: ChapterSettings) -> None:
        """Refuse, for the chapter's notebook, values only sweep samples may take
        (:attr:`notebook_requires`)."""
        for name, needed in self.notebook_requires.items():
            if getattr(settings, name) != needed:
                raise ParameterError(
                    f"{name} = {str(getattr(settings, name)).lower()} is for Monte Carlo samples "
                    f"(railpaper sweep); the chapter's notebook needs {name} = "
                    f"{str(needed).lower()}")

    def defaults(self) -> dict[str, Any]:
        return {p.name: p.default for p in self.parameters}


@dataclass
class ChapterResult:
    """What a chapter's ``run`` returns.

    Attributes
    ----------
    metrics : dict
        Deterministic numbers/booleans (no NaN: "never happened" is -1).
    timings : dict
        Wall-clock figures (not deterministic).
    timeseries : pandas.DataFrame
        First column ``t_s`` (or ``step`` where the chapter says so), units in column names.
    extra_tables : dict of str to DataFrame
        Other CSV outputs (e.g. ``toy_timeseries``), written as ``<key>.csv``.
    extra_files : dict of str to str
        Other text outputs, written verbatim as the file named by the key (e.g.
        ``toy_posterior.json``).
    """

    metrics: dict[str, float | int | bool]
    timings: dict[str, float] = field(default_factory=dict)
    timeseries: pd.DataFrame | None = None
    extra_tables: dict[str, pd.DataFrame] = field(default_factory=dict)
    extra_files: dict[str, str] = field(default_factory=dict)


def check_metrics(metrics: dict[str, Any]) -> dict[str, float | int | bool]:
    """Validate metric values: numbers or booleans, finite; numpy scalars become Python ones."""
    clean = {}
    for key, value in metrics.items():
        if isinstance(value, (bool, np.bool_)):
            clean[key] = bool(value)
            continue
        if isinstance(value, (int, np.integer)):
            clean[key] = int(value)
            continue
        value = float(value)
        if not math.isfinite(value):
            raise ValueError(f"metric '{key}' is {value}; use -1 for 'never happened'")
        clean[key] = value
    return clean


#: Largest dt_s·|λ_max| a chapter accepts: a sample time longer than π/|λ| of the continuous
#: model's fastest mode λ samples an oscillatory mode below its Nyquist rate (|Im λ| ≤ |λ|), so the
#: discrete model aliases it onto a slower one, and lets a real mode decay to e^-π ≈ 4 % within one
#: step, so consecutive samples say next to nothing about its rate (the parameters behind it).
MAX_STEP_PHASE_RAD = math.pi


def check_sample_time(name: str, dt_s: float, A: np.ndarray, model: str,
                      bound: float = MAX_STEP_PHASE_RAD) -> None:
    """Refuse a sample time too long for the fastest mode of the continuous model ``A``.

    Raises :class:`ParameterError` (one line naming the mode and the bound) when
    ``dt_s * max|eig(A)| > bound`` (default π, see :data:`MAX_STEP_PHASE_RAD`).
    """
    fastest = float(np.max(np.abs(np.linalg.eigvals(A))))
    if dt_s * fastest > bound:
        raise ParameterError(
            f"parameter '{name}' = {dt_s:g} s is too coarse for the fastest mode of {model} "
            f"(|λ| = {fastest:.0f} 1/s): need {name}·|λ_max| ≤ {bound:.3g}, i.e. "
            f"{name} ≤ {bound / fastest:.3g} s")


ProgressCallback = Callable[[float, str], None]


def no_progress(fraction: float, message: str) -> None:  # noqa: ARG001 - callback signature
    """Progress callback that says nothing."""


#: Environment variable naming the file a run inside a notebook kernel reports its progress to
#: (set by :func:`railpaper.pipeline.chapters.run_chapter` for a run in a terminal).
PROGRESS_FILE_ENV = "RAILPAPER_PROGRESS_FILE"


def default_progress() -> Callable[[float, str], None]:
    """The progress callback of a run given none: one line ``fraction<TAB>message`` appended to
    the file named by :data:`PROGRESS_FILE_ENV` per call when it is set, else
    :func:`no_progress`.  The pipeline reads that file and shows the run's progress in the
    terminal: a chapter's notebook cell can compute for minutes."""
    path = os.environ.get(PROGRESS_FILE_ENV)
    if not path:
        return no_progress

    def report(fraction: float, message: str) -> None:
        with open(path, "a") as handle:
            handle.write(f"{float(fraction):.4f}\t{' '.join(str(message).split())}\n")
    return report


#: Copies of every particle's Kalman mean and covariance (n + n² doubles) alive at a filter's
#: peak: the bank itself, predicted and updated moments, the resampled copy and temporaries.
#: Measured (peak RSS of a fresh process, N = 20 000 minus N = 100, ``/proc/self/status``
#: VmHWM): 23.0–24.9 kB per particle for the lateral RBPF (both schemes) and Q-GRBPF (n = 16),
#: ≈ 9.5–10 copies of (x, P) besides F, H, G; the 2-state toys (N = 400 000) need 400–810 B.
BANK_COPIES = 10
#: Per-particle scalars and short histories (weights, log-likelihoods, ancestors, draws, the
#: working scheme's chunks of up to 32 steps), doubles.
BANK_SCALARS = 64


def particle_bank_bytes(n_particles: int, n_states: int, per_particle_doubles: int = 0,
                        copies: int = BANK_COPIES) -> float:
    """Estimated peak memory of a bank of Kalman filters (one per particle or grid point).

    Parameters
    ----------
    n_particles : int
        Filters in the bank.
    n_states : int
        State dimension n of each filter.
    per_particle_doubles : int
        Further doubles per filter: its own matrices (F n², H p·n, G n·m), parameters θ and
        per-step records.
    copies : int
        Copies of (x, P) alive at the peak (:data:`BANK_COPIES`).

    Returns
    -------
    float
        Bytes: ``8 N (copies (n + n²) + per_particle_doubles + BANK_SCALARS)``.
    """
    per = copies * (n_states + n_states ** 2) + per_particle_doubles + BANK_SCALARS
    return 8.0 * n_particles * per


def available_memory_bytes(meminfo: str | Path = "/proc/meminfo") -> int | None:
    """``MemAvailable`` of ``/proc/meminfo`` in bytes (None where the file or line is missing)."""
    try:
        text = Path(meminfo).read_text()
    except OSError:
        return None
    for line in text.splitlines():
        if line.startswith("MemAvailable:"):
            return int(line.split()[1]) * 1024            # the kernel writes kB (KiB)
    return None


def _size(n_bytes: float) -> str:
    for unit, scale in (("TB", 1e12), ("GB", 1e9), ("MB", 1e6)):
        if n_bytes >= scale:
            return f"{n_bytes / scale:.3g} {unit}"
    return f"{n_bytes / 1e3:.3g} kB"


def check_banks(banks, available: int | None = None) -> None:
    """Refuse, before any work, a bank of filters that cannot fit in the available memory.

    Parameters
    ----------
    banks : iterable of tuple
        ``(parameter, value, n_filters, n_states, per_filter_doubles, what)`` per bank the run
        builds (one at a time): the parameter that sets its size and its value, the number of
        Kalman filters (particles or grid points; 0 = not run), their state dimension, the
        further doubles per filter (:func:`particle_bank_bytes`) and the bank in words.
    available : int, optional
        Bytes available; default :func:`available_memory_bytes` (no check where unknown).

    Raises
    ------
    ParameterError
        One line with the estimate, the machine's available memory and how many filters fit.
    """
    available = available_memory_bytes() if available is None else available
    if available is None:
        return
    for name, value, n_filters, n_states, extra, what in banks:
        need = particle_bank_bytes(n_filters, n_states, extra)
        if need > available:
            fits = int(n_filters * available / need)
            raise ParameterError(
                f"parameter '{name}' = {value} needs ≈ {_size(need)} for {what} ({n_filters} "
                f"filters of {n_states} states), but this machine has {_size(available)} "
                f"available (MemAvailable): at most {fits} filters fit")
