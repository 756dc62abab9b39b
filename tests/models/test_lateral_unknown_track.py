"""The lateral vehicle's filters without the track input: the shaping filter's exact
discretisation against quadrature, the track states' stationary covariance as a fixed point of
their own transition, one step of the augmented model against its equations, and a filter on a
simulated record whose innovations are as white as the known-input filter's."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.integrate import quad_vec
from scipy.linalg import expm

from railpaper.engine import LinearGaussianBatch, whitened_innovations
from railpaper.estimators.kalman_baseline import ShapingFilter
from railpaper.experiments.lateral_vehicle import filter_system, vehicle
from railpaper.experiments.suspension_fault_detection import SPEC, faults, records
from railpaper.experiments.track_shaping import shaping_filter
from railpaper.models import lateral_unknown_track as unknown_track

SHAPING = ShapingFilter(gain=0.5, a=9.4, b=62.4)        # the alignment at 300 km/h, about
DT_S = 0.005


def test_delay_is_the_wheelbase_over_the_speed_in_whole_samples():
    assert unknown_track.delay_steps(2.5, 300 / 3.6, 0.005) == 6       # 2.5 m / 83.3 m/s = 30 ms
    assert unknown_track.delay_steps(2.5, 200 / 3.6, 0.005) == 9       # 45 ms
    assert unknown_track.delay_steps(0.1, 100.0, 0.005) == 1           # never below one sample
    with pytest.raises(ValueError):
        unknown_track.delay_steps(2.5, 0.0, 0.005)


def test_discrete_shaping_against_the_exponential_and_quadrature():
    Af, Bf, _ = SHAPING.state_space()
    Phi, Q = unknown_track.discrete_shaping(Af, Bf, DT_S)
    assert np.allclose(Phi, expm(Af * DT_S), rtol=1e-12, atol=1e-14)
    integral, _ = quad_vec(lambda t: expm(Af * t) @ Bf @ Bf.T @ expm(Af.T * t), 0.0, DT_S,
                           epsabs=1e-16, epsrel=1e-12)
    assert np.allclose(Q, integral, rtol=1e-9, atol=1e-18)


def _track_block(delay):
    """The (s, r) rows and columns of an augmented model around a dummy vehicle."""
    Af, Bf, _ = SHAPING.state_space()
    Phi, Q = unknown_track.discrete_shaping(Af, Bf, DT_S)
    batch = LinearGaussianBatch(np.eye(16)[None], np.eye(16), np.zeros((1, 5, 16)), np.eye(5),
                                np.zeros((1, 16, 2)))
    aug = unknown_track.augment(batch, Phi, Q, delay)
    return Phi, Q, aug.F[0, 16:, 16:], aug.Q[16:, 16:]


def test_track_covariance_is_the_stationary_covariance_of_its_transition():
    for delay in (1, 6, 9):
        Phi, Q, T, Q_track = _track_block(delay)
        P = unknown_track.track_covariance(Phi, Q, delay)
        assert np.allclose(T @ P @ T.T + Q_track, P, rtol=1e-9, atol=1e-14)
        assert np.all(np.linalg.eigvalsh(P) > -1e-14)


def test_one_step_of_the_augmented_model_is_its_equations():
    rng = np.random.default_rng(3)
    F = rng.standard_normal((2, 16, 16))
    G = rng.standard_normal((2, 16, 2))
    H = rng.standard_normal((2, 5, 16))
    Af, Bf, _ = SHAPING.state_space()
    Phi, Q = unknown_track.discrete_shaping(Af, Bf, DT_S)
    delay = 4
    aug = unknown_track.augment(LinearGaussianBatch(F, np.eye(16), H, np.eye(5), G), Phi, Q,
                                delay)
    z = rng.standard_normal(16 + 2 + delay)
    x, s, r = z[:16], z[16:18], z[18:]
    for i in range(2):
        step = aug.F[i] @ z
        assert np.allclose(step[:16], F[i] @ x + G[i, :, 0] * s[1] + G[i, :, 1] * r[-1])
        assert np.allclose(step[16:18], Phi @ s)
        assert np.allclose(step[18:], np.concatenate([[s[1]], r[:-1]]))
        assert np.allclose(aug.H[i] @ z, H[i] @ x)
    assert not aug.B.any() and aug.Q[:16, :16].tolist() == np.eye(16).tolist()


def test_the_filter_without_the_track_is_as_consistent_as_the_one_given_it():
    """A fault-free 300 km/h record of the appendix: the mean normalised innovation squared
    from 1 s on is near the 5 channels for the filter given the track and for the one that
    estimates it (their ratio within 10 %)."""
    settings = SPEC.resolve({}, False)
    fixed, theta = vehicle()
    _, fault_settings = faults.catalogue()
    speed = 300.0
    rec = records.simulate_faulted(settings, fault_settings, fixed, theta, None, 0.0, speed, 300)
    system = filter_system(records.record_settings(settings, speed), fixed, theta, rec.record,
                           theta_ref=theta)
    fit, _, _ = shaping_filter(settings.spectrum, speed / 3.6,
                               (settings.wavelength_min_m, settings.wavelength_max_m),
                               "alignment")
    Phi, Q = unknown_track.discrete_shaping(*fit.state_space()[:2], settings.dt_s)
    delay = unknown_track.delay_steps(2 * fixed["a"], speed / 3.6, settings.dt_s)
    nis = []
    for model, n in ((system, 16), (unknown_track.unknown_track_system(system, Phi, Q, delay),
                                    16 + 2 + delay)):
        one = model(theta[None])
        P0 = np.zeros((n, n))
        P0[:16, :16] = 1e-10 * np.eye(16)
        if n > 16:
            P0[16:, 16:] = unknown_track.track_covariance(Phi, Q, delay)
        z = whitened_innovations(LinearGaussianBatch(one.F[0], one.Q, one.H[0], one.R,
                                                     one.B[0]),
                                 rec.record.y, np.zeros(n), P0, u=rec.record.u_mps).z
        nis.append(float((z[199:] ** 2).sum(axis=1).mean()))
    assert 3.5 < nis[0] < 6.0 and 3.5 < nis[1] < 6.0
    assert abs(nis[1] / nis[0] - 1.0) < 0.1
