"""The track irregularity as a Kalman filter sees it: a second-order shaping filter fitted to a
spectrum at the vehicle's speed (shared by the chapters that filter a vertical profile, and by
the fault appendix's filters that are not given the alignment)."""

from __future__ import annotations

import numpy as np

from railpaper import track
from railpaper.estimators import kalman_baseline as kb


def shaping_filter(spectrum: str, speed_mps: float, band_m: tuple[float, float],
                   component: str = "vertical"):
    """Second-order shaping filter fitted to a spectrum at speed V: ``S_t(ω) = S(ω/V)/V``.

    Parameters
    ----------
    spectrum : str
        A spectrum of :mod:`railpaper.track` (e.g. ``"fra-5"``).
    speed_mps : float
        Vehicle speed, m/s.
    band_m : (float, float)
        Shortest and longest wavelength of the profile, m; the band's variance constrains the fit.
    component : str
        ``"vertical"`` (profile, the default) or ``"alignment"``
        (:data:`railpaper.track.COMPONENTS`).

    Returns
    -------
    (ShapingFilter, ndarray, ndarray)
        The filter and the fitted samples: ω (rad/s, 200 log-spaced over the band) and S_t(ω).
    """
    omega_m = np.logspace(np.log10(2 * np.pi / band_m[1]), np.log10(2 * np.pi / band_m[0]), 200)
    omega_t = omega_m * speed_mps
    S_t = track.psd(spectrum, component, omega_m) / speed_mps
    variance = track.band_variance(spectrum, component, *band_m)
    return kb.fit_shaping_filter(omega_t, S_t, variance), omega_t, S_t
