"""The container of N linear-Gaussian state-space models, shared by models and estimators.

Models build it (:mod:`railpaper.models.linear_toys`, :mod:`railpaper.models.lateral_16state`)
and estimators consume it (:mod:`railpaper.engine.kalman_bank`, ``rbpf``, ``qgrbpf``,
``crlb``), so it lives below both layers: neither imports the other.
"""

from __future__ import annotations

import numpy as np


class LinearGaussianBatch:
    """Matrices of N linear-Gaussian models (one per particle or grid point), or of one model.

    ``x_k = F x_{k-1} + B u_k + noise(Q)``, ``y_k = H x_k + noise(R)``.  Each matrix is either
    shared (2-D) or per model (3-D with leading axis N).  Units are those of the model's state
    ``x``, input ``u`` and measurement ``y``.

    Attributes
    ----------
    F : ndarray, (n, n) or (N, n, n)
        State transition matrix over one sample (dimensionless).
    Q : ndarray, (n, n) or (N, n, n)
        Process-noise covariance in state coordinates (``G Q_w Gᵀ``), state units squared.
    H : ndarray, (p, n) or (N, p, n)
        Measurement matrix, measurement units per state unit.
    R : ndarray, (p, p) or (N, p, p)
        Measurement-noise covariance, measurement units squared.
    B : ndarray, (n, m) or (N, n, m), optional
        Input matrix of the discrete model, state units per input unit.
    """

    __slots__ = ("F", "Q", "H", "R", "B")

    def __init__(self, F, Q, H, R, B=None):
        self.F = np.asarray(F, float)
        self.Q = np.asarray(Q, float)
        self.H = np.asarray(H, float)
        self.R = np.asarray(R, float)
        self.B = None if B is None else np.asarray(B, float)

    def take(self, indices: np.ndarray) -> "LinearGaussianBatch":
        """The models at ``indices`` (shared matrices stay shared)."""
        def pick(M):
            return M if M is None or M.ndim < 3 else M[indices]
        return LinearGaussianBatch(pick(self.F), pick(self.Q), pick(self.H), pick(self.R),
                                   pick(self.B))
