"""Hardening (#7): every bad input on every command ends in one line on stderr
(``railpaper: error: ...``), a stated exit status, no traceback, and leaves the last good
outputs byte-identical.  Interrupts (SIGINT, SIGTERM) and a second run of the same chapter too.

The bad-input matrix runs every case through the CLI's entry point in one interpreter of its own
(one module fixture), and each case is its own test asserting on its result.  Run-level cases use the cheapest chapter
(reduced-order-observer) with --quick and a one-speed configuration.
"""

from __future__ import annotations

import json
import math
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from conftest import REPO, railpaper_cli

from railpaper.experiments.base import ParameterError, check_sample_time
from railpaper.models import lateral_16state

ROO, RBPF, PSO, QG = ("reduced-order-observer", "rbpf-parameter-estimation",
                      "partial-state-observer", "quasi-gaussian-rbpf")
SFD = "suspension-fault-detection"
CHEAP = ["--quick", "-p", "mc_seeds", "2", "-p", "sweep_speeds_kmh", "[60]",
         "-p", "speeds_kmh", "[60]"]
SIGNAL_AFTER_S = 2.0          # after the staging directory appears: the kernel is running cells
# Runs to be interrupted simulate 30 s of track (about a minute on a quiet machine): they must still
# be running when the signal comes, however loaded the machine is.
LONG = ["-p", "duration_s", "30"]
# The first run holds the chapter's lock while a second run is refused: 4 s of track (about 15 s;
# the refusal comes within the second run's start-up, a few seconds).
MEDIUM = ["-p", "duration_s", "4"]

