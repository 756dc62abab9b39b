"""The lateral-vehicle study of chapter ``rbpf-parameter-estimation`` (paper 003, Part 2).

``n_records`` records of the 16-state lateral vehicle (Eqs. 1–9,
:mod:`railpaper.models.lateral_16state`), seeds ``seed``, ``seed + 1``, …, each simulated at
``dt_s / truth_substeps`` from an alignment profile of ``spectrum`` and sampled at ``dt_s`` with
stated sensor noise; on each, the RBPF over θ = (Csy, λ, Kpy, Ksy, Csaly) with the paper's literal
scheme and with our working scheme (tempering, ESS-triggered resampling, Liu–West move only after
resampling, on normalised log-parameters: our modification, not the paper's method), the
augmented 21-state EKF from one initial guess (``ekf_guesses`` on the first record, as the
paper's 10), the exact posterior (IBIS) on the first ``ibis_records`` and the Kalman-likelihood
CRLB on the first record.  One record by hand: :func:`lateral_record`, :func:`record_system`,
:func:`lateral_rbpf`, :func:`lateral_ekf`.  :func:`run_lateral` returns the part, its own
metrics and its timings; the metrics of a stack of runs are :func:`lateral_metrics`.
"""

from __future__ import annotations

import time

import numpy as np
import pandas as pd

from railpaper.engine import FilterRun, crlb_std, fisher_information, run_rbpf
from railpaper.estimators.ekf import run_augmented_ekf
from railpaper.experiments.lateral_vehicle import (  # noqa: F401 (the chapter's API)
    RecordSettings,
    filter_noise,
    filter_system,
    noise_std,
    prior_centre,
    simulate_lateral,
    vehicle,
)
from railpaper.experiments.rbpf_parameter_estimation import posterior
from railpaper.experiments.rbpf_parameter_estimation.measurements import (
    read_measurements,
)
from railpaper.experiments.rbpf_parameter_estimation.result import (
    LateralPart,
    LateralRecord,
    LateralRun,
)
from railpaper.experiments.rbpf_parameter_estimation.spec import (
    JUDGED_PARTICLES,
    Settings,
    after_the_seen_records,
)
from railpaper.experiments.records import (
    RecordMap,
    RecordStudy,
    map_in_process,
    no_rows,
    normalised,
)
from railpaper.models import lateral_16state
from railpaper.settling import holds_from, settling_step
from railpaper.stats import max_abs_bias, mean_interval, median_interval, rate
from railpaper.threads import one_thread

WITHIN = 0.05
#: The paper's claim: every parameter within :data:`WITHIN` after this many steps.
CLAIM_STEP = 350


def lateral_record(settings: Settings, fixed: dict, theta: np.ndarray, seed: int
                   ) -> LateralRecord:
    """The record of seed ``seed``: the user's file when ``measurements_csv`` is set (every
    seed), else :func:`simulate_lateral` at the record settings of ``settings``."""
    if settings.measurements_csv:
        return read_measurements(settings.measurements_csv, settings.dt_s)
    return simulate_lateral(RecordSettings.of(settings), fixed, theta, seed)


def record_system(settings: Settings, fixed: dict, theta: np.ndarray, record: LateralRecord):
    """``system(theta)``, the filters' model of ``record``: :func:`filter_system` at the record
    settings of ``settings``, its ZOH balanced at the prior box's centre
    (:func:`prior_centre`)."""
    return filter_system(RecordSettings.of(settings), fixed, theta, record,
                         theta_ref=prior_centre(theta, settings.prior_low, settings.prior_high))


#: Steps over which the paper's RBPF at ``JUDGED_PARTICLES`` is timed for the real-time row (its
#: cost per step is the same at every step: it resamples and moves at each one).
REAL_TIME_STEPS = 200


