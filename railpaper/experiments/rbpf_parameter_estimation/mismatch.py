"""Paper 003's EKF and RBPF on a truth plant the filters' linear model does not contain.

Paper 003 (Ding et al. 2014, §3.2) reports that on line data its EKF converged from none of 10
initial guesses while the RBPF did, and puts this down to the EKF.  Simulated records from the
filters' own linear model cannot show a failure that comes from reality.  Here each record comes
from a truth plant with three things the linear model leaves out (numbers with sources in
``data/rbpf-parameter-estimation/mismatch.toml``):

* ``"creep"``: creep forces that saturate at μN (Vermeulen–Johnson, :mod:`railpaper.contact`);
* ``"conicity"``: a rolling-radius difference that is cubic in the displacement;
* ``"lowpass"``: the paper's 40 Hz low-pass in the measurement chain (:mod:`railpaper.sensors`).

The plant (:mod:`railpaper.models.lateral_truth`) runs at ``dt_s / truth_substeps`` on the same
alignment profile and with the same sensor-noise draws as the chapter's record of the same seed
(:func:`railpaper.experiments.lateral_vehicle.simulate_lateral`), so each record has a
matched (linear-plant) twin: the paired comparison.  The filters are the chapter's, unchanged
(known track input, the chapter's Q and R): ``lateral_ekf`` with ``ekf_converged``, and
``run_lateral_rbpf`` with the working scheme, all of
:mod:`railpaper.experiments.rbpf_parameter_estimation.experiment`.
The errors are relative to the plant's θ, whose λ is the small-amplitude conicity; the record's
equivalent conicity is reported next to them.

Measurement chains (``chain``): ``"paper"`` — sample at 1/dt_s (the paper's 1000 Hz), add the
sensor noise, then low-pass causally (the paper filtered the acquired data, noise included);
``"paper_zero_phase"`` — the same, forward-backward (offline, no delay); ``"sensor"`` — low-pass
the truth at the plant's rate, sample, add white noise (a filter inside the sensor).

What the study finds (the EKF's and the RBPF's rates under the truth plant against the matched
plant, per component) is on the chapter's page, computed by the run.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

from railpaper import contact, sensors, track
from railpaper.data import load_quantities
from railpaper.experiments.base import no_progress
from railpaper.experiments.lateral_vehicle import RecordSettings
from railpaper.experiments.rbpf_parameter_estimation import lateral
from railpaper.experiments.rbpf_parameter_estimation.result import LateralRecord
from railpaper.experiments.rbpf_parameter_estimation.spec import SPEC, Settings
from railpaper.experiments.records import RecordStudy, normalised
from railpaper.models import lateral_16state
from railpaper.models import lateral_truth
from railpaper.paths import DATA_DIR
from railpaper.settling import holds_from
from railpaper.stats import rate
from railpaper.threads import one_thread

MISMATCH_KEYS = ("friction_coefficient", "gravity", "wheel_load", "conicity_length_scale",
                 "lowpass_cutoff", "lowpass_order")
COMPONENTS = ("creep", "conicity", "lowpass")
CHAINS = ("paper", "paper_zero_phase", "sensor")
START = 350                      # the paper's claim: every parameter within 5 % after 350 steps


@dataclass(frozen=True)
class MismatchResult:
    """Outcome of :func:`run_mismatch`.

    Attributes
    ----------
    metrics : dict
        Name -> value (see :func:`run_mismatch`); rates are fractions (1) with 95 %
        Clopper–Pearson intervals in ``_low``/``_high`` and the record count in ``_n``.
    records : DataFrame
        One row per (plant, record): ``plant`` ("mismatch" / "matched"), ``seed``,
        ``ekf_converged`` (first guess, bool), ``ekf_converged_count`` (of the guesses run on
        that record), ``ekf_diverged`` / ``ekf_diverged_count`` (the run stopped on
        non-finite or |θ̂| > 1e12 values), ``rbpf_all_within`` (working scheme, every
        parameter within 5 % from step 350 to the end, bool), ``rbpf_final_error_<param>``
        and ``ekf_final_error_<param>`` (θ̂/θ − 1 at the last step, 1; NaN if the EKF
        diverged), and on mismatch rows
        ``saturation_max`` (largest β = |F_lin|/(μN), 1), ``displacement_max_m`` (largest
        |d|, m), ``conicity_ratio`` (λ_eq(√2 rms d)/λ, 1) and ``model_error_<channel>``
        (noise-free RMS of mismatch minus linear-plant measurements over the channel's noise
        std, 1).
    rbpf : dict of str to list of ndarray
        Plant -> per record, working-scheme θ̂/θ at steps 1..n_steps, shape (K, 5).
    ekf_first : dict of str to list of ndarray
        Plant -> the EKF runs (θ̂/θ, (K, 5), NaN if diverged) of every guess on the first record.
    settings : dict
        What was simulated: ``components``, ``chain``, ``friction`` (1), ``wheel_load_N``,
        ``conicity_scale_m``, ``lowpass_cutoff_hz``, ``lowpass_order``.
    timings : dict
        Wall time per part, s.

    :meth:`study_rows` gives the mismatch plant's records as the study :data:`MODEL_ERROR`'s rows.
    """

    metrics: dict
    records: pd.DataFrame
    rbpf: dict
    ekf_first: dict
    settings: dict
    timings: dict = field(default_factory=dict)

    def study_rows(self) -> pd.DataFrame:
        """The mismatch plant's records as the rows of the study :data:`MODEL_ERROR`
        (:func:`study_row`: the same computation, seed by seed; CSV round trip exact)."""
        mismatch = self.records[self.records.plant == "mismatch"]
        return normalised(pd.DataFrame([study_row(row, {})
                                        for row in mismatch.to_dict("records")]))


def mismatch_settings(path: Path | None = None, components=COMPONENTS,
                      chain: str = "paper") -> dict:
    """The truth plant's settings from ``mismatch.toml`` (components left out become linear)."""
    unknown = set(components) - set(COMPONENTS)
    if unknown or chain not in CHAINS:
        raise ValueError(f"components must be among {COMPONENTS} and chain one of {CHAINS}, "
                         f"got {tuple(components)!r}, {chain!r}")
    q = load_quantities(path or DATA_DIR / SPEC.name / "mismatch.toml", MISMATCH_KEYS)
    return dict(components=tuple(c for c in COMPONENTS if c in components), chain=chain,
                friction=q["friction_coefficient"].value if "creep" in components else np.inf,
                wheel_load_N=q["wheel_load"].value,
                conicity_scale_m=(q["conicity_length_scale"].value if "conicity" in components
                                  else np.inf),
                lowpass_cutoff_hz=q["lowpass_cutoff"].value,
                lowpass_order=int(q["lowpass_order"].value))