# (id, arguments, exit status, key words of the one line).  {OUT}: an output directory holding a
# previous run's files (must stay byte-identical); {CSV}: a measurement CSV written for the case;
# {FILE}: an existing regular file; {PROFILE}: a previous track export (must stay identical).
MATRIX = [
    # usage errors (argparse)
    ("no-command", [], 2, ["required", "command"]),
    ("unknown-command", ["frobnicate"], 2, ["invalid choice", "frobnicate"]),
    ("run-no-chapter", ["run"], 2, ["run:", "chapter"]),
    ("run-bad-option", ["run", ROO, "--fast"], 2, ["unrecognized", "--fast"]),
    ("list-extra-argument", ["list", "extra"], 2, ["unrecognized", "extra"]),
    # run: chapter and parameter names
    ("run-unknown-chapter", ["run", "no-such-chapter", "--out", "{OUT}"], 2,
     ["unknown chapter 'no-such-chapter'", ROO]),
    ("run-misspelt-chapter", ["run", "reduced-order-observr", "--out", "{OUT}"], 2,
     ["did you mean 'reduced-order-observer'"]),
    ("run-unknown-parameter", ["run", QG, "-p", "colour", "red", "--out", "{OUT}"], 2,
     ["has no parameter 'colour'"]),
    ("run-misspelt-parameter", ["run", PSO, "-p", "dt_ss", "1e-4", "--out", "{OUT}"], 2,
     ["no parameter 'dt_ss'", "did you mean 'dt_s'"]),
    ("run-misspelt-parameter-rbpf", ["run", RBPF, "-p", "n_particle", "10", "--out", "{OUT}"], 2,
     ["did you mean 'n_particles'"]),
    # run: values that only Monte Carlo samples of a sweep may take
    ("run-sample-only-side-tables", ["run", ROO, "-p", "side_tables", "false", "--out", "{OUT}"],
     2, ["side_tables = false is for Monte Carlo samples", "needs side_tables = true"]),
    ("run-sample-only-lateral", ["run", RBPF, "-p", "lateral", "false", "--out", "{OUT}"], 2,
     ["lateral = false is for Monte Carlo samples", "needs lateral = true"]),
    ("run-sample-only-timing", ["run", QG, "-p", "timing", "false", "--out", "{OUT}"], 2,
     ["timing = false is for Monte Carlo samples", "needs timing = true"]),
    # run: wrong types
    ("run-type-float", ["run", QG, "-p", "a_true", "abc", "--out", "{OUT}"], 2,
     ["'a_true' expects float", "'abc'"]),
    ("run-type-int", ["run", QG, "-p", "seed", "1.5", "--out", "{OUT}"], 2,
     ["'seed' expects an integer"]),
    ("run-type-bool", ["run", ROO, "-p", "side_tables", "maybe", "--out", "{OUT}"], 2,
     ["'side_tables' expects true or false"]),
    ("run-type-list", ["run", QG, "-p", "timing_particles", "many", "--out", "{OUT}"], 2,
     ["'timing_particles' expects a non-empty list"]),
    ("run-type-list-element", ["run", QG, "-p", "timing_particles", "[100, 1.5]",
                               "--out", "{OUT}"], 2, ["'timing_particles' expects an integer"]),
    ("run-type-str", ["run", RBPF, "-p", "spectrum", "[1, 2]", "--out", "{OUT}"], 2,
     ["'spectrum' expects a string"]),
    ("run-nan", ["run", PSO, "-p", "duration_s", ".nan", "--out", "{OUT}"], 2,
     ["'duration_s' must be finite"]),
    # run: non-physical values
    ("run-zero-speed", ["run", PSO, "-p", "speeds_kmh", "[0, 60]", "--out", "{OUT}"], 2,
     ["'speeds_kmh' must be > 0"]),
    ("run-negative-speed", ["run", RBPF, "-p", "speed_kmh", "-300", "--out", "{OUT}"], 2,
     ["'speed_kmh' must be > 0"]),
    ("run-negative-duration", ["run", PSO, "-p", "duration_s", "-1", "--out", "{OUT}"], 2,
     ["'duration_s' must be > 0"]),
    ("run-zero-step", ["run", RBPF, "-p", "dt_s", "0", "--out", "{OUT}"], 2,
     ["'dt_s' must be > 0"]),
    ("run-negative-wavelength", ["run", PSO, "-p", "wavelength_min_m", "-1", "--out", "{OUT}"],
     2, ["'wavelength_min_m' must be > 0"]),
    ("run-negative-noise", ["run", QG, "-p", "r_var", "-0.1", "--out", "{OUT}"], 2,
     ["'r_var' must be > 0"]),
    ("run-zero-particles-rbpf", ["run", RBPF, "-p", "n_particles", "0", "--out", "{OUT}"], 2,
     ["'n_particles' must be >= 2"]),
    ("run-negative-particles-qg", ["run", QG, "-p", "n_particles", "-5", "--out", "{OUT}"], 2,
     ["'n_particles' must be >= 2"]),
    ("run-one-record", ["run", QG, "-p", "n_monte_carlo", "0", "--out", "{OUT}"], 2,
     ["'n_monte_carlo' must be >= 1"]),
    ("run-dt-too-coarse-roo", ["run", ROO, "--quick", "-p", "dt_s", "0.002", "--out", "{OUT}"], 2,
     ["'dt_s'", "too coarse", "243 Hz", "5e-4"]),
    ("run-dt-too-coarse-pso", ["run", PSO, "--quick", "-p", "dt_s", "0.01", "--out", "{OUT}"], 2,
     ["'dt_s'", "229 Hz", "2e-3"]),
    ("run-dt-too-coarse-rbpf", ["run", RBPF, "--quick", "-p", "dt_s", "0.012",
                                "-p", "wavelength_min_m", "3", "--out", "{OUT}"], 2,
     ["'dt_s'", "too coarse", "fastest mode", "dt_s·|λ_max| ≤ 3.14"]),
    ("run-unknown-choice", ["run", ROO, "-p", "plant", "hertzian", "--out", "{OUT}"], 2,
     ["'plant' must be 'linear' or 'hertz'"]),
    ("run-unknown-spectrum", ["run", RBPF, "--quick", "-p", "spectrum", "german-lo",
                              "--out", "{OUT}"], 2, ["unknown spectrum 'german-lo'", "german-low"]),
    ("run-track-class", ["run", PSO, "-p", "track_class", "7", "--out", "{OUT}"], 2,
     ["'track_class' must be 1..6"]),
    ("run-window-after-end", ["run", PSO, "--quick", "-p", "error_window_start_s", "12",
                              "--out", "{OUT}"], 2, ["'error_window_start_s'", "duration_s"]),
    ("run-prior-box", ["run", QG, "-p", "a_true", "0.9", "--out", "{OUT}"], 2,
     ["a_true=0.9", "prior box"]),
    # the fault-detection appendix: a fault time outside the record, a factor <= 0, a name
    ("run-fault-time-outside", ["run", SFD, "-p", "fault_time_s", "9", "--out", "{OUT}"], 2,
     ["'fault_time_s' = 9 s lies outside the record"]),
    # (the appendix's other refusals, in process: tests/experiments/suspension_fault_detection)
    # run: measurement CSV (rbpf-parameter-estimation)
    ("csv-missing-file", ["run", RBPF, "--quick", "-p", "measurements_csv", "no-such-file.csv",
                          "--out", "{OUT}"], 2, ["measurements_csv", "cannot read"]),
    ("csv-missing-columns", ["run", RBPF, "--quick", "-p", "measurements_csv", "{CSV}",
                             "--out", "{OUT}"], 2, ["measurements_csv", "missing column",
                                                    "acc_b_mps2"]),
    ("csv-nan", ["run", RBPF, "--quick", "-p", "measurements_csv", "{CSV}", "--out", "{OUT}"], 2,
     ["measurements_csv", "acc_w2_mps2", "NaN", "row 5"]),
    ("csv-text", ["run", RBPF, "--quick", "-p", "measurements_csv", "{CSV}", "--out", "{OUT}"], 2,
     ["measurements_csv", "non-numeric", "row 3"]),
    ("csv-non-monotonic-time", ["run", RBPF, "--quick", "-p", "measurements_csv", "{CSV}",
                                "--out", "{OUT}"], 2, ["measurements_csv", "not increasing"]),
    ("csv-wrong-step", ["run", RBPF, "--quick", "-p", "measurements_csv", "{CSV}",
                        "--out", "{OUT}"], 2, ["measurements_csv", "uniformly by dt_s"]),
    ("csv-too-short", ["run", RBPF, "--quick", "-p", "measurements_csv", "{CSV}",
                       "--out", "{OUT}"], 2, ["measurements_csv", ">= 10 rows"]),
    # run: output directory
    ("run-out-is-file", ["run", QG, "--quick", "--out", "{FILE}"], 2, ["is a file"]),
    ("run-out-foreign-dir", ["run", QG, "--quick", "--out", "{FOREIGN}"], 2,
     ["no previous run", "new or empty directory"]),
    ("run-out-unwritable", ["run", QG, "--quick", "--out", "/proc/railpaper-nope/run"], 2,
     ["/proc"]),
    # track
    ("track-unknown-spectrum", ["track", "--spectrum", "fra-9", "-o", "{PROFILE}"], 2,
     ["unknown spectrum 'fra-9'", "did you mean 'fra-6'"]),
    ("track-unknown-component", ["track", "--spectrum", "fra-5", "--component", "vert",
                                 "-o", "{PROFILE}"], 2, ["unknown component 'vert'", "vertical"]),
    ("track-negative-length", ["track", "--spectrum", "fra-5", "--length-m", "-5",
                               "-o", "{PROFILE}"], 2, ["length_m must be", "> 0"]),
    ("track-zero-step", ["track", "--spectrum", "fra-5", "--dx-m", "0", "-o", "{PROFILE}"], 2,
     ["dx_m must be", "> 0"]),
    ("track-length-not-number", ["track", "--spectrum", "fra-5", "--length-m", "long",
                                 "-o", "{PROFILE}"], 2, ["track:", "--length-m", "'long'"]),
    ("track-too-many-samples", ["track", "--spectrum", "fra-5", "--length-m", "1e12",
                                "-o", "{PROFILE}"], 2, ["samples", "shorter length_m"]),
    ("track-negative-seed", ["track", "--spectrum", "fra-5", "--seed", "-1", "-o", "{PROFILE}"],
     2, ["seed must be an integer >= 0"]),
    ("track-band-reversed", ["track", "--spectrum", "fra-5", "--wavelength-min-m", "50",
                             "--wavelength-max-m", "10", "-o", "{PROFILE}"], 2,
     ["wavelength_min_m < wavelength_max_m"]),
    ("track-unknown-method", ["track", "--spectrum", "fra-5", "--method", "fft",
                              "-o", "{PROFILE}"], 2, ["--method", "invalid choice"]),
    ("track-no-output", ["track", "--spectrum", "fra-5"], 2, ["--spectrum and -o"]),
    ("track-output-dir-missing", ["track", "--spectrum", "fra-5", "-o", "{OUT}/no/such/x.csv"], 2,
     ["no such directory"]),
    # sweep
    ("sweep-unknown-chapter", ["sweep", "nope", "--seeds", "0:2", "--out", "{OUT}"], 2,
     ["unknown chapter 'nope'"]),
    ("sweep-seeds-syntax", ["sweep", QG, "--seeds", "a:b", "--out", "{OUT}"], 2,
     ["--seeds expects START:STOP"]),
    ("sweep-seeds-empty", ["sweep", QG, "--seeds", "5:2", "--out", "{OUT}"], 2,
     ["gives no seeds"]),
    ("sweep-seeds-repeated", ["sweep", QG, "--seeds", "1,1", "--out", "{OUT}"], 2,
     ["repeats a seed"]),
    ("sweep-grid-no-equals", ["sweep", QG, "--grid", "dt_s", "--seeds", "0:2", "--out", "{OUT}"],
     2, ["--grid expects NAME=V1,V2"]),
    ("sweep-grid-brackets", ["sweep", QG, "--grid", "speeds_kmh=[60", "--seeds", "0:2",
                             "--out", "{OUT}"], 2, ["--grid speeds_kmh", "cannot split"]),
    ("sweep-grid-misspelt", ["sweep", QG, "--grid", "n_particle=10", "--seeds", "0:2",
                             "--out", "{OUT}"], 2, ["did you mean 'n_particles'"]),
    ("sweep-grid-non-physical", ["sweep", QG, "--grid", "r_var=0.01,-1", "--seeds",
                                 "0:2", "--out", "{OUT}"], 2, ["'r_var' must be > 0"]),
    ("sweep-grid-dt-too-coarse", ["sweep", ROO, "--grid", "dt_s=1e-4,1e-3", "--seeds", "0:2",
                                  "--out", "{OUT}"], 2, ["'dt_s'", "too coarse"]),
    ("sweep-fixed-wrong-type", ["sweep", QG, "-p", "seed", "x", "--seeds", "0:2",
                                "--out", "{OUT}"], 2, ["'seed' expects"]),
    ("sweep-workers-zero", ["sweep", QG, "--seeds", "0:1", "--workers", "0", "--out", "{OUT}"],
     2, ["--workers must be >= 1"]),
    ("sweep-workers-not-int", ["sweep", QG, "--seeds", "0:1", "--workers", "two",
                               "--out", "{OUT}"], 2, ["sweep:", "--workers"]),
    ("sweep-scheduler-unreachable", ["sweep", QG, "--quick", "--seeds", "0:1", "--scheduler",
                                     "tcp://127.0.0.1:9", "--out", "{OUT}"], 2,
     ["cannot reach dask scheduler", "tcp://127.0.0.1:9"]),
    ("sweep-out-is-file", ["sweep", QG, "--quick", "--seeds", "0:1", "--out", "{FILE}"], 2,
     ["is a file"]),
    # check
    ("check-unknown-chapter", ["check", "nope"], 2, ["unknown chapter 'nope'"]),
    ("check-no-metrics", ["check", ROO, "--out", "{EMPTY}"], 2,
     ["metrics.json not found", "no run of"]),
    ("check-corrupt-metrics", ["check", ROO, "--out", "{CORRUPT}"], 2,
     ["corrupt metrics.json", "re-run"]),
    ("check-metrics-not-a-run", ["check", ROO, "--out", "{NOTARUN}"], 2,
     ["corrupt metrics.json", "no 'metrics' table"]),
    ("check-metrics-other-chapter", ["check", PSO, "--out", "{OUT}"], 2,
     ["holds a run of 'reduced-order-observer'"]),
    ("check-out-two-chapters", ["check", "--out", "{OUT}"], 2, ["exactly one chapter"]),
    # bench (refused before a minute of benchmarking)
    ("bench-out-not-json", ["bench", "--out", "{OUT}/bench.txt"], 2, ["expected a .json"]),
    ("bench-out-unwritable", ["bench", "--out", "/proc/railpaper-nope/bench.json"], 2,
     ["cannot write there"]),
    ("bench-out-is-dir", ["bench", "--out", "{DIRJSON}"], 2, ["cannot write there"]),
]

