"""A wheel–rail force estimate that survives sensor noise (chapter ``reduced-order-observer``).

On the measurements the paper's observer sees — ``y = [ż_c, z_c]`` with sensor noise and the
irregularity ``q`` — this module runs, besides that observer:

* a **Kalman filter** of the single-wheelset model augmented with a second-order shaping filter
  for ``q`` (the track spectrum at the speed run, :func:`shaping_filter`), so that ``q`` is a
  state and its record a measurement; the augmented model is discretised exactly (matrix
  exponential, Van Loan for the process noise: :func:`kalman_model`);
* its **Rauch–Tung–Striebel smoother** (offline: it uses the whole record).

Both come from :mod:`railpaper.estimators.kalman_smoother` (time-varying gains computed once per
speed, noise level and chunk of seeds, then applied to every seed of the chunk).  The force is
``K_r (ẑ_w − q̂)``.  The comparison is a map over records and a reduce: studies
:data:`ESTIMATOR_RECORDS` and :data:`TRACK_NOISE_RECORDS` give one wide row per seed,
:func:`samples_table` the long table and :func:`comparison_metrics` the metrics.

What the filter is told: the sensor noise σ of each body channel as ``noise_fraction`` × the
channel's stationary standard deviation under the model at that speed (the sensor's stated
accuracy relative to the expected signal; the simulated noise is that fraction of each record's
own RMS); the noise on ``q`` as ``track_noise_fraction`` × the stationary standard deviation of
``q``, at least :data:`Q_NOISE_FLOOR` of it; the prior of the first step: mean = the observer's
initial guess (body states from the first measurement, ``z_w`` off by ``initial_error_m``,
``q`` from its first sample, ``q̇ = 0``), covariance = the model's stationary covariance plus
``initial_error_m``² on ``z_w``.

Every sample is a record of the chapter's Monte Carlo: seed ``s`` at speed ``v`` has the track
profile and the standard-normal sensor draws of the chapter's single run with ``seed = s``
(:func:`record.noise_draws`), scaled to each noise level (common random numbers across
levels), so the observer's ratios at the chapter's noise equal the Monte Carlo table's.  Two
sweeps: every seed at every sensor noise level of :func:`noise_levels` (the run's noise on q),
and the first :data:`TRACK_NOISE_SEEDS` seeds at every noise level on the q record of
:data:`TRACK_NOISE_FRACTIONS` (the run's sensor noise): all three estimators take q as given.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd
from scipy.linalg import solve_discrete_lyapunov

from railpaper import stats, track
from railpaper.estimators import kalman_baseline as kb
from railpaper.estimators import kalman_smoother as ks
from railpaper.estimators import reduced_order_observer
from railpaper.experiments import track_shaping
from railpaper.experiments.records import RecordMap, RecordStudy, map_in_process
from railpaper.experiments.reduced_order_observer import record, spec
from railpaper.experiments.reduced_order_observer.result import (
    ForceEstimates,
    KalmanComparison,
)
from railpaper.experiments.reduced_order_observer.spec import ESTIMATORS, Settings
from railpaper.models import single_wheelset

#: Sensor-noise levels (σ / channel RMS) of the comparison; the run's ``noise_fraction`` is added.
NOISE_FRACTIONS = (1e-4, 1e-3, 1e-2, 3e-2)

#: Noise levels on the q record (σ / RMS of q) of the track-noise sweep, at the run's sensor
#: noise, on the first ``TRACK_NOISE_SEEDS`` seeds.
TRACK_NOISE_FRACTIONS = (1e-5, 1e-4, 1e-3)
TRACK_NOISE_SEEDS = 5

#: Smallest σ of the q record the filter assumes, as a fraction of q's stationary std.
Q_NOISE_FLOOR = 1e-6

#: Smallest σ of a body channel the filter assumes (a noise-free run), fraction of its std.
Y_NOISE_FLOOR = 1e-6



def shaping_filter(track_class: int, speed_mps: float) -> kb.ShapingFilter:
    """Second-order shaping filter fitted to the FRA vertical spectrum seen at speed V.

    The temporal one-sided PSD is ``S(Ω = ω/V)/V`` over the profile's wavelength band
    (:data:`spec.FRA_BAND_M`), with the band's variance as a constraint.
    """
    return track_shaping.shaping_filter(f"fra-{track_class}", speed_mps, spec.FRA_BAND_M)[0]


@dataclass(frozen=True)
class KalmanModel:
    """The augmented model ``x = [ż_c, z_c, ż_w, z_w, q, q̇]`` discretised exactly.

    Attributes
    ----------
    F, Q : ndarray, shape (6, 6)
        ``e^{A dt}`` and the process-noise covariance over a step (Van Loan).
    H : ndarray, shape (3, 6)
        Measured ``[ż_c, z_c, q]``.
    P_stationary : ndarray, shape (6, 6)
        Stationary covariance (``P = F P Fᵀ + Q``).
    """

    F: np.ndarray
    Q: np.ndarray
    H: np.ndarray
    P_stationary: np.ndarray

    @property
    def stationary_std(self) -> np.ndarray:
        """Stationary standard deviation of each state (SI units)."""
        return np.sqrt(np.diag(self.P_stationary))


def kalman_model(A: np.ndarray, B: np.ndarray, shaping: kb.ShapingFilter, dt_s: float) -> KalmanModel:
    """Plant ``(A, B)`` driven by ``q`` from ``shaping``: exact discretisation over ``dt_s``."""
    Aa, Ga, Ca = kb.augment(A, B, np.eye(A.shape[0])[:2], [shaping])
    H = np.vstack([Ca, np.eye(Aa.shape[0])[A.shape[0]]])               # [ż_c, z_c] and q
    F, Q = kb.discretise_noise(Aa, Ga, np.eye(1), dt_s)
    return KalmanModel(F=F, Q=Q, H=H, P_stationary=solve_discrete_lyapunov(F, Q))


def noise_levels(settings: Settings) -> list[float]:
    """The comparison's noise levels: :data:`NOISE_FRACTIONS` and the run's ``noise_fraction``."""
    return sorted(set(NOISE_FRACTIONS) | {float(settings.noise_fraction)})


def filter_covariances(model: KalmanModel, configs, settings: Settings):
    """``(R, P0)`` of each ``(sensor noise fraction, track noise fraction)`` in ``configs``
    (leading axis of R), as the module docstring says."""
    std = model.stationary_std
    R = np.array([np.diag([(max(f, Y_NOISE_FLOOR) * std[0]) ** 2,
                           (max(f, Y_NOISE_FLOOR) * std[1]) ** 2,
                           (max(fq, Q_NOISE_FLOOR) * std[4]) ** 2]) for f, fq in configs])
    P0 = model.P_stationary + np.diag([0.0, 0.0, 0.0, settings.initial_error_m ** 2, 0.0, 0.0])
    return R, P0


def _rms(x, axis=0):
    return np.sqrt(np.mean(x**2, axis=axis))


@dataclass(frozen=True)
class _Records:
    """Truth and standard-normal sensor draws of S records at one speed (columns = seeds, then
    the pad columns of :func:`record.padded`)."""

    seeds: list
    t_s: np.ndarray
    q: np.ndarray          # (K, S) true irregularity, m
    y: np.ndarray          # (K, S, 2) true [ż_c, z_c]
    force: np.ndarray      # (K, S) true dynamic force, N
    draws_y: np.ndarray    # (K, S, 2)
    draws_q: np.ndarray    # (K, S)


def _simulate(vehicle, settings: Settings, speed, profiles) -> _Records:
    """The plant on every seed's profile at one speed (the chapter's records and draws), as one
    batch of at least :data:`record.MIN_BATCH_COLUMNS` columns."""
    columns_q, draws_y, draws_q = [], [], []
    for seed, (distance_m, profile_m) in profiles.items():
        t_s, q = track.wheelset_inputs(distance_m, profile_m, speed / 3.6, [0.0], settings.dt_s,
                                       settings.duration_s)
        ny, nq = record.noise_draws(seed, speed, len(t_s))
        columns_q.append(q[:, 0])
        draws_y.append(ny)
        draws_q.append(nq)
    q = record.padded(np.column_stack(columns_q))                     # (K, S)
    y, z_w = record._plant_batch(vehicle, settings.plant, settings.dt_s, q)
    return _Records(list(profiles), t_s, q, y,
                    single_wheelset.dynamic_contact_force_N(vehicle, z_w, q, settings.plant),
                    record.padded(np.stack(draws_y, axis=1)),
                    record.padded(np.column_stack(draws_q)))


@dataclass(frozen=True)
class _SpeedErrors:
    """The estimators on S records at one speed under L ``(sensor, track)`` noise configs."""

    force_rms_N: np.ndarray        # (S,) true force over the error window
    q_rms_m: np.ndarray            # (S,) the record's q
    error_rms_N: dict              # estimator -> (L, S) RMS force error
    example: ForceEstimates        # the first record at the first config


def _speed_errors(vehicle, model, observer, settings: Settings, records: _Records,
                  configs) -> _SpeedErrors:
    """Every estimator on every record of ``records`` at every ``(sensor noise fraction, track
    noise fraction)`` of ``configs``."""
    t_s, q, y, force = records.t_s, records.q, records.y, records.force
    window = t_s >= settings.error_window_start_s
    force_rms, q_rms = _rms(force[window]), _rms(q)                    # (S,)
    L, S = len(configs), q.shape[1]
    sensor, track_noise = (np.array([c[i] for c in configs])[:, None] for i in (0, 1))
    meas = np.empty((len(q), L, S, 3))                                  # [ż_c, z_c, q] measured
    meas[..., :2] = y[:, None] + records.draws_y[:, None] * sensor[..., None] * _rms(y)
    meas[..., 2] = q[:, None] + records.draws_q[:, None] * track_noise * _rms(q)
    x2_initial = np.stack([np.zeros(S), q[0] + settings.initial_error_m], axis=-1)   # (S, 2)
    observed = record._observer_batch(
        observer, meas[..., :2].reshape(len(q), L * S, 2), meas[..., 2].reshape(len(q), L * S),
        np.tile(x2_initial, (L, 1))).reshape(len(q), L, S)
    estimates = {"observer": single_wheelset.dynamic_contact_force_N(vehicle, observed,
                                                                     meas[..., 2])}
    R, P0 = filter_covariances(model, configs, settings)
    gains = ks.gains(model.F, model.Q, model.H, R, P0, len(t_s))        # one model per config
    x0 = np.concatenate([meas[0, ..., :2], np.broadcast_to(x2_initial, (L, S, 2)),
                         meas[0, ..., 2:], np.zeros((L, S, 1))], axis=-1)
    x_filtered, innovations = ks.filter_means(gains, model.F, model.H, meas, x0)
    k_r = vehicle.contact_stiffness_N_per_m
    estimates["kalman"] = k_r * (x_filtered[..., 3] - x_filtered[..., 4])
    x_smoothed = ks.smoother_means(gains, model.F, model.H, innovations, x_filtered)
    del x_filtered, innovations, gains
    estimates["smoother"] = k_r * (x_smoothed[..., 3] - x_smoothed[..., 4])
    return _SpeedErrors(
        force_rms_N=force_rms, q_rms_m=q_rms,
        error_rms_N={name: _rms((f_est - force[:, None])[window])
                     for name, f_est in estimates.items()},
        example=ForceEstimates(t_s=t_s, force_true_N=force[:, 0],
                               **{f"{k}_N": v[:, 0, 0] for k, v in estimates.items()}))


def sensor_configs(settings: Settings) -> list[tuple[float, float]]:
    """``(sensor, track)`` noise fractions of the sensor sweep: the run's first, then the other
    levels of :func:`noise_levels`, at the run's ``track_noise_fraction``."""
    run_noise, run_track = float(settings.noise_fraction), float(settings.track_noise_fraction)
    return [(run_noise, run_track)] + [(f, run_track) for f in noise_levels(settings)
                                       if f != run_noise]


