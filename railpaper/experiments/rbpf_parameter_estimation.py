"""Chapter "rbpf-parameter-estimation": Ding et al. (2014)'s RBPF versus an augmented-state EKF.

Part 1 — Eq. (18) toy (:mod:`railpaper.experiments.rbpf_parameter_estimation_toy`): the RBPF
exactly as the paper's Steps 1–2.6, our working scheme, and an augmented-state EKF from the
paper's two initial conditions, on ``toy_seeds`` records (seeds ``seed``, ``seed + 1``, …).

Part 2 — the lateral vehicle (Eqs. 1–9, :mod:`railpaper.models.lateral_16state`): ``n_records``
records (seeds ``seed``, ``seed + 1``, …), each simulated at ``dt_s / truth_substeps`` from an
alignment profile of ``spectrum`` and sampled at ``dt_s`` with stated sensor noise; on each, the
RBPF over θ = (Csy, λ, Kpy, Ksy, Csaly) with the paper's literal scheme and with our working
scheme (tempering, ESS-triggered resampling, Liu–West move only after resampling, on normalised
log-parameters: our modification, not the paper's method), and the augmented 21-state EKF from
one initial guess (``ekf_guesses`` on the first record, as the paper's 10); the Kalman-likelihood
CRLB on the first record.  The Monte Carlo evidence of the claims (rates, medians, biases with
95 % intervals) is computed by :mod:`railpaper.experiments.rbpf_parameter_estimation_mc`.
``measurements_csv`` runs both RBPF schemes on a user's file (no evidence: it needs the truth).
``lateral=False`` skips Part 2 (sweep samples of the toy alone).

:func:`run` returns a :class:`~railpaper.experiments.rbpf_parameter_estimation_result.
RbpfParameterEstimationResult`: the metrics, timings and time series the pipeline writes, and
the two parts' named results (``result.toy``, ``result.lateral``).  One record by hand:
:func:`simulate_lateral`, :func:`filter_system`, :func:`lateral_rbpf`, :func:`lateral_ekf`
(the toy's: :mod:`~railpaper.experiments.rbpf_parameter_estimation_toy`).
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np
import pandas as pd

from railpaper import track
from railpaper.data import DATA_DIR, load_quantities
from railpaper.discretise import zoh
from railpaper.estimators.crlb import crlb_std, fisher_information
from railpaper.estimators.ekf import run_augmented_ekf
from railpaper.estimators.rbpf import FilterRun, run_rbpf
from railpaper.experiments import rbpf_parameter_estimation_mc as mc
from railpaper.experiments import rbpf_parameter_estimation_posterior as posterior
from railpaper.experiments.base import ParameterError, check_sample_time, no_progress
from railpaper.experiments.base import check_banks
from railpaper.experiments.rbpf_parameter_estimation_io import one_thread, read_measurements
from railpaper.experiments.rbpf_parameter_estimation_spec import SPEC
from railpaper.experiments.rbpf_parameter_estimation_result import (
    LateralPart, LateralRecord, LateralRun, RbpfParameterEstimationResult)
from railpaper.experiments.rbpf_parameter_estimation_toy import run_toy
from railpaper.models import lateral_16state as L
from railpaper.settling import settled_index

WITHIN = 0.05


def vehicle(params_path: Path | None = None) -> tuple[dict, np.ndarray]:
    """Fixed quantities and true θ from ``data/rbpf-parameter-estimation/parameters.toml``."""
    q = load_quantities(params_path or DATA_DIR / SPEC.name / "parameters.toml",
                        L.FIXED_KEYS + L.PARAM_NAMES)
    return {k: q[k].value for k in L.FIXED_KEYS}, np.array([q[k].value for k in L.PARAM_NAMES])


def steps_to_within(norm: np.ndarray, tol: float = WITHIN) -> np.ndarray:
    """Per column: first step (1-based) after which |norm − 1| <= tol to the end; -1 if never."""
    ok = np.abs(np.atleast_2d(norm.T).T - 1.0) <= tol
    index = np.array([settled_index(column) for column in ok.T])
    return np.where(index < 0, -1, index + 1)


# ----------------------------------------------------------------------------- Part 2: lateral
def noise_std(p: dict) -> np.ndarray:
    """Sensor noise std of the five channels (:data:`L.CHANNELS`): m/s², m/s², m/s², m/s², rad/s."""
    return np.array([p["noise_acc_wheelset_mps2"]] * 2 + [p["noise_acc_bogie_mps2"],
                    p["noise_acc_body_mps2"], p["noise_yawrate_radps"]])


def simulate_lateral(p: dict, fixed: dict, theta: np.ndarray, seed: int) -> LateralRecord:
    """One record: an alignment profile of ``spectrum`` (seed ``seed``), the vehicle simulated
    exactly at ``dt_s / truth_substeps``, the five channels sampled at ``dt_s`` with white sensor
    noise (generator ``[seed, 7]``), and the filters' input u_k = ẏ_t(t_{k−1}) held over a step."""
    v = p["speed_kmh"] / 3.6
    dtf = p["dt_s"] / p["truth_substeps"]
    dur = p["n_steps"] * p["dt_s"]
    length = max(v * dur + 2 * fixed["a"] + 10.0, 1.05 * p["wavelength_max_m"])
    dx = min(0.05, p["wavelength_min_m"] / 2)
    s, z = track.synthesize_profile(p["spectrum"], "alignment", length, dx, seed=seed,
                                    wavelength_min_m=p["wavelength_min_m"],
                                    wavelength_max_m=p["wavelength_max_m"])
    _, _, dq = track.wheelset_inputs(s, z, v, [0.0, 2 * fixed["a"]], dtf, dur, derivative=True)
    x = L.simulate_truth(fixed, theta, v, dtf, dq[:-1])
    sub = p["truth_substeps"]
    H = L.measurement_matrix(L.build_A_direct(fixed, theta, v))
    rng = np.random.default_rng([seed, 7])
    y = x[sub::sub][:p["n_steps"]] @ H.T
    y = y + rng.standard_normal(y.shape) * noise_std(p)
    u = dq[0:-1:sub][:p["n_steps"]]                       # u_k = ẏt(t_{k-1}), held over the step
    du = np.diff(dq[::sub], axis=0)
    return LateralRecord(seed=seed, y=y, u_mps=u, du_var_m2ps2=du.var(axis=0),
                         u_var_m2ps2=dq.var(axis=0))


