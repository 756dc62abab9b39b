"""Figures of chapter ``quasi-gaussian-rbpf`` (7 in wide, legends outside the data, display names).

Each function takes the run's
:class:`~railpaper.experiments.quasi_gaussian_rbpf.result.QuasiGaussianRBPFResult` and its
settings and returns a matplotlib figure; the notebook saves it and shows it as a numbered MyST
figure.  The parameters ``a``, ``b`` and their errors are dimensionless.
"""

from __future__ import annotations

import matplotlib.pyplot as plt
import numpy as np
from matplotlib.ticker import FuncFormatter, NullFormatter

from railpaper.experiments.display import legend_below
from railpaper.experiments.quasi_gaussian_rbpf.result import ReadingsStudy
from railpaper.experiments.quasi_gaussian_rbpf.spec import (
    NAMES,
    PAPER_STEPS,
    PARAMS,
    STYLES,
    Settings,
    true_values,
)

WIDTH_IN = 7.0
#: The paper's final errors (Section IV, discussion of Figs 1–4); its steps: spec.PAPER_STEPS.
PAPER_ERRORS = {"a": {"qgrbpf": 0.066, "rbpf": 0.167}, "b": {"qgrbpf": -0.055, "rbpf": -0.067}}
#: Steps shown in the close-up of the first steps (holds the paper's steps 4 and 53-55).
WINDOW_STEPS = 80
#: Colour of the paper's values (convergence steps, final errors are in the filters' colours).
PAPER_COLOR = "C4"


def line_widths(settings: Settings) -> dict[str, float]:
    """Line width per filter: the Q-GRBPF of the other reading of Eq. (10) than
    ``eq10_reading`` is drawn thin."""
    thin = "qgrbpf_printed" if settings.eq10_reading == "ratio" else "qgrbpf"
    return {name: 0.8 if name == thin else 1.3 for name in STYLES}


def _paper_steps(ax, par: str) -> None:
    labels = {"qgrbpf": "paper: Q-GRBPF converges (step 4)",
              "rbpf": "paper: RBPF converges (step 55 for a, 53 for b)"}
    for name, ls in (("qgrbpf", "-"), ("rbpf", "--")):
        ax.axvline(PAPER_STEPS[(par, name)], color=PAPER_COLOR, ls=ls, lw=1.0, label=labels[name])


def estimates(result, settings: Settings):
    """Estimates of a and b on the main record with the exact posterior (paper Figs 1–2): the
    first :data:`WINDOW_STEPS` steps (left) and the whole record (right)."""
    rec, widths = result.main, line_widths(settings)
    steps = rec.steps
    fig, axes = plt.subplots(2, 2, figsize=(WIDTH_IN, 6.6), sharey="row",
                             gridspec_kw={"width_ratios": [1, 1.35]})
    for row, j, par in zip(axes, range(2), PARAMS):
        mean, std = rec.exact.mean[:, j], rec.exact.std[:, j]
        for ax, stop in zip(row, (min(WINDOW_STEPS, len(steps)), len(steps))):
            k = slice(0, stop)
            ax.fill_between(steps[k], (mean - 2 * std)[k], (mean + 2 * std)[k], color="0.82",
                            label="exact posterior mean ± 2 std")
            ax.plot(steps[k], mean[k], color="k", lw=1.2, label="exact posterior mean")
            for name, (color, ls) in STYLES.items():
                ax.plot(steps[k], rec.runs[name].theta_mean[k, j], color=color, ls=ls,
                        lw=widths[name], label=NAMES[name])
            ax.axhline(true_values(settings)[par], color="k", ls=":", lw=1, label="true value")
        _paper_steps(row[0], par)
        row[0].set(ylabel=f"estimate of {par} (1)",
                   title=f"{par}: first {min(WINDOW_STEPS, len(steps))} steps")
        row[1].set_title(f"{par}: whole record (paper Fig. {1 + j})")
    for ax in axes[1]:
        ax.set_xlabel("step k")
    fig.tight_layout(rect=(0, 0.17, 1, 1))
    legend_below(fig, axes[0, 0])
    return fig


