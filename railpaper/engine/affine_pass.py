"""A whole record in one compiled pass: the Q-GRBPF and the RBPF (both schemes) on models affine in θ.

For a small model (2 states, a few particles' worth of arithmetic per step) the Python steps of
:class:`~railpaper.engine.qgrbpf.QuasiGaussianRBPF` and
:class:`~railpaper.engine.rbpf.RaoBlackwellisedPF` spend most of their time calling numpy, not
computing.  When the model is an :class:`~railpaper.engine.linear_gaussian.AffineSystem`
(``F(θ) = F0 + Σ θ_j F_j``, shared Q, H, R: both toys) a particle's matrices can be formed
where they are used, and every step — Kalman bank, weights, moments, Gaussian draws,
resampling, the Liu–West move — runs inside one numba function per record.

The kernels draw from the filter's own ``numpy.random.Generator`` (numba runs NumPy's
generators bit for bit) in the order the step-by-step filter draws (per step: the Q-GRBPF's
``standard_normal((N, d))`` then ``random(N)``; at a resampling of the RBPF ``random()`` then
``standard_normal((N, d))``), so the same generator gives the same draws and is left in the
same state.  The arithmetic is the same up to the order of sums, so the
estimates equal the step-by-step filter's to rounding (tests/engine/test_affine_pass.py, both
engines, both toys).  The filters' classes call this pass from ``run`` when it applies and
step by step otherwise::

    >>> import numpy as np
    >>> from railpaper.engine import run_qgrbpf
    >>> from railpaper.models.linear_toys import paper004_system, simulate_paper004
    >>> rng = np.random.default_rng(1)
    >>> sim = simulate_paper004(-0.7, 1.5, 1e-3, 1e-3, 0.05, 300, rng)
    >>> theta0 = np.column_stack([rng.uniform(-1, 0.4, 1000), rng.uniform(1, 2.8, 1000)])
    >>> run = run_qgrbpf(paper004_system(1e-3, 1e-3), sim.y, theta0, np.zeros(2),
    ...                  0.05 ** 2 * np.eye(2), rng)        # one compiled pass
    >>> bool(np.all(np.abs(run.theta_mean[-1] - (-0.7, 1.5)) < 0.3))
    True
"""

from __future__ import annotations

import math

import numba
import numpy as np

from railpaper.engine.kalman import LOG_2PI
from railpaper.engine.kernel_arrays import kernel_array
from railpaper.engine.linear_gaussian import AffineSystem


