"""The chapter's exact-posterior reference files (toy_record.csv, toy_posterior.json) against
independent routes: the record re-derived by a hand-written Eq. (18) loop from the documented
random draws, and the posterior recomputed from the two files alone by adaptive-Metropolis chains
(railpaper.engine.mcmc, a different algorithm from the chapter's IBIS) on a model built here
from the JSON's numbers, whose likelihood is checked against a plain Kalman loop."""

import json

import numba
import numpy as np
import pandas as pd
import pytest

from railpaper.engine import LinearGaussianBatch, adaptive_metropolis, kalman_log_posterior
from railpaper.experiments.rbpf_parameter_estimation import experiment as chapter
from railpaper.experiments.rbpf_parameter_estimation.result import steps_reported
from railpaper.pipeline.outputs import write_outputs

G = np.array([-1.0, -1.3])          # Eq. (18)'s noise input, as printed


@pytest.fixture(scope="module")
def toy_files(tmp_path_factory):
    """A toy-only chapter run (3 records, the exact posterior on the first 2), written as the
    pipeline writes it."""
    before = numba.get_num_threads()
    numba.set_num_threads(1)
    settings = chapter.SPEC.resolve({"toy_seeds": 3, "toy_ibis_records": 2, "lateral": False},
                                    quick=True)
    result = chapter.run(settings)
    out = tmp_path_factory.mktemp("toy")
    write_outputs(out, chapter.SPEC, settings, True, result)
    numba.set_num_threads(before)
    return settings, result, pd.read_csv(out / "toy_record.csv"), \
        json.loads((out / "toy_posterior.json").read_text())


def test_toy_record_rows_follow_the_documented_convention(toy_files):
    """Row k holds u_k (the input of the transition into step k) and y_k: re-derived by a
    plain loop x_k = F x_(k-1) + B u_k + G w_(k-1), y_k = x_k[0] + e_k from the documented draws
    (generator ``seed``: u, then x_0 (zero covariance), then w, then e)."""
    settings, _, record, doc = toy_files
    K, var = settings.toy_steps, settings.toy_noise_var
    assert list(record.columns) == ["step", "u", "y"]
    np.testing.assert_array_equal(record.step, np.arange(1, K + 1))
    rng = np.random.default_rng(settings.seed)
    u = rng.standard_normal(K)
    rng.standard_normal(2)                                   # x_0 ~ N(0, 0): drawn, unused
    w, e = rng.standard_normal(K) * np.sqrt(var), rng.standard_normal(K) * np.sqrt(var)
    x1, x2, x3, x4 = settings.toy_x1, settings.toy_x2, settings.toy_x3, settings.toy_x4
    F, B, x, y = np.array([[0.0, 1.5], [x1, x2]]), np.array([x3, x4]), np.zeros(2), []
    for k in range(K):
        x = F @ x + B * u[k] + G * w[k]
        y.append(x[0] + e[k])
    np.testing.assert_allclose(record.u, u, rtol=0, atol=1e-15)
    np.testing.assert_allclose(record.y, y, rtol=1e-12, atol=1e-12)
    assert doc["step"] == K and doc["w_var"] == doc["v_var"] == var
    np.testing.assert_array_equal(doc["prior_lower"], -settings.toy_prior_halfwidth * np.ones(4))
    np.testing.assert_array_equal(doc["prior_upper"], settings.toy_prior_halfwidth * np.ones(4))
    np.testing.assert_array_equal(doc["x0"], np.zeros(2))
    np.testing.assert_array_equal(doc["P0"], np.eye(2))


def _system_from(doc):
    """Eq. (18) for a batch of θ, written from the JSON's numbers only."""
    Q, R = doc["w_var"] * np.outer(G, G), np.array([[doc["v_var"]]])

    def system(theta):
        theta = np.atleast_2d(theta)
        F = np.zeros((len(theta), 2, 2))
        F[:, 0, 1], F[:, 1, 0], F[:, 1, 1] = 1.5, theta[:, 0], theta[:, 1]
        return LinearGaussianBatch(F, Q, [[1.0, 0.0]], R, theta[:, 2:4, None].copy())
    return system


