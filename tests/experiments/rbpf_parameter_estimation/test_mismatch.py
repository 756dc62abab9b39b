"""Paper 003 under model error (issue 13, part 5): the 40 Hz low-pass, mismatch.toml, the
truth records and the metrics of run_mismatch.

References: scipy.signal's Butterworth design and frequency response, the closed-form gain, the
chapter's own linear-plant records (exact ZOH, independent of the RK4 plant), scipy.stats'
exact binomial interval, and counts by hand.
"""

import numpy as np
import pytest
from scipy import signal, stats

from railpaper import sensors
from railpaper.data import load_quantities
from railpaper.experiments.lateral_vehicle import RecordSettings
from railpaper.experiments.rbpf_parameter_estimation import experiment
from railpaper.experiments.rbpf_parameter_estimation import lateral as study
from railpaper.experiments.rbpf_parameter_estimation import mismatch
from railpaper.paths import DATA_DIR

SMALL = experiment.SPEC.resolve(dict(n_steps=400, truth_substeps=4, n_particles=20,
                                     ekf_guesses=2, ekf_steps=40))
RECORD = RecordSettings.of(SMALL)


@pytest.mark.parametrize("order", [1, 2, 3, 4, 5])
@pytest.mark.parametrize("fc, fs", [(40.0, 1000.0), (40.0, 10000.0), (200.0, 1000.0)])
def test_butterworth_matches_scipy(order, fc, fs):
    sos = sensors.butterworth_lowpass(fc, fs, order)
    f = np.linspace(0.0, 0.499 * fs, 400)
    _, h = signal.sosfreqz(sos, worN=f, fs=fs)
    _, ref = signal.sosfreqz(signal.butter(order, fc, fs=fs, output="sos"), worN=f, fs=fs)
    np.testing.assert_allclose(h, ref, atol=1e-12)                   # magnitude and phase
    gain = 1 / np.sqrt(1 + (np.tan(np.pi * f / fs) / np.tan(np.pi * fc / fs)) ** (2 * order))
    np.testing.assert_allclose(np.abs(h), gain, atol=1e-12)
    np.testing.assert_allclose(sensors.butterworth_gain(f, fc, fs, order), gain, rtol=1e-12)
    _, h_c = signal.sosfreqz(sos, worN=[fc], fs=fs)
    assert abs(h_c[0]) == pytest.approx(2 ** -0.5, rel=1e-12)        # -3 dB at the cut-off


def test_lowpass_causal_and_zero_phase():
    fs, fc = 1000.0, 40.0
    x = np.random.default_rng(0).standard_normal((600, 3))
    b, a = signal.butter(2, fc, fs=fs)
    np.testing.assert_allclose(sensors.lowpass(x, fc, fs, 2), signal.lfilter(b, a, x, axis=0),
                               atol=1e-12)
    np.testing.assert_allclose(sensors.lowpass(x, fc, fs, 2, zero_phase=True),
                               signal.filtfilt(b, a, x, axis=0), atol=1e-9)
    with pytest.raises(ValueError):
        sensors.butterworth_lowpass(600.0, fs, 2)


def test_mismatch_toml_numbers():
    q = load_quantities(DATA_DIR / "rbpf-parameter-estimation" / "mismatch.toml",
                        mismatch.MISMATCH_KEYS)
    veh = load_quantities(DATA_DIR / "rbpf-parameter-estimation" / "parameters.toml")
    mass = veh["mbd"].value + veh["mb"].value + 2 * veh["mw"].value
    assert q["wheel_load"].value == pytest.approx(mass * q["gravity"].value / 4, rel=1e-9)
    assert q["lowpass_cutoff"].value == 40.0
    assert q["lowpass_order"].value == 2
    for key in mismatch.MISMATCH_KEYS:
        assert q[key].source.strip()


