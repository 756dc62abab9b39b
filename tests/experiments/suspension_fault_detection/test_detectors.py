"""The appendix's records and detectors against independent references: the oracle's change
posterior against one textbook Kalman filter per hypothesis run separately (the brute-force
check the appendix's page cites), the faulted record against the fault-free one and against
its own flange clearance, and the evidence's threshold and censored median against their
definitions."""

import numpy as np
import pytest

from railpaper.experiments.base import ParameterError
from railpaper.engine import predict, update
from railpaper.experiments.lateral_vehicle import track_velocity
from railpaper.experiments.suspension_fault_detection import detectors, evidence, faults, records
from railpaper.experiments.suspension_fault_detection import experiment as chapter
from railpaper.experiments.suspension_fault_detection.spec import SPEC
from railpaper.models import lateral_16state

SETTINGS = SPEC.resolve({}, True)


@pytest.fixture(scope="module")
def setup():
    fixed, theta = chapter.vehicle()
    catalogue, fault_settings = faults.catalogue()
    return fixed, theta, catalogue, fault_settings


def _record(setup, fault, speed, seed=2, tau=1.1):
    fixed, theta, catalogue, fault_settings = setup
    rec = records.simulate_faulted(SETTINGS, fault_settings, fixed, theta,
                                   None if fault is None else catalogue[fault], tau, speed, seed)
    system = chapter.filter_system(records.record_settings(SETTINGS, speed), fixed, theta,
                                   rec.record, theta_ref=theta)
    return rec, system


def test_oracle_posterior_equals_one_filter_per_hypothesis(setup):
    """Short record (1.3 s at 200 km/h, C_saly lost at 1.1 s), three fault times and two fault
    values: the bank's cumulative log-likelihood of each hypothesis, and the on-line
    P(fault by k), against textbook filters whose matrices switch at the hypothesis' step."""
    fixed, theta, catalogue, fault_settings = setup
    rec, system = _record(setup, "csaly_0", 200.0)
    K = 260
    short = type(rec.record)(seed=2, y=rec.record.y[:K], u_mps=rec.record.u_mps[:K],
                             du_var_m2ps2=rec.record.du_var_m2ps2,
                             u_var_m2ps2=rec.record.u_var_m2ps2)
    names, values = detectors.oracle_hypotheses([catalogue["csaly_0"], catalogue["ksy_70"]], theta)
    steps = np.array([201, 221, 241])                    # 1.0, 1.1, 1.2 s at 5 ms
    exact = detectors.oracle_change_posterior(system, theta, short, values, steps, 0.5)
    before = system(theta[None])
    after = system(values)

    def run(switch, v):
        n = lateral_16state.N_STATES
        x, P, ll = np.zeros(n), 1e-10 * np.eye(n), np.empty(K)
        for k in range(1, K + 1):
            s, i = (after, v) if switch is not None and k >= switch else (before, 0)
            x, P = predict(x, P, s.F[i], s.Q, s.B[i], short.u_mps[k - 1])
            x, P, ll[k - 1], _, _ = update(x, P, short.y[k - 1], s.H[i], s.R)
        return np.cumsum(ll)

    none = run(None, 0)
    changed = np.array([[run(t, v) for t in steps] for v in range(len(values))])   # (V, J, K)
    log_prior = np.log(0.5 / (len(values) * len(steps)))
    k = np.arange(1, K + 1)
    started = steps[None, :, None] <= k[None, None, :]
    num = np.where(started, log_prior + changed, -np.inf).reshape(-1, K)
    rest = np.where(~started, log_prior + changed, -np.inf).reshape(-1, K)
    log_num = np.logaddexp.reduce(num, axis=0)
    log_den = np.logaddexp(log_num, np.logaddexp(np.log(0.5) + none,
                                                 np.logaddexp.reduce(rest, axis=0)))
    assert np.allclose(exact.p_changed, np.exp(log_num - log_den), rtol=1e-8, atol=1e-10)
    final = log_prior + changed[:, :, -1]
    post = np.exp(final - final.max())
    post /= post.sum()
    assert np.allclose(exact.fault_time_posterior, post.sum(axis=0), atol=1e-9)
    assert np.allclose(exact.value_posterior, post.sum(axis=1), atol=1e-9)
    assert exact.value_posterior[names.index("csaly_0")] > 0.99     # it was C_saly lost
    inner = (exact.p_changed > 1e-12) & (exact.p_changed < 1 - 1e-9)  # its log odds, where
    assert inner.sum() > 10                                          # the probability has digits
    np.testing.assert_allclose(exact.log_odds[inner], np.log(exact.p_changed[inner])
                               - np.log1p(-exact.p_changed[inner]), rtol=1e-9, atol=1e-9)
    assert exact.fault_time_posterior[1] > 0.9                      # at 1.1 s