def lateral_rbpf(settings: Settings, system, record: LateralRecord, theta: np.ndarray, seed: int,
                 scheme: str) -> FilterRun:
    """One RBPF run on a record: ``n_particles`` particles θ × U(``prior_low``, ``prior_high``)
    per parameter (generator ``[seed, 11]``: both schemes start from the same particles), each
    with a Kalman filter from X = 0; ``scheme="paper"`` (Steps 1–2.6, δ = ``paper_delta``) or
    ``"working"`` (tempering, ESS-triggered resampling, moves of log-parameters)."""
    rng = np.random.default_rng([seed, 11])
    theta0 = theta * rng.uniform(settings.prior_low, settings.prior_high,
                                 (settings.n_particles, 5))
    opts = (dict(scheme="paper", delta=settings.paper_delta) if scheme == "paper" else
            dict(scheme="working", delta=settings.working_delta,
                 ess_fraction=settings.ess_fraction, tempering_steps=settings.tempering_steps,
                 log_mask=np.ones(5, bool)))
    return run_rbpf(system, record.y, theta0, np.zeros(lateral_16state.N_STATES),
                    1e-10 * np.eye(lateral_16state.N_STATES), rng, u=record.u_mps, **opts)


def run_lateral_rbpf(settings: Settings, fixed, theta, record: LateralRecord, seed: int,
                     scheme: str) -> np.ndarray:
    """Normalised estimates θ̂/θ (K, 5) of one RBPF run (:func:`lateral_rbpf`)."""
    system = record_system(settings, fixed, theta, record)
    return lateral_rbpf(settings, system, record, theta, seed, scheme).theta_mean / theta


def lateral_crlb(settings: Settings, fixed, theta, record: LateralRecord) -> dict:
    """Relative CRLB after 350 and n_steps steps, input known / unknown (process noise)."""
    v = settings.speed_kmh / 3.6
    out = {}
    for label, var, u in (("known", record.du_var_m2ps2, record.u_mps),
                          ("unknown", record.u_var_m2ps2, None)):
        Q, R = filter_noise(fixed, theta, RecordSettings.of(settings), var)
        info = fisher_information(lateral_16state.lateral_system(fixed, v, settings.dt_s, Q, R,
                                                                 theta_ref=theta),
                                  theta, record.y,
                                  np.zeros(lateral_16state.N_STATES),
                                  1e-10 * np.eye(lateral_16state.N_STATES), u,
                                  checkpoints=(350, settings.n_steps))
        for c, I in info.items():
            out[(label, c)] = crlb_std(I) / theta
    return out


def lateral_ekf(settings: Settings, fixed, theta, record: LateralRecord, seed, guesses: int
                ) -> list[np.ndarray]:
    """Normalised EKF estimates (K, 5) from ``guesses`` guesses U(prior box) x θ (generator
    ``[seed, 13]``; NaN rows if the run diverged); K = min(ekf_steps, n_steps).  Empty on
    a user's record (``record.seed`` None): the chapter judges the EKF on simulated records only."""
    if record.seed is None:
        return []
    Q, R = filter_noise(fixed, theta, RecordSettings.of(settings), record.du_var_m2ps2)
    model = lateral_16state.ekf_model(fixed, settings.speed_kmh / 3.6, settings.dt_s)
    rng = np.random.default_rng([seed, 13])
    runs = []
    for _ in range(guesses):
        guess = theta * rng.uniform(settings.prior_low, settings.prior_high, 5)
        K = min(settings.ekf_steps, settings.n_steps)
        r = run_augmented_ekf(model, record.y[:K], guess, np.zeros(lateral_16state.N_STATES),
                              1e-10 * np.eye(lateral_16state.N_STATES), (0.3 * theta) ** 2, Q, R,
                              (1e-4 * theta) ** 2, u=record.u_mps[:K], divergence_bound=1e12)
        runs.append(r.theta / theta if not r.diverged else np.full_like(r.theta, np.nan))
    return runs


def final_errors(norm: np.ndarray, prefix: str = "final_relative_error_") -> dict:
    """``<prefix><param>``: θ̂/θ − 1 at the last step of normalised estimates ``norm`` (K, 5),
    per parameter (1; NaN where the run diverged)."""
    return {f"{prefix}{name}": float(norm[-1, j] - 1.0)
            for j, name in enumerate(lateral_16state.PARAM_NAMES)}


def ekf_diverged(norm: np.ndarray) -> bool:
    """A lateral EKF run stopped (its normalised estimates are NaN after a divergence)."""
    return not bool(np.all(np.isfinite(norm[-1])))


def ekf_converged(norm: np.ndarray) -> bool:
    """A lateral EKF run is convergent and meaningful: every final estimate within 5 %."""
    return bool(np.all(np.isfinite(norm[-1])) and np.all(np.abs(norm[-1] - 1) <= WITHIN))


