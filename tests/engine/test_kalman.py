"""Batched Kalman primitives against filterpy (per filter) and scipy (log-likelihood)."""

import numpy as np
import pytest
from filterpy.kalman import KalmanFilter
from scipy.stats import multivariate_normal

from railpaper.engine.kalman import gaussian_logpdf, innovation, predict, update
from railpaper.engine.linear_gaussian import LinearGaussianBatch


def random_spd(rng, n, batch=()):
    A = rng.standard_normal(batch + (n, n))
    return A @ np.swapaxes(A, -1, -2) + n * np.eye(n)


@pytest.fixture
def problem():
    rng = np.random.default_rng(1)
    N, n, p, m = 7, 3, 2, 2
    return dict(
        x=rng.standard_normal((N, n)), P=random_spd(rng, n, (N,)) * 0.1,
        F=rng.standard_normal((N, n, n)) * 0.5, Q=random_spd(rng, n, (N,)) * 0.01,
        B=rng.standard_normal((N, n, m)), u=rng.standard_normal(m),
        H=rng.standard_normal((N, p, n)), R=random_spd(rng, p) * 0.05,
        y=rng.standard_normal(p), N=N, n=n, p=p, m=m)


def filterpy_step(d, i):
    kf = KalmanFilter(dim_x=d["n"], dim_z=d["p"], dim_u=d["m"])
    kf.x, kf.P = d["x"][i].copy(), d["P"][i].copy()
    kf.F, kf.Q, kf.B = d["F"][i], d["Q"][i], d["B"][i]
    kf.H, kf.R = d["H"][i], d["R"]
    kf.predict(u=d["u"])
    x_prior, P_prior = kf.x.copy(), kf.P.copy()
    kf.update(d["y"])
    return x_prior, P_prior, kf


def test_batched_predict_update_equal_filterpy_per_particle(problem):
    d = problem
    x_prior, P_prior = predict(d["x"], d["P"], d["F"], d["Q"], d["B"], d["u"])
    x_post, P_post, loglik, v, S = update(x_prior, P_prior, d["y"], d["H"], d["R"])
    for i in range(d["N"]):
        xp, Pp, kf = filterpy_step(d, i)
        np.testing.assert_allclose(x_prior[i], xp, atol=1e-10, rtol=0)
        np.testing.assert_allclose(P_prior[i], Pp, atol=1e-10, rtol=0)
        np.testing.assert_allclose(x_post[i], kf.x, atol=1e-10, rtol=0)
        np.testing.assert_allclose(P_post[i], kf.P, atol=1e-10, rtol=0)
        np.testing.assert_allclose(v[i], kf.y, atol=1e-10, rtol=0)
        np.testing.assert_allclose(S[i], kf.S, atol=1e-10, rtol=0)
        np.testing.assert_allclose(loglik[i], kf.log_likelihood, atol=1e-10, rtol=0)


def test_prior_is_not_modified_and_posterior_symmetric(problem):
    d = problem
    x0, P0 = d["x"].copy(), d["P"].copy()
    x_prior, P_prior = predict(d["x"], d["P"], d["F"], d["Q"])
    keep = P_prior.copy()
    _, P_post, *_ = update(x_prior, P_prior, d["y"], d["H"], d["R"])
    np.testing.assert_array_equal(d["x"], x0)
    np.testing.assert_array_equal(d["P"], P0)
    np.testing.assert_array_equal(P_prior, keep)
    np.testing.assert_array_equal(P_post, np.swapaxes(P_post, -1, -2))


def test_unbatched_equals_batched_row(problem):
    d = problem
    xb, Pb = predict(d["x"], d["P"], d["F"], d["Q"], d["B"], d["u"])
    x1, P1 = predict(d["x"][2], d["P"][2], d["F"][2], d["Q"][2], d["B"][2], d["u"])
    np.testing.assert_allclose(x1, xb[2], atol=1e-14)
    np.testing.assert_allclose(P1, Pb[2], atol=1e-14)
    outb = update(xb, Pb, d["y"], d["H"], d["R"])
    out1 = update(x1, P1, d["y"], d["H"][2], d["R"])
    for a, b in zip(out1, outb):
        np.testing.assert_allclose(a, b[2], atol=1e-12)
    assert np.ndim(out1[2]) == 0


def test_shared_matrices_and_per_filter_measurements(problem):
    d = problem
    Y = np.random.default_rng(3).standard_normal((d["N"], d["p"]))
    x, P, ll, *_ = update(d["x"], d["P"], Y, d["H"][0], d["R"])
    for i in range(d["N"]):
        xi, Pi, lli, *_ = update(d["x"][i], d["P"][i], Y[i], d["H"][0], d["R"])
        np.testing.assert_allclose(x[i], xi, atol=1e-13)
        np.testing.assert_allclose(ll[i], lli, atol=1e-13)


def test_log_likelihood_equals_scipy(problem):
    d = problem
    ll, v, S, _ = innovation(d["x"], d["P"], d["y"], d["H"], d["R"])
    for i in range(d["N"]):
        mean = d["H"][i] @ d["x"][i]
        ref = multivariate_normal(mean=mean, cov=d["H"][i] @ d["P"][i] @ d["H"][i].T + d["R"])
        assert ll[i] == pytest.approx(ref.logpdf(d["y"]), abs=1e-10)
    r = np.random.default_rng(5).standard_normal((4, 3))
    C = random_spd(np.random.default_rng(6), 3, (4,))
    lp, _, _ = gaussian_logpdf(r, C)
    for i in range(4):
        assert lp[i] == pytest.approx(multivariate_normal(np.zeros(3), C[i]).logpdf(r[i]), abs=1e-10)


def test_linear_gaussian_batch_take_keeps_shared():
    F = np.arange(12.0).reshape(3, 2, 2)
    s = LinearGaussianBatch(F, np.eye(2), np.eye(2), np.eye(2))
    t = s.take(np.array([2, 2, 0]))
    np.testing.assert_array_equal(t.F, F[[2, 2, 0]])
    assert t.Q.shape == (2, 2) and t.B is None