CSV_CASES = {"csv-missing-columns", "csv-nan", "csv-text", "csv-non-monotonic-time",
             "csv-wrong-step", "csv-too-short"}


def _measurements(case: str) -> pd.DataFrame:
    """A 20-row record at dt_s = 1 ms, broken the way ``case`` says."""
    frame = pd.DataFrame({"t_s": np.arange(20) * 1e-3,
                          **{c: 0.1 for c in lateral_16state.CHANNELS}})
    if case == "csv-missing-columns":
        frame = frame.drop(columns=["acc_b_mps2"])
    elif case == "csv-nan":
        frame.loc[4, "acc_w2_mps2"] = np.nan
    elif case == "csv-text":
        frame = frame.astype(object)
        frame.loc[2, "acc_b_mps2"] = "n/a"
    elif case == "csv-non-monotonic-time":
        frame.loc[[7, 8], "t_s"] = frame.loc[[8, 7], "t_s"].to_numpy()
    elif case == "csv-wrong-step":
        frame["t_s"] *= 2
    elif case == "csv-too-short":
        frame = frame.iloc[:5]
    return frame


def snapshot(folder: Path) -> dict[str, bytes]:
    """Every file under ``folder`` (hidden ones too) with its bytes."""
    return {str(p.relative_to(folder)): p.read_bytes() for p in sorted(folder.rglob("*"))
            if p.is_file()}


