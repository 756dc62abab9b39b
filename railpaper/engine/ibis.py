"""IBIS: a sequential Monte Carlo sampler of the exact posterior of static parameters.

For linear-Gaussian models with static parameters θ (``system(θ) -> LinearGaussianBatch``), a
Kalman filter gives the exact likelihood ``p(y_1..t | θ)``.  IBIS (Chopin 2002, *Biometrika* 89,
539–551) carries N particles θ_i, each with its Kalman state (x_i, P_i), and targets the exact
posterior ``π_t(θ) ∝ p(y_1..t | θ) 1_box(θ)`` after every step t — no artificial parameter
noise, no tempering:

1. θ_i ~ U(box), weights 1/N, (x_i, P_i) = (x0, P0);
2. step t: Kalman predict + update of every particle; log w_i += log N(y_t; H x⁻_i, S_i)
   (log-sum-exp normalisation); the cumulative log-likelihood ℓ_i = log p(y_1..t | θ_i) is kept;
3. if ESS < ``ess_fraction`` N: systematic resampling, then MCMC moves that leave π_t
   invariant.  A move proposes θ' for every particle and reruns the compiled Kalman bank over
   steps 1..t for all proposals in one :func:`~railpaper.engine.kalman_bank.kalman_run`
   call: this gives ℓ(θ') (the Metropolis–Hastings ratio uses the full-history likelihood) and
   the proposals' Kalman state at t.  Moves are repeated (``min_moves`` ≤ moves ≤
   ``max_moves``) until the particles have moved away from their resampled positions: the mean
   squared Mahalanobis displacement D = mean_i ‖θ_i − θ_i⁰‖²_Σ⁻¹ (Σ: the posterior covariance
   before resampling) reaches ``decorrelation`` · 2d.  Two independent posterior draws have
   E D = 2d, and a move kernel with lag correlation ρ gives E D = 2d (1 − ρ), so
   ``decorrelation`` is the 1 − ρ asked for (the stopping rule of the ``particles`` package's
   adaptive move sequence measures the same displacement).

Proposals, in the natural parameters (the prior is uniform on the box there, so no Jacobian is
needed and a proposal outside the box is rejected without a likelihood evaluation):

``"rw"``  (default) Gaussian random walk θ' = θ + N(0, c Σ) with c starting at 2.38²/d and
          adapted between moves, log c += acceptance − ``target_acceptance`` (Σ from the
          weighted particles before resampling: the random walk is affine-invariant, so the
          parameters' units do not matter).  Robust to non-Gaussian, box-truncated posteriors.
``"independent"`` θ' ~ N(θ̄, ``independent_inflation``² Σ) fitted to the particles (Chopin's
          original choice): a fresh draw per accepted move, efficient once the posterior is
          near-Gaussian, poor while it is not (early steps, box edges).

Cost: a move costs N × t filter steps (every proposal's filter re-runs steps 1..t), so the total
is dominated by the late resampling events and by the number of moves per event: ``min_moves =
1`` lets the displacement rule stop after one move once the proposal fits the posterior (the
independent proposal then decorrelates in one accepted draw), ``min_moves = 2`` always pays two.

Waste-free moves (``chain_length`` P > 1; Dau & Chopin 2022, *JRSS B* 84, 114–148, as in the
``particles`` package's ``smc_samplers``): resample only M = N / P chain starts and keep every
state of their P-long MH chains, so an event costs N − M full-history evaluations instead of
(number of moves) × N.  The particles are then more correlated (each chain start is kept, and
resampled starts repeat), so at equal N the posterior summaries carry more Monte Carlo error;
whether fewer evaluations at more error pays depends on the model and on how cheap a small
bank's evaluation is (both kinds of move are checked against exact posteriors in the tests).

Between resampling events the particles' matrices are fixed, so the bank runs over chunks of
steps in one call (as :meth:`railpaper.engine.rbpf.RaoBlackwellisedPF.steps`); the chunk is
re-run up to the step where the ESS drops.  Per-step summaries (mean, sd, 5 %/95 % weighted
quantiles) use the weights of that step before any resampling.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np

from railpaper.engine.kalman_bank import kalman_run
from railpaper.engine.linear_gaussian import (LinearGaussianBatch, concat_systems,
                                              merge_systems)
from railpaper.engine.particles import (gaussian_log_density, normalise_log_weight_columns,
                                        systematic_resample, weighted_mean_cov,
                                        weighted_quantiles)
from railpaper.memory import keep_freed_memory

PROPOSALS = ("rw", "independent")


@dataclass(frozen=True)
class IBISRun:
    """Posterior summaries of θ after every step (row k−1 = after y_1..y_k) and sampler costs.

    Units of θ are those of the model's parameters (``system``'s argument).

    Attributes
    ----------
    mean, sd : ndarray, (K, d)
        Weighted posterior mean and standard deviation of θ.
    q05, q95 : ndarray, (K, d)
        Weighted 5 % and 95 % posterior quantiles (inverse of the weighted empirical CDF):
        the 90 % equal-tailed credible interval.
    ess : ndarray, (K,)
        Effective sample size ``1 / Σ w²`` of the weights of each step (before resampling).
    log_evidence : ndarray, (K,)
        Particle estimate of ``log p(y_k | y_1..k−1)`` (natural log).
    resample_steps : ndarray of int, (R,)
        Steps (1-based) after whose update the particles were resampled and moved.
    n_moves : ndarray of int, (R,)
        MCMC moves made at each resampling event.
    acceptance : ndarray, (R,)
        Mean acceptance rate over the moves of each event (a proposal outside the box counts
        as rejected).
    displacement : ndarray, (R,)
        Mean squared Mahalanobis displacement D / (2d) reached at each event (1: as far as
        independent draws).
    moved_fraction : ndarray, (R,)
        Fraction of particles that accepted at least one move at each event.
    n_loglik_evals : int
        Full-history likelihood evaluations (one per proposal inside the box).
    n_filter_steps : int
        Kalman filter steps run in total (particles × steps, reweighting, re-runs and moves):
        the sampler's cost.
    theta : ndarray, (N, d)
        Final particles.
    weights : ndarray, (N,)
        Their normalised weights.
    loglik : ndarray, (N,)
        Their full-history log-likelihoods ``log p(y_1..K | θ_i)``.
    lower, upper : ndarray, (d,)
        The uniform prior box.
    """

    mean: np.ndarray
    sd: np.ndarray
    q05: np.ndarray
    q95: np.ndarray
    ess: np.ndarray
    log_evidence: np.ndarray
    resample_steps: np.ndarray
    n_moves: np.ndarray
    acceptance: np.ndarray
    displacement: np.ndarray
    moved_fraction: np.ndarray
    n_loglik_evals: int
    n_filter_steps: int
    theta: np.ndarray
    weights: np.ndarray
    loglik: np.ndarray
    lower: np.ndarray
    upper: np.ndarray


def credible_interval_covers(run: IBISRun, truth, step: int | None = None) -> np.ndarray:
    """Whether each parameter's 90 % credible interval [q05, q95] after ``step`` holds the truth.

    Parameters
    ----------
    run : IBISRun
    truth : array_like, (d,)
        True parameter values (units of θ).
    step : int, optional
        1-based step (default: the last).

    Returns
    -------
    covers : ndarray of bool, (d,)
    """
    k = run.mean.shape[0] if step is None else int(step)
    if not 1 <= k <= run.mean.shape[0]:
        raise ValueError(f"step must be in 1..{run.mean.shape[0]}, got {k}")
    truth = np.asarray(truth, float)
    return (run.q05[k - 1] <= truth) & (truth <= run.q95[k - 1])


class _Sampler:
    """The particle system of one IBIS run (see :func:`run_ibis`)."""

    def __init__(self, system, y, u, lower, upper, x0, P0, rng, theta0, opts):
        self.system, self.y, self.u, self.rng, self.o = system, y, u, rng, opts
        self.lower, self.upper = lower, upper
        self.x0, self.P0 = np.asarray(x0, float), np.asarray(P0, float)
        d = lower.size
        self.theta = (rng.uniform(lower, upper, (opts["n_particles"], d)) if theta0 is None
                      else np.array(theta0, float).reshape(-1, d))
        N = self.theta.shape[0]
        self.x, self.P = self._initial_state(N)
        self.sys = system(self.theta)
        self.log_w = np.full(N, -np.log(N))
        self.loglik = np.zeros(N)
        self.scale = 2.38 ** 2 / d
        self.events: list[tuple[int, int, float, float, float]] = []
        self.n_evals, self.n_steps_run = 0, 0

    def _initial_state(self, n):
        n_x = self.x0.shape[-1]
        return (np.broadcast_to(self.x0, (n, n_x)).copy(),
                np.broadcast_to(self.P0, (n, n_x, n_x)).copy())

    def bank(self, x, P, sys, k0, k1):
        """Kalman bank over steps k0+1..k1 (0-based slice k0:k1): (x, P, loglik (M, k1−k0))."""
        U = None if self.u is None else self.u[k0:k1]
        self.n_steps_run += x.shape[0] * (k1 - k0)
        return kalman_run(x, P, sys, self.y[k0:k1], U)

    def resample_move(self, t: int, weights: np.ndarray) -> None:
        """Resample (systematic) and move with π_t-invariant MH kernels; t steps are done."""
        mean, cov = weighted_mean_cov(self.theta, weights)
        if self.o["rejuvenate"] and self.o["chain_length"] > 1:
            self._waste_free(t, weights, mean, jittered_cholesky(cov, self.upper - self.lower))
            return
        idx = systematic_resample(weights, self.rng)
        self.theta, self.x, self.P = self.theta[idx], self.x[idx], self.P[idx]
        self.loglik, self.sys = self.loglik[idx], self.sys.take(idx)
        N, d = self.theta.shape
        self.log_w = np.full(N, -np.log(N))
        if not self.o["rejuvenate"]:
            self.events.append((t, 0, np.nan, 0.0, 0.0))
            return
        root = jittered_cholesky(cov, self.upper - self.lower)
        start, moved, rates, m, D = self.theta.copy(), np.zeros(N, bool), [], 0, 0.0
        while m < self.o["max_moves"]:
            accept = self._move(t, mean, root, self)
            moved |= accept
            rates.append(accept.mean())
            m += 1
            self._adapt(rates[-1])
            D = self._displacement(start, self.theta, root)
            if m >= self.o["min_moves"] and D >= self.o["decorrelation"]:
                break
        self.events.append((t, m, float(np.mean(rates)), D, float(moved.mean())))

    def _waste_free(self, t: int, weights: np.ndarray, mean: np.ndarray, root: np.ndarray
                    ) -> None:
        """Waste-free rejuvenation (Dau & Chopin 2022): M = N / P chain starts drawn from the
        weighted particles, each moved P − 1 times by the MH kernel; all M P states of the
        chains, starts included, are the new particles, with equal weights."""
        P_len = self.o["chain_length"]
        N = self.theta.shape[0]
        M = N // P_len
        idx = systematic_resample(weights, self.rng, M)
        head = _Chains(self.theta[idx], self.x[idx], self.P[idx], self.loglik[idx],
                       self.sys.take(idx))
        states, start, moved, rates = [head.snapshot()], head.theta.copy(), np.zeros(M, bool), []
        for _ in range(P_len - 1):
            accept = self._move(t, mean, root, head)
            moved |= accept
            rates.append(accept.mean())
            self._adapt(rates[-1])
            states.append(head.snapshot())
        self.theta = np.concatenate([c.theta for c in states])
        self.x = np.concatenate([c.x for c in states])
        self.P = np.concatenate([c.P for c in states])
        self.loglik = np.concatenate([c.loglik for c in states])
        self.sys = concat_systems([c.sys for c in states], [M] * P_len)
        self.log_w = np.full(N, -np.log(N))
        D = self._displacement(start, head.theta, root)
        self.events.append((t, P_len - 1, float(np.mean(rates)), D, float(moved.mean())))

    def _adapt(self, rate: float) -> None:
        """Random walk: log c += acceptance − target (bounded)."""
        if self.o["proposal"] == "rw":
            self.scale = float(np.clip(self.scale * np.exp(rate - self.o["target_acceptance"]),
                                       1e-4, 10.0))

    @staticmethod
    def _displacement(start: np.ndarray, theta: np.ndarray, root: np.ndarray) -> float:
        """D / (2d): mean squared Mahalanobis displacement from ``start``, Σ = root rootᵀ."""
        white = np.linalg.solve(root, (theta - start).T)                # (d, N)
        return float(np.mean(np.sum(white * white, axis=0))) / (2 * start.shape[1])

    def _move(self, t, mean, root, pop) -> np.ndarray:
        """One MH move of every particle of ``pop`` (the sampler itself, or the heads of
        waste-free chains: anything with theta, x, P, loglik, sys), updated in place;
        returns which particles accepted (M,)."""
        N, d = pop.theta.shape
        z = self.rng.standard_normal((N, d))
        log_u = np.log(self.rng.random(N))
        if self.o["proposal"] == "rw":
            prop = pop.theta + np.sqrt(self.scale) * z @ root.T
            log_q = np.zeros(N)                               # symmetric proposal
        else:
            c = self.o["independent_inflation"]
            prop = mean + c * z @ root.T
            cov = c * c * root @ root.T
            log_q = (gaussian_log_density(pop.theta, mean, cov)       # q(θ) − q(θ')
                     - gaussian_log_density(prop, mean, cov))
        inside = np.all((prop >= self.lower) & (prop <= self.upper), axis=1)
        accept = np.zeros(N, bool)
        if inside.any():
            ids = np.flatnonzero(inside)
            sys_p = self.system(prop[ids])
            x_p, P_p = self._initial_state(ids.size)
            x_p, P_p, ll = self.bank(x_p, P_p, sys_p, 0, t)
            ll = np.nan_to_num(ll.sum(axis=1), nan=-np.inf)
            self.n_evals += ids.size
            with np.errstate(invalid="ignore"):
                log_alpha = ll - pop.loglik[ids] + log_q[ids]
            ok = log_u[ids] < log_alpha                         # NaN/−inf: rejected
            accept[ids[ok]] = True
            pop.sys = _merge_subset(pop.sys, N, ids, ok, sys_p)
            pop.theta[ids[ok]] = prop[ids[ok]]
            pop.x[ids[ok]], pop.P[ids[ok]] = x_p[ok], P_p[ok]
            pop.loglik[ids[ok]] = ll[ok]
        return accept


@dataclass
class _Chains:
    """The current states of waste-free chains (one row per chain)."""

    theta: np.ndarray
    x: np.ndarray
    P: np.ndarray
    loglik: np.ndarray
    sys: LinearGaussianBatch

    def snapshot(self) -> "_Chains":
        """A copy that later in-place moves of the chains leave alone (``sys`` is replaced,
        never written into, by a move)."""
        return _Chains(self.theta.copy(), self.x.copy(), self.P.copy(), self.loglik.copy(),
                       self.sys)


def _merge_subset(sys: LinearGaussianBatch, N: int, ids, ok, sys_p) -> LinearGaussianBatch:
    """The N particles' matrices with those of the accepted proposals ``ids[ok]`` swapped in."""
    full_new = np.zeros(N, bool)
    full_new[ids[ok]] = True
    where = np.zeros(N, int)
    where[ids] = np.arange(ids.size)
    return merge_systems(sys, sys_p.take(where), full_new)