def test_faulted_record_equals_the_fault_free_one_until_the_fault(setup):
    rec, _ = _record(setup, "csaly_half", 200.0, tau=1.5)
    free, _ = _record(setup, None, 200.0, tau=1.5)
    first = rec.fault_step - 1                          # row of the first post-fault sample
    assert rec.fault_step == int(round(1.5 / SETTINGS.dt_s)) + 1
    assert np.array_equal(rec.record.y[:first], free.record.y[:first])
    assert not np.allclose(rec.record.y[first], free.record.y[first])
    assert np.all(rec.factor[:first] == 1.0) and np.all(rec.factor[first:] == 0.5)


def test_the_measurement_switches_with_the_fault(setup):
    """At the first post-fault sample the accelerations read A(θ after) x: the noise-free
    measurement there equals H(θ after) x, not H(θ before) x (K_sy acts on the bogie's and the
    body's lateral accelerations; C_saly only on the bogie's yaw, which no channel reads)."""
    fixed, theta, catalogue, fault_settings = setup
    rs = records.record_settings(SETTINGS, 200.0)
    clean = SETTINGS.replace(noise_acc_wheelset_mps2=1e-300, noise_acc_bogie_mps2=1e-300,
                             noise_acc_body_mps2=1e-300, noise_yawrate_radps=1e-300)
    rec = records.simulate_faulted(clean, fault_settings, fixed, theta, catalogue["ksy_70"], 1.5,
                                   200.0, 2)
    dq = track_velocity(rs, fixed, 2)
    sub, j = rs.truth_substeps, rec.fault_step - 1
    thetas, starts = faults.schedule(catalogue["ksy_70"], fault_settings, theta, j * sub,
                                     rs.n_steps * sub, rs.dt_s / sub)
    x = lateral_16state.simulate_truth_schedule(fixed, thetas, starts, 200 / 3.6, rs.dt_s / sub,
                                                dq[:-1])
    after, before = (lateral_16state.measurement_matrix(
        lateral_16state.build_A_direct(fixed, th, 200 / 3.6)) for th in (thetas[1], theta))
    assert np.allclose(rec.record.y[j], after @ x[(j + 1) * sub], rtol=1e-12, atol=1e-15)
    assert np.allclose(rec.record.y[j - 1], before @ x[j * sub], rtol=1e-12, atol=1e-15)
    assert not np.allclose(rec.record.y[j], before @ x[(j + 1) * sub])


def test_a_hunting_record_ends_before_flange_contact(setup):
    fixed, theta, catalogue, fault_settings = setup
    rec, _ = _record(setup, "csaly_0", 300.0, tau=1.0)
    stable, _ = _record(setup, "csaly_0", 200.0, tau=1.0)
    assert rec.flange_contact and rec.end_step < SETTINGS.duration_s / SETTINGS.dt_s
    assert not stable.flange_contact and len(stable.record.y) == stable.end_step
    assert len(rec.record.y) == rec.end_step and rec.end_step > rec.fault_step


@pytest.mark.parametrize("overrides, words", [
    ({"extra_fault_parameter": "csaly", "extra_fault_factor": 0}, "must be > 0"),
    ({"extra_fault_parameter": "c_saly"}, "unknown parameter 'c_saly'"),
    ({"faults": "csaly_half,damper"}, "unknown fault 'damper'"),
    ({"fault_time_s": 1.25}, "not on the prior's grid"),
    ({"duration_s": 3.0}, "must be >= 4 s"),
    ({"speeds_kmh": [300.0], "dt_s": 0.05}, "'dt_s'"),
    ({"bank_window_s": 0.001}, "shorter than one sample"),
    ({"ladder_records_per_fault": 2, "ladder_fault_free_records": 4, "speeds_kmh": [200.0]},
     "'ladder_speed_kmh' = 300 km/h is not one of speeds_kmh (200)"),
])
def test_bad_parameters_are_refused_in_one_line(overrides, words):
    """Before any work (the CLI's one line and exit 2 are tests/pipeline/test_hardening.py's)."""
    with pytest.raises(ParameterError) as error:
        chapter.validate(SPEC.resolve(overrides, True))
    assert words in str(error.value) and "\n" not in str(error.value)


