"""Whether each of the chapter's filters ends where the exact posterior says, record by record.

The ledger's decision procedures (version 3, ``data/vocabulary.toml``) turn a *reproduced*
claim about an estimator into an *artefact* when that estimator misses the exact posterior on
most of the same records.  For that they need, per record, a yes/no column
``satisfactory_<estimator>``: the estimator's final estimate lies within two exact-posterior
standard deviations of the exact posterior mean, for every parameter (|z| ≤ 2).  Chapter 004's
studies compute it beside their filters; this chapter's exact posterior (IBIS, Chopin 2002:
:mod:`~railpaper.experiments.rbpf_parameter_estimation.posterior`) costs more than its filters,
so it is a study of its own, one row per seed, joined to the filters' rows by seed:

* :data:`TOY_POSTERIOR` — on each toy record, the exact posterior of x1..x4 under the RBPF's
  prior box around initial condition 1 (IBIS generator ``[seed, 17]``, the chapter's calibration
  sampler) and around initial condition 2 (generator ``[seed, 17, 2]``), x0 = 0, P0 = I;
* :data:`LATERAL_POSTERIOR` — on each lateral record, the exact posterior of θ / θ_true under
  the box θ × [``prior_low``, ``prior_high``] (generator ``[seed, 17]``).

:func:`soundness_columns` derives the yes/no columns from a filters' study's rows (their final
estimates) and the posterior rows of the same seeds; :func:`estimator_of` says which estimator
wrote each column of a filters' study (the catalogue the procedures read).  The EKF's yardstick
is the same posterior (under the box around its own starting point): the question is whether a
filter ends where the data and the chapter's prior put the parameters, whatever its own prior.
A filter that diverged (no final number) misses it.  Our working-scheme RBPF on the toy records
keeps no final estimate in its study (no claim reads it), so it gets no column.
"""

from __future__ import annotations

import re

import numpy as np
import pandas as pd

from railpaper.experiments.rbpf_parameter_estimation import toy
from railpaper.experiments.rbpf_parameter_estimation.lateral import (
    PAPER_SCHEME_JUDGED,
    filtered_records,
)
from railpaper.experiments.rbpf_parameter_estimation.posterior import (
    lateral_posterior,
    toy_posterior,
)
from railpaper.experiments.rbpf_parameter_estimation.spec import Settings
from railpaper.experiments.records import RecordStudy
from railpaper.models import lateral_16state
from railpaper.threads import one_thread

CHAPTER = "rbpf-parameter-estimation"
#: |z| at or below which a final estimate agrees with the exact posterior (chapter 004's bar).
Z_SATISFACTORY = 2.0
#: The toy's filters whose final estimates the toy study keeps (per initial condition).
TOY_ESTIMATORS = ("rbpf", "ekf")


# ----------------------------------------------------------------------------- the posteriors
def toy_posterior_rows(settings: Settings, seeds) -> pd.DataFrame:
    """The study :data:`TOY_POSTERIOR`'s rows: per seed, ``posterior_mean_x<j>_init<ic>`` and
    ``posterior_sd_x<j>_init<ic>`` after the last step (dimensionless) of the record the toy
    study filtered (:func:`~railpaper.experiments.rbpf_parameter_estimation.toy.simulate` on
    ``default_rng(seed)``), for initial conditions 1 and 2."""
    rows = []
    with one_thread():
        for seed in seeds:
            seed = int(seed)
            sim = toy.simulate(settings, np.random.default_rng(seed))
            row = {"seed": seed}
            for ic, start in toy.TOY_INITS.items():
                key = () if ic == 1 else (ic,)         # initial condition 1: the chapter's draws
                post = toy_posterior(settings, sim, seed, start, key)
                for j in range(4):
                    row[f"posterior_mean_x{j + 1}_init{ic}"] = float(post.mean[-1, j])
                    row[f"posterior_sd_x{j + 1}_init{ic}"] = float(post.sd[-1, j])
            rows.append(row)
    return pd.DataFrame(rows)


def lateral_posterior_rows(settings: Settings, seeds) -> pd.DataFrame:
    """The study :data:`LATERAL_POSTERIOR`'s rows: per seed, ``posterior_mean_<param>`` and
    ``posterior_sd_<param>`` of θ / θ_true after the last step (1) of the simulated record the
    lateral studies filter."""
    def row(seed, record, system, theta) -> dict:
        post = lateral_posterior(settings, system, record, theta, seed)
        out = {"seed": seed}
        for j, name in enumerate(lateral_16state.PARAM_NAMES):
            out[f"posterior_mean_{name}"] = float(post.mean[-1, j])
            out[f"posterior_sd_{name}"] = float(post.sd[-1, j])
        return out

    return filtered_records(settings, seeds, row)


#: The toy's exact posterior per record (both initial conditions' boxes).
TOY_POSTERIOR = RecordStudy(CHAPTER, "toy_posterior", toy_posterior_rows, chunk_records=10)
#: The lateral exact posterior per record.
LATERAL_POSTERIOR = RecordStudy(CHAPTER, "lateral_posterior", lateral_posterior_rows,
                                chunk_records=1)

#: For each filters' study, the study holding its records' exact posterior.
POSTERIOR_OF = {"toy": TOY_POSTERIOR, "lateral_paper_scheme": LATERAL_POSTERIOR,
                "lateral_working_scheme": LATERAL_POSTERIOR,
                toy.TOY_JUDGED.name: TOY_POSTERIOR, PAPER_SCHEME_JUDGED.name: LATERAL_POSTERIOR}