def _loglik_by_hand(theta, y, u, doc):
    """log p(y_1..K | θ) by a plain scalar-measurement Kalman loop."""
    F, B = np.array([[0.0, 1.5], [theta[0], theta[1]]]), np.array(theta[2:4])
    Q, r = doc["w_var"] * np.outer(G, G), doc["v_var"]
    m, P, total = np.array(doc["x0"], float), np.array(doc["P0"], float), 0.0
    for yk, uk in zip(y, u):
        m, P = F @ m + B * uk, F @ P @ F.T + Q
        S, v = P[0, 0] + r, yk - m[0]
        total += -0.5 * (np.log(2 * np.pi * S) + v * v / S)
        K = P[:, 0] / S
        m, P = m + K * v, P - np.outer(K, K) * S
    return total


def test_toy_posterior_file_matches_adaptive_metropolis_on_the_record_file(toy_files):
    """The JSON's posterior mean and sd equal 24 adaptive-Metropolis chains run on the CSV's
    record with the JSON's prior box and noise, within the IBIS Monte Carlo error (tolerances
    of tests/engine/test_ibis.py: 0.25 posterior sd for the mean, 12 % for the sd)."""
    _, result, record, doc = toy_files
    y, u = record.y.to_numpy()[:, None], record.u.to_numpy()[:, None]
    lower, upper = np.array(doc["prior_lower"]), np.array(doc["prior_upper"])
    before = numba.get_num_threads()
    numba.set_num_threads(1)
    log_post = kalman_log_posterior(_system_from(doc), y, lower, upper, np.array(doc["x0"]),
                                    np.array(doc["P0"]), u)
    truth = result.toy.truth
    assert log_post(truth[None])[0] == pytest.approx(_loglik_by_hand(truth, y[:, 0], u[:, 0],
                                                                     doc), rel=1e-9)
    rng = np.random.default_rng(5)
    chains = adaptive_metropolis(log_post, rng.uniform(lower, upper, (24, 4)), 2000, 3000, rng)
    numba.set_num_threads(before)
    ref = chains.summary()
    assert np.all(ref["rhat"] < 1.01) and np.all(ref["mcse"] < 0.02 * ref["sd"])
    np.testing.assert_array_less(np.abs(np.array(doc["mean"]) - ref["mean"]), 0.25 * ref["sd"])
    np.testing.assert_array_less(np.abs(np.array(doc["sd"]) / ref["sd"] - 1), 0.12)
    # the file is the run's posterior of the illustrated record after its last step
    np.testing.assert_array_equal(doc["mean"], result.toy.posterior.mean[-1])


def test_toy_coverage_table_and_metrics_count_by_hand(toy_files):
    """Coverage rows: the posterior's 90 % interval from its own quantiles, the RBPF schemes'
    from mean ± 1.645 sd of the illustrated runs; metrics = counts over the table with scipy's
    exact binomial interval."""
    from scipy.stats import binomtest

    settings, result, _, _ = toy_files
    toy, m = result.toy, result.metrics
    cov = toy.coverage
    # the exact posterior (and so coverage and the EKF's offset) on the first toy_ibis_records
    assert sorted(set(cov.seed)) == [settings.seed, settings.seed + 1]
    assert len(cov) == 4 * settings.toy_ibis_records and settings.toy_seeds == 3
    assert m.get("toy_ekf_max_abs_offset_init2_n", 0) <= 2
    first = cov[cov.seed == settings.seed]
    post, run = toy.posterior, toy.illustrated[1]
    for j, row in enumerate(first.itertuples()):
        assert row.posterior_covers == (post.q05[-1, j] <= toy.truth[j] <= post.q95[-1, j])
        half = 1.6448536269514722 * run.rbpf_paper_sd[-1, j]
        assert row.paper_covers == (abs(run.rbpf_paper[-1, j] - toy.truth[j]) <= half)
        half = 1.6448536269514722 * run.rbpf_working_sd[-1, j]
        assert row.tempered_covers == (abs(run.rbpf_working[-1, j] - toy.truth[j]) <= half)
    for column, name in (("posterior_covers", "exact_posterior"),
                         ("paper_covers", "paper_scheme"), ("tempered_covers", "tempered")):
        k, n = int(cov[column].sum()), len(cov)
        ci = binomtest(k, n).proportion_ci(0.95, method="exact")
        key = f"coverage_90_{name}_toy"
        assert (m[key], m[key + "_n"]) == (k / n, n)
        assert m[key + "_low"] == pytest.approx(ci.low, abs=1e-9)
        assert m[key + "_high"] == pytest.approx(ci.high, abs=1e-9)


def test_steps_reported():
    assert steps_reported(500) == [100, 350, 500]
    assert steps_reported(1000) == [100, 350, 1000]
    assert steps_reported(2000) == [100, 350, 1000, 2000]
    assert steps_reported(200) == [100, 200]