# ----------------------------------------------------------------------------- pieces
@numba.njit(fastmath={"contract"}, error_model="numpy", cache=True)
def _kalman_bank(theta, x, P, F0, Ft, B0, Bt, u, Q, H, R, y, loglik, ws):  # pragma: no cover
    """Predict + update of every particle's filter in place, F_i = F0 + Σ θ_ij F_j:

    x⁻ = F x + B u,  P⁻ = F P Fᵀ + Q,  S = H P⁻ Hᵀ + R = L Lᵀ,  z = L⁻¹ (y − H x⁻),
    W = L⁻¹ H P⁻,  x = x⁻ + Wᵀ z,  P = P⁻ − Wᵀ W,  log N = −½ (zᵀz + log|S| + p log 2π).

    Structure of arrays, particles last (x (n, N), P (n, n, N)): every scalar formula is one
    SIMD loop over the particles, as in :mod:`railpaper.engine.kalman_bank`.  S not positive
    definite (or NaN): no update, log-likelihood −inf (as the bank)."""
    n, N = x.shape
    p, d, m = H.shape[0], Ft.shape[0], B0.shape[1]
    F, FP, Pm, xm, HP, S, Lc, v, z, W, logdet, bad = ws
    for a in range(n):                                           # F = F0 + Σ θ_j F_j
        for b in range(n):
            for i in range(N):
                F[a, b, i] = F0[a, b]
            for j in range(d):
                c = Ft[j, a, b]
                if c != 0.0:                                     # constants stay exact
                    for i in range(N):
                        F[a, b, i] += theta[i, j] * c
    for a in range(n):                                           # x⁻ = F x + B u
        for i in range(N):
            xm[a, i] = 0.0
        for k in range(n):
            for i in range(N):
                xm[a, i] += F[a, k, i] * x[k, i]
        for c in range(m):
            if u[c] != 0.0:
                for i in range(N):
                    xm[a, i] += B0[a, c] * u[c]
                for j in range(d):
                    if Bt[j, a, c] != 0.0:
                        for i in range(N):
                            xm[a, i] += theta[i, j] * Bt[j, a, c] * u[c]
    for a in range(n):                                           # F P
        for b in range(n):
            for i in range(N):
                FP[a, b, i] = 0.0
            for k in range(n):
                for i in range(N):
                    FP[a, b, i] += F[a, k, i] * P[k, b, i]
    for a in range(n):                                           # P⁻ = F P Fᵀ + Q
        for b in range(a, n):
            for i in range(N):
                Pm[a, b, i] = Q[a, b]
            for k in range(n):
                for i in range(N):
                    Pm[a, b, i] += FP[a, k, i] * F[b, k, i]
            for i in range(N):
                Pm[b, a, i] = Pm[a, b, i]
    for r in range(p):                                           # H P⁻, v = y − H x⁻
        for i in range(N):
            v[r, i] = y[r]
        for k in range(n):
            for i in range(N):
                v[r, i] -= H[r, k] * xm[k, i]
        for b in range(n):
            for i in range(N):
                HP[r, b, i] = 0.0
            for k in range(n):
                for i in range(N):
                    HP[r, b, i] += H[r, k] * Pm[k, b, i]
    for r in range(p):                                           # S = H P⁻ Hᵀ + R
        for c in range(r, p):
            for i in range(N):
                S[r, c, i] = R[r, c]
            for k in range(n):
                for i in range(N):
                    S[r, c, i] += HP[r, k, i] * H[c, k]
    for i in range(N):
        logdet[i] = 0.0
        bad[i] = False
    for c in range(p):                                           # S = L Lᵀ per particle
        for i in range(N):
            s = S[c, c, i]
            for k in range(c):
                s -= Lc[c, k, i] * Lc[c, k, i]
            if not s > 0.0:                                      # also catches NaN
                bad[i] = True
                s = 1.0
            Lc[c, c, i] = math.sqrt(s)
            logdet[i] += math.log(s)
        for r in range(c + 1, p):
            for i in range(N):
                s = S[c, r, i]
                for k in range(c):
                    s -= Lc[r, k, i] * Lc[c, k, i]
                Lc[r, c, i] = s / Lc[c, c, i]
    for r in range(p):                                           # z = L⁻¹ v, W = L⁻¹ H P⁻
        for i in range(N):
            z[r, i] = v[r, i]
        for b in range(n):
            for i in range(N):
                W[r, b, i] = HP[r, b, i]
        for k in range(r):
            for i in range(N):
                z[r, i] -= Lc[r, k, i] * z[k, i]
            for b in range(n):
                for i in range(N):
                    W[r, b, i] -= Lc[r, k, i] * W[k, b, i]
        for i in range(N):
            z[r, i] /= Lc[r, r, i]
        for b in range(n):
            for i in range(N):
                W[r, b, i] /= Lc[r, r, i]
    for i in range(N):                                           # log N(v; 0, S)
        zz = 0.0
        for r in range(p):
            zz += z[r, i] * z[r, i]
        loglik[i] = -math.inf if bad[i] else -0.5 * (zz + logdet[i] + p * LOG_2PI)
        if bad[i]:                                               # keep the prior
            for r in range(p):
                z[r, i] = 0.0
                for b in range(n):
                    W[r, b, i] = 0.0
    for a in range(n):                                           # x = x⁻ + Wᵀ z
        for i in range(N):
            x[a, i] = xm[a, i]
        for r in range(p):
            for i in range(N):
                x[a, i] += W[r, a, i] * z[r, i]
    for a in range(n):                                           # P = P⁻ − Wᵀ W
        for b in range(a, n):
            for i in range(N):
                P[a, b, i] = Pm[a, b, i]
            for r in range(p):
                for i in range(N):
                    P[a, b, i] -= W[r, a, i] * W[r, b, i]
            for i in range(N):
                P[b, a, i] = P[a, b, i]


def _workspace(N: int, n: int, p: int) -> tuple:
    """Scratch arrays of :func:`_kalman_bank` (particles last)."""
    return (np.empty((n, n, N)), np.empty((n, n, N)), np.empty((n, n, N)), np.empty((n, N)),
            np.empty((p, n, N)), np.empty((p, p, N)), np.zeros((p, p, N)), np.empty((p, N)),
            np.empty((p, N)), np.empty((p, n, N)), np.empty(N), np.empty(N, dtype=np.bool_))