def _previous_run(folder: Path) -> Path:
    """A directory standing for a previous run's outputs (a failing command must not touch it)."""
    folder.mkdir(parents=True)
    (folder / "metrics.json").write_text('{"chapter": "reduced-order-observer", "metrics": '
                                         '{"x": 1.0}, "parameters": {}, "quick": true}\n')
    (folder / "timeseries.csv").write_text("t_s,x\n0,1\n")
    (folder / "figure.png").write_bytes(bytes(range(256)))
    return folder


def _prepare(case: str, args: list[str], root: Path) -> tuple[list[str], Path]:
    """Arguments with placeholders filled; the folder whose bytes must survive the command."""
    root.mkdir(parents=True)
    out = _previous_run(root / "previous")
    fill = {"{OUT}": str(out), "{FILE}": str(root / "previous" / "timeseries.csv")}
    fill["{EMPTY}"] = str(root / "empty")
    fill["{DIRJSON}"] = str(root / "previous" / "old.json")
    (root / "previous" / "old.json").mkdir()
    (root / "empty").mkdir()
    fill["{FOREIGN}"] = str(root / "previous_foreign")
    shutil.copytree(out, root / "previous_foreign")
    (root / "previous_foreign" / "metrics.json").rename(root / "previous_foreign" / "notes.json")
    fill["{CORRUPT}"] = str(root / "corrupt")
    (root / "corrupt").mkdir()
    (root / "corrupt" / "metrics.json").write_text('{"chapter": "reduced-order-obs')
    fill["{NOTARUN}"] = str(root / "notarun")
    (root / "notarun").mkdir()
    (root / "notarun" / "metrics.json").write_text("[1, 2, 3]\n")
    fill["{PROFILE}"] = str(root / "previous" / "profile.csv")
    (root / "previous" / "profile.csv").write_text("distance_m,irregularity_m\n0,0.001\n")
    if case in CSV_CASES:
        fill["{CSV}"] = str(root / "measurements.csv")
        _measurements(case).to_csv(fill["{CSV}"], index=False)
    filled = []
    for arg in args:
        for key, value in fill.items():
            arg = arg.replace(key, value)
        filled.append(arg)
    return filled, root


