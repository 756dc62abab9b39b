"""ZOH of a stack of sparse matrices: Taylor without squaring, on the nonzeros only, compiled.

For a stack ``A`` (N, n, n) and an input matrix ``B`` (n, m) (or (N, n, m)) we want, for every
matrix of the stack, ``F = e^{A dt}`` and ``G = ∫₀^dt e^{As} ds B``: the top blocks of
``e^X`` with ``X = [[A dt, B dt], [0, 0]]`` (Van Loan), an (n+m)-square matrix whose last m
rows are zero.  The method:

1. **Balancing** by a fixed diagonal similarity ``D⁻¹ X D`` (``D`` from
   :func:`scipy.linalg.matrix_balance` of the first matrix, powers of two, so exact).  For the
   lateral model of paper 003 at dt = 1 ms this takes ``‖X‖₁`` from 65–86 to 0.47–0.97 over
   the prior box (0.5–1.7 × truth, its 32 corners): 14–18 terms, no squaring.
2. **Pattern**: the union of the nonzeros of ``[A | B]`` over the stack, found once per call,
   kept row by row (CSR).  A zero of one matrix inside the union contributes exact zeros.
3. **Number of terms per matrix** from ``β = ‖D⁻¹ X D‖₁`` (exact 1-norm): the smallest K with
   the relative truncation bound ``β^{K+1}/(K+1)! · e^β / (1 − β/(K+2)) ≤ tol`` (the tail of
   the exponential series over the lower bound ``‖e^X‖ ≥ e^{-β}``).
4. **Fallback**: if that K exceeds ``kmax``, scale ``X / 2^s`` until it does not, and square
   ``s`` times afterwards (``[[F, G], [0, I]]² = [[F², F G + G], [0, I]]``); far outside the
   prior box only.
5. **Horner** ``e^X ≈ I + X(I + X/2(… (I + X/K)))``, the products ``(X/k) W`` over the
   pattern's nonzeros only: per term ``nnz · (n+m)`` multiply-adds (lateral model: 45 · 18;
   14–18 terms over the prior box, ≈ 11.7k multiply-adds per matrix, 13k as run in blocks;
   the dense degree-12 route of :mod:`railpaper.engine.batch_expm`: 35k).  The last m rows of every
   iterate are ``[0 | I]`` and are never computed.

Layout: particles in blocks of :data:`BLOCK` (one SIMD lane per particle, the batch axis last),
blocks in parallel (``prange``).  Each lane runs its own K and s (other lanes of the block are
masked: their coefficients are zero, so the iterate stays the identity until their own K), so
the result of a matrix depends on its entries, the balancing and the union pattern (which sets
the order of the sums), not on its block-mates, its place in the stack or the number of threads.

Reference: :func:`railpaper.discretise.zoh` (``scipy.linalg.expm``); tests/engine/test_batch_expm.py.
"""

from __future__ import annotations

import math

import numba
import numpy as np
from scipy.linalg import matrix_balance

from railpaper.engine.kernel_arrays import kernel_array

BLOCK = 32          # matrices per block: the SIMD lanes of every inner loop
TOL = 2.0 ** -53    # relative truncation bound (unit roundoff): the series is cut below rounding
KMAX = 20           # most terms without squaring (≈ 6 terms cost one squaring)


@numba.njit(cache=True)
def _pattern(A, B):  # pragma: no cover - compiled
    """Union of the nonzeros of ``[A_i | B_i]`` (n, n+m) over the stack, and whether every
    entry is finite (``a − a`` is NaN exactly for NaN and ±inf)."""
    N, n, m = A.shape[0], A.shape[1], B.shape[2]
    nz = np.zeros((n, n + m), np.bool_)
    bad = np.zeros((n, n + m), np.bool_)
    for q in range(N):
        for i in range(n):
            for j in range(n):                    # elementwise ORs: one SIMD loop, no chain
                a = A[q, i, j]
                nz[i, j] |= a != 0.0
                bad[i, j] |= (a - a) != 0.0
    for q in range(B.shape[0]):
        for i in range(n):
            for j in range(m):
                b = B[q, i, j]
                nz[i, n + j] |= b != 0.0
                bad[i, n + j] |= (b - b) != 0.0
    return nz, not bad.any()