@numba.njit(cache=True)
def _normalise(lw, w):  # pragma: no cover - compiled
    """Normalised weights ``w`` from log weights ``lw`` by log-sum-exp (NaN as −inf);
    returns (log Σ exp lw, degenerate) as :func:`railpaper.engine.particles.normalise_log_weights`."""
    N = lw.shape[0]
    top = -math.inf
    for i in range(N):
        if lw[i] > top:                                          # NaN never compares greater
            top = lw[i]
    if top == math.inf:
        count = 0
        for i in range(N):
            count += lw[i] == math.inf
        for i in range(N):
            w[i] = (lw[i] == math.inf) / count
        return math.inf, True
    if top == -math.inf:
        for i in range(N):
            w[i] = 1.0 / N
        return -math.inf, True
    total = 0.0
    for i in range(N):
        w[i] = math.exp(lw[i] - top) if lw[i] == lw[i] else 0.0
        total += w[i]
    for i in range(N):
        w[i] /= total
    return top + math.log(total), False


@numba.njit(cache=True)
def _mean_cov(values, w, mean, cov):  # pragma: no cover - compiled
    """Weighted mean Σ w θ and covariance Σ w (θ − θ̄)(θ − θ̄)ᵀ (symmetric)."""
    N, d = values.shape
    for j in range(d):
        acc = 0.0
        for i in range(N):
            acc += w[i] * values[i, j]
        mean[j] = acc
    for a in range(d):
        for b in range(a, d):
            acc = 0.0
            for i in range(N):
                acc += w[i] * (values[i, a] - mean[a]) * (values[i, b] - mean[b])
            cov[a, b] = acc
            cov[b, a] = acc


@numba.njit(cache=True)
def _draws(centre, shared_centre, cov, Z, out):  # pragma: no cover - compiled
    """``out_i = centre_i + root z_i`` with ``cov = root rootᵀ`` the symmetric square root from
    ``eigh`` (negative round-off eigenvalues clipped to 0), as
    :func:`railpaper.engine.particles.gaussian_draws`."""
    N, d = out.shape
    val, vec = np.linalg.eigh(cov)
    root = np.empty((d, d))
    for a in range(d):
        for b in range(d):
            root[a, b] = vec[a, b] * math.sqrt(max(val[b], 0.0))
    for i in range(N):
        c = 0 if shared_centre else i
        for a in range(d):
            acc = 0.0
            for b in range(d):
                acc += Z[i, b] * root[a, b]
            out[i, a] = centre[c, a] + acc


@numba.njit(cache=True)
def _mixture(x, P, w, mean, std):  # pragma: no cover - compiled
    """Mean and per-component std of Σ w_i N(x_i, P_i) (x (n, N), P (n, n, N)):
    std² = Σ w (P_ii + (x_i − x̄)²); if a square overflows, the component is rescaled by its
    largest magnitude and the sum redone (as :func:`railpaper.engine.rbpf.mixture_moments_steps`)."""
    n, N = x.shape
    for a in range(n):
        acc = 0.0
        for i in range(N):
            acc += w[i] * x[a, i]
        mean[a] = acc
        acc = 0.0
        for i in range(N):
            c = x[a, i] - mean[a]
            acc += w[i] * (max(P[a, a, i], 0.0) + c * c)
        if math.isfinite(acc):
            std[a] = math.sqrt(acc)
            continue
        scale = 0.0
        for i in range(N):
            scale = max(scale, abs(x[a, i] - mean[a]), math.sqrt(max(P[a, a, i], 0.0)))
        if not (scale > 0 and math.isfinite(scale)):
            scale = 1.0
        acc = 0.0
        for i in range(N):
            c = (x[a, i] - mean[a]) / scale
            r = math.sqrt(max(P[a, a, i], 0.0)) / scale
            acc += w[i] * (r * r + c * c)
        std[a] = scale * math.sqrt(acc)


@numba.njit(cache=True)
def _search(cumulative, point, side_right):  # pragma: no cover - compiled
    """``numpy.searchsorted(cumulative, point, side)`` for one point, clipped to N − 1."""
    lo, hi = 0, cumulative.shape[0]
    while lo < hi:
        mid = (lo + hi) // 2
        if cumulative[mid] < point or (side_right and cumulative[mid] == point):
            lo = mid + 1
        else:
            hi = mid
    return min(lo, cumulative.shape[0] - 1)


