"""Chapter "rbpf-parameter-estimation": Ding et al. (2014)'s RBPF versus an augmented-state EKF.

Part 1 — Eq. (18) toy (:mod:`railpaper.experiments.rbpf_parameter_estimation.toy`): the RBPF
exactly as the paper's Steps 1–2.6, our working scheme, and an augmented-state EKF from the
paper's two initial conditions, on ``toy_seeds`` records (seeds ``seed``, ``seed + 1``, …).

Part 2 — the lateral vehicle (Eqs. 1–9, :mod:`railpaper.models.lateral_16state`): ``n_records``
records (seeds ``seed``, ``seed + 1``, …), each simulated at ``dt_s / truth_substeps`` from an
alignment profile of ``spectrum`` and sampled at ``dt_s`` with stated sensor noise; on each, the
RBPF over θ = (Csy, λ, Kpy, Ksy, Csaly) with the paper's literal scheme and with our working
scheme (tempering, ESS-triggered resampling, Liu–West move only after resampling, on normalised
log-parameters: our modification, not the paper's method), and the augmented 21-state EKF from
one initial guess (``ekf_guesses`` on the first record, as the paper's 10); the Kalman-likelihood
CRLB on the first record (:mod:`railpaper.experiments.rbpf_parameter_estimation.lateral`).  The Monte Carlo evidence of the claims (rates, medians, biases with
95 % intervals) is computed by :mod:`railpaper.experiments.rbpf_parameter_estimation.evidence`.
``measurements_csv`` runs both RBPF schemes on a user's file (no evidence: it needs the truth).
``lateral=False`` skips Part 2 (sweep samples of the toy alone).

:func:`run` returns a
:class:`~railpaper.experiments.rbpf_parameter_estimation.result.RbpfParameterEstimationResult`:
the metrics, timings and time series the pipeline writes, and the two parts' named results
(``result.toy``, ``result.lateral``).  One record by hand:
:mod:`~railpaper.experiments.rbpf_parameter_estimation.lateral` (the toy's:
:mod:`~railpaper.experiments.rbpf_parameter_estimation.toy`).
"""

from __future__ import annotations

import time

import numpy as np

from railpaper import track
from railpaper.estimators.ekf import eq18_model
from railpaper.experiments.base import (
    ParameterError,
    check_banks,
    check_sample_time,
    default_progress,
)
from railpaper.experiments.rbpf_parameter_estimation import (
    evidence,
    lateral,
    posterior,
    soundness,
)
from railpaper.experiments.rbpf_parameter_estimation.measurements import (
    read_measurements,
)
from railpaper.experiments.rbpf_parameter_estimation.mismatch import MODEL_ERROR
from railpaper.experiments.rbpf_parameter_estimation.model_error import run_model_error
from railpaper.experiments.rbpf_parameter_estimation.result import (
    RbpfParameterEstimationResult,
)
from railpaper.experiments.rbpf_parameter_estimation.spec import SPEC, Settings
from railpaper.experiments.rbpf_parameter_estimation.toy import (
    TOY,
    TOY_INITS,
    TOY_JUDGED,
    run_toy,
)
from railpaper.experiments.records import RecordMap, map_in_process
from railpaper.models import lateral_16state
from railpaper.threads import one_thread

#: The chapter's per-record studies: the toy's records and their exact posterior (calibration);
#: each lateral RBPF scheme's, the augmented EKF's (one guess) and the truth plant with model
#: error.
#: The exact posterior of the toy's and the lateral records (the soundness of the filters,
#: :mod:`~railpaper.experiments.rbpf_parameter_estimation.soundness`) follows them; then the
#: toy and the paper-scheme RBPF at ``JUDGED_PARTICLES``, which only the stored decisive
#: evidence holds (a run does not compute them).
STUDIES = (TOY, posterior.TOY_CALIBRATION, lateral.PAPER_SCHEME, lateral.WORKING_SCHEME,
           lateral.EKF, MODEL_ERROR, soundness.TOY_POSTERIOR, soundness.LATERAL_POSTERIOR,
           TOY_JUDGED, lateral.PAPER_SCHEME_JUDGED)

__all__ = ["SPEC", "STUDIES", "Settings", "run", "validate"]


