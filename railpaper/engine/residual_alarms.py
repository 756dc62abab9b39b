"""The classical residual test of an abrupt change: whitened innovations and CUSUM/GLR alarms.

The nominal model's Kalman filter turns the measurements into innovations ``v_k = y_k − H x⁻_k``
with covariance ``S_k = H P⁻_k Hᵀ + R``; whitened by the Cholesky factor ``S_k = L_k L_kᵀ``,

    z_k = L_k⁻¹ v_k ~ N(0, I_p), independent over k,

as long as the data follow the nominal model.  A change of the system (a failed damper) shows as
a change of the law of z: a shift of its mean, or a growth of its size.  Two alarm statistics of
Basseville & Nikiforov (*Detection of Abrupt Changes*, 1993, §2.2 and §2.4), each a function of z
only, so any detector threshold can be set on fault-free records:

* **CUSUM** (Page) for a known post-change law.  Here the size: ``z ~ N(0, σ² I)`` after the
  change, σ² > 1, with log-likelihood ratio per step
  ``s_k = −(p/2) log σ² + (1 − 1/σ²) ‖z_k‖² / 2`` and the recursion
  ``g_k = max(0, g_{k−1} + s_k)``, g_0 = 0.  It equals ``max(0, max_j Σ_{i=j..k} s_i)``, the
  largest log-likelihood ratio of "changed at j" against "no change" over every change time j.
* **GLR** for an unknown mean shift ν after an unknown time j inside a window of W steps:
  ``g_k = max_{k−W < j ≤ k} ‖Σ_{i=j..k} z_i‖² / (2 (k − j + 1))``, the log-likelihood ratio
  maximised over ν (its estimate is the window's mean of z) and over j.

An alarm is the first step whose statistic reaches its threshold (:func:`first_alarm`).

Example (a scalar random walk observed in noise; from step 150 the sensor noise is 3 times
larger, which the nominal filter does not know)::

    >>> import numpy as np
    >>> from railpaper.engine.linear_gaussian import LinearGaussianBatch
    >>> rng = np.random.default_rng(1)
    >>> x = np.cumsum(0.1 * rng.standard_normal(300))
    >>> y = (x + 0.5 * np.where(np.arange(300) < 150, 1.0, 3.0) * rng.standard_normal(300))
    >>> nominal = LinearGaussianBatch([[1.0]], [[0.01]], [[1.0]], [[0.25]])
    >>> z = whitened_innovations(nominal, y[:, None], np.zeros(1), np.eye(1)).z
    >>> alarm = first_alarm(cusum_variance(z, variance_ratio=4.0), threshold=8.0)
    >>> bool(150 <= alarm < 200)
    True
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from railpaper.engine.linear_gaussian import LinearGaussianBatch


@dataclass(frozen=True)
class Innovations:
    """The nominal filter's residuals, row k − 1 after y_k.

    Attributes
    ----------
    z : ndarray, (K, p)
        Whitened innovations ``L_k⁻¹ (y_k − H x⁻_k)``, dimensionless; N(0, I) under the nominal
        model.
    log_likelihood : ndarray, (K,)
        ``log N(y_k; H x⁻_k, S_k)`` (natural log).
    """

    z: np.ndarray
    log_likelihood: np.ndarray


def whitened_innovations(system: LinearGaussianBatch, y: np.ndarray, x0: np.ndarray,
                         P0: np.ndarray, u: np.ndarray | None = None) -> Innovations:
    """Run the nominal model's Kalman filter (one model: 2-D matrices) over ``y`` (K, p) with
    inputs ``u`` (K, m) or None, from ``x0``, ``P0``; return its whitened innovations."""
    for name in ("F", "Q", "H", "R"):
        if getattr(system, name).ndim != 2:
            raise ValueError(f"whitened_innovations: one nominal model is needed, "
                             f"got {name} of shape {getattr(system, name).shape}")
    y = np.asarray(y, float)
    F, Q, H, R = system.F, system.Q, system.H, system.R
    Bu = (np.zeros((len(y), F.shape[0])) if u is None or system.B is None
          else np.asarray(u, float) @ system.B.T)                 # B u_k, every step at once
    x, P = np.asarray(x0, float).copy(), np.asarray(P0, float).copy()
    identity = np.eye(F.shape[0])
    z, log_lik = np.empty(y.shape), np.empty(len(y))
    log_2pi = y.shape[1] * np.log(2.0 * np.pi)
    for k in range(len(y)):
        x = F @ x + Bu[k]                                     # x⁻ = F x + B u
        P = F @ P @ F.T + Q                                   # P⁻ = F P Fᵀ + Q
        v = y[k] - H @ x                                      # innovation
        PHt = P @ H.T
        S = H @ PHt + R                                       # S = H P⁻ Hᵀ + R
        L = np.linalg.cholesky(S)                             # S = L Lᵀ
        z[k] = np.linalg.solve(L, v)                          # z = L⁻¹ v
        log_lik[k] = -0.5 * (z[k] @ z[k] + log_2pi) - np.log(np.diag(L)).sum()
        K = np.linalg.solve(S, PHt.T).T                       # K = P⁻ Hᵀ S⁻¹
        x = x + K @ v
        A = identity - K @ H                                  # Joseph form:
        P = A @ P @ A.T + K @ R @ K.T                         # P = A P⁻ Aᵀ + K R Kᵀ
        P = 0.5 * (P + P.T)
    return Innovations(z=z, log_likelihood=log_lik)


def cusum_variance(z: np.ndarray, variance_ratio: float) -> np.ndarray:
    """Page's CUSUM ``g_k`` (K,) of z (K, p) against ``z ~ N(0, variance_ratio · I)``."""
    if not variance_ratio > 1.0:
        raise ValueError(f"variance_ratio must be > 1 (a growth of the residuals), "
                         f"got {variance_ratio}")
    z = np.atleast_2d(np.asarray(z, float).T).T
    p = z.shape[1]
    s = (-0.5 * p * np.log(variance_ratio)                    # log-likelihood ratio per step
         + 0.5 * (1.0 - 1.0 / variance_ratio) * np.sum(z * z, axis=1))
    g, out = 0.0, np.empty(len(s))
    for k, s_k in enumerate(s):
        g = max(0.0, g + s_k)                                 # g_k = max(0, g_(k−1) + s_k)
        out[k] = g
    return out


