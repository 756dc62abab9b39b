"""A truth plant for paper 003's lateral vehicle with what the linear model leaves out.

Same 7 DOF, 16 states, input and parameters as :mod:`railpaper.models.lateral_16state` (its
state order, θ = (Csy, λ, Kpy, Ksy, Csaly) and
:data:`~railpaper.models.lateral_16state.FIXED_KEYS`), but the wheel–rail forces are nonlinear:

* the creep forces of each wheel saturate at μN (:func:`railpaper.contact.creep_forces`,
  Vermeulen–Johnson with the model's f11, f22);
* the rolling-radius difference is ``Δr(d)`` of :func:`railpaper.contact.rolling_radius_difference`
  instead of ``2 λ d`` (λ of θ is its small-amplitude slope).

The linear model's wheel–rail terms, per wheelset j, are a lateral force ``2 F_y`` and a yaw
moment ``2 l0 F_x`` with, per wheel, ``F_y = −f22 ξ_y``, ``F_x = −f11 ξ_x``, creepages
``ξ_y = ẏw/v − ψw`` and ``ξ_x = l0 ψ̇w / v + Δr(d) / (2 r0)`` (right wheel; the left one has
−ξ_x and the same ξ_y, hence the same saturation).  Everything else — suspension, inertia, the
track input through d — is the linear model with f11 = f22 = 0.  With μ = ∞ and y_c = ∞ the
plant is the linear model exactly; :func:`simulate_truth` then reproduces
:func:`railpaper.models.lateral_16state.simulate_truth` to the RK4 error.  The normal load is the
static wheel load (no load transfer), and gravitational stiffness, spin creep and flange contact
stay out, as in the linear model.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from railpaper import contact
from railpaper.models import lateral_16state


@dataclass(frozen=True)
class WheelRail:
    """Nonlinear wheel–rail contact of the truth plant.

    Attributes
    ----------
    friction : float
        Friction coefficient μ, 1 (``numpy.inf``: creep forces never saturate).
    wheel_load_N : float
        Static normal load of one wheel, N.
    conicity_scale_m : float
        y_c of :func:`railpaper.contact.rolling_radius_difference`, m (``numpy.inf``: linear
        conicity).
    """

    friction: float
    wheel_load_N: float
    conicity_scale_m: float

    @classmethod
    def linear(cls) -> "WheelRail":
        """The linear model's contact (μ = ∞, y_c = ∞; the load is then irrelevant)."""
        return cls(np.inf, 1.0, np.inf)


_WHEELSETS = ((0, 3, 2, 14), (4, 7, 6, 15))      # (ẏw, ψw, ψ̇w, d) of wheelsets 1 and 2


