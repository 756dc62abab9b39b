"""Measurement chain: a digital Butterworth low-pass and its frequency response.

Paper 003 (Ding et al. 2014, §3.2) samples the line measurements at 1000 Hz and then applies a
"0–40 Hz low-frequency filter"; it states neither the filter's type nor its order.  Here it is a
Butterworth low-pass (a 2nd-order one unless the data say otherwise), designed from the analog
prototype by the bilinear transform with the cut-off pre-warped, so the digital filter has
exactly -3 dB at the cut-off.  It runs causally from rest (``scipy.signal.sosfilt``), as a filter
in the acquisition chain would, or forward-backward (zero phase, squared magnitude) for offline
processing.
"""

from __future__ import annotations

import numpy as np
from scipy import signal as _signal


def butterworth_lowpass(cutoff_hz: float, sample_rate_hz: float, order: int) -> np.ndarray:
    """Second-order sections of a digital Butterworth low-pass.

    The analog prototype's poles ``ω_a exp(iπ(2k + n + 1) / (2n))``, k = 0..n−1, with the
    pre-warped cut-off ``ω_a = 2 f_s tan(π f_c / f_s)``, are mapped by the bilinear transform
    ``z = (2 f_s + s) / (2 f_s − s)``; the n zeros go to z = −1 and the gain is set to 1 at DC.

    Parameters
    ----------
    cutoff_hz : float
        -3 dB frequency f_c, Hz (0 < f_c < f_s / 2).
    sample_rate_hz : float
        Sampling rate f_s, Hz.
    order : int
        Filter order n >= 1.

    Returns
    -------
    sos : ndarray, shape (ceil(n / 2), 6)
        Rows ``(b0, b1, b2, 1, a1, a2)`` as used by ``scipy.signal.sosfilt``.
    """
    if not 0 < cutoff_hz < sample_rate_hz / 2:
        raise ValueError(f"cutoff_hz must be in (0, sample_rate_hz / 2), got {cutoff_hz!r} at "
                         f"{sample_rate_hz!r} Hz")
    if int(order) != order or order < 1:
        raise ValueError(f"order must be an integer >= 1, got {order!r}")
    n, fs2 = int(order), 2.0 * sample_rate_hz
    wa = fs2 * np.tan(np.pi * cutoff_hz / sample_rate_hz)
    poles_s = wa * np.exp(1j * np.pi * (2 * np.arange(n) + n + 1) / (2 * n))
    poles_z = (fs2 + poles_s) / (fs2 - poles_s)
    upper = poles_z[poles_z.imag > 1e-12]                # one of each conjugate pair
    real = poles_z[np.abs(poles_z.imag) <= 1e-12].real
    sections = []
    for p in upper:
        a = np.array([1.0, -2.0 * p.real, abs(p) ** 2])
        sections.append(np.concatenate([np.array([1.0, 2.0, 1.0]) * a.sum() / 4.0, a]))
    for p in real:                                      # odd order: one first-order section
        a = np.array([1.0, -p, 0.0])
        sections.append(np.concatenate([np.array([1.0, 1.0, 0.0]) * a.sum() / 2.0, a]))
    return np.array(sections)


def butterworth_gain(frequency_hz, cutoff_hz: float, sample_rate_hz: float, order: int):
    """|H(e^{iω})| of :func:`butterworth_lowpass` in closed form, 1.

    ``1 / sqrt(1 + (tan(π f / f_s) / tan(π f_c / f_s))^(2n))`` for 0 <= f < f_s / 2.
    """
    ratio = np.tan(np.pi * np.asarray(frequency_hz, float) / sample_rate_hz) / np.tan(
        np.pi * cutoff_hz / sample_rate_hz)
    return 1.0 / np.sqrt(1.0 + ratio ** (2 * int(order)))


def lowpass(x, cutoff_hz: float, sample_rate_hz: float, order: int, zero_phase: bool = False,
            axis: int = 0) -> np.ndarray:
    """Low-pass ``x`` along ``axis`` with :func:`butterworth_lowpass`.

    Parameters
    ----------
    x : array_like
        Signal sampled at ``sample_rate_hz`` (any unit; returned in the same unit).
    cutoff_hz, sample_rate_hz, order
        As in :func:`butterworth_lowpass`.
    zero_phase : bool
        False: causal, from rest (zero initial filter state). True: forward-backward
        (``scipy.signal.sosfiltfilt``; magnitude squared, no delay; offline only).
    axis : int
        Time axis.
    """
    sos = butterworth_lowpass(cutoff_hz, sample_rate_hz, order)
    x = np.asarray(x, dtype=float)
    if zero_phase:
        return _signal.sosfiltfilt(sos, x, axis=axis)
    return _signal.sosfilt(sos, x, axis=axis)


__all__ = ["butterworth_gain", "butterworth_lowpass", "lowpass"]