@numba.njit(cache=True)
def _terms(beta, tol, kmax):  # pragma: no cover - compiled
    """(K, s): fewest Taylor terms K ≤ kmax of ``e^{X/2^s}``, smallest s, for ``‖X‖₁ = beta``."""
    s = 0
    b = beta
    while s < 2100:                               # b = inf (overflow) ends here: NaN out
        t = b                                     # b^{k+1}/(k+1)! for k = 0
        for k in range(1, kmax + 1):
            t *= b / (k + 1)
            if k + 2 > b and t * math.exp(b) / (1.0 - b / (k + 2)) <= tol:
                return k, s
        s += 1
        b *= 0.5
    return kmax, s


@numba.njit(fastmath={"contract"}, cache=True)
def _times_x(xs, W, Wn, cols, rowptr, n):  # pragma: no cover - compiled
    """Top rows of ``Wn = I + X W`` over X's nonzeros (CSR ``cols``/``rowptr``, values ``xs``).

    A row's first nonzero writes ``δ + x W``; the others go in fours (one load and store of
    ``Wn`` per four products), the rest one by one; the innermost loop runs over the lanes.
    """
    p, nb = W.shape[1], W.shape[2]
    for r in range(n):
        e, end = rowptr[r], rowptr[r + 1]
        if e == end:
            for j in range(p):
                for q in range(nb):
                    Wn[r, j, q] = 1.0 if r == j else 0.0
        else:
            c = cols[e]
            for j in range(p):
                for q in range(nb):
                    Wn[r, j, q] = (1.0 if r == j else 0.0) + xs[e, q] * W[c, j, q]
            e += 1
        while end - e >= 4:
            c0, c1, c2, c3 = cols[e], cols[e + 1], cols[e + 2], cols[e + 3]
            for j in range(p):
                for q in range(nb):
                    Wn[r, j, q] += (xs[e, q] * W[c0, j, q] + xs[e + 1, q] * W[c1, j, q]
                                    + xs[e + 2, q] * W[c2, j, q] + xs[e + 3, q] * W[c3, j, q])
            e += 4
        while e < end:
            c = cols[e]
            for j in range(p):
                for q in range(nb):
                    Wn[r, j, q] += xs[e, q] * W[c, j, q]
            e += 1


@numba.njit(fastmath={"contract"}, cache=True)
def _block(x, K, S, rows, cols, rowptr, n, p):  # pragma: no cover - compiled
    """``e^X`` per lane (rows n.. are [0 | I]): Horner with K[q] ≥ 1 terms, S[q] squarings."""
    nnz, nb = x.shape
    W = np.zeros((p, p, nb))                          # iterate; rows n.. stay [0 | I]
    Wn = np.zeros((p, p, nb))
    for c in range(n, p):
        for q in range(nb):
            W[c, c, q] = 1.0
            Wn[c, c, q] = 1.0
    xs = np.empty((nnz, nb))
    kb = K.max()
    for k in range(kb, 0, -1):                        # W = I + (X/k) W, lane q while k ≤ K[q]
        inv = 1.0 / k
        for e in range(nnz):
            for q in range(nb):
                xs[e, q] = x[e, q] * inv if k <= K[q] else 0.0
        if k == kb:                                   # first term I + X/K: no product
            for r in range(n):
                for j in range(p):
                    for q in range(nb):
                        Wn[r, j, q] = 1.0 if r == j else 0.0
            for e in range(nnz):
                for q in range(nb):
                    Wn[rows[e], cols[e], q] += xs[e, q]
        else:
            _times_x(xs, W, Wn, cols, rowptr, n)
        W, Wn = Wn, W
    for it in range(S.max()):                         # squarings, lane q while it < S[q]
        for r in range(n):
            for j in range(p):
                for q in range(nb):
                    Wn[r, j, q] = 0.0
            for c in range(p):
                for j in range(p):
                    for q in range(nb):
                        Wn[r, j, q] += W[r, c, q] * W[c, j, q]
        for r in range(n):
            for j in range(p):
                for q in range(nb):
                    W[r, j, q] = Wn[r, j, q] if it < S[q] else W[r, j, q]
    return W


