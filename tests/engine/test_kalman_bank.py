"""The compiled Kalman bank and batched expm against the textbook references.

References: :func:`railpaper.engine.kalman.predict` + Joseph-form ``update`` (numpy,
per-filter Cholesky) and :func:`scipy.linalg.expm`.
"""

import dataclasses
import numpy as np
import pytest
from scipy.linalg import expm

from railpaper.discretise import zoh
from railpaper.engine.batch_expm import expm_stack, zoh_stack
from railpaper.engine.kalman import predict, update
from railpaper.engine import kalman_bank
from railpaper.engine.kalman_bank import (block_size, kalman_run, kalman_step,
                                          measurement_pattern)
from railpaper.engine.linear_gaussian import LinearGaussianBatch
from railpaper.engine.rbpf import RaoBlackwellisedPF, run_rbpf
from railpaper.models import lateral_16state


def random_stable(rng, n, scale=1.0):
    """A random matrix with spectral radius < 1 (a stable discrete transition)."""
    A = rng.standard_normal((n, n))
    return scale * A / (1.05 * np.max(np.abs(np.linalg.eigvals(A))))


def random_spd(rng, n, floor=0.1):
    M = rng.standard_normal((n, n))
    return M @ M.T / n + floor * np.eye(n)


def reference_step(x, P, s, y, u):
    x_prior, P_prior = predict(x, P, s.F, s.Q, s.B, u)
    x_post, P_post, loglik, _, _ = update(x_prior, P_prior, y, s.H, s.R)
    return x_post, P_post, loglik


def rel(a, b):
    return np.max(np.abs(a - b)) / np.max(np.abs(b))


@pytest.mark.parametrize("n,p,m,N,shared", [(4, 1, 1, 1, False), (6, 2, 0, 37, True),
                                            (16, 5, 2, 130, False), (3, 3, 1, 64, True)])
def test_kalman_step_matches_textbook_filter_on_random_systems(n, p, m, N, shared):
    rng = np.random.default_rng(n * 100 + N)
    F = np.stack([random_stable(rng, n) for _ in range(N)])
    H = rng.standard_normal((N, p, n))
    Q = random_spd(rng, n) if shared else np.stack([random_spd(rng, n) for _ in range(N)])
    R = random_spd(rng, p)
    B = rng.standard_normal((N, n, m)) if m else None
    u = rng.standard_normal(m) if m else None
    s = LinearGaussianBatch(F, Q, H, R, B)
    x = rng.standard_normal((N, n))
    P = np.stack([random_spd(rng, n) for _ in range(N)])
    y = rng.standard_normal(p)
    for _ in range(5):                              # five consecutive steps
        xf, Pf, llf = kalman_step(x, P, s, y, u)
        xr, Pr, llr = reference_step(x, P, s, y, u)
        assert rel(xf, xr) < 1e-11 and rel(Pf, Pr) < 1e-11
        np.testing.assert_allclose(llf, llr, rtol=1e-11, atol=1e-11)
        assert np.array_equal(Pf, np.swapaxes(Pf, 1, 2))   # symmetric by construction
        x, P = xr, Pr
        y = y + rng.standard_normal(p)


def test_both_engines_skip_the_update_and_give_minus_inf_where_S_is_not_positive_definite():
    """Filter 0 is ordinary, filter 1 has R = −I, filter 2 has P⁻ = 0 and R = 0 (S singular)."""
    rng = np.random.default_rng(2)
    R = np.stack([np.eye(2), -np.eye(2), np.zeros((2, 2))])
    P = np.stack([random_spd(rng, 2), random_spd(rng, 2), np.zeros((2, 2))])
    s = LinearGaussianBatch(np.eye(2), np.zeros((2, 2)), np.eye(2), R)
    x, y = rng.standard_normal((3, 2)), np.ones(2)
    for x_post, P_post, loglik in (kalman_step(x, P, s, y), reference_step(x, P, s, y, None)):
        assert np.all(np.isneginf(loglik[1:])) and np.isfinite(loglik[0])
        np.testing.assert_array_equal(x_post[1:], x[1:])        # prior kept: F = I, Q = 0
        np.testing.assert_array_equal(P_post[1:], P[1:])
        ref = reference_step(x[:1], P[:1], LinearGaussianBatch(np.eye(2), np.zeros((2, 2)),
                                                               np.eye(2), np.eye(2)), y, None)
        np.testing.assert_allclose(x_post[0], ref[0][0], rtol=1e-12)