def glr_mean_shift(z: np.ndarray, window: int) -> np.ndarray:
    """GLR statistic ``g_k`` (K,) of a mean shift in z (K, p) that began inside the last
    ``window`` steps (window ≥ 1)."""
    if window < 1:
        raise ValueError(f"window must be >= 1, got {window}")
    z = np.atleast_2d(np.asarray(z, float).T).T
    K = len(z)
    c = np.vstack([np.zeros((1, z.shape[1])), np.cumsum(z, axis=0)])    # c_k = Σ_{i≤k} z_i
    out = np.zeros(K)
    for m in range(1, window + 1):                            # m = k − j + 1 steps since j
        ks = np.arange(m, K + 1)                              # steps k (1-based) with j ≥ 1
        total = c[ks] - c[ks - m]                             # Σ_{i=j..k} z_i
        out[ks - 1] = np.maximum(out[ks - 1], np.sum(total * total, axis=1) / (2.0 * m))
    return out


def first_alarm(statistic: np.ndarray, threshold: float) -> int:
    """Index (0-based row) of the first ``statistic`` ≥ ``threshold``; −1 if none."""
    hits = np.flatnonzero(np.asarray(statistic) >= threshold)
    return int(hits[0]) if hits.size else -1


__all__ = ["Innovations", "cusum_variance", "first_alarm", "glr_mean_shift",
           "whitened_innovations"]