@numba.njit(cache=True)
def _cumulative(w, c):  # pragma: no cover - compiled
    acc = 0.0
    for i in range(w.shape[0]):
        acc += w[i]
        c[i] = acc
    last = c[-1]
    for i in range(w.shape[0]):
        c[i] /= last


@numba.njit(cache=True)
def _gather(idx, theta, x, P):  # pragma: no cover - compiled
    """Particles ``idx`` of θ (N, d), x (n, N) and P (n, n, N), as new arrays."""
    N = idx.shape[0]
    theta_new, x_new, P_new = np.empty((N, theta.shape[1])), np.empty(x.shape), np.empty(P.shape)
    for i in range(N):
        theta_new[i] = theta[idx[i]]
    for a in range(x.shape[0]):
        for i in range(N):
            x_new[a, i] = x[a, idx[i]]
        for b in range(x.shape[0]):
            for i in range(N):
                P_new[a, b, i] = P[a, b, idx[i]]
    return theta_new, x_new, P_new


@numba.njit(cache=True)
def _log_density_or_flag(values, mean, cov, out):  # pragma: no cover - compiled
    """``out_i = log N(values_i; mean, cov)`` by Cholesky; False when ``cov`` is not positive
    definite (then ``out`` is untouched)."""
    N, d = values.shape
    L = np.zeros((d, d))
    logdet = 0.0
    for c in range(d):
        s = cov[c, c]
        for k in range(c):
            s -= L[c, k] * L[c, k]
        if not s > 0.0:
            return False
        L[c, c] = math.sqrt(s)
        logdet += 2.0 * math.log(L[c, c])
        for r in range(c + 1, d):
            s = cov[r, c]
            for k in range(c):
                s -= L[r, k] * L[c, k]
            L[r, c] = s / L[c, c]
    z = np.empty(d)
    for i in range(N):
        zz = 0.0
        for r in range(d):
            s = values[i, r] - mean[r]
            for k in range(r):
                s -= L[r, k] * z[k]
            z[r] = s / L[r, r]
            zz += z[r] * z[r]
        out[i] = -0.5 * (zz + logdet + d * LOG_2PI)
    return True


# ----------------------------------------------------------------------------- the filters
@numba.njit(cache=True)
def _qgrbpf_pass(theta, x, P, F0, Ft, B0, Bt, U, Q, H, R, Y, rng, printed, threshold, search,
                 ws, out_mean, out_std, out_x_mean, out_x_std, out_ess, out_degenerate,
                 out_log_evidence):  # pragma: no cover - compiled
    """Steps (1)–(6) of paper 004 over every row of Y (see :mod:`railpaper.engine.qgrbpf`).
    Returns the final (θ, x, P, q)."""
    N, d = theta.shape
    loglik, w, q, c = np.empty(N), np.empty(N), np.empty(N), np.empty(N)
    log_d, theta_new = np.zeros(N), np.empty((N, d))
    mean, cov = np.empty((1, d)), np.empty((d, d))
    idx = np.empty(N, dtype=np.int64)
    for k in range(Y.shape[0]):
        _kalman_bank(theta, x, P, F0, Ft, B0, Bt, U[k], Q, H, R, Y[k], loglik, ws)  # (6), (1)
        log_norm, degenerate = _normalise(loglik, w)                           # Eq. 6
        ss = 0.0
        for i in range(N):
            ss += w[i] * w[i]
        out_ess[k] = 1.0 / ss
        if threshold > 0:                                                      # threshold
            kept = 0.0
            for i in range(N):
                if w[i] >= threshold / N:
                    kept += w[i]
            if kept > 0:
                for i in range(N):
                    w[i] = w[i] / kept if w[i] >= threshold / N else 0.0
        _mean_cov(theta, w, mean[0], cov)                                      # (2): Eqs. 7-8
        _draws(mean, True, cov, rng.standard_normal((N, d)), theta_new)        # (3): Eq. 9
        flat = False
        if printed:                                                            # Eq. 10
            if not _log_density_or_flag(theta_new, mean[0], cov, log_d):
                degenerate = True                                              # singular P_k
                log_d[:] = 0.0
            _, flat = _normalise(log_d, q)                                     # Eq. 11
        else:
            for i in range(N):                                                 # d = 1
                q[i] = 1.0 / N
        _mixture(x, P, q, out_x_mean[k], out_x_std[k])                         # (4): H, R shared
        if search:                                                             # (5): Eqs. 16-17
            _cumulative(q, c)
            points = rng.random(N)
            for i in range(N):
                idx[i] = _search(c, points[i], False)
            theta, x, P = _gather(idx, theta_new, x, P)
            for i in range(N):
                q[i] = 1.0 / N
        else:
            theta = theta_new.copy()
        for j in range(d):
            out_mean[k, j] = mean[0, j]
            out_std[k, j] = math.sqrt(cov[j, j])
        out_degenerate[k] = degenerate or flat
        out_log_evidence[k] = log_norm - math.log(N)
    return theta, x, P, q


