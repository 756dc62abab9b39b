"""Monte Carlo evidence of chapter ``partial-state-observer``: the statistics its claim rules read.

Each Monte Carlo run is one seed (track profile and sensor noise) at one speed under one reading
of Table 1; a record (one seed: :mod:`~railpaper.experiments.partial_state_observer.records`,
where the numbers of a run are defined) is a row of the numbers of its runs.  This module is the
reduce: :func:`runs_table` reshapes the records' rows into one row per run, and
:func:`monte_carlo_metrics` (through :func:`evidence_metrics`) turns them into the ``mc_*``
metrics of ``metrics.json`` (medians, rates and paired trends over seeds with 95 % intervals,
:mod:`railpaper.stats`) and the percentiles of the selected reading's max errors.  Nothing here
decides a verdict: ``data/partial-state-observer/claims.toml`` does.  The deterministic evidence
(existence, ranks, the printed LMI (19), the wheelsets' stationary RMS) follows.
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from railpaper import stats, track
from railpaper.estimators import functional_observer
from railpaper.experiments.partial_state_observer.records import (
    MEASUREMENT,
    MEASURES,
    MONTE_CARLO_ESTIMATORS,
    READINGS,
    record_column,
)
from railpaper.experiments.partial_state_observer.spec import Settings
from railpaper.models import vertical_10dof

#: The columns of the table of runs (:func:`runs_table`), in order.
RUN_COLUMNS = ("reading", "seed", "speed_kmh", "estimator") + MEASURES + (
    "predicted_convergence_s",)


def _by_run(table: pd.DataFrame, measure: str, speeds, estimator: str, reading: str) -> np.ndarray:
    """One measure of ``table``'s runs, seed-major then speed: ``values[seed * n_speeds + j]``."""
    return np.column_stack([table[record_column(measure, s, estimator, reading)].to_numpy()
                            for s in speeds]).ravel()


def runs_table(rows: pd.DataFrame, kalman_rows: pd.DataFrame | None,
               settings: Settings) -> pd.DataFrame:
    """One row per run (reading, seed, speed, estimator) of the records' rows.

    Parameters
    ----------
    rows : DataFrame
        The records of :data:`~railpaper.experiments.partial_state_observer.records.MONTE_CARLO`,
        one per seed.
    kalman_rows : DataFrame or None
        The Kalman baseline's records of the selected reading (``settings.suspension_reading``),
        one per seed (often fewer seeds than ``rows``).
    settings : Settings
        The run's settings (speeds, selected reading).

    Returns
    -------
    DataFrame
        Columns :data:`RUN_COLUMNS`, rows by reading, estimator, seed (as given), speed
        (ascending); ``predicted_convergence_s`` is -1 where the estimator has no error dynamics
        of its own.
    """
    speeds = sorted(settings.speeds_kmh)
    blocks = []
    for reading in READINGS:
        estimators = [(name, rows) for name in MONTE_CARLO_ESTIMATORS]
        if reading == settings.suspension_reading and kalman_rows is not None and len(kalman_rows):
            estimators.append(("kalman", kalman_rows))
        for name, table in estimators:
            n = len(table)
            predicted = record_column("predicted_convergence_s", speeds[0], name, reading)
            blocks.append(pd.DataFrame(
                {"reading": reading, "seed": np.repeat(table["seed"].to_numpy(), len(speeds)),
                 "speed_kmh": np.tile(np.asarray(speeds, float), n), "estimator": name}
                | {m: _by_run(table, m, speeds, name, reading) for m in MEASURES}
                | {"predicted_convergence_s": (
                    _by_run(table, "predicted_convergence_s", speeds, name, reading)
                    if predicted in table.columns else np.full(n * len(speeds), -1.0))}))
    return pd.concat(blocks, ignore_index=True)[list(RUN_COLUMNS)]


