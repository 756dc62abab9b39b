"""The one-pass compiled filters (railpaper.engine.affine_pass) against the step-by-step
filters on the numpy reference engine (predict + Joseph update, numpy weights and moments):
same draws, same estimates to rounding, the generator left in the same state."""

import numpy as np
import pytest

from railpaper.engine import affine_pass
from railpaper.engine.linear_gaussian import AffineSystem, LinearGaussianBatch
from railpaper.engine.qgrbpf import QuasiGaussianRBPF
from railpaper.engine.rbpf import RaoBlackwellisedPF, run_filter
from railpaper.models.linear_toys import (eq18_system, paper004_system, simulate_eq18,
                                          simulate_paper004)

N = 300


@pytest.fixture(scope="module")
def toy004():
    rng = np.random.default_rng(3)
    sim = simulate_paper004(-0.7, 1.5, 1e-3, 1e-3, 0.05, 200, rng)
    theta0 = np.column_stack([rng.uniform(-1, 0.4, N), rng.uniform(1, 2.8, N)])
    return paper004_system(1e-3, 1e-3), sim.y, None, theta0, np.zeros(2), 0.05 ** 2 * np.eye(2)


@pytest.fixture(scope="module")
def toy18():
    rng = np.random.default_rng(4)
    truth = np.array([-0.4, 0.5, 0.5, 1.0])
    sim = simulate_eq18(truth, 0.1, 0.1, 200, rng)
    theta0 = truth + rng.uniform(-0.5, 0.5, (N, 4))
    return eq18_system(0.1, 0.1), sim.y, sim.u, theta0, np.zeros(2), np.eye(2)


FILTERS = {
    "qgrbpf": lambda s, t, x0, P0, g, e: QuasiGaussianRBPF(s, t, x0, P0, g, engine=e),
    "qgrbpf_printed": lambda s, t, x0, P0, g, e: QuasiGaussianRBPF(
        s, t, x0, P0, g, weighting="printed", engine=e),
    "qgrbpf_no_search": lambda s, t, x0, P0, g, e: QuasiGaussianRBPF(
        s, t, x0, P0, g, search=False, weight_threshold=0.0, engine=e),
    "rbpf_paper": lambda s, t, x0, P0, g, e: RaoBlackwellisedPF(
        s, t, x0, P0, g, scheme="paper", delta=0.98, engine=e),
    "rbpf_working": lambda s, t, x0, P0, g, e: RaoBlackwellisedPF(
        s, t, x0, P0, g, scheme="working", delta=0.9, ess_fraction=0.8, tempering_steps=50,
        engine=e),
}


def _both(toy, make):
    system, y, u, theta0, x0, P0 = toy
    out = {}
    for engine in ("compiled", "numpy"):
        rng = np.random.default_rng(11)
        filt = make(system, theta0, x0, P0, rng, engine)
        out[engine] = (run_filter(filt, y, u), rng.random(), filt)
    return out


@pytest.mark.parametrize("name", list(FILTERS))
@pytest.mark.parametrize("toy_name", ["toy004", "toy18"])
def test_one_pass_equals_step_by_step_reference(request, toy_name, name):
    toy = request.getfixturevalue(toy_name)
    out = _both(toy, FILTERS[name])
    (a, next_a, fa), (b, next_b, _) = out["compiled"], out["numpy"]
    assert fa.theta.shape == toy[3].shape
    for field in ("theta_mean", "theta_std", "x_mean", "x_std"):
        np.testing.assert_allclose(getattr(a, field), getattr(b, field), rtol=1e-9,
                                   atol=1e-11, err_msg=field)
    np.testing.assert_allclose(a.ess, b.ess, rtol=1e-9)
    np.testing.assert_allclose(a.log_evidence, b.log_evidence, rtol=1e-9, atol=1e-9)
    np.testing.assert_array_equal(a.resampled, b.resampled)
    if name != "qgrbpf_printed":     # printed: the collapsed P_k's Cholesky fails at rounding
        np.testing.assert_array_equal(a.degenerate, b.degenerate)
    np.testing.assert_allclose(a.theta, b.theta, rtol=1e-9, atol=1e-11)
    np.testing.assert_allclose(a.weights, b.weights, rtol=1e-9, atol=1e-12)
    assert next_a == next_b                           # the generator is left where it was


