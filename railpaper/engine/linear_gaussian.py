"""The container of N linear-Gaussian state-space models, and the model interface of the engine.

Models build it (:mod:`railpaper.models.linear_toys`, :mod:`railpaper.models.lateral_16state`)
and the engine consumes it (:mod:`railpaper.engine.kalman_bank`, ``rbpf``, ``qgrbpf``,
``ibis``, ``crlb``): a parameter filter sees a model only as a :class:`LinearGaussianSystem`,
a callable from a batch of parameter vectors to their matrices.
"""

from __future__ import annotations

from typing import Protocol

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


def merge_systems(old: LinearGaussianBatch, new: LinearGaussianBatch, take_new: np.ndarray
                  ) -> LinearGaussianBatch:
    """Per-model matrices: ``new``'s where ``take_new`` (N,) is True, else ``old``'s."""
    n = take_new.shape[0]

    def pick(a, b):
        if a is None:
            return None
        if a.ndim == 2 and b.ndim == 2 and np.array_equal(a, b):
            return a                                                      # shared, unchanged
        a = np.broadcast_to(a, (n,) + a.shape[-2:])
        b = np.broadcast_to(b, (n,) + b.shape[-2:])
        return np.where(take_new[:, None, None], b, a)
    return LinearGaussianBatch(*(pick(getattr(old, k), getattr(new, k))
                                 for k in ("F", "Q", "H", "R", "B")))


def concat_systems(batches: list[LinearGaussianBatch], sizes: list[int]) -> LinearGaussianBatch:
    """The models of ``batches`` one after another (batch j holds ``sizes[j]`` models); a matrix
    shared by every batch (the same 2-D array) stays shared."""
    def join(mats):
        if mats[0] is None:
            return None
        if all(M.ndim == 2 for M in mats) and all(np.array_equal(mats[0], M) for M in mats):
            return mats[0]
        return np.concatenate([np.broadcast_to(M, (k,) + M.shape[-2:])
                               for M, k in zip(mats, sizes)])
    return LinearGaussianBatch(*(join([getattr(b, k) for b in batches])
                                 for k in ("F", "Q", "H", "R", "B")))


class LinearGaussianSystem(Protocol):
    """A model as the engine sees it: ``system(theta)`` gives the matrices of N models.

    ``theta`` is an (N, d) array of parameter vectors (the particles, the grid points); the
    result holds per-model matrices (leading axis N) where they depend on θ and shared ones
    where they do not.  Paper 004's toy, paper 003's Eq. (18) toy and paper 003's lateral
    vehicle (whose ``system`` discretises A(θ) per particle) all have this form.
    """

    def __call__(self, theta: np.ndarray) -> LinearGaussianBatch: ...


class AffineSystem:
    """A :class:`LinearGaussianSystem` whose transition and input matrices are affine in θ::

        F(θ) = F0 + Σ_j θ_j F_j,    B(θ) = B0 + Σ_j θ_j B_j,    Q, H, R shared.

    Both toys are of this form (paper 004: F = [[0, 1], [a, b]]; paper 003's Eq. (18):
    F = [[0, 1.5], [x1, x2]], B = [x3, x4]ᵀ), so a compiled filter can form a particle's
    matrices from θ where it uses them (:mod:`railpaper.engine.affine_pass`) instead of
    receiving them.  Calling it gives the same :class:`LinearGaussianBatch` as any model.

    Attributes
    ----------
    F0 : ndarray, (n, n);  F_theta : ndarray, (d, n, n)
    Q : ndarray, (n, n);  H : ndarray, (p, n);  R : ndarray, (p, p)
    B0 : ndarray, (n, m) or None;  B_theta : ndarray, (d, n, m) or None
    """

    def __init__(self, F0, F_theta, Q, H, R, B0=None, B_theta=None):
        self.F0, self.F_theta = np.asarray(F0, float), np.asarray(F_theta, float)
        self.Q, self.H, self.R = (np.asarray(M, float) for M in (Q, H, R))
        self.B0 = None if B0 is None else np.asarray(B0, float)
        self.B_theta = None if B_theta is None else np.asarray(B_theta, float)
        d, n = self.F_theta.shape[0], self.F0.shape[0]
        if self.F_theta.shape != (d, n, n) or (self.B0 is None) != (self.B_theta is None):
            raise ValueError("AffineSystem: F_theta must be (d, n, n), and B0 and B_theta "
                             "given together")

    @property
    def n_params(self) -> int:
        """d, the length of θ."""
        return self.F_theta.shape[0]

    def __call__(self, theta: np.ndarray) -> LinearGaussianBatch:
        theta = np.atleast_2d(np.asarray(theta, float))
        F = _affine(self.F0, self.F_theta, theta)                       # F0 + Σ θ_j F_j
        B = None if self.B0 is None else _affine(self.B0, self.B_theta, theta)
        return LinearGaussianBatch(F, self.Q, self.H, self.R, B)


def _affine(M0: np.ndarray, M_theta: np.ndarray, theta: np.ndarray) -> np.ndarray:
    """``M0 + Σ_j θ_j M_j`` per row of θ, summing only the non-zero coefficients (a constant
    entry stays exact even where θ is infinite)."""
    M = np.repeat(M0[None], theta.shape[0], axis=0)
    for j in range(M_theta.shape[0]):
        nonzero = M_theta[j] != 0
        if nonzero.any():
            M[:, nonzero] += theta[:, j, None] * M_theta[j][nonzero]
    return M