def monte_carlo_metrics(rows: pd.DataFrame, kalman_rows: pd.DataFrame | None,
                        settings: Settings) -> dict:
    """The chapter's Monte Carlo metrics from its records' rows (the reduce): the ``mc_*``
    metrics of every reading (:func:`evidence_metrics`) and, for the selected reading, the 5th
    and 95th percentiles over seeds of each estimator's max error after 1 s at each speed
    (``max_error_after_1s_m_<speed>kmh[_hb0|_kalman|_q]_p05``, ``_p95``).  Arguments as for
    :func:`runs_table`."""
    mc = runs_table(rows, kalman_rows, settings)
    out = {}
    for reading in READINGS:
        out.update(evidence_metrics(mc, reading))
    own = mc[mc.reading == settings.suspension_reading]
    suffix = {"paper": "", "kalman": "_kalman", "hb0": "_hb0", "q": "_q"}
    for speed in settings.speeds_kmh:
        for name, suf in suffix.items():
            sub = own[(own.speed_kmh == speed) & (own.estimator == name)]["max_error_after_1s_m"]
            out[f"max_error_after_1s_m_{speed:g}kmh{suf}_p05"] = float(np.percentile(sub, 5))
            out[f"max_error_after_1s_m_{speed:g}kmh{suf}_p95"] = float(np.percentile(sub, 95))
    return out


def by_seed_and_speed(mc: pd.DataFrame, reading: str, estimator: str, column: str) -> np.ndarray:
    """``values[seed, speed]`` (seeds and speeds ascending) of one column of the runs table."""
    sub = mc[(mc.reading == reading) & (mc.estimator == estimator)]
    table = sub.pivot(index="seed", columns="speed_kmh", values=column).sort_index()
    table = table[sorted(table.columns)]
    if table.isna().any().any():
        raise ValueError(f"runs table lacks {estimator}/{column} for some seed and speed")
    return table.to_numpy(dtype=float)


#: (metric stem, estimator, column) of every paired trend over speeds.
TRENDS = (
    ("mc_trend_convergence_time_rho", "paper", "convergence_time_s"),
    ("mc_trend_convergence_time_fixed_threshold_rho", "paper", "convergence_time_fixed_s"),
    ("mc_trend_convergence_time_fixed_threshold_noisefree_rho", "paper_noisefree",
     "convergence_time_fixed_s"),
    ("mc_trend_max_error_rho", "paper", "max_error_after_1s_m"),
    ("mc_trend_max_error_fixednoise_rho", "paper_fixednoise", "max_error_after_1s_m"),
    ("mc_trend_max_error_noisefree_rho", "paper_noisefree", "max_error_after_1s_m"),
    ("mc_trend_tracking_rho", "paper", "relative_rms_error"),
    ("mc_trend_tracking_fixednoise_rho", "paper_fixednoise", "relative_rms_error"),
    ("mc_trend_tracking_noisefree_rho", "paper_noisefree", "relative_rms_error"),
    ("mc_trend_oscillation_rho", "paper", "rms_error_m"),
    ("mc_trend_oscillation_fixednoise_rho", "paper_fixednoise", "rms_error_m"),
    ("mc_trend_oscillation_noisefree_rho", "paper_noisefree", "rms_error_m"),
)


def evidence_metrics(mc: pd.DataFrame, reading: str) -> dict:
    """The ``mc_*`` metrics of one reading from the runs table.

    Parameters
    ----------
    mc : DataFrame
        One row per run: ``reading, seed, speed_kmh, estimator`` and the columns of
        :func:`run_measures`; every seed at every speed for the estimators used here.
    reading : str
        Which reading's runs; the metric names end in ``_<reading>``.
    """
    out = {}
    speeds = sorted(mc.speed_kmh.unique())
    for name, estimator in (("mc_convergence_time_s", "paper"), ("mc_convergence_time_s_hb0", "hb0")):
        per_seed = by_seed_and_speed(mc, reading, estimator, "convergence_time_s").mean(axis=1)
        out.update(stats.median_interval(per_seed).metrics(f"{name}_{reading}"))
    converged = by_seed_and_speed(mc, reading, "paper", "converged")
    out.update(stats.proportion_interval(int(converged.sum()), converged.size)
               .metrics(f"mc_converged_rate_{reading}"))
    for stem, estimator, column in TRENDS if len(speeds) > 1 else ():   # a trend needs 2 speeds
        values_ = by_seed_and_speed(mc, reading, estimator, column)
        out.update(stats.paired_trend(values_).metrics(f"{stem}_{reading}"))
        # the same trend with power: mean per-seed least-squares slope (column unit per km/h)
        out.update(stats.paired_slope(values_, speeds).metrics(
            f"{stem.removesuffix('_rho')}_slope_per_kmh_{reading}"))
    for name, estimator, column in (
            ("mc_biggest_mean_relative_error", "paper", "biggest_mean_relative_error"),
            ("mc_biggest_mean_relative_error_noisefree", "paper_noisefree",
             "biggest_mean_relative_error"),
            ("mc_biggest_mean_signed_relative_error", "paper", "biggest_mean_signed_relative_error")):
        top = by_seed_and_speed(mc, reading, estimator, column)[:, -1]
        out.update(stats.median_interval(top).metrics(f"{name}_{reading}"))
    for column in ("convergence_time_s", "max_error_after_1s_m"):
        medians = np.median(by_seed_and_speed(mc, reading, "paper", column), axis=0)
        for speed, value in zip(speeds, medians):
            out[f"mc_median_{column}_{speed:g}kmh_{reading}"] = float(value)
    return out


