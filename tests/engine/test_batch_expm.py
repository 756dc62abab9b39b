"""The sparse Taylor ZOH (:mod:`railpaper.engine.sparse_zoh`) against independent references.

References: :func:`scipy.linalg.expm` of the augmented matrix ``[[A dt, B dt], [0, 0]]`` (Padé
13 with scaling and squaring, no balancing); a 50-digit :mod:`decimal` Taylor series with scaling
and squaring; the degree-K Taylor polynomial summed power by power in numpy; the term-count bound
evaluated with exact factorials (:mod:`fractions`).
"""

from __future__ import annotations

import math
from decimal import Decimal, localcontext
from fractions import Fraction

import numba
import numpy as np
import pytest
from scipy.linalg import expm, matrix_balance

from railpaper.engine.sparse_zoh import KMAX, TOL, term_counts, zoh_affine, zoh_sparse
from railpaper.models import lateral_16state

DT = 1e-3          # s, the chapter's step
SPEED = 300 / 3.6  # m/s


@pytest.fixture(scope="module")
def lateral():
    from railpaper.experiments.rbpf_parameter_estimation.lateral import vehicle
    fixed, theta = vehicle()
    A0, Ak = lateral_16state.affine_terms(fixed, SPEED)
    return A0, Ak, theta, lateral_16state.input_matrix()


def rel(a, b):
    """Per matrix: max |a − b| / max |b| over the last two axes."""
    return np.max(np.abs(a - b), axis=(-2, -1)) / np.max(np.abs(b), axis=(-2, -1))


def scipy_zoh(A, B, dt):
    """F, G from scipy's expm of each augmented matrix (one stacked call)."""
    A = np.asarray(A, float)
    n, m = A.shape[-1], np.shape(B)[-1]
    M = np.zeros(A.shape[:-2] + (n + m, n + m))
    M[..., :n, :n], M[..., :n, n:] = A * dt, np.asarray(B) * dt
    E = expm(M)
    return E[..., :n, :n], E[..., :n, n:]


def expm_decimal(M, digits=50):
    """e^M in ``digits``-digit decimal arithmetic: M/2^s with ‖·‖₁ ≤ 1/2, 60 terms, s squarings."""
    with localcontext() as ctx:
        ctx.prec = digits
        k = M.shape[0]
        norm = float(np.abs(M).sum(axis=0).max())
        s = max(0, math.ceil(math.log2(norm / 0.5))) if norm > 0 else 0
        X = np.array([[Decimal(float(v)) / Decimal(2) ** s for v in row] for row in M], object)
        term = np.array([[Decimal(int(i == j)) for j in range(k)] for i in range(k)], object)
        E = term.copy()
        for j in range(1, 60):
            term = term.dot(X) / j
            E = E + term
        for _ in range(s):
            E = E.dot(E)
        return np.array([[float(v) for v in row] for row in E])


def bound_terms(beta, tol, kmax):
    """(K, s) by the module's rule, evaluated with exact factorials: smallest s, then smallest K,
    with β_s^{K+1}/(K+1)! · e^{β_s} / (1 − β_s/(K+2)) ≤ tol, β_s = β / 2^s."""
    s = 0
    while True:
        b = Fraction(beta) / 2 ** s
        for K in range(1, kmax + 1):
            if K + 2 > b and (float(b ** (K + 1) / math.factorial(K + 1)) * math.exp(float(b))
                              / (1 - float(b) / (K + 2))) <= tol:
                return K, s
        s += 1


def balanced_blocks(A, B, dt, d):
    """The balanced augmented matrices D⁻¹ [[A dt, B dt], [0, 0]] D, (N, n+m, n+m)."""
    n, m = A.shape[-1], B.shape[-1]
    M = np.zeros((A.shape[0], n + m, n + m))
    M[:, :n, :n], M[:, :n, n:] = A * dt, B * dt
    return M * d[None, None, :] / d[None, :, None]


