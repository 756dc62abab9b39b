"""Monte Carlo evidence of chapter ``partial-state-observer``: the statistics its claim rules read.

Each Monte Carlo run is one seed (track profile and sensor noise) at one speed under one reading
of Table 1.  :func:`run_measures` turns one run's estimate into numbers; :func:`evidence_metrics`
turns the table of runs into the ``mc_*`` metrics of ``metrics.json`` (medians, rates and paired
trends over seeds with 95 % intervals, :mod:`railpaper.stats`).  Nothing here decides a verdict:
``data/partial-state-observer/claims.toml`` does.

Definitions (wheelsets 1-4; ``win``: t ≥ the error window start, 1 s)
----------------------------------------------------------------------
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
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from railpaper import stats, track
from railpaper.data import data_path, load_quantities, values
from railpaper.estimators import functional_observer as fo
from railpaper.models import vertical_10dof as v10
from railpaper.settling import settling_time_s

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

def existence_table(model: v10.Model) -> pd.DataFrame:
    """Darouach's conditions for z = [z_w1 … z_w4] with each measurement set."""
    rows = []
    for name in v10.MEASUREMENT_SETS:
        C = model.output_matrix(name)
        ex = fo.existence(model.A, C, model.L)
        rows.append({"measurement set": name, "outputs": C.shape[0],
                     "rank [CA; C; L]": ex["rank_CA_C_L"], "rank [LA; CA; C; L]": ex["rank_LA_CA_C_L"],
                     "condition 1": ex["condition1"],
                     "rank-drop points Re s ≥ 0": int(np.sum(ex["pencil_zeros"].real >= 0)),
                     "condition 2": ex["condition2"], "observer exists": ex["exists"]})
    return pd.DataFrame(rows)


def ranks(model: v10.Model) -> dict:
    """The ranks the paper quotes after Eq. (13), ours (C = its acceleration matrix).

    Controllability is tested by PBH on the scaled model: the Kalman matrix [B AB … A¹⁹B] of
    the unscaled model spans ~1e100 and its numerical rank is meaningless (returned too).
    """
    Ca, L = model.output_matrix("accelerations"), model.L
    sc = fo.scaling_for(model.A, model.output_matrix("both"), L)
    At, Bt, _, _ = sc.apply(model.A, model.B, model.output_matrix("both"), L)
    pbh = min(fo.numerical_rank(np.hstack([lam * np.eye(20) - At, Bt])) for lam in np.linalg.eigvals(At))
    matrix = int(np.linalg.matrix_rank(np.hstack([np.linalg.matrix_power(model.A, k) @ model.B
                                                  for k in range(20)])))
    return {"rank_Q0_pbh": pbh, "rank_Q0_matrix": matrix,
            "rank_C_printed": fo.numerical_rank(Ca * sc.S[None, :]), "rank_L": fo.numerical_rank(L),
            "rank_CLt_printed": fo.numerical_rank(Ca @ L.T)}


def rank_claims(model: v10.Model) -> pd.DataFrame:
    """The ranks the paper quotes after Eq. (13) beside ours, as a table."""
    r = ranks(model)
    rows = [("rank(Q0), controllability", 20, r["rank_Q0_pbh"],
             f"PBH on the scaled model; the unscaled Kalman matrix gives a numerical rank of "
             f"{r['rank_Q0_matrix']}"),
            ("rank(C)", 20, r["rank_C_printed"], "C is 6×20: its rank cannot exceed 6"),
            ("rank(L)", 4, r["rank_L"], ""),
            ("rank(C Lᵀ)", 10, r["rank_CLt_printed"], "C Lᵀ is 6×4: its rank cannot exceed 4")]
    return pd.DataFrame(rows, columns=["quantity", "paper", "ours", "note"])


def printed_lmi19(model: v10.Model) -> dict:
    """Whether the LMI (19) as printed can hold (see :func:`printed_lmi19_blocks`)."""
    C = model.output_matrix(MEASUREMENT)
    sc = fo.scaling_for(model.A, C, model.L)
    At, _, Ct, Lt = sc.apply(model.A, model.B, C, model.L)
    par = fo.parametrise(At, Ct, Lt)
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


def wheelset_rms(model: v10.Model, spectrum: str, band_m: tuple[float, float],
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


def wheelset_similarity(model: v10.Model, spectrum: str, band_m: tuple[float, float],
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
