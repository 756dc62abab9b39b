"""Chapter partial-state-observer: the Monte Carlo evidence its claim rules read, against
independent references (brute-force loops, scipy, the library's single-run simulators)."""

import control
import numpy as np
import pandas as pd
import pytest
from scipy import stats as st
from scipy.integrate import quad

from railpaper import track
from railpaper.data import data_path, load_quantities, values
from railpaper.discretise import foh, simulate_foh
from railpaper.estimators import kalman_baseline as kb
from railpaper.experiments.partial_state_observer import evidence as ev
from railpaper.experiments.partial_state_observer import records
from railpaper.experiments.partial_state_observer.spec import SPEC
from railpaper.models import vertical_10dof
from railpaper.settling import settling_time_s


def brute_settle(t, err, thr):
    """Smallest k with |err[j]| < thr for every j >= k (all columns); -1 if none."""
    for k in range(len(t)):
        if np.all(np.abs(err[k:]) < thr):
            return t[k]
    return -1.0


def test_settle_times_match_brute_force():
    rng = np.random.default_rng(3)
    t = np.arange(60) * 0.1
    err = rng.standard_normal((4, 3, 60, 2)) * np.exp(-t)[:, None]
    err[1, 2, -1, 0] = 9.0                                    # fails at the last sample
    err[2, 0] = 0.0                                           # always below: settles at t = 0
    thr = np.abs(rng.standard_normal((4, 3, 2))) * 0.05 + 0.01
    got = settling_time_s(t, np.all(np.abs(err) < thr[..., None, :], axis=-1), axis=-1)
    for i in range(4):
        for j in range(3):
            assert got[i, j] == brute_settle(t, err[i, j], thr[i, j])
    assert got[1, 2] == -1.0 and got[2, 0] == 0.0


def test_run_measures_by_hand():
    """Two wheelsets would be four; the formulas are per column, so a hand case with known sums."""
    t = np.array([0.0, 0.5, 1.0, 1.5, 2.0])
    z = np.tile(np.array([[1.0], [-1.0], [1.0], [-1.0], [1.0]]), (1, 4)) * [1, 2, 3, 4]
    err = np.zeros((5, 4))
    err[0] = 0.5                                              # initial error, gone from t = 0.5
    err[2:, 0] = [0.1, -0.1, 0.1]                              # wheelset 1 oscillates after 1 s
    m = records.run_measures(t, z, z + err, 0.2, 0.05, 1.0)
    # threshold 5 % of RMS(z_i) = 0.05 i: wheelset 1 never settles (0.1 > 0.05 at the end)
    assert m["convergence_time_s"] == 2.0 and not m["converged"]      # censored at the duration
    assert m["convergence_time_fixed_s"] == 0.5                        # fixed 0.2 > 0.1
    assert m["max_error_after_1s_m"] == pytest.approx(0.1)
    rel = np.array([0.1, 0, 0, 0])                           # mean |err| / RMS(z_i) after 1 s
    assert m["biggest_mean_relative_error"] == pytest.approx(rel.max())
    assert m["mean_relative_error"] == pytest.approx(rel.mean())
    assert m["relative_rms_error"] == pytest.approx(np.mean([0.1, 0, 0, 0]))
    assert m["rms_error_m"] == pytest.approx(np.sqrt(3 * 0.01 / 12))
    # signed: wheelset 1's errors 0.1, -0.1, 0.1 average to 0.1 / 3 (|mean| / RMS 1)
    assert m["biggest_mean_signed_relative_error"] == pytest.approx(0.1 / 3)
    ok = records.run_measures(t, z, z + np.where(t[:, None] < 1, 0.5, 0.0), 0.2, 0.05, 1.0)
    assert ok["converged"] and ok["convergence_time_s"] == 1.0


def _runs_table(rng, seeds=7, speeds=(60.0, 80.0, 120.0, 160.0)):
    rows = []
    for reading in records.READINGS:
        for seed in range(seeds):
            for j, v in enumerate(speeds):
                for est in ("paper", "paper_noisefree", "paper_fixednoise", "hb0"):
                    rows.append({"reading": reading, "seed": 100 + seed, "speed_kmh": v,
                                 "estimator": est, "converged": bool(rng.random() < 0.9),
                                 **{c: float(rng.random() + 0.1 * j) for c in (
                                     "convergence_time_s", "convergence_time_fixed_s",
                                     "max_error_after_1s_m", "relative_rms_error", "rms_error_m",
                                     "biggest_mean_relative_error",
                                     "biggest_mean_signed_relative_error")}})
    return pd.DataFrame(rows).sample(frac=1.0, random_state=1)     # order must not matter