def lateral_record(p: dict, fixed: dict, theta: np.ndarray, seed: int) -> LateralRecord:
    """The record of seed ``seed``: the user's file when ``measurements_csv`` is set (every
    seed), else :func:`simulate_lateral`."""
    if p["measurements_csv"]:
        return read_measurements(p["measurements_csv"], p)
    return simulate_lateral(p, fixed, theta, seed)


def filter_noise(fixed, theta, p, input_var) -> tuple[np.ndarray, np.ndarray]:
    """Q = Γ diag(input_var) Γᵀ (+1e-14 I) at the nominal θ, R = diag(noise²)."""
    _, G = zoh(L.build_A_direct(fixed, theta, p["speed_kmh"] / 3.6), L.input_matrix(), p["dt_s"])
    Q = G @ np.diag(input_var) @ G.T + 1e-14 * np.eye(L.N_STATES)
    return Q, np.diag(noise_std(p) ** 2)


def filter_system(p: dict, fixed: dict, theta: np.ndarray, record: LateralRecord):
    """``system(theta)``: the ZOH model E(θ), F(θ), H(θ) at ``dt_s`` for a batch of particles,
    with the process noise of the record's input changes and the sensor noise (:func:`filter_noise`);
    the ZOH's balancing is that of the prior box's centre (it changes only the rounding)."""
    Q, R = filter_noise(fixed, theta, p, record.du_var_m2ps2)
    centre = theta * 0.5 * (p["prior_low"] + p["prior_high"])       # balancing only
    return L.lateral_system(fixed, p["speed_kmh"] / 3.6, p["dt_s"], Q, R, theta_ref=centre)


