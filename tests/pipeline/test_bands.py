"""railpaper bands: batch seeds, widening capped at rule thresholds, the tolerances file."""

import json

import pytest

from railpaper.data import read_toml
from railpaper.pipeline import bands as bands_module
from railpaper.pipeline.bands import band, compute_bands, write_bands
from railpaper.pipeline.check import load_tolerances


def test_band_widens_by_a_quarter_of_the_range():
    low, high, note = band([1.0, 3.0, 2.0], [])
    assert (low, high, note) == (0.5, 3.5, "")


def test_band_stops_halfway_to_a_threshold_on_either_side():
    low, high, note = band([1.0, 3.0], [3.2, 0.9])
    assert high == pytest.approx(3.1) and low == pytest.approx(0.95)
    assert "capped halfway to the threshold 3.2" in note


def test_band_reports_a_straddled_threshold_and_keeps_point_bands():
    assert "straddles the rule threshold 2" in band([1.0, 3.0], [2.0])[2]
    assert band([20, 20, 20], [5.0])[:2] == (20, 20)         # counts stay exact


def test_float_point_bands_get_a_relative_floor_capped_at_thresholds():
    low, high, _ = band([0.7999999999999999] * 3, [])
    assert low < 0.8 - 5e-10 and high > 0.8 + 5e-10
    low, high, note = band([0.7999999999999999] * 3, [0.8])
    assert high < 0.8 and "capped" in note


def test_rounding_level_bands_hold_the_values_another_cpu_gives():
    """Seen on an AMD EPYC against bands written on another CPU: a critical speed that differs in
    the 15th digit and residuals at rounding level (3.3e-13 there, 4.9e-13 here)."""
    low, high, _ = band([456.39365619408477] * 10, [])
    assert low <= 456.3936561940856 <= high and high - low < 1e-6
    low, high, _ = band([3.279198621125877e-13] * 10, [])
    assert low <= 4.947251029202918e-13 <= high and high <= 2e-9
    low, high, note = band([1.1716e-11] * 10, [1e-9])                  # a rule reads 1e-9
    assert high < 1e-9 and "capped" in note


def test_refloor_widens_stored_point_bands_and_never_narrows(tmp_path, monkeypatch):
    data = tmp_path / "ch"
    data.mkdir()
    (data / "tolerances.toml").write_text(
        '[full.speed]\nmin = 456.39365619408477\nmax = 456.39365619408477\nsource = "s"\n'
        '[full.count]\nmin = 3\nmax = 3\nsource = "c"\n'
        '[full.wide]\nmin = 1.0\nmax = 2.0\nsource = "w"\n')
    monkeypatch.setattr(bands_module, "chapter_data_dir", lambda chapter: data)
    monkeypatch.setattr(bands_module, "rule_thresholds", lambda chapter: {})
    out = bands_module.refloor("ch", quick=False)
    assert out["speed"][0] <= 456.3936561940856 <= out["speed"][1]
    assert "rounding on another CPU" in out["speed"][2]
    assert out["count"] == (3, 3, "c") and out["wide"] == (1.0, 2.0, "w")


def test_compute_bands_runs_disjoint_batches_and_resumes(monkeypatch, tmp_path):
    chapter = "reduced-order-observer"
    calls = []

    def fake_run(name, overrides, quick, out, progress, page):
        calls.append(overrides["seed"])
        out.mkdir(parents=True)
        from railpaper.pipeline.chapters import chapter_spec
        settings = chapter_spec(name).resolve(overrides, quick)
        metrics = {"x": float(overrides["seed"]) / 1000, "n": 20}
        (out / "metrics.json").write_text(json.dumps({"parameters": settings.as_dict(),
                                                      "metrics": metrics}))

    monkeypatch.setattr(bands_module, "run_chapter", fake_run)
    out = compute_bands(chapter, True, batches=4, work_dir=tmp_path, metrics=["x", "n"])
    assert calls == [0, 1000, 2000, 3000]
    assert out["x"][:2] == (-0.75, 3.75) and out["n"][:2] == (20, 20)
    assert "4 disjoint seed batches" in out["x"][2]
    compute_bands(chapter, True, batches=4, work_dir=tmp_path, metrics=["x"])
    assert len(calls) == 4                                   # finished batches reused


def test_write_bands_replaces_one_mode_and_loads(tmp_path, monkeypatch):
    chapter = "reduced-order-observer"
    path = tmp_path / "tolerances.toml"
    path.write_text('[meta]\nparameters = "defaults"\n[full.a]\nmin = 1\nsource = "kept"\n'
                    '[quick.old]\nmax = 2\nsource = "replaced"\n')
    write_bands(chapter, True, {"b": (0.5, float("inf"), 'say "why"')}, path)
    doc = read_toml(path)
    assert doc["full"] == {"a": {"min": 1, "source": "kept"}}
    assert doc["quick"] == {"b": {"min": 0.5, "max": float("inf"), "source": 'say "why"'}}
    monkeypatch.setattr("railpaper.pipeline.check.chapter_data_dir", lambda c: tmp_path)
    assert load_tolerances(chapter)["quick"]["b"][:2] == (0.5, float("inf"))