# One interpreter runs every case through ``railpaper.cli.main`` in turn, each with its own
# stderr, exit status and working directory (the repository, as for a user's `railpaper`): the
# cases then share one import of the package instead of paying it sixty times.  The exit-status
# and one-line path of the real executable is the same function (``python -m railpaper`` calls
# ``sys.exit(main())``); tests/pipeline/test_cli.py runs its cases as separate processes.
_DRIVER = r"""
import contextlib, io, json, os, sys, traceback
os.chdir(sys.argv[1])
from railpaper import cli
out = []
for argv in json.load(sys.stdin):
    err = io.StringIO()
    with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
        try:
            status = cli.main(argv)
        except SystemExit as exc:                # argparse's usage errors
            status = exc.code if isinstance(exc.code, int) else 1
        except BaseException:                    # a traceback a user would have seen
            traceback.print_exc()
            status = 1
    out.append([status, err.getvalue()])
with open(sys.argv[2], "w") as handle:
    json.dump(out, handle)
"""


@pytest.fixture(scope="module")
def outcomes(tmp_path_factory):
    """Every matrix case run once through the CLI's entry point (one interpreter for all, in a
    process of its own), with the bytes of its root folder before and after."""
    base = tmp_path_factory.mktemp("hardening")
    prepared = {case: _prepare(case, args, base / case) for case, args, _, _ in MATRIX}
    before = {case: snapshot(root) for case, (_, root) in prepared.items()}
    answers = base / "answers.json"
    driver = subprocess.run([sys.executable, "-c", _DRIVER, str(REPO), str(answers)],
                            input=json.dumps([filled for filled, _ in prepared.values()]),
                            capture_output=True, text=True, timeout=600,
                            env=dict(os.environ, PYTHONWARNINGS="ignore"))
    assert driver.returncode == 0, driver.stderr[-3000:]
    results = json.loads(answers.read_text())
    return {case: (subprocess.CompletedProcess(filled, status, "", stderr), before[case],
                   snapshot(root), root)
            for (case, (filled, root)), (status, stderr) in zip(prepared.items(), results)}