class TruthPlant:
    """Right-hand side and measurements of the nonlinear lateral plant for one θ and speed.

    Parameters
    ----------
    fixed : dict
        Fixed quantities (:data:`~railpaper.models.lateral_16state.FIXED_KEYS`, SI units).
    theta : array_like, shape (5,)
        (Csy N s/m, λ, Kpy N/m, Ksy N/m, Csaly N s/m).
    speed_mps : float
        Vehicle speed v, m/s.
    wheel_rail : WheelRail
        Contact nonlinearities.
    """

    def __init__(self, fixed: dict, theta, speed_mps: float, wheel_rail: WheelRail):
        self.fixed, self.theta = dict(fixed), np.asarray(theta, float)
        self.v, self.wr = float(speed_mps), wheel_rail
        self.A_free = lateral_16state.build_A_direct(dict(fixed, f11=0.0, f22=0.0), self.theta,
                                                     self.v)
        self.B = lateral_16state.input_matrix()

    def creepages(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(ξ_x, ξ_y), each (..., 2) for the two wheelsets (right wheel), 1, of states (..., 16)."""
        fx, v = self.fixed, self.v
        idx = np.array(_WHEELSETS)
        vy, psi, vpsi, d = (x[..., idx[:, c]] for c in range(4))
        dr = contact.rolling_radius_difference(d, self.theta[1], self.wr.conicity_scale_m)
        return fx["l0"] * vpsi / v + dr / (2.0 * fx["r0"]), vy / v - psi

    def wheel_forces(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(F_x, F_y) of the right wheel of each wheelset, (..., 2) each, N."""
        xi_x, xi_y = self.creepages(x)
        return contact.creep_forces(xi_x, xi_y, self.fixed["f11"], self.fixed["f22"],
                                    self.wr.wheel_load_N, self.wr.friction)

    def saturation(self, x: np.ndarray) -> np.ndarray:
        """β = |F_lin| / (μN) of each wheelset, (..., 2), 1 (0 when μ = ∞)."""
        xi_x, xi_y = self.creepages(x)
        lin = np.hypot(self.fixed["f11"] * xi_x, self.fixed["f22"] * xi_y)
        return lin / (self.wr.friction * self.wr.wheel_load_N)

    def derivative(self, x: np.ndarray, u: np.ndarray) -> np.ndarray:
        """ẋ (..., 16) for states x (..., 16) and input u (..., 2) = (ẏt1, ẏt2), m/s."""
        xdot = x @ self.A_free.T + np.asarray(u, float) @ self.B.T
        f_x, f_y = self.wheel_forces(x)
        for j, (iv, _, ivpsi, _) in enumerate(_WHEELSETS):
            xdot[..., iv] += 2.0 * f_y[..., j] / self.fixed["mw"]
            xdot[..., ivpsi] += 2.0 * self.fixed["l0"] * f_x[..., j] / self.fixed["iwz"]
        return xdot

    def measurements(self, x: np.ndarray) -> np.ndarray:
        """The five channels (..., 5) of :data:`~railpaper.models.lateral_16state.CHANNELS` at
        states x: the four lateral accelerations (m/s², from the nonlinear forces; the input
        does not enter them) and the bogie yaw rate (rad/s)."""
        acc = self.derivative(x, np.zeros(x.shape[:-1] + (2,)))[..., list(lateral_16state.ACC_ROWS)]
        yaw = lateral_16state.YAW_RATE_STATE
        return np.concatenate([acc, x[..., yaw:yaw + 1]], axis=-1)


def simulate_truth(fixed: dict, theta, speed_mps: float, dt_fine_s: float, u_fine: np.ndarray,
                   wheel_rail: WheelRail) -> np.ndarray:
    """States of the nonlinear plant from rest, fixed-step classical RK4, input held per step.

    Parameters
    ----------
    fixed, theta, speed_mps
        As in :class:`TruthPlant`.
    dt_fine_s : float
        Integration step h, s (the chapter's dt_s / truth_substeps).
    u_fine : ndarray, shape (K, 2)
        ``u_fine[k-1]`` = (ẏt1, ẏt2), m/s, held over step k (as
        :func:`railpaper.models.lateral_16state.simulate_truth`).
    wheel_rail : WheelRail
        Contact nonlinearities (:meth:`WheelRail.linear` for the linear model).

    Returns
    -------
    x : ndarray, shape (K+1, 16)
        ``x[0] = 0``, ``x[k]`` after step k.  Local error O(h⁵); at 300 km/h and h = 1e-4 s the
        fastest creep mode has |λ| h ≈ 0.015.
    """
    plant = TruthPlant(fixed, theta, speed_mps, wheel_rail)
    u_fine = np.asarray(u_fine, float)
    h = float(dt_fine_s)
    x = np.zeros((len(u_fine) + 1, lateral_16state.N_STATES))
    for k, u in enumerate(u_fine):
        x[k + 1] = rk4_step(plant.derivative, x[k], u, h)
    return x


def rk4_step(derivative, x: np.ndarray, u: np.ndarray, h: float) -> np.ndarray:
    """One classical Runge–Kutta step of ``ẋ = derivative(x, u)`` over h, u held."""
    k1 = derivative(x, u)
    k2 = derivative(x + 0.5 * h * k1, u)
    k3 = derivative(x + 0.5 * h * k2, u)
    k4 = derivative(x + h * k3, u)
    return x + h / 6.0 * (k1 + 2.0 * k2 + 2.0 * k3 + k4)


__all__ = ["TruthPlant", "WheelRail", "rk4_step", "simulate_truth"]