def track_input(settings: Settings, fixed: dict, seed: int) -> np.ndarray:
    """ẏt under both wheelsets at the truth rate, (K_fine + 1, 2), m/s — the chapter's
    :func:`~railpaper.experiments.lateral_vehicle.simulate_lateral` input (same
    profile for the same seed; ``tests/experiments/rbpf_parameter_estimation/test_mismatch.py`` checks the records agree)."""
    v = settings.speed_kmh / 3.6
    dtf = settings.dt_s / settings.truth_substeps
    dur = settings.n_steps * settings.dt_s
    length = max(v * dur + 2 * fixed["a"] + 10.0, 1.05 * settings.wavelength_max_m)
    s, z = track.synthesize_profile(settings.spectrum, "alignment", length,
                                    min(0.05, settings.wavelength_min_m / 2), seed=seed,
                                    wavelength_min_m=settings.wavelength_min_m,
                                    wavelength_max_m=settings.wavelength_max_m)
    return track.wheelset_inputs(s, z, v, [0.0, 2 * fixed["a"]], dtf, dur, derivative=True)[2]


def chain_output(signal_fine: np.ndarray, noise: np.ndarray, settings: Settings, st: dict
                 ) -> np.ndarray:
    """Measurements (n_steps, 5) at dt_s from the plant's channels on the fine grid.

    ``signal_fine[k]`` is the channel vector at fine time k dt_fine (k = 0..), ``noise`` the
    sensor noise at the filter samples.  Row k-1 belongs to filter step k (time k dt_s).
    """
    sub, n = settings.truth_substeps, settings.n_steps
    if "lowpass" not in st["components"]:
        return signal_fine[sub::sub][:n] + noise
    filt = dict(cutoff_hz=st["lowpass_cutoff_hz"], order=st["lowpass_order"])
    if st["chain"] == "sensor":
        smooth = sensors.lowpass(signal_fine, sample_rate_hz=sub / settings.dt_s, **filt)
        return smooth[sub::sub][:n] + noise
    # from rest: a zero sample at t = 0 (the plant is at rest) would leave the filter at rest
    return sensors.lowpass(signal_fine[sub::sub][:n] + noise, sample_rate_hz=1.0 / settings.dt_s,
                           zero_phase=st["chain"] == "paper_zero_phase", **filt)


