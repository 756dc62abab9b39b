"""Which readings of paper 004's Section IV make its convergence steps possible?

The paper's RBPF "converges at step 55" (a) and 53 (b), its Q-GRBPF at step 4, with final errors
0.167 / 0.067 and 0.066 / 0.055.  A calibrated filter cannot settle before the exact posterior
mean does, so the exact posterior (:func:`railpaper.engine.grid_posterior.grid_posterior`)
under each reading of the printed noise settings (``data/quasi-gaussian-rbpf/readings.toml``)
says which of those numbers a working filter could show.  A settling step is read against the
figure's last value, so it also depends on the figure's horizon, lost with the figures: every
reading is evaluated at every horizon of the file.

Per reading, horizon H and parameter: the median over records of the exact posterior mean's
settling step (within ``tolerance`` of its value at H) with its 95 % order-statistic interval, and
the median |error| of the posterior mean at steps 4 and 55 (53 for b).

The study is a map over records and a reduce: :func:`readings_rows` gives one wide row per record
(:func:`record_row`: every reading, horizon and parameter), :func:`study_from_rows` turns the
table of rows into the :class:`~railpaper.experiments.quasi_gaussian_rbpf.result.ReadingsStudy`.
"""

from __future__ import annotations

from typing import Sequence

import numpy as np
import pandas as pd

from railpaper.data import read_toml
from railpaper.engine import grid_posterior
from railpaper.experiments.quasi_gaussian_rbpf.result import Reading, ReadingsStudy
from railpaper.experiments.quasi_gaussian_rbpf.spec import PAPER_STEPS, PARAMS, Settings
from railpaper.models.linear_toys import paper004_system, simulate_paper004
from railpaper.paths import DATA_DIR
from railpaper.settling import settling_step
from railpaper.stats import median_interval
from railpaper.threads import one_thread

READINGS_FILE = DATA_DIR / "quasi-gaussian-rbpf" / "readings.toml"
#: Seed-stream offset: records of this study never share a stream with the chapter's records.
STREAM = 7_004


def load_readings(path=READINGS_FILE) -> tuple[tuple[Reading, ...], tuple[int, ...]]:
    """The readings and horizons of ``readings.toml``."""
    raw = read_toml(path)
    horizons = tuple(int(h) for h in raw.pop("horizons")["values"])
    if max(horizons) < max(PAPER_STEPS.values()):
        raise ValueError(f"{path}: the longest horizon must reach step {max(PAPER_STEPS.values())}"
                         f" (the paper's RBPF step), got {max(horizons)}")
    readings = tuple(Reading(key, t["label"], float(t["q_var"]), float(t["r_var"]),
                             float(t["p0_std"]), t["source"]) for key, t in raw.items())
    return readings, horizons


def posterior_paths(reading: Reading, truth, lower, upper, n_steps: int, grid_size: int,
                    seed: int, record: int):
    """Exact posterior mean and std (n_steps, 2) of one simulated record under ``reading``."""
    rng = np.random.default_rng(np.random.SeedSequence([seed, STREAM, record]))
    sim = simulate_paper004(truth[0], truth[1], reading.q_var, reading.r_var, reading.p0_std,
                            n_steps, rng)
    exact = grid_posterior(paper004_system(reading.q_var, reading.r_var), sim.y, lower, upper,
                           grid_size, np.zeros(2), reading.p0_std ** 2 * np.eye(2))
    return exact.mean, exact.std


def settling_column(reading: str, par: str, horizon: int) -> str:
    """Column of a row: the settling step (steps) of ``par`` under ``reading`` at ``horizon``."""
    return f"settling_step_{reading}_{par}_h{horizon}"


def error_columns(reading: str, par: str) -> tuple[str, str, str, str]:
    """Columns of a row (1): |posterior mean − truth| at step 4 and at the paper's RBPF step,
    posterior std at both."""
    k = PAPER_STEPS[(par, "rbpf")]
    return (f"abs_error_{reading}_{par}_step4", f"abs_error_{reading}_{par}_step{k}",
            f"std_{reading}_{par}_step4", f"std_{reading}_{par}_step{k}")