@numba.njit(cache=True)
def _liu_west(theta, w, a, h2, offset, scale, log_mask, rng, z, shrunk, mean, cov
              ):  # pragma: no cover - compiled
    """The Liu–West move of :func:`railpaper.engine.particles.liu_west_move`: on
    z = (g(θ) − offset) / scale (g = log where ``log_mask``), m_i = a z_i + (1 − a) z̄,
    z_i' ~ N(m_i, h² V); returns the new θ."""
    N, d = theta.shape
    for i in range(N):
        for j in range(d):
            v = math.log(theta[i, j]) if log_mask[j] else theta[i, j]
            z[i, j] = (v - offset[j]) / scale[j]
    _mean_cov(z, w, mean, cov)
    for i in range(N):
        for j in range(d):
            shrunk[i, j] = a * z[i, j] + (1.0 - a) * mean[j]
    for r in range(d):
        for s in range(d):
            cov[r, s] *= h2
    new = np.empty((N, d))
    _draws(shrunk, False, cov, rng.standard_normal((N, d)), new)
    for i in range(N):
        for j in range(d):
            v = new[i, j] * scale[j] + offset[j]
            new[i, j] = math.exp(v) if log_mask[j] else v
    return new


@numba.njit(cache=True)
def _rbpf_pass(theta, x, P, log_w, k0, F0, Ft, B0, Bt, U, Q, H, R, Y, rng, paper, a, h2,
               ess_fraction, tempering_steps, offset, scale, log_mask, ws, out_mean, out_std,
               out_x_mean, out_x_std, out_ess, out_degenerate, out_log_evidence,
               out_resampled):  # pragma: no cover - compiled
    """Paper 003's Steps 2.1–2.6 over every row of Y (see :mod:`railpaper.engine.rbpf`):
    ``paper``: resample and move at every step; else the working scheme (tempered increments
    over the first ``tempering_steps``, resample and move when ESS < ``ess_fraction`` N).
    Returns the final (θ, x, P, log w)."""
    N, d = theta.shape
    loglik, lw, w, c = np.empty(N), np.empty(N), np.empty(N), np.empty(N)
    mean, cov = np.empty(d), np.empty((d, d))
    z, shrunk, idx = np.empty((N, d)), np.empty((N, d)), np.empty(N, dtype=np.int64)
    uniform = 1.0 / N
    log_uniform = math.log(uniform)
    for k in range(Y.shape[0]):
        _kalman_bank(theta, x, P, F0, Ft, B0, Bt, U[k], Q, H, R, Y[k], loglik, ws)  # 2.6, 2.1
        step = k0 + k + 1
        beta = 1.0
        if not paper and step <= tempering_steps:
            beta = step / tempering_steps
        for i in range(N):
            lw[i] = log_w[i] + beta * loglik[i]
        log_norm, degenerate = _normalise(lw, w)
        _mean_cov(theta, w, mean, cov)                                         # Eq. 17
        _mixture(x, P, w, out_x_mean[k], out_x_std[k])
        ss = 0.0
        for i in range(N):
            ss += w[i] * w[i]
        ess = 1.0 / ss
        out_ess[k] = ess
        for j in range(d):
            out_mean[k, j] = mean[j]
            out_std[k, j] = math.sqrt(cov[j, j])
        out_degenerate[k] = degenerate
        out_log_evidence[k] = log_norm if beta == 1.0 else math.nan
        resample = paper or degenerate or ess < ess_fraction * N
        out_resampled[k] = resample
        if not resample:
            for i in range(N):
                log_w[i] = np.log(w[i])                                        # 0 -> -inf
            continue
        _cumulative(w, c)                                                      # 2.3: systematic
        u0 = rng.random()
        for i in range(N):
            idx[i] = _search(c, (u0 + i) / N, True)
        theta, x, P = _gather(idx, theta, x, P)
        for i in range(N):
            w[i] = uniform
            log_w[i] = log_uniform
        theta = _liu_west(theta, w, a, h2, offset, scale, log_mask, rng, z, shrunk, mean,
                          cov)                                                 # 2.5
    return theta, x, P, log_w


