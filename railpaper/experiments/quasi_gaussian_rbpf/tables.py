"""Tables and computed sentences of chapter ``quasi-gaussian-rbpf`` as the page shows them.

Every function returns Markdown: 3–4 significant digits, units in the headers, display names of
the filters, text in full.  Monte Carlo statistics are medians (rates) over records with their
95 % intervals, as the chapter's metrics hold them (``name``, ``name_low``, ``name_high``).
"""

from __future__ import annotations

import pandas as pd

from railpaper.data import data_path, load_quantities
from railpaper.experiments.display import markdown, number
from railpaper.experiments.quasi_gaussian_rbpf.result import ReadingsStudy
from railpaper.experiments.quasi_gaussian_rbpf.spec import (
    NAMES,
    PAPER_STEPS,
    PARAMS,
    STYLES,
    Settings,
)


def _meets(row, low: float, high: float) -> bool:
    """The row's 95 % interval of the settling step meets [low, high]."""
    return row.settling_step_low <= high and row.settling_step_high >= low


def possible_horizons(study: ReadingsStudy, reading: str, par: str, step: int) -> list[int]:
    """Figure horizons (steps) at which the exact posterior's median settling step of ``par``
    has a 95 % interval meeting ``step ± 5``: where a calibrated filter can show ``step``."""
    rows = study.table[(study.table.reading == reading) & (study.table.parameter == par)]
    return [int(r.horizon_steps) for r in rows.itertuples()
            if _meets(r, max(step - 5, 1), step + 5)]


def readings_table(study: ReadingsStudy) -> str:
    """Markdown: per reading (the labels of data/quasi-gaussian-rbpf/readings.toml state its Q,
    R and P0), the settling step of ``a`` at each horizon (median [95 %]) and the posterior's
    absolute error and std of ``a`` at step 55 (no ``|`` inside a cell: it would end the
    cell)."""
    head = ["reading"] + [
        f"settling step of a, {h}-step figure" for h in study.horizons_steps] + [
        "abs. error of a at step 55 (median)", "posterior std of a at step 55 (median)"]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for reading in study.readings:
        rows = study.table[(study.table.reading == reading.key) & (study.table.parameter == "a")]
        err = study.errors[(study.errors.reading == reading.key)
                           & (study.errors.parameter == "a")].iloc[0]
        cells = [reading.label]
        cells += [f"{r.settling_step:g} [{r.settling_step_low:g}, {r.settling_step_high:g}]"
                  for r in rows.itertuples()]
        cells += [f"{err.abs_error_rbpf_step:.3g}", f"{err.std_rbpf_step:.3g}"]
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)


def readings_summary(study: ReadingsStudy) -> str:
    """Markdown bullets, computed from the study: under which reading and figure horizon a
    calibrated filter can show the RBPF's step 55 (a) / 53 (b) and the Q-GRBPF's step 4."""
    out, both = [], []
    for reading in study.readings:
        rb = {par: possible_horizons(study, reading.key, par, PAPER_STEPS[(par, "rbpf")])
              for par in PARAMS}
        qg = {par: possible_horizons(study, reading.key, par, 4) for par in PARAMS}
        rb_h = sorted(set(rb["a"]) & set(rb["b"]))
        qg_h = sorted(set(qg["a"]) & set(qg["b"]))
        both += sorted(set(rb_h) & set(qg_h))
        can = ([f"the RBPF's steps 55 / 53 if the figures showed {_list(rb_h)} steps"]
               if rb_h else []) + ([f"the Q-GRBPF's step 4 if the figures showed {_list(qg_h)} steps"]
                                   if qg_h else [])
        cannot = ([] if rb_h else ["the RBPF's steps 55 / 53"]) + (
            [] if qg_h else ["the Q-GRBPF's step 4"])
        text = "; ".join(([f"a calibrated filter can show {'; '.join(can)}"] if can else [])
                         + ([f"no calibrated filter shows {' or '.join(cannot)}"]
                            if cannot else []))
        out.append(f"* **{reading.label}**: {text}.")
    out.append("* " + ("Under no reading and no horizon can a calibrated filter show both the "
                       "RBPF's and the Q-GRBPF's steps: one of the two filters does not follow "
                       "the data." if not both else
                       f"Both steps are possible together at horizons {_list(both)}."))
    return "\n".join(out)


def _list(values) -> str:
    values = [str(v) for v in values]
    return values[0] if len(values) == 1 else ", ".join(values[:-1]) + " or " + values[-1]


__all__ = ["parameter_table", "errata_table", "grid_check", "monte_carlo_table", "timing_table",
           "collapse_summary"]


