"""Records of chapter ``partial-state-observer``: one seed's runs, simulated; its row of numbers.

A record is one seed: its track profile (US FRA class ``track_class``) and its sensor noise, run
at every speed under both readings of Table 1 (same track, same noise draws).  The chapter's
expensive work is two studies of such records (:class:`~railpaper.experiments.records.RecordStudy`):

* :data:`MONTE_CARLO` (:func:`monte_carlo_rows`): every speed and reading, the paper's observer
  with the paper's noise, noise-free and with speed-independent noise, the ``H B = 0`` variant
  and ``ẑ = q``; each run's numbers of :func:`run_measures` and, for the two observers, the
  convergence time their error dynamics alone predict;
* :data:`KALMAN_BASELINE` (:func:`kalman_baseline_rows`), one study per reading: the Kalman
  baseline's numbers on the runs of that reading (a run computes it for the first
  :data:`KALMAN_SEEDS` seeds of the selected reading: an illustration, no claim reads it).

A row's columns are named by :func:`record_column` (``max_error_after_1s_m_60kmh_paper_labels``);
the chapter's evidence (:func:`~railpaper.experiments.partial_state_observer.evidence.runs_table`,
:func:`~railpaper.experiments.partial_state_observer.evidence.monte_carlo_metrics`) is the reduce.

The numbers of a run (wheelsets 1-4; ``win``: t ≥ the error window start, 1 s)
------------------------------------------------------------------------------
* ``convergence_time_s``: first time after which ``|ẑ_i − z_i| < threshold_i`` for every i to the
  end of the run, with ``threshold_i`` = 5 % of the RMS of the true z_i over the run; the run's
  duration if it never settles (censored: the statistics then stay finite and conservative);
* ``convergence_time_fixed_s``: the same against a threshold that does not depend on the speed
  (5 % of the RMS of the seed's whole track profile);
* ``converged``: settled at a time ≤ the window start (the paper: 'after starting 1 second when
  the observer become stable');
* ``max_error_after_1s_m``: ``max_{i, win} |ẑ_i − z_i|``;
* ``mean_relative_error``: ``mean_i mean_win |ẑ_i − z_i| / RMS_win(z_i)``;
* ``biggest_mean_relative_error``: ``max_i mean_win |ẑ_i − z_i| / RMS_win(z_i)``;
* ``biggest_mean_signed_relative_error``: ``max_i |mean_win (ẑ_i − z_i)| / RMS_win(z_i)`` (the
  average of the signed error: the estimate's offset, which noise averages out);
* ``relative_rms_error``: ``mean_i RMS_win(ẑ_i − z_i) / RMS_win(z_i)`` (tracking);
* ``rms_error_m``: ``RMS_{i, win}(ẑ_i − z_i)`` (the estimate's oscillation about the truth).

Seeds are simulated :data:`SEED_GROUP` at a time (one chunk of records; the group size bounds
the memory).  A record's numbers do not depend on its chunk: every matrix product over runs has
at least two rows, because a chunk of one seed is simulated as that seed twice
(:func:`batch_seeds`).  OpenBLAS multiplies a one-row matrix (``gemv``) with another rounding than
a matrix of several rows (``gemm``), whose rows do not depend on how many there are; with the
Kalman baseline's (seeds × 28) products, a seed simulated alone differed from the same seed in a
chunk of ten in the last bits of 77 of its 80 numbers.
"""

from __future__ import annotations

from functools import cached_property, lru_cache, partial

import numpy as np
import pandas as pd

from railpaper import track
from railpaper.data import data_path, load_quantities, values
from railpaper.discretise import foh
from railpaper.estimators import functional_observer
from railpaper.estimators import kalman_baseline as kb
from railpaper.experiments.base import ParameterError
from railpaper.experiments.partial_state_observer.spec import SPEC, Settings
from railpaper.experiments.records import RecordStudy
from railpaper.experiments.track_shaping import shaping_filter
from railpaper.models import vertical_10dof
from railpaper.settling import settling_time_s
from railpaper.threads import one_thread

#: Measurement set of the chapter's observers: the only one that passes Darouach's conditions.
MEASUREMENT = "both"

