"""The Q-GRBPF's split Kalman step: predict once, weigh, update the stored prior with the new θ.

``kalman_predict`` (prior + predictive log-likelihood, no covariance update) and
``kalman_update`` (measurement update of a given prior) of :mod:`railpaper.engine.kalman_bank`
against filterpy and the numpy reference, and the compiled Q-GRBPF that uses them against the
numpy engine on a small model whose H (and R) depend on θ.
"""

import numpy as np
import pytest
from filterpy.kalman import KalmanFilter

from railpaper.engine.kalman import innovation, predict
from railpaper.engine.kalman_bank import BankPrior, kalman_predict, kalman_step, kalman_update
from railpaper.engine.linear_gaussian import LinearGaussianBatch
from railpaper.engine.qgrbpf import QuasiGaussianRBPF, run_qgrbpf


def random_spd(rng, n, floor=0.1):
    M = rng.standard_normal((n, n))
    return M @ M.T / n + floor * np.eye(n)


def random_bank(rng, N, n=16, p=5, m=2):
    """N stable filters with their own F, H, B; shared Q, R; priors x, P; y, u."""
    A = rng.standard_normal((N, n, n))
    F = A / (1.05 * np.abs(np.linalg.eigvals(A)).max(axis=1))[:, None, None]
    s = LinearGaussianBatch(F, random_spd(rng, n), rng.standard_normal((N, p, n)),
                            random_spd(rng, p), rng.standard_normal((N, n, m)))
    P = np.stack([random_spd(rng, n) for _ in range(N)])
    return s, rng.standard_normal((N, n)), P, rng.standard_normal(p), rng.standard_normal(m)


@pytest.mark.parametrize("per_filter_R", [False, True])
def test_kalman_update_equals_filterpy_update_of_the_given_prior(per_filter_R):
    rng = np.random.default_rng(21)
    N, n, p = 70, 6, 3
    x_prior = rng.standard_normal((N, n))
    P_prior = np.stack([random_spd(rng, n) for _ in range(N)])
    H = rng.standard_normal((N, p, n))
    R = (np.stack([random_spd(rng, p) for _ in range(N)]) if per_filter_R
         else random_spd(rng, p))
    y = rng.standard_normal(p)
    x_post, P_post, loglik = kalman_update(BankPrior.from_arrays(x_prior, P_prior), y, H, R)
    for i in range(N):
        kf = KalmanFilter(dim_x=n, dim_z=p)
        kf.x, kf.P = x_prior[i].copy(), P_prior[i].copy()
        kf.H, kf.R = H[i], R[i] if per_filter_R else R
        kf.update(y)                                        # Joseph form
        np.testing.assert_allclose(x_post[i], kf.x, rtol=1e-11, atol=1e-12)
        np.testing.assert_allclose(P_post[i], kf.P, rtol=1e-10, atol=1e-12)
        np.testing.assert_allclose(loglik[i], kf.log_likelihood, rtol=1e-11)
    assert np.array_equal(P_post, np.swapaxes(P_post, 1, 2))    # symmetric by construction


def test_kalman_update_keeps_the_prior_where_S_is_not_positive_definite():
    rng = np.random.default_rng(2)
    R = np.stack([np.eye(2), -np.eye(2)])
    x, P = rng.standard_normal((2, 2)), np.stack([random_spd(rng, 2), random_spd(rng, 2)])
    prior = BankPrior.from_arrays(x, P)
    x_post, P_post, loglik = kalman_update(prior, np.ones(2), np.eye(2), R)
    assert np.isfinite(loglik[0]) and np.isneginf(loglik[1])
    assert np.array_equal(x_post[1], x[1]) and np.array_equal(P_post[1], P[1])


