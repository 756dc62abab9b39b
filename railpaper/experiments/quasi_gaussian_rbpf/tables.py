"""Tables and computed sentences of chapter ``quasi-gaussian-rbpf`` as the page shows them.

Every function returns Markdown: 3–4 significant digits, units in the headers, display names of
the filters, text in full.  Monte Carlo statistics are medians (rates) over records with their
95 % intervals, as the chapter's metrics hold them (``name``, ``name_low``, ``name_high``).
"""

from __future__ import annotations

import pandas as pd

from railpaper.data import data_path, load_quantities
from railpaper.experiments.display import markdown, number
from railpaper.experiments.quasi_gaussian_rbpf.evidence import PARAMS
from railpaper.experiments.quasi_gaussian_rbpf.figures import NAMES, STYLES

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


def monte_carlo_table(metrics: dict, params: dict) -> str:
    """Per parameter and statistic (rows), per filter and the exact posterior (columns):
    the median or rate over the Monte Carlo records with its 95 % interval."""
    names = ["posterior"] + list(STYLES)
    short = params["short_horizon"]
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


def collapse_summary(result, params: dict) -> str:
    """Per parameter: the exact posterior's std at step 4 and at the end of the main record,
    and how the printed Q-GRBPF settles, collapses and ends (medians and rates over records)."""
    m, exact, k4 = result.metrics, result.main.exact, min(4, params["n_steps"]) - 1
    lines = []
    for j, par in enumerate(PARAMS):
        lines.append(
            f"* **{par}**: the exact posterior std is {number(exact.std[k4, j], 3)} at step "
            f"{k4 + 1} and {number(exact.std[-1, j], 3)} at step {params['n_steps']} (main "
            f"record); over the records the printed Q-GRBPF settles at step "
            f"{number(m[f'mc_settling_step_{par}_qgrbpf_printed'])} (median), keeps "
            f"{number(m[f'mc_final_std_ratio_{par}_qgrbpf_printed'], 2)} of the posterior's "
            f"spread and ends within 2 posterior std in "
            f"{m[f'mc_within_2std_rate_{par}_qgrbpf_printed']:.0%} of the records (the ratio "
            f"reading in {m[f'mc_within_2std_rate_{par}_qgrbpf']:.0%}, the RBPF in "
            f"{m[f'mc_within_2std_rate_{par}_rbpf']:.0%}).")
    return "\n".join(lines) + "\n"
