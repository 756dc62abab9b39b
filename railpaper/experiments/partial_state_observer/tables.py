"""Tables of chapter ``partial-state-observer`` as the page shows them (Markdown, units in headers).

Every function takes the run's named results and returns Markdown: four significant digits,
"never" for a convergence time that never happened (-1 in the data), text in full, wide tables
transposed.
"""

from __future__ import annotations

import re

import numpy as np
import pandas as pd

from railpaper.data import data_path, load_quantities
from railpaper.experiments.display import markdown, number, seconds

__all__ = ["markdown", "number", "seconds", "parameter_table", "modal_table", "existence_table",
           "rank_table", "observer_table", "median_table", "alpha_sweep_table"]

ESTIMATOR_NAMES = {"paper": "paper's observer (uses q)", "hb0": "observer with H B = 0 (no q)",
                   "kalman": "Kalman filter (no q)", "q": "ẑ = q",
                   "paper_noisefree": "paper's observer, noise-free",
                   "paper_fixednoise": "paper's observer, speed-independent noise"}


def parameter_table(reading: str, vehicle) -> str:
    """Table 1's parameters (the ``reading``'s suspension) with units and sources, and the
    derived contact quantities of ``vehicle``."""
    q = load_quantities(data_path("partial-state-observer/parameters.toml"))
    q.update(load_quantities(data_path("partial-state-observer/suspension_readings.toml"),
                             section=reading))
    rows = [(re.sub(r"_(kg_m2|kg|N_per_m|Ns_per_m|m_per_s2|m)$", "", k).replace("_", " "),
             number(v.value), v.unit, v.source) for k, v in q.items()]
    rows += [("Hertz constant G", number(vehicle.hertz_constant_m_per_N23), "m/N^(2/3)",
              "3.86 R^-0.115 × 10⁻⁸, R = 0.4575 m"),
             ("static wheel load P0", number(vehicle.static_wheel_load_N), "N",
              "(M_c/4 + M_t/2 + M_w) g / 2"),
             ("contact stiffness per wheelset", number(vehicle.contact_stiffness_N_per_m), "N/m",
              "2 · 3/(2G) P0^(1/3)"),
             ("axle positions", ", ".join(number(a) for a in vehicle.axle_offsets_m), "m",
              "0, 2 l_t, 2 l_c, 2 l_c + 2 l_t")]
    return markdown(pd.DataFrame(rows, columns=["parameter", "value", "unit", "source"]))


def modal_table(modes: pd.DataFrame) -> str:
    """The model's modes: undamped, natural and damped frequency (Hz), damping ratio, poles."""
    rows = [(r.mode, number(r.undamped_Hz), number(r.natural_Hz), number(r.damping_ratio),
             number(r.damped_Hz), r.poles_per_s) for r in modes.itertuples()]
    return markdown(pd.DataFrame(rows, columns=[
        "mode", "undamped (Hz)", "natural (Hz)", "damping ratio", "damped (Hz)", "poles (1/s)"]))


def existence_table(existence: pd.DataFrame) -> str:
    """Darouach's conditions for each measurement set (yes/no instead of True/False)."""
    frame = existence.copy()
    for col in frame.columns:
        if frame[col].dtype == bool:
            frame[col] = frame[col].map({True: "yes", False: "no"})
    return markdown(frame)


def rank_table(claims: pd.DataFrame) -> str:
    """The paper's rank statements after Eq. (13) against ours, with the reason."""
    return markdown(claims.fillna(""))


def observer_table(paper, hb0, B: np.ndarray) -> str:
    """Poles (1/s), relative residual of ``NH + JC = HA`` and max |H B| of both observers."""
    def poles(obs):
        return ", ".join(number(p, 4) for p in np.sort(obs.poles.real))
    rows = [("paper's (uses q)", poles(paper), number(paper.residual, 2), number(np.abs(paper.HB).max(), 3)),
            ("H B = 0 (no q)", poles(hb0), number(hb0.residual, 2), number(np.abs(hb0.H @ B).max(), 3))]
    return markdown(pd.DataFrame(rows, columns=["observer", "real parts of the poles of N (1/s)",
                                                "‖NH + JC − HA‖ / ‖HA‖", "max abs(H B)"]))


def median_table(mc: pd.DataFrame, reading: str) -> str:
    """Monte Carlo medians per estimator (rows) and speed (columns) for one reading."""
    own = mc[mc.reading == reading]
    med = own.groupby(["estimator", "speed_kmh"])[
        ["convergence_time_s", "max_error_after_1s_m", "mean_relative_error"]].median()
    speeds = sorted(own.speed_kmh.unique())
    head = ["estimator", "quantity"] + [f"{s:g} km/h" for s in speeds]
    rows = []
    for name in [n for n in ESTIMATOR_NAMES if n in med.index.get_level_values(0)]:
        m = med.loc[name]
        rows.append((ESTIMATOR_NAMES[name], "convergence time (s)",
                     *(seconds(m.convergence_time_s[s]) for s in speeds)))
        rows.append(("", "max error after 1 s (mm)",
                     *(number(1e3 * m.max_error_after_1s_m[s]) for s in speeds)))
        rows.append(("", "mean relative error (%)",
                     *(number(100 * m.mean_relative_error[s]) for s in speeds)))
    return markdown(pd.DataFrame(rows, columns=head))


def alpha_sweep_table(sweep: pd.DataFrame) -> str:
    """Convergence time (s, noisy record) for each α (rows) and speed (columns)."""
    noisy = sweep[sweep.noisy]
    speeds = sorted(noisy.speed_kmh.unique())
    rows = []
    for alpha, g in noisy.groupby("alpha_per_s", sort=True):
        g = g.set_index("speed_kmh")
        rows.append((number(alpha), number(g.slowest_rate_per_s.iloc[0]),
                     "yes" if g.hb_zero_feasible.iloc[0] else "no",
                     *(seconds(g.convergence_time_s[s]) for s in speeds)))
    return markdown(pd.DataFrame(rows, columns=[
        "α (1/s)", "slowest designed rate (1/s)", "H B = 0 feasible"]
        + [f"{s:g} km/h (s)" for s in speeds]))