def track_configs(settings: Settings) -> list[tuple[float, float]]:
    """``(sensor, track)`` noise fractions of the track-noise sweep: the run's sensor noise and
    each of :data:`TRACK_NOISE_FRACTIONS`."""
    return [(float(settings.noise_fraction), f) for f in TRACK_NOISE_FRACTIONS]


#: The two sweeps: the noise configs of each and the level in the name of its columns.
SWEEPS = {"sensor": (sensor_configs, 0), "track": (track_configs, 1)}


def error_column(estimator: str, sweep: str, level: float, speed_kmh: float) -> str:
    """Column of a record's row holding one estimator's RMS force error (N) at one noise level
    of a sweep (``sensor`` or ``track``) and one speed, e.g.
    ``force_rms_error_N_kalman_sensor_noise0.01_60kmh``."""
    return f"force_rms_error_N_{estimator}_{sweep}_noise{level!r}_{speed_kmh:g}kmh"


def _estimator(settings: Settings):
    """The vehicle (reading ``p0_basis``), its (A, B) and the paper's discrete observer."""
    vehicle = single_wheelset.load_parameters(p0_basis=settings.p0_basis)
    A, B = single_wheelset.state_space(vehicle)
    hold = "zoh" if settings.observer_form == "paper" else "foh"
    observer = reduced_order_observer.design(A, B, 2, settings.observer_poles).discretise(
        settings.dt_s, hold)
    return vehicle, A, B, observer


