"""One Rao–Blackwellised particle filter (RBPF) for static parameters of linear-Gaussian models.

Particles carry parameter vectors θ_i (N, d); each particle carries its own Kalman filter for
the linear state, run with the matrices ``system(θ_i)``.  The model is a callable
``system(theta (N, d)) -> LinearGaussianBatch`` (see :mod:`railpaper.engine.linear_gaussian`), so the
same engine serves paper 004's toy, paper 003's Eq. (18) toy and paper 003's lateral vehicle
model (where ``system`` discretises A(θ) per particle).  ``system`` is called only when θ
changes; resampling reuses the matrices by index.

Step k (paper 003, Steps 2.1–2.6; Step 2.6 of step k−1 is done first here):

1. KF prediction of every particle's state with its own matrices (and the known input u_k);
2. KF measurement update; its predictive log-likelihood ``log N(y_k; H x⁻, S)`` updates the
   log weight (paper 003 Step 2.1, paper 004 Eqs. 3–6);
3. estimates: weighted parameter mean/std (paper 003 Eq. 17), mixture state mean/std, ESS;
4. resampling (systematic, paper 003 Step 2.3);
5. Liu–West kernel move of θ (paper 003 Eq. 12 / Step 2.5); new matrices ``system(θ)``.

Schemes
-------
``scheme="paper"``
    Resample AND move at every step, as papers 003 and 004 describe.
``scheme="working"``
    Resample only when ESS < ``ess_fraction`` N; move only right after resampling; the move is
    made on normalised parameters (offset/scale from the initial cloud unless given); optional
    likelihood tempering: weight increments multiplied by ``min(1, k / tempering_steps)`` over
    the first ``tempering_steps`` steps (this flattens the early posterior on purpose).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np

from railpaper.engine import affine_pass
from railpaper.engine.kalman import predict, update
from railpaper.engine.kalman_bank import kalman_run, kalman_step
from railpaper.engine.linear_gaussian import LinearGaussianBatch
from railpaper.engine.particles import (
    effective_sample_size,
    liu_west_move,
    liu_west_shrinkage,
    normalise_log_weights,
    systematic_resample,
    weighted_mean_cov,
)
from railpaper.memory import keep_freed_memory

SCHEMES = ("paper", "working")
ENGINES = ("compiled", "numpy")


def bank_step(x, P, system: LinearGaussianBatch, y, u, engine: str, ancestors=None):
    """Predict + update of every particle's Kalman filter: ``(x, P, log-likelihood)``.

    ``engine="compiled"``: the fused kernel of :mod:`railpaper.engine.kalman_bank`;
    ``"numpy"``: the textbook :func:`predict` + Joseph-form :func:`update` (the reference).
    Filter i starts from ``x[ancestors[i]], P[ancestors[i]]`` when ``ancestors`` is given.
    """
    if engine == "compiled":
        return kalman_step(x, P, system, y, u, ancestors)
    if ancestors is not None:
        x, P = x[ancestors], P[ancestors]
    x_prior, P_prior = predict(x, P, system.F, system.Q, system.B, u)
    x, P, loglik, _, _ = update(x_prior, P_prior, y, system.H, system.R)
    return x, P, loglik


@dataclass
class StepEstimate:
    """What one step of a parameter filter (:class:`RaoBlackwellisedPF`, the Q-GRBPF) returns.

    Attributes
    ----------
    theta_mean, theta_std : ndarray, (d,)
        Weighted mean and standard deviation of the parameter particles (paper 003 Eq. 17),
        in the parameters' units.
    x_mean, x_std : ndarray, (n,), or None
        Mixture mean and standard deviation of the linear state (None until filled in by
        :meth:`RaoBlackwellisedPF.steps`), in the state's units.
    ess : float
        Effective sample size of the step's weights (particles).
    degenerate : bool
        Every weight underflowed (the model cannot explain the measurement).
    log_evidence : float
        log p(y_k | y_1..k-1) of the step (nan while tempering).
    resampled : bool
        The particles were resampled after this step.
    """

    theta_mean: np.ndarray
    theta_std: np.ndarray
    x_mean: np.ndarray | None
    x_std: np.ndarray | None
    ess: float
    degenerate: bool
    log_evidence: float
    resampled: bool


@dataclass
class FilterRun:
    """Per-step outputs of a parameter filter over K steps (row k-1 = after y_k).

    Attributes
    ----------
    theta_mean, theta_std : ndarray, (K, d)
        Weighted mean and standard deviation of the parameter particles.
    x_mean, x_std : ndarray, (K, n)
        Mixture mean and standard deviation of the linear state.
    ess : ndarray, (K,)
        Effective sample size of the weights used for the estimate.
    resampled : ndarray of bool, (K,)
    degenerate : ndarray of bool, (K,)
        Weights could not be normalised (all −inf/NaN) and fell back to uniform.
    log_evidence : ndarray, (K,)
        Particle estimate of log p(y_k | y_1..k-1) (untempered steps only; NaN otherwise).
    theta, weights : ndarray
        Final particles (N, d) and their normalised weights (N,).
    """

    theta_mean: np.ndarray
    theta_std: np.ndarray
    x_mean: np.ndarray
    x_std: np.ndarray
    ess: np.ndarray
    resampled: np.ndarray
    degenerate: np.ndarray
    log_evidence: np.ndarray
    theta: np.ndarray
    weights: np.ndarray


def mixture_moments(x: np.ndarray, P: np.ndarray, weights: np.ndarray
                    ) -> tuple[np.ndarray, np.ndarray]:
    """Mean and per-component std of the Gaussian mixture Σ w_i N(x_i, P_i)."""
    return mixture_moments_var(x, np.diagonal(P, axis1=-2, axis2=-1), weights)


def mixture_moments_var(x: np.ndarray, var: np.ndarray, weights: np.ndarray
                        ) -> tuple[np.ndarray, np.ndarray]:
    """:func:`mixture_moments` from the components' variances ``var`` (N, n) = diag P_i."""
    mean, std = mixture_moments_steps(x[:, None], var[:, None], weights[None])
    return mean[0], std[0]


