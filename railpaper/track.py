"""Track irregularity: spectra, random profiles and the inputs seen by each wheelset.

Spectra (numbers in ``data/track_spectra.toml``, formulas below) are returned as **one-sided**
power spectral densities S(Omega) in m^2/(rad/m) of the spatial angular frequency Omega
(rad/m, Omega = 2 pi / wavelength), normalised so that the variance of the irregularity is

    sigma^2 = integral_0^inf S(Omega) dOmega.

- US FRA classes 1-6 (``fra-1`` ... ``fra-6``), in cm^2/(rad/m) before conversion:
  S_v = F k A_v Omega_c^2 / (Omega^2 (Omega^2 + Omega_c^2)), S_a the same with A_a.
  The literature is split on whether this formula is one- or two-sided.  We read it as
  one-sided, as Zhai (*Vehicle-Track Coupled Dynamics*) does: F = :data:`FRA_SIDEDNESS_FACTOR`
  = 1.0.  (A two-sided reading would be F = 2.)
- German high-speed, low/high interference (``german-low``, ``german-high``), in m^2/(rad/m):
  S_v = A_v Omega_c^2 / ((Omega^2 + Omega_r^2)(Omega^2 + Omega_c^2)), S_a the same with A_a.
- Chinese high-speed ballastless track, TB/T 3352-2014 (``china-hsr``): S(f) = A_i / f^n_i,
  piecewise in the spatial frequency f (1/m), S in mm^2/(1/m); converted with
  S(Omega) = S(f = Omega / 2 pi) / (2 pi) * 1e-6.  Outside the tabulated band the end
  segments are extrapolated.

Every spectrum also carries a default wavelength band; :func:`psd` evaluates the formula at
any Omega > 0, the band only limits :func:`band_variance` defaults and synthesis.
"""

from __future__ import annotations

import difflib
import functools
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd
from scipy import integrate

from railpaper.data import DataError, Quantity, _check_quantity, data_path, read_toml

SPECTRA = ("fra-1", "fra-2", "fra-3", "fra-4", "fra-5", "fra-6",
           "german-low", "german-high", "china-hsr")
COMPONENTS = ("vertical", "alignment")
METHODS = ("ifft", "harmonic")

#: Most samples one profile may have: the ifft method holds a few float64/complex arrays of this
#: length (about 2 GB at this size), so a longer request is refused rather than exhausting memory.
MAX_PROFILE_SAMPLES = 50_000_000

#: Factor multiplying the FRA formula: 1.0 = the formula is a one-sided PSD (Zhai's reading).
FRA_SIDEDNESS_FACTOR = 1.0

_BAND_KEYS = {"wavelength_min_m": "m", "wavelength_max_m": "m"}
#: Expected quantity keys and their units per spectrum family.
_FAMILY_KEYS = {
    "fra": {"k": "1", "A_v": "cm^2*rad/m", "A_a": "cm^2*rad/m", "Omega_c": "rad/m",
            "Omega_s": "rad/m", **_BAND_KEYS},
    "german": {"A_v": "m*rad", "A_a": "m*rad", "A_g": "m*rad", "Omega_c": "rad/m",
               "Omega_r": "rad/m", "Omega_s": "rad/m", **_BAND_KEYS},
    "china": {f"{c}_{p}": u for c in COMPONENTS
              for p, u in (("break_f", "1/m"), ("A", "mm^2*m"), ("n", "1"))} | _BAND_KEYS,
}
_TEXT_KEYS = ("description", "formula")


@dataclass(frozen=True)
class Spectrum:
    """One spectrum of the data file: name, family, text and quantities."""

    name: str
    family: str
    description: str
    formula: str
    quantities: dict[str, Quantity]

    def value(self, key: str):
        """Bare value of a quantity (float or list of float)."""
        return self.quantities[key].value


def _family(name: str) -> str:
    return name.split("-")[0]


def _one_of(kind: str, name, valid) -> str:
    close = difflib.get_close_matches(str(name), valid, n=1)
    hint = f"; did you mean '{close[0]}'?" if close else ""
    return f"unknown {kind} {name!r}{hint} (valid: {', '.join(valid)})"