@pytest.mark.parametrize("N", [1, 37, 200])
def test_predict_then_update_is_the_fused_kalman_step_bit_for_bit(N):
    """The split is the fused step's arithmetic in two kernels: identical bits (with a
    resampling's ancestors), and the prior and likelihood of the textbook predict."""
    rng = np.random.default_rng(N)
    s, x, P, y, u = random_bank(rng, N)
    ancestors = rng.integers(0, N, N)
    prior, loglik = kalman_predict(x, P, s, y, u, ancestors)
    split = kalman_update(prior, y, s.H, s.R)
    fused = kalman_step(x, P, s, y, u, ancestors)
    for a, b in zip(split, fused):
        assert np.array_equal(a, b)
    assert np.array_equal(loglik, fused[2])
    x_prior, P_prior = prior.x, prior.P                 # out of the blocks and back: same bits
    again = kalman_update(BankPrior.from_arrays(x_prior, P_prior), y, s.H, s.R)
    for a, b in zip(again, fused):
        assert np.array_equal(a, b)
    with pytest.raises(TypeError, match="BankPrior"):
        kalman_update(x_prior, y, s.H, s.R)
    xr, Pr = predict(x[ancestors], P[ancestors], s.F, s.Q, s.B, u)
    np.testing.assert_allclose(x_prior, xr, rtol=1e-12, atol=1e-14)
    np.testing.assert_allclose(P_prior, Pr, rtol=1e-12, atol=1e-14)
    np.testing.assert_allclose(loglik, innovation(xr, Pr, y, s.H, s.R)[0], rtol=1e-11)


@pytest.mark.parametrize("per_filter", [False, True])
def test_predict_with_matrix_rows_continues_whole_filters(per_filter):
    """ancestors = matrix_rows = idx: filter i continues filter idx[i] with its state and its
    matrices (a search's copy made in the gather), bit for bit the predict of the copies."""
    rng = np.random.default_rng(4)
    N = 150
    s, x, P, y, u = random_bank(rng, N, n=5, p=3)
    if per_filter:
        s = LinearGaussianBatch(s.F, np.stack([random_spd(rng, 5) for _ in range(N)]), s.H,
                                np.stack([random_spd(rng, 3) for _ in range(N)]), s.B)
    idx = rng.integers(0, N, N)
    (gathered, ll_gathered), (copied, ll_copied) = (kalman_predict(x, P, s, y, u, idx, idx),
                                                    kalman_predict(x[idx], P[idx], s.take(idx),
                                                                   y, u))
    assert np.array_equal(gathered.x, copied.x) and np.array_equal(gathered.P, copied.P)
    assert np.array_equal(ll_gathered, ll_copied)
    with pytest.raises(ValueError, match="matrix_rows"):
        kalman_predict(x, P, s, y, u, matrix_rows=np.array([N]))


def theta_model(depends: str):
    """``system(θ)``, θ = (a, h): F(θ) = [[a, 0.2], [−0.1, 0.7]]; H(θ) = [[1, h], [0, 1]] when
    H depends on θ (else h = 1); R(θ) = diag(0.05 (1 + h²), 0.1) when R does too.  Not an
    AffineSystem, so the Q-GRBPF runs step by step on both engines."""
    def system(theta):
        N = len(theta)
        F = np.tile(np.array([[0.0, 0.2], [-0.1, 0.7]]), (N, 1, 1))
        F[:, 0, 0] = theta[:, 0]
        H = np.array([[1.0, 1.0], [0.0, 1.0]])
        if depends != "nothing":
            H = np.tile(H, (N, 1, 1))
            H[:, 0, 1] = theta[:, 1]
        R = np.diag([0.05 * 2.0, 0.1])
        if depends == "H and R":
            R = np.tile(R, (N, 1, 1))
            R[:, 0, 0] = 0.05 * (1.0 + theta[:, 1] ** 2)
        return LinearGaussianBatch(F, 0.01 * np.eye(2), H, R, np.array([[0.0], [1.0]]))
    return system


@pytest.mark.parametrize("depends", ["H", "H and R", "nothing"])
@pytest.mark.parametrize("weighting", ["ratio", "printed"])
def test_compiled_qgrbpf_equals_numpy_qgrbpf_when_H_depends_on_theta(depends, weighting):
    """Step (4) updates the old particle's prediction with the new θ's H and R: the compiled
    split (kalman_predict, then kalman_update of the stored prior) against the numpy engine
    (full predict + Joseph update, predicted again for step 4) over a whole run."""
    system = theta_model(depends)
    rng = np.random.default_rng(5)
    K, truth = 60, np.array([[0.6, 0.8]])
    s = system(truth)
    F, B, H, R = (M.reshape(M.shape[-2:]) for M in (s.F, s.B, s.H, s.R))
    x, ys = np.zeros(2), []
    us = rng.standard_normal((K, 1))
    for k in range(K):
        x = F @ x + B @ us[k] + 0.1 * rng.standard_normal(2)
        ys.append(H @ x + np.sqrt(np.diag(R)) * rng.standard_normal(2))
    theta0 = np.random.default_rng(8).uniform([0.2, 0.3], [0.95, 1.5], (300, 2))
    runs = [run_qgrbpf(system, np.array(ys), theta0, np.zeros(2), 0.1 * np.eye(2),
                       np.random.default_rng(3), u=us, weighting=weighting, engine=engine)
            for engine in ("compiled", "numpy")]
    for key in ("theta_mean", "theta_std", "x_mean", "x_std", "log_evidence"):
        np.testing.assert_allclose(getattr(runs[0], key), getattr(runs[1], key), rtol=1e-9,
                                   atol=1e-13, err_msg=key)
    np.testing.assert_allclose(runs[0].theta, runs[1].theta, rtol=1e-9)
    assert np.all(np.isfinite(runs[0].log_evidence))