def balance_scale(A0, B):
    """scipy's powers-of-two balancing of [[A0 dt, B dt], [0, 0]]."""
    n, m = B.shape
    M = np.zeros((n + m, n + m))
    M[:n, :n], M[:n, n:] = A0 * DT, B * DT
    return matrix_balance(M, permute=False, separate=True)[1][0]


def taylor_then_square(X, K, s):
    """(Σ_{k ≤ K} (X/2^s)^k / k!)^(2^s), power by power in numpy."""
    Y = X / 2.0 ** s
    E, P = np.eye(len(X)), np.eye(len(X))
    for k in range(1, K + 1):
        P = P @ Y / k
        E = E + P
    for _ in range(s):
        E = E @ E
    return E


def lateral_stack(lateral, factors):
    A0, Ak, theta, _ = lateral
    return lateral_16state.a_of_theta(A0, Ak, theta * factors)


# ----------------------------------------------------------------------------- parity with scipy
def test_prior_box_matches_scipy_without_squaring(lateral):
    B = lateral[3]
    A = lateral_stack(lateral, np.random.default_rng(3).uniform(0.5, 1.7, (1000, 5)))
    F, G = zoh_sparse(A, B, DT)
    Fr, Gr = scipy_zoh(A, B, DT)
    assert rel(F, Fr).max() < 1e-13 and rel(G, Gr).max() < 1e-13   # measured 1.4e-15, 1.2e-15
    K, s = term_counts(A, B, DT)
    assert np.all(s == 0) and K.min() >= 14 and K.max() <= 18       # Taylor only, 14-18 terms


@pytest.mark.parametrize("factor", [10.0, 100.0, 0.01, 1e-6])
def test_far_outside_the_box_matches_scipy(lateral, factor):
    B = lateral[3]
    A = lateral_stack(lateral, factor * np.random.default_rng(4).uniform(0.8, 1.25, (37, 5)))
    F, G = zoh_sparse(A, B, DT)
    Fr, Gr = scipy_zoh(A, B, DT)
    assert rel(F, Fr).max() < 1e-13 and rel(G, Gr).max() < 1e-13
    if factor >= 10:
        assert np.all(term_counts(A, B, DT)[1] > 0)                   # the squaring fallback ran


def test_one_matrix_and_per_matrix_B(lateral):
    A0, Ak, theta, B = lateral
    A = lateral_16state.a_of_theta(A0, Ak, theta)
    F, G = zoh_sparse(A, B, DT)
    Fr, Gr = scipy_zoh(A[0], B, DT)
    assert F.shape == (1, 16, 16) and G.shape == (1, 16, 2)
    assert rel(F[0], Fr) < 1e-13 and rel(G[0], Gr) < 1e-13
    rng = np.random.default_rng(8)
    Bs = rng.standard_normal((5, 16, 2)) * (rng.random((5, 16, 2)) < 0.3)
    As = np.repeat(A, 5, axis=0)
    F, G = zoh_sparse(As, Bs, DT)
    Fr, Gr = scipy_zoh(As, Bs, DT)
    assert rel(F, Fr).max() < 1e-13 and rel(G, Gr).max() < 1e-13