def simulate_mismatch(settings: Settings, fixed: dict, theta: np.ndarray, seed: int, st: dict
                      ) -> tuple[LateralRecord, dict]:
    """One record of the truth plant with settings ``st`` (:func:`mismatch_settings`).

    Returns
    -------
    record : LateralRecord
        What the filters are given, as
        :func:`~railpaper.experiments.lateral_vehicle.simulate_lateral` returns it.
    diagnostics : dict
        The plant's size on this record (see :class:`MismatchResult` ``records``).
    """
    v, sub = settings.speed_kmh / 3.6, settings.truth_substeps
    dtf = settings.dt_s / sub
    dq = track_input(settings, fixed, seed)
    wr = lateral_truth.WheelRail(st["friction"], st["wheel_load_N"], st["conicity_scale_m"])
    x = lateral_truth.simulate_truth(fixed, theta, v, dtf, dq[:-1], wr)
    plant = lateral_truth.TruthPlant(fixed, theta, v, wr)
    rng = np.random.default_rng([seed, 7])                  # the chapter's noise draws
    std = lateral.noise_std(RecordSettings.of(settings))
    noise = rng.standard_normal((settings.n_steps, 5)) * std
    y = chain_output(plant.measurements(x), noise, settings, st)
    # noise-free model error against the linear plant, in units of each channel's noise std
    x_lin = lateral_16state.simulate_truth(fixed, theta, v, dtf, dq[:-1])
    H = lateral_16state.measurement_matrix(lateral_16state.build_A_direct(fixed, theta, v))
    lin = x_lin @ H.T
    zero = np.zeros_like(noise)
    err = (chain_output(plant.measurements(x), zero, settings, st)
           - chain_output(lin, zero, settings, dict(st, components=())))  # what the filters expect
    d = x[:, 14:16]
    rms_d = float(np.sqrt(np.mean(d ** 2)))
    scale = st["conicity_scale_m"]
    diag = dict(saturation_max=float(plant.saturation(x).max()),
                displacement_max_m=float(np.abs(d).max()),
                conicity_ratio=float(contact.equivalent_conicity(np.sqrt(2) * rms_d, 1.0, scale))
                if np.isfinite(scale) and rms_d > 0 else 1.0,
                **{f"model_error_{c}": float(e) for c, e in
                   zip(lateral_16state.CHANNELS, np.sqrt(np.mean(err ** 2, axis=0)) / std)})
    record = LateralRecord(seed=seed, y=y, u_mps=dq[0:-1:sub][:settings.n_steps],
                                   du_var_m2ps2=np.diff(dq[::sub], axis=0).var(axis=0),
                                   u_var_m2ps2=dq.var(axis=0))
    return record, diag


def _filter_record(settings: Settings, fixed, theta, rec, seed, guesses
                   ) -> tuple[dict, np.ndarray, list]:
    """Working-scheme RBPF and ``guesses`` EKF runs on one record; the row of ``records``."""
    norm = lateral.run_lateral_rbpf(settings, fixed, theta, rec, seed, "working")
    ekf = lateral.lateral_ekf(settings, fixed, theta, rec, seed, guesses)
    row = dict(seed=seed, ekf_converged=lateral.ekf_converged(ekf[0]),
               ekf_converged_count=int(sum(map(lateral.ekf_converged, ekf))),
               ekf_diverged=lateral.ekf_diverged(ekf[0]),
               ekf_diverged_count=int(sum(map(lateral.ekf_diverged, ekf))),
               rbpf_all_within=bool(holds_from(np.abs(norm - 1.0) <= lateral.WITHIN, START).all()),
               **lateral.final_errors(norm, "rbpf_final_error_"),
               **lateral.final_errors(ekf[0], "ekf_final_error_"))
    return row, norm, ekf