def test_threshold_allows_at_most_the_false_alarm_probability():
    rng = np.random.default_rng(5)
    for n, alpha in ((30, 0.05), (8, 0.05), (200, 0.1), (10, 0.5)):
        maxima = rng.standard_normal(n)
        h = evidence.threshold(maxima, alpha)
        assert np.mean(maxima >= h) <= alpha + 1e-12
        below = np.max(maxima[maxima < h])                          # the next lower level
        assert np.mean(maxima >= below) > alpha


def test_censored_median_is_the_order_statistic_median():
    rng = np.random.default_rng(6)
    x = rng.exponential(size=31)
    median = evidence.censored_median(x)
    assert median.median == np.median(x) and median.low <= median.median <= median.high
    y = np.concatenate([x[:20], np.full(11, np.inf)])               # 11 of 31 never alarmed
    assert evidence.censored_median(y).median == np.sort(y)[15]
    never = evidence.censored_median(np.full(5, np.inf))
    assert (never.median, never.low, never.high, never.n) == (None, None, None, 5)


def test_drift_schedule_ends_at_its_factor(setup):
    fixed, theta, catalogue, fault_settings = setup
    fault = catalogue["csaly_drift"]
    thetas, starts = faults.schedule(fault, fault_settings, theta, 1000, 8000, 5e-4)
    j = lateral_16state.PARAM_NAMES.index("csaly")
    values = np.array([t[j] for t in thetas]) / theta[j]
    assert values[0] == 1.0 and values[-1] == fault.factor and np.all(np.diff(values) < 0)
    assert starts[1] == 1000 and starts[-1] == 1000 + int(round(fault_settings["drift_s"] / 5e-4))
    t = np.array([0.5, 1.0, 2.0, 3.0, 4.0])
    assert np.allclose(faults.factor_at(fault, fault_settings, t, 1.0), [1, 1, 0.75, 0.5, 0.5])


def test_windowed_chi2_is_the_sliding_sum_of_squared_innovations():
    import numpy as np

    from railpaper.experiments.suspension_fault_detection.detectors import windowed_chi2

    z = np.arange(12.0).reshape(6, 2)                   # energies 1, 13, 41, 85, 145, 221
    energy = (z ** 2).sum(axis=1)
    brute = [energy[max(0, k - 2):k + 1].sum() for k in range(6)]          # window 3
    assert windowed_chi2(z, 3).tolist() == brute
    healthy = np.random.default_rng(5).standard_normal((20_000, 5))
    s = windowed_chi2(healthy, 50)[49:]
    assert abs(s.mean() - 250.0) < 3.0                   # χ²(W p): mean W p = 250, sd 22


def test_bank_hypotheses_are_every_parameter_times_every_factor(setup):
    """Parameter-major: hypothesis 5 j + i changes parameter j to factor i, nothing else."""
    fixed, theta, catalogue, fault_settings = setup
    factors = faults.bayes_factors()
    bank = detectors.bank_hypotheses(theta, factors)
    assert len(bank.factor) == len(lateral_16state.PARAM_NAMES) * len(factors)
    for v in range(len(bank.factor)):
        j, i = divmod(v, len(factors))
        expected = theta.copy()
        expected[j] *= factors[i]
        assert bank.parameter[v] == j and bank.factor[v] == factors[i]
        np.testing.assert_array_equal(bank.values[v], expected)
    test_values = {f.factor for f in catalogue.values()}
    assert not test_values & set(factors)          # the truth is never one of the hypotheses


@pytest.mark.parametrize("fault, speed, seed", [("csaly_half", 300.0, 0), ("ksy_70", 200.0, 1),
                                                (None, 300.0, 3)])