def load_spectra(path: Path | str | None = None) -> dict[str, Spectrum]:
    """Load and check the track-spectrum file.

    Parameters
    ----------
    path : path-like, optional
        TOML file; default ``data/track_spectra.toml``.

    Returns
    -------
    dict of str to Spectrum
        One entry per name in :data:`SPECTRA`.  Raises :class:`DataError` (one line naming the
        file and the key) for an unknown or missing spectrum or key, wrong or missing unit,
        missing source, non-positive value or inconsistent piecewise table.
    """
    path = Path(path) if path is not None else data_path("track_spectra.toml")
    document = read_toml(path)
    spectra = {}
    for name, table in document.items():
        if name not in SPECTRA:
            raise DataError(f"{path}: unknown key '{name}' (expected one of {list(SPECTRA)})")
        if not isinstance(table, dict):
            raise DataError(f"{path}: key '{name}': expected a table")
        spectra[name] = _check_spectrum(path, name, table)
    missing = [name for name in SPECTRA if name not in spectra]
    if missing:
        raise DataError(f"{path}: missing key '{missing[0]}'")
    return spectra


def _check_spectrum(path: Path, name: str, table: dict) -> Spectrum:
    family = _family(name)
    expected = _FAMILY_KEYS[family]
    text = {}
    for key in _TEXT_KEYS:
        if not isinstance(table.get(key), str) or not table[key].strip():
            raise DataError(f"{path}: key '{name}.{key}': missing text")
        text[key] = table[key]
    quantities = {}
    for key, sub in table.items():
        where = f"{name}.{key}"
        if key in _TEXT_KEYS:
            continue
        if key not in expected:
            raise DataError(f"{path}: unknown key '{where}' (expected one of {sorted(expected)})")
        if not isinstance(sub, dict) or "value" not in sub:
            raise DataError(f"{path}: key '{where}': expected a table with value, unit and source")
        q = _check_quantity(path, where, sub)
        if q.unit != expected[key]:
            raise DataError(f"{path}: key '{where}': unit '{q.unit}', expected '{expected[key]}'")
        numbers = q.value if isinstance(q.value, list) else [q.value]
        if family == "china" and not isinstance(q.value, list) and not key.startswith("wave"):
            raise DataError(f"{path}: key '{where}': expected a list of values")
        if any(v <= 0 for v in numbers):
            raise DataError(f"{path}: key '{where}': non-physical value {min(numbers)!r}"
                            " (must be > 0)")
        quantities[key] = q
    absent = sorted(set(expected) - set(quantities))
    if absent:
        raise DataError(f"{path}: missing key '{name}.{absent[0]}'")
    lo, hi = quantities["wavelength_min_m"].value, quantities["wavelength_max_m"].value
    if not lo < hi:
        raise DataError(f"{path}: key '{name}.wavelength_min_m': {lo} m is not below {hi} m")
    if family == "china":
        for c in COMPONENTS:
            breaks = quantities[f"{c}_break_f"].value
            if np.any(np.diff(breaks) <= 0):
                raise DataError(f"{path}: key '{name}.{c}_break_f': not strictly increasing")
            for key in (f"{c}_A", f"{c}_n"):
                if len(quantities[key].value) != len(breaks) + 1:
                    raise DataError(f"{path}: key '{name}.{key}': needs {len(breaks) + 1} values"
                                    f" (one per segment), got {len(quantities[key].value)}")
    return Spectrum(name, family, text["description"], text["formula"], quantities)


@functools.lru_cache(maxsize=1)
def _default_spectra() -> dict[str, Spectrum]:
    return load_spectra()


def _spectrum(name: str) -> Spectrum:
    if name not in SPECTRA:
        raise ValueError(_one_of("spectrum", name, SPECTRA))
    return _default_spectra()[name]


def _component(component: str) -> str:
    if component not in COMPONENTS:
        raise ValueError(_one_of("component", component, COMPONENTS))
    return component


def list_spectra() -> list[tuple[str, str, tuple[str, ...]]]:
    """(name, description, components) of every spectrum, for ``railpaper track --list``."""
    return [(name, _spectrum(name).description, COMPONENTS) for name in SPECTRA]


def default_band(spectrum: str) -> tuple[float, float]:
    """Default wavelength band (wavelength_min_m, wavelength_max_m) of a spectrum, m."""
    spec = _spectrum(spectrum)
    return float(spec.value("wavelength_min_m")), float(spec.value("wavelength_max_m"))


