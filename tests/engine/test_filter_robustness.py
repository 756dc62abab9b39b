"""Filters never emit NaN on degenerate weights or ill-conditioned covariances.

Extreme noise levels (R, Q scaled by 1e-12 and 1e12), an ill-conditioned initial covariance,
a deliberately wrong model (data from a strongly unstable system the filters' prior excludes)
and all-zero likelihoods (every particle's likelihood underflows to 0, or is exactly 0 because
the squared innovation overflows), on the two small toys of :mod:`railpaper.models.linear_toys`:
the RBPF (both schemes), the Q-GRBPF (both readings of Eq. 10), each on both Kalman engines
(compiled bank and numpy), the augmented EKF and the batched Kalman filter.
"""

import numpy as np
import pytest

from railpaper.engine import kalman
from railpaper.engine.qgrbpf import run_qgrbpf
from railpaper.engine.rbpf import initial_bank, run_rbpf
from railpaper.estimators.ekf import eq18_model, run_augmented_ekf
from railpaper.models import linear_toys as toys

TRUTH_EQ18 = np.array([-0.4, 0.5, 0.5, 1.0])
WRONG_EQ18 = np.array([0.6, 0.9, -3.0, 2.0])   # poles 1.43 and -0.53: the record explodes
VAR = 0.1                                       # W and V variance of Eq. (18)
N_STEPS, N_PARTICLES = 30, 60

FILTERS = {
    f"{name}-{engine}": (fn, dict(options, engine=engine))
    for engine in ("compiled", "numpy")
    for name, fn, options in (
        ("rbpf-paper", run_rbpf, {"scheme": "paper"}),
        ("rbpf-working", run_rbpf, {"scheme": "working", "tempering_steps": 10}),
        ("qgrbpf-ratio", run_qgrbpf, {"weighting": "ratio"}),
        ("qgrbpf-printed", run_qgrbpf, {"weighting": "printed"}))
}

# name: (w_var, v_var, P0, true parameters, offset added to every measurement)
SCENARIOS = {
    "R*1e-12": (VAR, VAR * 1e-12, np.eye(2), TRUTH_EQ18, 0.0),
    "R*1e12": (VAR, VAR * 1e12, np.eye(2), TRUTH_EQ18, 0.0),
    "Q*1e-12": (VAR * 1e-12, VAR, np.eye(2), TRUTH_EQ18, 0.0),
    "Q*1e12": (VAR * 1e12, VAR, np.eye(2), TRUTH_EQ18, 0.0),
    "P0 cond 1e24": (VAR, VAR, np.diag([1e12, 1e-12]), TRUTH_EQ18, 0.0),
    "wrong model": (VAR, VAR, np.eye(2), WRONG_EQ18, 0.0),
    "wrong model, R*1e-12": (VAR, VAR * 1e-12, np.eye(2), WRONG_EQ18, 0.0),
    "zero likelihoods (underflow)": (VAR, VAR, np.eye(2), TRUTH_EQ18, 1e6),
}
OVERFLOW = (VAR, VAR, np.eye(2), TRUTH_EQ18, 1e160)

def record(truth, offset, seed=0):
    sim = toys.simulate_eq18(truth, VAR, VAR, N_STEPS, np.random.default_rng(seed))
    return sim.y + offset, sim.u


def prior_cloud(rng):
    return rng.uniform(-2.0, 2.0, (N_PARTICLES, 4))


def assert_finite_run(run):
    for name in ("theta_mean", "theta_std", "x_mean", "x_std", "ess", "theta", "weights"):
        value = getattr(run, name)
        assert np.all(np.isfinite(value)), f"{name} has NaN/inf"
    assert np.all(run.theta_std >= 0) and np.all((run.ess >= 1 - 1e-9) & (run.ess <= N_PARTICLES + 1e-9))
    assert np.isclose(run.weights.sum(), 1.0)


def run_particle_filter(filter_name, scenario):
    w_var, v_var, P0, truth, offset = scenario
    y, u = record(truth, offset)
    fn, options = FILTERS[filter_name]
    rng = np.random.default_rng(1)
    return fn(toys.eq18_system(w_var, v_var), y, prior_cloud(rng), np.zeros(2), P0, rng, u=u,
              **options)


