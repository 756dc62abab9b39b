"""Quasi-Gaussian Rao–Blackwellised particle filter (Q-GRBPF), paper 004, Steps (1)–(6).

The parameter posterior is approximated by a Gaussian at every step; each parameter particle
carries a Kalman filter for the linear state (same ``system(theta)`` interface as
:mod:`railpaper.engine.rbpf`).  Step k, with the paper's equation numbers:

(6, of step k−1) KF prediction of every particle with its own matrices A(θ_i) (Eqs. 18–19).
(1) Likelihood weights ``W_k(i) = N(y_k; H x⁻_i, H P⁻_i Hᵀ + R)`` (Eqs. 3–5), normalised
    (Eq. 6) by log-sum-exp; the *weight threshold* (below) is applied here.
(2) Gaussian moments ``θ̂_k = Σ w θ_i``, ``P_k = Σ w (θ_i−θ̂)(θ_i−θ̂)ᵀ`` (Eqs. 7–8): these are
    the parameter estimate and its covariance.
(3) New particles ``θ_k(i) ~ N(θ̂_k, P_k)`` (Eq. 9) and their weights ``d_k(i)``, normalised to
    ``q_k(i)`` (Eqs. 10–11).
(4) KF measurement update of particle i's state with the matrices of the new θ_k(i)
    (Eqs. 12–15).  As printed, the new θ_k(i) inherits the prior state of old particle i.
    The compiled engine predicts once: step (1) is
    :func:`~railpaper.engine.kalman_bank.kalman_predict` (prior and likelihood, no covariance
    update) and step (4) :func:`~railpaper.engine.kalman_bank.kalman_update` of that stored prior
    with the new θ's
    H and R (the lateral model's H holds rows of A(θ)).  The numpy engine (the reference)
    runs a full predict + update in step (1) and, when H or R depend on θ, predicts again
    for step (4); when they do not (both toys) it reuses the update of step (1).
(5) "Search algorithm" (Eqs. 16–17): M = N uniforms u_p, each selects the index l with
    ``Σ_{j<l} q_j < u_p ≤ Σ_{j≤l} q_j``; (θ, x, P) of l are copied (multinomial resampling).
    On the compiled engine x, P and the matrices are copied by the next step's gather
    (``ancestors``), as the RBPF does.  When the model also gives its measurement matrices
    alone (``system.measurement(θ) -> (H, R)``, the lateral vehicle), step (4) uses those and
    the full matrices (the ZOH of A(θ)) are formed only for the θ the search keeps, about
    63 % of them (1 − 1/e): a matrix depends on its own θ only, so the results are the same.

Ambiguities and how we resolve them
-----------------------------------
* Eq. (10) prints ``d_k(i) = N(θ_k(i), P_k(i))`` with no argument and calls it an importance
  weight.  An importance weight is target / proposal.  Here the target (the Gaussian filtering
  approximation N(θ̂_k, P_k)) and the proposal (Eq. 9 draws from the same N(θ̂_k, P_k)) coincide,
  so ``d_k(i) = N(θ_k(i); θ̂_k, P_k) / N(θ_k(i); θ̂_k, P_k) = 1`` and ``q_k(i) = 1/N``
  (``weighting="ratio"``, our default).  The search in step (5) is then a uniform multinomial
  draw: it changes which KF state a θ inherits and duplicates ~37 % of the particles, but not
  the distribution of θ — consistent with the abstract's "the resampling was omitted".
  ``weighting="printed"`` takes Eq. (10) literally: ``d_k(i) = N(θ_k(i); θ̂_k, P_k)`` (density of
  the draw).  Resampling by that density squares the Gaussian, halving the parameter covariance
  at every step on top of the likelihood: a self-inflicted collapse (fast "convergence",
  over-confidence).  Both are available; the chapter compares them with the exact posterior.
* "Weight threshold" (Section IV, no value given): likelihood weights of Eq. (6) below
  ``weight_threshold / N`` are set to zero before the moments (Eqs. 7–8), then renormalised
  (kept unchanged if that would remove every particle).  With threshold c the moments ignore
  at most a mass c, so the default c = 0.01 has a small effect.
* ``search=False`` skips step (5) (the honest "resampling omitted" variant).
"""

from __future__ import annotations

from typing import Callable

import numpy as np

