"""Resamplings against accuracy and calibration for the working (tempered Liu–West) scheme.

The engine issue asked whether fewer resamplings (the dominant start-up cost: each one moves
every particle and so pays N discretisations) can be had without losing accuracy.  This script
measures, on the chapter's own records (``simulate_lateral`` at the chapter's defaults, seeds
0..R−1) and its own filter set-up (:func:`railpaper.experiments.rbpf_parameter_estimation.experiment.lateral_rbpf`),
for a few settings of the two levers — the ESS threshold that triggers resampling and the
length of the likelihood tempering — per setting:

* resamplings over the record (median over records) and the run time per step (median);
* the rate of records on which every parameter stays within 5 % from step 350 (the paper's
  claim, the chapter's statistic) with its 95 % Clopper–Pearson interval;
* the coverage of the 90 % interval (mean ± 1.645 sd) at the last step over records ×
  parameters, with its interval: a calibrated filter covers 0.9.

Usage: ``NUMBA_NUM_THREADS=2 .venv/bin/python -m railpaper.bench.resampling_study [records]``.  A
measurement, not a test: it prints a table and asserts nothing.
"""

from __future__ import annotations

import sys
import time

import numpy as np

from railpaper.experiments.rbpf_parameter_estimation import experiment as E
from railpaper.experiments.rbpf_parameter_estimation import lateral as study
from railpaper.experiments.rbpf_parameter_estimation.toy import gaussian_covers
from railpaper.stats import rate

#: (ess_fraction, tempering_steps); the first is the chapter's default.
SETTINGS = ((None, None), (0.5, None), (0.3, None), (None, 100), (0.5, 100))
START, WITHIN = 350, 0.05


def run_setting(records: list, p: dict, fixed: dict, theta: np.ndarray) -> dict:
    """Every record through the working scheme with parameters ``p``; the table's statistics."""
    resamplings, seconds, within, covers = [], [], [], []
    for seed, (record, system) in enumerate(records):
        t0 = time.perf_counter()
        run = study.lateral_rbpf(p, system, record, theta, seed, "working")
        seconds.append((time.perf_counter() - t0) / len(record.y))
        resamplings.append(int(run.resampled.sum()))
        rel = run.theta_mean / theta - 1.0
        within.append(bool(np.all(np.abs(rel[START - 1:]) <= WITHIN)))
        covers.append(gaussian_covers(run.theta_mean[-1] / theta, run.theta_std[-1] / theta, 1.0))
    w, c = rate(within), rate(np.array(covers))
    return dict(resamplings=float(np.median(resamplings)),
                steps_per_s=1.0 / float(np.median(seconds)),
                within=(w.value, w.low, w.high), coverage=(c.value, c.low, c.high))


def main(n_records: int = 10) -> list[dict]:
    base = dict(E.SPEC.resolve({}, False))
    fixed, theta = study.vehicle()
    records = []
    for seed in range(n_records):
        record = study.simulate_lateral(base, fixed, theta, seed)
        records.append((record, study.filter_system(base, fixed, theta, record)))
    rows = []
    for ess, temper in SETTINGS:
        p = dict(base)
        if ess is not None:
            p["ess_fraction"] = ess
        if temper is not None:
            p["tempering_steps"] = temper
        row = dict(ess_fraction=p["ess_fraction"], tempering_steps=p["tempering_steps"],
                   **run_setting(records, p, fixed, theta))
        rows.append(row)
        print(f"ESS < {row['ess_fraction']:.2f} N, tempering {row['tempering_steps']:4d} steps: "
              f"resamplings {row['resamplings']:5.0f}, {row['steps_per_s']:6.0f} steps/s, "
              "within 5 % from step 350 {:.2f} [{:.2f}, {:.2f}], ".format(*row["within"])
              + "90 % coverage {:.3f} [{:.3f}, {:.3f}]".format(*row["coverage"]), flush=True)
    print(f"{n_records} records of {len(records[0][0].y)} steps, N = {base['n_particles']}, "
          "chapter defaults otherwise (first row)")
    return rows


if __name__ == "__main__":
    main(int(sys.argv[1]) if len(sys.argv) > 1 else 10)
