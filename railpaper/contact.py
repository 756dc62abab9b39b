"""Wheel–rail normal contact: Hertz constant, nonlinear force and its linearisation.

Hertz: ``P = (delta / G)^(3/2)`` for compression ``delta > 0`` (m), zero when contact is lost,
with the contact constant G in m/N^(2/3) (Zhai, *Vehicle–Track Coupled Dynamics*; papers 000, 001).
"""

from __future__ import annotations

import numpy as np

#: Coefficients of G = c * R^(-e) * 1e-8 (R in m): (c, e) per tread type.
TREAD_COEFFICIENTS = {"worn": (3.86, 0.115), "conical": (4.57, 0.149)}


def hertz_constant(wheel_radius_m: float, tread: str = "worn") -> float:
    """Hertz contact constant G, m/N^(2/3).

    G = 3.86 R^-0.115 1e-8 (worn tread) or 4.57 R^-0.149 1e-8 (conical tread), R in m.
    """
    if tread not in TREAD_COEFFICIENTS:
        raise ValueError(f"unknown tread '{tread}' (expected one of {sorted(TREAD_COEFFICIENTS)})")
    if not wheel_radius_m > 0:
        raise ValueError(f"wheel_radius_m must be > 0, got {wheel_radius_m!r}")
    c, e = TREAD_COEFFICIENTS[tread]
    return c * wheel_radius_m ** (-e) * 1e-8


def hertz_force(compression_m, G: float):
    """Nonlinear Hertz force (N) for compression ``delta`` (m): (delta/G)^1.5, zero if delta <= 0."""
    delta = np.asarray(compression_m, dtype=float)
    return np.where(delta > 0.0, (np.maximum(delta, 0.0) / G) ** 1.5, 0.0)


def static_compression(static_load_N: float, G: float) -> float:
    """Compression (m) under a static wheel load P0 (N): delta0 = G P0^(2/3)."""
    if not static_load_N > 0:
        raise ValueError(f"static_load_N must be > 0, got {static_load_N!r}")
    return G * static_load_N ** (2.0 / 3.0)


def linearised_stiffness(static_load_N: float, G: float) -> float:
    """Linearised contact stiffness K_r = dP/d(delta) at P0 = 3/(2G) P0^(1/3), N/m."""
    if not static_load_N > 0:
        raise ValueError(f"static_load_N must be > 0, got {static_load_N!r}")
    return 1.5 / G * static_load_N ** (1.0 / 3.0)


# ----------------------------------------------------------------------------- tangential contact
# Tangential (creep) forces and the wheel–rail rolling-radius difference.
#
# Creep law: Kalker's linear coefficients with the Vermeulen–Johnson saturation, combined as in
# Shen, Hedrick & Elkins (1983, *Vehicle System Dynamics* 12, 79–83): the linear force
# ``F_lin = (−f11 ξx, −f22 ξy)`` of one wheel is scaled by ``R(β)/β``, β = |F_lin| / (μN), with
# the Vermeulen–Johnson (1964, *J. Appl. Mech.* 31, 338–340) cubic
# ``R(β) = β − β²/3 + β³/27`` for β < 3 and ``R = 1`` beyond (full sliding, |F| = μN).  It
# takes exactly the f11, f22 (N) of a linear lateral model, reduces to ``F = −f ξ`` for small
# creepage and has a continuous slope up to saturation.  (Polach's law has further parameters —
# reduction factors k_A, k_S and the friction decay with slip velocity — fitted to measured
# adhesion curves that we do not have; its small-creepage slope equals the linear law's only for
# a matching choice of them.)  Spin creepage is left out, as in paper 003's linear model.
#
# Rolling-radius difference: the odd cubic ``Δr(y) = 2 λ y (1 + (y / y_c)²)`` (symmetric profile;
# the lowest-order nonlinearity), which is ``2 λ y`` for |y| ≪ y_c and whose local conicity
# reaches 4 λ at y = y_c. Its equivalent conicity by harmonic linearisation (first Fourier
# coefficient over a sinusoid of amplitude A, the describing-function definition; UIC 519 derives
# λ_eq from the same Δr function by related methods) rises with amplitude:
# ``λ_eq(A) = λ (1 + 3 A² / (4 y_c²))``. An analytic approximation, not a measured profile.