#: Readings of Table 1's suspension rows, default first (data/.../suspension_readings.toml).
READINGS = ("labels", "symbols")
SUSPENSION_KEYS = ("primary_stiffness_N_per_m", "primary_damping_Ns_per_m",
                   "secondary_stiffness_N_per_m", "secondary_damping_Ns_per_m")


def suspension(reading: str) -> dict[str, float]:
    """Suspension values (SI) of one reading of paper 000's Table 1."""
    if reading not in READINGS:
        raise ValueError(f"reading must be one of {READINGS}, got {reading!r}")
    path = data_path("partial-state-observer/suspension_readings.toml")
    return values(load_quantities(path, SUSPENSION_KEYS, section=reading))


#: The numbers :func:`run_measures` gives of each run (s, m, 1; ``converged`` a bool).
MEASURES = ("convergence_time_s", "convergence_time_fixed_s", "converged", "max_error_after_1s_m",
            "mean_relative_error", "biggest_mean_relative_error",
            "biggest_mean_signed_relative_error", "relative_rms_error", "rms_error_m")
#: Estimators of every record (the Kalman baseline's rows are a study of their own).
MONTE_CARLO_ESTIMATORS = ("paper", "paper_noisefree", "paper_fixednoise", "hb0", "q")


def record_column(measure: str, speed_kmh: float, estimator: str, reading: str) -> str:
    """Name of a record's column: one measure of one run
    (``max_error_after_1s_m_60kmh_paper_labels``; the measure's unit ends its own name)."""
    return f"{measure}_{speed_kmh:g}kmh_{estimator}_{reading}"


def run_measures(t_s, z_true, z_est, fixed_threshold_m, fraction: float,
                 window_start_s: float) -> dict:
    """Numbers of each run (definitions in the module docstring), for a batch of runs.

    Parameters
    ----------
    t_s : ndarray, shape (K,)
        Sample times from the observer's start, s.
    z_true, z_est : ndarray, shape (..., K, 4)
        Simulated and estimated wheelset displacements, m (leading axes: runs).
    fixed_threshold_m : float or ndarray, shape (...)
        Speed-independent convergence threshold of each run, m.
    fraction : float
        Convergence threshold as a fraction of the RMS of each true z_i (0.05).
    window_start_s : float
        Errors are measured from this time on, s (1 s).

    Returns
    -------
    dict of str to ndarray, shape (...)
    """
    err = np.asarray(z_est) - np.asarray(z_true)
    i0 = int(np.searchsorted(t_s, window_start_s))        # t_s ascending: the window is a slice
    ew, zw = err[..., i0:, :], np.asarray(z_true)[..., i0:, :]
    rms_true = np.sqrt(np.mean(zw**2, axis=-2))
    duration = float(t_s[-1])
    thr = fraction * np.sqrt(np.mean(np.asarray(z_true) ** 2, axis=-2))             # (..., p)
    tc = settling_time_s(t_s, np.all(np.abs(err) < thr[..., None, :], axis=-1), axis=-1)
    fixed = np.broadcast_to(np.asarray(fixed_threshold_m, float)[..., None], rms_true.shape)
    tf = settling_time_s(t_s, np.all(np.abs(err) < fixed[..., None, :], axis=-1), axis=-1)
    mean_rel = np.mean(np.abs(ew), axis=-2) / rms_true
    return {"convergence_time_s": np.where(tc < 0, duration, tc),
            "convergence_time_fixed_s": np.where(tf < 0, duration, tf),
            "converged": (tc >= 0) & (tc <= window_start_s),
            "max_error_after_1s_m": np.abs(ew).max(axis=(-2, -1)),
            "mean_relative_error": mean_rel.mean(axis=-1),
            "biggest_mean_relative_error": mean_rel.max(axis=-1),
            "biggest_mean_signed_relative_error": (np.abs(np.mean(ew, axis=-2))
                                                   / rms_true).max(axis=-1),
            "relative_rms_error": np.mean(np.sqrt(np.mean(ew**2, axis=-2)) / rms_true, axis=-1),
            "rms_error_m": np.sqrt(np.mean(ew**2, axis=(-2, -1)))}


