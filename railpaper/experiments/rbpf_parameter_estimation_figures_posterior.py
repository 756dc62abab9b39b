"""Figures of the rbpf-parameter-estimation chapter's exact posterior and model-error sections,
each from a run's result and resolved parameters; 7 in wide, legends outside the data."""

from __future__ import annotations

import matplotlib.pyplot as plt
import numpy as np

from railpaper.experiments.display import legend_below
from railpaper.experiments.rbpf_parameter_estimation_figures import WINDOW_S
from railpaper.experiments.rbpf_parameter_estimation_tables import PARAM_LABELS
from railpaper.models.lateral_16state import PARAM_NAMES

Z90 = 1.6448536269514722
#: Display names and colours of the three estimators against the posterior.
ESTIMATORS = {"posterior": ("exact posterior (IBIS): mean (black), 90 % interval", "k"),
              "paper": ("RBPF, paper's scheme: mean ± 1.645 sd", "C3"),
              "working": ("RBPF, our tempered scheme: mean ± 1.645 sd", "C0")}


def _band(ax, t, mean, low, high, key):
    label, color = ESTIMATORS[key]
    if key == "posterior":
        ax.fill_between(t, low, high, color="C2", alpha=0.35, lw=0, label=label)
        ax.plot(t, mean, color=color, lw=1.1)
    else:
        ax.plot(t, mean, color=color, lw=1.0, label=label)
        for edge in (low, high):
            ax.plot(t, edge, color=color, lw=0.6, ls="--")


def posterior_vs_filters(result, params):
    """The illustrated lateral record: for each parameter, the exact posterior's mean and 90 %
    interval and both RBPF schemes' mean ± 1.645 sd, normalised by the true value, over the
    whole record (left) and from 0.3 s on (right, the window of the paper's 350-step claim)."""
    lat = result.lateral
    run, t = lat.illustrated, lat.t_s
    post = run.posterior
    fig, axes = plt.subplots(5, 2, figsize=(7, 9.4), sharex="col",
                             gridspec_kw={"width_ratios": [1.25, 1]})
    zoom = t >= WINDOW_S - 0.05
    series = {"posterior": (post.mean, post.q05, post.q95),
              "paper": (run.rbpf_paper_norm, run.rbpf_paper_norm - Z90 * run.rbpf_paper_sd_norm,
                        run.rbpf_paper_norm + Z90 * run.rbpf_paper_sd_norm),
              "working": (run.rbpf_working_norm,
                          run.rbpf_working_norm - Z90 * run.rbpf_working_sd_norm,
                          run.rbpf_working_norm + Z90 * run.rbpf_working_sd_norm)}
    for j, name in enumerate(PARAM_NAMES):
        for col, mask in enumerate((slice(None), zoom)):
            ax = axes[j, col]
            for key, (mean, low, high) in series.items():
                _band(ax, t[mask], mean[mask, j], low[mask, j], high[mask, j], key)
            ax.axhspan(0.95, 1.05, color="0.93", zorder=0, label="±5 % of the true value")
            ax.axhline(1.0, color="0.3", lw=0.6)
            ax.axvline(WINDOW_S, color="k", ls=":", lw=1)
        axes[j, 0].set_ylabel(f"{PARAM_LABELS[name]} / true (1)")
    axes[0, 0].set_title(f"record {params['seed']}: the whole record")
    axes[0, 1].set_title("from 0.3 s (step 350 dotted)")
    for ax in axes[-1]:
        ax.set_xlabel("time (s)")
    fig.tight_layout(rect=(0, 0.07, 1, 1))
    legend_below(fig, axes[0, 0], ncol=2)
    return fig


def ekf_model_error(result, params):
    """The EKF from every initial guess on the first record: the linear plant (the filter's own
    model, top) and the truth plant with model error (bottom), one panel per parameter; a note
    instead on a user's record (no truth plant)."""
    if result.mismatch is None:
        fig, ax = plt.subplots(figsize=(7, 1.2))
        ax.text(0.5, 0.5, "no truth plant: this run filtered a record of the user's",
                ha="center", va="center")
        ax.set_axis_off()
        return fig
    rows = (("linear plant (the filters' model)", result.lateral.illustrated.ekf_norm),
            ("truth plant with model error (same track, same sensor noise)",
             result.mismatch.ekf_first["mismatch"]))
    fig = plt.figure(figsize=(7, 4.8), layout="constrained")
    for sub, (title, runs) in zip(fig.subfigures(2, 1, hspace=0.04), rows):
        sub.suptitle(f"{len(runs)} initial guesses, record {params['seed']}: {title}",
                     fontsize=9.5)
        axes = sub.subplots(1, 5, sharex=True)
        for j, (ax, name) in enumerate(zip(axes, PARAM_NAMES)):
            for r in runs:
                ax.plot(np.arange(1, len(r) + 1) * params["dt_s"], r[:, j], color=f"C{j}",
                        lw=0.7, alpha=0.8)
            ax.axhspan(0.95, 1.05, color="0.8", zorder=0)
            ax.axhline(1.0, color="0.3", lw=0.6)
            ax.set_title(PARAM_LABELS[name], fontsize=9.5)
            ax.set_xlabel("time (s)")
            ax.tick_params(labelsize=8.5)
        axes[0].set_ylabel("estimate / true (1)")
    return fig


__all__ = ["ESTIMATORS", "ekf_model_error", "posterior_vs_filters"]