def test_random_dense_matrices_fallback_vs_50_digit_reference():
    """Norms 0.01-50 mixed in one call: lanes of a block take different K and s."""
    rng = np.random.default_rng(11)
    n, m, N, dt = 7, 3, 16, 0.1
    A, B = rng.standard_normal((N, n, n)), rng.standard_normal((n, m))
    M = np.zeros((N, n + m, n + m))
    M[:, :n, n:] = B * dt
    norms = np.geomspace(0.01, 50, N)[rng.permutation(N)]
    for i in range(N):                 # scale A so the augmented 1-norm is norms[i]
        lo, hi = 0.0, 1e3
        for _ in range(200):
            mid = 0.5 * (lo + hi)
            M[i, :n, :n] = A[i] * mid * dt
            lo, hi = (mid, hi) if np.abs(M[i]).sum(axis=0).max() < norms[i] else (lo, mid)
        A[i] *= lo
    M[:, :n, :n] = A * dt
    F, G = zoh_sparse(A, B, dt)
    Fr, Gr = scipy_zoh(A, B, dt)
    assert rel(F, Fr).max() < 5e-13 and rel(G, Gr).max() < 5e-13    # scipy's own error ~1e-13
    for i in range(N):
        E = expm_decimal(M[i])
        assert rel(F[i], E[:n, :n]) < 1e-13 and rel(G[i], E[:n, n:]) < 1e-13
    assert term_counts(A, B, dt)[1].max() >= 5                       # norm 50: ≥ 5 squarings


# ----------------------------------------------------------------------------- pattern and lanes
def test_extra_zeros_and_lane_independence(lateral):
    """Some matrices have zeros where others have entries: results equal scipy (also alone);
    a matrix's bits do not depend on its block-mates (other K, other values) nor on its place
    in the stack, for the same union pattern."""
    B = lateral[3]
    rng = np.random.default_rng(6)
    A = lateral_stack(lateral, rng.uniform(0.5, 1.7, (70, 5)))
    rows, cols = np.nonzero(A[0])
    for i in range(0, 70, 3):                       # drop 1-8 entries of every third matrix
        k = rng.choice(len(rows), rng.integers(1, 9), replace=False)
        A[i, rows[k], cols[k]] = 0.0
    A[5, 0, 2] = 0.3                                # an entry no other matrix has
    F, G = zoh_sparse(A, B, DT)
    Fr, Gr = scipy_zoh(A, B, DT)
    assert rel(F, Fr).max() < 1e-13 and rel(G, Gr).max() < 1e-13
    for i in (0, 3, 5, 6, 69):
        Fi, Gi = zoh_sparse(A[i:i + 1], B, DT)
        assert rel(Fi[0], Fr[i]) < 1e-13 and rel(Gi[0], Gr[i]) < 1e-13
    other = A.copy()                                # odd places: new θ (×1-4), K differs
    other[1::2] = lateral_stack(lateral, rng.uniform(0.5, 4.0, (35, 5)))
    other[5] = A[5]
    Fo, Go = zoh_sparse(other, B, DT, scale=balance_scale(A[0], B))
    Fa, Ga = zoh_sparse(A, B, DT, scale=balance_scale(A[0], B))
    np.testing.assert_array_equal(Fo[0::2], Fa[0::2])
    np.testing.assert_array_equal(Go[0::2], Ga[0::2])
    perm = rng.permutation(70)
    Fp, Gp = zoh_sparse(A[perm], B, DT, scale=balance_scale(A[0], B))
    np.testing.assert_array_equal(Fp, Fa[perm])
    np.testing.assert_array_equal(Gp, Ga[perm])


def test_same_bits_on_one_and_two_threads(lateral):
    B = lateral[3]
    rng = np.random.default_rng(7)
    f = rng.uniform(0.5, 1.7, (1000, 5))
    f[::17] *= 12.0                                  # some matrices on the squaring path
    A = lateral_stack(lateral, f)
    before = numba.get_num_threads()
    try:
        numba.set_num_threads(1)
        one = zoh_sparse(A, B, DT)
        numba.set_num_threads(numba.config.NUMBA_NUM_THREADS)
        other = zoh_sparse(A, B, DT)
    finally:
        numba.set_num_threads(before)
    np.testing.assert_array_equal(one[0], other[0])
    np.testing.assert_array_equal(one[1], other[1])