def test_working_scheme_resamples_and_moves_in_log_space(toy004):
    """The working scheme with a log-space move (a positive parameter) and tempering, against
    the reference: the move's transform is applied and undone as in liu_west_move."""
    system, y, u, theta0, x0, P0 = toy004
    positive = np.abs(theta0) + 0.1
    runs = []
    for engine in ("compiled", "numpy"):
        filt = RaoBlackwellisedPF(system, positive, x0, P0, np.random.default_rng(5),
                                  scheme="working", delta=0.9, ess_fraction=0.8,
                                  tempering_steps=100, log_mask=np.array([False, True]),
                                  engine=engine)
        runs.append(run_filter(filt, y, u))
    assert runs[0].resampled.sum() > 3
    np.testing.assert_allclose(runs[0].theta_mean, runs[1].theta_mean, rtol=1e-9)
    assert np.all(runs[0].theta[:, 1] > 0)


def test_a_second_record_continues_from_the_first(toy004):
    """run_record from a filter that already stepped (tempering counted from its step count,
    a pending resampling's copy applied) equals stepping on."""
    system, y, u, theta0, x0, P0 = toy004
    results = []
    for engine in ("compiled", "numpy"):
        filt = RaoBlackwellisedPF(system, theta0, x0, P0, np.random.default_rng(9),
                                  scheme="working", delta=0.9, ess_fraction=0.8,
                                  tempering_steps=150, engine=engine)
        for k in range(40):                            # step by step first (both engines)
            filt.step(y[k])
        results.append(run_filter(filt, y[40:]))
    np.testing.assert_allclose(results[0].theta_mean, results[1].theta_mean, rtol=1e-9)
    np.testing.assert_allclose(results[0].log_evidence, results[1].log_evidence, rtol=1e-9)


def test_other_models_and_the_numpy_engine_are_stepped():
    """A model that is not an AffineSystem, or the numpy engine, is not run in one pass."""
    def system(theta):
        return LinearGaussianBatch(theta[:, :, None], [[0.1]], [[1.0]], [[0.5]])
    theta0 = np.random.default_rng(0).uniform(0, 1, (50, 1))
    filt = RaoBlackwellisedPF(system, theta0, np.zeros(1), np.eye(1), np.random.default_rng(0))
    assert filt.run_record(np.zeros((3, 1))) is None and filt.k == 0
    affine = AffineSystem(np.zeros((1, 1)), np.ones((1, 1, 1)), [[0.1]], [[1.0]], [[0.5]])
    assert affine_pass.applies(affine, "compiled") and not affine_pass.applies(affine, "numpy")
    assert not affine_pass.applies(system, "compiled")


def test_affine_system_builds_the_toys_matrices_exactly():
    """F(θ) = F0 + Σ θ_j F_j reproduces paper 004's [[0, 1], [a, b]] and Eq. (18)'s
    [[0, 1.5], [x1, x2]], B = (x3, x4)ᵀ bit for bit, also where θ is infinite."""
    theta = np.array([[-0.7, 1.5], [np.inf, -2.0], [0.3, -np.inf]])
    s = paper004_system(1e-3, 1e-3)(theta)
    for i, (a, b) in enumerate(theta):
        np.testing.assert_array_equal(s.F[i], [[0.0, 1.0], [a, b]])
    theta18 = np.array([[-0.4, 0.5, 0.5, 1.0], [1e300, -1e300, np.inf, 3.0]])
    s18 = eq18_system(0.1, 0.1)(theta18)
    for i, (x1, x2, x3, x4) in enumerate(theta18):
        np.testing.assert_array_equal(s18.F[i], [[0.0, 1.5], [x1, x2]])
        np.testing.assert_array_equal(s18.B[i], [[x3], [x4]])
    with pytest.raises(ValueError, match="F_theta"):
        AffineSystem(np.zeros((2, 2)), np.zeros((1, 3, 3)), np.eye(2), np.eye(2), np.eye(2))
