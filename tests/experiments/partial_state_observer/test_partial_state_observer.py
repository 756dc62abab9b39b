"""Chapter partial-state-observer: contract, independent expectations, tolerances, notebook."""

import json
import math

import numpy as np
import pytest

from railpaper.data import read_toml
from railpaper.experiments.base import ParameterError, check_metrics
from railpaper.experiments.partial_state_observer import experiment as ch
from railpaper.experiments.partial_state_observer.spec import SPEC
from railpaper.pipeline.claim_rules import check_row, is_untestable
from railpaper.pipeline.outputs import chapter_data_dir, claims, errata_table

SPEEDS = ("60kmh", "80kmh", "120kmh", "160kmh")


@pytest.fixture(scope="module")
def quick_run():
    settings = SPEC.resolve({}, quick=True)
    return settings, ch.run(settings)


def test_spec_and_validation():
    assert SPEC.name == "partial-state-observer"
    assert SPEC.notebook == "partial_state_observer.ipynb"
    quick = SPEC.resolve({}, quick=True)
    assert quick.speeds_kmh == (60.0, 80.0, 120.0, 160.0) and quick.duration_s >= 2.0
    assert quick.n_seeds >= 5 and SPEC.resolve({}).n_seeds >= 20
    assert SPEC.resolve({}).suspension_reading == "labels"
    for bad in ({"beta": 1.0}, {"error_window_start_s": 9.0}, {"dt_s": 0.01},
                {"wavelength_min_m": 400.0}, {"speeds_kmh": [60.0, 60.0]},
                {"suspension_reading": "swapped"}, {"n_seeds": 1000}):
        with pytest.raises(ParameterError):
            ch.run(SPEC.resolve(bad, quick=True))
    with pytest.raises(ParameterError):
        SPEC.resolve({"alpha": 3.0})


def test_metric_keys_and_timeseries(quick_run):
    settings, result = quick_run
    metrics = check_metrics(result.metrics)
    for lab in SPEEDS:
        for suffix in ("", "_kalman"):
            for key in ("convergence_time_s", "max_error_after_1s_m", "mean_relative_error"):
                assert f"{key}_{lab}{suffix}" in metrics
    for name in ("displacements", "accelerations", "both"):
        assert f"existence_rank_{name}" in metrics and f"existence_ok_{name}" in metrics
    assert metrics["existence_ok_both"] and not metrics["existence_ok_displacements"]
    assert not metrics["existence_ok_accelerations"]
    n = settings.n_seeds
    for reading in ("labels", "symbols"):           # every reading's evidence in every run
        assert metrics[f"mc_convergence_time_s_{reading}_n"] == n
        assert metrics[f"mc_trend_max_error_rho_{reading}_n"] == n
        assert metrics[f"mc_converged_rate_{reading}_n"] == n * len(settings.speeds_kmh)
        assert metrics[f"rank_Q0_pbh_{reading}"] == 20 and metrics[f"rank_L_{reading}"] == 4
        assert metrics[f"rank_C_printed_{reading}"] == 6 and metrics[f"rank_CLt_printed_{reading}"] == 4
    assert metrics["lmi19_printed_feasible"] is False
    ts = result.timeseries
    assert ts.columns[0] == "t_s"
    assert len(ts) == round(settings.duration_s / settings.dt_s) + 1
    for lab in SPEEDS:
        for i in range(1, 5):
            assert f"zw{i}_true_m_{lab}" in ts and f"zw{i}_est_m_{lab}" in ts
    assert np.all(np.isfinite(ts.to_numpy()))