# ----------------------------------------------------------------------------- the term count
def test_term_count_follows_the_bound(lateral):
    for beta in (0.0, 1e-3, 0.1, 0.5, 0.68, 0.85, 1.0, 1.3, 4.4, 50.0, 1e4):
        for tol, kmax in ((TOL, KMAX), (1e-13, KMAX), (1e-6, 18), (1e-6, 4)):
            A = np.array([[[beta / DT]]])
            got = tuple(int(v[0]) for v in term_counts(A, np.zeros((1, 1)), DT, np.ones(2),
                                                        tol, kmax))
            assert got == bound_terms(beta, tol, kmax), (beta, tol, kmax)


@pytest.mark.parametrize("kmax", [18, 5])
def test_result_is_the_truncated_series_of_the_counted_degree(lateral, kmax):
    """With a loose tolerance the truncation is visible (≈ 1e-7): the result must equal the
    Taylor polynomial of exactly the counted degree (then squared s times), not one degree
    less or more, and stay within the bound of e^X."""
    B = lateral[3]
    rng = np.random.default_rng(9)
    f = rng.uniform(0.5, 1.7, (40, 5))
    f[::7] *= 4.0
    A = lateral_stack(lateral, f)
    d = balance_scale(A[0], B)
    tol = 1e-6
    F, G = zoh_sparse(A, B, DT, scale=d, tol=tol, kmax=kmax)
    X = balanced_blocks(A, B, DT, d)
    K, s = term_counts(A, B, DT, d, tol, kmax)
    assert len(set(K)) > 1 and (kmax > 5 or s.max() > 0)
    for i in range(len(A)):
        beta = np.abs(X[i]).sum(axis=0).max()
        assert (K[i], s[i]) == bound_terms(beta, tol, kmax)
        E = taylor_then_square(X[i], K[i], s[i]) * d[:, None] / d[None, :]
        assert rel(F[i], E[:16, :16]) < 1e-13 and rel(G[i], E[:16, 16:]) < 1e-13
        short = taylor_then_square(X[i], K[i] - 1, s[i]) * d[:, None] / d[None, :]
        assert rel(F[i], short[:16, :16]) > 1e3 * rel(F[i], E[:16, :16])
        exact = expm(X[i])
        approx = (F[i] / d[:16, None] * d[None, :16])
        assert np.abs(approx - exact[:16, :16]).sum(axis=0).max() <= 2 ** s[i] * 4 * tol


def test_rejects_nan_and_mismatched_B():
    with pytest.raises(ValueError, match="NaN"):
        zoh_sparse(np.full((2, 3, 3), np.nan), np.ones((3, 1)), 0.1)
    with pytest.raises(ValueError, match="NaN"):
        zoh_sparse(np.zeros((2, 3, 3)), np.full((3, 1), np.inf), 0.1)
    with pytest.raises(ValueError, match="does not fit"):
        zoh_sparse(np.zeros((2, 3, 3)), np.ones((4, 1)), 0.1)


def test_product_kernel_uses_packed_fma_where_the_cpu_has_it():
    """The sparse product's lane loops are vectorised: packed FMA (``vfmadd…pd``) in the
    machine code of :func:`railpaper.engine.sparse_zoh._times_x` (compiled afresh with the same options:
    a copy loaded from numba's cache carries no assembly) when the host CPU has FMA."""
    import re

    import llvmlite.binding as ll

    from railpaper.engine.sparse_zoh import _times_x
    if not ll.get_host_cpu_features().get("fma"):
        pytest.skip("host CPU without FMA")
    options = {k: v for k, v in _times_x.targetoptions.items() if k not in ("cache", "nopython")}
    fresh = numba.njit(**options)(_times_x.py_func)
    W, cols, rowptr = np.zeros((4, 4, 8)), np.arange(3), np.array([0, 1, 2, 3])
    fresh(np.zeros((3, 8)), W, W.copy(), cols, rowptr, 3)
    asm = "\n".join(fresh.inspect_asm().values())
    assert re.search(r"vfmadd\w*pd\s[^\n]*%[yz]mm", asm)


