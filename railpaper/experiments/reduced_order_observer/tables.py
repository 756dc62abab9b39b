"""Tables of chapter ``reduced-order-observer`` as the page shows them (Markdown, units in headers).

Every function takes the run's named results or metrics and returns Markdown: numbers to four
significant digits, "never" instead of the -1 of a convergence time that never happened, text in
full (no truncation), wide tables transposed.
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from railpaper.data import data_path, load_quantities
from railpaper.experiments.display import markdown, number, seconds  # noqa: F401 - re-exported
from railpaper.experiments.reduced_order_observer import spec
from railpaper.experiments.reduced_order_observer.spec import ESTIMATORS, Settings
from railpaper.models import single_wheelset


def parameter_table(vehicle_readings: dict[str, single_wheelset.SingleWheelset]) -> str:
    """Table 1's parameters with units and sources, and the derived contact quantities of each
    reading of P0 (``{reading: vehicle}``)."""
    quantities = load_quantities(data_path("reduced-order-observer/parameters.toml"))
    rows = [(k.replace("_", " "), number(q.value), q.unit, q.source + (f"; {q.note}" if q.note else ""))
            for k, q in quantities.items()]
    first = next(iter(vehicle_readings.values()))
    rows.append(("Hertz constant G", number(first.hertz_constant_m_per_N23), "m/N^(2/3)",
                 "Table 1 formula G = 3.86 R^(−0.115) · 10^(−8), R = 0.42 m"))
    for reading, v in vehicle_readings.items():
        rows.append((f"static load P0 per contact (P0 per {reading})", number(v.static_wheel_load_N),
                     "N", f"(M_c + M_w) g / {v.contacts}"))
        rows.append((f"contact stiffness K_r (P0 per {reading})",
                     number(v.contact_stiffness_N_per_m), "N/m",
                     f"{v.contacts} · 3/(2G) · P0^(1/3) (Eq. 3)"))
    return markdown(pd.DataFrame(rows, columns=["parameter", "value", "unit", "source"]))


def errata_table(errata: pd.DataFrame) -> str:
    """The errata (location, printed, correction, reason), numbered E1, E2, …"""
    frame = errata.copy()
    frame.insert(0, "erratum", [f"E{i + 1}" for i in range(len(frame))])
    return markdown(frame)


def rank_table(metrics: dict) -> str:
    """The ranks the paper quotes, per reading of P0: exact (rational arithmetic), numpy's
    floating-point rank of the Kalman matrix (default tolerance) and the PBH rank."""
    rows = []
    for name, what in (("Q0", "rank Q0 = [B AB A²B A³B] (paper: 4)"),
                       ("Q1", "rank Q1 = [C; CA; CA²; CA³] (paper: 4)"),
                       ("reduced", "rank [A12; A12·A22] (reduced pair, needs 2)")):
        for reading in spec.READINGS:
            rows.append((what, f"P0 per {reading}", metrics[f"rank_{name}_exact_{reading}"],
                         metrics[f"rank_{name}_numpy_{reading}"],
                         metrics[f"rank_{name}_pbh_{reading}"]))
    return markdown(pd.DataFrame(rows, columns=["test", "reading", "exact rank",
                                                "numpy rank (default tolerance)", "PBH rank"]))


def speed_sweep_table(sweep: pd.DataFrame, observer_form: str) -> str:
    """The one-record speed sweep, transposed: one column per speed."""
    other = "foh" if observer_form == "paper" else "paper"
    names = {"paper": "paper observer (ZOH)", "foh": "FOH observer"}
    rows = [
        (f"convergence time, {names[observer_form]} (s)", "convergence_time_s", seconds, 1),
        (f"convergence time, {names[other]} (s)", f"convergence_time_s_{other}", seconds, 1),
        ("convergence time, error equation alone (s)", "predicted_convergence_time_s", seconds, 1),
        (f"RMS force error, {names[observer_form]} (kN)", "force_rms_error_N", number, 1e-3),
        (f"RMS force error, {names[other]} (kN)", f"force_rms_error_N_{other}", number, 1e-3),
        ("RMS dynamic force (kN)", "force_rms_N", number, 1e-3),
        (f"RMS displacement error, {names[observer_form]} (µm)", "displacement_rms_error_m",
         number, 1e6),
        ("RMS wheelset displacement z_w (mm)", "z_w_rms_m", number, 1e3),
        ("samples with contact lost (%)", "contact_lost_fraction", number, 100.0),
    ]
    table = {"quantity": [r[0] for r in rows]}
    for _, s in sweep.iterrows():
        table[f"{s.speed_kmh:g} km/h"] = [
            fmt(s[col]) if fmt is seconds else fmt(s[col] * scale) for _, col, fmt, scale in rows]
    return markdown(pd.DataFrame(table))


#: Rows of :func:`evidence_table`: metric stem and what it is.
EVIDENCE_ROWS = (
    ("mc_convergence_time_s_worst", "convergence time, worse of the two speeds (s)"),
    ("mc_displacement_relative_rms_error_worst", "RMS displacement error / RMS z_w, worse speed"),
    ("mc_force_relative_rms_error_worst", "RMS force error / RMS force, worse speed"),
    ("mc_trend_convergence_time_rho", "ρ(speed, convergence time)"),
    ("mc_trend_predicted_convergence_time_rho", "ρ(speed, convergence time of the error equation)"),
    ("mc_trend_force_rms_error_fixed_noise_rho", "ρ(speed, RMS force error), noise fixed"),
    ("mc_trend_force_rms_error_rho", "ρ(speed, RMS force error), noise ∝ channel RMS"),
    ("mc_trend_force_relative_rms_error_rho", "ρ(speed, RMS force error / RMS force)"),
    ("mc_trend_force_rms_rho", "ρ(speed, RMS dynamic force)"),
)


def evidence_table(metrics: dict) -> str:
    """The Monte Carlo statistics the claims read, per reading of P0: median over seeds with its
    95 % order-statistic interval and the number of seeds."""
    rows = []
    for stem, what in EVIDENCE_ROWS:
        for reading in spec.READINGS:
            k = f"{stem}_{reading}"
            if k not in metrics:                  # trends need at least two speeds
                continue
            rows.append((what, f"P0 per {reading}", number(metrics[k]),
                         f"[{number(metrics[k + '_low'])}, {number(metrics[k + '_high'])}]",
                         metrics[f"{k}_n"]))
    return markdown(pd.DataFrame(rows, columns=["statistic", "reading", "median over seeds",
                                                "95 % interval", "seeds"]))


def noise_table(noise_sweep: pd.DataFrame) -> str:
    """Force and displacement errors of the paper's observer against the sensor noise."""
    rows = [(number(r.noise_fraction * 100), number(r.force_relative_rms_error),
             number(r.displacement_rms_error_m * 1e6)) for r in noise_sweep.itertuples()]
    return markdown(pd.DataFrame(rows, columns=["sensor noise σ (% of channel RMS)",
                                                "RMS force error / RMS force",
                                                "RMS displacement error (µm)"]))