PROFILE_DX_M = 0.05
SEED_GROUP = 10               # seeds simulated together (one chunk; bounds its memory)
KALMAN_SEEDS = 20             # the Kalman baseline (an illustration, no claim) runs on these many


def error_dynamics(disc: functional_observer.DiscreteFunctionalObserver, n_steps: int,
                   e0: float) -> np.ndarray:
    """The error dynamics alone, ``ε[k] = Φ^k ε[0]`` with every component of ε[0] = e0."""
    eps = np.empty((n_steps, disc.Phi.shape[0]))
    eps[0] = e0
    for k in range(n_steps - 1):
        eps[k + 1] = disc.Phi @ eps[k]
    return eps


def predicted_convergence_s(eps: np.ndarray, t_s, z_true, settings: Settings) -> float:
    """Convergence time of the error dynamics ``eps`` alone against the run's threshold."""
    thr = settings.convergence_fraction * np.sqrt(np.mean(z_true**2, axis=0))
    return settling_time_s(t_s, np.all(np.abs(eps[: len(t_s)]) < thr, axis=-1))


class Context:
    """Everything that does not depend on the seed, for one reading of Table 1: model,
    observers, discretisations and (made on first use) the Kalman baseline's shaping ``filters``
    and models by speed in km/h."""

    def __init__(self, settings: Settings, reading: str):
        self.settings = settings
        self.reading = reading
        self.vehicle = v = vertical_10dof.load_parameters(**suspension(reading))
        self.model = m = vertical_10dof.build_model(self.vehicle)
        self.C = m.output_matrix(MEASUREMENT)
        self.plant = foh(m.A, m.B, settings.dt_s)
        try:
            self.paper = functional_observer.design(m.A, m.B, self.C, m.L, settings.alpha_per_s,
                                                    settings.beta)
        except functional_observer.LMIInfeasible as exc:
            raise ParameterError(f"parameters 'alpha_per_s', 'beta': no observer with poles in "
                                 f"[{settings.alpha_per_s:g}, "
                                 f"{settings.beta * settings.alpha_per_s:g}] 1/s ({exc})") from None
        # H B = 0 leaves no freedom: every pole sits at −K_p/C_p; a region around it
        corner = v.primary_stiffness_N_per_m / v.primary_damping_Ns_per_m
        self.hb0 = functional_observer.design(m.A, m.B, self.C, m.L,
                                              corner / np.sqrt(settings.beta), settings.beta,
                                              hb_zero=True)
        self.paper_zoh = self.paper.discretise(settings.dt_s, "zoh")
        self.paper_foh = self.paper.discretise(settings.dt_s, "foh")
        self.hb0_zoh = self.hb0.discretise(settings.dt_s, "zoh")
        n_steps = int(round(settings.duration_s / settings.dt_s)) + 1
        self.eps = {name: error_dynamics(d, n_steps, settings.initial_error_m)
                    for name, d in (("paper", self.paper_zoh), ("hb0", self.hb0_zoh))}
        self.spectrum = f"fra-{settings.track_class}"
        self.band = (settings.wavelength_min_m, settings.wavelength_max_m)
        self.lead = int(round(settings.lead_in_s / settings.dt_s))

    @cached_property
    def filters(self) -> dict:
        """The shaping filter of q (and the PSD it fits) at each speed, km/h."""
        return {s: shaping_filter(self.spectrum, s / 3.6, self.band)
                for s in self.settings.speeds_kmh}

    @cached_property
    def kalman_model(self) -> dict:
        """``(Φ, Q_d, C)`` of the Kalman baseline's augmented model at each speed, km/h."""
        m, out = self.model, {}
        for s, (filt, _, _) in self.filters.items():
            Aa, Ga, Ca = kb.augment(m.A, m.B, self.C, [filt] * 4)
            out[s] = kb.discretise_noise(Aa, Ga, np.eye(4), self.settings.dt_s) + (Ca,)
        return out


@lru_cache(maxsize=4)
def context(settings: Settings, reading: str) -> Context:
    """The :class:`Context` of ``reading`` under ``settings``, made once per process (a run and
    every chunk of its records share it)."""
    return Context(settings, reading)