def psd(spectrum: str, component: str, omega_rad_m) -> np.ndarray:
    """One-sided PSD of a track irregularity.

    Parameters
    ----------
    spectrum : str
        One of :data:`SPECTRA`.
    component : str
        ``"vertical"`` (profile) or ``"alignment"``.
    omega_rad_m : array_like
        Spatial angular frequency Omega = 2 pi / wavelength, rad/m, all > 0.

    Returns
    -------
    ndarray
        S(Omega) in m^2/(rad/m), same shape as ``omega_rad_m``; variance = integral_0^inf S dOmega.
    """
    spec = _spectrum(spectrum)
    _component(component)
    omega = np.asarray(omega_rad_m, dtype=float)
    if not np.all(np.isfinite(omega)) or np.any(omega <= 0):
        raise ValueError("omega_rad_m must be finite and > 0 rad/m")
    w2 = omega ** 2
    if spec.family == "fra":
        a = spec.value("A_v" if component == "vertical" else "A_a")
        oc2 = spec.value("Omega_c") ** 2
        s_cm2 = FRA_SIDEDNESS_FACTOR * spec.value("k") * a * oc2 / (w2 * (w2 + oc2))
        return s_cm2 * 1e-4
    if spec.family == "german":
        a = spec.value("A_v" if component == "vertical" else "A_a")
        oc2, or2 = spec.value("Omega_c") ** 2, spec.value("Omega_r") ** 2
        return a * oc2 / ((w2 + or2) * (w2 + oc2))
    breaks = np.asarray(spec.value(f"{component}_break_f"))
    coeff = np.asarray(spec.value(f"{component}_A"))
    expo = np.asarray(spec.value(f"{component}_n"))
    f_per_m = omega / (2.0 * np.pi)
    seg = np.searchsorted(breaks, f_per_m, side="right")
    s_mm2_m = coeff[seg] * f_per_m ** (-expo[seg])
    return s_mm2_m / (2.0 * np.pi) * 1e-6


def _band(spectrum: str, wavelength_min_m, wavelength_max_m) -> tuple[float, float]:
    lo, hi = default_band(spectrum)
    lo = lo if wavelength_min_m is None else float(wavelength_min_m)
    hi = hi if wavelength_max_m is None else float(wavelength_max_m)
    if not (math.isfinite(lo) and math.isfinite(hi) and 0 < lo < hi):
        raise ValueError(f"wavelength band must satisfy 0 < wavelength_min_m < wavelength_max_m,"
                         f" got {lo!r} m to {hi!r} m")
    return lo, hi


def band_variance(spectrum: str, component: str, wavelength_min_m: float | None = None,
                  wavelength_max_m: float | None = None) -> float:
    """Variance of the irregularity in a wavelength band, m^2.

    integral of :func:`psd` over Omega in [2 pi / wavelength_max_m, 2 pi / wavelength_min_m]
    (``scipy.integrate.quad`` in log Omega, segment boundaries as break points).

    ``spectrum``, ``component`` as in :func:`psd`; the band (m) defaults to the spectrum's.
    """
    _spectrum(spectrum)
    _component(component)
    lo, hi = _band(spectrum, wavelength_min_m, wavelength_max_m)
    u_lo, u_hi = math.log(2 * math.pi / hi), math.log(2 * math.pi / lo)
    points = None
    if _family(spectrum) == "china":
        breaks = np.log(2 * np.pi * np.asarray(_spectrum(spectrum).value(f"{component}_break_f")))
        points = [p for p in breaks if u_lo < p < u_hi] or None
    value, _ = integrate.quad(lambda u: float(psd(spectrum, component, math.exp(u))) * math.exp(u),
                              u_lo, u_hi, points=points, limit=200, epsabs=0.0, epsrel=1e-10)
    return float(value)