def errors(result, settings: Settings):
    """Estimation errors on the main record (paper Figs 3–4), symlog, with the exact
    posterior's ±2 std band and the paper's final errors over the horizons they can be from."""
    rec, widths = result.main, line_widths(settings)
    steps, short = rec.steps, min(settings.short_horizon, len(rec.steps))
    fig, axes = plt.subplots(2, 1, figsize=(WIDTH_IN, 6.4), sharex=True)
    for ax, j, par in zip(axes, range(2), PARAMS):
        truth = true_values(settings)[par]
        err, std = rec.exact.mean[:, j] - truth, rec.exact.std[:, j]
        ax.fill_between(steps, err - 2 * std, err + 2 * std, color="0.82",
                        label="exact posterior mean ± 2 std")
        for name, (color, ls) in STYLES.items():
            ax.plot(steps, rec.runs[name].theta_mean[:, j] - truth, color=color, ls=ls,
                    lw=widths[name], label=NAMES[name])
        for name, mark in (("qgrbpf", "Q-GRBPF"), ("rbpf", "RBPF")):
            ax.hlines(PAPER_ERRORS[par][name], short, steps[-1], color=STYLES[name][0], lw=2.2,
                      alpha=0.45, label=f"paper's final error, {mark} (from step {short} on)")
        ax.axvline(short, color=PAPER_COLOR, ls="--", lw=1.0,
                   label=f"step {short}: shortest horizon of the paper's figures")
        ax.axhline(0, color="k", lw=0.8)
        ax.set_yscale("symlog", linthresh=0.05)
        low, high = ax.get_ylim()
        ticks = [t for t in (-1, -0.3, -0.1, 0, 0.1, 0.3, 1) if low <= t <= high]
        ax.set_yticks(ticks, [f"{t:g}".replace("-", "−") for t in ticks])
        ax.yaxis.set_minor_formatter(NullFormatter())
        ax.set(ylabel=f"error of {par} (1)", title=f"{par} (paper Fig. {3 + j})")
    axes[1].set_xlabel("step k")
    fig.tight_layout(rect=(0, 0.16, 1, 1))
    legend_below(fig, axes[0])
    return fig


def spread_ratio(result, settings: Settings):
    """Each filter's parameter std over the exact posterior's, main record: every filter on a
    log scale (left) and a linear close-up around 1 (right)."""
    rec, widths = result.main, line_widths(settings)
    fig, axes = plt.subplots(2, 2, figsize=(WIDTH_IN, 5.6), sharex=True)
    for row, j, par in zip(axes, range(2), PARAMS):
        for name, (color, ls) in STYLES.items():
            ratio = rec.runs[name].theta_std[:, j] / rec.exact.std[:, j]
            for ax in row:
                ax.plot(rec.steps, ratio, color=color, ls=ls, lw=widths[name], label=NAMES[name])
        for ax in row:
            ax.axhline(1, color="k", lw=0.8, label="calibrated (ratio 1)")
        row[0].set(yscale="log", ylabel=f"std of {par}: filter /\nexact posterior")
        row[1].set_ylim(bottom=0)
    axes[0, 0].set_title("every filter (log scale)")
    axes[0, 1].set_title("close-up around 1 (linear)")
    for ax in axes[1]:
        ax.set_xlabel("step k")
    fig.tight_layout(rect=(0, 0.14, 1, 1))
    legend_below(fig, axes[0, 0])
    return fig


