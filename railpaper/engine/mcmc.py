"""Reference MCMC for static parameters: adaptive Metropolis chains on the exact Kalman likelihood.

An independent route to the posterior that :mod:`railpaper.engine.ibis` samples
sequentially: C random-walk Metropolis chains run side by side (one compiled Kalman-bank call
per iteration evaluates all C proposals over the whole record) on

    log π(θ) = log p(y_1..K | θ) + log 1_box(θ)      (uniform prior on the box, natural θ)

Warm-up (Haario, Saksman & Tamminen 2001, *Bernoulli* 7, 223–242, per chain): every
``adapt_every`` iterations each chain's proposal covariance becomes (2.38²/d) · s_c · Cov(the
chain's own second half of its history so far) + ε I, and its scale s_c follows the acceptance
rate towards 0.234.  After warm-up the proposals are frozen, so the kept samples are those of
ordinary Metropolis chains (exactly π-invariant, no adaptation theory needed).  Chains start
from independent uniform draws on the box, so several of them reaching the same region, and
the Gelman–Rubin R̂ (:func:`gelman_rubin`) near 1, are the check that they have found the
posterior.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np

from railpaper.engine.kalman_bank import kalman_run


def kalman_log_posterior(system, y: np.ndarray, lower, upper, x0, P0,
                         u: np.ndarray | None = None) -> Callable[[np.ndarray], np.ndarray]:
    """``log π(θ)`` (M, d) → (M,): exact Kalman log-likelihood of the whole record, −inf off
    the box (the uniform prior's constant is dropped)."""
    y = np.atleast_2d(np.asarray(y, float))
    lower, upper = np.asarray(lower, float), np.asarray(upper, float)
    x0, P0 = np.asarray(x0, float), np.asarray(P0, float)

    def log_post(theta: np.ndarray) -> np.ndarray:
        theta = np.atleast_2d(theta)
        out = np.full(theta.shape[0], -np.inf)
        inside = np.all((theta >= lower) & (theta <= upper), axis=1)
        if inside.any():
            m = int(inside.sum())
            x = np.broadcast_to(x0, (m, x0.size)).copy()
            P = np.broadcast_to(P0, (m,) + P0.shape).copy()
            _, _, ll = kalman_run(x, P, system(theta[inside]), y, u)
            out[inside] = np.nan_to_num(ll.sum(axis=1), nan=-np.inf)
        return out

    return log_post


@dataclass(frozen=True)
class ChainRun:
    """Samples of C parallel chains after warm-up.

    Attributes
    ----------
    samples : ndarray, (n_keep, C, d)
        Kept states (units of θ).
    log_target : ndarray, (n_keep, C)
    acceptance : ndarray, (C,)
        Acceptance rate of each chain after warm-up.
    n_evaluations : int
        Target evaluations (proposals inside the box count; others are free).
    """

    samples: np.ndarray
    log_target: np.ndarray
    acceptance: np.ndarray
    n_evaluations: int

    def summary(self) -> dict:
        """Pooled mean and sd (d,), Monte Carlo standard error of the mean from the spread of
        the chain means (d,) and R̂ (d,)."""
        flat = self.samples.reshape(-1, self.samples.shape[-1])
        chain_means = self.samples.mean(axis=0)                          # (C, d)
        C = chain_means.shape[0]
        return dict(mean=flat.mean(axis=0), sd=flat.std(axis=0),
                    mcse=chain_means.std(axis=0, ddof=1) / np.sqrt(C),
                    rhat=gelman_rubin(self.samples))


def gelman_rubin(samples: np.ndarray) -> np.ndarray:
    """Potential scale reduction R̂ per parameter of (n, C, d) chains (Gelman & Rubin 1992,
    the basic form: sqrt of (pooled variance estimate / mean within-chain variance))."""
    n = samples.shape[0]
    within = samples.var(axis=0, ddof=1).mean(axis=0)
    between = n * samples.mean(axis=0).var(axis=0, ddof=1)
    pooled = (n - 1) / n * within + between / n
    return np.sqrt(pooled / within)


def adaptive_metropolis(log_target: Callable[[np.ndarray], np.ndarray], theta0: np.ndarray,
                        n_warmup: int, n_keep: int, rng: np.random.Generator, *,
                        initial_sd: np.ndarray | None = None, adapt_every: int = 50,
                        thin: int = 1, eps: float = 1e-12) -> ChainRun:
    """C adaptive-Metropolis chains (adapted in warm-up, frozen after), vectorised over chains.

    Parameters
    ----------
    log_target : callable
        (C, d) → (C,) log density up to a constant (−inf allowed).
    theta0 : ndarray, (C, d)
        Starting points (finite log target).
    n_warmup, n_keep : int
        Warm-up iterations (discarded) and kept iterations (after thinning: n_keep // thin).
    rng : numpy.random.Generator
    initial_sd : ndarray, (d,), optional
        Proposal sd before the first adaptation (default: 1/10 of the starting points' spread).
    adapt_every : int
        Iterations between covariance updates in warm-up.
    thin : int
        Keep every ``thin``-th state.
    eps : float
        Ridge ε added to the adapted covariances, relative to their diagonal.

    Returns
    -------
    ChainRun
    """
    theta = np.array(theta0, float)
    C, d = theta.shape
    lp = log_target(theta)
    if not np.all(np.isfinite(lp)):
        raise ValueError("every starting point needs a finite log target")
    sd0 = (0.1 * theta.std(axis=0) + 1e-12) if initial_sd is None else np.asarray(initial_sd)
    roots = np.broadcast_to(np.diag(sd0), (C, d, d)).copy()             # proposal factors
    log_scale = np.zeros(C)
    history = np.empty((n_warmup, C, d))
    kept, kept_lp, accepted, evals = [], [], np.zeros(C), 0
    for it in range(n_warmup + n_keep):
        z = rng.standard_normal((C, d))
        prop = theta + np.exp(0.5 * log_scale)[:, None] * np.einsum("cij,cj->ci", roots, z)
        lp_prop = log_target(prop)
        evals += int(np.count_nonzero(np.isfinite(lp_prop)))
        with np.errstate(invalid="ignore"):
            acc = np.log(rng.random(C)) < lp_prop - lp
        theta[acc], lp[acc] = prop[acc], lp_prop[acc]
        if it < n_warmup:
            history[it] = theta
            log_scale += (acc - 0.234) / np.sqrt(1.0 + it / adapt_every)   # Robbins–Monro
            if (it + 1) % adapt_every == 0 and it + 1 >= 2 * adapt_every:
                window = history[(it + 1) // 2:it + 1]                  # second half so far
                centred = window - window.mean(axis=0)
                cov = np.einsum("nci,ncj->cij", centred, centred) / (len(window) - 1)
                diag = np.einsum("cii->ci", cov)
                cov = 2.38 ** 2 / d * cov + (eps * diag)[:, :, None] * np.eye(d)
                roots = _safe_cholesky(cov, roots, np.all(diag > 0, axis=1))
        else:
            accepted += acc
            if (it - n_warmup) % thin == 0:
                kept.append(theta.copy())
                kept_lp.append(lp.copy())
    return ChainRun(samples=np.array(kept), log_target=np.array(kept_lp),
                    acceptance=accepted / max(n_keep, 1), n_evaluations=evals)


def _safe_cholesky(cov: np.ndarray, previous: np.ndarray, moved: np.ndarray) -> np.ndarray:
    """Cholesky factors of (C, d, d) covariances; a chain that did not move in every parameter
    over the window, or whose covariance is not positive definite, keeps its previous factor."""
    out = previous.copy()
    for c in np.flatnonzero(moved):
        try:
            out[c] = np.linalg.cholesky(cov[c])
        except np.linalg.LinAlgError:
            pass
    return out