def _sweep_rows(settings: Settings, seeds: tuple[int, ...], sweep: str) -> pd.DataFrame:
    """One row per seed of ``seeds``: per speed of ``speeds_kmh``, ``force_rms_N_<v>kmh``,
    ``q_rms_m_<v>kmh`` and :func:`error_column` of every estimator and config of ``sweep``."""
    seeds = [int(s) for s in seeds]
    vehicle, A, B, observer = _estimator(settings)
    profiles = {seed: record.profile(settings, seed) for seed in seeds}
    configs, level = SWEEPS[sweep][0](settings), SWEEPS[sweep][1]
    row, n = {"seed": seeds}, len(seeds)
    for speed in settings.speeds_kmh:
        model = kalman_model(A, B, shaping_filter(settings.track_class, speed / 3.6),
                             settings.dt_s)
        errors = _speed_errors(vehicle, model, observer, settings,
                               _simulate(vehicle, settings, speed, profiles), configs)
        row[f"force_rms_N_{speed:g}kmh"] = errors.force_rms_N[:n]
        row[f"q_rms_m_{speed:g}kmh"] = errors.q_rms_m[:n]
        for name, error_rms in errors.error_rms_N.items():
            for i, config in enumerate(configs):
                row[error_column(name, sweep, config[level], speed)] = error_rms[i, :n]
    return pd.DataFrame(row)