def assert_one_error_line(result, status: int, words) -> str:
    assert "Traceback" not in result.stderr, result.stderr[-3000:]
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1, result.stderr[-3000:]
    assert lines[0].startswith("railpaper: error: "), lines[0]
    for word in words:
        assert word in lines[0], (word, lines[0])
    assert result.returncode == status, (result.returncode, lines[0])
    return lines[0]


@pytest.mark.parametrize("case, args, status, words", MATRIX, ids=[m[0] for m in MATRIX])
def test_bad_input(outcomes, case, args, status, words):
    result, before, after, root = outcomes[case]
    assert_one_error_line(result, status, words)
    assert after == before                                  # nothing written, changed or removed
    assert not list(root.glob(".*staging*")) and not list(root.glob(".*previous-*"))


# ------------------------------------------------------------- runs: concurrent and interrupted

def _start_run(out: Path, extra: tuple[str, ...] = ()) -> subprocess.Popen:
    env = dict(os.environ, PYTHONWARNINGS="ignore", OMP_NUM_THREADS="1")
    return subprocess.Popen([sys.executable, "-m", "railpaper", "run", ROO, *CHEAP, *extra,
                             "--out", str(out)], cwd=REPO, env=env, text=True,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            preexec_fn=_default_sigint)


def _default_sigint() -> None:
    """SIGINT as in a terminal, even when this suite runs in the background of a script (which
    starts it with SIGINT ignored, and a child inherits that)."""
    signal.signal(signal.SIGINT, signal.SIG_DFL)