@numba.njit(cache=True)
def _finish_block(x, lo, d, rows, cols, rowptr, n, tol, kmax, F, G):  # pragma: no cover
    """Terms, scaling, Horner and squaring of one block whose balanced ``X dt`` values on the
    pattern are ``x`` (nnz, nb); writes ``F[lo + q]``, ``G[lo + q]`` with the balancing undone."""
    nnz, nb = x.shape
    m = G.shape[2]
    p = n + m
    K = np.zeros(nb, np.int64)
    S = np.zeros(nb, np.int64)
    colsum = np.zeros(p)
    for q in range(nb):
        colsum[:] = 0.0
        for e in range(nnz):
            colsum[cols[e]] += abs(x[e, q])
        K[q], S[q] = _terms(colsum.max(), tol, kmax)
        for e in range(nnz):
            x[e, q] *= 0.5 ** S[q]                    # X / 2^s, exact
    W = _block(x, K, S, rows, cols, rowptr, n, p)
    ratio = np.empty((n, p))                          # undo the balancing: D e^X D⁻¹
    for i in range(n):
        for j in range(p):
            ratio[i, j] = d[i] / d[j]                 # once per block, not once per matrix
    for q in range(nb):
        for i in range(n):
            for j in range(n):
                F[lo + q, i, j] = W[i, j, q] * ratio[i, j]
            for j in range(m):
                G[lo + q, i, j] = W[i, n + j, q] * ratio[i, n + j]