def critical_speeds(fixed: dict, theta: np.ndarray, settings: Settings
                    ) -> tuple[pd.DataFrame, dict]:
    """Least-damped real part vs speed for the three readings of "half", and the metrics (the
    critical speeds, km/h; the least-damped real part at the chapter's speed, 1/s)."""
    metrics = {}
    speeds = np.arange(10.0, 200.01, 2.0)
    halved = dict(fixed, mw=fixed["mw"] / 2, mb=fixed["mb"] / 2)
    doubled = dict(fixed, mw=fixed["mw"] * 2, mb=fixed["mb"] * 2)
    curves = {}
    for key, fx in (("chosen", fixed), ("all_halved", halved), ("wheelset_bogie_doubled", doubled)):
        re, vc = lateral_16state.critical_speed(fx, theta, speeds)
        curves[key] = re
        metrics[f"critical_speed_found_{key}"] = bool(vc > 0)   # else: stable to the search's end
        if vc > 0:
            metrics[f"critical_speed_kmh_{key}"] = vc * 3.6
    A = lateral_16state.build_A_direct(fixed, theta, settings.speed_kmh / 3.6)
    metrics["least_damped_real_at_speed_per_s"] = lateral_16state.least_damped(A)[0]
    return pd.DataFrame({"speed_kmh": speeds * 3.6, **curves}), metrics


def scheme_row(seed: int, norm: np.ndarray, start: int = CLAIM_STEP, tol: float = WITHIN
               ) -> dict:
    """One record's row of a scheme's study from its normalised estimates ``norm`` = θ̂/θ
    (K, 5): ``within_5pct_from_350`` (every parameter within ``tol`` at every step from
    ``start`` to the end), ``within_5pct_at_350`` (at step ``start``), and
    ``final_relative_error_<param>`` (θ̂/θ − 1 at the last step, 1)."""
    with np.errstate(invalid="ignore"):
        at = bool(np.all(np.abs(norm[start - 1] - 1.0) <= tol))
    return {"seed": int(seed),
            "within_5pct_from_350": bool(holds_from(np.abs(norm - 1.0) <= tol, start).all()),
            "within_5pct_at_350": at, **final_errors(norm)}


def filtered_records(settings: Settings, seeds, filter_row) -> pd.DataFrame:
    """One row per seed of ``seeds``, in order, on one thread: ``filter_row(seed, record,
    system, theta)`` on the record of each seed (:func:`lateral_record`) and its filters'
    model (:func:`record_system`) — the loop every lateral per-record study shares."""
    fixed, theta = vehicle()
    rows = []
    with one_thread():
        for seed in seeds:
            record = lateral_record(settings, fixed, theta, int(seed))
            system = record_system(settings, fixed, theta, record)
            rows.append(filter_row(int(seed), record, system, theta))
    return pd.DataFrame(rows)


def scheme_rows(settings: Settings, seeds, scheme: str) -> pd.DataFrame:
    """:func:`scheme_row` of the ``scheme`` RBPF (:func:`lateral_rbpf`) on each simulated
    record of ``seeds``, one after another on one thread."""
    return filtered_records(settings, seeds, lambda seed, record, system, theta: scheme_row(
        seed, lateral_rbpf(settings, system, record, theta, seed, scheme).theta_mean / theta))


def paper_scheme_rows(settings: Settings, seeds) -> pd.DataFrame:
    """The study :data:`PAPER_SCHEME`'s rows: :func:`scheme_rows` of the paper's scheme."""
    return scheme_rows(settings, seeds, "paper")


def working_scheme_rows(settings: Settings, seeds) -> pd.DataFrame:
    """The study :data:`WORKING_SCHEME`'s rows: :func:`scheme_rows` of our working scheme."""
    return scheme_rows(settings, seeds, "working")


#: The paper-scheme RBPF on records ``seed`` … ``seed + paper_records − 1``: one row per record.
PAPER_SCHEME = RecordStudy("rbpf-parameter-estimation", "lateral_paper_scheme",
                           paper_scheme_rows, chunk_records=1)
#: Our working-scheme RBPF on records ``seed`` … ``seed + working_records − 1``.
WORKING_SCHEME = RecordStudy("rbpf-parameter-estimation", "lateral_working_scheme",
                             working_scheme_rows, chunk_records=1)


