"""One record of chapter ``reduced-order-observer``: the simulated truth, the measurements, and
the paper's observer on them (typed results, SI units).

:func:`simulate_record` simulates the single-wheelset plant on a track profile at one speed and
adds the sensor noise; :func:`run_observer` runs one discrete reduced-order observer on it and
turns ẑ_w into the wheel–rail force (Eq. 4); :func:`simulate_speed` does both for the two
discretisations of the observer.
"""

from __future__ import annotations

import numba
import numpy as np

from railpaper import contact, track
from railpaper.discretise import foh, simulate_foh
from railpaper.experiments.reduced_order_observer.result import (
    ObserverRun,
    Record,
    SpeedRun,
)
from railpaper.experiments.reduced_order_observer.spec import FRA_BAND_M, Settings
from railpaper.models import single_wheelset
from railpaper.settling import settling_time_s


def _simulate_hertz(vehicle, t_s, q_m, x0, substeps=4):
    """RK4 with ``substeps`` per sample and q interpolated linearly (nonlinear Hertz plant)."""
    dt = (t_s[1] - t_s[0]) / substeps
    x = np.empty((len(t_s), 4))
    x[0] = x0
    state = np.array(x0, float)
    f = lambda s, q: single_wheelset.nonlinear_derivative(vehicle, s, q)  # noqa: E731
    for k in range(len(t_s) - 1):
        q0, q1 = q_m[k], q_m[k + 1]
        for j in range(substeps):
            qa, qm, qb = (q0 + (q1 - q0) * (j + c) / substeps for c in (0.0, 0.5, 1.0))
            k1 = f(state, qa)
            k2 = f(state + 0.5 * dt * k1, qm)
            k3 = f(state + 0.5 * dt * k2, qm)
            k4 = f(state + dt * k3, qb)
            state = state + dt / 6.0 * (k1 + 2 * k2 + 2 * k3 + k4)
        x[k + 1] = state
    return x


def simulate_record(vehicle, settings: Settings, distance_m, profile_m, speed_kmh,
                    salt=()) -> Record:
    """Simulate the plant on the profile at one speed and add the sensor noise.

    The plant starts at static equilibrium on q(0); ``plant="linear"`` is exact for q linear
    between samples, ``"hertz"`` is the nonlinear contact (RK4).  The sensor noise draws are
    :func:`noise_draws` of ``(seed, speed, *salt)``, scaled to ``noise_fraction`` of each
    measured channel's RMS (``track_noise_fraction`` of the RMS of q for the irregularity).
    """
    dt, duration = settings.dt_s, settings.duration_s
    t_s, q = track.wheelset_inputs(distance_m, profile_m, speed_kmh / 3.6, [0.0], dt, duration)
    q = q[:, 0]
    noise_y, noise_q = noise_draws(settings.seed, speed_kmh, len(t_s), salt)
    A, B = single_wheelset.state_space(vehicle)
    x0 = np.array([0.0, q[0], 0.0, q[0]])                 # static equilibrium on q(0)
    if settings.plant == "linear":
        x = simulate_foh(*foh(A, B, dt), q[:, None], x0)   # exact for q linear between samples
    else:
        x = _simulate_hertz(vehicle, t_s, q, x0)
    y = x[:, :2].copy()                                    # measured x1 = [ż_c, z_c]
    y += noise_y * settings.noise_fraction * np.sqrt(np.mean(y**2, axis=0))
    q_meas = q + noise_q * settings.track_noise_fraction * np.sqrt(np.mean(q**2))
    return Record(speed_kmh=float(speed_kmh), t_s=t_s, q_m=q, x_true=x, y_measured=y,
                  q_measured_m=q_meas,
                  x2_initial=x[0, 2:] + np.array([0.0, settings.initial_error_m]),
                  force_true_N=single_wheelset.dynamic_contact_force_N(vehicle, x[:, 3], q,
                                                                       settings.plant))


