"""Paper 003's lateral vehicle with model error the filters do not have: the fault appendix's
truth on the last rung of its realism ladder.

Three things a real vehicle has and the filters' linear 16-state model
(:mod:`railpaper.models.lateral_16state`) leaves out, all at once:

* **saturating creep and a nonlinear rolling-radius difference** — the wheel–rail forces of
  :class:`railpaper.models.lateral_truth.TruthPlant` (Vermeulen–Johnson saturation at μN,
  ``Δr = 2 λ y (1 + (y / y_c)²)``);
* **a conicity the filters do not know** — the truth's small-amplitude conicity λ is whatever
  θ it is given, the filters keep the nominal one;
* **a series stiffness in the anti-yaw damper** — the damper is a Maxwell element: its force F
  (the one ``C_saly L_bw ψ̇_b`` of the linear model) obeys ``Ḟ = K_s (L_bw ψ̇_b − F / C_saly)``
  and acts on the bogie frame as the yaw moment ``−L_bw F``.  For ``K_s → ∞`` it is the
  linear model's damper.  A lost damper (``C_saly = 0``) carries no force: F is set to zero.

The state is the linear model's 16 (same order) and F (N), :data:`DAMPER_FORCE_STATE`.
Measurements are the linear model's five channels of the nonlinear forces
(:meth:`TruthPlant.measurements`; the damper moment acts on the bogie yaw, which no channel
reads directly).  :func:`linear_matrix` is the plant linearised at rest with linear contact
(the reference of the tests and of the critical speed); :func:`simulate_schedule` integrates
the plant with θ piecewise constant, as the fault records need.
"""

from __future__ import annotations

import numpy as np

from railpaper.models import lateral_16state
from railpaper.models.lateral_truth import TruthPlant, WheelRail, rk4_step

#: Index of the anti-yaw damper force in the state, N.
DAMPER_FORCE_STATE = lateral_16state.N_STATES
#: States of the plant: the linear model's 16 and the damper force.
N_STATES = lateral_16state.N_STATES + 1
#: |λ| h below which the damper force's own relaxation (λ = −K_s / C_saly) keeps classical RK4
#: stable (its real-axis bound is 2.785).
RK4_STABLE_STEP = 2.5
_CSALY = lateral_16state.PARAM_NAMES.index("csaly")
_YAW_RATE = lateral_16state.YAW_RATE_STATE


def _without_damper(theta) -> np.ndarray:
    """θ with C_saly = 0: the damper is the plant's own element, not the linear model's."""
    out = np.array(theta, float)
    out[_CSALY] = 0.0
    return out


class ModelErrorPlant:
    """Right-hand side and measurements of the plant for one θ, speed, contact and series
    stiffness.

    Parameters
    ----------
    fixed : dict
        Fixed quantities (:data:`~railpaper.models.lateral_16state.FIXED_KEYS`, SI units).
    theta : array_like, shape (5,)
        The truth's (Csy N s/m, λ, Kpy N/m, Ksy N/m, Csaly N s/m).
    speed_mps : float
        Vehicle speed v, m/s.
    wheel_rail : WheelRail
        Contact nonlinearities (:meth:`WheelRail.linear` for linear contact).
    series_stiffness_N_per_m : float
        K_s of the anti-yaw damper, N/m (as C_saly, the dampers of the bogie together).
    """

    def __init__(self, fixed: dict, theta, speed_mps: float, wheel_rail: WheelRail,
                 series_stiffness_N_per_m: float):
        if not series_stiffness_N_per_m > 0:
            raise ValueError("the series stiffness must be positive, N/m")
        self.contact = TruthPlant(fixed, _without_damper(theta), speed_mps, wheel_rail)
        self.damping_N_s_per_m = float(np.asarray(theta, float)[_CSALY])
        self.stiffness_N_per_m = float(series_stiffness_N_per_m)
        self.arm_m, self.yaw_inertia_kg_m2 = float(fixed["lbw"]), float(fixed["ib"])

    def derivative(self, x: np.ndarray, u: np.ndarray) -> np.ndarray:
        """ẋ (..., 17) for states x (..., 17) and input u (..., 2) = (ẏt1, ẏt2), m/s."""
        xdot = np.empty(np.shape(x))
        xdot[..., :DAMPER_FORCE_STATE] = self.contact.derivative(x[..., :DAMPER_FORCE_STATE], u)
        force = x[..., DAMPER_FORCE_STATE]
        xdot[..., _YAW_RATE] -= self.arm_m * force / self.yaw_inertia_kg_m2   # M = −L_bw F
        if self.damping_N_s_per_m > 0:      # Ḟ = K_s (L_bw ψ̇_b − F / C)
            xdot[..., DAMPER_FORCE_STATE] = self.stiffness_N_per_m * (
                self.arm_m * x[..., _YAW_RATE] - force / self.damping_N_s_per_m)
        else:                               # no damper: no force
            xdot[..., DAMPER_FORCE_STATE] = 0.0
        return xdot

    def measurements(self, x: np.ndarray) -> np.ndarray:
        """The five channels (..., 5) of :data:`~railpaper.models.lateral_16state.CHANNELS`."""
        return self.contact.measurements(x[..., :DAMPER_FORCE_STATE])