def synthesize_profile(spectrum: str, component: str, length_m: float, dx_m: float, seed: int,
                       wavelength_min_m: float | None = None,
                       wavelength_max_m: float | None = None, method: str = "ifft",
                       n_harmonics: int | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Random irregularity profile with the one-sided PSD of a spectrum, band-limited.

    Parameters
    ----------
    spectrum, component : str
        As in :func:`psd`.
    length_m : float
        Profile length, m (> 0); samples at 0, dx, ..., <= length_m.
    dx_m : float
        Sample spacing, m (> 0).
    seed : int
        Seed of ``numpy.random.default_rng``; same seed gives a bit-identical profile.
    wavelength_min_m, wavelength_max_m : float, optional
        Band, m; default the spectrum's band.  Needs wavelength_min_m >= 2 dx_m (Nyquist) and
        wavelength_max_m <= length_m.
    method : {"ifft", "harmonic"}
        ``"ifft"``: random phases on the FFT grid Omega_k = 2 pi k / (N dx), cosine amplitudes
        sqrt(2 P_k) with P_k ~ S(Omega_k) dOmega the integral of S over the bin's cell clipped
        to the band, zero outside (periodic profile; sample variance = band integral).
        ``"harmonic"``: sum of ``n_harmonics`` cosines sqrt(2 S(Omega_k) dOmega)
        cos(Omega_k x + phi_k), the band split into equal dOmega intervals and Omega_k drawn
        uniformly inside each (not periodic; variance = band integral on average over seeds).
    n_harmonics : int, optional
        Harmonic method only; default (band width)/(2 pi / length_m), clipped to [16, 8192].
        Cost ~ n_harmonics x number of samples.

    Returns
    -------
    distance_m : ndarray, shape (N,)
        Distance along the track, m.
    irregularity_m : ndarray, shape (N,)
        Irregularity, m.
    """
    _spectrum(spectrum)
    _component(component)
    if method not in METHODS:
        raise ValueError(_one_of("method", method, METHODS))
    if seed is None:
        raise ValueError("seed must be given explicitly (an int) for a reproducible profile")
    if isinstance(seed, (int, np.integer)) and seed < 0:
        raise ValueError(f"seed must be an integer >= 0, got {seed}")
    for label, v in (("length_m", length_m), ("dx_m", dx_m)):
        if not (isinstance(v, (int, float, np.floating, np.integer)) and math.isfinite(v) and v > 0):
            raise ValueError(f"{label} must be a finite number > 0, got {v!r}")
    if dx_m * 2 > length_m:
        raise ValueError(f"dx_m = {dx_m} m is too coarse for length_m = {length_m} m")
    lo, hi = _band(spectrum, wavelength_min_m, wavelength_max_m)
    if lo < 2 * dx_m * (1 - 1e-12):
        raise ValueError(f"wavelength_min_m = {lo} m is below the Nyquist wavelength 2*dx_m ="
                         f" {2 * dx_m} m; use dx_m <= {lo / 2} m")
    if hi > length_m * (1 + 1e-12):
        raise ValueError(f"wavelength_max_m = {hi} m exceeds length_m = {length_m} m;"
                         f" use length_m >= {hi} m")
    n = int(math.floor(length_m / dx_m + 1e-9)) + 1
    if n > MAX_PROFILE_SAMPLES:
        raise ValueError(f"length_m / dx_m = {n - 1:.3g} samples is more than "
                         f"{MAX_PROFILE_SAMPLES:.0e}; use a shorter length_m or a larger dx_m")
    distance = np.arange(n) * float(dx_m)
    omega_lo, omega_hi = 2 * np.pi / hi, 2 * np.pi / lo
    rng = np.random.default_rng(seed)
    if method == "ifft":
        d_omega = 2 * np.pi / (n * dx_m)
        k = np.arange(n // 2 + 1)
        omega = k * d_omega
        # power of bin k = integral of S over its cell [Omega_k -+ dOmega/2] clipped to the band
        # (Simpson), so the sample variance is the band integral even at a steep band edge
        cell_lo = np.maximum(omega - d_omega / 2, omega_lo)
        cell_hi = np.minimum(omega + d_omega / 2, omega_hi)
        inside = (cell_hi > cell_lo) & (k > 0) & (2 * k < n)
        if not inside.any():
            raise ValueError(f"the band {lo}-{hi} m holds no FFT bin of a {n * dx_m} m grid")
        a, b = cell_lo[inside], cell_hi[inside]
        s_a, s_b = psd(spectrum, component, a), psd(spectrum, component, b)
        power = (b - a) / 6 * (s_a + 4 * psd(spectrum, component, (a + b) / 2) + s_b)
        amplitude = np.zeros(k.size)
        amplitude[inside] = np.sqrt(2 * power)
        phase = rng.uniform(0.0, 2 * np.pi, size=k.size)
        return distance, np.fft.irfft(0.5 * n * amplitude * np.exp(1j * phase), n=n)
    if n_harmonics is None:
        width_bins = math.ceil((omega_hi - omega_lo) * length_m / (2 * np.pi))
        n_harmonics = int(np.clip(width_bins, 16, 8192))
    if int(n_harmonics) < 1:
        raise ValueError(f"n_harmonics must be >= 1, got {n_harmonics!r}")
    n_harmonics = int(n_harmonics)
    edges = np.linspace(omega_lo, omega_hi, n_harmonics + 1)
    d_omega = np.diff(edges)
    omega = edges[:-1] + rng.uniform(0.0, 1.0, n_harmonics) * d_omega
    phase = rng.uniform(0.0, 2 * np.pi, n_harmonics)
    amplitude = np.sqrt(2 * psd(spectrum, component, omega) * d_omega)
    # x_m = (j L + l) dx: exp(i Omega x) = exp(i Omega j L dx) exp(i Omega l dx), so the sum over
    # harmonics is a (J x K) @ (K x L) product; chunks of harmonics bound the memory.
    cols = int(math.ceil(math.sqrt(n)))
    rows = -(-n // cols)
    block_start = np.arange(rows) * (cols * float(dx_m))
    block_local = np.arange(cols) * float(dx_m)
    total = np.zeros((rows, cols), dtype=complex)
    chunk = max(1, 2_000_000 // (rows + cols))
    for start in range(0, n_harmonics, chunk):
        sl = slice(start, start + chunk)
        left = amplitude[sl] * np.exp(1j * (np.multiply.outer(block_start, omega[sl]) + phase[sl]))
        total += left @ np.exp(1j * np.multiply.outer(omega[sl], block_local))
    return distance, total.real.ravel()[:n]


def _check_profile(distance_m, irregularity_m) -> tuple[np.ndarray, np.ndarray]:
    s = np.asarray(distance_m, dtype=float)
    z = np.asarray(irregularity_m, dtype=float)
    if s.ndim != 1 or z.shape != s.shape or s.size < 2:
        raise ValueError(f"distance_m and irregularity_m must be 1-D of equal length >= 2,"
                         f" got shapes {s.shape} and {z.shape}")
    if not (np.all(np.isfinite(s)) and np.all(np.isfinite(z))):
        raise ValueError("distance_m and irregularity_m must be finite")
    if np.any(np.diff(s) <= 0):
        raise ValueError("distance_m must be strictly increasing")
    return s, z


def wheelset_inputs(distance_m, irregularity_m, speed_mps: float, axle_offsets_m, dt_s: float,
                    duration_s: float, derivative: bool = False):
    """Time-domain irregularity under each wheelset of a vehicle running at constant speed.

    Wheelset j is ``axle_offsets_m[j]`` behind the first, so it sees the profile with the delay
    offset_j / V: q_j(t) = profile(s0 + V t - offset_j), with s0 = distance_m[0] +
    max(axle_offsets_m) so that the last wheelset starts on the profile.  The profile is
    interpolated linearly.

    Parameters
    ----------
    distance_m, irregularity_m : array_like, shape (N,)
        Profile: strictly increasing distance (m) and irregularity (m).
    speed_mps : float
        Vehicle speed V, m/s (> 0).
    axle_offsets_m : array_like, shape (J,)
        Distance of each wheelset behind the first, m (>= 0; usually starts with 0).
    dt_s, duration_s : float
        Time step and duration, s (> 0); times 0, dt, ..., <= duration.
    derivative : bool
        Also return dq/dt = V dprofile/ds, m/s, with dprofile/ds from ``numpy.gradient`` on the
        profile grid, interpolated linearly like the profile.

    Returns
    -------
    t_s : ndarray, shape (K,)
    q_m : ndarray, shape (K, J)
    dq_mps : ndarray, shape (K, J), only with ``derivative=True``
    """
    s, z = _check_profile(distance_m, irregularity_m)
    offsets = np.atleast_1d(np.asarray(axle_offsets_m, dtype=float))
    if offsets.ndim != 1 or offsets.size == 0 or not np.all(np.isfinite(offsets) & (offsets >= 0)):
        raise ValueError(f"axle_offsets_m must be a non-empty 1-D array of finite values >= 0 m,"
                         f" got {axle_offsets_m!r}")
    for label, v in (("speed_mps", speed_mps), ("dt_s", dt_s), ("duration_s", duration_s)):
        if not (math.isfinite(v) and v > 0):
            raise ValueError(f"{label} must be a finite number > 0, got {v!r}")
    t = np.arange(int(math.floor(duration_s / dt_s + 1e-9)) + 1) * float(dt_s)
    spread = float(offsets.max() - offsets.min())
    needed = spread + speed_mps * t[-1]
    have = float(s[-1] - s[0])
    if needed > have * (1 + 1e-12) + 1e-12:
        raise ValueError(f"profile of {have:.6g} m is too short: {speed_mps:g} m/s for"
                         f" {t[-1]:g} s with axle spread {spread:g} m needs at least {needed:.6g} m")
    position = (s[0] + offsets.max() - offsets)[None, :] + speed_mps * t[:, None]
    q = np.interp(position, s, z)
    if not derivative:
        return t, q
    dq = speed_mps * np.interp(position, s, np.gradient(z, s))
    return t, q, dq


def profile_frame(distance_m, irregularity_m) -> pd.DataFrame:
    """Profile as a DataFrame with columns ``distance_m`` (m) and ``irregularity_m`` (m)."""
    s, z = _check_profile(distance_m, irregularity_m)
    return pd.DataFrame({"distance_m": s, "irregularity_m": z})