def track_length_m(settings: Settings, ctx: Context) -> float:
    """Length of each seed's track profile: the fastest run, its lead-in and the bogies, m."""
    length_m = (max(settings.speeds_kmh) / 3.6 * (settings.duration_s + settings.lead_in_s + 0.1)
                + max(ctx.vehicle.axle_offsets_m) + 1.0)
    return max(length_m, settings.wavelength_max_m * 1.01)


def batch_seeds(seeds) -> list[int]:
    """The seeds to simulate for ``seeds``: a lone seed twice (see the module docstring)."""
    seeds = [int(s) for s in seeds]
    return seeds * 2 if len(seeds) == 1 else seeds


def simulate_foh_batch(Phi, Gamma0, Gamma1, u: np.ndarray, x0: np.ndarray) -> np.ndarray:
    """:func:`railpaper.discretise.simulate_foh` for many runs: u (..., K, m), x0 (..., n).

    The step loop runs on a time-major copy (each step reads one contiguous block).
    """
    lead, K = u.shape[:-2], u.shape[-2]
    u_t = np.moveaxis(u.reshape((-1,) + u.shape[-2:]), 1, 0)              # (K, B, m)
    drive = u_t[:-1] @ (Gamma0 - Gamma1).T + u_t[1:] @ Gamma1.T
    x = np.empty((K, drive.shape[1], Phi.shape[0]))
    x[0] = np.reshape(x0, (-1, Phi.shape[0]))
    PhiT = Phi.T
    for k in range(K - 1):
        np.matmul(x[k], PhiT, out=x[k + 1])
        x[k + 1] += drive[k]
    return np.ascontiguousarray(np.moveaxis(x, 0, 1)).reshape(lead + (K, Phi.shape[0]))


def simulate_truths(ctx: Context, settings: Settings, q_in: np.ndarray, t_s: np.ndarray, seeds,
                    speeds) -> dict:
    """Exact plant responses (track linear between samples) and noisy measurements of many runs.

    ``q_in[i, j]`` (K + lead, 4) is the track under the wheelsets for seed i at speed j; the noise
    of that run is drawn from ``default_rng([seed, 1000 V])``.  Arrays of the result have leading
    axes (seed, speed); ``sigma`` is each channel's noise σ (0.5 % of its RMS).
    """
    m, n_lead = ctx.model, ctx.lead
    x0 = -np.linalg.solve(m.A, m.B @ q_in[..., 0, :, None])[..., 0]   # static equilibrium
    x = np.ascontiguousarray(simulate_foh_batch(*ctx.plant, q_in, x0)[..., n_lead:, :])
    y_clean = x @ ctx.C.T
    sigma = settings.noise_fraction * np.sqrt(np.mean(y_clean**2, axis=-2))
    unit = np.stack([[np.random.default_rng([seed, int(round(v * 1000))]).standard_normal(
        y_clean.shape[-2:]) for v in speeds] for seed in seeds])
    return {"t_s": t_s, "q_m": q_in[..., n_lead:, :], "x": x, "z_m": x @ m.L.T,
            "y_clean": y_clean, "y": y_clean + unit * sigma[..., None, :], "unit_noise": unit,
            "sigma": sigma, "speeds": list(speeds)}


def record(tr: dict, i: int, j: int) -> dict:
    """One run (seed index i, speed index j) of :func:`simulate_truths` as the notebook uses it."""
    return {k: tr[k] if k == "t_s" else tr[k][i, j] for k in
            ("t_s", "q_m", "x", "z_m", "y_clean", "y", "sigma")} | {"speed_kmh": tr["speeds"][j]}


