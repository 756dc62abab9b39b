"""Typed results of chapter ``partial-state-observer``: one record, its estimates, the whole run.

:func:`railpaper.experiments.partial_state_observer.experiment.run` returns a
:class:`PartialStateObserverResult`; the notebook reads its named fields.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import pandas as pd

from railpaper.experiments.base import ChapterResult


@dataclass(frozen=True)
class Record:
    """One simulated run: the vehicle on one track profile at one speed, with its sensors.

    Attributes
    ----------
    speed_kmh : float
        Speed of the run, km/h.
    t_s : ndarray, shape (K,)
        Sample times from the start of the observers (after the lead-in), s.
    q_m : ndarray, shape (K, 4)
        Track irregularity under wheelsets 1-4, m (positive downward).
    x : ndarray, shape (K, 20)
        Exact plant state (displacements m or rad, velocities m/s or rad/s), paper's order.
    z_m : ndarray, shape (K, 4)
        True wheelset displacements ``z_w1 … z_w4``, m.
    y_clean : ndarray, shape (K, 12)
        Noise-free measurements: six displacements (m, rad) then six accelerations.
    y : ndarray, shape (K, 12)
        Measurements with white noise of σ = ``noise_fraction`` × each channel's RMS.
    sigma : ndarray, shape (12,)
        Noise σ of each channel (units of the channel).
    """

    speed_kmh: float
    t_s: np.ndarray
    q_m: np.ndarray
    x: np.ndarray
    z_m: np.ndarray
    y_clean: np.ndarray
    y: np.ndarray
    sigma: np.ndarray

    @classmethod
    def from_run(cls, run: dict) -> "Record":
        """The record of one run as
        :func:`~railpaper.experiments.partial_state_observer.records.record` returns it."""
        return cls(**{k: run[k] for k in cls.__dataclass_fields__})


@dataclass(frozen=True)
class Estimates:
    """Wheelset-displacement estimates ``ẑ`` (K, 4) of every estimator on one record, m.

    Attributes
    ----------
    paper_m : ndarray
        The paper's functional observer (uses q), zero-order hold.
    hb0_m : ndarray
        The observer with ``H B = 0`` (no q), zero-order hold.
    kalman_m : ndarray
        Steady-state Kalman filter with a shaping filter for q (not told q).
    q_m : ndarray
        The baseline ``ẑ = q``.
    paper_foh_m : ndarray or None
        The paper's observer with a first-order hold (noise-free records only).
    """

    paper_m: np.ndarray
    hb0_m: np.ndarray
    kalman_m: np.ndarray
    q_m: np.ndarray
    paper_foh_m: np.ndarray | None = None

    @classmethod
    def from_dict(cls, est: dict) -> "Estimates":
        """From ``{"paper", "hb0", "kalman", "q"[, "paper_foh"]}``."""
        return cls(est["paper"], est["hb0"], est["kalman"], est["q"], est.get("paper_foh"))


@dataclass
class PartialStateObserverResult(ChapterResult):
    """What :func:`~railpaper.experiments.partial_state_observer.experiment.run` returns:
    :class:`ChapterResult` plus named results.

    Attributes
    ----------
    design : object
        The selected reading's model and observers (``vehicle``, ``model``, ``C``, ``paper``,
        ``hb0``, their discretisations ``paper_zoh``, ``paper_foh``, ``hb0_zoh`` and the Kalman
        baseline's shaping ``filters`` by speed in km/h):
        :class:`~railpaper.experiments.partial_state_observer.records.Context`.
    designs : dict of str to object
        The same for each reading of Table 1 (``labels``, ``symbols``).
    records : dict of float to Record
        The single record (seed ``seed``, selected reading) at each speed (km/h).
    estimates : dict of float to Estimates
        Every estimator on that record, with the sensors' noise.
    noise_free : dict of float to Estimates
        The same on the noise-free measurements (with ``paper_foh_m``).
    monte_carlo : DataFrame
        One row per (reading, seed, speed, estimator): convergence times (s, -1 never), errors
        (m), relative errors and the error dynamics' predicted convergence time (s)
        (:func:`~railpaper.experiments.partial_state_observer.evidence.runs_table` of the
        records' rows).
    alpha_sweep : DataFrame
        Convergence time (s) of the paper's observer against the pole region α (1/s), per speed,
        noisy and noise-free, with the error dynamics' prediction and H B = 0 feasibility.
    existence : DataFrame
        Darouach's existence conditions for three measurement sets.
    modal_table : DataFrame
        Modes of the assembled model (selected reading).
    rank_claims : DataFrame
        The paper's rank statements after Eq. (13), as printed and as we compute them.
    """

    design: object = None
    designs: dict = field(default_factory=dict)
    records: dict = field(default_factory=dict)
    estimates: dict = field(default_factory=dict)
    noise_free: dict = field(default_factory=dict)
    monte_carlo: pd.DataFrame = field(default_factory=pd.DataFrame)
    alpha_sweep: pd.DataFrame = field(default_factory=pd.DataFrame)
    existence: pd.DataFrame = field(default_factory=pd.DataFrame)
    modal_table: pd.DataFrame = field(default_factory=pd.DataFrame)
    rank_claims: pd.DataFrame = field(default_factory=pd.DataFrame)