def judged_particles_rows(settings: Settings, seeds) -> pd.DataFrame:
    """The study :data:`PAPER_SCHEME_JUDGED`'s rows: :func:`paper_scheme_rows` with
    :data:`JUDGED_PARTICLES` particles in place of ``n_particles``."""
    return paper_scheme_rows(settings.replace(n_particles=JUDGED_PARTICLES), seeds)


#: The paper-scheme RBPF with :data:`JUDGED_PARTICLES` (1000) particles, the count at which the
#: ledger judges the paper's RBPF (the paper prints none; blind policy,
#: ``data/rbpf-parameter-estimation/blind/particles_reply.md``): one row per record, as
#: :data:`PAPER_SCHEME`, which keeps our cheaper ``n_particles`` beside it.
PAPER_SCHEME_JUDGED = RecordStudy("rbpf-parameter-estimation",
                                  "lateral_paper_scheme_judged_particles",
                                  judged_particles_rows, chunk_records=1,
                                  first_record=after_the_seen_records,
                                  repeats="lateral_paper_scheme")


def ekf_row(seed: int, norm: np.ndarray) -> dict:
    """One record's row of the study :data:`EKF` from the first EKF guess's normalised estimates
    ``norm`` (K, 5; NaN after a divergence): ``ekf_converged`` (every final estimate within 5 %,
    :func:`ekf_converged`), ``ekf_diverged`` (the run stopped) and
    ``final_relative_error_<param>`` (1; NaN after a divergence)."""
    return {"seed": int(seed), "ekf_converged": ekf_converged(norm),
            "ekf_diverged": ekf_diverged(norm), **final_errors(norm)}


def ekf_rows(settings: Settings, seeds) -> pd.DataFrame:
    """The study :data:`EKF`'s rows: one augmented-EKF guess (the first of
    :func:`lateral_ekf`, generator ``[seed, 13]``) on each simulated record of ``seeds``."""
    fixed, theta = vehicle()
    rows = []
    with one_thread():
        for seed in seeds:
            record = lateral_record(settings, fixed, theta, int(seed))
            rows.append(ekf_row(int(seed), lateral_ekf(settings, fixed, theta, record,
                                                       int(seed), 1)[0]))
    return pd.DataFrame(rows)


#: The augmented EKF, one guess per record, on records ``seed`` … (the chapter: ``n_records``).
EKF = RecordStudy("rbpf-parameter-estimation", "lateral_ekf", ekf_rows, chunk_records=1)


def lateral_metrics(rows: pd.DataFrame, suffix: str) -> dict:
    """Evidence metrics of one RBPF scheme from its study's rows (:func:`scheme_row`, one per
    record, in record order).

    Returns
    -------
    dict
        ``lateral_within_5pct_from_350_rate``: records with every parameter within 5 % at
        every step from 350 to the end; ``lateral_within_5pct_at_350_rate``: at step 350
        alone; ``lateral_bias_max_abs``: largest |mean final relative error| over the
        parameters (simultaneous interval, :func:`max_abs_bias`); ``lateral_median_final_abs_
        error_max``: median over records of the largest final |relative error| — each with
        ``_low``, ``_high``, ``_n`` — and per parameter ``lateral_bias_<j>`` (mean final
        relative error, 95 % t interval); every name ends in ``suffix``.
    """
    finals = rows[[f"final_relative_error_{name}"
                   for name in lateral_16state.PARAM_NAMES]].to_numpy(float)
    out = {}
    out.update(rate(rows["within_5pct_from_350"].to_numpy(bool))
               .metrics(f"lateral_within_5pct_from_350_rate{suffix}"))
    out.update(rate(rows["within_5pct_at_350"].to_numpy(bool))
               .metrics(f"lateral_within_5pct_at_350_rate{suffix}"))
    out.update(max_abs_bias(finals).metrics(f"lateral_bias_max_abs{suffix}"))
    out.update(median_interval(np.abs(finals).max(axis=1))
               .metrics(f"lateral_median_final_abs_error_max{suffix}"))
    for j, name in enumerate(lateral_16state.PARAM_NAMES):
        out.update(mean_interval(finals[:, j]).metrics(f"lateral_bias_{name}{suffix}"))
    return out


