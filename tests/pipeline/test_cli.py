"""CLI: bad input ends in one clear line and exit 2, before any kernel starts; track export."""

import signal

import pandas as pd
import pytest
from conftest import railpaper_cli

from railpaper import cli


@pytest.mark.parametrize("args, message", [
    (["run", "no-such-chapter"], "unknown chapter 'no-such-chapter'"),
    (["run", "reduced-order-observr"], "did you mean 'reduced-order-observer'"),
    (["run", "reduced-order-observer", "-p", "speed_kmh", "60"], "did you mean 'speeds_kmh'"),
    (["run", "reduced-order-observer", "-p", "speeds_kmh", "fast"], "expects a non-empty list"),
    (["run", "reduced-order-observer", "-p", "speeds_kmh", "[0, 60]"], "must be > 0"),
    (["run", "reduced-order-observer", "-p", "duration_s", "-1"], "must be > 0"),
    (["run", "reduced-order-observer", "-p", "seed", "1.5"], "expects an integer"),
    (["check", "nope"], "unknown chapter 'nope'"),
    (["compile", "--jobs", "0"], "--jobs must be >= 1"),
    (["track", "--spectrum", "fra-9", "-o", "x.csv"], "fra-9"),
    (["track", "--spectrum", "fra-5", "--component", "sideways", "-o", "x.csv"], "sideways"),
    (["track", "--spectrum", "fra-5", "--dx-m", "0", "-o", "x.csv"], "dx"),
])
def test_bad_input_one_line_exit_2(args, message, tmp_path):
    result = railpaper_cli(*args)
    assert result.returncode == 2
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("railpaper: error:"), result.stderr
    assert message in lines[0]


def test_track_export(tmp_path):
    out = tmp_path / "profile.csv"
    result = railpaper_cli("track", "--spectrum", "fra-5", "--component", "vertical",
                           "--length-m", "2000", "--dx-m", "0.25", "--seed", "0", "-o", str(out))
    assert result.returncode == 0, result.stderr
    frame = pd.read_csv(out)
    assert list(frame.columns) == ["distance_m", "irregularity_m"]
    assert len(frame) == pytest.approx(8000, abs=2)
    assert 1e-4 < frame.irregularity_m.std() < 0.05


def test_track_list_and_run_list():
    result = railpaper_cli("track", "--list")
    assert result.returncode == 0
    for name in ("fra-1", "fra-6", "german-low", "german-high", "china-hsr"):
        assert name in result.stdout
    listing = railpaper_cli("list")
    assert listing.returncode == 0 and "speeds_kmh" in listing.stdout


@pytest.mark.parametrize("signal_error", [KeyboardInterrupt(), cli.Interrupted(signal.SIGTERM)],
                         ids=["SIGINT", "SIGTERM"])
def test_a_signal_that_lands_in_a_library_lock_still_ends_in_one_line(monkeypatch, capsys,
                                                                     signal_error):
    """dask's as_completed can turn a Ctrl-C into 'RuntimeError: cannot release un-acquired lock'
    raised while handling it: the command still ends as interrupted (one line, 128 + signal);
    a RuntimeError of its own is not swallowed."""
    def interrupted_inside_a_lock(args):
        try:
            raise signal_error
        except KeyboardInterrupt:
            raise RuntimeError("cannot release un-acquired lock") from None

    monkeypatch.setattr(cli, "cmd_list", interrupted_inside_a_lock)
    signum = signal_error.args[0] if signal_error.args else signal.SIGINT
    assert cli.main(["list"]) == 128 + signum
    err = capsys.readouterr().err.strip().splitlines()
    assert err == [f"railpaper: error: interrupted by {signal.Signals(signum).name}; previous "
                   "outputs left untouched"]

    def plain_runtime_error(args):
        raise RuntimeError("a bug")

    monkeypatch.setattr(cli, "cmd_list", plain_runtime_error)
    with pytest.raises(RuntimeError, match="a bug"):
        cli.main(["list"])
