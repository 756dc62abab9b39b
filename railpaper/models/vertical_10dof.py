"""Paper 000: 10-DOF vertical model of a four-axle vehicle (Zheng, Chai, Peng, Li 2016, Eqs. 1-10).

Degrees of freedom (displacements positive downward, from static equilibrium)::

    z_c, β_c, z_t1, β_t1, z_t2, β_t2, z_w1, z_w2, z_w3, z_w4

State in the paper's order (Eq. after (10))::

    x = [z_c ż_c β_c β̇_c z_t1 ż_t1 β_t1 β̇_t1 z_t2 ż_t2 β_t2 β̇_t2 z_w1 ż_w1 … z_w4 ż_w4]

Geometry (read from the signs of Eqs. 2-10): the front bogie (1) is attached to the car body at
``z_c − l_c β_c``, the rear bogie (2) at ``z_c + l_c β_c``; wheelset 1 sits under ``z_t1 − l_t β_t1``,
wheelset 2 under ``z_t1 + l_t β_t1``, wheelset 3 under ``z_t2 − l_t β_t2``, wheelset 4 under
``z_t2 + l_t β_t2``.  Wheelset 1 leads; the wheelsets see the track delayed by
``(0, 2 l_t, 2 l_c, 2 l_c + 2 l_t) / V``.

M, C and K are assembled from the springs and dampers (secondary body–bogie K_s, C_s per bogie;
primary bogie–wheelset K_p, C_p per wheelset; linearised Hertz contact per wheelset = two wheels,
``k_H = 2 · 3/(2G) P0^(1/3)`` at the per-wheel static load P0), not typed from the paper's rows.
The track irregularity ``q_i`` under wheelset i enters as the force ``k_H q_i`` (Eq. 7-10 with
``P_i − P0 ≈ k_H (z_wi − q_i)``).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import pandas as pd

from railpaper import contact
from railpaper.data import data_path, load_quantities, values

PARAMETER_KEYS = (
    "car_body_mass_kg", "bogie_mass_kg", "wheelset_mass_kg", "car_body_pitch_inertia_kg_m2",
    "bogie_pitch_inertia_kg_m2", "primary_stiffness_N_per_m", "primary_damping_Ns_per_m",
    "secondary_stiffness_N_per_m", "secondary_damping_Ns_per_m", "half_bogie_spacing_m",
    "half_wheelbase_m", "wheel_radius_m", "gravity_m_per_s2", "wheels_per_wheelset",
)

#: Degrees of freedom, in the paper's order.
DOF_NAMES = ("z_c", "beta_c", "z_t1", "beta_t1", "z_t2", "beta_t2", "z_w1", "z_w2", "z_w3", "z_w4")
#: States (paper's order): each DOF followed by its rate.
STATE_NAMES = tuple(name for dof in DOF_NAMES for name in (dof, dof + "_dot"))
#: DOF indices of the car body and bogies (what the sensors see) and of the wheelsets.
BODY_BOGIE_DOFS = (0, 1, 2, 3, 4, 5)
WHEELSET_DOFS = (6, 7, 8, 9)
#: Measurement sets of the chapter.
MEASUREMENT_SETS = ("displacements", "accelerations", "both")


@dataclass(frozen=True)
class Vertical10Dof:
    """Parameters of the paper-000 vehicle (SI units; see ``data/partial-state-observer``)."""

    car_body_mass_kg: float
    bogie_mass_kg: float
    wheelset_mass_kg: float
    car_body_pitch_inertia_kg_m2: float
    bogie_pitch_inertia_kg_m2: float
    primary_stiffness_N_per_m: float
    primary_damping_Ns_per_m: float
    secondary_stiffness_N_per_m: float
    secondary_damping_Ns_per_m: float
    half_bogie_spacing_m: float
    half_wheelbase_m: float
    wheel_radius_m: float
    gravity_m_per_s2: float
    wheels_per_wheelset: float = 2.0
    tread: str = "worn"

    @property
    def hertz_constant_m_per_N23(self) -> float:
        """Hertz contact constant G, m/N^(2/3) (worn tread, G = 3.86 R^-0.115 1e-8)."""
        return contact.hertz_constant(self.wheel_radius_m, self.tread)

    @property
    def static_wheelset_load_N(self) -> float:
        """Static load of one wheelset on the rails, (M_c/4 + M_t/2 + M_w) g, N."""
        return (self.car_body_mass_kg / 4 + self.bogie_mass_kg / 2
                + self.wheelset_mass_kg) * self.gravity_m_per_s2

    @property
    def static_wheel_load_N(self) -> float:
        """Per-wheel static load P0 (the wheelset load shared by its wheels), N."""
        return self.static_wheelset_load_N / self.wheels_per_wheelset

    @property
    def contact_stiffness_N_per_m(self) -> float:
        """Linearised contact stiffness of one wheelset, n_wheels · 3/(2G) P0^(1/3), N/m."""
        return self.wheels_per_wheelset * contact.linearised_stiffness(
            self.static_wheel_load_N, self.hertz_constant_m_per_N23)

    @property
    def axle_offsets_m(self) -> tuple[float, float, float, float]:
        """Distance of each wheelset behind the leading one, (0, 2l_t, 2l_c, 2l_c+2l_t), m."""
        lc, lt = self.half_bogie_spacing_m, self.half_wheelbase_m
        return (0.0, 2 * lt, 2 * lc, 2 * lc + 2 * lt)


def load_parameters(path=None, **overrides) -> Vertical10Dof:
    """Paper-000 parameters from ``data/partial-state-observer/parameters.toml``."""
    path = path or data_path("partial-state-observer/parameters.toml")
    params = values(load_quantities(path, PARAMETER_KEYS))
    params.update(overrides)
    for key in PARAMETER_KEYS:
        if not params[key] > 0:
            raise ValueError(f"parameter '{key}' must be > 0, got {params[key]!r}")
    return Vertical10Dof(**params)


def _point(dof: int | None = None, rot: int | None = None, arm: float = 0.0) -> np.ndarray:
    """Coefficient row of a point's vertical displacement: ``z[dof] + arm · β[rot]``."""
    a = np.zeros(10)
    if dof is not None:
        a[dof] += 1.0
    if rot is not None:
        a[rot] += arm
    return a