def plant_table(plants: pd.DataFrame) -> str:
    """Linear vs Hertz plant (noise-free, FOH observer): what linearising the contact costs."""
    rows = [(number(r.speed_kmh), r.plant, number(r.force_rms_N / 1e3),
             number(r.force_rms_error_N_foh_observer / 1e3),
             number(r.force_rms_error_N_foh_observer / r.force_rms_N),
             number(100 * r.contact_lost_fraction)) for r in plants.itertuples()]
    return markdown(pd.DataFrame(rows, columns=[
        "speed (km/h)", "plant", "RMS dynamic force (kN)", "RMS force error, FOH observer (kN)",
        "RMS error / RMS force", "samples with contact lost (%)"]))


def percent(ratio: float) -> str:
    """A ratio as a percentage to three significant digits (0.000394 → "0.0394 %")."""
    return f"{number(100 * ratio, 3)} %"


def estimator_table(metrics: dict, settings: Settings) -> str:
    """RMS force error / RMS force of each estimator at the run's sensor noise: median over the
    Monte Carlo seeds with its 95 % interval, one column per speed."""
    rows = []
    for name, label in ESTIMATORS.items():
        row = [label]
        for speed in settings.speeds_kmh:
            k = f"mc_force_rms_error_ratio_{name}_{speed:g}kmh"
            row.append(f"{percent(metrics[k])} [{number(100 * metrics[k + '_low'], 3)}, "
                       f"{number(100 * metrics[k + '_high'], 3)}]")
        rows.append(row)
    n = metrics[f"mc_force_rms_error_ratio_kalman_{settings.speeds_kmh[0]:g}kmh_n"]
    columns = ["estimator"] + [f"{s:g} km/h: RMS error / RMS force, median [95 % interval] over "
                               f"{n} seeds" for s in settings.speeds_kmh]
    return markdown(pd.DataFrame(rows, columns=columns))


def what_works(result, settings: Settings, transient_s: float = 0.1) -> dict[str, str]:
    """Numbers of the chapter's closing section, as text: at the first and the last of the run's
    speeds (``speed_first``, ``speed_last``) the estimators' median ratios with intervals
    (``<estimator>_first``, ``<estimator>_last``); at the first speed, the Kalman filter's
    median ratio at each noise level on q with that noise in µm (``track_<i>``), and each
    estimator's RMS error over the first ``transient_s`` of seed ``seed``'s record
    (``transient_<estimator>``), relative to the RMS force over the error window."""
    m, out = result.metrics, {}
    for which, speed in (("first", settings.speeds_kmh[0]), ("last", settings.speeds_kmh[-1])):
        out[f"speed_{which}"] = f"{speed:g} km/h"
        for name in ("observer", "kalman", "smoother"):
            k = f"mc_force_rms_error_ratio_{name}_{speed:g}kmh"
            out[f"{name}_{which}"] = (f"{percent(m[k])} [{number(100 * m[k + '_low'], 3)}, "
                                      f"{number(100 * m[k + '_high'], 3)} %]")
    speed = settings.speeds_kmh[0]
    s = result.estimators.samples
    track = s[(s.sweep == "track") & (s.speed_kmh == speed) & (s.estimator == "kalman")]
    for i, (fraction, t) in enumerate(track.groupby("track_noise_fraction")):
        out[f"track_{i}"] = (f"{number(100 * fraction, 2)} % of the RMS of q (about "
                             f"{number(fraction * t.q_rms_m.median() * 1e6, 2)} µm) gives "
                             f"{percent(t.ratio.median())}")
    e = result.estimators.examples[speed]
    force_rms = np.sqrt(np.mean(e.force_true_N[e.t_s >= settings.error_window_start_s] ** 2))
    early = e.t_s < transient_s
    for name in ("observer", "kalman", "smoother"):
        error = getattr(e, f"{name}_N")[early] - e.force_true_N[early]
        out[f"transient_{name}"] = f"{number(np.sqrt(np.mean(error ** 2)) / force_rms, 2)}×"
    return out