def plant_metrics(rows: pd.DataFrame, runs: list, ekf_first: list, suffix: str,
                  guesses: int) -> dict:
    """Metrics of one plant from its per-record rows (see :func:`run_mismatch`)."""
    out = {f"ekf_lateral_converged_count{suffix}": int(sum(map(lateral.ekf_converged,
                                                               ekf_first)))}
    if guesses == 10:
        out[f"ekf_lateral_converged_of_10{suffix}"] = out[f"ekf_lateral_converged_count{suffix}"]
    out[f"ekf_lateral_diverged_count{suffix}"] = int(sum(map(lateral.ekf_diverged, ekf_first)))
    out.update(rate(rows.ekf_converged.to_numpy(bool))
               .metrics(f"lateral_ekf_converge_rate{suffix}"))
    out.update(rate(rows.rbpf_all_within.to_numpy(bool))
               .metrics(f"lateral_all_within_5pct_fraction{suffix}"))
    out.update(lateral.lateral_metrics(pd.DataFrame([lateral.scheme_row(seed, norm, START)
                                                     for seed, norm in zip(rows.seed, runs)]),
                                       f"_working_scheme{suffix}"))
    return out


def study_row(row: dict, diag: dict) -> dict:
    """A record's row of the study :data:`MODEL_ERROR` from its ``records`` row and the plant's
    diagnostics: the first EKF guess's outcome (``ekf_converged``, ``ekf_diverged``, its final
    errors), the working-scheme RBPF's (``rbpf_all_within``: every parameter within 5 % from
    step 350; its final errors), and the plant's size — not the counts over several EKF
    guesses, which only the first record has."""
    return {k: v for k, v in dict(row, **diag).items()
            if k not in ("plant", "ekf_converged_count", "ekf_diverged_count")}


def model_error_rows(settings: Settings, seeds) -> pd.DataFrame:
    """The study :data:`MODEL_ERROR`'s rows: the chapter's truth plant (every component, the
    paper's measurement chain) on each record of ``seeds``, filtered by one EKF guess and the
    working-scheme RBPF, as :func:`run_mismatch` filters it."""
    st = mismatch_settings()
    fixed, theta = lateral.vehicle()
    rows = []
    with one_thread():
        for seed in seeds:
            rec, diag = simulate_mismatch(settings, fixed, theta, int(seed), st)
            row, _, _ = _filter_record(settings, fixed, theta, rec, int(seed), 1)
            rows.append(study_row(row, diag))
    return pd.DataFrame(rows)


#: The truth plant with model error (the paper's "line data" reading), one row per record.
MODEL_ERROR = RecordStudy("rbpf-parameter-estimation", "model_error", model_error_rows,
                          chunk_records=1)


