"""The lateral vehicle of paper 003 as the chapters simulate and filter it, shared by chapter
``rbpf-parameter-estimation`` and the fault-detection appendix (chapters never import each
other).

The vehicle's data are ``data/rbpf-parameter-estimation/parameters.toml``; a record
(:class:`LateralRecord`) is an alignment profile driven through the 16-state model
(:mod:`railpaper.models.lateral_16state`) simulated exactly on a fine grid, sampled at ``dt_s``
with white sensor noise; the filters' model is the exact ZOH of A(θ) at ``dt_s``
(:func:`filter_system`).  What a record depends on besides its seed is a
:class:`RecordSettings` (speed, sample time, truth substeps, length, track spectrum and band,
the four sensor noises); a chapter makes one from its own settings with
:meth:`RecordSettings.of`, which reads the fields of the same names.
"""

from __future__ import annotations

from dataclasses import dataclass, fields, replace
from pathlib import Path
from typing import Any

import numpy as np

from railpaper import track
from railpaper.data import load_quantities
from railpaper.discretise import zoh
from railpaper.experiments.base import Parameter
from railpaper.models import lateral_16state
from railpaper.paths import DATA_DIR

#: The vehicle's data (paper 003 prints none: a project choice, sources in the file).
VEHICLE_FILE = DATA_DIR / "rbpf-parameter-estimation" / "parameters.toml"

#: The chapter parameters of a record's track and sensors (chapter 003's defaults), shared by
#: the chapters that simulate this vehicle.
P = Parameter
TRACK_AND_SENSORS = [
    P("spectrum", "german-low", "str", "alignment irregularity spectrum: fra-1 to fra-6, "
      "german-low, german-high or china-hsr"),
    P("wavelength_min_m", 1.0, "float", "shortest irregularity wavelength, m", positive=True),
    P("wavelength_max_m", 100.0, "float", "longest irregularity wavelength, m", positive=True),
    P("noise_acc_wheelset_mps2", 0.1, "float", "wheelset accelerometer noise std, m/s^2",
      positive=True),
    P("noise_acc_bogie_mps2", 0.1, "float", "bogie accelerometer noise std, m/s^2",
      positive=True),
    P("noise_acc_body_mps2", 0.01, "float", "car-body accelerometer noise std, m/s^2",
      positive=True),
    P("noise_yawrate_radps", 0.001, "float", "bogie yaw-rate gyro noise std, rad/s",
      positive=True),
]


@dataclass(frozen=True)
class RecordSettings:
    """What a lateral record depends on besides its seed (units in the names)."""

    speed_kmh: float
    dt_s: float
    truth_substeps: int
    n_steps: int
    spectrum: str
    wavelength_min_m: float
    wavelength_max_m: float
    noise_acc_wheelset_mps2: float
    noise_acc_bogie_mps2: float
    noise_acc_body_mps2: float
    noise_yawrate_radps: float

    @classmethod
    def of(cls, settings: Any, **changes: Any) -> "RecordSettings":
        """The record settings held by a chapter's ``settings`` (fields of the same names), with
        ``changes`` (e.g. the speed of one of several)."""
        values = {f.name: changes[f.name] if f.name in changes else getattr(settings, f.name)
                  for f in fields(cls)}
        return cls(**values)


@dataclass(frozen=True)
class LateralRecord:
    """One lateral record: what the filters are given.

    Attributes
    ----------
    seed : int or None
        Seed of the simulated record (track profile and sensor noise); None for a user's file.
    y : ndarray, shape (K, 5)
        Measurements at steps 1..K: lateral accelerations of wheelsets 1, 2, the bogie and the
        car body (m/s²) and the bogie yaw rate (rad/s) (:data:`lateral_16state.CHANNELS`).
    u_mps : ndarray, shape (K, 2) or None
        Track lateral velocity under wheelsets 1 and 2 (m/s), held over each filter step
        (``u_k`` = value at step k − 1); None when a user's file has none.
    du_var_m2ps2 : ndarray, shape (2,)
        Variance of the input's change over one filter step, (m/s)²: the filters' process noise.
    u_var_m2ps2 : ndarray, shape (2,)
        Variance of the input itself, (m/s)²: the process noise when the input is not known.
    """

    seed: int | None
    y: np.ndarray
    u_mps: np.ndarray | None
    du_var_m2ps2: np.ndarray
    u_var_m2ps2: np.ndarray

    def first_steps(self, n_steps: int) -> LateralRecord:
        """The record cut to its first ``n_steps`` filter steps (measurements and input)."""
        return replace(self, y=self.y[:n_steps],
                       u_mps=None if self.u_mps is None else self.u_mps[:n_steps])


def vehicle(params_path: Path | None = None) -> tuple[dict, np.ndarray]:
    """Fixed quantities and true θ from ``data/rbpf-parameter-estimation/parameters.toml``."""
    q = load_quantities(params_path or VEHICLE_FILE,
                        lateral_16state.FIXED_KEYS + lateral_16state.PARAM_NAMES)
    return ({k: q[k].value for k in lateral_16state.FIXED_KEYS},
            np.array([q[k].value for k in lateral_16state.PARAM_NAMES]))


def noise_std(settings: RecordSettings) -> np.ndarray:
    """Sensor noise std of the five channels (:data:`lateral_16state.CHANNELS`): m/s², m/s²,
    m/s², m/s², rad/s."""
    return np.array([settings.noise_acc_wheelset_mps2] * 2 + [
        settings.noise_acc_bogie_mps2, settings.noise_acc_body_mps2, settings.noise_yawrate_radps])