@pytest.mark.parametrize("scenario", SCENARIOS)
@pytest.mark.parametrize("filter_name", FILTERS)
def test_particle_filters_stay_finite(filter_name, scenario):
    with np.errstate(all="ignore"):
        run = run_particle_filter(filter_name, SCENARIOS[scenario])
    assert_finite_run(run)


def test_underflow_scenario_really_has_all_zero_likelihoods():
    """Independent check of the scenario: at step 1 no particle's likelihood is representable."""
    y, u = record(TRUTH_EQ18, 1e6)
    theta, x, P, _, sys = initial_bank(toys.eq18_system(VAR, VAR),
                                       prior_cloud(np.random.default_rng(1)), np.zeros(2),
                                       np.eye(2))
    x_prior, P_prior = kalman.predict(x, P, sys.F, sys.Q, sys.B, u[0])
    _, _, loglik, _, _ = kalman.update(x_prior, P_prior, y[0], sys.H, sys.R)
    assert np.all(np.exp(loglik) == 0.0) and np.all(np.isfinite(loglik))


def test_rbpf_underflow_keeps_the_best_particle():
    """With every likelihood 0 in linear space the log-domain weights still rank the particles:
    the estimate is a weighted mean of the cloud (inside its bounding box), not a NaN."""
    with np.errstate(all="ignore"):
        run = run_particle_filter("rbpf-working-compiled", SCENARIOS["zero likelihoods (underflow)"])
    assert not run.degenerate[0]
    assert np.all(np.abs(run.theta_mean) < 1e3)


@pytest.mark.parametrize("filter_name", FILTERS)
def test_particle_filters_with_overflowing_likelihoods(filter_name):
    with np.errstate(all="ignore"):
        run = run_particle_filter(filter_name, OVERFLOW)
    assert run.degenerate.all()         # the weights do fall back, as documented
    assert_finite_run(run)


@pytest.mark.parametrize("scenario", [*SCENARIOS, "overflow"])
def test_ekf_stays_finite_and_flags_divergence(scenario):
    w_var, v_var, P0, truth, offset = OVERFLOW if scenario == "overflow" else SCENARIOS[scenario]
    y, u = record(truth, offset)
    with np.errstate(all="ignore"):
        run = run_augmented_ekf(eq18_model, y, np.zeros(4), np.zeros(2), P0, np.ones(4),
                                w_var * toys.EQ18_G @ toys.EQ18_G.T, np.array([[v_var]]), 1e-6,
                                u=u)
    for name in ("theta", "theta_std", "x"):
        assert np.all(np.isfinite(getattr(run, name))), name
    if scenario == "overflow":
        assert run.diverged and run.diverged_step == 1


def kf_sequence(P0, R, n_steps=50):
    """A batch of 5 Kalman filters on Eq. (18) with fixed θ, noise-free transition, y = 1."""
    F = np.array([[0.0, 1.5], [-0.4, 0.5]])
    H = np.array([[1.0, 0.0]])
    x, P = np.zeros((5, 2)), np.broadcast_to(P0, (5, 2, 2)).copy()
    for _ in range(n_steps):
        x_prior, P_prior = kalman.predict(x, P, F, np.zeros((2, 2)))
        x, P, loglik, _, _ = kalman.update(x_prior, P_prior, np.array([1.0]), H, R)
    return x, P, loglik


@pytest.mark.parametrize("P0, R", [
    (np.diag([1e12, 1e-12]), np.array([[1e-3]])),
    (np.eye(2), np.array([[1e-15]])),
    (np.eye(2), np.array([[1e12]])),
    (np.zeros((2, 2)), np.array([[1e-300]])),
], ids=["P0 cond 1e24", "R 1e-15", "R 1e12", "P0 = 0, R 1e-300"])
def test_batched_kalman_stays_finite_and_psd(P0, R):
    x, P, loglik = kf_sequence(P0, R)
    assert np.all(np.isfinite(x)) and np.all(np.isfinite(P)) and np.all(np.isfinite(loglik))
    assert np.allclose(P, np.swapaxes(P, -1, -2))
    scale = max(1.0, float(np.max(np.abs(P))))
    assert np.linalg.eigvalsh(P).min() >= -1e-9 * scale


def test_batched_kalman_exactly_singular_innovation():
    x, P, loglik = kf_sequence(np.zeros((2, 2)), np.zeros((1, 1)), n_steps=1)
    assert np.all(np.isfinite(x)) and np.all(np.isfinite(P)) and not np.any(np.isnan(loglik))