@pytest.fixture(scope="module")
def lateral():
    from railpaper.experiments.rbpf_parameter_estimation.lateral import vehicle
    fixed, theta = vehicle()
    return fixed, theta, 300 / 3.6, 1e-3


def test_expm_stack_matches_scipy_on_the_lateral_model_and_random_matrices(lateral):
    fixed, theta, v, dt = lateral
    rng = np.random.default_rng(3)
    A0, Ak = lateral_16state.affine_terms(fixed, v)
    A = lateral_16state.a_of_theta(A0, Ak, theta * rng.uniform(0.5, 1.7, (70, 5)))
    F, G = zoh_stack(A, lateral_16state.input_matrix(), dt)
    Fr, Gr = zoh(A, lateral_16state.input_matrix(), dt)          # scipy expm, stacked
    assert rel(F, Fr) < 1e-12 and rel(G, Gr) < 1e-12
    for norm in (0.01, 1.0, 30.0):                  # no squaring ... several squarings
        M = rng.standard_normal((9, 7, 7))
        M *= norm / np.abs(M).sum(axis=1).max(axis=-1)[:, None, None]
        E = expm_stack(M)
        for i in range(9):
            assert rel(E[i], expm(M[i])) < 1e-10
    A1 = A[0]
    F1, G1 = zoh(A1, lateral_16state.input_matrix(), dt)          # the library's scalar ZOH (scipy)
    F2, G2 = zoh_stack(A1[None], lateral_16state.input_matrix(), dt)
    assert rel(F2[0], F1) < 1e-12 and rel(G2[0], G1) < 1e-12


def test_expm_stack_rejects_nan():
    with pytest.raises(ValueError, match="NaN"):
        expm_stack(np.full((2, 3, 3), np.nan))


@pytest.fixture(scope="module")
def lateral_record(lateral):
    """``make(scheme) -> (system, ys, u, theta0, options)``: 120 steps of a lateral record."""
    fixed, theta, v, dt = lateral
    rng = np.random.default_rng(5)
    A = lateral_16state.build_A_direct(fixed, theta, v)
    K = 120
    u = 1e-3 * rng.standard_normal((K, 2))
    Fd, Gd = zoh(A, lateral_16state.input_matrix(), dt)
    H = lateral_16state.measurement_matrix(A)
    Q = Gd @ Gd.T * 1e-6 + 1e-14 * np.eye(16)
    R = np.diag([0.1, 0.1, 0.1, 0.01, 0.001]) ** 2
    x, ys = np.zeros(16), []
    for k in range(K):
        x = Fd @ x + Gd @ u[k]
        ys.append(H @ x + np.sqrt(np.diag(R)) * rng.standard_normal(5))
    system = lateral_16state.lateral_system(fixed, v, dt, Q, R)
    theta0 = theta * np.random.default_rng(1).uniform(0.5, 1.7, (48, 5))

    def make(scheme):
        opts = dict(scheme=scheme, delta=0.9 if scheme == "working" else 0.98)
        if scheme == "working":
            opts.update(ess_fraction=0.8, tempering_steps=30, log_mask=np.ones(5, bool))
        return system, np.array(ys), u, theta0, opts
    return make


@pytest.mark.parametrize("scheme", ["working", "paper"])
def test_compiled_rbpf_equals_numpy_rbpf_on_the_lateral_model(lateral_record, scheme):
    """Same seed, same data: the compiled engine follows the textbook one particle by particle."""
    system, ys, u, theta0, opts = lateral_record(scheme)
    runs = [run_rbpf(system, ys, theta0, np.zeros(16), 1e-10 * np.eye(16),
                     np.random.default_rng(7), u=u, engine=engine, **opts)
            for engine in ("compiled", "numpy")]
    assert np.array_equal(runs[0].resampled, runs[1].resampled)
    np.testing.assert_allclose(runs[0].theta_mean, runs[1].theta_mean, rtol=1e-9)
    np.testing.assert_allclose(runs[0].x_mean, runs[1].x_mean, rtol=1e-6, atol=1e-12)


