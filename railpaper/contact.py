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