def run_observer(observer, vehicle, record: Record, threshold_m: float,
                 window: np.ndarray) -> ObserverRun:
    """Run one discrete observer on a record; force from the linearised contact (Eq. 4)."""
    z_w_est = observer.run(record.y_measured, record.q_measured_m[:, None], record.x2_initial)[:, 1]
    force_est = single_wheelset.dynamic_contact_force_N(vehicle, z_w_est, record.q_measured_m,
                                                        "linear")
    error = z_w_est - record.x_true[:, 3]
    return ObserverRun(
        z_w_est_m=z_w_est, force_est_N=force_est,
        convergence_time_s=settling_time_s(record.t_s, np.abs(error) < threshold_m),
        force_rms_error_N=float(np.sqrt(np.mean((force_est - record.force_true_N)[window] ** 2))),
        displacement_rms_error_m=float(np.sqrt(np.mean(error[window] ** 2))))


def simulate_speed(vehicle, observers, settings: Settings, distance_m, profile_m, speed_kmh,
                   salt=()) -> SpeedRun:
    """One run at one speed: :func:`simulate_record`, then both observers on it (SI units)."""
    record = simulate_record(vehicle, settings, distance_m, profile_m, speed_kmh, salt)
    t_s, z_w = record.t_s, record.x_true[:, 3]
    threshold = settings.convergence_fraction * np.sqrt(np.mean(z_w ** 2))
    window = t_s >= settings.error_window_start_s
    error_free = np.empty((len(t_s), 2))                   # error dynamics alone: e[k+1] = Φ e[k]
    error_free[0] = record.x2_initial - record.x_true[0, 2:]
    for k in range(len(t_s) - 1):
        error_free[k + 1] = observers["paper"].Phi @ error_free[k]
    force = record.force_true_N
    return SpeedRun(
        record=record, z_w_rms_m=float(np.sqrt(np.mean(z_w ** 2))),
        force_rms_N=float(np.sqrt(np.mean(force[window] ** 2))),
        predicted_convergence_time_s=settling_time_s(t_s, np.abs(error_free[:, 1]) < threshold),
        contact_lost_fraction=float(np.mean(force <= -vehicle.contacts * vehicle.static_wheel_load_N)),
        **{form: run_observer(obs, vehicle, record, threshold, window)
           for form, obs in observers.items()})


def all_speeds(settings: Settings) -> list[float]:
    """Speeds of the main runs then of the sweep, without repeats, km/h (the run's order)."""
    return list(dict.fromkeys(settings.speeds_kmh + settings.sweep_speeds_kmh))