def monte_carlo_errors(result, settings: Settings):
    """Over the Monte Carlo records: final errors (left) and final distances from the exact
    posterior mean in posterior std (right, log), horizontal boxes per filter."""
    mc = result.monte_carlo
    names = ["posterior"] + list(STYLES)
    fig, axes = plt.subplots(2, 2, figsize=(WIDTH_IN, 5.8), sharey=True)
    for row, par in zip(axes, PARAMS):
        row[0].boxplot([mc[f"final_error_{par}_{n}"] for n in names][::-1], vert=False,
                       widths=0.6)
        row[0].axvline(0, color="k", lw=0.8)
        row[0].set(xlabel=f"final error of {par} (1)")
        z = [np.abs(mc[f"final_z_{par}_{n}"]) for n in names[1:]][::-1]
        row[1].boxplot(z, positions=range(1, len(names)), vert=False, widths=0.6)
        row[1].axvline(2, color="k", ls=":", lw=1)
        row[1].set(xscale="log", xlabel=f"|final {par} − posterior mean| / posterior std")
    for ax in axes[:, 0]:
        ax.set_yticks(range(1, len(names) + 1), [NAMES[n] for n in names][::-1])
    fig.tight_layout()
    return fig


def settling(result, settings: Settings):
    """Distribution over records of the settling step of every filter and of the exact
    posterior mean (log axis), with the paper's steps."""
    mc, tol = result.monte_carlo, settings.tolerance_to_truth
    fig, axes = plt.subplots(2, 1, figsize=(WIDTH_IN, 5.8), sharex=True)
    for ax, par in zip(axes, PARAMS):
        for name in ["posterior"] + list(STYLES):
            color, ls = STYLES.get(name, ("k", ":"))
            steps = np.sort(mc[f"settling_step_{par}_{name}"])
            ax.step(steps, np.arange(1, len(steps) + 1) / len(steps), where="post", color=color,
                    ls=ls, lw=1.5 if name == "posterior" else 1.2,
                    label="exact posterior mean" if name == "posterior" else NAMES[name])
        _paper_steps(ax, par)
        ax.set(xscale="log", ylabel="fraction of records", ylim=(0, 1.03), title=par)
    axes[1].xaxis.set_major_formatter(FuncFormatter(lambda v, _: f"{v:g}"))
    axes[1].set_xlabel(f"settling step (the estimate stays within ±{tol:g} of its final value)")
    fig.tight_layout(rect=(0, 0.16, 1, 1))
    legend_below(fig, axes[0])
    return fig


def computing_time(result, settings: Settings):
    """Seconds per step against N (left) and the paired ratios at the paper's N (right)."""
    curves, pairs = result.computing_time.curves_s_per_step, result.computing_time.paired_s_per_step
    fig, (ax, bx) = plt.subplots(1, 2, figsize=(WIDTH_IN, 3.9),
                                 gridspec_kw={"width_ratios": [1.1, 1]})
    for name, (color, ls) in STYLES.items():
        d = curves[curves["filter"] == name]
        ax.loglog(d.n_particles, d.seconds_per_step * 1e3, marker="o", ms=4, color=color, ls=ls,
                  label=NAMES[name])
    counts = sorted(curves.n_particles.unique())
    ax.set_xticks(counts, [str(n) for n in counts])
    ax.xaxis.set_minor_formatter(NullFormatter())
    ax.yaxis.set_major_formatter(FuncFormatter(lambda v, _: f"{v:g}"))
    ax.yaxis.set_minor_formatter(NullFormatter())
    ax.set(xlabel="particles N", ylabel="computing time per step (ms)")
    ratios = {"Q-GRBPF,\nratio": pairs.qgrbpf / pairs.rbpf,
              "Q-GRBPF,\nprinted": pairs.qgrbpf_printed / pairs.rbpf,
              "one re-\nsampling": pairs.resampling / pairs.rbpf}
    bx.boxplot(list(ratios.values()), widths=0.6)
    bx.set_xticks(range(1, 4), list(ratios))
    bx.axhline(0.44, color=PAPER_COLOR, ls="--", lw=1, label="paper: 56 % less (ratio 0.44)")
    bx.set(ylabel="time / time of one RBPF step", ylim=(0, None),
           title=f"{len(pairs)} paired repeats, N = {settings.timing_ratio_particles}")
    handles = ax.get_legend_handles_labels()
    extra = bx.get_legend_handles_labels()
    fig.tight_layout(rect=(0, 0.17, 1, 1))
    fig.legend(handles[0] + extra[0], handles[1] + extra[1], loc="lower center", ncol=2,
               frameon=False)
    return fig


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