@dataclass
class Model:
    """Matrices of the 10-DOF model (SI units).

    Attributes
    ----------
    M, C, K : ndarray, shape (10, 10)
        Mass (kg, kg·m²), damping (N·s/m …) and stiffness (N/m …) matrices.
    F : ndarray, shape (10, 4)
        Force per metre of irregularity: generalised force = F q (N/m).
    A : ndarray, shape (20, 20)
        ``ẋ = A x + B q`` in the paper's state order, 1/s and 1/s².
    B : ndarray, shape (20, 4)
    L : ndarray, shape (4, 20)
        Functional to observe: ``z = [z_w1 … z_w4] = L x``.
    parameters : Vertical10Dof
    """

    M: np.ndarray
    C: np.ndarray
    K: np.ndarray
    F: np.ndarray
    A: np.ndarray
    B: np.ndarray
    L: np.ndarray
    parameters: Vertical10Dof
    springs: list = field(default_factory=list)

    def output_matrix(self, measurement: str) -> np.ndarray:
        """Output matrix of a measurement set (rows: z_c, β_c, z_t1, β_t1, z_t2, β_t2 …).

        ``"displacements"``: the six body/bogie displacements the paper's ``y`` lists;
        ``"accelerations"``: their six accelerations (the rows of A the paper's C holds; the
        track input has no direct feedthrough to them); ``"both"``: displacements then
        accelerations (12 rows).
        """
        disp = np.zeros((6, 20))
        for row, dof in enumerate(BODY_BOGIE_DOFS):
            disp[row, 2 * dof] = 1.0
        acc = self.A[[2 * dof + 1 for dof in BODY_BOGIE_DOFS], :]
        if measurement == "displacements":
            return disp
        if measurement == "accelerations":
            return acc.copy()
        if measurement == "both":
            return np.vstack([disp, acc])
        raise ValueError(f"unknown measurement set '{measurement}' (expected {MEASUREMENT_SETS})")

    def output_names(self, measurement: str) -> list[str]:
        """Channel names (with units) of a measurement set."""
        disp = [f"{DOF_NAMES[d]}_{'rad' if 'beta' in DOF_NAMES[d] else 'm'}" for d in BODY_BOGIE_DOFS]
        acc = [f"{DOF_NAMES[d]}_ddot_{'rad_s2' if 'beta' in DOF_NAMES[d] else 'm_s2'}"
               for d in BODY_BOGIE_DOFS]
        return {"displacements": disp, "accelerations": acc, "both": disp + acc}[measurement]