def test_linear_truth_record_is_the_chapter_record():
    fixed, theta = study.vehicle()
    st = mismatch.mismatch_settings(components=())
    rec, diag = mismatch.simulate_mismatch(SMALL, fixed, theta, 4, st)
    ref = study.simulate_lateral(RECORD, fixed, theta, 4)
    np.testing.assert_array_equal(rec.u_mps, ref.u_mps)               # same track input
    np.testing.assert_array_equal(rec.du_var_m2ps2, ref.du_var_m2ps2)
    np.testing.assert_array_equal(rec.u_var_m2ps2, ref.u_var_m2ps2)
    # same noise draws, and RK4 vs exact ZOH: differences far below the noise
    assert np.max(np.abs(rec.y - ref.y) / study.noise_std(RECORD)) < 1e-6
    assert max(v for k, v in diag.items() if k.startswith("model_error_")) < 1e-6
    assert diag["saturation_max"] == 0.0 and diag["conicity_ratio"] == 1.0


def test_paper_chain_is_a_butterworth_on_the_acquired_data():
    fixed, theta = study.vehicle()
    ref = study.simulate_lateral(RECORD, fixed, theta, 2)
    sos = signal.butter(2, 40.0, fs=1 / SMALL.dt_s, output="sos")
    rec, _ = mismatch.simulate_mismatch(SMALL, fixed, theta, 2, mismatch.mismatch_settings(
        components=("lowpass",), chain="paper"))
    expected = signal.sosfilt(sos, ref.y, axis=0)
    assert np.max(np.abs(rec.y - expected) / study.noise_std(RECORD)) < 1e-6
    rec, _ = mismatch.simulate_mismatch(SMALL, fixed, theta, 2, mismatch.mismatch_settings(
        components=("lowpass",), chain="paper_zero_phase"))
    expected = signal.sosfiltfilt(sos, ref.y, axis=0)
    assert np.max(np.abs(rec.y - expected) / study.noise_std(RECORD)) < 1e-6


def test_run_mismatch_metrics_from_records():
    res = mismatch.run_mismatch(SMALL, 2, chain="paper")
    m, r = res.metrics, res.records
    assert list(r.plant) == ["mismatch", "matched"] * 2
    for plant in ("mismatch", "matched"):
        rows = r[r.plant == plant]
        for flag, name in (("rbpf_all_within", "lateral_all_within_5pct_fraction"),
                           ("ekf_converged", "lateral_ekf_converge_rate")):
            k, n = int(rows[flag].sum()), len(rows)
            ci = stats.binomtest(k, n).proportion_ci(0.95, method="exact")
            assert m[f"{name}_{plant}"] == k / n and m[f"{name}_{plant}_n"] == n
            assert m[f"{name}_{plant}_low"] == pytest.approx(ci.low, abs=1e-12)
            assert m[f"{name}_{plant}_high"] == pytest.approx(ci.high, abs=1e-12)
        first = res.ekf_first[plant]
        assert len(first) == SMALL.ekf_guesses
        assert m[f"ekf_lateral_converged_count_{plant}"] == sum(
            bool(np.all(np.abs(e[-1] - 1) <= 0.05)) for e in first)
        norm = res.rbpf[plant]
        assert [bool(np.all(np.abs(x[349:] - 1) <= 0.05)) for x in norm] == list(
            rows.rbpf_all_within)
        assert rows.rbpf_final_error_lambda.tolist() == pytest.approx(
            [x[-1, 1] - 1 for x in norm])
    mm, ma = r[r.plant == "mismatch"], r[r.plant == "matched"]
    lost = int((ma.rbpf_all_within.to_numpy() & ~mm.rbpf_all_within.to_numpy()).sum())
    assert m["rbpf_within_lost_mismatch"] == lost
    assert m["mismatch_saturation_max"] == mm.saturation_max.max() > 0
    assert 1 < m["mismatch_conicity_ratio_median"] < 1.5
    assert np.isnan(ma.saturation_max).all()
    again = mismatch.run_mismatch(SMALL, 2, chain="paper", matched=False)
    for key, value in again.metrics.items():                      # same seed -> same numbers
        assert value == m[key] or (np.isnan(value) and np.isnan(m[key])), key
