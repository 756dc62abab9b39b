"""The appendix's records: paper 003's lateral vehicle on an alignment profile, with a fault
that starts at a known (to us) time and is unknown to the detectors.

The truth is simulated exactly on the fine grid with θ piecewise constant
(:func:`railpaper.models.lateral_16state.simulate_truth_schedule`); the measurement matrix
changes with θ too, because the four accelerations are rows of A(θ) x.  A sample at time t_k
reads θ of the transition that ended there, so a fault at time τ = j·dt_s first shows in filter
step j + 1 (1-based), both in the data and in the oracle's hypothesis "τ = j + 1".
Where a fault makes the vehicle hunt, the record ends at the last sample before a wheelset
reaches flange contact: the linear model has no flange.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from railpaper.experiments.lateral_vehicle import (
    LateralRecord,
    RecordSettings,
    noisy_record,
    sampled_record,
    track_velocity,
)
from railpaper.experiments.suspension_fault_detection import faults
from railpaper.experiments.suspension_fault_detection.result import Fault
from railpaper.experiments.suspension_fault_detection.spec import Settings
from railpaper.models import lateral_16state, lateral_model_error


@dataclass(frozen=True)
class FaultedRecord:
    """One simulated record and where its fault and its end lie.

    Attributes
    ----------
    record : LateralRecord
        What the detectors are given (``y`` ends at ``end_step``).
    fault_step : int
        First filter step (1-based) whose transition and measurement follow the fault; −1 when
        fault-free.
    end_step : int
        Samples in the record.
    flange_contact : bool
        The record was cut at flange contact.
    factor : ndarray, (end_step,)
        The faulted parameter's true value at each sample, fraction of nominal.
    """

    record: LateralRecord
    fault_step: int
    end_step: int
    flange_contact: bool
    factor: np.ndarray


def record_settings(settings: Settings, speed_kmh: float) -> RecordSettings:
    """What :mod:`railpaper.experiments.lateral_vehicle` reads of a record at one speed: the
    appendix's sample time, truth substeps, track and sensors, ``duration_s / dt_s`` steps."""
    return RecordSettings.of(settings, speed_kmh=speed_kmh,
                             n_steps=int(round(settings.duration_s / settings.dt_s)))


def _model_error_truth(model_error: faults.ModelError, fixed: dict, thetas, starts, v: float,
                       dt_fine: float, dq: np.ndarray, piece: np.ndarray, sub: int
                       ) -> tuple[np.ndarray, np.ndarray]:
    """Fine-grid states (K_fine + 1, 17) of the plant with model error and its noise-free
    channels at the samples (n_steps, 5), each sample read with the θ of the transition that
    ended there."""
    states = lateral_model_error.simulate_schedule(
        fixed, thetas, starts, v, dt_fine, dq[:-1], model_error.wheel_rail,
        model_error.series_stiffness_N_per_m)
    x = states[sub::sub][:len(piece)]
    y_clean = np.empty((len(x), len(lateral_16state.CHANNELS)))
    for i, th in enumerate(thetas):
        rows = piece[:len(x)] == i
        if rows.any():
            plant = lateral_model_error.ModelErrorPlant(fixed, th, v, model_error.wheel_rail,
                                                        model_error.series_stiffness_N_per_m)
            y_clean[rows] = plant.measurements(x[rows])
    return states, y_clean


def simulate_faulted(settings: Settings, fault_settings: dict, fixed: dict, theta: np.ndarray,
                     fault: Fault | None, fault_time_s: float, speed_kmh: float, seed: int,
                     model_error: faults.ModelError | None = None) -> FaultedRecord:
    """The record of ``seed`` at ``speed_kmh`` with ``fault`` from ``fault_time_s`` on (None:
    fault-free); sensor noise and track as chapter 003's records.  ``fault_settings`` are the
    catalogue's (:func:`~railpaper.experiments.suspension_fault_detection.faults.catalogue`).
    With ``model_error`` the truth is :mod:`railpaper.models.lateral_model_error` with θ of
    :meth:`~.faults.ModelError.truth_theta` (the fault acts on it); ``factor`` is then relative
    to the truth's nominal value."""
    rs = record_settings(settings, speed_kmh)
    sub, K = rs.truth_substeps, rs.n_steps
    dt_fine = rs.dt_s / sub
    dq = track_velocity(rs, fixed, seed)
    fault_sample = int(round(fault_time_s / rs.dt_s)) if fault is not None else K
    if model_error is not None:
        theta = model_error.truth_theta(theta)
    thetas, starts = faults.schedule(fault, fault_settings, theta, fault_sample * sub, K * sub,
                                     dt_fine)
    v = speed_kmh / 3.6
    piece = np.searchsorted(np.asarray(starts), np.arange(1, K + 1) * sub, side="left") - 1
    if model_error is None:
        states = lateral_16state.simulate_truth_schedule(fixed, thetas, starts, v, dt_fine,
                                                         dq[:-1])
        H_pieces = np.stack([lateral_16state.measurement_matrix(
            lateral_16state.build_A_direct(fixed, th, v)) for th in thetas])
        record = sampled_record(rs, seed, states, H_pieces[piece], dq)
    else:
        states, y_clean = _model_error_truth(model_error, fixed, thetas, starts, v, dt_fine,
                                             dq, piece, sub)
        record = noisy_record(rs, seed, y_clean, dq)
    contact = lateral_16state.flange_contact_step(states[:, :lateral_16state.N_STATES],
                                                  fault_settings["flange_clearance_m"])
    end = K if contact < 0 else min(K, (contact - 1) // sub)
    if end < K:
        record = record.first_steps(end)
    j = None if fault is None else lateral_16state.PARAM_NAMES.index(fault.parameter)
    factor = (np.ones(end) if j is None else
              np.array([th[j] for th in thetas])[piece[:end]] / theta[j])
    return FaultedRecord(record=record, fault_step=fault_sample + 1 if fault else -1,
                         end_step=end, flange_contact=end < K, factor=factor)


__all__ = ["FaultedRecord", "record_settings", "simulate_faulted"]