def mixture_moments_steps(x: np.ndarray, var: np.ndarray, weights: np.ndarray
                          ) -> tuple[np.ndarray, np.ndarray]:
    """Mixture mean and std for J steps at once: x, var (N, J, n), weights (J, N) → (J, n).

    ``std² = Σ w (P_ii + (x_i − x̄)²)``, centred first; if a square overflows (states of
    1e160), the components are rescaled by their largest magnitude and the sum redone.
    """
    mean = np.einsum("jn,njd->jd", weights, x)
    centred, var = x - mean, np.clip(var, 0.0, None)
    with np.errstate(over="ignore", invalid="ignore"):
        spread = np.einsum("jn,njd->jd", weights, var + centred * centred)
    if np.all(np.isfinite(spread)):
        return mean, np.sqrt(spread)
    scale = np.maximum(np.abs(centred).max(axis=0), np.sqrt(var.max(axis=0)))
    scale = np.where((scale > 0) & np.isfinite(scale), scale, 1.0)   # no overflow in squares
    spread = np.einsum("jn,njd->jd", weights, (np.sqrt(var) / scale) ** 2 + (centred / scale) ** 2)
    return mean, scale * np.sqrt(spread)


def initial_bank(system: Callable[[np.ndarray], LinearGaussianBatch], theta0, x0, P0):
    """Step 1 of both filters: the particle bank.

    Returns
    -------
    theta : (N, d) parameter particles; x : (N, n) and P : (N, n, n) every particle's Kalman
    mean and covariance; log_w : (N,) uniform log-weights; sys : ``system(theta)``.
    """
    theta = np.array(theta0, dtype=float, ndmin=2)
    n_particles = theta.shape[0]
    x0, P0 = np.asarray(x0, float), np.asarray(P0, float)
    x = np.broadcast_to(x0, (n_particles, x0.shape[-1])).copy()
    P = np.broadcast_to(P0, (n_particles,) + P0.shape[-2:]).copy()
    return theta, x, P, np.full(n_particles, -np.log(n_particles)), system(theta)