# ----------------------------------------------------------------------------- entry points
def applies(system, engine: str) -> bool:
    """True when the one-pass kernels can run ``system`` on ``engine``."""
    return engine == "compiled" and isinstance(system, AffineSystem)


def _matrices(system: AffineSystem, n_steps: int, u):
    n, d = system.F0.shape[0], system.n_params
    if system.B0 is None or u is None:
        B0, Bt, U = np.zeros((n, 1)), np.zeros((d, n, 1)), np.zeros((n_steps, 1))
    else:
        B0, Bt = system.B0, system.B_theta
        U = np.asarray(u, float).reshape(n_steps, -1)
    return tuple(kernel_array(M) for M in (system.F0, system.F_theta, B0, Bt, U, system.Q,
                                           system.H, system.R))


def _particles_last(x, P) -> tuple[np.ndarray, np.ndarray]:
    """(N, n), (N, n, n) → C-contiguous (n, N), (n, n, N): the kernels' layout."""
    return (kernel_array(np.asarray(x, float).T),
            kernel_array(np.asarray(P, float).transpose(1, 2, 0)))


def _particles_first(x, P) -> tuple[np.ndarray, np.ndarray]:
    """The inverse of :func:`_particles_last`."""
    return np.ascontiguousarray(x.T), np.ascontiguousarray(P.transpose(2, 0, 1))


def _outputs(n_steps: int, d: int, n: int):
    return (np.empty((n_steps, d)), np.empty((n_steps, d)), np.empty((n_steps, n)),
            np.empty((n_steps, n)), np.empty(n_steps), np.empty(n_steps, dtype=np.bool_),
            np.empty(n_steps))


def qgrbpf_pass(system: AffineSystem, theta, x, P, Y, u, rng: np.random.Generator, *,
                printed: bool, threshold: float, search: bool):
    """The Q-GRBPF over every row of ``Y`` (K, p) from particles ``theta`` (N, d) and their
    filters ``x`` (N, n), ``P`` (N, n, n).  Returns (per-step outputs, final (θ, x, P, q)):
    the outputs are mean, std (K, d), x mean, x std (K, n), ess, degenerate, log evidence
    (K,)."""
    Y = kernel_array(np.atleast_2d(np.asarray(Y, float)))
    K, (N, d) = len(Y), theta.shape
    n, p = x.shape[1], system.H.shape[0]
    out = _outputs(K, d, n)
    theta, x, P, q = _qgrbpf_pass(np.array(theta, float), *_particles_last(x, P),
                                  *_matrices(system, K, u), Y, rng, printed, float(threshold),
                                  search, _workspace(N, n, p), *out)
    return out, (theta, *_particles_first(x, P), q)


def rbpf_pass(system: AffineSystem, theta, x, P, log_w, steps_done: int, Y, u,
              rng: np.random.Generator, *, paper: bool, a: float, h2: float,
              ess_fraction: float, tempering_steps: int, offset, scale, log_mask):
    """The RBPF over every row of ``Y`` (K, p), ``steps_done`` steps into its record (the
    tempering schedule counts from there).  Liu–West constants ``a``, ``h2``; the move's
    ``offset``, ``scale`` and ``log_mask`` (d,) as :func:`railpaper.engine.particles.liu_west_move`.
    Returns (per-step outputs as :func:`qgrbpf_pass` plus ``resampled`` (K,), final
    (θ, x, P, log w))."""
    Y = kernel_array(np.atleast_2d(np.asarray(Y, float)))
    K, (N, d) = len(Y), theta.shape
    n, p = x.shape[1], system.H.shape[0]
    out = _outputs(K, d, n) + (np.empty(K, dtype=np.bool_),)
    vec = (np.zeros(d) if offset is None else np.asarray(offset, float),
           np.ones(d) if scale is None else np.asarray(scale, float),
           np.zeros(d, np.bool_) if log_mask is None else np.asarray(log_mask, np.bool_))
    theta, x, P, log_w = _rbpf_pass(
        np.array(theta, float), *_particles_last(x, P), np.array(log_w, float),
        int(steps_done), *_matrices(system, K, u), Y, rng, bool(paper), float(a), float(h2),
        float(ess_fraction), int(tempering_steps), *vec, _workspace(N, n, p), *out)
    return out, (theta, *_particles_first(x, P), log_w)
