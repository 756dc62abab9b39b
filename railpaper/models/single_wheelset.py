"""Paper 001: single-wheelset vertical vehicle model (Li, Zheng, Chai 2014, Eqs. 5-7).

State ``x = [ż_c, z_c, ż_w, z_w]`` (m/s, m, m/s, m), displacements positive downward, measured
from static equilibrium; input ``q`` = vertical track irregularity under the wheelset (m).

    M_c z̈_c = −K_p (z_c − z_w) − C_p (ż_c − ż_w)
    M_w z̈_w =  K_p (z_c − z_w) + C_p (ż_c − ż_w) − K_r (z_w − q)

with the errata fixed (Eqs. 5-6 print first derivatives; row 3 of A divides by M_c; Table 1
prints K_p in N/mm).  K_r is the wheelset's linearised contact stiffness (Eq. 3), under one of
two readings of the paper's P0 (``p0_basis``):

* ``"wheel"`` (the chapter's default): Hertz acts per wheel–rail contact, so the wheelset has two
  contacts, each at the per-wheel static load P0 = (M_c + M_w) g / 2 with the stiffness
  3/(2G) P0^(1/3); K_r = 2 · 3/(2G) P0^(1/3);
* ``"wheelset"`` (the text's words, "P0 is the wheelset static load"): Eq. (3) applied once to
  the wheelset's static load P0 = (M_c + M_w) g, one contact; K_r = 3/(2G) P0^(1/3), a factor
  2^(-2/3) ≈ 0.63 of the other reading.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from railpaper import contact
from railpaper.data import data_path, load_quantities, values

#: Readings of the paper's P0 (Eq. 3): per wheel (two contacts) or per wheelset (one contact).
P0_BASES = ("wheel", "wheelset")

PARAMETER_KEYS = (
    "car_body_mass_kg", "wheelset_mass_kg", "suspension_damping_Ns_per_m",
    "suspension_stiffness_N_per_m", "wheel_radius_m", "gravity_m_per_s2", "measurement_noise_D",
)


@dataclass(frozen=True)
class SingleWheelset:
    """Parameters of the paper-001 vehicle (SI units)."""

    car_body_mass_kg: float
    wheelset_mass_kg: float
    suspension_damping_Ns_per_m: float
    suspension_stiffness_N_per_m: float
    wheel_radius_m: float
    gravity_m_per_s2: float
    measurement_noise_D: float = 0.01
    tread: str = "worn"
    p0_basis: str = "wheel"

    def __post_init__(self):
        if self.p0_basis not in P0_BASES:
            raise ValueError(f"p0_basis must be one of {P0_BASES}, got {self.p0_basis!r}")

    @property
    def hertz_constant_m_per_N23(self) -> float:
        """Hertz contact constant G, m/N^(2/3) (worn tread, paper 001 Table 1)."""
        return contact.hertz_constant(self.wheel_radius_m, self.tread)

    @property
    def contacts(self) -> int:
        """Number of Hertz contacts carrying the wheelset: 2 (``"wheel"``) or 1 (``"wheelset"``)."""
        return 2 if self.p0_basis == "wheel" else 1

    @property
    def static_wheel_load_N(self) -> float:
        """Static load P0 of one contact, N: (M_c + M_w) g / contacts."""
        return (self.car_body_mass_kg + self.wheelset_mass_kg) * self.gravity_m_per_s2 / self.contacts

    @property
    def contact_stiffness_N_per_m(self) -> float:
        """Wheelset contact stiffness K_r = contacts · 3/(2G) P0^(1/3), N/m."""
        return self.contacts * contact.linearised_stiffness(self.static_wheel_load_N,
                                                            self.hertz_constant_m_per_N23)


def load_parameters(path=None, **overrides) -> SingleWheelset:
    """Paper-001 parameters from ``data/reduced-order-observer/parameters.toml``."""
    path = path or data_path("reduced-order-observer/parameters.toml")
    params = values(load_quantities(path, PARAMETER_KEYS))
    params.update(overrides)
    for key in PARAMETER_KEYS[:-1]:
        if not params[key] > 0:
            raise ValueError(f"parameter '{key}' must be > 0, got {params[key]!r}")
    return SingleWheelset(**params)


def state_space(vehicle: SingleWheelset) -> tuple[np.ndarray, np.ndarray]:
    """Continuous ``(A, B)`` of Eq. (7), corrected: ``ẋ = A x + B q``."""
    Mc, Mw = vehicle.car_body_mass_kg, vehicle.wheelset_mass_kg
    Cp, Kp = vehicle.suspension_damping_Ns_per_m, vehicle.suspension_stiffness_N_per_m
    Kr = vehicle.contact_stiffness_N_per_m
    A = np.array([
        [-Cp / Mc, -Kp / Mc, Cp / Mc, Kp / Mc],            # z̈_c = (−C_p(ż_c−ż_w) − K_p(z_c−z_w))/M_c
        [1.0, 0.0, 0.0, 0.0],                              # d z_c/dt = ż_c
        [Cp / Mw, Kp / Mw, -Cp / Mw, -(Kr + Kp) / Mw],     # z̈_w: row 3 divided by M_w (erratum)
        [0.0, 0.0, 1.0, 0.0],                              # d z_w/dt = ż_w
    ])
    B = np.array([[0.0], [0.0], [Kr / Mw], [0.0]])         # B = [0 0 K_r/M_w 0]^T
    return A, B


def paper_output_matrix(vehicle: SingleWheelset) -> np.ndarray:
    """The paper's C of Eq. (8): body acceleration, z_c, ż_w, z_w."""
    A, _ = state_space(vehicle)
    return np.vstack([A[0], np.eye(4)[1:]])