def lateral_rbpf(p: dict, system, record: LateralRecord, theta: np.ndarray, seed: int,
                 scheme: str) -> FilterRun:
    """One RBPF run on a record: ``n_particles`` particles θ × U(``prior_low``, ``prior_high``)
    per parameter (generator ``[seed, 11]``: both schemes start from the same particles), each
    with a Kalman filter from X = 0; ``scheme="paper"`` (Steps 1–2.6, δ = ``paper_delta``) or
    ``"working"`` (tempering, ESS-triggered resampling, moves of log-parameters)."""
    rng = np.random.default_rng([seed, 11])
    theta0 = theta * rng.uniform(p["prior_low"], p["prior_high"], (p["n_particles"], 5))
    opts = (dict(scheme="paper", delta=p["paper_delta"]) if scheme == "paper" else
            dict(scheme="working", delta=p["working_delta"], ess_fraction=p["ess_fraction"],
                 tempering_steps=p["tempering_steps"], log_mask=np.ones(5, bool)))
    return run_rbpf(system, record.y, theta0, np.zeros(L.N_STATES),
                    1e-10 * np.eye(L.N_STATES), rng, u=record.u_mps, **opts)


def run_lateral_rbpf(p, fixed, theta, record: LateralRecord, seed: int, scheme: str
                     ) -> np.ndarray:
    """Normalised estimates θ̂/θ (K, 5) of one RBPF run (:func:`lateral_rbpf`)."""
    system = filter_system(p, fixed, theta, record)
    return lateral_rbpf(p, system, record, theta, seed, scheme).theta_mean / theta


def lateral_crlb(p, fixed, theta, record: LateralRecord) -> dict:
    """Relative CRLB after 350 and n_steps steps, input known / unknown (process noise)."""
    v = p["speed_kmh"] / 3.6
    out = {}
    for label, var, u in (("known", record.du_var_m2ps2, record.u_mps),
                          ("unknown", record.u_var_m2ps2, None)):
        Q, R = filter_noise(fixed, theta, p, var)
        info = fisher_information(L.lateral_system(fixed, v, p["dt_s"], Q, R, theta_ref=theta),
                                  theta, record.y,
                                  np.zeros(L.N_STATES), 1e-10 * np.eye(L.N_STATES), u,
                                  checkpoints=(350, p["n_steps"]))
        for c, I in info.items():
            out[(label, c)] = crlb_std(I) / theta
    return out


def lateral_ekf(p, fixed, theta, record: LateralRecord, seed, guesses: int) -> list[np.ndarray]:
    """Normalised EKF estimates (K, 5) from ``guesses`` guesses U(prior box) x θ (generator
    ``[seed, 13]``; NaN rows if the run diverged); K = min(ekf_steps, n_steps).  Empty on
    a user's record (``record.seed`` None): the chapter judges the EKF on simulated records only."""
    if record.seed is None:
        return []
    Q, R = filter_noise(fixed, theta, p, record.du_var_m2ps2)
    model = L.ekf_model(fixed, p["speed_kmh"] / 3.6, p["dt_s"])
    rng = np.random.default_rng([seed, 13])
    runs = []
    for _ in range(guesses):
        guess = theta * rng.uniform(p["prior_low"], p["prior_high"], 5)
        K = min(p["ekf_steps"], p["n_steps"])
        r = run_augmented_ekf(model, record.y[:K], guess, np.zeros(L.N_STATES),
                              1e-10 * np.eye(L.N_STATES), (0.3 * theta) ** 2, Q, R,
                              (1e-4 * theta) ** 2, u=record.u_mps[:K], divergence_bound=1e12)
        runs.append(r.theta / theta if not r.diverged else np.full_like(r.theta, np.nan))
    return runs


def ekf_converged(norm: np.ndarray) -> bool:
    """A lateral EKF run is convergent and meaningful: every final estimate within 5 %."""
    return bool(np.all(np.isfinite(norm[-1])) and np.all(np.abs(norm[-1] - 1) <= WITHIN))