def run_mismatch(settings: Settings, n_records: int | None = None, *, components=COMPONENTS,
                 chain: str = "paper", matched: bool = True, ekf_guesses_per_record: int = 1,
                 mismatch_path: Path | None = None, progress=None) -> MismatchResult:
    """EKF (``ekf_guesses`` guesses on the first record) and working-scheme RBPF on the truth
    plant, and on the matched linear plant of the same seeds.

    Parameters
    ----------
    settings : Settings
        The chapter's settings (``n_steps`` >= 350).
    n_records : int, optional
        Records (seeds ``settings.seed``, ``settings.seed + 1``, …; >= 2); default
        ``settings.n_records``.
    components : iterable of str
        Which of :data:`COMPONENTS` the truth plant has (the others stay linear).
    chain : str
        Measurement chain of the low-pass, one of :data:`CHAINS` (module docstring).
    matched : bool
        Also filter the chapter's linear-plant records of the same seeds.
    ekf_guesses_per_record : int
        EKF guesses on records after the first (the chapter: 1).
    mismatch_path : path, optional
        Another ``mismatch.toml``.
    progress : callable, optional
        ``progress(fraction, message)``.

    Returns
    -------
    MismatchResult
        ``metrics`` for plant suffix ``_mismatch`` (and ``_matched``):
        ``ekf_lateral_converged_count`` / ``ekf_lateral_converged_of_10`` (first record, as the
        chapter's) and ``ekf_lateral_diverged_count`` (of those guesses, runs that stopped),
        ``lateral_ekf_converge_rate`` (first guess, over records),
        ``lateral_all_within_5pct_fraction`` (working scheme, over records), the chapter's
        :func:`~railpaper.experiments.rbpf_parameter_estimation.lateral.lateral_metrics` with suffix
        ``_working_scheme<plant>``; paired counts ``rbpf_within_lost_mismatch`` /
        ``rbpf_within_gained_mismatch`` and ``ekf_converged_lost_mismatch`` /
        ``ekf_converged_gained_mismatch`` (records where the outcome flips from the matched to
        the mismatch plant); and the plant's size ``mismatch_saturation_max``,
        ``mismatch_displacement_max_m``, ``mismatch_conicity_ratio_median``,
        ``mismatch_model_error_median_<channel>`` (1, see ``records``).
    """
    progress = progress or no_progress
    n_records = int(settings.n_records if n_records is None else n_records)
    if n_records < 2 or settings.n_steps < START:
        raise ValueError(f"run_mismatch needs n_records >= 2 and n_steps >= {START}")
    st = mismatch_settings(mismatch_path, components, chain)
    fixed, theta = lateral.vehicle()
    plants = ("mismatch", "matched") if matched else ("mismatch",)
    rows, rbpf, ekf_first = [], {k: [] for k in plants}, {}
    timings = {f"{k}_{part}_s": 0.0 for k in plants for part in ("simulate", "filter")}
    with one_thread():
        for i in range(n_records):
            seed = settings.seed + i
            for plant in plants:
                progress(i / n_records, f"record {i}, {plant} plant")
                t0 = time.perf_counter()
                rec, diag = (simulate_mismatch(settings, fixed, theta, seed, st)
                             if plant == "mismatch" else
                             (lateral.simulate_lateral(RecordSettings.of(settings), fixed, theta,
                                                       seed), {}))
                t1 = time.perf_counter()
                guesses = settings.ekf_guesses if i == 0 else ekf_guesses_per_record
                row, norm, ekf = _filter_record(settings, fixed, theta, rec, seed, guesses)
                timings[f"{plant}_simulate_s"] += t1 - t0
                timings[f"{plant}_filter_s"] += time.perf_counter() - t1
                rows.append(dict(plant=plant, **row, **diag))
                rbpf[plant].append(norm)
                if i == 0:
                    ekf_first[plant] = ekf
    records = pd.DataFrame(rows)
    metrics = {}
    for plant in plants:
        metrics.update(plant_metrics(records[records.plant == plant], rbpf[plant],
                                     ekf_first[plant], f"_{plant}", settings.ekf_guesses))
    mm = records[records.plant == "mismatch"].set_index("seed")
    if matched:
        ma = records[records.plant == "matched"].set_index("seed")
        for col, name in (("rbpf_all_within", "rbpf_within"), ("ekf_converged", "ekf_converged")):
            metrics[f"{name}_lost_mismatch"] = int((ma[col] & ~mm[col]).sum())
            metrics[f"{name}_gained_mismatch"] = int((~ma[col] & mm[col]).sum())
    metrics["mismatch_saturation_max"] = float(mm.saturation_max.max())
    metrics["mismatch_displacement_max_m"] = float(mm.displacement_max_m.max())
    metrics["mismatch_conicity_ratio_median"] = float(mm.conicity_ratio.median())
    for c in lateral_16state.CHANNELS:
        metrics[f"mismatch_model_error_median_{c}"] = float(mm[f"model_error_{c}"].median())
    progress(1.0, "done")
    return MismatchResult(metrics=metrics, records=records, rbpf=rbpf, ekf_first=ekf_first,
                          settings=st, timings=timings)


__all__ = ["CHAINS", "COMPONENTS", "MODEL_ERROR", "MismatchResult", "chain_output", "mismatch_settings",
           "plant_metrics", "run_mismatch", "simulate_mismatch", "track_input"]