def _wait_for_staging(out: Path, process: subprocess.Popen, timeout_s: float = 60) -> Path:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        staging = list(out.parent.glob(f".{out.name}.staging-*"))
        if staging:
            return staging[0]
        assert process.poll() is None, process.communicate()
        time.sleep(0.05)
    raise AssertionError("the run never created its staging directory")


def _processes_in(folder: Path) -> list[str]:
    """Pids of processes whose working directory is ``folder`` (a kernel runs in staging)."""
    pids = []
    for proc in Path("/proc").glob("[0-9]*"):
        try:
            if os.readlink(proc / "cwd").startswith(str(folder)):
                pids.append(proc.name)
        except OSError:
            pass
    return pids


@pytest.fixture(scope="module")
def runs(tmp_path_factory, after_quick_book):
    """Real runs of the chapter, at the same time: a first run; a second run into the same
    directory while the first runs; two runs over previous outputs, interrupted by SIGINT and
    SIGTERM once their kernels execute cells."""
    base = tmp_path_factory.mktemp("runs")
    out = base / "first" / "run"
    first = _start_run(out, MEDIUM)
    _wait_for_staging(out, first)
    interrupted = {}
    for signum in (signal.SIGINT, signal.SIGTERM):
        target = _previous_run(base / signum.name / "run")
        interrupted[signum] = (target, snapshot(target), _start_run(target, LONG))
    second = railpaper_cli("run", ROO, *CHEAP, "--out", str(out), timeout=120)
    for signum, (target, before, process) in interrupted.items():
        staging = _wait_for_staging(target, process)
        time.sleep(SIGNAL_AFTER_S)
        running = process.poll() is None
        process.send_signal(signum)
        _, stderr = process.communicate(timeout=60)
        time.sleep(0.5)
        interrupted[signum] = dict(target=target, before=before, after=snapshot(target),
                                   running=running, status=process.returncode, stderr=stderr,
                                   left=_processes_in(staging))
    first_out, first_err = first.communicate(timeout=300)
    return dict(out=out, status=first.returncode, stdout=first_out, stderr=first_err,
                second=second, interrupted=interrupted)


def test_second_run_of_the_same_chapter_is_refused(runs):
    out = runs["out"]
    assert_one_error_line(runs["second"], 2, ["another run is writing", str(out)])
    assert runs["status"] == 0, runs["stderr"][-3000:]    # the first run completes regardless
    assert f"written to {out}" in runs["stdout"]
    assert (out / "metrics.json").exists() and (out / "reduced_order_observer.ipynb").exists()
    assert not list(out.parent.glob(".run.staging-*"))


def test_run_page_marks_non_default_parameters(runs):
    """The first run's page (a whole ``railpaper run`` with ``-p``) names its non-default
    parameters above the claims it judged (the run page's own tests: test_run_page.py)."""
    out = runs["out"]
    assert json.loads((out / "metrics.json").read_text())["parameters"]["duration_s"] == 4
    assert (out / "index.html").exists()
    text = (out / "page" / "reduced_order_observer.html").read_text()
    assert "Non-default parameters: " in text
    for name in ("duration_s", "mc_seeds", "speeds_kmh"):
        assert name in text.split("Non-default parameters: ")[1].split(".")[0], name


@pytest.mark.parametrize("signum", [signal.SIGINT, signal.SIGTERM], ids=["SIGINT", "SIGTERM"])
def test_interrupted_run_keeps_previous_outputs(runs, signum):
    r = runs["interrupted"][signum]
    assert r["running"], "the run ended before it could be interrupted"
    line = assert_one_error_line(subprocess.CompletedProcess([], r["status"], "", r["stderr"]),
                                 128 + signum, [f"interrupted by {signum.name}",
                                                "previous outputs left untouched"])
    assert line.endswith("untouched")
    assert r["after"] == r["before"]                      # byte-identical previous outputs
    parent = r["target"].parent
    assert not list(parent.glob(".run.staging-*")) and not list(parent.glob(".run.previous-*"))
    assert r["left"] == []                                # no kernel left running in staging


