"""The bank's register-blocked products give the plain loops' bits.

``stack_matmul``, ``_symmetric_abt`` and ``_posterior_block`` add four terms per load and store
of their output, in the same order as the plain loops.  Each is checked here against the plain
loop, compiled with the same options (so the same fused multiply-adds), bit for bit, on shapes
whose row and inner counts are not multiples of the blocking (tails), and against numpy's
products to rounding.
"""

import numba
import numpy as np
import pytest

from railpaper.engine.batch_expm import stack_matmul
from railpaper.engine.kalman_bank import _posterior_block, _symmetric_abt

OPTIONS = dict(fastmath={"contract"})


@numba.njit(**OPTIONS)
def plain_matmul(A, B, C):
    r, k, c, nb = A.shape[0], A.shape[1], B.shape[1], A.shape[2]
    C[:] = 0.0
    for i in range(r):
        for l in range(k):
            for j in range(c):
                for q in range(nb):
                    C[i, j, q] += A[i, l, q] * B[l, j, q]


@numba.njit(**OPTIONS)
def plain_symmetric_abt(A, B, D, C):
    r, k, nb = A.shape[0], A.shape[1], A.shape[2]
    for i in range(r):
        for j in range(i, r):
            for q in range(nb):
                C[i, j, q] = D[q, i, j]
        for l in range(k):
            for j in range(i, r):
                for q in range(nb):
                    C[i, j, q] += A[i, l, q] * B[j, l, q]
        for j in range(i + 1, r):
            for q in range(nb):
                C[j, i, q] = C[i, j, q]


@numba.njit(**OPTIONS)
def plain_downdate(W, P):
    p, n, nb = W.shape
    for r in range(p):
        for i in range(n):
            for j in range(i, n):
                for q in range(nb):
                    P[i, j, q] -= W[r, i, q] * W[r, j, q]
    for i in range(n):
        for j in range(i + 1, n):
            for q in range(nb):
                P[j, i, q] = P[i, j, q]


def lanes_first(M):
    """(nb, r, c) -> the kernels' (r, c, nb)."""
    return np.ascontiguousarray(np.moveaxis(M, 0, -1))


@pytest.mark.parametrize("r,k,c", [(16, 16, 16), (5, 16, 16), (7, 9, 3), (1, 3, 2), (2, 4, 5)])
def test_stack_matmul_is_the_plain_loop_bit_for_bit(r, k, c):
    rng = np.random.default_rng(r * 100 + k * 10 + c)
    nb = 13
    A, B = rng.standard_normal((nb, r, k)), rng.standard_normal((nb, k, c))
    C, C_plain = np.empty((r, c, nb)), np.empty((r, c, nb))
    stack_matmul(lanes_first(A), lanes_first(B), C)
    plain_matmul(lanes_first(A), lanes_first(B), C_plain)
    assert np.array_equal(C, C_plain)
    np.testing.assert_allclose(C, lanes_first(A @ B), rtol=1e-12, atol=1e-12)


@pytest.mark.parametrize("r,k", [(16, 16), (5, 7), (3, 4), (6, 1)])
def test_symmetric_abt_is_the_plain_loop_bit_for_bit(r, k):
    rng = np.random.default_rng(r * 10 + k)
    nb = 11
    A, B = rng.standard_normal((nb, r, k)), rng.standard_normal((nb, r, k))
    D = rng.standard_normal((nb, r, r))
    D = D + np.swapaxes(D, 1, 2)
    S = A @ np.swapaxes(A, 1, 2)                       # a symmetric A Bᵀ: B = A
    C, C_plain = np.empty((r, r, nb)), np.empty((r, r, nb))
    _symmetric_abt(lanes_first(A), lanes_first(A), D, 0, 1, C)
    plain_symmetric_abt(lanes_first(A), lanes_first(A), D, C_plain)
    assert np.array_equal(C, C_plain)
    np.testing.assert_allclose(C, lanes_first(S + D), rtol=1e-12, atol=1e-12)
    _symmetric_abt(lanes_first(A), lanes_first(B), D, 0, 1, C)   # upper triangle of A Bᵀ + D
    plain_symmetric_abt(lanes_first(A), lanes_first(B), D, C_plain)
    assert np.array_equal(C, C_plain)


@pytest.mark.parametrize("p,n", [(5, 16), (4, 6), (1, 3), (9, 5)])
def test_posterior_downdate_is_the_plain_loop_bit_for_bit(p, n):
    rng = np.random.default_rng(p * 10 + n)
    nb = 7
    W = rng.standard_normal((nb, p, n))
    P0 = rng.standard_normal((nb, n, n))
    P0 = P0 @ np.swapaxes(P0, 1, 2) + 10 * np.eye(n)
    xp, z = rng.standard_normal((n, nb)), rng.standard_normal((p, nb))
    P, P_plain, x = lanes_first(P0), lanes_first(P0), np.empty((n, nb))
    _posterior_block(xp, lanes_first(W), z, x, P)
    plain_downdate(lanes_first(W), P_plain)
    assert np.array_equal(P, P_plain)
    np.testing.assert_allclose(P, lanes_first(P0 - np.swapaxes(W, 1, 2) @ W), rtol=1e-12,
                               atol=1e-12)