def test_kalman_run_over_steps_is_bit_identical_to_kalman_step_step_by_step():
    rng = np.random.default_rng(9)
    N, n, p, m = 70, 6, 3, 2
    s = LinearGaussianBatch(np.stack([random_stable(rng, n) for _ in range(N)]), random_spd(rng, n),
                            rng.standard_normal((N, p, n)), random_spd(rng, p),
                            rng.standard_normal((N, n, m)))
    x, P = rng.standard_normal((N, n)), np.stack([random_spd(rng, n) for _ in range(N)])
    Y, U = rng.standard_normal((7, p)), rng.standard_normal((7, m))
    x_end, P_end, loglik, x_hist, var_hist = kalman_run(x, P, s, Y, U, record=True)
    for k in range(7):
        x, P, ll = kalman_step(x, P, s, Y[k], U[k])
        assert np.array_equal(ll, loglik[:, k]) and np.array_equal(x, x_hist[:, k])
        assert np.array_equal(np.diagonal(P, axis1=1, axis2=2), var_hist[:, k])
    assert np.array_equal(x, x_end) and np.array_equal(P, P_end)


def sparse_measurement_system(rng, N, n, p, m):
    """Random filters whose H (N, p, n) has structural zeros: each row keeps its own random
    half of the columns (as the lateral model's acceleration rows keep 21 of 80 entries), and
    one filter's kept entry is an exact zero the others do not share."""
    keep = rng.random((p, n)) < 0.5
    keep[:, 0] = True
    H = rng.standard_normal((N, p, n)) * keep
    H[3, 0, 0] = 0.0
    return LinearGaussianBatch(np.stack([random_stable(rng, n) for _ in range(N)]),
                               random_spd(rng, n), H, random_spd(rng, p),
                               rng.standard_normal((N, n, m))), keep


def test_measurement_pattern_lists_each_rows_structural_nonzeros_in_order():
    rng = np.random.default_rng(4)
    s, keep = sparse_measurement_system(rng, 9, 7, 3, 1)
    H = s.H.copy()
    H[5, 2, 6] = np.nan                     # a NaN entry stays in the products
    keep[2, 6] = True
    hcols, hcount = measurement_pattern(H)
    for r in range(3):
        assert list(hcols[r, :hcount[r]]) == list(np.flatnonzero(keep[r]))


def test_sparse_measurement_products_equal_the_dense_ones_bit_for_bit_and_the_textbook():
    """The kernels run H P⁻, S and v over H's structural nonzeros only: the bits equal the same
    kernel told every column is used (the dense products), and the filter equals the Joseph
    form on random systems with sparse H."""
    rng = np.random.default_rng(21)
    N, n, p, m = 70, 16, 5, 2
    s, _ = sparse_measurement_system(rng, N, n, p, m)
    x, P = rng.standard_normal((N, n)), np.stack([random_spd(rng, n) for _ in range(N)])
    Y, U = rng.standard_normal((6, p)), rng.standard_normal((6, m))
    sparse = kalman_run(x, P, s, Y, U, record=True)
    dense_cols = np.tile(np.arange(n), (p, 1))
    outs = (np.empty((N, n)), np.empty((N, n, n)), np.empty((N, 6)), np.empty((N, 6, n)),
            np.empty((N, 6, n)))
    kalman_bank._kf_run(x, P, s.F, s.Q[None], s.B, U, s.H, dense_cols, np.full(p, n), s.R[None],
                        Y, np.arange(N), *outs, True, block_size(N))
    for a, b in zip(sparse, outs):
        assert np.array_equal(a, b)
    xr, Pr = x, P
    for k in range(6):
        xr, Pr, llr = reference_step(xr, Pr, s, Y[k], U[k])
        np.testing.assert_allclose(sparse[2][:, k], llr, rtol=1e-10, atol=1e-10)
    assert rel(sparse[0], xr) < 1e-10 and rel(sparse[1], Pr) < 1e-10