def validate(p: dict) -> None:
    """Refuse non-physical or inconsistent resolved parameters with one line, before any work."""
    if not p["prior_low"] < 1.0 < p["prior_high"]:
        raise ParameterError("prior_low < 1 < prior_high is needed (the box must hold the truth)")
    if not 1 / 3 < p["paper_delta"] <= 1 or not 1 / 3 < p["working_delta"] <= 1:
        raise ParameterError("Liu-West delta must be in (1/3, 1]")
    if p["wavelength_min_m"] < 2 * p["speed_kmh"] / 3.6 * p["dt_s"]:
        raise ParameterError("wavelength_min_m is shorter than the filter's Nyquist wavelength "
                             "2 V dt_s")
    if p["spectrum"] not in track.SPECTRA:
        raise ParameterError(f"parameter 'spectrum': unknown spectrum {p['spectrum']!r}; "
                             f"one of {', '.join(track.SPECTRA)}")
    for name in ("toy_seeds", "n_records"):
        if p[name] >= 1000:
            raise ParameterError(f"parameter '{name}' must be < 1000 (seed batches 1000 apart are "
                                 f"disjoint), got {p[name]}")
    if p["ess_fraction"] > 1:
        raise ParameterError("ess_fraction must be <= 1")
    fixed, theta = vehicle()
    check_sample_time("dt_s", p["dt_s"], L.build_A_direct(fixed, theta, p["speed_kmh"] / 3.6),
                      f"the lateral model at {p['speed_kmh']:g} km/h")
    check_banks([("toy_particles", p["toy_particles"], p["toy_particles"], 2, 10, "the toy RBPF"),
                 ("n_particles", p["n_particles"], p["n_particles"] * p["lateral"], L.N_STATES,
                  L.N_STATES * (L.N_STATES + 7) + 5, "the lateral RBPF, F, H, G per particle"),
                 ("ibis_particles", p["ibis_particles"], 2 * p["ibis_particles"] * p["lateral"],
                  L.N_STATES, L.N_STATES * (L.N_STATES + 7) + 5,
                  "the lateral IBIS sampler, particles and their proposals"),
                 ("toy_ibis_particles", p["toy_ibis_particles"], 2 * p["toy_ibis_particles"], 2,
                  10, "the toy IBIS sampler, particles and their proposals")])
    if p["measurements_csv"]:
        read_measurements(p["measurements_csv"], p)


def critical_speeds(fixed: dict, theta: np.ndarray, p: dict, metrics: dict) -> pd.DataFrame:
    """Least-damped real part vs speed for the three readings of "half" (metrics: the speeds)."""
    speeds = np.arange(10.0, 200.01, 2.0)
    halved = dict(fixed, mw=fixed["mw"] / 2, mb=fixed["mb"] / 2)
    doubled = dict(fixed, mw=fixed["mw"] * 2, mb=fixed["mb"] * 2)
    curves = {}
    for key, fx in (("chosen", fixed), ("all_halved", halved), ("wheelset_bogie_doubled", doubled)):
        re, vc = L.critical_speed(fx, theta, speeds)
        curves[key] = re
        metrics[f"critical_speed_kmh_{key}"] = vc * 3.6 if vc > 0 else -1
    A = L.build_A_direct(fixed, theta, p["speed_kmh"] / 3.6)
    metrics["least_damped_real_at_speed_per_s"] = L.least_damped(A)[0]
    return pd.DataFrame({"speed_kmh": speeds * 3.6, **curves})