def estimator_rows(settings: Settings, seeds: tuple[int, ...]) -> pd.DataFrame:
    """The sensor sweep's rows (:func:`_sweep_rows`): every estimator at every sensor noise level
    of :func:`noise_levels` (the run's track noise), per speed of ``speeds_kmh``."""
    return _sweep_rows(settings, seeds, "sensor")


def track_noise_rows(settings: Settings, seeds: tuple[int, ...]) -> pd.DataFrame:
    """The track-noise sweep's rows (:func:`_sweep_rows`): every estimator at every noise level
    of :data:`TRACK_NOISE_FRACTIONS` on the q record (the run's sensor noise)."""
    return _sweep_rows(settings, seeds, "track")


#: The estimators on every Monte Carlo seed at every sensor noise level (chunks of 40 seeds, the
#: quick run's one batch: a chunk's fixed cost — the filter's gains per speed, the time loops —
#: is then under half of it, and its arrays under 1 GB at the default sizes).
ESTIMATOR_RECORDS = RecordStudy("reduced-order-observer", "estimators", estimator_rows,
                                chunk_records=40)

#: The estimators on the first :data:`TRACK_NOISE_SEEDS` seeds at every track noise level.
TRACK_NOISE_RECORDS = RecordStudy("reduced-order-observer", "estimators_track_noise",
                                  track_noise_rows, chunk_records=TRACK_NOISE_SEEDS)


def comparison_seeds(settings: Settings) -> dict[str, list[int]]:
    """The seeds of each study: ``mc_seeds`` seeds from ``seed``; the first
    :data:`TRACK_NOISE_SEEDS` of them for the track-noise sweep."""
    seeds = list(range(settings.seed, settings.seed + settings.mc_seeds))
    return {ESTIMATOR_RECORDS.name: seeds, TRACK_NOISE_RECORDS.name: seeds[:TRACK_NOISE_SEEDS]}


def comparison_records(settings: Settings, progress=None,
                       record_map: RecordMap = map_in_process) -> dict[str, pd.DataFrame]:
    """The rows of :data:`ESTIMATOR_RECORDS` and :data:`TRACK_NOISE_RECORDS` through
    ``record_map``, by study name."""
    progress = progress or (lambda fraction, message: None)
    seeds = comparison_seeds(settings)
    return {
        ESTIMATOR_RECORDS.name: record_map(ESTIMATOR_RECORDS, settings,
                                           seeds[ESTIMATOR_RECORDS.name],
                                           lambda f, m: progress(0.85 * f, m)),
        TRACK_NOISE_RECORDS.name: record_map(TRACK_NOISE_RECORDS, settings,
                                             seeds[TRACK_NOISE_RECORDS.name],
                                             lambda f, m: progress(0.85 + 0.1 * f, m))}