from railpaper.engine import affine_pass
from railpaper.engine.kalman import predict, update
from railpaper.engine.kalman_bank import kalman_predict, kalman_update
from railpaper.engine.linear_gaussian import LinearGaussianBatch
from railpaper.engine.particles import (
    effective_sample_size,
    gaussian_draws,
    gaussian_log_density,
    multinomial_search_resample,
    normalise_log_weights,
    weighted_mean_cov,
)
from railpaper.engine.rbpf import (
    ENGINES,
    FilterRun,
    StepEstimate,
    bank_step,
    initial_bank,
    mixture_moments,
    run_filter,
)
from railpaper.memory import keep_freed_memory

WEIGHTINGS = ("ratio", "printed")


def _same_measurement_model(a: LinearGaussianBatch, b: LinearGaussianBatch) -> bool:
    """True when H and R are shared (2-D) and equal in both batches."""
    return (a.H.ndim == 2 and b.H.ndim == 2 and a.R.ndim == 2 and b.R.ndim == 2
            and np.array_equal(a.H, b.H) and np.array_equal(a.R, b.R))


class QuasiGaussianRBPF:
    """Stateful Q-GRBPF; call :meth:`step` once per measurement.

    Parameters
    ----------
    system : callable
        ``system(theta (N, d)) -> LinearGaussianBatch``.
    theta0 : ndarray, (N, d)
        Initial particles (Step 1: uniform on the prior box).
    x0, P0 : ndarray
        Initial state mean (n,) and covariance (n, n) of every particle's KF.
    rng : numpy.random.Generator
    weighting : {"ratio", "printed"}
        Meaning of Eq. (10), see the module docstring.
    weight_threshold : float
        Likelihood weights below ``weight_threshold / N`` are dropped before Eqs. 7–8.
    search : bool
        Perform the search/resampling of step (5).
    engine : {"compiled", "numpy"}
        Kalman bank implementation (see :func:`railpaper.engine.rbpf.bank_step`).
    """

    def __init__(self, system: Callable[[np.ndarray], LinearGaussianBatch], theta0, x0, P0,
                 rng: np.random.Generator, *, weighting: str = "ratio",
                 weight_threshold: float = 0.01, search: bool = True, engine: str = "compiled"):
        if weighting not in WEIGHTINGS:
            raise ValueError(f"weighting must be one of {WEIGHTINGS}, got {weighting!r}")
        if engine not in ENGINES:
            raise ValueError(f"engine must be one of {ENGINES}, got {engine!r}")
        keep_freed_memory()          # the per-step arrays reuse the process's memory
        self.engine = engine
        self.system, self.rng, self.weighting = system, rng, weighting
        self.weight_threshold, self.search = float(weight_threshold), bool(search)
        self.theta, self.x, self.P, self.log_w, self.sys = initial_bank(system, theta0, x0, P0)
        # searched but not yet copied (compiled engine): particle i continues the Kalman filter
        # ancestors[i] of x, P, with the matrices of sys at matrix_rows[i] (its θ is already
        # theta[i]); the next bank call's gather copies them
        self.ancestors, self.matrix_rows = None, None
        self.measurement = getattr(system, "measurement", None)

    def _threshold(self, w: np.ndarray) -> np.ndarray:
        keep = w >= self.weight_threshold / len(w)
        if self.weight_threshold <= 0 or not keep.any():
            return w
        w = np.where(keep, w, 0.0)
        return w / w.sum()

    def materialise(self) -> None:
        """Make a pending search's copy now: afterwards particle i's Kalman filter is x[i],
        P[i] with the matrices of sys at i, as on the numpy engine.  Later steps give the same
        results either way (the kernel's gather reads the same numbers)."""
        if self.ancestors is not None:
            idx, rows = self.ancestors, self.matrix_rows
            self.ancestors, self.matrix_rows = None, None
            self.x, self.P, self.sys = self.x[idx], self.P[idx], self.sys.take(rows)

    def step(self, y: np.ndarray, u: np.ndarray | None = None) -> StepEstimate:
        """Process measurement ``y_k`` (input ``u_k`` of the transition into step k)."""
        n_particles = self.theta.shape[0]
        s = self.sys
        if self.engine == "compiled":    # x⁻, P⁻ kept for (4): no posterior covariance here
            prior, loglik = kalman_predict(self.x, self.P, s, y, u,            # (6), (1)
                                           self.ancestors, self.matrix_rows)
        else:
            x_post, P_post, loglik = bank_step(self.x, self.P, s, y, u, self.engine)  # (6), (1)
        w, log_norm, degenerate = normalise_log_weights(loglik)             # Eq. 6
        ess = effective_sample_size(w)
        w = self._threshold(w)                                              # weight threshold
        theta_hat, P_theta = weighted_mean_cov(self.theta, w)               # (2): Eqs. 7-8
        theta_new = gaussian_draws(theta_hat, P_theta, n_particles, self.rng)  # (3): Eq. 9
        log_d = np.zeros(n_particles)                                       # ratio: d = 1
        if self.weighting == "printed":                                     # d = N(θ; θ̂, P)
            try:
                log_d = gaussian_log_density(theta_new, theta_hat, P_theta)
            except np.linalg.LinAlgError:                                   # singular P_k
                degenerate = True
        q, _, flat = normalise_log_weights(log_d)                           # Eq. 11
        survivors_only = (self.engine == "compiled" and self.search
                          and self.measurement is not None)
        if survivors_only:                  # H, R now; F (the ZOH) after the search
            H_new, R_new = self.measurement(theta_new)
        else:
            s_new = self.system(theta_new)
            H_new, R_new = s_new.H, s_new.R
        if self.engine == "compiled":       # (4): Eqs. 12-15, the old particle's prediction,
            x, P, _ = kalman_update(prior, y, H_new, R_new)                   # the new θ's H, R
        elif _same_measurement_model(s, s_new):
            x, P = x_post, P_post            # H, R do not depend on θ: same update as in (1)
        else:
            x_prior, P_prior = predict(self.x, self.P, s.F, s.Q, s.B, u)
            x, P, _, _, _ = update(x_prior, P_prior, y, s_new.H, s_new.R)
        x_mean, x_std = mixture_moments(x, P, q)
        ancestors = rows = None
        if self.search:                                                     # (5): Eqs. 16-17
            idx = multinomial_search_resample(q, self.rng)
            if survivors_only:                # matrices of the kept θ only, once each
                kept, rows = np.unique(idx, return_inverse=True)
                s_new = self.system(theta_new[kept])
            theta_new = theta_new[idx]
            if self.engine == "compiled":     # x, P, matrices copied by the next gather
                ancestors = idx
                rows = idx if rows is None else rows
            else:
                x, P, s_new = x[idx], P[idx], s_new.take(idx)
            q = np.full(n_particles, 1.0 / n_particles)
        with np.errstate(divide="ignore"):
            self.log_w = np.log(q)
        self.theta, self.x, self.P, self.sys = theta_new, x, P, s_new
        self.ancestors, self.matrix_rows = ancestors, rows
        return StepEstimate(theta_mean=theta_hat, theta_std=np.sqrt(np.diag(P_theta)),
                            x_mean=x_mean, x_std=x_std, ess=ess,
                            degenerate=bool(degenerate or flat),
                            log_evidence=log_norm - np.log(n_particles), resampled=self.search)


    def run_record(self, Y: np.ndarray, U: np.ndarray | None = None) -> FilterRun | None:
        """Every row of ``Y`` in one compiled pass (:mod:`railpaper.engine.affine_pass`) when
        the model is an :class:`~railpaper.engine.linear_gaussian.AffineSystem` and the engine
        compiled: the same draws and, to rounding, the same estimates as :meth:`step` row by
        row.  None (nothing done) otherwise."""
        if not affine_pass.applies(self.system, self.engine):
            return None
        self.materialise()
        (mean, std, x_mean, x_std, ess, degenerate, log_evidence), (theta, x, P, q) = \
            affine_pass.qgrbpf_pass(self.system, self.theta, self.x, self.P, Y, U, self.rng,
                                    printed=self.weighting == "printed",
                                    threshold=self.weight_threshold, search=self.search)
        with np.errstate(divide="ignore"):
            self.log_w = np.log(q)
        self.theta, self.x, self.P, self.sys = theta, x, P, self.system(theta)
        return FilterRun(theta_mean=mean, theta_std=std, x_mean=x_mean, x_std=x_std, ess=ess,
                         resampled=np.full(len(mean), self.search), degenerate=degenerate,
                         log_evidence=log_evidence, theta=theta.copy(), weights=q.copy())


def run_qgrbpf(system, y, theta0, x0, P0, rng, *, u=None, **options) -> FilterRun:
    """Run :class:`QuasiGaussianRBPF` over ``y`` (K, p) with inputs ``u`` (K, m) or None."""
    return run_filter(QuasiGaussianRBPF(system, theta0, x0, P0, rng, **options), y, u)