def run_lateral(p: dict, metrics: dict, timings: dict, progress
                ) -> tuple[LateralPart, pd.DataFrame]:
    """Part 2: critical speed, both RBPF schemes and one EKF guess on every record (the first:
    ``ekf_guesses`` and the CRLB), the exact posterior (IBIS) on the first ``ibis_records``;
    metrics and timings into the dicts. Returns the part and the first record's time series."""
    fixed, theta = vehicle()
    critical = critical_speeds(fixed, theta, p, metrics)
    user = bool(p["measurements_csv"])
    if user:
        first = lateral_record(p, fixed, theta, p["seed"])
        p = dict(p, n_steps=len(first.y), n_records=1)
    n_ibis = min(p["ibis_records"], p["n_records"])
    runs, ekf_first, crlb, ekf_count = [], [], None, None
    spent = {"working": 0.0, "paper": 0.0, "ibis": 0.0}
    for i in range(p["n_records"]):
        progress(0.1 + 0.8 * i / p["n_records"], f"lateral record {i}")
        seed = p["seed"] + i
        rec = first if user else lateral_record(p, fixed, theta, seed)
        system, fr = filter_system(p, fixed, theta, rec), {}
        for scheme in ("working", "paper"):
            t0 = time.perf_counter()
            fr[scheme] = lateral_rbpf(p, system, rec, theta, seed, scheme)
            spent[scheme] += time.perf_counter() - t0
        post = None
        if i < n_ibis:
            t0 = time.perf_counter()
            post = posterior.lateral_posterior(p, system, rec, theta, seed)
            spent["ibis"] += time.perf_counter() - t0
        ekf = []
        if not user:
            if i == 0:
                progress(0.15, "CRLB and EKF")
                t0 = time.perf_counter()
                crlb = lateral_crlb_metrics(p, fixed, theta, rec, metrics)
                timings["crlb_s"] = time.perf_counter() - t0
            t0 = time.perf_counter()
            ekf = lateral_ekf(p, fixed, theta, rec, seed, p["ekf_guesses"] if i == 0 else 1)
            timings["ekf_lateral_s"] = (timings.get("ekf_lateral_s", 0.0)
                                        + time.perf_counter() - t0)
            ekf_first.append(ekf_converged(ekf[0]))
            if i == 0:
                ekf_count = int(sum(map(ekf_converged, ekf)))
                metrics["ekf_lateral_converged_count"] = ekf_count
                if p["ekf_guesses"] == 10:
                    metrics["ekf_lateral_converged_of_10"] = ekf_count
        runs.append(LateralRun(None if user else seed, fr["paper"].theta_mean / theta,
                               fr["working"].theta_mean / theta, tuple(ekf),
                               fr["paper"].theta_std / theta, fr["working"].theta_std / theta,
                               post))
    for scheme in ("working", "paper"):
        timings[f"rbpf_{scheme}_per_run_s"] = spent[scheme] / p["n_records"]
    timings["ibis_lateral_per_run_s"] = spent["ibis"] / n_ibis
    for field, suffix in (("rbpf_working_norm", ""), ("rbpf_paper_norm", "_paper_scheme")):
        norm = getattr(runs[0], field)                          # the illustrated record
        steps = steps_to_within(norm)
        metrics[f"steps_to_within_5pct_all{suffix}"] = (int(steps.max()) if np.all(steps > 0)
                                                        else -1)
        for j, name in enumerate(L.PARAM_NAMES):
            metrics[f"steps_to_within_5pct_{name}{suffix}"] = int(steps[j])
            metrics[f"final_relative_error_{name}{suffix}"] = float(norm[-1, j] - 1)
    # Rao-Blackwellisation (paper §4): the augmented state (16 + 5) vs what the particles sample
    metrics["rb_augmented_state_dim"] = L.N_STATES + theta.size
    metrics["rb_particle_dim"] = int(runs[0].rbpf_paper_norm.shape[1])
    t_s = np.arange(1, p["n_steps"] + 1) * p["dt_s"]
    part = LateralPart(fixed=fixed, theta_true=theta, t_s=t_s, runs=tuple(runs),
                       critical_speed=critical, crlb=crlb, ekf_converged_count=ekf_count)
    if not user:
        for field, suffix in (("rbpf_paper_norm", "_paper_scheme"),
                              ("rbpf_working_norm", "_working_scheme")):
            metrics.update(mc.lateral_metrics(list(part.stack(field)), suffix, start=350,
                                              tol=WITHIN))
        metrics.update(mc.rate(ekf_first).metrics("lateral_ekf_converge_rate"))
    metrics.update(posterior.lateral_metrics(part, simulated=not user))
    main, paper, names = runs[0].rbpf_working_norm, runs[0].rbpf_paper_norm, \
        list(enumerate(L.PARAM_NAMES))
    return part, pd.DataFrame({"t_s": t_s, **{f"{name}_norm": main[:, j] for j, name in names},
                               **{f"{name}_norm_paper_scheme": paper[:, j] for j, name in names}})


