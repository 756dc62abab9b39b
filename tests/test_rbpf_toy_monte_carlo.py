"""Monte Carlo statistics of paper 003's toy (railpaper.experiments.rbpf_parameter_estimation_mc)
against independent references: scipy's exact binomial test and counts by hand."""

import numpy as np
import pandas as pd
import pytest
from scipy.stats import binomtest

from railpaper.experiments import rbpf_parameter_estimation_mc as toy_mc


@pytest.mark.parametrize("k, n", [(0, 1), (0, 48), (1, 48), (2, 48), (24, 48), (47, 48),
                                  (48, 48), (3, 7)])
def test_binomial_interval_is_clopper_pearson(k, n):
    low, high = toy_mc.binomial_interval(k, n)
    reference = binomtest(k, n).proportion_ci(confidence_level=0.95, method="exact")
    assert low == pytest.approx(reference.low, abs=1e-12)
    assert high == pytest.approx(reference.high, abs=1e-12)
    if k == 0:
        assert high == pytest.approx(1 - 0.025 ** (1 / n), rel=1e-12)   # the README's rule


def test_binomial_interval_refuses_impossible_counts():
    with pytest.raises(ValueError, match="0 <= k <= n"):
        toy_mc.binomial_interval(5, 4)


def _sweep(rng, n_ok=9, n_failed=2):
    rows = []
    for i in range(n_ok + n_failed):
        row = {"seed": i, "status": "ok" if i < n_ok else "error"}
        for ic in (1, 2):
            row[f"toy_ekf_diverged_fraction_init{ic}"] = float(rng.integers(0, 2))
            row[f"toy_ekf_biased_fraction_init{ic}"] = float(rng.integers(0, 2))
            row[f"toy_final_abs_error_max_rbpf_init{ic}"] = rng.lognormal()
            row[f"toy_rbpf_working_error_median_init{ic}"] = rng.lognormal()
        rows.append(row)
    return pd.DataFrame(rows)


def test_rates_and_metrics_count_what_they_say():
    rng = np.random.default_rng(7)
    sweep = _sweep(rng)
    ok = sweep[sweep.status == "ok"]
    toy_stats = pd.DataFrame({"init": [1, 1, 2, 2, 2], "ekf_diverged": [True, False, False, False, True],
                              "ekf_biased": [True, True, False, False, True]})
    rates = toy_mc.ekf_event_rates(ok, toy_stats).set_index(["init", "event", "records"])
    for ic in (1, 2):
        for event in ("diverged", "biased"):
            hand = int(sum(ok[f"toy_ekf_{event}_fraction_init{ic}"] == 1.0))
            main = int(toy_stats[toy_stats.init == ic][f"ekf_{event}"].sum())
            assert rates.loc[(ic, event, "sweep"), "count"] == hand
            assert rates.loc[(ic, event, "sweep"), "n"] == 9
            both = rates.loc[(ic, event, "sweep + main run")]
            assert (both["count"], both["n"]) == (hand + main, 9 + (ic == 1) * 2 + (ic == 2) * 3)
    metrics = toy_mc.monte_carlo_metrics(sweep)
    assert metrics["mc_failed_samples"] == 2
    assert metrics["mc_ekf_divergence_fraction_ic2"] == rates.loc[(2, "diverged", "sweep"),
                                                                  "fraction"]
    errors = np.sort(ok["toy_final_abs_error_max_rbpf_init1"].to_numpy())
    assert metrics["mc_rbpf_final_abs_error_median_ic1"] == pytest.approx(errors[4])  # 9 values
    assert metrics["mc_rbpf_final_abs_error_p90_ic1"] == pytest.approx(
        errors[7] + 0.2 * (errors[8] - errors[7]))                   # linear, position 7.2


def test_sweep_records_follow_the_main_run():
    seeds, sample = toy_mc.sweep_seeds_and_params({"seed": 3, "toy_seeds": 4, "mc_seeds": 5,
                                                   "lateral": True, "n_steps": 10})
    assert list(seeds) == [7, 8, 9, 10, 11]
    assert sample == {"seed": 3, "toy_seeds": 1, "mc_seeds": 5, "lateral": False, "n_steps": 10}


def test_no_finished_sample_is_one_clear_error():
    sweep = _sweep(np.random.default_rng(1), n_ok=0, n_failed=3).assign(error="MemoryError: x")
    with pytest.raises(ValueError, match="no Monte Carlo sample .* ok; first error: MemoryError"):
        toy_mc.monte_carlo_metrics(sweep)
    with pytest.raises(ValueError, match="no Monte Carlo sample"):
        toy_mc.ekf_event_rates(sweep[sweep.status == "ok"], pd.DataFrame(
            {"init": [1], "ekf_diverged": [False], "ekf_biased": [False]}))