def profile(settings: Settings, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """Track profile (distance_m, irregularity_m) of one seed, long enough for every speed."""
    length_m = max(max(all_speeds(settings)) / 3.6 * settings.duration_s + 10.0, 2 * FRA_BAND_M[1])
    return track.synthesize_profile(
        f"fra-{settings.track_class}", "vertical", length_m, 0.05, seed,
        wavelength_min_m=FRA_BAND_M[0], wavelength_max_m=FRA_BAND_M[1])


def noise_draws(seed: int, speed_kmh: float, n_samples: int, salt: tuple = ()):
    """Standard-normal sensor draws (K, 2) on [ż_c, z_c] and (K,) on q of one run."""
    rng = np.random.default_rng([seed, int(round(speed_kmh * 1000)), *salt])
    return rng.standard_normal((n_samples, 2)), rng.standard_normal(n_samples)


#: Fewest columns of a batch: a batch of one column is padded with a copy of it, because numpy
#: computes it differently (a mean over one contiguous column sums pairwise, a matrix times one
#: column is a BLAS gemv, not a gemm) and its numbers would differ in the last bits from the
#: same column's in a wider batch.
MIN_BATCH_COLUMNS = 2


def padded(columns: np.ndarray) -> np.ndarray:
    """``columns`` (K, N, …) with copies of its last column appended up to
    :data:`MIN_BATCH_COLUMNS` columns (the batches of one seed at one speed)."""
    missing = MIN_BATCH_COLUMNS - columns.shape[1]
    if missing <= 0:
        return columns
    return np.concatenate([columns] + [columns[:, -1:]] * missing, axis=1)


def _plant_batch(vehicle, plant, dt_s, q):
    """Plant response to q (K, N) from rest on q[0]: y = [ż_c, z_c] (K, N, 2) and z_w (K, N).

    ``plant="linear"``: exact for q linear between samples (FOH); ``"hertz"``: RK4 with four
    substeps per sample and q linear between samples, as the chapter's single runs (compiled:
    :func:`_hertz_kernel`).
    """
    x = np.zeros((4, q.shape[1]))
    x[1] = x[3] = q[0]
    out = np.empty((len(q), q.shape[1], 3))
    out[0] = x[[0, 1, 3]].T
    if plant == "linear":
        Phi, G0, G1 = foh(*single_wheelset.state_space(vehicle), dt_s)
        ga, gb = (G0 - G1)[:, :1], G1[:, :1]
        for k in range(len(q) - 1):
            x = Phi @ x + ga * q[k] + gb * q[k + 1]
            out[k + 1] = x[[0, 1, 3]].T
        return out[..., :2], out[..., 2]
    G, P0 = vehicle.hertz_constant_m_per_N23, vehicle.static_wheel_load_N
    _hertz_kernel(np.ascontiguousarray(q, dtype=float), dt_s / 4, 4, np.array([
        vehicle.car_body_mass_kg, vehicle.wheelset_mass_kg, vehicle.suspension_damping_Ns_per_m,
        vehicle.suspension_stiffness_N_per_m, G, P0, float(vehicle.contacts),
        contact.static_compression(P0, G)]), out)
    return out[..., :2], out[..., 2]


@numba.njit(cache=True)
def _hertz_derivative(x, q, c):
    """:func:`railpaper.models.single_wheelset.nonlinear_derivative`, compiled; ``c`` = M_c, M_w,
    C_p, K_p, G, P0, contacts, δ0."""
    suspension = c[3] * (x[1] - x[3]) + c[2] * (x[0] - x[2])
    delta = c[7] + x[3] - q
    force = (max(delta, 0.0) / c[4]) ** 1.5 if delta > 0.0 else 0.0
    dynamic_contact = c[6] * (force - c[5])
    return np.array([-suspension / c[0], x[0], (suspension - dynamic_contact) / c[1], x[2]])


@numba.njit(cache=True)
def _hertz_kernel(q, h, substeps, c, out):
    """RK4 of the Hertz plant from rest on q[0], ``substeps`` steps of h per sample, q linear
    between samples (the operations of :func:`railpaper.experiments.reduced_order_observer.record.
    _simulate_hertz`, per column of q); fills out[k, n] = [ż_c, z_c, z_w]."""
    K, N = q.shape
    for n in range(N):
        x = np.array([0.0, q[0, n], 0.0, q[0, n]])
        out[0, n, 0], out[0, n, 1], out[0, n, 2] = x[0], x[1], x[3]
        for k in range(K - 1):
            for j in range(substeps):
                dq = q[k + 1, n] - q[k, n]
                qa = q[k, n] + dq * (j + 0.0) / substeps
                qm = q[k, n] + dq * (j + 0.5) / substeps
                qb = q[k, n] + dq * (j + 1.0) / substeps
                k1 = _hertz_derivative(x, qa, c)
                k2 = _hertz_derivative(x + 0.5 * h * k1, qm, c)
                k3 = _hertz_derivative(x + 0.5 * h * k2, qm, c)
                k4 = _hertz_derivative(x + h * k3, qb, c)
                x = x + h / 6.0 * (k1 + 2 * k2 + 2 * k3 + k4)
            out[k + 1, n, 0], out[k + 1, n, 1], out[k + 1, n, 2] = x[0], x[1], x[3]


def _observer_batch(observer, y, q, x2_initial):
    """Estimated z_w (K, N) of a discrete reduced-order observer on y (K, N, 2), q (K, N)."""
    v = np.concatenate([y, q[..., None]], axis=2)
    drive = v[:-1] @ observer.Gamma_now.T + v[1:] @ observer.Gamma_next.T
    w = x2_initial - y[0] @ observer.L.T
    z = np.empty(q.shape)
    PhiT, L = observer.Phi.T, observer.L
    z[0] = w[:, 1]
    for k in range(len(q) - 1):
        w = w @ PhiT + drive[k]
        z[k + 1] = w[:, 1]
    return z + y @ L[1]