def test_block_size_changes_no_bit():
    """A filter's result does not depend on the bank it runs in: a bank of 40 (two blocks of
    20) and of 1 (one block of 1) give the bits of the same filters inside a bank of 200
    (blocks of 64, filters 0..39 in the first), so the block choice is speed only."""
    rng = np.random.default_rng(12)
    N, n, p, m = 200, 16, 5, 2
    s = LinearGaussianBatch(np.stack([random_stable(rng, n) for _ in range(N)]),
                            np.stack([random_spd(rng, n) for _ in range(N)]),
                            rng.standard_normal((p, n)), random_spd(rng, p),
                            rng.standard_normal((N, n, m)))
    x, P = rng.standard_normal((N, n)), np.stack([random_spd(rng, n) for _ in range(N)])
    Y, U = rng.standard_normal((9, p)), rng.standard_normal((9, m))
    assert [block_size(k) for k in (1, 40, 64, 65, 200)] == [1, 20, 32, 64, 64]
    full = kalman_run(x, P, s, Y, U)
    for part in (slice(0, 40), slice(7, 8)):
        small = kalman_run(x[part], P[part], s.take(np.arange(N)[part]), Y, U)
        for a, b in zip(small, full):
            assert np.array_equal(a, b[part])


def test_ancestors_gather_equals_copying_the_resampled_filters():
    """kalman_run(..., ancestors=idx) starts filter i from x[idx[i]], P[idx[i]]: bit-identical
    to copying first; indices outside the bank are refused."""
    rng = np.random.default_rng(10)
    N, n, p = 45, 5, 2
    s = LinearGaussianBatch(np.stack([random_stable(rng, n) for _ in range(N)]),
                            random_spd(rng, n), rng.standard_normal((p, n)), random_spd(rng, p))
    x, P = rng.standard_normal((N, n)), np.stack([random_spd(rng, n) for _ in range(N)])
    idx = np.sort(rng.integers(0, N, N))
    Y = rng.standard_normal((3, p))
    gathered = kalman_run(x, P, s, Y, ancestors=idx)
    copied = kalman_run(x[idx], P[idx], s, Y)
    for a, b in zip(gathered, copied):
        assert np.array_equal(a, b)
    with pytest.raises(ValueError, match="ancestors"):
        kalman_run(x, P, s, Y, ancestors=np.array([0, N]))


def test_chunked_working_rbpf_equals_step_by_step(lateral_record):
    """RaoBlackwellisedPF.steps (chunks between resampling events) = step() K times."""
    system, ys, u, theta0, opts = lateral_record("working")
    opts.update(ess_fraction=0.97, tempering_steps=10)        # resample often
    a = RaoBlackwellisedPF(system, theta0, np.zeros(16), 1e-10 * np.eye(16),
                           np.random.default_rng(7), **opts)
    b = RaoBlackwellisedPF(system, theta0, np.zeros(16), 1e-10 * np.eye(16),
                           np.random.default_rng(7), **opts)
    chunked = a.steps(ys, u, max_chunk=16)
    stepwise = [b.step(ys[k], u[k]) for k in range(len(ys))]
    assert sum(o.resampled for o in stepwise) >= 5          # chunks really get cut back
    for o1, o2 in zip(chunked, stepwise):
        for key in (f.name for f in dataclasses.fields(o1)):
            v1, v2 = getattr(o1, key), getattr(o2, key)
            if key in ("x_mean", "x_std"):              # batched over a chunk: rounding only
                np.testing.assert_allclose(v1, v2, rtol=1e-12, atol=1e-300)
            else:                                       # the filter's path: bit-identical
                assert np.array_equal(v1, v2, equal_nan=True), key
    assert np.array_equal(a.x, b.x) and np.array_equal(a.theta, b.theta)