def nonlinear_derivative(vehicle: SingleWheelset, x: np.ndarray, q_m: float) -> np.ndarray:
    """ẋ of the plant with nonlinear Hertz contact (loss of contact when compression ≤ 0).

    The contact force per wheel is (δ/G)^1.5 with δ = δ0 + z_w − q, δ0 = G P0^(2/3) the static
    compression; gravity and the static load cancel at equilibrium, so with the linear
    suspension the equilibrium is the same as the linear model's.
    """
    Mc, Mw = vehicle.car_body_mass_kg, vehicle.wheelset_mass_kg
    Cp, Kp = vehicle.suspension_damping_Ns_per_m, vehicle.suspension_stiffness_N_per_m
    G, P0 = vehicle.hertz_constant_m_per_N23, vehicle.static_wheel_load_N
    delta0 = contact.static_compression(P0, G)
    suspension = Kp * (x[1] - x[3]) + Cp * (x[0] - x[2])
    dynamic_contact = vehicle.contacts * (contact.hertz_force(delta0 + x[3] - q_m, G) - P0)
    return np.array([-suspension / Mc, x[0], (suspension - dynamic_contact) / Mw, x[2]])


def dynamic_contact_force_N(vehicle: SingleWheelset, z_w_m, q_m, plant: str = "linear"):
    """Dynamic wheel–rail force on the wheelset (total minus static load n P0), N, compression +.

    ``plant="linear"``: K_r (z_w − q) (Eq. 4); ``plant="hertz"``: n[(δ0 + z_w − q)/G]^1.5 − n P0,
    with n = ``vehicle.contacts``.
    """
    z_w_m, q_m = np.asarray(z_w_m, float), np.asarray(q_m, float)
    if plant == "linear":
        return vehicle.contact_stiffness_N_per_m * (z_w_m - q_m)
    G, P0 = vehicle.hertz_constant_m_per_N23, vehicle.static_wheel_load_N
    delta0 = contact.static_compression(P0, G)
    return vehicle.contacts * (contact.hertz_force(delta0 + z_w_m - q_m, G) - P0)