class RaoBlackwellisedPF:
    """Stateful RBPF; call :meth:`step` once per measurement (usable in real time).

    Parameters
    ----------
    system : callable
        ``system(theta (N, d)) -> LinearGaussianBatch``.
    theta0 : ndarray, (N, d)
        Initial parameter particles (e.g. uniform on the prior box).
    x0 : ndarray, (n,) or (N, n)
        Initial state mean of every particle's Kalman filter.
    P0 : ndarray, (n, n) or (N, n, n)
        Initial state covariance.
    rng : numpy.random.Generator
        The only source of randomness.
    scheme : {"paper", "working"}
    delta : float
        Liu–West discount factor δ (a = (3δ−1)/(2δ), h² = 1 − a²).
    move : bool
        False disables the Liu–West move (parameters then only resampled).
    ess_fraction : float
        "working": resample when ESS < ess_fraction · N.
    tempering_steps : int
        "working": likelihood tempering over the first steps (0 = off).
    offset, scale : ndarray, (d,), optional
        Normalisation of the (log-)parameters for the move ("working" default: mean and std of
        the initial cloud; "paper": none).
    log_mask : ndarray of bool, (d,), optional
        Parameters moved in log space (must be positive).
    engine : {"compiled", "numpy"}
        Kalman bank implementation (see :func:`bank_step`).

    :meth:`step` calls the bank through the attribute ``bank_step`` (:func:`bank_step`), so a
    profiler can time it on one filter by wrapping ``filt.bank_step``, as it wraps
    ``filt.system``.
    """

    bank_step = staticmethod(bank_step)

    def __init__(self, system: Callable[[np.ndarray], LinearGaussianBatch], theta0, x0, P0,
                 rng: np.random.Generator, *, scheme: str = "paper", delta: float = 0.98,
                 move: bool = True, ess_fraction: float = 0.5, tempering_steps: int = 0,
                 offset=None, scale=None, log_mask=None, engine: str = "compiled"):
        if scheme not in SCHEMES:
            raise ValueError(f"scheme must be one of {SCHEMES}, got {scheme!r}")
        if engine not in ENGINES:
            raise ValueError(f"engine must be one of {ENGINES}, got {engine!r}")
        keep_freed_memory()          # the per-step arrays reuse the process's memory
        self.engine = engine
        self.system, self.rng, self.scheme = system, rng, scheme
        self.delta, self.move = float(delta), bool(move)
        self.ess_fraction, self.tempering_steps = float(ess_fraction), int(tempering_steps)
        self.theta, self.x, self.P, self.log_w, self.sys = initial_bank(system, theta0, x0, P0)
        self.log_mask = None if log_mask is None else np.asarray(log_mask, bool)
        if scheme == "working" and offset is None and scale is None:
            z = self.theta.copy()
            if self.log_mask is not None:
                z[:, self.log_mask] = np.log(z[:, self.log_mask])
            offset, scale = z.mean(axis=0), z.std(axis=0)
            scale = np.where(scale > 0, scale, 1.0)
        self.offset, self.scale = offset, scale
        self.ancestors = None        # resampled but not yet copied: the bank's gather copies
        self.k = 0

    def step(self, y: np.ndarray, u: np.ndarray | None = None) -> StepEstimate:
        """Process measurement ``y_k`` (input ``u_k`` of the transition into step k)."""
        x, P, loglik = self.bank_step(self.x, self.P, self.sys, y, u, self.engine,  # Steps 2.6,
                                      self.ancestors)                             # 2.1, 2.4
        out, w = self._weigh(loglik, x, np.diagonal(P, axis1=-2, axis2=-1))
        self._finish(w, out.resampled, x, P)
        return out

    def steps(self, Y: np.ndarray, U: np.ndarray | None = None, max_chunk: int = 32
              ) -> list[StepEstimate]:
        """Process measurements ``Y`` (K, p): the same results as K calls of :meth:`step`.

        With the working scheme on the compiled engine, the particles' matrices are fixed
        between resampling events, so the Kalman bank runs over chunks of steps in one call
        (:func:`railpaper.engine.kalman_bank.kalman_run`, bit-identical to step by step);
        weights, estimates and the resampling test are still evaluated at every step, and a
        chunk is cut back to the step where resampling happens (the bank is re-run up to that
        step, since its covariances are not stored per step).  The chunk length adapts:
        doubled (up to ``max_chunk``) after a chunk without resampling, else half the number
        of steps the last chunk lasted (on paper 003's lateral run this re-runs ≈ 50 % extra
        bank steps while resampling is frequent, ≈ 6 % once it has settled).
        """
        Y = np.asarray(Y, float)
        if self.engine != "compiled" or self.scheme != "working":
            return [self.step(Y[k], None if U is None else U[k]) for k in range(len(Y))]
        outputs, k0, chunk = [], 0, 1
        while k0 < len(Y):
            Yc = Y[k0:k0 + chunk]
            Uc = None if U is None else np.asarray(U, float)[k0:k0 + chunk]
            x_end, P_end, loglik, x_hist, var_hist = kalman_run(
                self.x, self.P, self.sys, Yc, Uc, record=True, ancestors=self.ancestors)
            weights = []
            for j in range(len(Yc)):
                out, w = self._weigh(loglik[:, j])
                outputs.append(out)
                weights.append(w)
                if out.resampled:
                    break
                with np.errstate(divide="ignore"):
                    self.log_w = np.log(w)
            means, stds = mixture_moments_steps(x_hist[:, :j + 1], var_hist[:, :j + 1],
                                                np.array(weights))
            for o, mean, std in zip(outputs[-(j + 1):], means, stds):
                o.x_mean, o.x_std = mean, std
            if out.resampled:
                if j < len(Yc) - 1:                    # the bank's state after step j
                    x_end, P_end, _ = kalman_run(self.x, self.P, self.sys, Yc[:j + 1],
                                                 None if Uc is None else Uc[:j + 1],
                                                 ancestors=self.ancestors)
                self._finish(w, True, x_end, P_end)
                chunk = max(1, (j + 1) // 2)
            else:
                self.x, self.P, self.ancestors = x_end, P_end, None
                chunk = min(2 * chunk, max_chunk)
            k0 += j + 1
        return outputs

    def run_record(self, Y: np.ndarray, U: np.ndarray | None = None) -> FilterRun | None:
        """Every row of ``Y`` in one compiled pass (:mod:`railpaper.engine.affine_pass`) when
        the model is an :class:`~railpaper.engine.linear_gaussian.AffineSystem`, the engine
        compiled and the move on: the same draws and, to rounding, the same estimates as
        :meth:`step` row by row.  None (nothing done) otherwise."""
        if not (affine_pass.applies(self.system, self.engine) and self.move):
            return None
        x, P = self.x, self.P
        if self.ancestors is not None:                   # a pending resampling's copy
            x, P = x[self.ancestors], P[self.ancestors]
        a, h2 = liu_west_shrinkage(self.delta)
        (mean, std, x_mean, x_std, ess, degenerate, log_evidence, resampled), \
            (theta, x, P, log_w) = affine_pass.rbpf_pass(
                self.system, self.theta, x, P, self.log_w, self.k, Y, U, self.rng,
                paper=self.scheme == "paper", a=a, h2=h2, ess_fraction=self.ess_fraction,
                tempering_steps=self.tempering_steps, offset=self.offset, scale=self.scale,
                log_mask=self.log_mask)
        self.k += len(mean)
        self.theta, self.x, self.P, self.log_w = theta, x, P, log_w
        self.sys, self.ancestors = self.system(theta), None
        return FilterRun(theta_mean=mean, theta_std=std, x_mean=x_mean, x_std=x_std, ess=ess,
                         resampled=resampled, degenerate=degenerate,
                         log_evidence=log_evidence, theta=theta.copy(), weights=np.exp(log_w))

    def _weigh(self, loglik: np.ndarray, x: np.ndarray | None = None,
               var: np.ndarray | None = None) -> tuple[StepEstimate, np.ndarray]:
        """Weights, estimates and the resampling decision of step k from its log-likelihoods
        (the state moments only when x and var = diag P are given)."""
        self.k += 1
        n_particles = self.theta.shape[0]
        beta = 1.0
        if self.scheme == "working" and self.k <= self.tempering_steps:
            beta = self.k / self.tempering_steps
        w, log_norm, degenerate = normalise_log_weights(self.log_w + beta * loglik)
        theta_mean, theta_cov = weighted_mean_cov(self.theta, w)                # Eq. 17
        x_mean, x_std = (None, None) if x is None else mixture_moments_var(x, var, w)
        ess = effective_sample_size(w)
        resample = (self.scheme == "paper" or degenerate
                    or ess < self.ess_fraction * n_particles)
        out = StepEstimate(theta_mean=theta_mean, theta_std=np.sqrt(np.diag(theta_cov)),
                           x_mean=x_mean, x_std=x_std, ess=ess, degenerate=degenerate,
                           log_evidence=log_norm if beta == 1.0 else np.nan, resampled=resample)
        return out, w

    def _finish(self, w: np.ndarray, resample: bool, x: np.ndarray, P: np.ndarray) -> None:
        """Resampling (Step 2.3) and Liu–West move (Step 2.5) after step k's update."""
        n_particles = self.theta.shape[0]
        theta, sys, ancestors = self.theta, self.sys, None
        moved = self.move and (self.scheme == "paper" or resample)
        if resample:                                                            # Step 2.3
            idx = systematic_resample(w, self.rng)
            theta = theta[idx]
            if self.engine == "compiled":         # x, P copied by the next bank call's gather
                ancestors = idx
            else:
                x, P = x[idx], P[idx]
            if not moved:                         # a move makes new matrices anyway
                sys = sys.take(idx)
            w = np.full(n_particles, 1.0 / n_particles)
        if moved:                                                               # Step 2.5
            theta = liu_west_move(theta, w, self.delta, self.rng, self.offset, self.scale,
                                  self.log_mask)
            sys = self.system(theta)
        with np.errstate(divide="ignore"):
            self.log_w = np.log(w)
        self.theta, self.x, self.P, self.sys, self.ancestors = theta, x, P, sys, ancestors


def stack_steps(outputs: list[StepEstimate], theta: np.ndarray, weights: np.ndarray
                ) -> FilterRun:
    """Stack per-step estimates into a :class:`FilterRun`."""
    def col(key, dtype=float):
        return np.array([getattr(o, key) for o in outputs], dtype=dtype)
    return FilterRun(theta_mean=col("theta_mean"), theta_std=col("theta_std"),
                     x_mean=col("x_mean"), x_std=col("x_std"), ess=col("ess"),
                     resampled=col("resampled", bool), degenerate=col("degenerate", bool),
                     log_evidence=col("log_evidence"), theta=theta, weights=weights)


def run_filter(filt, y: np.ndarray, u: np.ndarray | None = None) -> FilterRun:
    """Run a stateful parameter filter (RBPF or Q-GRBPF) over measurements y (K, p): in one
    compiled pass where the filter's ``run_record`` can, else step by step."""
    y = np.asarray(y, float)
    whole = getattr(filt, "run_record", None)
    run = None if whole is None else whole(y, u)
    if run is not None:
        return run
    if hasattr(filt, "steps"):
        outputs = filt.steps(y, u)
    else:
        outputs = [filt.step(y[k], None if u is None else u[k]) for k in range(len(y))]
    return stack_steps(outputs, filt.theta.copy(), np.exp(filt.log_w))


def run_rbpf(system, y, theta0, x0, P0, rng, *, u=None, **options) -> FilterRun:
    """Run :class:`RaoBlackwellisedPF` over ``y`` (K, p) with inputs ``u`` (K, m) or None.

    ``options`` are the keyword options of :class:`RaoBlackwellisedPF`.
    """
    return run_filter(RaoBlackwellisedPF(system, theta0, x0, P0, rng, **options), y, u)