def run_kalman(ctx: Context, speed_kmh: float, tr: dict, j: int | None, e0: float,
               noisy: bool = True) -> np.ndarray:
    """Steady-state Kalman estimates of z_w (not told q), started with the same error e0; each
    run's filter is told that run's noise σ (R = diag σ², kept > 0 without noise).

    ``tr`` holds runs at leading axes (seed, speed) and ``j`` picks the speed (None: ``tr`` is
    one run); returns the estimates, seed axis first (or of the one run).
    """
    pick = (lambda a: a) if j is None else (lambda a: a[:, j])
    Phi, Qd, Ca = ctx.kalman_model[speed_kmh]
    y_clean, sigma, q, x = (pick(tr[k]) for k in ("y_clean", "sigma", "q_m", "x"))
    y = pick(tr["y"]) if noisy else y_clean
    lead = y.shape[:-2]
    rms = np.sqrt(np.mean(y_clean**2, axis=-2)).reshape(-1, y.shape[-1])
    filters = [kb.steady_state_kalman(Phi, Qd, Ca, np.diag(np.maximum(s, 1e-6 * r) ** 2))
               for s, r in zip(sigma.reshape(-1, y.shape[-1]), rms)]
    A_updT = np.stack([(np.eye(Phi.shape[0]) - f.K @ f.C).T for f in filters])
    drive = np.einsum("bkq,bnq->bkn", y.reshape((-1,) + y.shape[-2:]), np.stack([f.K for f in filters]))
    dq = (q[..., 1, :] - q[..., 0, :]) / tr["t_s"][1]
    prior = np.concatenate([x[..., 0, :], np.stack([q[..., 0, :], dq], axis=-1).reshape(
        lead + (8,))], axis=-1).reshape(len(filters), -1)
    prior[:, [12, 14, 16, 18]] += e0
    prior[:, 20::2] += e0
    out = np.empty(drive.shape[:2] + (4,))
    PhiT = Phi.T
    for k in range(drive.shape[1]):                 # x⁺ = (I − K C) x⁻ + K y;  x⁻ ← Φ x⁺
        post = (prior[:, None, :] @ A_updT)[:, 0] + drive[:, k]
        out[:, k] = post[:, [12, 14, 16, 18]]
        prior = post @ PhiT
    return out.reshape(lead + out.shape[1:])


def monte_carlo_runs(ctx: Context, settings: Settings, tr: dict, kalman: bool) -> dict:
    """Estimates of the runs of :func:`simulate_truths` (speeds ascending): the paper's observer
    with the paper's noise (``paper``), noise-free (``paper_noisefree``) and with speed-independent
    noise (``paper_fixednoise``: each channel's σ of the lowest speed, on the same draws); the
    H B = 0 variant, ẑ = q and (if ``kalman``) the Kalman baseline with the paper's noise."""
    sigma_fixed = tr["sigma"][:, :1, None, :]
    z0 = tr["z_m"][..., 0, :] + settings.initial_error_m
    ys = np.stack([tr["y"], tr["y_clean"], tr["y_clean"] + tr["unit_noise"] * sigma_fixed], axis=2)
    us = np.broadcast_to(tr["q_m"][:, :, None], ys.shape[:-1] + (4,))
    paper = ctx.paper_zoh.run(ys, us, z0[:, :, None, :])
    out = {"paper": paper[:, :, 0], "paper_noisefree": paper[:, :, 1],
           "paper_fixednoise": paper[:, :, 2], "hb0": ctx.hb0_zoh.run(tr["y"], None, z0),
           "q": tr["q_m"]}
    if kalman:
        out["kalman"] = np.stack([run_kalman(ctx, v, tr, j, settings.initial_error_m)
                                  for j, v in enumerate(tr["speeds"])], axis=1)
    return out


def track_inputs(ctx: Context, settings: Settings, seeds, speeds, length_m: float | None = None):
    """Times, track under the wheelsets (seed, speed, K + lead, 4) and each seed's
    speed-independent convergence threshold (5 % of its whole profile's RMS), m; the profiles
    are :func:`track_length_m` long unless ``length_m`` is given."""
    length_m = track_length_m(settings, ctx) if length_m is None else length_m
    q_in, fixed = [], []
    for seed in seeds:
        distance, profile = track.synthesize_profile(
            ctx.spectrum, "vertical", length_m, PROFILE_DX_M, seed,
            wavelength_min_m=settings.wavelength_min_m, wavelength_max_m=settings.wavelength_max_m)
        fixed.append(settings.convergence_fraction * float(np.sqrt(np.mean(profile**2))))
        runs = [track.wheelset_inputs(distance, profile, v / 3.6, ctx.vehicle.axle_offsets_m,
                                      settings.dt_s, settings.duration_s + ctx.lead * settings.dt_s)
                for v in speeds]
        q_in.append([q for _, q in runs])
    t = runs[0][0]
    return t[ctx.lead:] - t[ctx.lead], np.array(q_in), np.array(fixed)