# ---- deterministic evidence: existence, ranks, the printed LMI (19)

def existence_table(model: vertical_10dof.Model) -> pd.DataFrame:
    """Darouach's conditions for z = [z_w1 … z_w4] with each measurement set."""
    rows = []
    for name in vertical_10dof.MEASUREMENT_SETS:
        C = model.output_matrix(name)
        ex = functional_observer.existence(model.A, C, model.L)
        rows.append({"measurement set": name, "outputs": C.shape[0],
                     "rank [CA; C; L]": ex["rank_CA_C_L"], "rank [LA; CA; C; L]": ex["rank_LA_CA_C_L"],
                     "condition 1": ex["condition1"],
                     "rank-drop points Re s ≥ 0": int(np.sum(ex["pencil_zeros"].real >= 0)),
                     "condition 2": ex["condition2"], "observer exists": ex["exists"]})
    return pd.DataFrame(rows)


def ranks(model: vertical_10dof.Model) -> dict:
    """The ranks the paper quotes after Eq. (13), ours (C = its acceleration matrix).

    Controllability is tested by PBH on the scaled model: the Kalman matrix [B AB … A¹⁹B] of
    the unscaled model spans ~1e100 and its numerical rank is meaningless (returned too).
    """
    Ca, L = model.output_matrix("accelerations"), model.L
    sc = functional_observer.scaling_for(model.A, model.output_matrix("both"), L)
    At, Bt, _, _ = sc.apply(model.A, model.B, model.output_matrix("both"), L)
    pbh = min(functional_observer.numerical_rank(np.hstack([lam * np.eye(20) - At, Bt]))
              for lam in np.linalg.eigvals(At))
    matrix = int(np.linalg.matrix_rank(np.hstack([np.linalg.matrix_power(model.A, k) @ model.B
                                                  for k in range(20)])))
    return {"rank_Q0_pbh": pbh, "rank_Q0_matrix": matrix,
            "rank_C_printed": functional_observer.numerical_rank(Ca * sc.S[None, :]),
            "rank_L": functional_observer.numerical_rank(L),
            "rank_CLt_printed": functional_observer.numerical_rank(Ca @ L.T)}


def rank_claims(model: vertical_10dof.Model) -> pd.DataFrame:
    """The ranks the paper quotes after Eq. (13) beside ours, as a table."""
    r = ranks(model)
    rows = [("rank(Q0), controllability", 20, r["rank_Q0_pbh"],
             f"PBH on the scaled model; the unscaled Kalman matrix gives a numerical rank of "
             f"{r['rank_Q0_matrix']}"),
            ("rank(C)", 20, r["rank_C_printed"], "C is 6×20: its rank cannot exceed 6"),
            ("rank(L)", 4, r["rank_L"], ""),
            ("rank(C Lᵀ)", 10, r["rank_CLt_printed"], "C Lᵀ is 6×4: its rank cannot exceed 4")]
    return pd.DataFrame(rows, columns=["quantity", "paper", "ours", "note"])


def printed_lmi19(model: vertical_10dof.Model) -> dict:
    """Whether the LMI (19) as printed can hold (see :func:`printed_lmi19_blocks`)."""
    C = model.output_matrix(MEASUREMENT)
    sc = functional_observer.scaling_for(model.A, C, model.L)
    At, _, Ct, Lt = sc.apply(model.A, model.B, C, model.L)
    par = functional_observer.parametrise(At, Ct, Lt)
    return printed_lmi19_blocks(par.H1, par.H2)