def lateral_crlb_metrics(p, fixed, theta, rec: LateralRecord, metrics: dict) -> pd.DataFrame:
    """CRLB of the first record into ``metrics`` (crlb_rel_*); returns the table of
    :attr:`LateralPart.crlb`."""
    cr = lateral_crlb(p, fixed, theta, rec)
    rows = []
    for j, name in enumerate(L.PARAM_NAMES):
        metrics[f"crlb_rel_350_{name}"] = float(cr[("known", 350)][j])
        metrics[f"crlb_rel_final_{name}"] = float(cr[("known", p["n_steps"])][j])
        metrics[f"crlb_rel_350_unknown_input_{name}"] = float(cr[("unknown", 350)][j])
        rows.append(dict(parameter=name, **{f"{a}_{c}": cr[(a, c)][j] for a, c in cr}))
    return pd.DataFrame(rows)


def run(*, quick: bool = False, progress=None, **p) -> RbpfParameterEstimationResult:
    """The whole chapter for resolved parameters ``p`` (see :data:`SPEC`), on one numba and one
    OpenBLAS thread (:func:`~railpaper.experiments.rbpf_parameter_estimation_io.one_thread`)."""
    progress = progress or no_progress
    validate(p)
    with one_thread():
        return _run(p, progress)


def _run(p: dict, progress) -> RbpfParameterEstimationResult:
    metrics, timings = {}, {}
    progress(0.02, "toy")
    t0 = time.perf_counter()
    toy = run_toy(p)
    timings["toy_s"] = time.perf_counter() - t0
    st = toy.records
    for ic in (1, 2):                                           # the illustrated record
        main = st[(st.seed == p["seed"]) & (st.init == ic)].iloc[0]
        metrics[f"toy_ekf_diverged_init{ic}"] = bool(main.ekf_diverged)
        metrics[f"toy_ekf_final_abs_error_max_init{ic}"] = float(main.ekf_err_max)
        metrics[f"toy_final_abs_error_max_rbpf_init{ic}"] = float(main.rbpf_err_max)
        metrics[f"toy_final_abs_error_max_rbpf_working_init{ic}"] = float(
            main.rbpf_working_err_max)
    metrics.update(mc.toy_metrics(st))
    t0 = time.perf_counter()
    toy = posterior.toy_posteriors(p, toy)                      # the exact posterior, toy
    timings["ibis_toy_s"] = time.perf_counter() - t0
    metrics.update(posterior.toy_metrics(toy))
    lateral, ts = run_lateral(p, metrics, timings, progress) if p["lateral"] else (None, None)
    mismatch = None
    if p["lateral"] and not p["measurements_csv"]:
        from railpaper.experiments.rbpf_parameter_estimation_model_error import run_model_error
        progress(0.9, "model error")
        t0 = time.perf_counter()
        mismatch, more = run_model_error(p, lateral)
        metrics.update(more)
        timings["mismatch_s"] = time.perf_counter() - t0
    progress(1.0, "done")
    return RbpfParameterEstimationResult(
        metrics=metrics, timings=timings, timeseries=ts,
        extra_tables={"toy_timeseries": toy.table(),
                      "toy_record": posterior.toy_record_table(toy.record)},
        extra_files={"toy_posterior.json": posterior.toy_posterior_json(p, toy.posterior)},
        toy=toy, lateral=lateral, mismatch=mismatch)
