"""Resamplings against accuracy and calibration for the working (tempered Liu–West) scheme.

The engine issue asked whether fewer resamplings (the dominant start-up cost: each one moves
every particle and so pays N discretisations) can be had without losing accuracy.  This script
measures, on the chapter's own records (``simulate_lateral`` at the chapter's defaults, seeds
0..R−1) and its own filter set-up
(:func:`railpaper.experiments.rbpf_parameter_estimation.lateral.lateral_rbpf`), for a few
settings of the two levers — the ESS threshold that triggers resampling and the length of the
likelihood tempering — per setting:

* resamplings over the record (median over records) and the run time per step (median);
* the rate of records on which every parameter stays within 5 % from step 350 (the paper's
  claim, the chapter's statistic) with its 95 % Clopper–Pearson interval;
* the coverage of the 90 % interval (mean ± 1.645 sd) at the last step over records ×
  parameters, with its interval: a calibrated filter covers 0.9.

Usage: ``NUMBA_NUM_THREADS=2 .venv/bin/python -m railpaper.bench.resampling_study [records]``.  A
measurement, not a test: it prints a table and asserts nothing.

``--paired FIRST_SEED RECORDS OUT.csv`` compares two ESS thresholds (0.8 and 0.5) on the same
records (seeds FIRST_SEED …, each record filtered at both), one CSV row per record, and prints
the paired differences with their 95 % t intervals: the evidence behind the chapter's threshold
(``data/rbpf-parameter-estimation/ess_threshold_paired.csv``: seeds 20000–20199).
"""

from __future__ import annotations

import sys
import time

import numpy as np

from railpaper.experiments.lateral_vehicle import RecordSettings
from railpaper.experiments.rbpf_parameter_estimation import experiment
from railpaper.experiments.rbpf_parameter_estimation import lateral as study
from railpaper.experiments.rbpf_parameter_estimation.spec import Settings
from railpaper.experiments.rbpf_parameter_estimation.toy import gaussian_covers
from railpaper.stats import mean_interval, rate
from railpaper.threads import one_thread

#: (ess_fraction, tempering_steps); the first is the chapter's default (ESS < 0.5 N since
#: 2026-12-04; 0.8 before).
SETTINGS = ((None, None), (0.8, None), (0.3, None), (None, 100), (0.8, 100))
START, WITHIN = 350, 0.05


def run_setting(records: list, settings: Settings, fixed: dict, theta: np.ndarray) -> dict:
    """Every record through the working scheme with ``settings``; the table's statistics."""
    resamplings, seconds, within, covers = [], [], [], []
    for seed, (record, system) in enumerate(records):
        t0 = time.perf_counter()
        run = study.lateral_rbpf(settings, system, record, theta, seed, "working")
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
    settings = experiment.SPEC.resolve({}, False)
    fixed, theta = study.vehicle()
    records = []
    for seed in range(n_records):
        record = study.simulate_lateral(RecordSettings.of(settings), fixed, theta, seed)
        records.append((record, study.record_system(settings, fixed, theta, record)))
    rows = []
    for ess, temper in SETTINGS:
        varied = settings
        if ess is not None:
            varied = varied.replace(ess_fraction=ess)
        if temper is not None:
            varied = varied.replace(tempering_steps=temper)
        row = dict(ess_fraction=varied.ess_fraction, tempering_steps=varied.tempering_steps,
                   **run_setting(records, varied, fixed, theta))
        rows.append(row)
        print(f"ESS < {row['ess_fraction']:.2f} N, tempering {row['tempering_steps']:4d} steps: "
              f"resamplings {row['resamplings']:5.0f}, {row['steps_per_s']:6.0f} steps/s, "
              "within 5 % from step 350 {:.2f} [{:.2f}, {:.2f}], ".format(*row["within"])
              + "90 % coverage {:.3f} [{:.3f}, {:.3f}]".format(*row["coverage"]), flush=True)
    print(f"{n_records} records of {len(records[0][0].y)} steps, N = {settings.n_particles}, "
          "chapter defaults otherwise (first row)")
    return rows


#: The thresholds the paired study compares (the chapter's former and present default).
PAIRED_THRESHOLDS = (0.8, 0.5)


def paired_rows(first_seed: int, n_records: int, thresholds=PAIRED_THRESHOLDS) -> list[dict]:
    """Per record (seeds first_seed …): at each threshold, whether every parameter stays within
    5 % from step 350 on, how many of the 5 parameters its 90 % interval (mean ± 1.645 sd)
    covers at the last step, the largest final |relative error|, the resamplings and the
    seconds of the run.  Chapter defaults otherwise, one thread."""
    settings = experiment.SPEC.resolve({}, False)
    fixed, theta = study.vehicle()
    rows = []
    with one_thread():
        for seed in range(first_seed, first_seed + n_records):
            record = study.lateral_record(settings, fixed, theta, seed)
            system = study.record_system(settings, fixed, theta, record)
            row = {"seed": seed}
            for ess in thresholds:
                t0 = time.perf_counter()
                run = study.lateral_rbpf(settings.replace(ess_fraction=ess), system, record,
                                         theta, seed, "working")
                rel = run.theta_mean / theta - 1.0
                row[f"within_{ess}"] = bool(np.all(np.abs(rel[START - 1:]) <= WITHIN))
                row[f"covers_{ess}"] = int(np.sum(gaussian_covers(
                    run.theta_mean[-1] / theta, run.theta_std[-1] / theta, 1.0)))
                row[f"final_abs_max_{ess}"] = float(np.abs(rel[-1]).max())
                row[f"resamplings_{ess}"] = int(run.resampled.sum())
                row[f"seconds_{ess}"] = time.perf_counter() - t0
            rows.append(row)
    return rows


def paired_summary(rows: list[dict], thresholds=PAIRED_THRESHOLDS) -> list[str]:
    """Lines: each threshold's rates, and the paired differences (second − first) with their
    95 % t intervals, for the within-5 % indicator and the coverage fraction."""
    a, b = thresholds
    lines = []
    for name, scale in (("within", 1.0), ("covers", 5.0)):
        x = np.array([r[f"{name}_{a}"] for r in rows], float) / scale
        y = np.array([r[f"{name}_{b}"] for r in rows], float) / scale
        d = mean_interval(y - x)
        lines.append(f"{name}: {x.mean():.3f} at ESS < {a} N, {y.mean():.3f} at {b} N; paired "
                     f"difference {d.value:+.3f} [{d.low:+.3f}, {d.high:+.3f}], {len(rows)} records")
    for name in ("resamplings", "seconds"):
        lines.append(f"median {name}: " + ", ".join(
            f"{np.median([r[f'{name}_{t}'] for r in rows]):.3g} at {t} N" for t in thresholds))
    return lines


if __name__ == "__main__":
    if len(sys.argv) > 1 and sys.argv[1] == "--paired":
        import pandas as pd
        found = paired_rows(int(sys.argv[2]), int(sys.argv[3]))
        pd.DataFrame(found).to_csv(sys.argv[4], index=False)
        print("\n".join(paired_summary(found)))
    else:
        main(int(sys.argv[1]) if len(sys.argv) > 1 else 10)