def test_independent_expectations(quick_run):
    """Against theory and baselines, not against earlier output."""
    settings, result = quick_run
    m = result.metrics
    v = result.design.vehicle
    assert m["hb0_fixed_pole_per_s"] == pytest.approx(
        -v.primary_stiffness_N_per_m / v.primary_damping_Ns_per_m, rel=1e-6)
    assert m["hb0_fixed_pole_per_s_labels"] == pytest.approx(-2.14e6 / 4.9e4, rel=1e-6)
    assert m["hb0_fixed_pole_per_s_symbols"] == pytest.approx(-2.535e6 / 1.96e5, rel=1e-6)
    assert m["observer_residual"] < 1e-10 and m["hb0_residual"] < 1e-10
    assert settings.alpha_per_s <= m["observer_slowest_rate_per_s"] * (1 + 1e-5)
    assert m["observer_fastest_rate_per_s"] <= settings.beta * settings.alpha_per_s * (1 + 1e-5)
    for lab in SPEEDS:
        # ẑ = q is off by the contact deflection only: dynamic force / k_H, micrometres
        assert m[f"max_error_after_1s_m_{lab}_q"] < 50e-6
        # the FOH-discretised observer is exact up to the interpolation of y: ~ micrometres
        assert m[f"max_error_after_1s_m_{lab}_noisefree_foh"] < 5e-6
        assert m[f"max_error_after_1s_m_{lab}_noisefree_foh"] < m[f"max_error_after_1s_m_{lab}_noisefree"]
        # the Kalman filter (optimal for its model) beats the noise-blind observer
        assert m[f"max_error_after_1s_m_{lab}_kalman"] < m[f"max_error_after_1s_m_{lab}"]
    # noise-free convergence follows the error dynamics alone: t = ln(e0/threshold)/rate
    sweep = result.alpha_sweep
    clean = sweep[~sweep.noisy]
    assert np.all(np.abs(clean.convergence_time_s - clean.predicted_s) < 0.2 * clean.predicted_s + 0.003)
    mc = result.monte_carlo
    paper = mc[mc.estimator == "paper"]
    assert np.all(np.abs(paper.convergence_time_s - paper.predicted_convergence_s) < 0.015)
    # the H B = 0 variant's error decays at −K_p/C_p: t = ln(e0 / threshold) / rate, per reading
    for reading in ("labels", "symbols"):
        hb0 = mc[(mc.estimator == "hb0") & (mc.reading == reading)]
        gap = np.abs(hb0.convergence_time_s - hb0.predicted_convergence_s)
        assert np.all(gap < 0.2 * hb0.predicted_convergence_s + 0.005)
    # the single record is one run of the Monte Carlo: same numbers
    own = mc[(mc.reading == "labels") & (mc.seed == settings.seed) & (mc.estimator == "paper")]
    for speed, lab in zip(settings.speeds_kmh, SPEEDS):
        row = own[own.speed_kmh == speed].iloc[0]
        assert row.max_error_after_1s_m == pytest.approx(m[f"max_error_after_1s_m_{lab}"], rel=1e-12)


def test_deterministic():
    settings = SPEC.resolve({"speeds_kmh": [80.0], "n_seeds": 2, "alpha_sweep_per_s": [20.0]},
                            quick=True)
    a, b = ch.run(settings), ch.run(settings)
    assert json.dumps(a.metrics, sort_keys=True) == json.dumps(b.metrics, sort_keys=True)
    assert a.timeseries.equals(b.timeseries)


def test_data_files():
    errata = errata_table("partial-state-observer")
    assert list(errata.columns) == ["location", "printed", "correction", "reason"]
    assert len(errata) >= 10
    rows = claims("partial-state-observer")
    for key, table in rows.items():
        check_row(key, table, "claims.toml")
        assert "paper 000" in table["source"] and (table.get("rule") or is_untestable(table))
    groups = {}
    for key, table in rows.items():                  # readings: default first, parameter named
        groups.setdefault(table.get("group", key), []).append(table)
    for group in groups.values():
        if len(group) > 1 and "reading_parameter" in group[0]:
            assert "'labels'" in group[0]["reading_parameter"]
    tol = read_toml(chapter_data_dir("partial-state-observer") / "tolerances.toml")
    assert tol["meta"]["parameters"] == "defaults"
    for mode in ("full", "quick"):
        for band in tol[mode].values():
            assert band["min"] <= band["max"] and band["source"]


def _within_tolerances(metrics: dict, mode: str) -> list[str]:
    tol = read_toml(chapter_data_dir("partial-state-observer") / "tolerances.toml")[mode]
    return [f"{k}={metrics[k]!r} not in [{b['min']}, {b['max']}]" for k, b in tol.items()
            if not b["min"] <= metrics[k] <= b["max"]]


def test_quick_metrics_within_tolerances(quick_run):
    assert _within_tolerances(quick_run[1].metrics, "quick") == []


@pytest.mark.slow
def test_notebook_quick_through_papermill(quick_chapter_dir):
    """The quick book's papermill run of the notebook (tests/conftest.py)."""
    out = quick_chapter_dir("partial-state-observer")
    run = json.loads((out / "metrics.json").read_text())
    assert run["chapter"] == "partial-state-observer" and run["quick"] is True
    assert all(not (isinstance(v, float) and math.isnan(v)) for v in run["metrics"].values())
    assert _within_tolerances(run["metrics"], "quick") == []
    for name in ("wheelset_displacement", "convergence", "max_error_vs_speed", "speed_trends",
                 "convergence_vs_alpha", "shaping_filter_fit", "noise_free_error"):
        assert (out / f"{name}.png").stat().st_size > 10_000