# ------------------------------------------------------------------- zoh_affine: A(θ) never built
def test_affine_zoh_from_theta_matches_scipy_and_the_built_matrix(lateral):
    """zoh_affine(θ) against scipy's ZOH of A(θ) built by the affine form (prior box and
    ×100 outside it, where squaring runs) and against zoh_sparse of the same A(θ)."""
    A0, Ak, theta, B = lateral
    rng = np.random.default_rng(7)
    for factors in (rng.uniform(0.5, 1.7, (300, 5)), 100 * rng.uniform(0.8, 1.25, (20, 5))):
        th = theta * factors
        A = lateral_16state.a_of_theta(A0, Ak, th)
        F, G = zoh_affine(th, A0, Ak, B, DT)
        Fr, Gr = scipy_zoh(A, B, DT)
        assert rel(F, Fr).max() < 1e-13 and rel(G, Gr).max() < 1e-13
        Fs, Gs = zoh_sparse(A, B, DT)
        assert rel(F, Fs).max() < 1e-14 and rel(G, Gs).max() < 1e-14   # only A's rounding


def test_affine_zoh_lane_independence_and_errors(lateral):
    """A matrix's bits depend on its own θ only (not on block-mates or its place); bad input
    is refused with one message."""
    A0, Ak, theta, B = lateral
    th = theta * np.random.default_rng(8).uniform(0.5, 1.7, (70, 5))
    d = balance_scale(lateral_16state.a_of_theta(A0, Ak, theta)[0], B)
    F, G = zoh_affine(th, A0, Ak, B, DT, scale=d)
    perm = np.random.default_rng(9).permutation(70)
    Fp, Gp = zoh_affine(th[perm], A0, Ak, B, DT, scale=d)
    assert np.array_equal(Fp, F[perm]) and np.array_equal(Gp, G[perm])
    F1, G1 = zoh_affine(th[33:34], A0, Ak, B, DT, scale=d)
    assert np.array_equal(F1[0], F[33]) and np.array_equal(G1[0], G[33])
    with pytest.raises(ValueError, match="NaN or inf"):
        zoh_affine(np.full((2, 5), np.nan), A0, Ak, B, DT)
    with pytest.raises(ValueError, match="do not fit"):
        zoh_affine(th[:, :4], A0, Ak, B, DT)


def test_lateral_system_bits_do_not_depend_on_the_order_of_calls(lateral):
    """With theta_ref the balancing is fixed when the system is made: a particle's matrices are
    the same bits whichever filter called the system first and whatever its block-mates."""
    from railpaper.experiments.rbpf_parameter_estimation.lateral import vehicle
    fixed, theta = vehicle()
    Q, R = 1e-12 * np.eye(16), 1e-6 * np.eye(5)
    rng = np.random.default_rng(11)
    a, b = theta * rng.uniform(0.5, 1.7, (40, 5)), theta * rng.uniform(0.5, 1.7, (40, 5))
    s1 = lateral_16state.lateral_system(fixed, SPEED, DT, Q, R, theta_ref=1.1 * theta)
    s2 = lateral_16state.lateral_system(fixed, SPEED, DT, Q, R, theta_ref=1.1 * theta)
    first_a = s1(a)
    s2(b)                                                   # another filter called first
    second_a = s2(a[::-1])
    assert np.array_equal(first_a.F, second_a.F[::-1])
    assert np.array_equal(first_a.H, second_a.H[::-1])
    A = lateral_16state.a_of_theta(*lateral_16state.affine_terms(fixed, SPEED), a)
    Fr, Gr = scipy_zoh(A, lateral_16state.input_matrix(), DT)
    assert rel(first_a.F, Fr).max() < 1e-13 and rel(first_a.B, Gr).max() < 1e-13
    np.testing.assert_allclose(first_a.H, lateral_16state.measurement_matrix(A),
                               rtol=1e-14, atol=1e-14)