def validate(settings: Settings) -> None:
    """Refuse non-physical or inconsistent settings with one line, before any work."""
    if not settings.prior_low < 1.0 < settings.prior_high:
        raise ParameterError("prior_low < 1 < prior_high is needed (the box must hold the truth)")
    if not 1 / 3 < settings.paper_delta <= 1 or not 1 / 3 < settings.working_delta <= 1:
        raise ParameterError("Liu-West delta must be in (1/3, 1]")
    if settings.wavelength_min_m < 2 * settings.speed_kmh / 3.6 * settings.dt_s:
        raise ParameterError("wavelength_min_m is shorter than the filter's Nyquist wavelength "
                             "2 V dt_s")
    if settings.spectrum not in track.SPECTRA:
        raise ParameterError(f"parameter 'spectrum': unknown spectrum {settings.spectrum!r}; "
                             f"one of {', '.join(track.SPECTRA)}")
    for name, value in (("toy_seeds", settings.toy_seeds), ("n_records", settings.n_records),
                        ("paper_records", settings.paper_records),
                        ("working_records", settings.working_records)):
        if value >= 1000:
            raise ParameterError(f"parameter '{name}' must be < 1000 (seed batches 1000 apart are "
                                 f"disjoint), got {value}")
    for name, value in (("ess_fraction", settings.ess_fraction),
                        ("toy_ess_fraction", settings.toy_ess_fraction)):
        if value > 1:
            raise ParameterError(f"{name} must be <= 1")
    fixed, theta = lateral.vehicle()
    check_sample_time("dt_s", settings.dt_s,
                      lateral_16state.build_A_direct(fixed, theta, settings.speed_kmh / 3.6),
                      f"the lateral model at {settings.speed_kmh:g} km/h")
    n_states = lateral_16state.N_STATES
    check_banks([("toy_particles", settings.toy_particles, settings.toy_particles, 2, 10,
                  "the toy RBPF"),
                 ("n_particles", settings.n_particles, settings.n_particles * settings.lateral,
                  n_states, n_states * (n_states + 7) + 5,
                  "the lateral RBPF, F, H, G per particle"),
                 ("ibis_particles", settings.ibis_particles,
                  2 * settings.ibis_particles * settings.lateral,
                  n_states, n_states * (n_states + 7) + 5,
                  "the lateral IBIS sampler, particles and their proposals"),
                 ("toy_ibis_particles", settings.toy_ibis_particles,
                  2 * settings.toy_ibis_particles, 2, 10,
                  "the toy IBIS sampler, particles and their proposals")])
    if settings.measurements_csv:
        read_measurements(settings.measurements_csv, settings.dt_s)


def run(settings: Settings, *, progress=None,
        record_map: RecordMap = map_in_process) -> RbpfParameterEstimationResult:
    """The whole chapter for ``settings`` (see :data:`SPEC`), on one numba and one OpenBLAS
    thread (:func:`railpaper.threads.one_thread`).  ``record_map(study, settings, seeds,
    progress)`` computes the rows of the per-record studies (:data:`STUDIES`: the toy's records
    and their exact posterior after the illustrated one, and each lateral RBPF scheme's records
    after the first ``n_records``); default: in this process."""
    progress = progress or default_progress()
    validate(settings)
    with one_thread():
        return _run(settings, progress, record_map)


def _run(settings: Settings, progress, record_map: RecordMap) -> RbpfParameterEstimationResult:
    metrics, timings = {}, {}
    progress(0.02, "toy")
    t0 = time.perf_counter()
    toy = run_toy(settings, record_map,
                  lambda fraction, message: progress(0.02 + 0.06 * fraction, message))
    timings["toy_s"] = time.perf_counter() - t0
    st = toy.records
    for ic in (1, 2):                                           # the illustrated record
        main = st[(st.seed == settings.seed) & (st.init == ic)].iloc[0]
        metrics[f"toy_ekf_diverged_init{ic}"] = bool(main.ekf_diverged)
        metrics[f"toy_ekf_final_abs_error_max_init{ic}"] = float(main.ekf_err_max)
        metrics[f"toy_final_abs_error_max_rbpf_init{ic}"] = float(main.rbpf_err_max)
        metrics[f"toy_final_abs_error_max_rbpf_working_init{ic}"] = float(
            main.rbpf_working_err_max)
    metrics.update(evidence.toy_metrics(st))
    for ic, start in TOY_INITS.items():           # the EKF's first linearisation (§3.1's mechanism)
        singular = np.linalg.svd(eq18_model(start)[0], compute_uv=False)
        metrics[f"toy_ekf_transition_rcond_init{ic}"] = float(singular[-1] / singular[0])
    t0 = time.perf_counter()
    progress(0.08, "toy: exact posterior")
    toy = posterior.toy_posteriors(                             # the exact posterior, toy
        settings, toy, record_map, lambda fraction, message: progress(0.08 + 0.02 * fraction,
                                                                      message))
    timings["ibis_toy_s"] = time.perf_counter() - t0
    metrics.update(posterior.toy_metrics(toy))
    metrics.update(evidence.toy_offset_metrics(toy.records, toy.coverage, toy.truth))
    part, ts, mismatch = None, None, None
    if settings.lateral:
        part, more, spent = lateral.run_lateral(settings, progress, record_map)
        metrics.update(more)
        timings.update(spent)
        ts = lateral.lateral_timeseries(part)
    if settings.lateral and not settings.measurements_csv:
        progress(0.9, "model error")
        t0 = time.perf_counter()
        mismatch, more = run_model_error(settings, part)
        metrics.update(more)
        timings["mismatch_s"] = time.perf_counter() - t0
    progress(1.0, "done")
    return RbpfParameterEstimationResult(
        metrics=metrics, timings=timings, timeseries=ts,
        extra_tables={"toy_timeseries": toy.table(),
                      "toy_record": posterior.toy_record_table(toy.record),
                      "records_toy": toy.rows,
                      **({} if part is None or part.paper_scheme_rows.empty else
                         {"records_lateral_paper_scheme": part.paper_scheme_rows,
                          "records_lateral_working_scheme": part.working_scheme_rows,
                          "records_lateral_ekf": part.ekf_rows}),
                      **({} if mismatch is None else
                         {"records_model_error": mismatch.study_rows()})},
        extra_files={"toy_posterior.json": posterior.toy_posterior_json(settings, toy.posterior)},
        toy=toy, lateral=part, mismatch=mismatch)