def build_model(vehicle: Vertical10Dof) -> Model:
    """Assemble M, C, K from the springs and dampers and form the state space."""
    v = vehicle
    lc, lt = v.half_bogie_spacing_m, v.half_wheelbase_m
    kH = v.contact_stiffness_N_per_m
    M = np.diag([v.car_body_mass_kg, v.car_body_pitch_inertia_kg_m2,
                 v.bogie_mass_kg, v.bogie_pitch_inertia_kg_m2,
                 v.bogie_mass_kg, v.bogie_pitch_inertia_kg_m2] + [v.wheelset_mass_kg] * 4)
    # (upper point, lower point, stiffness, damping): a spring-damper pair between two points.
    springs = [
        (_point(0, 1, -lc), _point(2), v.secondary_stiffness_N_per_m, v.secondary_damping_Ns_per_m),
        (_point(0, 1, +lc), _point(4), v.secondary_stiffness_N_per_m, v.secondary_damping_Ns_per_m),
        (_point(2, 3, -lt), _point(6), v.primary_stiffness_N_per_m, v.primary_damping_Ns_per_m),
        (_point(2, 3, +lt), _point(7), v.primary_stiffness_N_per_m, v.primary_damping_Ns_per_m),
        (_point(4, 5, -lt), _point(8), v.primary_stiffness_N_per_m, v.primary_damping_Ns_per_m),
        (_point(4, 5, +lt), _point(9), v.primary_stiffness_N_per_m, v.primary_damping_Ns_per_m),
    ] + [(_point(w), _point(), kH, 0.0) for w in WHEELSET_DOFS]   # contact: wheelset to rail
    K = np.zeros((10, 10))
    C = np.zeros((10, 10))
    for upper, lower, k, c in springs:
        d = upper - lower
        K += k * np.outer(d, d)
        C += c * np.outer(d, d)
    F = np.zeros((10, 4))
    for i, w in enumerate(WHEELSET_DOFS):
        F[w, i] = kH                      # rail point moves by q_i: force k_H q_i on wheelset i
    Minv = np.diag(1.0 / np.diag(M))
    A = np.zeros((20, 20))
    B = np.zeros((20, 4))
    pos, vel = np.arange(0, 20, 2), np.arange(1, 20, 2)
    A[pos, vel] = 1.0
    A[np.ix_(vel, pos)] = -Minv @ K
    A[np.ix_(vel, vel)] = -Minv @ C
    B[vel, :] = Minv @ F
    L = np.zeros((4, 20))
    for i, w in enumerate(WHEELSET_DOFS):
        L[i, 2 * w] = 1.0
    return Model(M=M, C=C, K=K, F=F, A=A, B=B, L=L, parameters=v, springs=springs)


def static_deflection_m(model: Model) -> np.ndarray:
    """Static DOF displacements under gravity, ``K⁻¹ M g`` on the heave DOFs (m, rad)."""
    g = np.zeros(10)
    for dof in (0, 2, 4, 6, 7, 8, 9):
        g[dof] = model.M[dof, dof] * model.parameters.gravity_m_per_s2
    return np.linalg.solve(model.K, g)