@numba.njit(parallel=True, cache=True)
def _zoh_blocks(A, B, dt, d, rows, cols, rowptr, tol, kmax, F, G):  # pragma: no cover
    N, n = A.shape[0], A.shape[1]
    nnz = cols.shape[0]
    for blk in numba.prange((N + BLOCK - 1) // BLOCK):
        lo = blk * BLOCK
        nb = min(BLOCK, N - lo)
        x = np.empty((nnz, nb))                       # D⁻¹ X D on the pattern, lane = matrix
        for q in range(nb):
            bq = lo + q if B.shape[0] > 1 else 0
            for e in range(nnz):
                r, c = rows[e], cols[e]
                v = A[lo + q, r, c] if c < n else B[bq, r, c - n]
                x[e, q] = v * dt * (d[c] / d[r])      # exact scaling (powers of two)
        _finish_block(x, lo, d, rows, cols, rowptr, n, tol, kmax, F, G)


@numba.njit(parallel=True, cache=True)
def _zoh_affine_blocks(theta, xa, xk, n, tol, kmax, d, rows, cols, rowptr, F, G
                       ):  # pragma: no cover - compiled
    N, n_theta = theta.shape
    nnz = cols.shape[0]
    for blk in numba.prange((N + BLOCK - 1) // BLOCK):
        lo = blk * BLOCK
        nb = min(BLOCK, N - lo)
        x = np.empty((nnz, nb))
        for e in range(nnz):                          # X(θ) dt on the pattern: xa + Σ θ_k xk
            for q in range(nb):
                v = xa[e]
                for k in range(n_theta):
                    v += theta[lo + q, k] * xk[k, e]
                x[e, q] = v
        _finish_block(x, lo, d, rows, cols, rowptr, n, tol, kmax, F, G)


def balance_scale(A0: np.ndarray, B0: np.ndarray, dt_s: float) -> np.ndarray:
    """Powers-of-two diagonal balancing ``[[A0 dt, B0 dt], [0, 0]]`` (scipy)."""
    n, m = A0.shape[0], B0.shape[1]
    M = np.zeros((n + m, n + m))
    M[:n, :n], M[:n, n:] = A0 * dt_s, B0 * dt_s
    _, (scale, _) = matrix_balance(M, permute=False, separate=True)
    return np.asarray(scale, float)


def zoh_sparse(A: np.ndarray, B: np.ndarray, dt_s: float, scale: np.ndarray | None = None,
               tol: float = TOL, kmax: int = KMAX) -> tuple[np.ndarray, np.ndarray]:
    """Exact ZOH ``(e^{A dt}, ∫₀^dt e^{As} ds B)`` of a stack, on A's and B's nonzeros only.

    Parameters
    ----------
    A : ndarray, shape (N, n, n)
        Continuous state matrices, 1/s.
    B : ndarray, shape (n, m) or (N, n, m)
        Continuous input matrix (shared or one per matrix of the stack).
    dt_s : float
        Sample time, s.
    scale : ndarray, shape (n+m,), optional
        Balancing diagonal of ``[[A dt, B dt], [0, 0]]`` (powers of two); default: scipy's
        balancing of the first matrix.
    tol : float
        Relative truncation bound per matrix (see the module docstring).
    kmax : int
        Most Taylor terms before scaling and squaring is used instead.

    Returns
    -------
    F : ndarray, shape (N, n, n)
        ``e^{A dt}``.
    G : ndarray, shape (N, n, m)
        ``∫₀^dt e^{As} ds B``, units of B times s.
    """
    A = kernel_array(A)
    B = np.asarray(B, dtype=float)
    B3 = kernel_array(B[None] if B.ndim == 2 else B)
    N, n, m = A.shape[0], A.shape[-1], B3.shape[-1]
    if B3.shape[0] not in (1, N) or B3.shape[1] != n:
        raise ValueError(f"zoh_sparse: B of shape {B.shape} does not fit A of shape {A.shape}")
    nz, finite = _pattern(A, B3)
    if not finite:
        raise ValueError("zoh_sparse: matrix has NaN or inf entries")
    d = balance_scale(A[0], B3[0], dt_s) if scale is None else np.asarray(scale, float)
    rows, cols = np.nonzero(nz)                   # row-major: CSR order
    rowptr = np.searchsorted(rows, np.arange(n + 1)).astype(np.int64)
    F, G = np.empty((N, n, n)), np.empty((N, n, m))
    _zoh_blocks(A, B3, float(dt_s), d, rows.astype(np.int64), cols.astype(np.int64), rowptr,
                float(tol), int(kmax), F, G)
    return F, G


def affine_balance(theta: np.ndarray, A0: np.ndarray, Ak: np.ndarray, B: np.ndarray,
                   dt_s: float) -> np.ndarray:
    """:func:`balance_scale` of ``A(θ) = A0 + Σ_k θ_k A_k`` for one θ (d,)."""
    return balance_scale(A0 + np.tensordot(np.asarray(theta, float), Ak, axes=1), B, dt_s)


def _checked_theta(theta: np.ndarray, n_theta: int) -> np.ndarray:
    """θ as a contiguous (N, n_theta) float array; a wrong shape or a NaN/inf is refused."""
    theta = kernel_array(np.atleast_2d(theta))
    if theta.ndim != 2 or theta.shape[1] != n_theta:
        raise ValueError(f"zoh_affine: shapes theta {theta.shape} and {n_theta} affine terms "
                         "do not fit")
    if not np.all(np.isfinite(theta)):
        raise ValueError("zoh_affine: theta has NaN or inf entries")
    return theta


class AffineZOH:
    """:func:`zoh_sparse` of ``A(θ_i) = A0 + Σ_k θ_ik A_k``, prepared once for fixed matrices.

    ``A(θ)`` is never built: the union pattern of ``A0``, the ``A_k`` and ``B`` (found from the
    d + 2 matrices, not by scanning N) and the balanced values ``A0 dt``, ``A_k dt`` on it are
    formed here, once; a call forms ``(A0 + Σ θ_k A_k) dt`` on the pattern lane by lane and runs
    the same Horner/squaring kernel.

    Parameters
    ----------
    A0 : ndarray, shape (n, n)
        Constant part of A, 1/s.
    Ak : ndarray, shape (d, n, n)
        ``∂A/∂θ_k``, 1/s per unit of θ_k.
    B : ndarray, shape (n, m)
        Continuous input matrix (shared).
    dt_s : float
        Sample time, s.
    scale : ndarray, shape (n+m,)
        Balancing diagonal (powers of two), e.g. :func:`affine_balance` of a reference θ.
    tol, kmax
        As for :func:`zoh_sparse`.
    """

    def __init__(self, A0: np.ndarray, Ak: np.ndarray, B: np.ndarray, dt_s: float,
                 scale: np.ndarray, tol: float = TOL, kmax: int = KMAX):
        A0, Ak, B = (np.asarray(M, float) for M in (A0, Ak, B))
        n, m = A0.shape[0], B.shape[1]
        if Ak.shape[1:] != A0.shape or B.shape[0] != n:
            raise ValueError(f"zoh_affine: shapes A0 {A0.shape}, Ak {Ak.shape}, B {B.shape} "
                             "do not fit")
        self.n, self.m, self.n_theta = n, m, len(Ak)
        self.d = np.asarray(scale, float)
        self.tol, self.kmax = float(tol), int(kmax)
        X0 = np.concatenate([A0, B], axis=1)                      # (n, n+m)
        Xk = np.concatenate([Ak, np.zeros((len(Ak), n, m))], axis=2)
        rows, cols = np.nonzero((X0 != 0) | (Xk != 0).any(axis=0))     # row-major: CSR order
        self.rowptr = np.searchsorted(rows, np.arange(n + 1)).astype(np.int64)
        balance = dt_s * self.d[cols] / self.d[rows]               # exact (powers of two)
        self.xa = np.ascontiguousarray(X0[rows, cols] * balance)
        self.xk = np.ascontiguousarray(Xk[:, rows, cols] * balance)
        self.rows, self.cols = rows.astype(np.int64), cols.astype(np.int64)

    def __call__(self, theta: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``(F, G)``: ``e^{A(θ_i) dt}`` (N, n, n) and ``∫₀^dt e^{A(θ_i)s} ds B`` (N, n, m)."""
        theta = _checked_theta(theta, self.n_theta)
        F, G = np.empty((len(theta), self.n, self.n)), np.empty((len(theta), self.n, self.m))
        _zoh_affine_blocks(theta, self.xa, self.xk, self.n, self.tol, self.kmax, self.d,
                           self.rows, self.cols, self.rowptr, F, G)
        return F, G


def zoh_affine(theta: np.ndarray, A0: np.ndarray, Ak: np.ndarray, B: np.ndarray, dt_s: float,
               scale: np.ndarray | None = None, tol: float = TOL, kmax: int = KMAX
               ) -> tuple[np.ndarray, np.ndarray]:
    """One call of :class:`AffineZOH` (default ``scale``: :func:`affine_balance` of θ_0).

    Returns
    -------
    F : ndarray, shape (N, n, n)
    G : ndarray, shape (N, n, m)
    """
    theta = _checked_theta(theta, len(Ak))
    if scale is None:
        scale = affine_balance(theta[0], A0, Ak, B, dt_s)
    return AffineZOH(A0, Ak, B, dt_s, scale, tol, kmax)(theta)


def term_counts(A: np.ndarray, B: np.ndarray, dt_s: float, scale: np.ndarray | None = None,
                tol: float = TOL, kmax: int = KMAX) -> tuple[np.ndarray, np.ndarray]:
    """Taylor terms K and squarings s that :func:`zoh_sparse` uses for each matrix.

    ``β`` is summed here in numpy, so at a boundary of the bound it may differ from the
    kernel's in the last bit; for reports and tests.

    Returns
    -------
    K, s : ndarray of int, shape (N,)
    """
    A = np.asarray(A, float)
    B = np.broadcast_to(np.asarray(B, float), A.shape[:1] + np.shape(B)[-2:])
    n = A.shape[-1]
    d = balance_scale(A[0], B[0], dt_s) if scale is None else np.asarray(scale, float)
    X = np.concatenate([A, B], axis=-1) * dt_s * (d[None, :] / d[:n, None])
    beta = np.abs(X).sum(axis=-2).max(axis=-1)
    Ks = np.array([_terms(b, float(tol), int(kmax)) for b in beta], dtype=np.int64)
    return Ks[:, 0], Ks[:, 1]


def multiply_adds(nnz: int, n: int, m: int, terms: int, squarings: int = 0) -> int:
    """Multiply-adds per matrix in :func:`zoh_sparse`'s products (scalings not counted).

    ``terms − 1`` sparse products of ``nnz · (n+m)`` (the first term is a scatter) and
    ``n (n+m)²`` per squaring; the ``nnz · terms`` scalings ``X/k`` come on top.
    """
    return (terms - 1) * nnz * (n + m) + squarings * n * (n + m) ** 2