def test_the_window_against_the_unwindowed_statistic_on_short_records(setup, fault, speed, seed):
    """bayes and glr on the first 260 samples (1.3 s) of a record whose fault starts at 1.0 s
    (step 201), changes from step 150 on, the run's window (W = 20 samples) and hypotheses:
    (1) the bank equals change_likelihoods over every change step followed by
    change_statistics with the window (1e-9 nats); (2) the windowed statistic never exceeds the
    unwindowed one (a sum of fewer non-negative terms), equals it for the first W steps, and
    while the true change lies in the window the two differ by less than 1e-2 nats once the
    unwindowed one has passed 10 nats (the changes the window drops are old, and their ratios
    small beside the true one's); (3) both first reach 10 nats at most 2 samples (10 ms) apart.
    Measured on these records (2026-12-06): in-window differences 8e-4 (C_saly) and 0 (no
    fault) nats; on K_sy at 200 km/h the statistic stays below 10 nats while the true change is
    in the window and the two first reach 10 nats at steps 257 and 259."""
    from railpaper.engine import change_likelihoods, change_statistics
    fixed, theta, catalogue, fault_settings = setup
    rec, system = _record(setup, fault, speed, seed=seed, tau=1.0)
    K, first, W = 260, 150, chapter.window_steps(SETTINGS)
    short = rec.record.first_steps(K)
    bank = detectors.bank_hypotheses(theta, faults.bayes_factors())
    windowed = detectors.change_bank(system, theta, short, bank, W, first)
    lik = change_likelihoods(system, short.y, theta, bank.values, np.arange(first, K + 1),
                             np.zeros(16), detectors.P0_SCALE * np.eye(16), u=short.u_mps)
    same = change_statistics(lik, W)
    full = change_statistics(lik).log_shiryaev_roberts
    rows = slice(first - 1, K)
    np.testing.assert_allclose(windowed.log_shiryaev_roberts[rows],
                               same.log_shiryaev_roberts[rows], rtol=0, atol=1e-9)
    np.testing.assert_allclose(windowed.glr[rows], same.glr[rows], rtol=0, atol=1e-9)
    log_r = windowed.log_shiryaev_roberts
    assert np.all(log_r[rows] <= full[rows] + 1e-9)
    np.testing.assert_allclose(log_r[first - 1:first - 1 + W], full[first - 1:first - 1 + W],
                               rtol=0, atol=1e-9)
    steps = np.arange(1, K + 1)
    inside = (steps >= 201) & (steps < 201 + W) & (full > 10.0)
    if fault is not None and inside.any():
        assert np.max(full[inside] - log_r[inside]) < 1e-2
    if fault is not None:
        assert abs(int(np.argmax(full >= 10.0)) - int(np.argmax(log_r >= 10.0))) <= 2


def test_a_ladder_rung_keeps_its_operating_point_and_tail_check():
    """Of a rung's evidence, the ladder keeps detection within 0.5 s and 2 s, the Kaplan-Meier
    median, the thresholds and the mean times at 100 h, and the tail check, each prefixed with
    the rung; nothing at another operating point, nothing else."""
    metrics = {"detected_within_2s_bayes_csaly_0_300kmh_at_100h": 1.0,
               "detected_within_2s_bayes_csaly_0_300kmh_at_1000h": 0.9,
               "detected_within_1s_bayes_csaly_0_300kmh_at_100h": 1.0,
               "km_delay_median_s_glr_ksy_70_300kmh_at_100h_low": 0.2,
               "threshold_at_100h_cusum_300kmh": 9.3, "threshold_at_10h_cusum_300kmh": 8.0,
               "mtbfa_h_at_100h_cusum_300kmh_high": 5.0, "tail_check_p_cusum_300kmh": 0.06,
               "isolated_bayes_csaly_0_300kmh_at_100h": 1.0}
    kept = chapter._kept(metrics, "ladder_r_")
    assert kept == {"ladder_r_detected_within_2s_bayes_csaly_0_300kmh_at_100h": 1.0,
                    "ladder_r_km_delay_median_s_glr_ksy_70_300kmh_at_100h_low": 0.2,
                    "ladder_r_threshold_at_100h_cusum_300kmh": 9.3,
                    "ladder_r_mtbfa_h_at_100h_cusum_300kmh_high": 5.0,
                    "ladder_r_tail_check_p_cusum_300kmh": 0.06}