def printed_lmi19_blocks(H1: np.ndarray, H2: np.ndarray) -> dict:
    """Whether the LMI (19) as printed can be strictly negative definite, for any P and G.

    (19) is ``[[D, P H1, G H2], [H1ᵀ P, 0, 0], [H2ᵀ P, 0, 0]] < 0``: its second and third diagonal
    blocks are zero.  For ``x`` supported on a zero diagonal block, ``xᵀ M x = 0``, so ``M`` can be
    negative definite only if those blocks are empty.
    """
    zero = int(H1.shape[1] + H2.shape[1])
    return {"lmi19_printed_zero_block_size": zero, "lmi19_printed_feasible": zero == 0,
            "lmi19_H1_norm": float(np.linalg.norm(H1))}


def wheelset_rms(model: vertical_10dof.Model, spectrum: str, band_m: tuple[float, float],
                 speed_mps: float, n_points: int = 4000
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Stationary RMS displacement (m), acceleration (m/s²) and contact deflection z_w − q (m),
    each (4,), of the four wheelsets on a track of ``spectrum``.

    The irregularity q(s) reaches wheelset k at s − o_k (``axle_offsets_m``), so for a unit
    harmonic of spatial frequency Ω the wheelsets respond with Z(Ω) = L (jω I − A)⁻¹ B e(Ω),
    ω = Ω V, e_k = exp(−jΩ o_k); with the profile's one-sided PSD S(Ω) on the wavelength band,
    var z_i = ∫ |Z_i(Ω)|² S(Ω) dΩ, var z̈_i = ∫ ω⁴ |Z_i(Ω)|² S(Ω) dΩ and var(z_i − q_i) =
    ∫ |Z_i(Ω) − e_i(Ω)|² S(Ω) dΩ (trapezoid on a log grid of ``n_points``).  No simulation and no
    seed: the exact second moments of the linear model's stationary response.  The displacement
    follows the rail (a stiff contact: RMS deflection ≈ 3e-4 of RMS displacement on FRA class 5);
    the deflection, to which the dynamic contact force is proportional, is the wheelset's own."""
    omega = np.geomspace(2 * np.pi / band_m[1], 2 * np.pi / band_m[0], n_points)   # rad/m
    offsets = np.asarray(model.parameters.axle_offsets_m)
    n = model.A.shape[0]
    resolvent = np.linalg.solve(1j * omega[:, None, None] * speed_mps * np.eye(n) - model.A,
                                np.broadcast_to(model.B, (len(omega),) + model.B.shape))
    delays = np.exp(-1j * omega[:, None] * offsets)
    z = np.einsum("ij,wjk,wk->wi", model.L, resolvent, delays)
    psd = track.psd(spectrum, "vertical", omega)[:, None]
    density = np.abs(z) ** 2 * psd
    acceleration = density * (omega * speed_mps)[:, None] ** 4
    deflection = np.abs(z - delays) ** 2 * psd
    return tuple(np.sqrt(np.trapezoid(d, omega, axis=0))
                 for d in (density, acceleration, deflection))


def wheelset_similarity(model: vertical_10dof.Model, spectrum: str, band_m: tuple[float, float],
                        speeds_kmh) -> dict:
    """The two wheelsets of one frame compared, over the speeds and both bogies, by the largest
    |RMS(w2)/RMS(w1) − 1| and |RMS(w4)/RMS(w3) − 1| of :func:`wheelset_rms`:
    ``wheelset_rms_ratio_max_deviation`` (displacement and acceleration) and
    ``wheelset_deflection_ratio_max_deviation`` (contact deflection z_w − q), 1."""
    worst = {"motion": 0.0, "deflection": 0.0}
    for speed in speeds_kmh:
        displacement, acceleration, deflection = wheelset_rms(model, spectrum, band_m,
                                                              speed / 3.6)
        for key, quantities in (("motion", (displacement, acceleration)),
                                ("deflection", (deflection,))):
            for rms in quantities:
                worst[key] = max(worst[key], abs(rms[1] / rms[0] - 1.0),
                                 abs(rms[3] / rms[2] - 1.0))
    return {"wheelset_rms_ratio_max_deviation": float(worst["motion"]),
            "wheelset_deflection_ratio_max_deviation": float(worst["deflection"])}