def parameter_table() -> str:
    """The toy system's and the filters' values with units and where they come from."""
    quantities = load_quantities(data_path("quasi-gaussian-rbpf/parameters.toml"))
    rows = [(f"`{k}`", number(q.value), q.unit, q.source + (f"; {q.note}" if q.note else ""))
            for k, q in quantities.items()]
    return markdown(pd.DataFrame(rows, columns=["parameter", "value", "unit", "source"]))


def errata_table(errata: pd.DataFrame) -> str:
    """The errata (location, as printed, our correction, why), text in full."""
    frame = errata.fillna("").astype(str)
    frame.columns = ["where", "as printed", "our correction", "why"]
    return markdown(frame)


def grid_check(metrics: dict) -> str:
    """One sentence: is the grid fine enough and the prior box wide enough for this run?"""
    return (f"Grid check on this run's main record: the smallest posterior std is "
            f"{number(metrics['grid_min_std_over_spacing'], 3)} grid spacings, and the final "
            f"posterior mass in the outermost cells is {number(metrics['grid_edge_mass'], 2)}.")


def _interval(metrics: dict, key: str, digits: int = 3) -> str:
    return (f"{number(metrics[key], digits)} [{number(metrics[key + '_low'], digits)}, "
            f"{number(metrics[key + '_high'], digits)}]")


def monte_carlo_table(metrics: dict, settings: Settings) -> str:
    """Per parameter and statistic (rows), per filter and the exact posterior (columns):
    the median or rate over the Monte Carlo records with its 95 % interval."""
    names = ["posterior"] + list(STYLES)
    short = settings.short_horizon
    stats = [("median abs. final error of {p} (1)", "mc_abs_final_error_{p}_{n}", True),
             (f"median abs. error of {{p}} at step {short} (1)", "mc_abs_short_error_{p}_{n}",
              True),
             ("median settling step of {p} (step)", "mc_settling_step_{p}_{n}", True),
             ("fraction of records ending within 2 posterior std of {p}",
              "mc_within_2std_rate_{p}_{n}", False),
             ("median final std of {p}: filter / posterior", "mc_final_std_ratio_{p}_{n}", False)]
    rows = []
    for par in PARAMS:
        for label, key, with_posterior in stats:
            rows.append([label.format(p=par)] + [
                _interval(metrics, key.format(p=par, n=n)) if n != "posterior" or with_posterior
                else "—" for n in names])
    return markdown(pd.DataFrame(rows, columns=["statistic"] + [NAMES[n] for n in names]))


def timing_table(curves: pd.DataFrame) -> str:
    """Milliseconds per step of each filter (columns) per particle count (rows), and the
    Q-GRBPF (ratio) / RBPF (paper's scheme) ratio."""
    per = curves.pivot(index="n_particles", columns="filter", values="seconds_per_step")
    names = [n for n in STYLES if n in per.columns]
    rows = [[str(n)] + [number(1e3 * per.loc[n, f], 3) for f in names]
            + [number(per.loc[n, "qgrbpf"] / per.loc[n, "rbpf"], 3)] for n in per.index]
    return markdown(pd.DataFrame(rows, columns=["particles N"]
                                 + [f"{NAMES[f]} (ms per step)" for f in names]
                                 + ["Q-GRBPF (ratio) / RBPF (paper's scheme)"]))


def collapse_summary(result, settings: Settings) -> str:
    """Per parameter: the exact posterior's std at step 4 and at the end of the main record,
    and how the printed Q-GRBPF settles, collapses and ends (medians and rates over records)."""
    m, exact, k4 = result.metrics, result.main.exact, min(4, settings.n_steps) - 1
    lines = []
    for j, par in enumerate(PARAMS):
        lines.append(
            f"* **{par}**: the exact posterior std is {number(exact.std[k4, j], 3)} at step "
            f"{k4 + 1} and {number(exact.std[-1, j], 3)} at step {settings.n_steps} (main "
            f"record); over the records the printed Q-GRBPF settles at step "
            f"{number(m[f'mc_settling_step_{par}_qgrbpf_printed'])} (median), keeps "
            f"{number(m[f'mc_final_std_ratio_{par}_qgrbpf_printed'], 2)} of the posterior's "
            f"spread and ends within 2 posterior std in "
            f"{m[f'mc_within_2std_rate_{par}_qgrbpf_printed']:.0%} of the records (the ratio "
            f"reading in {m[f'mc_within_2std_rate_{par}_qgrbpf']:.0%}, the RBPF in "
            f"{m[f'mc_within_2std_rate_{par}_rbpf']:.0%}).")
    return "\n".join(lines) + "\n"