def run_ibis(system: Callable[[np.ndarray], LinearGaussianBatch], y: np.ndarray, lower, upper,
             x0, P0, rng: np.random.Generator, *, u: np.ndarray | None = None,
             n_particles: int = 1000, ess_fraction: float = 0.5, proposal: str = "rw",
             min_moves: int = 2, max_moves: int = 20, decorrelation: float = 0.5,
             target_acceptance: float = 0.25, independent_inflation: float = 1.2,
             rejuvenate: bool = True, chain_length: int = 1, theta0: np.ndarray | None = None,
             max_chunk: int = 64, progress: Callable[[float, str], None] | None = None) -> IBISRun:
    """Exact-posterior SMC (IBIS) of θ under a uniform prior on the box [lower, upper].

    Parameters
    ----------
    system : callable
        ``system(theta (M, d)) -> LinearGaussianBatch`` (e.g.
        :func:`railpaper.models.linear_toys.eq18_system`, ``lateral_16state.lateral_system``).
    y : ndarray, (K, p)
        Measurements; row k−1 is y_k.
    lower, upper : array_like, (d,)
        The prior box (units of θ).
    x0, P0 : ndarray, (n,), (n, n)
        State mean and covariance before the first transition.
    rng : numpy.random.Generator
        The only source of randomness (same seed: bit-identical run).
    u : ndarray, (K, m), optional
        Known inputs; row k−1 is u_k, the input of the transition into step k.
    n_particles : int
        N (ignored when ``theta0`` is given).
    ess_fraction : float
        Resample and move when ESS < ess_fraction · N.
    proposal : {"rw", "independent"}
        See the module docstring.
    min_moves, max_moves : int
        Bounds on the MCMC moves per resampling event.
    decorrelation : float
        Moves stop (after ``min_moves``) once the mean squared Mahalanobis displacement from
        the resampled positions reaches ``decorrelation · 2d`` (see the module docstring).
    target_acceptance : float
        Acceptance rate the random walk's scale is adapted towards.
    independent_inflation : float
        Scale of the independent proposal's standard deviations relative to the particles'.
    rejuvenate : bool
        False: resample without moving (degenerates; kept to show why the moves matter).
    chain_length : int
        1: resample N particles and move each ``min_moves`` … ``max_moves`` times (above).
        P > 1: waste-free moves (Dau & Chopin 2022): resample N / P chain starts and keep all
        N states of their P-long MH chains (``min_moves``, ``max_moves`` and
        ``decorrelation`` are then unused).  N must be a multiple of P.
    theta0 : ndarray, (N, d), optional
        Initial particles (default: N uniform draws on the box).
    max_chunk : int
        Longest run of steps given to the Kalman bank in one call between resampling events.
    progress : callable, optional
        ``progress(fraction, message)``.

    Returns
    -------
    IBISRun
    """
    if proposal not in PROPOSALS:
        raise ValueError(f"proposal must be one of {PROPOSALS}, got {proposal!r}")
    keep_freed_memory()              # the moves' re-runs reuse the process's memory
    y = np.atleast_2d(np.asarray(y, float))
    u = None if u is None else np.asarray(u, float).reshape(len(y), -1)
    lower, upper = np.atleast_1d(np.asarray(lower, float)), np.atleast_1d(np.asarray(upper, float))
    if not np.all(upper > lower):
        raise ValueError("the prior box needs upper > lower in every parameter")
    if int(chain_length) < 1:
        raise ValueError(f"chain_length must be at least 1, got {chain_length}")
    n_total = int(n_particles) if theta0 is None else int(np.asarray(theta0).shape[0])
    if n_total % int(chain_length):
        raise ValueError(f"waste-free IBIS needs the {n_total} particles to be a multiple of "
                         f"chain_length = {chain_length}")
    opts = dict(n_particles=int(n_particles), rejuvenate=bool(rejuvenate), proposal=proposal,
                chain_length=int(chain_length),
                min_moves=int(min_moves), max_moves=int(max_moves),
                decorrelation=float(decorrelation),
                target_acceptance=float(target_acceptance),
                independent_inflation=float(independent_inflation))
    s = _Sampler(system, y, u, lower, upper, x0, P0, rng, theta0, opts)
    N, K = s.theta.shape[0], y.shape[0]
    rows: dict[str, list] = {k: [] for k in ("mean", "sd", "q05", "q95", "ess", "log_evidence")}
    t, chunk = 0, 1
    while t < K:
        c = min(chunk, K - t)
        x_end, P_end, L = s.bank(s.x, s.P, s.sys, t, t + c)
        L = np.where(np.isnan(L), -np.inf, L)
        LW = s.log_w[:, None] + np.cumsum(L, axis=1)              # (N, c) log weights per step
        W, log_norm = normalise_log_weight_columns(LW)            # (c, N)
        ess = 1.0 / np.sum(W * W, axis=1)
        low = np.flatnonzero(ess < ess_fraction * N)
        j = int(low[0]) if low.size else c - 1                     # last step of this chunk
        append_summaries(rows, s.theta, W[:j + 1], log_norm[:j + 1],
                         np.concatenate([[0.0], log_norm[:j]]), ess[:j + 1])
        if low.size and j < c - 1:                                 # the bank's state at t+j+1
            x_end, P_end, _ = s.bank(s.x, s.P, s.sys, t, t + j + 1)
        s.x, s.P = x_end, P_end
        s.loglik = s.loglik + np.sum(L[:, :j + 1], axis=1)
        with np.errstate(divide="ignore"):
            s.log_w = np.log(W[j])
        t += j + 1
        if low.size:
            s.resample_move(t, W[j])
            chunk = max(1, (j + 1) // 2)
        else:
            chunk = min(2 * chunk, max_chunk)
        if progress is not None:
            progress(t / K, f"IBIS step {t}/{K}, {len(s.events)} resampling events")
    ev = np.array(s.events, dtype=float).reshape(-1, 5)
    with np.errstate(divide="ignore"):
        w_final = np.exp(s.log_w - np.max(s.log_w))
    return IBISRun(**{k: np.array(v) for k, v in rows.items()},
                   resample_steps=ev[:, 0].astype(int), n_moves=ev[:, 1].astype(int),
                   acceptance=ev[:, 2], displacement=ev[:, 3], moved_fraction=ev[:, 4],
                   n_loglik_evals=s.n_evals, n_filter_steps=s.n_steps_run, theta=s.theta.copy(),
                   weights=w_final / w_final.sum(), loglik=s.loglik.copy(), lower=lower,
                   upper=upper)


def jittered_cholesky(cov: np.ndarray, box_width: np.ndarray) -> np.ndarray:
    """Lower Cholesky factor of Σ; if Σ is singular (e.g. one distinct particle), of Σ plus the
    smallest diagonal jitter (10⁻⁹, 10⁻⁸, … × box width)² that factorises."""
    jitter = 0.0
    for _ in range(8):
        try:
            return np.linalg.cholesky(cov + np.diag(jitter * box_width ** 2))
        except np.linalg.LinAlgError:
            jitter = 1e-18 if jitter == 0.0 else 100.0 * jitter
    return np.diag(1e-3 * box_width)


def append_summaries(rows: dict, theta, W, log_norm, prev_log_norm, ess) -> None:
    """Append per-step mean, sd, quantiles, ESS and incremental log evidence (W: (J, N))."""
    mean = W @ theta                                                # (J, d)
    centred = theta[None] - mean[:, None]                           # (J, N, d)
    var = np.einsum("jn,jnd->jd", W, centred * centred)
    q = weighted_quantiles(theta, W, (0.05, 0.95))
    rows["mean"].extend(mean)
    rows["sd"].extend(np.sqrt(np.clip(var, 0.0, None)))
    rows["q05"].extend(q[0])
    rows["q95"].extend(q[1])
    rows["ess"].extend(ess)
    rows["log_evidence"].extend(log_norm - prev_log_norm)