#: A study run at ``JUDGED_PARTICLES`` has the columns of the study it repeats.
_SAME_COLUMNS_AS = {study.name: study.repeats
                    for study in (toy.TOY_JUDGED, PAPER_SCHEME_JUDGED)}


def _kind(study: str) -> str:
    """The study whose columns ``study`` has (itself, or the one it repeats at another
    particle count)."""
    return _SAME_COLUMNS_AS.get(study, study)


# ----------------------------------------------------------------------------- the columns
def _agrees(estimate: np.ndarray, mean: np.ndarray, sd: np.ndarray) -> np.ndarray:
    """Per record (rows), whether every parameter's ``|estimate − mean| ≤ 2 sd``; a record with
    no estimate (NaN: the filter diverged) does not agree."""
    with np.errstate(invalid="ignore"):
        inside = np.abs(estimate - mean) <= Z_SATISFACTORY * sd
    return (inside & np.isfinite(estimate)).all(axis=1)


def _posterior_columns(study: str) -> list[str]:
    """The columns of the posterior study of ``study``."""
    if _kind(study) == "toy":
        return [f"posterior_{what}_x{j}_init{ic}" for ic in toy.TOY_INITS for j in range(1, 5)
                for what in ("mean", "sd")]
    return [f"posterior_{what}_{p}" for p in lateral_16state.PARAM_NAMES
            for what in ("mean", "sd")]


def soundness_columns(study: str, rows: pd.DataFrame, posterior: pd.DataFrame | None,
                      settings: Settings) -> pd.DataFrame:
    """``rows`` of the filters' study ``study`` with its ``satisfactory_*`` columns added, from
    the ``posterior`` rows of the same seeds (a record without one, or every record when
    ``posterior`` is None, gets NaN: not known).

    * ``toy`` (and ``toy_judged_particles``): ``satisfactory_<m>_init<ic>`` for m in ``rbpf``
      (the paper scheme) and ``ekf``,
      from their final estimates (truth + ``<m>_final_error_x<j>_init<ic>``), and
      ``satisfactory_<m>_both_inits`` (both initial conditions);
    * ``lateral_*_scheme``: ``satisfactory`` (the study's one filter), from θ̂/θ = 1 +
      ``final_relative_error_<param>``.
    """
    if study not in POSTERIOR_OF:
        raise ValueError(f"study {study!r} of chapter {CHAPTER} has no exact posterior; those "
                         f"that have: {', '.join(POSTERIOR_OF)}")
    if posterior is None:                     # no exact posterior for these settings
        posterior = pd.DataFrame({"seed": rows.seed, **{c: np.nan for c in
                                                        _posterior_columns(study)}})
    joined = rows.merge(posterior, on="seed", how="left", validate="one_to_one")
    known = joined[_posterior_columns(study)[0]].notna().to_numpy()
    out = rows.copy()

    def column(flags: np.ndarray) -> np.ndarray:
        return np.where(known, flags.astype(float), np.nan)

    if _kind(study) == "toy":
        truth = toy.truth(settings)
        for m in TOY_ESTIMATORS:
            both = np.ones(len(rows), bool)
            for ic in toy.TOY_INITS:
                cols = range(1, 5)
                estimate = truth + joined[[f"{m}_final_error_x{j}_init{ic}" for j in cols]
                                          ].to_numpy(float)
                flags = _agrees(estimate,
                                joined[[f"posterior_mean_x{j}_init{ic}" for j in cols]
                                       ].to_numpy(float),
                                joined[[f"posterior_sd_x{j}_init{ic}" for j in cols]
                                       ].to_numpy(float))
                out[f"satisfactory_{m}_init{ic}"] = column(flags)
                both &= flags
            out[f"satisfactory_{m}_both_inits"] = column(both)
        return out
    names = lateral_16state.PARAM_NAMES
    estimate = 1.0 + joined[[f"final_relative_error_{p}" for p in names]].to_numpy(float)
    out["satisfactory"] = column(_agrees(
        estimate, joined[[f"posterior_mean_{p}" for p in names]].to_numpy(float),
        joined[[f"posterior_sd_{p}" for p in names]].to_numpy(float)))
    return out


_TOY_COLUMN = re.compile(r"^(rbpf_working|rbpf|ekf)_.+_(init1|init2|both_inits)$")


def estimator_of(study: str, column: str) -> str | None:
    """The estimator whose output ``column`` of ``study`` holds, as its soundness column names
    it (``satisfactory_<name>``; ``""`` for a study's one filter, column ``satisfactory``), or
    None (not an estimator's output, or one without a soundness column).

    >>> estimator_of("toy", "rbpf_converged_init1"), estimator_of("toy", "ekf_settle_init2")
    ('rbpf_init1', 'ekf_init2')
    >>> estimator_of("toy", "rbpf_working_err_max_init1") is None    # kept no final estimate
    True
    >>> estimator_of("lateral_paper_scheme", "within_5pct_from_350")
    ''
    """
    if _kind(study) == "toy":
        match = _TOY_COLUMN.match(column)
        if match is None or match.group(1) not in TOY_ESTIMATORS:
            return None
        return f"{match.group(1)}_{match.group(2)}"
    if _kind(study) in ("lateral_paper_scheme", "lateral_working_scheme"):
        return None if column == "seed" else ""
    return None


__all__ = ["LATERAL_POSTERIOR", "POSTERIOR_OF", "TOY_POSTERIOR", "estimator_of",
           "lateral_posterior_rows", "soundness_columns", "toy_posterior_rows"]
