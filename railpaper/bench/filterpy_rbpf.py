"""The baseline a researcher would write today: an RBPF as a Python list of filterpy filters.

One ``filterpy.kalman.KalmanFilter`` per particle, doing exactly the per-step work of
:class:`railpaper.engine.rbpf.RaoBlackwellisedPF` on the same data:

* the same discretisation policy — exact ZOH, ``scipy.linalg.expm`` of ``[[A dt, B dt], [0, 0]]``
  for each particle whose θ moved (every step in the paper scheme, after resampling in the
  working scheme), with ``A(θ) = A0 + Σ θ_k A_k``;
* the same likelihood — ``log N(y; H x⁻, S)`` from the filter's own ``y``, ``S`` and ``SI``
  (cheaper than filterpy's ``log_likelihood`` property, so the baseline is not handicapped);
* the same weights, estimates, resampling and Liu–West move (the library's functions, called in
  the same order with the same generator, so both filters draw the same random numbers and the
  estimates agree to rounding — the benchmark checks that).
"""

from __future__ import annotations

import numpy as np
from filterpy.kalman import KalmanFilter
from scipy.linalg import expm

from railpaper.engine import (LOG_2PI, effective_sample_size, liu_west_move, mixture_moments,
                              normalise_log_weights, systematic_resample, weighted_mean_cov)


class FilterpyRBPF:
    """RBPF over a list of filterpy filters (paper or working scheme, as the library's).

    Parameters
    ----------
    A0, Ak : ndarray
        ``A(θ) = A0 + Σ θ_k A_k``: (n, n) and (d, n, n), 1/s.
    B : ndarray, (n, m)
        Continuous input matrix.
    measurement : callable
        ``measurement(A (n, n)) -> H (p, n)``.
    dt_s : float
    Q, R : ndarray
        Discrete process-noise and measurement-noise covariances.
    theta0, x0, P0, rng, scheme, delta, ess_fraction, tempering_steps, log_mask
        As :class:`railpaper.engine.rbpf.RaoBlackwellisedPF`.
    """

    def __init__(self, A0, Ak, B, measurement, dt_s, Q, R, theta0, x0, P0, rng, *,
                 scheme="working", delta=0.9, ess_fraction=0.8, tempering_steps=0,
                 log_mask=None):
        self.A0, self.Ak, self.Bc, self.measurement, self.dt = A0, Ak, B, measurement, dt_s
        self.rng, self.scheme, self.delta = rng, scheme, delta
        self.ess_fraction, self.tempering_steps = ess_fraction, tempering_steps
        self.theta = np.array(theta0, float)
        n, m, p = A0.shape[0], B.shape[1], R.shape[0]
        self.kfs = []
        for _ in range(len(self.theta)):
            kf = KalmanFilter(dim_x=n, dim_z=p, dim_u=m)
            kf.x, kf.P, kf.Q, kf.R = np.array(x0, float)[:, None], np.array(P0, float), Q, R
            self.kfs.append(kf)
        self.log_mask = None if log_mask is None else np.asarray(log_mask, bool)
        self.offset = self.scale = None
        if scheme == "working":
            z = self.theta.copy()
            if self.log_mask is not None:
                z[:, self.log_mask] = np.log(z[:, self.log_mask])
            self.offset, self.scale = z.mean(axis=0), z.std(axis=0)
            self.scale = np.where(self.scale > 0, self.scale, 1.0)
        self.log_w = np.full(len(self.theta), -np.log(len(self.theta)))
        self.k = 0
        self._discretise()

    def _discretise(self):
        """Exact ZOH of every particle's A(θ_i), one ``scipy.linalg.expm`` each."""
        n, m = self.A0.shape[0], self.Bc.shape[1]
        for kf, th in zip(self.kfs, self.theta):
            A = self.A0 + np.tensordot(th, self.Ak, axes=1)
            M = np.zeros((n + m, n + m))
            M[:n, :n], M[:n, n:] = A * self.dt, self.Bc * self.dt
            E = expm(M)
            kf.F, kf.B, kf.H = E[:n, :n], E[:n, n:], self.measurement(A)

    def step(self, y, u):
        self.k += 1
        N, p = len(self.kfs), len(y)
        loglik = np.empty(N)
        u_col = np.asarray(u, float)[:, None]
        for i, kf in enumerate(self.kfs):
            kf.predict(u=u_col)
            kf.update(y)
            v = kf.y[:, 0]
            loglik[i] = -0.5 * (v @ kf.SI @ v + np.linalg.slogdet(kf.S)[1] + p * LOG_2PI)
        beta = 1.0
        if self.scheme == "working" and self.k <= self.tempering_steps:
            beta = self.k / self.tempering_steps
        w, _, degenerate = normalise_log_weights(self.log_w + beta * loglik)
        theta_mean, _ = weighted_mean_cov(self.theta, w)
        x = np.array([kf.x[:, 0] for kf in self.kfs])
        P = np.array([kf.P for kf in self.kfs])
        mixture_moments(x, P, w)
        ess = effective_sample_size(w)
        resample = self.scheme == "paper" or degenerate or ess < self.ess_fraction * N
        if resample:
            idx = systematic_resample(w, self.rng)
            mats = [(kf.F, kf.B, kf.H) for kf in self.kfs]
            for i, kf in enumerate(self.kfs):
                kf.x, kf.P = x[idx[i]][:, None].copy(), P[idx[i]].copy()
                kf.F, kf.B, kf.H = mats[idx[i]]
            self.theta = self.theta[idx]
            w = np.full(N, 1.0 / N)
            self.theta = liu_west_move(self.theta, w, self.delta, self.rng, self.offset,
                                       self.scale, self.log_mask)
            self._discretise()
        with np.errstate(divide="ignore"):
            self.log_w = np.log(w)
        return theta_mean