def record_row(readings, horizons, truth, lower, upper, grid_size: int, tolerance: float,
               seed: int, record: int) -> dict:
    """One record's row: ``seed`` (= ``record``), then per reading and parameter the settling
    step at every horizon (:func:`settling_column`) and the errors and stds of
    :func:`error_columns`."""
    n_steps = max(horizons)
    row = {"seed": int(record)}
    for reading in readings:
        mean, std = posterior_paths(reading, truth, lower, upper, n_steps, grid_size, seed,
                                    record)
        for j, par in enumerate(PARAMS):
            for horizon in horizons:
                row[settling_column(reading.key, par, horizon)] = settling_step(
                    np.abs(mean[:horizon, j] - mean[horizon - 1, j]) <= tolerance)
            k = PAPER_STEPS[(par, "rbpf")] - 1
            values = (abs(mean[3, j] - truth[j]), abs(mean[k, j] - truth[j]), std[3, j],
                      std[k, j])
            row.update(zip(error_columns(reading.key, par), values))
    return row


def readings_rows(settings: Settings, seeds: Sequence[int]) -> pd.DataFrame:
    """The rows (:func:`record_row`) of records ``seeds`` under the readings of
    :data:`READINGS_FILE`, with the chapter's truth, prior box, grid and tolerance: the chapter's
    per-record work of this study, on one thread."""
    readings, horizons = load_readings()
    truth, lower, upper = (np.asarray(v, float) for v in (
        (settings.a_true, settings.b_true), (settings.a_min, settings.b_min),
        (settings.a_max, settings.b_max)))
    with one_thread():
        return pd.DataFrame([record_row(readings, horizons, truth, lower, upper,
                                        settings.grid_size, settings.tolerance_to_truth,
                                        settings.seed, record) for record in seeds])


def study_from_rows(table: pd.DataFrame, readings, horizons) -> ReadingsStudy:
    """The reduce: the :class:`ReadingsStudy` of the records in ``table`` (one row each, as
    :func:`record_row` gives them, in record order)."""
    n_records = len(table)
    steps = np.zeros((len(readings), len(horizons), 2, n_records), dtype=int)
    rows, err_rows = [], []
    for i, reading in enumerate(readings):
        for h, horizon in enumerate(horizons):
            for j, par in enumerate(PARAMS):
                steps[i, h, j] = table[settling_column(reading.key, par, horizon)].to_numpy()
                est = median_interval(steps[i, h, j])
                rows.append(dict(reading=reading.key, horizon_steps=horizon, parameter=par,
                                 settling_step=est.value, settling_step_low=est.low,
                                 settling_step_high=est.high, n_records=est.n))
        for par in PARAMS:
            e4, ek, s4, sk = (float(np.median(table[c].to_numpy(float)))
                              for c in error_columns(reading.key, par))
            err_rows.append(dict(reading=reading.key, parameter=par, abs_error_step4=e4,
                                 abs_error_rbpf_step=ek, std_step4=s4, std_rbpf_step=sk))
    return ReadingsStudy(readings=readings, horizons_steps=horizons, table=pd.DataFrame(rows),
                         errors=pd.DataFrame(err_rows), settling_steps=steps)


def run_readings(*, truth=(-0.7, 1.5), lower=(-1.0, 1.0), upper=(0.4, 2.8), n_records: int = 40,
                 grid_size: int = 81, tolerance: float = 0.05, seed: int = 0,
                 path=READINGS_FILE, progress=None) -> ReadingsStudy:
    """The exact posterior's settling steps under every reading and horizon, computed here, record
    after record (the chapter's run maps :func:`readings_rows` over the records instead; the
    same rows and the same reduce).

    Parameters
    ----------
    truth : (a, b)
    lower, upper : (2,)
        Uniform prior box of the chapter.
    n_records : int
        Records per reading (record r uses the stream ``(seed, STREAM, r)`` for every reading).
    grid_size : int
        Grid points per parameter.
    tolerance : float
        Settling band (the chapter's ``tolerance_to_truth``), 1.
    path : path
        The readings file (default :data:`READINGS_FILE`).
    progress : callable, optional
        ``progress(message)`` after each record.
    """
    readings, horizons = load_readings(path)
    truth, lower, upper = (np.asarray(v, float) for v in (truth, lower, upper))
    rows = []
    for r in range(n_records):
        rows.append(record_row(readings, horizons, truth, lower, upper, grid_size, tolerance,
                               seed, r))
        if progress is not None:
            progress(f"readings study: record {r + 1}/{n_records}")
    return study_from_rows(pd.DataFrame(rows), readings, horizons)