def samples_table(rows: dict[str, pd.DataFrame], settings: Settings) -> pd.DataFrame:
    """The comparison's samples (:attr:`KalmanComparison.samples`, one row per seed, speed,
    noise config, estimator and sweep) from the studies' rows (:func:`comparison_records`)."""
    out = []
    for speed in settings.speeds_kmh:
        lab = f"{speed:g}kmh"
        for sweep, study in (("sensor", ESTIMATOR_RECORDS), ("track", TRACK_NOISE_RECORDS)):
            table = rows[study.name]
            configs, level = SWEEPS[sweep][0](settings), SWEEPS[sweep][1]
            seeds = [int(s) for s in table["seed"]]
            force_rms = table[f"force_rms_N_{lab}"].to_numpy()
            q_rms = table[f"q_rms_m_{lab}"].to_numpy()
            for name in ESTIMATORS:
                for sensor_level, track_level in configs:
                    error = table[error_column(
                        name, sweep, (sensor_level, track_level)[level], speed)].to_numpy()
                    out += [(seed, speed, sensor_level, track_level, name, force_rms[j],
                             error[j], error[j] / force_rms[j], q_rms[j], sweep)
                            for j, seed in enumerate(seeds)]
    return pd.DataFrame(out, columns=["seed", "speed_kmh", "noise_fraction",
                                      "track_noise_fraction", "estimator", "force_rms_N",
                                      "force_rms_error_N", "ratio", "q_rms_m", "sweep"])


def examples(settings: Settings) -> dict:
    """Per speed of ``speeds_kmh``, the forces of seed ``seed`` at the run's noise
    (:class:`ForceEstimates`; the same numbers as that record's in the studies)."""
    vehicle, A, B, observer = _estimator(settings)
    profiles = {settings.seed: record.profile(settings, settings.seed)}
    out = {}
    for speed in settings.speeds_kmh:
        model = kalman_model(A, B, shaping_filter(settings.track_class, speed / 3.6),
                             settings.dt_s)
        out[speed] = _speed_errors(vehicle, model, observer, settings,
                                   _simulate(vehicle, settings, speed, profiles),
                                   sensor_configs(settings)[:1]).example
    return out


def compare(settings: Settings, progress=None,
            record_map: RecordMap = map_in_process) -> KalmanComparison:
    """The paper's observer, the Kalman filter and the smoother at the run's speeds
    (``speeds_kmh``), reading ``p0_basis``: on ``mc_seeds`` seeds × :func:`noise_levels` (track
    noise ``track_noise_fraction``), and on the first :data:`TRACK_NOISE_SEEDS` seeds ×
    :data:`TRACK_NOISE_FRACTIONS` at the run's sensor noise (the records through
    ``record_map``; the example forces of seed ``seed`` computed here)."""
    progress = progress or (lambda fraction, message: None)
    return comparison(comparison_records(settings, progress, record_map), settings,
                      lambda f, m: progress(0.95 + 0.05 * f, m))


def comparison(rows: dict[str, pd.DataFrame], settings: Settings, progress=None
               ) -> KalmanComparison:
    """:class:`KalmanComparison` of the studies' ``rows`` (:func:`comparison_records`): their
    :func:`samples_table`, the example forces (:func:`examples`) and the shaping filters."""
    progress = progress or (lambda fraction, message: None)
    progress(0.0, "Kalman filter and smoother, example record")
    shaping = {speed: shaping_filter(settings.track_class, speed / 3.6)
               for speed in settings.speeds_kmh}
    return KalmanComparison(samples=samples_table(rows, settings), examples=examples(settings),
                            shaping=shaping)


def comparison_metrics(comparison: KalmanComparison, settings: Settings) -> dict:
    """At the run's ``noise_fraction``, per speed ``<v>kmh``:

    * ``force_rms_error_ratio_{kalman,smoother}_<v>kmh``: RMS force error / RMS force of seed
      ``seed`` (the single record);
    * ``mc_force_rms_error_ratio_{observer,kalman,smoother}_<v>kmh``: median over the
      ``mc_seeds`` seeds with its 95 % order-statistic interval (``_low``, ``_high``, ``_n``).
    """
    s = comparison.samples
    at = s[(s.sweep == "sensor") & (s.noise_fraction == float(settings.noise_fraction))]
    metrics = {}
    for speed in settings.speeds_kmh:
        lab = f"{speed:g}kmh"
        for name in ESTIMATORS:
            rows = at[(at.speed_kmh == speed) & (at.estimator == name)].sort_values("seed")
            if name != "observer":
                metrics[f"force_rms_error_ratio_{name}_{lab}"] = float(
                    rows[rows.seed == settings.seed].ratio.iloc[0])
            metrics.update(stats.median_interval(rows.ratio.to_numpy()).metrics(
                f"mc_force_rms_error_ratio_{name}_{lab}"))
    return metrics