@pytest.mark.parametrize("weighting", ["ratio", "printed"])
def test_compiled_qgrbpf_equals_numpy_qgrbpf_on_the_paper004_toy(weighting):
    from railpaper.engine.qgrbpf import run_qgrbpf
    from railpaper.models.linear_toys import paper004_system, simulate_paper004
    sim = simulate_paper004(-0.7, 1.5, 1e-3, 1e-3, 0.05, 60, np.random.default_rng(4))
    theta0 = np.random.default_rng(8).uniform([-1.0, 1.0], [0.4, 2.8], (200, 2))
    runs = [run_qgrbpf(paper004_system(1e-3, 1e-3), sim.y, theta0, np.zeros(2),
                       0.05 ** 2 * np.eye(2), np.random.default_rng(3), weighting=weighting,
                       engine=engine) for engine in ("compiled", "numpy")]
    np.testing.assert_allclose(runs[0].theta_mean, runs[1].theta_mean, rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(runs[0].log_evidence, runs[1].log_evidence, rtol=1e-9)


def test_compiled_qgrbpf_second_update_equals_the_textbook_one_on_the_lateral_model(
        lateral_record):
    """H depends on θ in the lateral model, so step (4) is a second measurement update with the
    new θ's H: the compiled split (kalman_predict, then kalman_update of the stored prior)
    against predict + Joseph update, step by step from the same bank.  (Whole runs are not
    compared: the draws of Eq. 9 use an eigendecomposition, whose eigenvector signs a rounding
    difference can flip.)"""
    from railpaper.engine.qgrbpf import QuasiGaussianRBPF
    system, ys, u, theta0, _ = lateral_record("paper")
    filters = [QuasiGaussianRBPF(system, theta0, np.zeros(16), 1e-10 * np.eye(16),
                                 np.random.default_rng(7), engine=engine)
               for engine in ("compiled", "numpy")]
    for k in range(40):
        outs = [f.step(ys[k], u[k]) for f in filters]
        filters[0].materialise()                    # the search's copy, pending on compiled
        np.testing.assert_allclose(filters[0].x, filters[1].x, rtol=1e-7, atol=1e-13)
        np.testing.assert_allclose(filters[0].P, filters[1].P, rtol=1e-7, atol=1e-16)
        np.testing.assert_allclose(outs[0].theta_mean, outs[1].theta_mean, rtol=1e-9)
        filters[1].x, filters[1].P = filters[0].x.copy(), filters[0].P.copy()   # same bank
        filters[1].theta, filters[1].sys = filters[0].theta.copy(), filters[0].sys
        filters[1].rng = np.random.default_rng(k)
        filters[0].rng = np.random.default_rng(k)


@pytest.mark.parametrize("kernel", ["stack_matmul", "_symmetric_abt", "_innovation_block"])
def test_bank_products_use_packed_fma_where_the_cpu_has_it(kernel):
    """The Kalman bank's products (F P, then F P Fᵀ + Q; the update's H P⁻ and S over H's
    nonzeros) run their lane loops as vectors: packed FMA (``vfmadd…pd`` on ymm/zmm) in the
    machine code compiled afresh with the kernels' options (a copy loaded from numba's cache
    carries no assembly)."""
    import re

    import llvmlite.binding as ll
    import numba

    from railpaper.engine.batch_expm import stack_matmul
    from railpaper.engine.kalman_bank import _innovation_block, _symmetric_abt
    if not ll.get_host_cpu_features().get("fma"):
        pytest.skip("host CPU without FMA")
    f = {"stack_matmul": stack_matmul, "_symmetric_abt": _symmetric_abt,
         "_innovation_block": _innovation_block}[kernel]
    options = {k: v for k, v in f.targetoptions.items() if k not in ("cache", "nopython")}
    fresh = numba.njit(**options)(f.py_func)
    A = np.ones((4, 4, 16))
    if kernel == "stack_matmul":
        fresh(A, A, np.empty_like(A))
    elif kernel == "_symmetric_abt":
        fresh(A, A, np.ones((1, 4, 4)), 0, 0, np.empty_like(A))
    else:
        p, n, nb = 2, 4, 16
        work = kalman_bank._innovation_workspace(n, p, nb, True)
        fresh(np.ones((p, n, nb)), np.tile(np.arange(n), (p, 1)), np.full(p, n), A,
              np.ones((n, nb)), np.ones(p), np.eye(p)[None], 0, 0, True, *work)
    asm = "\n".join(fresh.inspect_asm().values())
    assert re.search(r"vfmadd\w*pd\s[^\n]*%[yz]mm", asm)