def run_lateral(settings: Settings, progress, record_map: RecordMap = map_in_process
                ) -> tuple[LateralPart, dict, dict]:
    """Part 2: critical speed, both RBPF schemes and one EKF guess on every record (the first:
    ``ekf_guesses`` and the CRLB), the exact posterior (IBIS) on the first ``ibis_records``.
    Returns the part, its metrics and its timings (s)."""
    timings = {}
    fixed, theta = vehicle()
    critical, metrics = critical_speeds(fixed, theta, settings)
    user = bool(settings.measurements_csv)
    n_steps, n_records = settings.n_steps, settings.n_records
    if user:
        first = lateral_record(settings, fixed, theta, settings.seed)
        n_steps, n_records = len(first.y), 1
    n_ibis = min(settings.ibis_records, n_records)
    runs, ekf_first, crlb, ekf_count = [], [], None, None
    spent = {"working": 0.0, "paper": 0.0, "ibis": 0.0}
    for i in range(n_records):
        progress(0.1 + 0.6 * i / n_records, f"lateral record {i}")
        seed = settings.seed + i
        rec = first if user else lateral_record(settings, fixed, theta, seed)
        system, fr = record_system(settings, fixed, theta, rec), {}
        for scheme in ("working", "paper"):
            t0 = time.perf_counter()
            fr[scheme] = lateral_rbpf(settings, system, rec, theta, seed, scheme)
            spent[scheme] += time.perf_counter() - t0
        if i == 0:          # the paper's RBPF at the count the ledger judges it (real time),
            t0 = time.perf_counter()                  # timed on the record's first steps
            lateral_rbpf(settings.replace(n_particles=JUDGED_PARTICLES), system,
                         rec.first_steps(REAL_TIME_STEPS), theta, seed, "paper")
            spent["paper_judged"] = time.perf_counter() - t0
        post = None
        if i < n_ibis:
            t0 = time.perf_counter()
            post = posterior.lateral_posterior(settings, system, rec, theta, seed)
            spent["ibis"] += time.perf_counter() - t0
        ekf = []
        if not user:
            if i == 0:
                progress(0.15, "CRLB and EKF")
                t0 = time.perf_counter()
                crlb, more = lateral_crlb_metrics(settings, fixed, theta, rec)
                metrics.update(more)
                timings["crlb_s"] = time.perf_counter() - t0
            t0 = time.perf_counter()
            ekf = lateral_ekf(settings, fixed, theta, rec, seed,
                              settings.ekf_guesses if i == 0 else 1)
            timings["ekf_lateral_s"] = (timings.get("ekf_lateral_s", 0.0)
                                        + time.perf_counter() - t0)
            ekf_first.append(ekf_converged(ekf[0]))
            if i == 0:
                ekf_count = int(sum(map(ekf_converged, ekf)))
                metrics["ekf_lateral_converged_count"] = ekf_count
                if settings.ekf_guesses == 10:
                    metrics["ekf_lateral_converged_of_10"] = ekf_count
        runs.append(LateralRun(None if user else seed, fr["paper"].theta_mean / theta,
                               fr["working"].theta_mean / theta, tuple(ekf),
                               fr["paper"].theta_std / theta, fr["working"].theta_std / theta,
                               post))
    # records n_records … paper_records - 1 (paper scheme) and … working_records - 1 (working
    # scheme): each scheme's claims need more records than the other estimators; they are the
    # rows of its study, mapped by the caller's record map
    scheme_tables = {}
    for scheme, study, wanted in (("paper", PAPER_SCHEME, settings.paper_records),
                                  ("working", WORKING_SCHEME, settings.working_records)):
        if user:                                          # no truth: no per-record rows
            scheme_tables[scheme] = no_rows()
            continue
        field = "rbpf_paper_norm" if scheme == "paper" else "rbpf_working_norm"
        first = normalised(pd.DataFrame([scheme_row(r.seed, getattr(r, field)) for r in runs]))
        if wanted > n_records:
            progress(0.7, f"lateral records {n_records}-{wanted - 1}, {scheme} scheme alone")
            more = record_map(study, settings, range(settings.seed + n_records,
                                                     settings.seed + wanted),
                              lambda fraction, message: progress(0.7 + 0.2 * fraction, message))
            first = pd.concat([first, more], ignore_index=True)
        scheme_tables[scheme] = first
    ekf_table = (no_rows() if user else
                 normalised(pd.DataFrame([ekf_row(r.seed, r.ekf_norm[0]) for r in runs])))
    for scheme in ("working", "paper"):
        # the records filtered here (the first n_records), RBPF alone: the rate it sustains
        timings[f"rbpf_{scheme}_per_run_s"] = spent[scheme] / n_records
        timings[f"steps_per_second_rbpf_{scheme}_scheme"] = n_steps * n_records / spent[scheme]
    timings["steps_per_second_rbpf_paper_scheme_judged_particles"] = (
        min(n_steps, REAL_TIME_STEPS) / spent["paper_judged"])
    timings["ibis_lateral_per_run_s"] = spent["ibis"] / n_ibis
    for field, suffix in (("rbpf_working_norm", ""), ("rbpf_paper_norm", "_paper_scheme")):
        norm = getattr(runs[0], field)                          # the illustrated record
        steps = settling_step(np.abs(norm - 1.0) <= WITHIN)   # per parameter
        metrics[f"steps_to_within_5pct_all{suffix}"] = (int(steps.max()) if np.all(steps > 0)
                                                        else -1)
        for j, name in enumerate(lateral_16state.PARAM_NAMES):
            metrics[f"steps_to_within_5pct_{name}{suffix}"] = int(steps[j])
            metrics[f"final_relative_error_{name}{suffix}"] = float(norm[-1, j] - 1)
    # Rao-Blackwellisation (paper §4): the augmented state (16 + 5) vs what the particles sample
    metrics["rb_augmented_state_dim"] = lateral_16state.N_STATES + theta.size
    metrics["rb_particle_dim"] = int(runs[0].rbpf_paper_norm.shape[1])
    # the particle count at which the ledger judges the paper's RBPF (its stored studies)
    metrics["rbpf_judged_particles"] = JUDGED_PARTICLES
    t_s = np.arange(1, n_steps + 1) * settings.dt_s
    part = LateralPart(fixed=fixed, theta_true=theta, t_s=t_s, runs=tuple(runs),
                       critical_speed=critical, crlb=crlb, ekf_converged_count=ekf_count,
                       paper_scheme_rows=scheme_tables["paper"], ekf_rows=ekf_table,
                       working_scheme_rows=scheme_tables["working"])
    if not user:
        metrics.update(lateral_metrics(part.paper_scheme_rows, "_paper_scheme"))
        metrics.update(lateral_metrics(part.working_scheme_rows, "_working_scheme"))
        metrics.update(rate(ekf_first).metrics("lateral_ekf_converge_rate"))
    metrics.update(posterior.lateral_metrics(part, simulated=not user))
    return part, metrics, timings