def track_velocity(settings: RecordSettings, fixed: dict, seed: int) -> np.ndarray:
    """Track lateral velocity under both wheelsets on the fine grid, (K_fine + 1, 2) m/s: an
    alignment profile of ``spectrum`` (seed ``seed``) long enough for ``n_steps`` at ``dt_s``."""
    v = settings.speed_kmh / 3.6
    dtf = settings.dt_s / settings.truth_substeps
    dur = settings.n_steps * settings.dt_s
    length = max(v * dur + 2 * fixed["a"] + 10.0, 1.05 * settings.wavelength_max_m)
    dx = min(0.05, settings.wavelength_min_m / 2)
    s, z = track.synthesize_profile(settings.spectrum, "alignment", length, dx, seed=seed,
                                    wavelength_min_m=settings.wavelength_min_m,
                                    wavelength_max_m=settings.wavelength_max_m)
    _, _, dq = track.wheelset_inputs(s, z, v, [0.0, 2 * fixed["a"]], dtf, dur, derivative=True)
    return dq


def sampled_record(settings: RecordSettings, seed: int, states: np.ndarray, H: np.ndarray,
                   dq: np.ndarray) -> LateralRecord:
    """The record the filters see: fine-grid ``states`` (K_fine + 1, 16) sampled every
    ``truth_substeps`` and read through ``H`` ((5, 16), or (n_steps, 5, 16) when the
    measurement changes with θ over the record), white sensor noise (generator ``[seed, 7]``),
    and the input u_k = ẏ_t(t_{k−1}) held over a step."""
    sub = settings.truth_substeps
    x = states[sub::sub][:settings.n_steps]
    y = x @ H.T if H.ndim == 2 else np.einsum("kij,kj->ki", H[:len(x)], x)
    return noisy_record(settings, seed, y, dq)


def noisy_record(settings: RecordSettings, seed: int, y_clean: np.ndarray, dq: np.ndarray
                 ) -> LateralRecord:
    """The record of noise-free channels ``y_clean`` (n_steps, 5) at the samples: white sensor
    noise (generator ``[seed, 7]``, the draws of :func:`sampled_record`) and the input
    u_k = ẏ_t(t_{k−1}) held over a step."""
    sub = settings.truth_substeps
    rng = np.random.default_rng([seed, 7])
    y = y_clean + rng.standard_normal(y_clean.shape) * noise_std(settings)
    u = dq[0:-1:sub][:settings.n_steps]                   # u_k = ẏt(t_{k-1}), held over the step
    du = np.diff(dq[::sub], axis=0)
    return LateralRecord(seed=seed, y=y, u_mps=u, du_var_m2ps2=du.var(axis=0),
                         u_var_m2ps2=dq.var(axis=0))


def simulate_lateral(settings: RecordSettings, fixed: dict, theta: np.ndarray, seed: int
                     ) -> LateralRecord:
    """One record: an alignment profile of ``spectrum`` (seed ``seed``), the vehicle simulated
    exactly at ``dt_s / truth_substeps``, the five channels sampled at ``dt_s`` with white sensor
    noise (generator ``[seed, 7]``), and the filters' input u_k = ẏ_t(t_{k−1}) held over a step."""
    v = settings.speed_kmh / 3.6
    dq = track_velocity(settings, fixed, seed)
    x = lateral_16state.simulate_truth(fixed, theta, v, settings.dt_s / settings.truth_substeps,
                                       dq[:-1])
    H = lateral_16state.measurement_matrix(lateral_16state.build_A_direct(fixed, theta, v))
    return sampled_record(settings, seed, x, H, dq)


def filter_noise(fixed, theta, settings: RecordSettings, input_var) -> tuple[np.ndarray, np.ndarray]:
    """Q = Γ diag(input_var) Γᵀ (+1e-14 I) at the nominal θ, R = diag(noise²)."""
    _, G = zoh(lateral_16state.build_A_direct(fixed, theta, settings.speed_kmh / 3.6),
               lateral_16state.input_matrix(), settings.dt_s)
    Q = G @ np.diag(input_var) @ G.T + 1e-14 * np.eye(lateral_16state.N_STATES)
    return Q, np.diag(noise_std(settings) ** 2)


def prior_centre(theta: np.ndarray, prior_low: float, prior_high: float) -> np.ndarray:
    """The centre of the prior box ``prior_low``..``prior_high`` (factors of the nominal θ):
    chapter 003's balancing point of the filters' ZOH (:func:`filter_system`)."""
    return theta * 0.5 * (prior_low + prior_high)


def filter_system(settings: RecordSettings, fixed: dict, theta: np.ndarray,
                  record: LateralRecord, theta_ref: np.ndarray):
    """``system(theta)``: the ZOH model E(θ), F(θ), H(θ) at ``dt_s`` for a batch of particles,
    with the process noise of the record's input changes and the sensor noise
    (:func:`filter_noise`); the ZOH's balancing is that of ``theta_ref`` (chapter 003: the prior
    box's :func:`prior_centre`; it changes only the rounding)."""
    Q, R = filter_noise(fixed, theta, settings, record.du_var_m2ps2)
    return lateral_16state.lateral_system(fixed, settings.speed_kmh / 3.6, settings.dt_s, Q, R,
                                          theta_ref=theta_ref)


__all__ = ["LateralRecord", "RecordSettings", "TRACK_AND_SENSORS", "VEHICLE_FILE", "filter_noise",
           "filter_system", "noise_std", "noisy_record", "prior_centre", "sampled_record",
           "simulate_lateral",
           "track_velocity", "vehicle"]
