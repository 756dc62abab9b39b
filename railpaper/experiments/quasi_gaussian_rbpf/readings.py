"""Which readings of paper 004's Section IV make its convergence steps possible?

The paper's RBPF "converges at step 55" (a) and 53 (b), its Q-GRBPF at step 4, with final errors
0.167 / 0.067 and 0.066 / 0.055.  A calibrated filter cannot settle before the exact posterior
mean does, so the exact posterior (:func:`railpaper.engine.grid_posterior.grid_posterior`)
under each reading of the printed noise settings (``data/quasi-gaussian-rbpf/readings.toml``)
says which of those numbers a working filter could show.  A settling step is read against the
figure's last value, so it also depends on the figure's horizon, lost with the figures: every
reading is evaluated at every horizon of the file.

Per reading, horizon H and parameter: the median over records of the exact posterior mean's
settling step (within ``tolerance`` of its value at H) with its 95 % order-statistic interval, and
the median |error| of the posterior mean at steps 4 and 55 (53 for b).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd

from railpaper.data import read_toml

from railpaper.paths import DATA_DIR
from railpaper.engine.grid_posterior import grid_posterior
from railpaper.models.linear_toys import paper004_system, simulate_paper004
from railpaper.settling import settling_step
from railpaper.stats import median_interval

READINGS_FILE = DATA_DIR / "quasi-gaussian-rbpf" / "readings.toml"
PARAMS = ("a", "b")
#: The paper's steps: (parameter, filter) -> step (Section IV, Figs. 3-4).
PAPER_STEPS = {("a", "rbpf"): 55, ("b", "rbpf"): 53, ("a", "qgrbpf"): 4, ("b", "qgrbpf"): 4}
#: Seed-stream offset: records of this study never share a stream with the chapter's records.
STREAM = 7_004


@dataclass(frozen=True)
class Reading:
    """One reading of the printed noise settings (variances of w, e and the state prior std)."""

    key: str
    label: str
    q_var: float
    r_var: float
    p0_std: float
    source: str


@dataclass(frozen=True)
class ReadingsStudy:
    """The exact posterior's pace under every reading.

    Attributes
    ----------
    readings : tuple of Reading
    horizons_steps : tuple of int
        Figure horizons H (steps) the settling step is read against.
    table : pandas.DataFrame
        One row per (reading, horizon, parameter): ``reading``, ``horizon_steps``, ``parameter``,
        ``settling_step`` (median) with ``settling_step_low``/``_high`` (95 %), ``n_records``.
    errors : pandas.DataFrame
        One row per (reading, parameter): median |posterior mean − truth| at step 4
        (``abs_error_step4``) and at the RBPF's step (``abs_error_rbpf_step``), posterior std at
        both (``std_step4``, ``std_rbpf_step``).
    settling_steps : numpy.ndarray, (readings, horizons, parameters, records)
        Per-record settling steps behind ``table``.
    """

    readings: tuple
    horizons_steps: tuple
    table: pd.DataFrame
    errors: pd.DataFrame
    settling_steps: np.ndarray

    def interval_gap(self, reading: str, par: str, step: int) -> float:
        """:func:`interval_gap` of this study (steps)."""
        return interval_gap(self.table, reading, par, step)

    def metrics(self) -> dict:
        """``reading_<key>_settling_step_<p>_h<H>`` (+ ``_low``, ``_high``, ``_n``),
        ``reading_<key>_interval_gap_<p>_<rbpf|qgrbpf>`` (steps from the paper's step ± 5 to the
        nearest interval; 0 = possible at some horizon) and
        ``reading_<key>_abs_error_<p>_step{4,<rbpf step>}``."""
        m = {}
        for row in self.table.itertuples():
            name = f"reading_{row.reading}_settling_step_{row.parameter}_h{row.horizon_steps}"
            m.update({name: row.settling_step, f"{name}_low": row.settling_step_low,
                      f"{name}_high": row.settling_step_high, f"{name}_n": row.n_records})
        for reading in self.readings:
            for (par, filt), step in PAPER_STEPS.items():
                m[f"reading_{reading.key}_interval_gap_{par}_{filt}"] = self.interval_gap(
                    reading.key, par, step)
        for row in self.errors.itertuples():
            step = PAPER_STEPS[(row.parameter, "rbpf")]
            m[f"reading_{row.reading}_abs_error_{row.parameter}_step4"] = row.abs_error_step4
            m[f"reading_{row.reading}_abs_error_{row.parameter}_step{step}"] = \
                row.abs_error_rbpf_step
        return m


def interval_gap(table: pd.DataFrame, reading: str, par: str, step: int) -> float:
    """Steps between the paper's ``step ± 5`` and the nearest 95 % interval of the posterior's
    median settling step over all horizons (0: some horizon's interval meets it)."""
    rows = table[(table.reading == reading) & (table.parameter == par)]
    low, high = max(step - 5, 1), step + 5
    return float(min(max(0.0, r.settling_step_low - high, low - r.settling_step_high)
                     for r in rows.itertuples()))


def load_readings(path=READINGS_FILE) -> tuple[tuple[Reading, ...], tuple[int, ...]]:
    """The readings and horizons of ``readings.toml``."""
    raw = read_toml(path)
    horizons = tuple(int(h) for h in raw.pop("horizons")["values"])
    if max(horizons) < max(PAPER_STEPS.values()):
        raise ValueError(f"{path}: the longest horizon must reach step {max(PAPER_STEPS.values())}"
                         f" (the paper's RBPF step), got {max(horizons)}")
    readings = tuple(Reading(key, t["label"], float(t["q_var"]), float(t["r_var"]),
                             float(t["p0_std"]), t["source"]) for key, t in raw.items())
    return readings, horizons


def posterior_paths(reading: Reading, truth, lower, upper, n_steps: int, grid_size: int,
                    seed: int, record: int):
    """Exact posterior mean and std (n_steps, 2) of one simulated record under ``reading``."""
    rng = np.random.default_rng(np.random.SeedSequence([seed, STREAM, record]))
    sim = simulate_paper004(truth[0], truth[1], reading.q_var, reading.r_var, reading.p0_std,
                            n_steps, rng)
    exact = grid_posterior(paper004_system(reading.q_var, reading.r_var), sim.y, lower, upper,
                           grid_size, np.zeros(2), reading.p0_std ** 2 * np.eye(2))
    return exact.mean, exact.std


def run_readings(*, truth=(-0.7, 1.5), lower=(-1.0, 1.0), upper=(0.4, 2.8), n_records: int = 40,
                 grid_size: int = 81, tolerance: float = 0.05, seed: int = 0,
                 path=READINGS_FILE, progress=None) -> ReadingsStudy:
    """The exact posterior's settling steps under every reading and horizon.

    Parameters
    ----------
    truth : (a, b)
    lower, upper : (2,)
        Uniform prior box of the chapter.
    n_records : int
        Records per reading (record r uses the stream ``(seed, STREAM, r)`` for every reading).
    grid_size : int
        Grid points per parameter.
    tolerance : float
        Settling band (the chapter's ``tolerance_to_truth``), 1.
    """
    readings, horizons = load_readings(path)
    truth, lower, upper = (np.asarray(v, float) for v in (truth, lower, upper))
    n_steps = max(horizons)
    steps = np.zeros((len(readings), len(horizons), 2, n_records), dtype=int)
    rows, err_rows = [], []
    for i, reading in enumerate(readings):
        abs_err = {p: ([], [], [], []) for p in PARAMS}
        for r in range(n_records):
            mean, std = posterior_paths(reading, truth, lower, upper, n_steps, grid_size, seed, r)
            for j, par in enumerate(PARAMS):
                for h, horizon in enumerate(horizons):
                    steps[i, h, j, r] = settling_step(
                        np.abs(mean[:horizon, j] - mean[horizon - 1, j]) <= tolerance)
                k = PAPER_STEPS[(par, "rbpf")] - 1
                for lst, val in zip(abs_err[par], (abs(mean[3, j] - truth[j]),
                                                   abs(mean[k, j] - truth[j]), std[3, j], std[k, j])):
                    lst.append(val)
        if progress is not None:
            progress(f"readings study: reading {i + 1}/{len(readings)} ({n_records} records)")
        for h, horizon in enumerate(horizons):
            for j, par in enumerate(PARAMS):
                est = median_interval(steps[i, h, j])
                rows.append(dict(reading=reading.key, horizon_steps=horizon, parameter=par,
                                 settling_step=est.value, settling_step_low=est.low,
                                 settling_step_high=est.high, n_records=est.n))
        for par in PARAMS:
            e4, ek, s4, sk = (float(np.median(v)) for v in abs_err[par])
            err_rows.append(dict(reading=reading.key, parameter=par, abs_error_step4=e4,
                                 abs_error_rbpf_step=ek, std_step4=s4, std_rbpf_step=sk))
    return ReadingsStudy(readings=readings, horizons_steps=horizons, table=pd.DataFrame(rows),
                         errors=pd.DataFrame(err_rows), settling_steps=steps)


def plot_readings(study: ReadingsStudy):
    """Median settling step of the exact posterior mean vs the figure's horizon, one line per
    reading, with the paper's RBPF (55 / 53 ± 5) and Q-GRBPF (4 ± 5) steps shaded.

    Returns
    -------
    matplotlib.figure.Figure
    """
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(7, 3.6), sharey=True, layout="constrained")
    markers = "osd^v"
    colours = ("tab:blue", "tab:orange", "black", "tab:purple", "tab:brown")
    for ax, par in zip(axes, PARAMS):
        rbpf = PAPER_STEPS[(par, "rbpf")]
        ax.axhspan(rbpf - 5, rbpf + 5, color="tab:red", alpha=0.15, lw=0)
        ax.axhspan(1, 9, color="tab:green", alpha=0.15, lw=0)
        ax.text(study.horizons_steps[-1], rbpf + 6, f"RBPF: step {rbpf}", ha="right",
                va="bottom", fontsize=8, color="tab:red")
        ax.text(study.horizons_steps[-1], 10, "Q-GRBPF: step 4", ha="right", va="bottom",
                fontsize=8, color="tab:green")
        for reading, marker, colour in zip(study.readings, markers, colours):
            rows = study.table[(study.table.reading == reading.key)
                               & (study.table.parameter == par)]
            h = rows.horizon_steps.to_numpy()
            ax.errorbar(h, rows.settling_step, fmt=f"-{marker}", ms=4, capsize=2,
                        yerr=[rows.settling_step - rows.settling_step_low,
                              rows.settling_step_high - rows.settling_step],
                        color=colour, label=reading.label)
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xticks(study.horizons_steps, [str(h) for h in study.horizons_steps])
        ax.xaxis.set_minor_formatter(plt.NullFormatter())
        ax.set_xlabel("figure horizon (steps)")
        ax.set_title(f"parameter {par}", fontsize=10)
        ax.grid(alpha=0.3, which="both")
    axes[0].set_ylabel("settling step of the\nexact posterior mean")
    fig.legend(*axes[0].get_legend_handles_labels(), loc="outside lower center", ncol=1,
               fontsize=8, frameon=False)
    return fig


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
    """Markdown: per reading, the settling step of ``a`` at each horizon (median [95 %]) and the
    posterior's absolute error and std of ``a`` at step 55 (no ``|`` inside a cell: it would
    end the cell)."""
    head = ["reading", "Q, R variance", "P0 std"] + [
        f"settling step of a, {h}-step figure" for h in study.horizons_steps] + [
        "abs. error of a at step 55 (median)", "posterior std of a at step 55 (median)"]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for reading in study.readings:
        rows = study.table[(study.table.reading == reading.key) & (study.table.parameter == "a")]
        err = study.errors[(study.errors.reading == reading.key)
                           & (study.errors.parameter == "a")].iloc[0]
        cells = [reading.label, f"{reading.q_var:.3g}, {reading.r_var:.3g}",
                 f"{reading.p0_std:.3g}"]
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
