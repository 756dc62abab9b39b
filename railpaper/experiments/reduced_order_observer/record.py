"""One record of chapter ``reduced-order-observer``: the simulated truth, the measurements, and
the paper's observer on them (typed results, SI units).

:func:`simulate_record` simulates the single-wheelset plant on a track profile at one speed and
adds the sensor noise; :func:`run_observer` runs one discrete reduced-order observer on it and
turns ẑ_w into the wheel–rail force (Eq. 4); :func:`simulate_speed` does both for the two
discretisations of the observer.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from railpaper import track
from railpaper.discretise import foh, simulate_foh
from railpaper.experiments.reduced_order_observer import evidence
from railpaper.models import single_wheelset as sw
from railpaper.settling import settling_time_s


def _simulate_hertz(vehicle, t_s, q_m, x0, substeps=4):
    """RK4 with ``substeps`` per sample and q interpolated linearly (nonlinear Hertz plant)."""
    dt = (t_s[1] - t_s[0]) / substeps
    x = np.empty((len(t_s), 4))
    x[0] = x0
    state = np.array(x0, float)
    f = lambda s, q: sw.nonlinear_derivative(vehicle, s, q)  # noqa: E731
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


@dataclass(frozen=True)
class Record:
    """One simulated record at one speed: the truth and what the observer is given (SI units).

    Attributes
    ----------
    speed_kmh : float
        Vehicle speed, km/h.
    t_s : ndarray, shape (K,)
        Sample times, s (step ``dt_s``).
    q_m : ndarray, shape (K,)
        True vertical irregularity under the wheelset, m.
    x_true : ndarray, shape (K, 4)
        True state ``[ż_c, z_c, ż_w, z_w]`` (m/s, m, m/s, m).
    y_measured : ndarray, shape (K, 2)
        Measured ``[ż_c, z_c]`` (m/s, m): truth plus sensor noise.
    q_measured_m : ndarray, shape (K,)
        Irregularity given to the estimators, m (plus ``track_noise_fraction`` noise).
    x2_initial : ndarray, shape (2,)
        The observer's initial ``[ż_w, z_w]`` (m/s, m): truth plus ``initial_error_m`` on z_w.
    force_true_N : ndarray, shape (K,)
        Dynamic wheel–rail force of the plant (total minus static load), N.
    """

    speed_kmh: float
    t_s: np.ndarray
    q_m: np.ndarray
    x_true: np.ndarray
    y_measured: np.ndarray
    q_measured_m: np.ndarray
    x2_initial: np.ndarray
    force_true_N: np.ndarray


def simulate_record(vehicle, params, distance_m, profile_m, speed_kmh, salt=()) -> Record:
    """Simulate the plant on the profile at one speed and add the sensor noise.

    The plant starts at static equilibrium on q(0); ``plant="linear"`` is exact for q linear
    between samples, ``"hertz"`` is the nonlinear contact (RK4).  The sensor noise draws are
    :func:`evidence.noise_draws` of ``(seed, speed, *salt)``, scaled to ``noise_fraction`` of each
    measured channel's RMS (``track_noise_fraction`` of the RMS of q for the irregularity).
    """
    dt, duration = params["dt_s"], params["duration_s"]
    t_s, q = track.wheelset_inputs(distance_m, profile_m, speed_kmh / 3.6, [0.0], dt, duration)
    q = q[:, 0]
    noise_y, noise_q = evidence.noise_draws(params["seed"], speed_kmh, len(t_s), salt)
    A, B = sw.state_space(vehicle)
    x0 = np.array([0.0, q[0], 0.0, q[0]])                 # static equilibrium on q(0)
    if params["plant"] == "linear":
        x = simulate_foh(*foh(A, B, dt), q[:, None], x0)   # exact for q linear between samples
    else:
        x = _simulate_hertz(vehicle, t_s, q, x0)
    y = x[:, :2].copy()                                    # measured x1 = [ż_c, z_c]
    y += noise_y * params["noise_fraction"] * np.sqrt(np.mean(y**2, axis=0))
    q_meas = q + noise_q * params["track_noise_fraction"] * np.sqrt(np.mean(q**2))
    return Record(speed_kmh=float(speed_kmh), t_s=t_s, q_m=q, x_true=x, y_measured=y,
                  q_measured_m=q_meas,
                  x2_initial=x[0, 2:] + np.array([0.0, params["initial_error_m"]]),
                  force_true_N=sw.dynamic_contact_force_N(vehicle, x[:, 3], q, params["plant"]))


@dataclass(frozen=True)
class ObserverRun:
    """One discrete reduced-order observer on one :class:`Record`.

    Attributes
    ----------
    z_w_est_m : ndarray, shape (K,)
        Estimated wheelset displacement, m.
    force_est_N : ndarray, shape (K,)
        Estimated dynamic wheel–rail force ``K_r (ẑ_w − q_measured)``, N.
    convergence_time_s : float
        First time after which ``|ẑ_w − z_w|`` stays below the threshold, s (-1: never).
    force_rms_error_N : float
        RMS of ``f̂ − f`` from ``error_window_start_s`` on, N.
    displacement_rms_error_m : float
        RMS of ``ẑ_w − z_w`` over the same window, m.
    """

    z_w_est_m: np.ndarray
    force_est_N: np.ndarray
    convergence_time_s: float
    force_rms_error_N: float
    displacement_rms_error_m: float


@dataclass(frozen=True)
class SpeedRun:
    """A record at one speed with both discretisations of the paper's observer on it.

    Attributes
    ----------
    record : Record
        Truth and measurements.
    z_w_rms_m, force_rms_N : float
        RMS of the true z_w over the run (m) and of the true force over the error window (N).
    predicted_convergence_time_s : float
        Convergence time of the error equation alone, ``e[k+1] = Φ e[k]``, s (-1: never).
    contact_lost_fraction : float
        Fraction of samples where the true force would lift the wheels (total load ≤ 0).
    paper, foh : ObserverRun
        The observer discretised with y and q held over a step (the paper's) or linear between
        samples.
    """

    record: Record
    z_w_rms_m: float
    force_rms_N: float
    predicted_convergence_time_s: float
    contact_lost_fraction: float
    paper: ObserverRun
    foh: ObserverRun

    def observer(self, form: str) -> ObserverRun:
        """The run of the observer discretised as ``form`` (``"paper"`` or ``"foh"``)."""
        return {"paper": self.paper, "foh": self.foh}[form]


def run_observer(observer, vehicle, record: Record, threshold_m: float,
                 window: np.ndarray) -> ObserverRun:
    """Run one discrete observer on a record; force from the linearised contact (Eq. 4)."""
    z_w_est = observer.run(record.y_measured, record.q_measured_m[:, None], record.x2_initial)[:, 1]
    force_est = sw.dynamic_contact_force_N(vehicle, z_w_est, record.q_measured_m, "linear")
    error = z_w_est - record.x_true[:, 3]
    return ObserverRun(
        z_w_est_m=z_w_est, force_est_N=force_est,
        convergence_time_s=settling_time_s(record.t_s, np.abs(error) < threshold_m),
        force_rms_error_N=float(np.sqrt(np.mean((force_est - record.force_true_N)[window] ** 2))),
        displacement_rms_error_m=float(np.sqrt(np.mean(error[window] ** 2))))


def simulate_speed(vehicle, observers, params, distance_m, profile_m, speed_kmh, salt=()) -> SpeedRun:
    """One run at one speed: :func:`simulate_record`, then both observers on it (SI units)."""
    record = simulate_record(vehicle, params, distance_m, profile_m, speed_kmh, salt)
    t_s, z_w = record.t_s, record.x_true[:, 3]
    threshold = params["convergence_fraction"] * np.sqrt(np.mean(z_w ** 2))
    window = t_s >= params["error_window_start_s"]
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
