"""Monte Carlo evidence of paper 003's chapter (railpaper.experiments.rbpf_parameter_estimation.evidence)
against independent references: loops written out by hand, scipy's exact binomial test and
scipy's t interval."""

import numpy as np
import pandas as pd
import pytest
from scipy import stats as st

from railpaper.experiments.rbpf_parameter_estimation import evidence as mc
from railpaper.experiments.rbpf_parameter_estimation import lateral as study
from railpaper.settling import holds_from, settling_step
from railpaper.stats import max_abs_bias, rate


def _settle_by_loop(err, tol):
    for k in range(len(err)):                       # first k with every later step inside
        if all(e <= tol for e in err[k:]):
            return k + 1
    return len(err) + 1


@pytest.mark.parametrize("seed", range(6))
def test_settle_step_matches_a_loop(seed):
    rng = np.random.default_rng(seed)
    err = np.abs(rng.normal(0, 1, 40)) * np.linspace(1, 0.1, 40)
    if seed == 0:
        err[-1] = np.nan                            # NaN counts as outside
    for tol in (0.05, 0.3, 1.0, 10.0):
        assert settling_step(err <= tol, never=len(err) + 1) == _settle_by_loop(
            np.where(np.isnan(err), np.inf, err), tol)
    assert settling_step(np.zeros(5) <= 0.1, never=6) == 1
    assert settling_step(np.array([0.0, 0.0, 1.0]) <= 0.1, never=4) == 4     # never: K + 1


def test_within_from_checks_every_step_from_start():
    norm = np.ones((10, 2))
    norm[4, 1] = 1.06                               # step 5 outside
    assert not holds_from(np.abs(norm - 1.0) <= 0.05, 5).all()
    assert holds_from(np.abs(norm - 1.0) <= 0.05, 6).all()
    assert holds_from(np.abs(norm - 1.0) <= 0.07, 5).all()
    norm[9, 0] = np.nan
    assert not holds_from(np.abs(norm - 1.0) <= 0.05, 6).all()
    with pytest.raises(ValueError, match="outside the record"):
        holds_from(np.abs(norm - 1.0) <= 0.05, 11).all()


@pytest.mark.parametrize("k, n", [(0, 20), (3, 20), (19, 20), (20, 20), (2, 6)])
def test_rate_is_clopper_pearson(k, n):
    hits = np.r_[np.ones(k, bool), np.zeros(n - k, bool)]
    est = rate(hits)
    ref = st.binomtest(k, n).proportion_ci(confidence_level=0.95, method="exact")
    assert (est.value, est.n) == (k / n, n)
    assert est.low == pytest.approx(ref.low, abs=1e-12)
    assert est.high == pytest.approx(ref.high, abs=1e-12)


def test_max_abs_bias_is_bonferroni_t_by_hand():
    rng = np.random.default_rng(3)
    x = rng.normal([0.0, 0.08, -0.02], [0.01, 0.02, 0.05], size=(20, 3))
    est = max_abs_bias(x)
    lows, highs = [], []
    for col in x.T:                                 # scipy's t interval at 1 - 0.05/3
        lo, hi = st.t.interval(1 - 0.05 / 3, len(col) - 1, loc=col.mean(), scale=st.sem(col))
        lows.append(lo)
        highs.append(hi)
    lows, highs = np.array(lows), np.array(highs)
    assert est.value == pytest.approx(np.abs(x.mean(axis=0)).max())
    dist = np.where(lows > 0, lows, np.where(highs < 0, -highs, 0.0))
    assert est.low == pytest.approx(dist.max())
    assert est.high == pytest.approx(np.maximum(np.abs(lows), np.abs(highs)).max())
    assert est.n == 20 and est.low <= est.value <= est.high
    assert est.low > 0.05                           # column 1's bias of 8 % is resolved
    with pytest.raises(ValueError, match="n >= 2"):
        max_abs_bias(x[:1])


def test_max_abs_bias_covers_zero_bias_when_there_is_none():
    x = np.random.default_rng(0).normal(0, 0.01, size=(30, 5))
    assert max_abs_bias(x).low == 0.0


def _toy_table():
    rows = []
    ekf_conv = {1: [False, False, True, True, False], 2: [True, True, True, False, True]}
    rbpf_conv = {1: [True, True, False, True, True], 2: [True, False, True, True, True]}
    for ic in (1, 2):
        for i in range(5):
            rows.append(dict(seed=10 + i, init=ic, ekf_converged=ekf_conv[ic][i],
                             ekf_diverged=ic == 1 and i == 0, rbpf_converged=rbpf_conv[ic][i],
                             ekf_err_max=[1.0, 0.5, 0.1, 0.05, 0.3][i],
                             rbpf_err_max=[0.1, 0.1, 0.3, 0.1, 0.1][i],
                             ekf_settle=[501, 501, 40, 30, 501][i],
                             rbpf_settle=[20, 30, 501, 50, 60][i]))
    return pd.DataFrame(rows).sample(frac=1.0, random_state=1)      # order must not matter