def test_evidence_metrics_against_scipy():
    rng = np.random.default_rng(5)
    mc = _runs_table(rng)
    out = ev.evidence_metrics(mc, "symbols")
    sub = mc[mc.reading == "symbols"]

    def grid(est, col):
        s = sub[sub.estimator == est].sort_values(["seed", "speed_kmh"])
        return s[col].to_numpy().reshape(7, 4)

    conv = grid("paper", "convergence_time_s").mean(axis=1)
    assert out["mc_convergence_time_s_symbols"] == pytest.approx(np.median(conv))
    # order-statistic interval for n = 7 at 95 %: ranks 1 and 7 (P(B(7, 1/2) <= 0) = 0.0078)
    assert out["mc_convergence_time_s_symbols_low"] == pytest.approx(conv.min())
    assert out["mc_convergence_time_s_symbols_n"] == 7
    k = int(grid("paper", "converged").sum())
    ci = st.binomtest(k, 28).proportion_ci(0.95, method="exact")
    assert out["mc_converged_rate_symbols"] == pytest.approx(k / 28)
    assert out["mc_converged_rate_symbols_low"] == pytest.approx(ci.low)
    assert out["mc_converged_rate_symbols_high"] == pytest.approx(ci.high)
    for stem, est, col in (("mc_trend_max_error_rho", "paper", "max_error_after_1s_m"),
                           ("mc_trend_oscillation_fixednoise_rho", "paper_fixednoise", "rms_error_m")):
        rhos = [st.spearmanr([60, 80, 120, 160], row).statistic for row in grid(est, col)]
        assert out[f"{stem}_symbols"] == pytest.approx(np.median(rhos))
        rising = sum(r > 0 for r in rhos)
        assert out[f"{stem}_symbols_rising_fraction"] == pytest.approx(rising / 7)
    top = grid("paper", "biggest_mean_relative_error")[:, -1]
    assert out["mc_biggest_mean_relative_error_symbols"] == pytest.approx(np.median(top))
    signed = grid("paper", "biggest_mean_signed_relative_error")[:, -1]
    assert out["mc_biggest_mean_signed_relative_error_symbols"] == pytest.approx(
        np.median(signed))
    assert "mc_convergence_time_s_labels" not in out


def test_printed_lmi19_cannot_be_negative_definite():
    """Random P > 0 and G: the printed (19) always has a non-negative eigenvalue."""
    rng = np.random.default_rng(2)
    p, n, m2 = 3, 5, 4
    H1, H2 = rng.standard_normal((p, n)), rng.standard_normal((m2, n))
    N1, N2 = rng.standard_normal((p, p)), rng.standard_normal((m2, p))
    for _ in range(50):
        R = rng.standard_normal((p, p))
        P, G = R @ R.T + 0.1 * np.eye(p), rng.standard_normal((p, m2))
        D = P @ N1 + N1.T @ P - G @ N2 - N2.T @ G.T
        M = np.block([[D, P @ H1, G @ H2], [H1.T @ P, np.zeros((n, n)), np.zeros((n, n))],
                      [H2.T @ G.T, np.zeros((n, n)), np.zeros((n, n))]])
        assert np.linalg.eigvalsh(M).max() >= -1e-12
    out = ev.printed_lmi19_blocks(H1, H2)
    assert out["lmi19_printed_feasible"] is False and out["lmi19_printed_zero_block_size"] == 2 * n


def test_readings_of_table1():
    labels, symbols = records.suspension("labels"), records.suspension("symbols")
    assert labels["primary_stiffness_N_per_m"] == 2.14e6 == symbols["secondary_stiffness_N_per_m"]
    assert labels["primary_damping_Ns_per_m"] == 4.9e4 == symbols["secondary_damping_Ns_per_m"]
    assert labels["secondary_stiffness_N_per_m"] == 2.535e6 == symbols["primary_stiffness_N_per_m"]
    assert labels["secondary_damping_Ns_per_m"] == 1.96e5 == symbols["primary_damping_Ns_per_m"]
    default = values(load_quantities(data_path("partial-state-observer/parameters.toml")))
    assert {k: default[k] for k in records.SUSPENSION_KEYS} == labels       # parameters.toml = default
    with pytest.raises(ValueError):
        records.suspension("swapped")