def vermeulen_johnson_ratio(beta):
    """Saturation curve |F| / (μN) of the Vermeulen–Johnson law, 1.

    Parameters
    ----------
    beta : array_like
        |F_lin| / (μN) >= 0, the linear-law force over the friction limit, 1.

    Returns
    -------
    ndarray
        ``β − β²/3 + β³/27`` for β < 3, else 1 (slope 1 at 0, slope 0 and value 1 at 3).
    """
    b = np.minimum(np.asarray(beta, dtype=float), 3.0)
    return b - b ** 2 / 3.0 + b ** 3 / 27.0


def creep_forces(xi_x, xi_y, f11_N: float, f22_N: float, normal_load_N: float,
                 friction: float):
    """Saturating longitudinal and lateral creep forces on one wheel, N.

    Parameters
    ----------
    xi_x, xi_y : array_like
        Longitudinal and lateral creepage, 1 (broadcast together).
    f11_N, f22_N : float
        Linear (Kalker) longitudinal and lateral creep coefficients of one wheel, N.
    normal_load_N : float
        Wheel–rail normal load N, N (> 0).
    friction : float
        Friction coefficient μ, 1 (> 0; ``numpy.inf`` = the linear law, no saturation).

    Returns
    -------
    fx, fy : ndarray
        ``(−f11 ξx, −f22 ξy) · R(β)/β`` (see the module section above): ``−f ξ`` for small
        creepage, magnitude μN in full sliding, direction always that of the linear force.
    """
    if not normal_load_N > 0 or not friction > 0:
        raise ValueError(f"normal_load_N and friction must be > 0, got {normal_load_N!r}, "
                         f"{friction!r}")
    fx = -f11_N * np.asarray(xi_x, dtype=float)
    fy = -f22_N * np.asarray(xi_y, dtype=float)
    if np.isinf(friction):
        return np.broadcast_arrays(fx, fy)
    beta = np.hypot(fx, fy) / (friction * normal_load_N)
    # R(β)/β without dividing by β: 1 − β/3 + β²/27 below 3, 1/β at and above
    scale = np.where(beta < 3.0, 1.0 - beta / 3.0 + beta ** 2 / 27.0,
                     1.0 / np.maximum(beta, 3.0))
    return fx * scale, fy * scale


def rolling_radius_difference(y_m, conicity: float, length_scale_m: float):
    """Δr(y) = r_left − r_right = 2 λ y (1 + (y / y_c)²), m.

    Parameters
    ----------
    y_m : array_like
        Lateral displacement of the wheelset relative to the track, m.
    conicity : float
        λ, the small-amplitude (linear) conicity, 1.
    length_scale_m : float
        y_c, m (> 0; ``numpy.inf`` gives the linear ``2 λ y``).
    """
    if not length_scale_m > 0:
        raise ValueError(f"length_scale_m must be > 0, got {length_scale_m!r}")
    y = np.asarray(y_m, dtype=float)
    return 2.0 * conicity * y * (1.0 + (y / length_scale_m) ** 2)


def equivalent_conicity(amplitude_m, conicity: float, length_scale_m: float,
                        n_points: int = 256):
    """Equivalent conicity λ_eq(A) of :func:`rolling_radius_difference` by harmonic linearisation.

    ``λ_eq(A) = (1 / (π A)) ∫₀^{2π} Δr(A sin φ) / 2 · sin φ dφ`` (the first Fourier coefficient
    of Δr/2 over a sinusoidal lateral motion of amplitude A, divided by A), evaluated with the
    trapezoidal rule on ``n_points`` equally spaced φ (exact for this trigonometric polynomial).

    Parameters
    ----------
    amplitude_m : array_like
        Amplitude A of the lateral motion, m (> 0).
    conicity, length_scale_m : float
        As in :func:`rolling_radius_difference`.

    Returns
    -------
    ndarray
        λ_eq, 1 (λ at A → 0, rising with A).
    """
    A = np.asarray(amplitude_m, dtype=float)[..., None]
    phi = 2.0 * np.pi * np.arange(n_points) / n_points
    half_dr = 0.5 * rolling_radius_difference(A * np.sin(phi), conicity, length_scale_m)
    return (half_dr * np.sin(phi)).mean(axis=-1) * 2.0 / A[..., 0]