def linear_matrix(fixed: dict, theta, speed_mps: float,
                  series_stiffness_N_per_m: float) -> np.ndarray:
    """The plant's A (17×17, 1/s) with linear contact: the linear model's A without its damper
    term, and the damper's two rows (for C_saly > 0)."""
    theta = np.asarray(theta, float)
    A = np.zeros((N_STATES, N_STATES))
    A[:DAMPER_FORCE_STATE, :DAMPER_FORCE_STATE] = lateral_16state.build_A_direct(
        fixed, _without_damper(theta), speed_mps)
    A[_YAW_RATE, DAMPER_FORCE_STATE] = -fixed["lbw"] / fixed["ib"]
    if theta[_CSALY] > 0:
        A[DAMPER_FORCE_STATE, _YAW_RATE] = series_stiffness_N_per_m * fixed["lbw"]
        A[DAMPER_FORCE_STATE, DAMPER_FORCE_STATE] = -series_stiffness_N_per_m / theta[_CSALY]
    return A


def critical_speed(fixed: dict, theta, speeds_mps: np.ndarray,
                   series_stiffness_N_per_m: float) -> tuple[np.ndarray, float]:
    """The linearised plant's (:func:`linear_matrix`) least-damped real part over
    ``speeds_mps`` and the first speed (m/s) where it crosses 0 (-1: none), as
    :func:`railpaper.models.lateral_16state.critical_speed`."""
    return lateral_16state.first_unstable_speed(
        lambda v: linear_matrix(fixed, theta, v, series_stiffness_N_per_m), speeds_mps)


def simulate_schedule(fixed: dict, thetas, starts, speed_mps: float, dt_fine_s: float,
                      u_fine: np.ndarray, wheel_rail: WheelRail,
                      series_stiffness_N_per_m: float) -> np.ndarray:
    """States (K+1, 17) from rest, fixed-step classical RK4, input held per step, θ piecewise
    constant: ``thetas[i]`` from fine step ``starts[i]`` (``starts[0] = 0``, increasing) on, as
    :func:`railpaper.models.lateral_16state.simulate_truth_schedule`.  Where C_saly becomes 0
    the damper force is set to 0 (the limit of a Maxwell element whose damping vanishes)."""
    u_fine = np.asarray(u_fine, float)
    if len(thetas) != len(starts) or not starts or starts[0] != 0:
        raise ValueError("need one start per θ, the first at step 0")
    h = float(dt_fine_s)
    x = np.zeros((len(u_fine) + 1, N_STATES))
    ends = list(starts[1:]) + [len(u_fine)]
    for theta, start, end in zip(thetas, starts, ends):
        plant = ModelErrorPlant(fixed, theta, speed_mps, wheel_rail, series_stiffness_N_per_m)
        damping = plant.damping_N_s_per_m
        if 0 < damping < series_stiffness_N_per_m * h / RK4_STABLE_STEP:
            raise ValueError(f"C_saly = {damping:g} N s/m is too small for RK4 at h = {h:g} s "
                             f"(K_s h / C > {RK4_STABLE_STEP}); treat the damper as lost (0) "
                             "or take a shorter step")
        if damping == 0:
            x[start, DAMPER_FORCE_STATE] = 0.0
        for k in range(start, min(end, len(u_fine))):
            x[k + 1] = rk4_step(plant.derivative, x[k], u_fine[k], h)
    return x


__all__ = ["DAMPER_FORCE_STATE", "N_STATES", "RK4_STABLE_STEP", "ModelErrorPlant",
           "critical_speed", "linear_matrix", "simulate_schedule"]
