"""Read-only inputs reach the compiled kernels in the same form as writable ones: no second
compilation of a kernel (seconds of a first run) and the same numbers."""

import numpy as np

from railpaper.engine import kalman_bank
from railpaper.engine.kernel_arrays import kernel_array
from railpaper.engine.linear_gaussian import LinearGaussianBatch
from railpaper.estimators import kalman_smoother


def read_only(*arrays):
    out = []
    for a in arrays:
        a = np.array(a, dtype=float)
        a.setflags(write=False)
        out.append(a)
    return out


def test_kernel_array_copies_only_what_is_not_in_form():
    a = np.zeros((3, 2))
    assert kernel_array(a) is a
    view = np.broadcast_to(np.eye(2), (3, 2, 2))
    b = kernel_array(view)
    assert b.flags.writeable and b.flags.c_contiguous and np.array_equal(b, view)
    assert kernel_array(np.arange(4), np.int64).dtype == np.int64


def test_bank_compiles_once_for_read_only_inputs():
    rng = np.random.default_rng(0)
    N, n, p, K = 6, 3, 2, 5
    system = LinearGaussianBatch(F=0.9 * np.eye(n) + 0.01 * rng.standard_normal((N, n, n)),
                                 Q=0.1 * np.eye(n), H=rng.standard_normal((p, n)),
                                 R=np.eye(p), B=rng.standard_normal((n, 1)))
    x, P = rng.standard_normal((N, n)), np.broadcast_to(np.eye(n), (N, n, n)).copy()
    Y, U = rng.standard_normal((K, p)), rng.standard_normal((K, 1))
    F_ro, H_ro = read_only(system.F, system.H)
    frozen_system = LinearGaussianBatch(F=F_ro, Q=system.Q, H=H_ro, R=system.R, B=system.B)
    kernels = (kalman_bank._kf_run, kalman_bank._kf_predict, kalman_bank._kf_update)

    def every_entry(x, P, s, Y, U):
        prior, loglik = kalman_bank.kalman_predict(x, P, s, Y[0], U[0])
        return (*kalman_bank.kalman_run(x, P, s, Y, U, record=True), prior.x, prior.P, loglik,
                *kalman_bank.kalman_update(prior, Y[0], s.H, s.R))
    writable = every_entry(x, P, system, Y, U)
    compiled = [len(k.signatures) for k in kernels]
    frozen = every_entry(*read_only(x, P), frozen_system, *read_only(Y, U))
    assert [len(k.signatures) for k in kernels] == compiled
    for a, b in zip(writable, frozen):
        assert np.array_equal(a, b)


def test_smoother_compiles_once_for_read_only_inputs():
    rng = np.random.default_rng(1)
    G, S, n, p, T = 2, 3, 2, 1, 8
    F = np.stack([[[1.0, 0.01], [0.0, 0.95]]] * G)
    H, Q, R = np.array([[1.0, 0.0]]), 0.01 * np.eye(n), np.array([[0.1]])
    g = kalman_smoother.gains(F, Q, H, R, np.eye(n), T)
    y = rng.standard_normal((T, G, S, p))
    x_post, innovations = kalman_smoother.filter_means(g, F, H, y, np.zeros(n))
    smoothed = kalman_smoother.smoother_means(g, F, H, innovations, x_post)
    kernels = (kalman_smoother._riccati_kernel, kalman_smoother._filter_kernel,
               kalman_smoother._smoother_kernel)
    counts = [len(k.signatures) for k in kernels]
    F_ro, y_ro = read_only(F, y)
    g2 = kalman_smoother.gains(F_ro, *read_only(Q, H, R, np.eye(n)), T)
    x_post2, innovations2 = kalman_smoother.filter_means(g2, F_ro, H, y_ro, np.zeros(n))
    smoothed2 = kalman_smoother.smoother_means(g2, F_ro, H, *read_only(innovations2, x_post2))
    assert counts == [len(k.signatures) for k in kernels]
    assert np.array_equal(g.K, g2.K) and np.array_equal(x_post, x_post2)
    assert np.array_equal(smoothed, smoothed2)