def simulated(settings: Settings, reading: str, seeds) -> tuple[dict, np.ndarray]:
    """Runs of ``seeds`` (as given: see :func:`batch_seeds`) at every speed, ascending, under
    ``reading``, and each seed's speed-independent convergence threshold, m."""
    ctx = context(settings, reading)
    speeds = sorted(settings.speeds_kmh)
    t_s, q_in, fixed = track_inputs(ctx, settings, seeds, speeds)
    return simulate_truths(ctx, settings, q_in, t_s, seeds, speeds), fixed


def measure_columns(ctx: Context, settings: Settings, tr: dict, estimates: dict, fixed,
                    n_seeds: int) -> dict:
    """Columns of the first ``n_seeds`` runs' numbers, each estimator at each speed: the
    measures of :func:`run_measures` and, where the estimator's error dynamics are
    known, ``predicted_convergence_s``."""
    columns = {}
    for name, zh in estimates.items():
        meas = run_measures(tr["t_s"], tr["z_m"], zh, fixed[:, None],
                                     settings.convergence_fraction, settings.error_window_start_s)
        for j, speed in enumerate(tr["speeds"]):
            for key in MEASURES:
                columns[record_column(key, speed, name, ctx.reading)] = \
                    meas[key][:n_seeds, j]
            if name in ctx.eps:
                predicted = [predicted_convergence_s(ctx.eps[name], tr["t_s"], tr["z_m"][i, j],
                                                     settings) for i in range(n_seeds)]
                columns[record_column("predicted_convergence_s", speed, name,
                                               ctx.reading)] = np.array(predicted, dtype=float)
    return columns


def monte_carlo_rows(settings: Settings, seeds: tuple[int, ...]) -> pd.DataFrame:
    """The :data:`MONTE_CARLO` rows of ``seeds``: one per seed, in order; columns ``seed`` and
    :func:`record_column` of each reading, estimator
    (:data:`MONTE_CARLO_ESTIMATORS`), speed and measure."""
    with one_thread():
        runs = batch_seeds(seeds)
        columns = {"seed": np.array(seeds, dtype=np.int64)}
        for reading in READINGS:
            ctx = context(settings, reading)
            tr, fixed = simulated(settings, reading, runs)
            est = monte_carlo_runs(ctx, settings, tr, kalman=False)
            columns.update(measure_columns(ctx, settings, tr, est, fixed, len(seeds)))
        return pd.DataFrame(columns)


def kalman_baseline_rows(settings: Settings, seeds: tuple[int, ...], *, reading: str
                         ) -> pd.DataFrame:
    """The Kalman baseline's rows of ``seeds`` under ``reading`` (:data:`KALMAN_BASELINE`): one
    per seed, in order; columns ``seed`` and :func:`record_column` of each speed and
    measure, estimator ``kalman``."""
    with one_thread():
        runs = batch_seeds(seeds)
        ctx = context(settings, reading)
        tr, fixed = simulated(settings, reading, runs)
        est = {"kalman": np.stack([run_kalman(ctx, v, tr, j, settings.initial_error_m)
                                   for j, v in enumerate(tr["speeds"])], axis=1)}
        return pd.DataFrame({"seed": np.array(seeds, dtype=np.int64)}
                            | measure_columns(ctx, settings, tr, est, fixed, len(seeds)))


#: Every speed and reading of a seed, every estimator but the Kalman baseline.
MONTE_CARLO = RecordStudy(SPEC.name, "monte_carlo", monte_carlo_rows, chunk_records=SEED_GROUP)
#: The Kalman baseline on the runs of each reading (a run uses its selected reading's).
KALMAN_BASELINE = {reading: RecordStudy(SPEC.name, f"kalman_baseline_{reading}",
                                        partial(kalman_baseline_rows, reading=reading),
                                        chunk_records=SEED_GROUP)
                   for reading in READINGS}
