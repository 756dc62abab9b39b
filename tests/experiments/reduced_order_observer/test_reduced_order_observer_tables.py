"""Chapter reduced-order-observer as the page shows it: typed results agree with the metrics,
tables have units, four significant digits, no sentinels and no truncation; figures ≤ 7 in."""

import matplotlib
import numpy as np
import pandas as pd
import pytest

from railpaper.experiments.reduced_order_observer import experiment as chapter
from railpaper.experiments.reduced_order_observer import figures, tables
from railpaper.experiments.reduced_order_observer.spec import SPEC
from railpaper.pipeline.outputs import errata_table

matplotlib.use("Agg")

SMALL = dict(duration_s=0.6, error_window_start_s=0.3, sweep_speeds_kmh=[60.0, 100.0, 160.0],
             mc_seeds=3)


@pytest.fixture(scope="module")
def small():
    settings = SPEC.resolve(SMALL, quick=True)
    return settings, chapter.run(settings)


@pytest.mark.parametrize("value, text", [
    (4.18e9, r"$4.18 \times 10^{9}$"), (4.2e-8, r"$4.2 \times 10^{-8}$"), (0.000123456, "0.0001235"),
    (12345.6, "12350"), (95502.090508, "95500"), (9.999996, "10"), (0.102, "0.102"), (3, "3"),
    (0.0, "0"), (float("nan"), "—"), (-0.5, "-0.5")])
def test_number_four_significant_digits(value, text):
    assert tables.number(value) == text


def test_seconds_says_never():
    assert tables.seconds(-1.0) == "never" and tables.seconds(0.1234) == "0.1234"


def test_markdown_table_escapes_pipes_and_keeps_text_whole():
    long = "a reason " * 30
    text = tables.markdown(pd.DataFrame({"a (s)": ["x|y"], "b": [long]}))
    assert text.splitlines()[0] == "| a (s) | b |"
    assert "x\\|y" in text and long in text


def test_typed_results_are_the_metrics(small):
    settings, result = small
    for speed in settings.speeds_kmh:
        run, lab = result.runs[speed], f"{speed:g}kmh"
        assert run.paper.force_rms_error_N == result.metrics[f"force_rms_error_N_{lab}"]
        assert run.paper.convergence_time_s == result.metrics[f"convergence_time_s_{lab}"]
        assert run.record.speed_kmh == speed and run.record.x_true.shape == (len(run.record.t_s), 4)
        np.testing.assert_array_equal(result.timeseries[f"wheel_rail_force_est_N_{lab}"],
                                      run.paper.force_est_N)
    assert result.speed_sweep.speed_kmh.tolist() == list(settings.sweep_speeds_kmh)
    assert not result.monte_carlo.empty and not result.noise_sweep.empty
    assert np.allclose(np.sort(result.error_poles_per_s.real), np.sort(settings.observer_poles))


def test_tables_render(small):
    settings, result = small
    sweep = result.speed_sweep.copy()
    sweep.loc[0, "convergence_time_s"] = -1.0                      # a run that never converged
    text = tables.speed_sweep_table(sweep, settings.observer_form)
    assert "never" in text and "-1" not in text
    assert text.splitlines()[0] == "| quantity | 60 km/h | 100 km/h | 160 km/h |"
    for text in (tables.evidence_table(result.metrics), tables.rank_table(result.metrics),
                 tables.noise_table(result.noise_sweep), tables.plant_table(result.plant_comparison),
                 tables.parameter_table({"wheel": result.vehicle}),
                 tables.errata_table(errata_table(SPEC.name))):
        assert "…" not in text and "nan" not in text.lower() and "dtype" not in text
    assert "| E1 |" in tables.errata_table(pd.DataFrame({"location": ["x"]}))


def test_figures_fit_the_page(small):
    settings, result = small
    for fig in (figures.displacement(result, settings),
                figures.force(result, settings, result.metrics), figures.trends(result, settings), figures.monte_carlo(result, settings),
                figures.force_error_vs_noise(result, settings),
                figures.force_estimates(result, settings)):
        assert fig.get_figwidth() <= 7.0
        matplotlib.pyplot.close(fig)


def test_closing_numbers_are_the_metrics(small):
    settings, result = small
    m = result.metrics
    words = tables.what_works(result, settings)
    assert words["speed_first"] == "60 km/h" and words["speed_last"] == "100 km/h"
    k = "mc_force_rms_error_ratio_kalman_60kmh"
    assert words["kalman_first"].startswith(tables.percent(m[k]) + " [")
    assert tables.percent(0.000394) == "0.0394 %"
    assert {f"track_{i}" for i in range(3)} <= set(words)
    for name in ("observer", "kalman", "smoother"):
        assert words[f"transient_{name}"].endswith("×")
    text = tables.estimator_table(m, settings)
    assert "Kalman filter" in text and tables.percent(m[k]) in text