def lateral_timeseries(part: LateralPart) -> pd.DataFrame:
    """The illustrated (first) record's normalised estimates θ̂/θ of both schemes against time."""
    main, paper = part.runs[0].rbpf_working_norm, part.runs[0].rbpf_paper_norm
    names = list(enumerate(lateral_16state.PARAM_NAMES))
    return pd.DataFrame({"t_s": part.t_s, **{f"{name}_norm": main[:, j] for j, name in names},
                         **{f"{name}_norm_paper_scheme": paper[:, j] for j, name in names}})


def lateral_crlb_metrics(settings: Settings, fixed, theta, rec: LateralRecord
                         ) -> tuple[pd.DataFrame, dict]:
    """CRLB of the first record: the table of :attr:`LateralPart.crlb` and the metrics
    ``crlb_rel_*`` (relative standard deviations, 1)."""
    cr = lateral_crlb(settings, fixed, theta, rec)
    metrics = {}
    rows = []
    for j, name in enumerate(lateral_16state.PARAM_NAMES):
        metrics[f"crlb_rel_350_{name}"] = float(cr[("known", 350)][j])
        metrics[f"crlb_rel_final_{name}"] = float(cr[("known", settings.n_steps)][j])
        metrics[f"crlb_rel_350_unknown_input_{name}"] = float(cr[("unknown", 350)][j])
        rows.append(dict(parameter=name, **{f"{a}_{c}": cr[(a, c)][j] for a, c in cr}))
    return pd.DataFrame(rows), metrics


