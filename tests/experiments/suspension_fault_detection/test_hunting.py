"""The model-free hunting detector: its band, its RMS over 100 m, its band centre.

References: a sinusoid's RMS (amplitude / √2), scipy's filter run separately with a brute-force
sliding mean, and the model's eigenvalues."""

import numpy as np
import pytest
from scipy.signal import butter, sosfilt

from railpaper.experiments.lateral_vehicle import LateralRecord, vehicle
from railpaper.experiments.suspension_fault_detection import detectors
from railpaper.models import lateral_16state

DT, SPEED = 0.005, 300 / 3.6
BOGIE = lateral_16state.CHANNELS.index("acc_b_mps2")


def _record(bogie_mps2):
    y = np.zeros((len(bogie_mps2), 5))
    y[:, BOGIE] = bogie_mps2
    return LateralRecord(seed=None, y=y, u_mps=None, du_var_m2ps2=np.zeros(2),
                         u_var_m2ps2=np.zeros(2))


def test_a_sinusoid_in_the_band_gives_its_rms_and_one_outside_almost_nothing():
    f0 = 6.0
    t = DT * np.arange(1, 2001)
    centre = np.sqrt((f0 - 2.0) * (f0 + 2.0))          # a Butterworth band-pass's unit gain
    inside = detectors.hunting_rms(_record(2.0 * np.sin(2 * np.pi * centre * t)), DT, SPEED, f0)
    assert inside[-1] == pytest.approx(2.0 / np.sqrt(2.0), rel=1e-2)
    outside = detectors.hunting_rms(_record(2.0 * np.sin(2 * np.pi * 0.6 * t)), DT, SPEED, f0)
    assert outside[-1] < 0.01 * inside[-1]


def test_the_rms_runs_over_the_last_100_m_by_brute_force():
    y = np.random.default_rng(2).standard_normal(600)
    f0 = 6.4
    got = detectors.hunting_rms(_record(y), DT, SPEED, f0)
    filtered = sosfilt(butter(2, (f0 - 2, f0 + 2), btype="bandpass", fs=1 / DT, output="sos"), y)
    window = round(100.0 / (SPEED * DT))                # 240 samples at 300 km/h
    assert window == 240
    brute = [np.sqrt(np.mean(filtered[max(0, k - window + 1):k + 1] ** 2)) for k in range(600)]
    np.testing.assert_allclose(got, brute, rtol=1e-9, atol=1e-12)


def test_the_band_centre_is_the_lost_dampers_hunting_mode():
    fixed, theta = vehicle()
    f0 = detectors.hunting_frequency_hz(fixed, theta, SPEED)
    lost = theta.copy()
    lost[lateral_16state.PARAM_NAMES.index("csaly")] = 0.0
    ev = np.linalg.eigvals(lateral_16state.build_A_direct(fixed, lost, SPEED))
    unstable = ev[ev.real > 1e-6]                       # the lost damper hunts at 300 km/h
    assert len(unstable) == 2                           # one complex pair
    assert f0 == pytest.approx(abs(unstable[0].imag) / (2 * np.pi), rel=1e-12)
    assert 6.0 < f0 < 7.0