@pytest.mark.parametrize("signum", [signal.SIGINT, signal.SIGTERM], ids=["SIGINT", "SIGTERM"])
def test_interrupted_sweep_keeps_finished_samples(tmp_path, signum):
    """A sweep interrupted mid-way ends in one error line (no dask warnings of the cancelled
    samples), exit 128+signal, and its results.csv holds the samples finished so far."""
    out = tmp_path / "sweep"
    process = subprocess.Popen(
        [sys.executable, "-m", "railpaper", "sweep", ROO, *CHEAP[1:], "--quick", "--seeds",
         "0:500", "--workers", "1", "--out", str(out)], cwd=REPO, text=True,
        env=dict(os.environ, PYTHONWARNINGS="ignore"), stdout=subprocess.PIPE,
        stderr=subprocess.PIPE, preexec_fn=_default_sigint)
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline and process.poll() is None:
        results = out / "results.csv"
        if results.exists() and len(results.read_text().splitlines()) >= 2:   # a sample done
            break
        time.sleep(0.1)
    assert process.poll() is None, process.communicate()
    process.send_signal(signum)
    _, stderr = process.communicate(timeout=60)
    assert "Traceback" not in stderr and "WARNING" not in stderr, stderr[-3000:]
    errors = [line for line in stderr.splitlines() if not line.startswith("railpaper: sweep")]
    assert errors == [f"railpaper: error: interrupted by {signum.name}; finished samples kept "
                      f"in {out / 'results.csv'}; the same command resumes"], stderr[-3000:]
    assert process.returncode == 128 + signum
    table = pd.read_csv(out / "results.csv")
    assert len(table) >= 1 and (table.status == "ok").all()


# ------------------------------------------------------------------------ the sample-time bound

def test_sample_time_bound_against_an_oscillator():
    """dt·|λ_max| ≤ π: for an undamped oscillator of ω rad/s the limit is dt = π/ω exactly."""
    omega = 2 * math.pi * 50.0                                # 50 Hz: Nyquist sample time 10 ms
    A = np.array([[0.0, 1.0], [-omega ** 2, 0.0]])
    check_sample_time("dt_s", 0.0099, A, "an oscillator")
    with pytest.raises(ParameterError, match=r"dt_s ≤ 0\.01 s"):
        check_sample_time("dt_s", 0.0101, A, "an oscillator")
    with pytest.raises(ParameterError, match="too coarse"):       # a real mode of 1000 1/s
        check_sample_time("dt_s", 0.004, np.array([[-1000.0]]), "a fast real mode")


def test_measurements_csv_is_read_where_the_user_is(tmp_path, monkeypatch):
    """A relative measurements_csv names a file in the caller's directory, not in the kernel's
    staging directory: resolving the parameters makes it absolute (empty stays empty)."""
    from railpaper.experiments.rbpf_parameter_estimation import experiment as chapter
    monkeypatch.chdir(tmp_path)
    settings = chapter.SPEC.resolve({"measurements_csv": "record.csv"}, quick=True)
    assert settings.measurements_csv == str((tmp_path / "record.csv").resolve())
    assert chapter.SPEC.resolve({}, quick=True).measurements_csv == ""


@pytest.mark.parametrize("signum", [signal.SIGINT, signal.SIGTERM], ids=["SIGINT", "SIGTERM"])
def test_signal_during_the_output_swap_waits_for_its_end(signum):
    """The swap of staging and output is not cut between its two renames: a signal arriving
    inside ``signals_deferred`` takes effect (as KeyboardInterrupt here) only after the block."""
    from railpaper.pipeline.chapters import signals_deferred
    steps = []

    def interrupt(sig, frame):
        raise KeyboardInterrupt(sig)

    old = {s: signal.signal(s, interrupt) for s in (signal.SIGINT, signal.SIGTERM)}
    try:
        with pytest.raises(KeyboardInterrupt):
            with signals_deferred():
                os.kill(os.getpid(), signum)
                time.sleep(0.05)
                steps.append("first rename")
                steps.append("second rename")
    finally:
        for s, handler in old.items():
            signal.signal(s, handler)
    assert steps == ["first rename", "second rename"]
