"""The exact posterior of an abrupt parameter change: when did θ jump, and to what?

A linear-Gaussian model whose parameters are θ₀ up to an unknown step and θ_v (one of V
candidate post-change values) from step τ on is, for every hypothesis (v, τ), a linear-Gaussian
model with time-varying matrices, so a Kalman filter gives its likelihood p(y_1..k | v, τ)
exactly.  Over a grid of change steps τ_1 < … < τ_J the hypotheses share their pre-change
history, so one bank runs them all: the no-change filter, and from step τ_j on V more filters
started from its state (the same x and P) with the matrices of θ_v::

    ℓ_vj(k) = ℓ₀(k)                               k < τ_j
    ℓ_vj(k) = ℓ₀(τ_j − 1) + Σ_{i=τ_j..k} log N(y_i; H_v x⁻_i, S_i)    k ≥ τ_j

and, with prior masses π_vj on the hypotheses and π_∅ on "no change in the record", the
posterior probability that the change has happened by step k (an on-line alarm statistic) is

    P(τ ≤ k | y_1..k) = Σ_{τ_j ≤ k} π_vj e^{ℓ_vj(k)} / (Σ_{τ_j ≤ k} π_vj e^{ℓ_vj(k)} + (π_∅ + Σ_{τ_j > k} π_vj) e^{ℓ₀(k)})

(log-sum-exp throughout).  No particle approximates τ or v: for the filters' model the only
approximation is the grid (a change between grid steps is attributed to a neighbouring one);
data from another model (a finer truth, an input held differently) are filtered exactly under
this one.  Cost: Σ_j V (K − τ_j) filter
steps, i.e. about V J K / 2.

Example (a scalar AR(1) whose coefficient jumps from 0.9 to −0.5 at step 60)::

    >>> import numpy as np
    >>> from railpaper.engine.linear_gaussian import LinearGaussianBatch
    >>> def system(theta):
    ...     a = np.atleast_2d(theta)[:, 0]
    ...     return LinearGaussianBatch(a[:, None, None], [[1.0]], [[1.0]], [[0.1]])
    >>> rng = np.random.default_rng(3)
    >>> x, y = 0.0, []
    >>> for k in range(1, 121):
    ...     x = (0.9 if k < 60 else -0.5) * x + rng.standard_normal()
    ...     y.append(x + np.sqrt(0.1) * rng.standard_normal())
    >>> lik = change_likelihoods(system, np.array(y)[:, None], [0.9], [[-0.5]],
    ...                          np.arange(20, 101), np.zeros(1), np.eye(1))
    >>> post = change_posterior(lik, p_no_change=0.5)
    >>> bool(post.p_changed[50] < 0.5 < post.p_changed[-1])
    True
    >>> int(post.tau_steps[np.argmax(post.tau_posterior)])
    60
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np

from railpaper.engine.kalman_bank import kalman_run, kalman_run_restarting
from railpaper.engine.linear_gaussian import LinearGaussianBatch, concat_systems


@dataclass(frozen=True)
class ChangeLikelihoods:
    """Cumulative log-likelihoods (natural log) of every change hypothesis after every step.

    Attributes
    ----------
    no_change : ndarray, (K,)
        ℓ₀(k) = log p(y_1..k | θ₀ throughout); entry k−1 is after step k.
    changed : ndarray, (V, J, K)
        ℓ_vj(k): θ₀ before step ``tau_steps[j]``, ``thetas_after[v]`` from it on (equal to
        ``no_change`` before the change).
    tau_steps : ndarray of int, (J,)
        The grid of change steps (1-based: the first step whose transition and measurement use
        the post-change matrices).
    thetas_after : ndarray, (V, d)
        The candidate post-change parameters (units of θ).
    filter_steps : int
        Kalman filter steps run (the cost).
    """

    no_change: np.ndarray
    changed: np.ndarray
    tau_steps: np.ndarray
    thetas_after: np.ndarray
    filter_steps: int


@dataclass(frozen=True)
class ChangePosterior:
    """The on-line posterior of a change, from :func:`change_posterior`.

    Attributes
    ----------
    p_changed : ndarray, (K,)
        P(τ ≤ k | y_1..k) after every step k (row k−1): the alarm statistic.
    log_odds_changed : ndarray, (K,)
        log P(τ ≤ k | y_1..k) − log P(τ > k | y_1..k), natural log, computed from the
        log-likelihoods (finite where ``p_changed`` rounds to 1).
    tau_posterior : ndarray, (J,)
        P(τ = τ_j | y_1..K, a change happened) after the last step.
    value_posterior : ndarray, (V,)
        P(θ_after = θ_v | y_1..K, a change happened) after the last step.
    p_changed_final : float
        P(a change in the record | y_1..K).
    tau_steps : ndarray of int, (J,)
        The grid (as in :class:`ChangeLikelihoods`).
    """

    p_changed: np.ndarray
    tau_posterior: np.ndarray
    value_posterior: np.ndarray
    p_changed_final: float
    tau_steps: np.ndarray
    log_odds_changed: np.ndarray | None = None


def change_likelihoods(system: Callable[[np.ndarray], LinearGaussianBatch], y: np.ndarray,
                       theta_before, thetas_after, tau_steps, x0, P0,
                       u: np.ndarray | None = None) -> ChangeLikelihoods:
    """Exact cumulative log-likelihoods of "no change" and of every (post-change value, change
    step) hypothesis, by one growing Kalman bank (see the module docstring).

    Parameters
    ----------
    system : callable
        ``system(theta (M, d)) -> LinearGaussianBatch`` (e.g.
        :func:`railpaper.models.lateral_16state.lateral_system`).
    y : ndarray, (K, p)
        Measurements; row k−1 is y_k.
    theta_before : array_like, (d,)
        θ₀, the parameters before the change.
    thetas_after : array_like, (V, d)
        Candidate parameters after the change.
    tau_steps : array_like of int, (J,)
        Change steps to consider, strictly increasing, in 2..K (1-based).
    x0, P0 : ndarray, (n,), (n, n)
        State mean and covariance before the first transition.
    u : ndarray, (K, m), optional
        Known inputs; row k−1 is u_k.

    Returns
    -------
    ChangeLikelihoods
    """
    y = np.atleast_2d(np.asarray(y, float))
    K = y.shape[0]
    taus = np.asarray(tau_steps, dtype=np.int64)
    if taus.ndim != 1 or taus.size == 0 or np.any(np.diff(taus) <= 0) or taus[0] < 2 \
            or taus[-1] > K:
        raise ValueError(f"tau_steps must be strictly increasing steps in 2..{K}")
    before = np.atleast_2d(np.asarray(theta_before, float))
    after = np.atleast_2d(np.asarray(thetas_after, float))
    V, J = after.shape[0], taus.size
    nominal, post = system(before), system(after)
    n = np.asarray(x0).shape[-1]
    x = np.asarray(x0, float).reshape(1, n).copy()
    P = np.asarray(P0, float).reshape(1, n, n).copy()
    per_step = np.empty((1 + V * J, K))          # row 0: no change; row 1 + j V + v: (v, j)
    models = [nominal]
    sizes = [1]
    steps_run = 0
    edges = list(taus - 1) + [K]                 # 0-based: segment j runs steps edges[j]..
    k = 0
    for j in range(J + 1):
        stop = edges[j]
        if stop > k:                             # steps k+1..stop (0-based k..stop-1)
            U = None if u is None else np.asarray(u, float)[k:stop]
            bank = concat_systems(models, sizes)
            x, P, ll = kalman_run(x, P, bank, y[k:stop], U)
            per_step[:x.shape[0], k:stop] = ll
            steps_run += x.shape[0] * (stop - k)
            k = stop
        if j < J:                                # V new filters from the no-change state
            x = np.concatenate([x, np.repeat(x[:1], V, axis=0)])
            P = np.concatenate([P, np.repeat(P[:1], V, axis=0)])
            models.append(post)
            sizes.append(V)
    ll0 = per_step[0]
    cum0 = np.cumsum(ll0)
    changed = np.empty((V, J, K))
    for j, tau in enumerate(taus):
        rows = per_step[1 + j * V:1 + (j + 1) * V]
        head = cum0[tau - 2]                     # ℓ₀(τ − 1)
        changed[:, j, :tau - 1] = cum0[:tau - 1]
        changed[:, j, tau - 1:] = head + np.cumsum(rows[:, tau - 1:], axis=1)
    return ChangeLikelihoods(no_change=cum0, changed=changed, tau_steps=taus.copy(),
                             thetas_after=after.copy(), filter_steps=steps_run)


def change_posterior(lik: ChangeLikelihoods, p_no_change: float = 0.5,
                     prior: np.ndarray | None = None) -> ChangePosterior:
    """Posterior of the change from :func:`change_likelihoods`.

    Parameters
    ----------
    lik : ChangeLikelihoods
    p_no_change : float
        Prior probability π_∅ of no change in the record, in [0, 1).
    prior : ndarray, (V, J), optional
        Relative prior weights of the hypotheses (default: uniform over values and grid);
        scaled to total 1 − π_∅.

    Returns
    -------
    ChangePosterior
    """
    if not 0.0 <= p_no_change < 1.0:
        raise ValueError(f"p_no_change must be in [0, 1), got {p_no_change}")
    V, J, K = lik.changed.shape
    w = np.ones((V, J)) if prior is None else np.asarray(prior, float)
    if w.shape != (V, J) or np.any(w < 0) or w.sum() <= 0:
        raise ValueError(f"prior must be non-negative weights of shape {(V, J)}")
    log_w = np.log(np.clip(w / w.sum(), 1e-300, None)) + np.log1p(-p_no_change)
    log_w = np.where(w > 0, log_w, -np.inf)
    steps = np.arange(1, K + 1)
    started = lik.tau_steps[None, :, None] <= steps[None, None, :]        # (1, J, K)
    terms = log_w[:, :, None] + lik.changed                                # (V, J, K)
    log_changed = _logsumexp(np.where(started, terms, -np.inf).reshape(V * J, K))
    # not yet changed: π_∅ plus the prior mass of the grid steps still ahead, times e^{ℓ₀(k)}
    mass = _logsumexp(log_w)                                               # (J,) per τ_j
    suffix = np.full(J + 1, -np.inf)                                       # log Σ_{i ≥ j} mass_i
    for j in range(J - 1, -1, -1):
        suffix[j] = np.logaddexp(suffix[j + 1], mass[j])
    with np.errstate(divide="ignore"):
        log_none = np.log(p_no_change)
    ahead = np.logaddexp(log_none, suffix[np.searchsorted(lik.tau_steps, steps, side="right")])
    log_rest = ahead + lik.no_change
    p_changed = np.exp(log_changed - np.logaddexp(log_changed, log_rest))
    final = terms[:, :, -1]
    top = final.max()
    joint = np.exp(final - top)
    z = joint.sum()
    tau_post, value_post = joint.sum(axis=0) / z, joint.sum(axis=1) / z
    return ChangePosterior(p_changed=p_changed, tau_posterior=tau_post,
                           value_posterior=value_post, p_changed_final=float(p_changed[-1]),
                           tau_steps=lik.tau_steps.copy(),
                           log_odds_changed=log_changed - log_rest)


@dataclass(frozen=True)
class ChangeStatistics:
    """The classical on-line statistics of one change from a known regime, from
    :func:`change_statistics`.

    Attributes
    ----------
    log_shiryaev_roberts : ndarray, (K,)
        log R_k of the mixture Shiryaev–Roberts statistic after every step k (−inf while no
        hypothesis has started).
    glr : ndarray, (K,)
        The window-limited generalised likelihood ratio g_k (natural log; −inf while no
        hypothesis has started).
    window_steps : int or None
        W: only changes at the last W steps (τ_j > k − W) enter; None for every change so far.
    """

    log_shiryaev_roberts: np.ndarray
    glr: np.ndarray
    window_steps: int | None


def change_statistics(lik: ChangeLikelihoods, window_steps: int | None = None,
                      prior: np.ndarray | None = None) -> ChangeStatistics:
    """The mixture Shiryaev–Roberts statistic and the window-limited GLR of a change from the
    known regime θ₀ to one of the candidate values, from exact Kalman likelihoods.

    With the log-likelihood ratio of hypothesis (v, τ_j) against no change after step k,
    ``λ_vj(k) = ℓ_vj(k) − ℓ₀(k) = Σ_{i=τ_j..k} log Λ_i(v, τ_j)`` (zero before the change)::

        R_k = Σ_{j: k−W < τ_j ≤ k} Σ_v π_v e^{λ_vj(k)}        (Shiryaev–Roberts, mixed over v)
        g_k = max_{j: k−W < τ_j ≤ k} max_v λ_vj(k)             (GLR; Willsky & Jones, Lai 1998)

    One change from a known regime, so no reset or run-length model; every grid step is a
    possible change time with weight one (R_k is not a posterior).  ``prior`` (V,) weighs the
    values (uniform by default, normalised to 1).  Window-limiting drops the terms of changes
    more than W steps back; for R_k that is a sum of non-negative terms, so the windowed
    statistic never exceeds the full one, and equals it while k ≤ W.
    """
    V, J, K = lik.changed.shape
    if window_steps is not None and window_steps < 1:
        raise ValueError(f"window_steps must be >= 1 or None, got {window_steps}")
    log_w = _log_prior(prior, V)
    steps = np.arange(1, K + 1)
    tau = lik.tau_steps[:, None]
    inside = tau <= steps[None, :]                                           # (J, K)
    if window_steps is not None:
        inside &= tau > steps[None, :] - window_steps
    ratio = lik.changed - lik.no_change[None, None, :]                       # λ_vj(k)
    live = np.broadcast_to(inside[None], ratio.shape)
    log_terms = np.where(live, log_w[:, None, None] + ratio, -np.inf)
    log_sr = _logsumexp(log_terms.reshape(V * J, K))
    glr = np.where(live, ratio, -np.inf).reshape(V * J, K).max(axis=0)
    return ChangeStatistics(log_shiryaev_roberts=log_sr, glr=glr, window_steps=window_steps)


@dataclass(frozen=True)
class WindowedChangeStatistics:
    """The on-line statistics of one change at any step within a window, from
    :func:`windowed_change_statistics`.

    Attributes
    ----------
    log_shiryaev_roberts : ndarray, (K,)
        log R_k (natural log; −inf before the first change step).
    glr : ndarray, (K,)
        g_k, the largest log-likelihood ratio in the window (−inf before the first change step).
    glr_value : ndarray of int, (K,)
        The candidate value v of g_k's maximum (−1 before the first change step): which
        parameter and how far, the diagnosis that comes with an alarm.
    glr_change_step : ndarray of int, (K,)
        The change step τ (1-based) of g_k's maximum (−1 before the first change step).
    window_steps : int
        W.
    filter_steps : int
        Kalman filter steps run (the cost): V W (K − τ₀ + 1) + K.
    """

    log_shiryaev_roberts: np.ndarray
    glr: np.ndarray
    glr_value: np.ndarray
    glr_change_step: np.ndarray
    window_steps: int
    filter_steps: int


def windowed_change_statistics(system: Callable[[np.ndarray], LinearGaussianBatch],
                               y: np.ndarray, theta_before, thetas_after, window_steps: int,
                               x0, P0, u: np.ndarray | None = None, first_change_step: int = 2,
                               prior: np.ndarray | None = None) -> WindowedChangeStatistics:
    """The window-limited mixture Shiryaev–Roberts statistic and GLR of one change from θ₀ to
    one of V candidate values at **any** step, with exact Kalman likelihood ratios.

    The statistics of :func:`change_statistics` with every step from ``first_change_step`` on
    a possible change time (weight one each) and the window W = ``window_steps``::

        R_k = Σ_{τ = max(k−W+1, τ₀)..k} Σ_v π_v Π_{i=τ..k} Λ_i(v, τ)
        g_k = max_{τ, v} Σ_{i=τ..k} log Λ_i(v, τ)

    where Λ_i(v, τ) is the ratio of the predictive densities of y_i under the Kalman filter
    started at τ − 1 from the no-change filter's state (the same x and P) with the matrices of
    θ_v, and under the no-change filter.  A hypothesis' filter lives only while its change
    lies in the window, so one bank of V W filters runs the whole record (a ring: the V
    filters of the change W steps back are restarted from the no-change filter's state at
    every step, :func:`~railpaper.engine.kalman_bank.kalman_run_restarting`) — the same
    numbers as :func:`change_likelihoods` over every step followed by
    :func:`change_statistics` with the window, at V W (K − τ₀) filter steps instead of about
    V K² / 2.  ``prior`` (V,) weighs the values (uniform by default, normalised to 1).
    """
    y = np.atleast_2d(np.asarray(y, float))
    K = y.shape[0]
    W = int(window_steps)
    if W < 1:
        raise ValueError(f"window_steps must be >= 1, got {window_steps}")
    if not 2 <= first_change_step <= K:
        raise ValueError(f"first_change_step must be in 2..{K}, got {first_change_step}")
    before = np.atleast_2d(np.asarray(theta_before, float))
    after = np.atleast_2d(np.asarray(thetas_after, float))
    V = after.shape[0]
    log_w = _log_prior(prior, V)
    U = None if u is None else np.asarray(u, float).reshape(K, -1)
    nominal, post = system(before), system(after)
    n = np.asarray(x0).shape[-1]
    # the no-change filter, its state after every step kept: x_post[k] after step k
    x_post, P_post = np.empty((K + 1, n)), np.empty((K + 1, n, n))
    x_post[0], P_post[0] = np.asarray(x0, float).reshape(n), np.asarray(P0, float)
    ll0 = np.empty(K)
    for k in range(1, K + 1):
        x, P, ll = kalman_run(x_post[k - 1][None], P_post[k - 1][None], nominal, y[k - 1:k],
                              None if U is None else U[k - 1:k])
        x_post[k], P_post[k], ll0[k - 1] = x[0], P[0], ll[0, 0]
    # lane r V + v holds the changes τ ≡ r (mod W) to θ_v, restarted at each one from the
    # no-change filter's state after step τ − 1; local row t is step k = τ₀ + t
    t0 = first_change_step - 1
    rows = K - t0
    slot = np.repeat(np.arange(W), V)                         # r of each lane
    phase = (slot - first_change_step) % W                    # rows t with (τ₀ + t) % W == r
    lanes = kalman_run_restarting(x_post[t0:K], P_post[t0:K], concat_systems([post] * W, [V] * W),
                                  y[t0:], None if U is None else U[t0:], phase, W)
    steps_run = K + V * W * rows
    # Σ_{i=τ..k} log Λ_i of each lane's current change τ: a cumulative sum since its restart
    total = np.cumsum(lanes - ll0[t0:][None, :], axis=1)       # (V W, rows)
    t = np.arange(rows)
    last = t[None, :] - (t[None, :] - phase[:, None]) % W      # row of the current restart
    before_restart = np.where(last > 0, np.take_along_axis(total, np.maximum(last - 1, 0),
                                                           axis=1), 0.0)
    live = last >= 0                                          # the lane has started
    log_ratio = np.where(live, total - before_restart, -np.inf)
    v_of_lane = np.tile(np.arange(V), W)
    weighted = log_ratio + log_w[v_of_lane][:, None]
    log_sr = np.full(K, -np.inf)
    glr = np.full(K, -np.inf)
    glr_value = np.full(K, -1, dtype=np.int64)
    glr_step = np.full(K, -1, dtype=np.int64)
    log_sr[t0:] = _logsumexp(weighted)
    best = np.argmax(log_ratio, axis=0)
    glr[t0:] = log_ratio[best, t]
    glr_value[t0:] = v_of_lane[best]
    glr_step[t0:] = last[best, t] + first_change_step
    return WindowedChangeStatistics(log_shiryaev_roberts=log_sr, glr=glr, glr_value=glr_value,
                                    glr_change_step=glr_step, window_steps=W,
                                    filter_steps=steps_run)


def _log_prior(prior: np.ndarray | None, V: int) -> np.ndarray:
    """log of the values' prior weights ``prior`` (V,), normalised to 1 (uniform when None);
    one line of ValueError unless they are non-negative with a positive sum."""
    w = np.full(V, 1.0 / V) if prior is None else np.asarray(prior, float)
    if w.shape != (V,) or np.any(w < 0) or w.sum() <= 0:
        raise ValueError(f"prior must be non-negative weights of shape {(V,)}")
    with np.errstate(divide="ignore"):
        return np.log(w / w.sum())


def _logsumexp(a: np.ndarray) -> np.ndarray:
    """log Σ_i exp(a[i, k]) over the first axis (−inf where every term is −inf)."""
    top = np.max(a, axis=0)
    safe = np.where(np.isfinite(top), top, 0.0)
    with np.errstate(divide="ignore"):
        return safe + np.log(np.sum(np.exp(a - safe), axis=0))
