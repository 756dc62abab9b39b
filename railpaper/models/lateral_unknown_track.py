"""Paper 003's lateral vehicle for filters that are not given the track: the alignment becomes
part of the state.

The filters of :mod:`railpaper.models.lateral_16state` are handed the track's lateral velocity
under each wheelset, ``u_k = (ẏt1, ẏt2)(t_{k−1})`` held over the step.  A vehicle in service has
no such measurement.  Here the filters model it instead, as a railway-dynamics engineer would:

* the alignment under the leading wheelset is a second-order shaping filter of the track
  spectrum at the vehicle's speed (``s = (y_t, ẏ_t)``, driven by white noise; its continuous
  ``(Af, Bf)`` from :class:`railpaper.estimators.kalman_baseline.ShapingFilter`), discretised
  exactly (:func:`discrete_shaping`);
* the trailing wheelset runs over the same rail ``L / v`` later (``L = 2a``, the bogie's
  wheelbase): a shift register ``r`` of the leading velocity's last ``d`` samples,
  ``d = round(L / (v dt))`` (:func:`delay_steps`; the rounding is a model error of at most
  half a sample, stated where it is used).

The state is ``z = (x (16), s (2), r (d))`` and one step reads (``G`` the vehicle's input matrix
over a step, column 0 the leading wheelset, column 1 the trailing one)::

    x_k = F(θ) x_{k−1} + G(θ)[:, 0] s_{k−1}[1] + G(θ)[:, 1] r_{k−1}[d−1]
    s_k = Φ_s s_{k−1} + w_k,             w_k ~ N(0, Q_s)
    r_k = (s_{k−1}[1], r_{k−1}[0], …, r_{k−1}[d−2])

so the inputs are those the known-input filters are given, now estimated.  The measurements
are the vehicle's (``H = [H(θ) 0]``).  :func:`augment` builds the batch of such models from the
known-input batch; :func:`track_covariance` is the stationary covariance of ``(s, r)``, the
filters' initial covariance of the track states (the track is not at rest when a record starts).
"""

from __future__ import annotations

import numpy as np
from scipy.linalg import expm, solve_discrete_lyapunov

from railpaper.engine import LinearGaussianBatch
from railpaper.models.lateral_16state import N_STATES

#: States of the shaping filter: the alignment under the leading wheelset and its velocity.
SHAPING_STATES = 2


def delay_steps(wheelbase_m: float, speed_mps: float, dt_s: float) -> int:
    """Samples between the leading and the trailing wheelset passing one point of the rail:
    ``round(L / (v dt))``, at least 1."""
    if wheelbase_m <= 0 or speed_mps <= 0 or dt_s <= 0:
        raise ValueError("need a positive wheelbase, speed and sample time")
    return max(1, int(round(wheelbase_m / (speed_mps * dt_s))))


def discrete_shaping(Af: np.ndarray, Bf: np.ndarray, dt_s: float) -> tuple[np.ndarray, np.ndarray]:
    """``(Φ_s, Q_s)`` of ``ṡ = Af s + Bf w`` with unit white noise w over one sample, exactly
    (Van Loan 1978: the exponential of ``[[−Af, Bf Bfᵀ], [0, Afᵀ]] dt``)."""
    n = Af.shape[0]
    block = np.zeros((2 * n, 2 * n))
    block[:n, :n] = -Af
    block[:n, n:] = Bf @ Bf.T
    block[n:, n:] = Af.T
    e = expm(block * dt_s)
    Phi = e[n:, n:].T                                   # e^{Af dt}
    Q = Phi @ e[:n, n:]                                 # ∫ e^{Af t} Bf Bfᵀ e^{Afᵀ t} dt
    return Phi, 0.5 * (Q + Q.T)