@pytest.mark.parametrize("search", [False, True])
def test_compiled_qgrbpf_step_keeps_the_prediction_for_the_update(search):
    """One step by hand: the stored state is the measurement update, with the new θ's H and R,
    of the OLD particle's prediction (its F, B), then the search's copy (pending until the
    next step's gather, or materialise)."""
    system = theta_model("H and R")
    rng = np.random.default_rng(8)
    theta0 = rng.uniform([0.2, 0.3], [0.95, 1.5], (50, 2))
    x0, P0 = rng.standard_normal((50, 2)), np.stack([random_spd(rng, 2) for _ in range(50)])
    y, u = np.array([0.5, -0.1]), np.ones(1)
    filt = QuasiGaussianRBPF(system, theta0, x0, P0, np.random.default_rng(3), search=search)
    filt.step(y, u)
    idx = filt.ancestors if search else np.arange(50)
    assert (filt.ancestors is not None) == search
    filt.materialise()
    assert filt.ancestors is None
    old = system(theta0).take(idx)                          # particle i continues idx[i]
    new = system(filt.theta)
    x_prior, P_prior = predict(x0[idx], P0[idx], old.F, old.Q, old.B, u)
    kf_x, kf_P = [], []
    for i in range(50):
        kf = KalmanFilter(dim_x=2, dim_z=2)
        kf.x, kf.P, kf.H, kf.R = x_prior[i], P_prior[i], new.H[i], new.R[i]
        kf.update(y)
        kf_x.append(kf.x)
        kf_P.append(kf.P)
    np.testing.assert_allclose(filt.x, np.array(kf_x), rtol=1e-12, atol=1e-14)
    np.testing.assert_allclose(filt.P, np.array(kf_P), rtol=1e-12, atol=1e-14)


@pytest.mark.parametrize("weighting", ["ratio", "printed"])
def test_qgrbpf_forms_full_matrices_only_for_the_theta_its_search_keeps(weighting):
    """With ``system.measurement`` (H, R alone) the compiled Q-GRBPF updates with those and
    calls ``system`` after the search on the kept θ only, once each (the ZOH of the lateral
    model is the expensive part); the run is bit for bit that of the same model without
    ``measurement``, and each later system call holds at most 1 − (1 − 1/N)^N ≈ 63 % of N θ
    in expectation (checked: fewer than N)."""
    base = theta_model("H and R")
    calls = []

    def system(theta):
        calls.append(len(theta))
        return base(theta)

    def measurement(theta):
        s = base(theta)
        return s.H, s.R

    system.measurement = measurement
    rng = np.random.default_rng(12)
    theta0 = rng.uniform([0.2, 0.3], [0.95, 1.5], (200, 2))
    ys, us = rng.standard_normal((25, 2)), rng.standard_normal((25, 1))
    runs = [run_qgrbpf(model, ys, theta0, np.zeros(2), 0.1 * np.eye(2),
                       np.random.default_rng(5), u=us, weighting=weighting)
            for model in (system, base)]
    for key in ("theta_mean", "theta_std", "x_mean", "x_std", "log_evidence", "theta"):
        assert np.array_equal(getattr(runs[0], key), getattr(runs[1], key)), key
    later = calls[1:]                                          # calls[0]: the initial bank
    assert len(later) == len(ys) and all(len_ < 200 for len_ in later)
    assert 0.55 < np.mean(later) / 200 < 0.72                  # 1 − 1/e ≈ 0.632