def test_toy_metrics_count_by_hand():
    m = mc.toy_metrics(_toy_table())
    assert m["toy_ekf_fail_rate_init1"] == 3 / 5 and m["toy_ekf_fail_rate_init1_n"] == 5
    assert m["toy_ekf_blowup_rate_init1"] == 1 / 5
    assert m["toy_ekf_converge_rate_init2"] == 4 / 5
    assert m["toy_ekf_outcome_differs_rate"] == 4 / 5       # records 0, 1, 3, 4
    assert m["toy_rbpf_converge_rate_init1"] == 4 / 5
    assert m["toy_rbpf_converge_both_rate"] == 3 / 5        # records 0, 3, 4
    gaps = sorted([0.9, 0.4, -0.2, -0.05, 0.2])
    assert m["toy_error_gap_ekf_minus_rbpf_init1"] == pytest.approx(gaps[2])
    assert (m["toy_error_gap_ekf_minus_rbpf_init1_low"],
            m["toy_error_gap_ekf_minus_rbpf_init1_high"]) == pytest.approx((gaps[0], gaps[-1]))
    assert m["toy_settle_gap_ekf_minus_rbpf_init1"] == 441   # median of 481, 471, -461, -20, 441
    ref = st.binomtest(3, 5).proportion_ci(method="exact")
    assert m["toy_ekf_fail_rate_init1_low"] == pytest.approx(ref.low)


def test_toy_metrics_need_both_initial_conditions():
    table = _toy_table()
    with pytest.raises(ValueError, match="both initial conditions"):
        mc.toy_metrics(table[~((table.init == 2) & (table.seed == 12))])


def test_lateral_metrics_by_hand():
    K = 400
    runs = []
    finals = np.array([[1.01, 0.99, 1.0, 1.02, 0.98], [1.03, 1.0, 1.0, 1.06, 1.0],
                       [0.99, 1.0, 1.0, 1.01, 1.0]])
    for f in finals:
        r = np.tile(f, (K, 1))
        r[:349] = 1.5                               # outside 5 % until step 349
        runs.append(r)
    runs[2][360, 4] = 0.9                           # record 2 leaves the band after step 350
    rows = pd.DataFrame([study.scheme_row(seed, r) for seed, r in enumerate(runs)])
    m = study.lateral_metrics(rows, "_x")
    assert m["lateral_within_5pct_from_350_rate_x"] == pytest.approx(1 / 3)   # record 0 only
    assert m["lateral_within_5pct_at_350_rate_x"] == pytest.approx(2 / 3)     # not record 1
    assert m["lateral_within_5pct_from_350_rate_x_n"] == 3
    assert m["lateral_bias_ksy_x"] == pytest.approx(np.mean([0.02, 0.06, 0.01]))
    assert m["lateral_bias_max_abs_x"] == pytest.approx(np.mean([0.02, 0.06, 0.01]))
    assert m["lateral_median_final_abs_error_max_x"] == pytest.approx(0.02)
    lo, hi = st.t.interval(0.95, 2, loc=0.01, scale=st.sem([0.01, 0.03, -0.01]))
    assert (m["lateral_bias_csy_x_low"], m["lateral_bias_csy_x_high"]) == pytest.approx((lo, hi))


def test_evidence_table_rows_are_the_metrics():
    m = {"a": 0.5, "a_low": 0.2, "a_high": 0.8, "a_n": 20, "b": 1.0, "b_low": 0.9,
         "b_high": 1.0, "b_n": 6}
    table = mc.evidence_table(m, {"b": "rate of b", "a": "median a"})
    assert list(table.statistic) == ["rate of b", "median a"]
    assert table.iloc[1][["value", "low", "high", "n"]].tolist() == [0.5, 0.2, 0.8, 20]