def test_batched_simulators_match_single_runs():
    settings = SPEC.resolve({"duration_s": 0.3, "speeds_kmh": [60.0, 120.0]}, quick=True)
    ctx = records.Context(settings, "symbols")
    t_s, q_in, fixed = records.track_inputs(ctx, settings, [4, 5], [60.0, 120.0], 310.0)
    assert q_in.shape[:2] == (2, 2) and fixed.shape == (2,)
    tr = records.simulate_truths(ctx, settings, q_in, t_s, [4, 5], [60.0, 120.0])
    m = ctx.model
    Phi, G0, G1 = foh(m.A, m.B, settings.dt_s)
    for i in range(2):
        for j in range(2):
            x0 = -np.linalg.solve(m.A, m.B @ q_in[i, j, 0])
            ref = simulate_foh(Phi, G0, G1, q_in[i, j], x0)[ctx.lead:]
            np.testing.assert_allclose(tr["x"][i, j], ref, rtol=1e-9, atol=1e-12 * np.abs(ref).max())
    est = records.run_kalman(ctx, 120.0, tr, 1, settings.initial_error_m)
    one = records.record(tr, 1, 1)
    rms = np.sqrt(np.mean(one["y_clean"] ** 2, axis=0))
    kf = kb.steady_state_kalman(*ctx.kalman_model[120.0], np.diag(np.maximum(one["sigma"], 1e-6 * rms) ** 2))
    q, dq = one["q_m"][0], (one["q_m"][1] - one["q_m"][0]) / t_s[1]
    x0 = np.concatenate([one["x"][0], np.column_stack([q, dq]).ravel()])
    x0[[12, 14, 16, 18]] += settings.initial_error_m
    x0[20::2] += settings.initial_error_m
    np.testing.assert_allclose(est[1], kf.run(one["y"], x0)[:, [12, 14, 16, 18]], rtol=1e-9, atol=1e-15)
    hb0 = records.monte_carlo_runs(ctx, settings, tr, kalman=False)["hb0"]
    np.testing.assert_allclose(hb0[0, 1], ctx.hb0_zoh.run(tr["y"][0, 1], None,
                                                          tr["z_m"][0, 1, 0] + settings.initial_error_m))


@pytest.mark.parametrize("reading", records.READINGS)
def test_hb0_poles_at_primary_corner_in_both_readings(reading):
    settings = SPEC.resolve({}, quick=True)
    ctx = records.Context(settings, reading)
    v = vertical_10dof.load_parameters(**records.suspension(reading))
    np.testing.assert_allclose(ctx.hb0.poles.real,
                               -v.primary_stiffness_N_per_m / v.primary_damping_Ns_per_m, rtol=1e-5)


def test_wheelset_rms_equals_python_control_response_integrated_by_quad():
    """The stationary RMS of wheelsets 1 and 2 (displacement, acceleration, contact deflection)
    from python-control's frequency response with the axle delays, integrated against the track
    PSD by scipy's adaptive quad, against the log-grid trapezoid of evidence.wheelset_rms; and
    the deflection ratio of the two wheelsets of the first bogie, which the claim reads."""
    model = vertical_10dof.build_model(vertical_10dof.load_parameters())
    band, speed = (1.524, 304.8), 80 / 3.6
    system = control.ss(model.A, model.B, model.L, np.zeros((4, 4)))
    offsets = np.asarray(model.parameters.axle_offsets_m)

    def density(omega, wheelset, quantity):
        delays = np.exp(-1j * omega * offsets)
        z = system(1j * omega * speed) @ delays
        value = {"displacement": abs(z[wheelset]) ** 2,
                 "acceleration": abs(z[wheelset]) ** 2 * (omega * speed) ** 4,
                 "deflection": abs(z[wheelset] - delays[wheelset]) ** 2}[quantity]
        return value * track.psd("fra-5", "vertical", omega)

    def integral(wheelset, quantity):      # adaptive quad in log Ω, piece by piece
        edges = np.linspace(np.log(2 * np.pi / band[1]), np.log(2 * np.pi / band[0]), 41)
        return sum(quad(lambda u: density(np.exp(u), wheelset, quantity) * np.exp(u), a, b,
                        limit=200, epsrel=1e-10)[0] for a, b in zip(edges[:-1], edges[1:]))

    ours = dict(zip(("displacement", "acceleration", "deflection"),
                    ev.wheelset_rms(model, "fra-5", band, speed)))
    for quantity, rms in ours.items():
        for wheelset in (0, 1):
            expected = np.sqrt(integral(wheelset, quantity))
            assert rms[wheelset] == pytest.approx(expected, rel=1e-4), (quantity, wheelset)
    ratio = ours["deflection"][1] / ours["deflection"][0]
    expected = np.sqrt(integral(1, "deflection") / integral(0, "deflection"))
    assert ratio == pytest.approx(expected, abs=1e-5)
    assert abs(ratio - 1) > 0.05            # the deflections of one bogie's wheelsets differ