def track_covariance(Phi_s: np.ndarray, Q_s: np.ndarray, delay: int) -> np.ndarray:
    """Stationary covariance of ``(s, r)`` (2 + d square): ``P = Φ_s P Φ_sᵀ + Q_s`` for s,
    ``cov(s_k, r_k[i]) = Φ_s^{i+1} P cᵀ`` and ``cov(r_k[i], r_k[j]) = c Φ_s^{j−i} P cᵀ``
    (i ≤ j), with ``c = (0, 1)`` the velocity and ``r_k[i] = c s_{k−1−i}``."""
    P = solve_discrete_lyapunov(Phi_s, Q_s)
    P = 0.5 * (P + P.T)
    c = np.array([0.0, 1.0])
    powers = [np.eye(SHAPING_STATES)]
    for _ in range(delay + 1):
        powers.append(Phi_s @ powers[-1])
    out = np.zeros((SHAPING_STATES + delay, SHAPING_STATES + delay))
    out[:SHAPING_STATES, :SHAPING_STATES] = P
    for i in range(delay):
        column = powers[i + 1] @ P @ c
        out[:SHAPING_STATES, SHAPING_STATES + i] = column
        out[SHAPING_STATES + i, :SHAPING_STATES] = column
        for j in range(i, delay):
            out[SHAPING_STATES + i, SHAPING_STATES + j] = c @ powers[j - i] @ P @ c
            out[SHAPING_STATES + j, SHAPING_STATES + i] = out[SHAPING_STATES + i,
                                                              SHAPING_STATES + j]
    return out


def augment(batch: LinearGaussianBatch, Phi_s: np.ndarray, Q_s: np.ndarray,
            delay: int) -> LinearGaussianBatch:
    """The models of the module docstring from the known-input ``batch`` (F (N, 16, 16),
    B (N, 16, 2) the step's input matrix G, Q (16, 16) or per model, H (N, p, 16)): F, Q and H
    of ``z = (x, s, r)``, and a zero input matrix (no input is known)."""
    if delay < 1:
        raise ValueError(f"delay must be at least one sample, got {delay}")
    F, G, H = np.asarray(batch.F), np.asarray(batch.B), np.asarray(batch.H)
    if F.ndim == 2:
        F, G, H = F[None], G[None], H[None]
    N, n = F.shape[0], N_STATES + SHAPING_STATES + delay
    s0, r0 = N_STATES, N_STATES + SHAPING_STATES
    F_aug = np.zeros((N, n, n))
    F_aug[:, :s0, :s0] = F
    F_aug[:, :s0, s0 + 1] += G[:, :, 0]                 # leading wheelset: ẏt = s[1]
    F_aug[:, :s0, r0 + delay - 1] += G[:, :, 1]         # trailing: ẏt d samples earlier
    F_aug[:, s0:r0, s0:r0] = Phi_s
    F_aug[:, r0, s0 + 1] = 1.0                          # r_k[0] = s_{k−1}[1]
    for i in range(1, delay):
        F_aug[:, r0 + i, r0 + i - 1] = 1.0              # r_k[i] = r_{k−1}[i−1]
    Q = np.asarray(batch.Q)
    Q_aug = np.zeros(Q.shape[:-2] + (n, n))
    Q_aug[..., :s0, :s0] = Q
    Q_aug[..., s0:r0, s0:r0] = Q_s
    H_aug = np.zeros(H.shape[:-1] + (n,))
    H_aug[..., :s0] = H
    return LinearGaussianBatch(F_aug, Q_aug, H_aug, batch.R, np.zeros((N, n, G.shape[-1])))


def unknown_track_system(system, Phi_s: np.ndarray, Q_s: np.ndarray, delay: int):
    """``system(theta) -> LinearGaussianBatch`` of :func:`augment` around a known-input
    ``system`` (:func:`railpaper.models.lateral_16state.lateral_system`); its ``n_states``
    attribute is the augmented state's size and ``track_covariance`` the track states'
    stationary covariance (:func:`track_covariance`, the filters' start)."""

    def augmented(theta: np.ndarray) -> LinearGaussianBatch:
        return augment(system(theta), Phi_s, Q_s, delay)

    augmented.n_states = N_STATES + SHAPING_STATES + delay
    augmented.track_covariance = track_covariance(Phi_s, Q_s, delay)
    return augmented


__all__ = ["SHAPING_STATES", "augment", "delay_steps", "discrete_shaping", "track_covariance",
           "unknown_track_system"]