def test_toy_records_follow_the_documented_draws_and_definitions():
    """run_toy: record i draws from default_rng(seed + i) the simulation, then per initial
    condition the prior, the paper RBPF, the working RBPF (same particles) and the EKF; each
    row's final errors, flags and settle steps recomputed here from the estimators directly."""
    from railpaper.engine import run_rbpf
    from railpaper.estimators.ekf import eq18_model, run_augmented_ekf
    from railpaper.experiments.rbpf_parameter_estimation import experiment as chapter
    from railpaper.experiments.rbpf_parameter_estimation.toy import run_toy
    from railpaper.models.linear_toys import EQ18_G, eq18_system, simulate_eq18

    settings = chapter.SPEC.resolve({"seed": 5, "toy_seeds": 2, "toy_steps": 60,
                                     "toy_particles": 30, "toy_tempering_steps": 10}, quick=True)
    part = run_toy(settings)
    truth, v = np.array([-0.4, 0.5, 0.5, 1.0]), 0.1
    system = eq18_system(v, v)
    starts = {1: np.zeros(4), 2: np.array([-0.26, 1.0, 0.24, -0.5])}
    for i in range(2):
        rng = np.random.default_rng(5 + i)
        sim = simulate_eq18(truth, v, v, 60, rng)
        for ic, start in starts.items():
            theta0 = rng.uniform(start - 2.0, start + 2.0, (30, 4))
            args = (system, sim.y, theta0, np.zeros(2), np.eye(2), rng)
            paper = run_rbpf(*args, u=sim.u, scheme="paper", delta=0.98)
            working = run_rbpf(*args, u=sim.u, scheme="working", delta=0.9, ess_fraction=0.8,
                               tempering_steps=10)
            ekf = run_augmented_ekf(eq18_model, sim.y, start, np.zeros(2), np.eye(2), 1.0,
                                    v * EQ18_G @ EQ18_G.T, np.array([[v]]), 1e-6, u=sim.u,
                                    divergence_bound=1e3)
            row = part.records[(part.records.seed == 5 + i) & (part.records.init == ic)].iloc[0]
            e_paper = np.abs(paper.theta_mean - truth).max(axis=1)
            e_working = np.abs(working.theta_mean - truth).max(axis=1)
            assert row.rbpf_err_max == e_paper[-1] and row.rbpf_working_err_max == e_working[-1]
            assert row.rbpf_converged == (e_paper[-1] <= 0.2)
            assert row.rbpf_settle == _settle_by_loop(e_paper, 0.2)
            for j in range(4):                  # 90 % interval: final mean +- 1.645 sd
                for key, run in (("rbpf", paper), ("rbpf_working", working)):
                    inside = abs(run.theta_mean[-1, j] - truth[j]) <= 1.6448536269514722 * \
                        run.theta_std[-1, j]
                    assert row[f"{key}_covers_x{j + 1}"] == inside
            assert row.ekf_diverged == ekf.diverged
            if not ekf.diverged:
                e_ekf = np.abs(ekf.theta - truth).max(axis=1)
                assert row.ekf_err_max == e_ekf[-1]
                assert row.ekf_settle == _settle_by_loop(e_ekf, 0.2)
                assert row.ekf_converged == (e_ekf[-1] <= 0.2)
            if i == 0:
                run = part.illustrated[ic]
                np.testing.assert_array_equal(run.rbpf_paper, paper.theta_mean)
                np.testing.assert_array_equal(run.rbpf_working, working.theta_mean)
                np.testing.assert_array_equal(run.ekf, ekf.theta)
    table = part.table()
    assert list(table.columns[:2]) == ["step", "x1_rbpf_init1"] and len(table) == 60
    np.testing.assert_array_equal(table.x3_ekf_init2, part.illustrated[2].ekf[:, 2])


def test_toy_offset_metrics_read_converged_records_against_the_posterior_mean():
    """Largest |median offset from the exact posterior mean| over x1..x4 with Bonferroni
    order-statistic intervals, written out with numpy and scipy's binomial quantiles; records
    where the EKF did not converge (and the other initial condition) are left out for both
    filters."""
    rng = np.random.default_rng(5)
    truth = np.array([-0.4, 0.5, 0.5, 1.0])
    n = 41
    post = truth + rng.normal(0.0, 0.05, (n, 4))
    ekf = post + rng.normal([0.01, -0.05, 0.0, 0.02], 0.05, (n, 4))
    rbpf = post + rng.normal(0.0, 0.05, (n, 4))
    converged = np.ones(n, bool)
    converged[[3, 17]] = False
    ekf[3] = 9.0                                        # a failed run: left out
    rows = [dict(seed=i, init=2, ekf_converged=bool(converged[i]),
                 **{f"ekf_final_error_x{j + 1}": ekf[i, j] - truth[j] for j in range(4)},
                 **{f"rbpf_final_error_x{j + 1}": rbpf[i, j] - truth[j] for j in range(4)})
            for i in range(n)]
    rows += [dict(r, init=1, ekf_converged=False) for r in rows]
    coverage = pd.DataFrame([dict(seed=i, parameter=f"x{j + 1}", posterior_mean=post[i, j])
                             for i in range(n) for j in range(4)])
    m = mc.toy_offset_metrics(pd.DataFrame(rows), coverage, truth)
    for name, est in (("ekf", ekf), ("rbpf", rbpf)):
        d = np.sort(((est - post) / np.abs(truth))[converged], axis=0)
        k = len(d)
        r = 0                                          # largest r: P(B <= r - 1) <= alpha / 2
        while st.binom.cdf(r, k, 0.5) <= 0.05 / 4 / 2:
            r += 1
        low, high = d[max(r, 1) - 1], d[k - max(r, 1)]
        med = np.median(d, axis=0)
        assert m[f"toy_{name}_max_abs_offset_init2"] == pytest.approx(np.abs(med).max())
        assert m[f"toy_{name}_max_abs_offset_init2_low"] == pytest.approx(
            max(0.0, np.max(np.maximum(low, -high))))
        assert m[f"toy_{name}_max_abs_offset_init2_high"] == pytest.approx(
            np.max(np.maximum(np.abs(low), np.abs(high))))
        assert m[f"toy_{name}_max_abs_offset_init2_n"] == n - 2