def _mode_label(shape: np.ndarray, mass: np.ndarray) -> str:
    """Name of a mode from its dominant DOF group and the sign pattern inside the group."""
    energy = mass * shape**2
    groups = {"car-body bounce": [0], "car-body pitch": [1], "bogie bounce": [2, 4],
              "bogie pitch": [3, 5], "wheelset bounce": [6, 7, 8, 9]}
    name = max(groups, key=lambda g: energy[groups[g]].sum())
    dofs = groups[name]
    if len(dofs) == 2:
        same = shape[dofs[0]] * shape[dofs[1]] > 0
        return f"{name}, {'in phase' if same else 'anti-phase'}"
    if len(dofs) == 4:
        big = np.abs(shape[dofs]) > 0.2 * np.abs(shape[dofs]).max()
        signs = "".join("0" if not b else ("+" if x > 0 else "-")
                        for x, b in zip(shape[dofs] * np.sign(shape[dofs][np.argmax(big)]), big))
        return f"{name} ({signs})"
    return name


def modal_table(model: Model) -> pd.DataFrame:
    """Modes of the 10-DOF model: undamped ``K φ = ω² M φ`` and the poles of A matched to them.

    Each pole of A (upper half plane) is assigned to the undamped mode whose shape it resembles
    most (modal assurance criterion on the position part of its eigenvector).  Overdamped modes
    (the bogie modes: C_p is large) get two real poles.

    Returns
    -------
    DataFrame
        ``mode``; ``undamped_Hz``; ``natural_Hz`` = sqrt(λ1 λ2)/2π and ``damping_ratio`` =
        −(λ1 + λ2)/(2 sqrt(λ1 λ2)) of the mode's pole pair; ``damped_Hz`` (0 when overdamped);
        ``poles_per_s`` (text).
    """
    from scipy.linalg import eigh

    mass = np.diag(model.M)
    w2, phi = eigh(model.K, model.M)
    order = np.argsort(w2)
    w2, phi = w2[order], phi[:, order]
    # clusters of repeated frequencies (the identical front and rear bogie pitch modes)
    cluster = np.zeros(len(w2), int)
    for j in range(1, len(w2)):
        same = abs(w2[j] - w2[j - 1]) <= 1e-9 * w2[j]
        cluster[j] = cluster[j - 1] if same else cluster[j - 1] + 1
    lam, vec = np.linalg.eig(model.A)
    keep = lam.imag >= -1e-9
    lam, pos = lam[keep], vec[0::2, keep]
    mac = np.abs(phi.T @ (mass[:, None] * pos)) ** 2 / (
        np.einsum("ij,i,ij->j", phi, mass, phi)[:, None]
        * np.einsum("ij,i,ij->j", pos.conj(), mass, pos).real[None, :])
    cluster_mac = np.array([mac[cluster == c].sum(axis=0) for c in range(cluster[-1] + 1)])
    owner = np.argmax(cluster_mac, axis=0)
    rows = []
    for c in range(cluster[-1] + 1):
        members = np.flatnonzero(cluster == c)
        mine = np.sort_complex(lam[owner == c])
        for i, j in enumerate(members):
            if np.all(np.abs(mine.imag) > 1e-9) and len(mine) == len(members):
                pair = [mine[i], np.conj(mine[i])]
            elif len(mine) == 2 * len(members):
                pair = [mine[i], mine[i + len(members)]]
            else:
                raise RuntimeError(f"modal_table: cannot match poles to mode {j}")
            prod, total = (pair[0] * pair[1]).real, (pair[0] + pair[1]).real
            label = _mode_label(phi[:, j], mass)
            if len(members) > 1 and "wheelset" not in label:
                label = label.split(",")[0] + ", front/rear (repeated)"
            rows.append({
                "mode": label,
                "undamped_Hz": float(np.sqrt(w2[j]) / (2 * np.pi)),
                "natural_Hz": float(np.sqrt(prod) / (2 * np.pi)),
                "damping_ratio": float(-total / (2 * np.sqrt(prod))),
                "damped_Hz": float(abs(pair[0].imag) / (2 * np.pi)),
                "poles_per_s": " / ".join(f"{p.real:.4g}{p.imag:+.4g}j" if abs(p.imag) > 1e-9
                                          else f"{p.real:.4g}" for p in pair[:1 if pair[0].imag else 2]),
            })
    return pd.DataFrame(rows)
