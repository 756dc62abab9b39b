"""Figures of the rbpf-parameter-estimation chapter, each from a run's
:class:`~railpaper.experiments.rbpf_parameter_estimation.result.RbpfParameterEstimationResult` and
its settings (:class:`~railpaper.experiments.rbpf_parameter_estimation.spec.Settings`); 7 in wide,
legends outside the data, display names."""

from __future__ import annotations

import matplotlib.pyplot as plt
import numpy as np

from railpaper.experiments.display import legend_below
from railpaper.experiments.rbpf_parameter_estimation.spec import Settings
from railpaper.experiments.rbpf_parameter_estimation.tables import PARAM_LABELS
from railpaper.models.lateral_16state import PARAM_NAMES

#: Display names and line styles of the three toy filters.
TOY_FILTERS = {"rbpf_paper": ("RBPF, paper scheme", "-"),
               "rbpf_working": ("RBPF, our working scheme", "--"), "ekf": ("augmented EKF", ":")}
#: Display names of the two RBPF schemes.
SCHEMES = {"working": "our working scheme", "paper": "paper's scheme"}
WINDOW_S = 0.35                                    # the paper's 350 steps at 1 ms


def toy_estimates(result, settings: Settings):
    """Eq. (18), one record: the estimates of x1..x4 by the three filters from both initial
    conditions, with the true values (paper Figs 2-5)."""
    toy = result.toy
    step = np.arange(1, toy.steps + 1)
    fig, axes = plt.subplots(2, 2, figsize=(7, 6.4), sharex=True)
    for j, ax in enumerate(axes.flat):
        for ic, color in ((1, "C0"), (2, "C3")):
            run = toy.illustrated[ic]
            for key, (label, ls) in TOY_FILTERS.items():
                marks = dict(marker="o", ms=3, markevery=(10 * ic, 40)) if key == "ekf" else {}
                ax.plot(step, getattr(run, key)[:, j], color=color, ls=ls, lw=1.2,
                        label=f"{label}, initial condition {ic}", **marks)
        ax.axhline(toy.truth[j], color="k", lw=0.8, label="true value")
        ax.set(title=f"$x_{j + 1}$ (paper Fig. {j + 2})", ylabel=f"estimate of $x_{j + 1}$ (1)")
    for ax in axes[1]:
        ax.set_xlabel("step n")
    fig.tight_layout(rect=(0, 0.14, 1, 1))
    legend_below(fig, axes[0, 0], ncol=2)
    return fig


def toy_errors(result, settings: Settings):
    """Eq. (18), every record: final max |error| per filter and initial condition (log scale),
    and the settle steps of the EKF against the RBPF (paper scheme) from initial condition 1."""
    st, K = result.toy.records, result.toy.steps
    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(7, 3.9), gridspec_kw={"width_ratios": [1.5, 1]})
    cols = [("rbpf_err_max", "RBPF\npaper"), ("rbpf_working_err_max", "RBPF\nours"),
            ("ekf_err_max", "EKF")]
    rng = np.random.default_rng(0)                                  # jitter of the dots only
    for i, (ic, (col, _)) in enumerate((ic, c) for ic in (1, 2) for c in cols):
        v = st[st.init == ic][col].to_numpy()
        ax1.scatter(i + rng.uniform(-0.2, 0.2, v.size), v, s=8, color=f"C{i % 3}")
    ax1.set_xticks(range(6), [f"{n}\ninit. {ic}" for ic in (1, 2) for _, n in cols], fontsize=8)
    ax1.axhline(settings.toy_bias_tol, color="k", ls=":", lw=1)
    ax1.text(5.4, settings.toy_bias_tol, " convergence\n tolerance", va="center", fontsize=8)
    ax1.set(yscale="log", xlim=(-0.5, 6.6), ylabel="final max |error| over $x_1..x_4$ (1)",
            title=f"{settings.toy_seeds} records of {K} steps")
    one = st[st.init == 1]
    ax2.scatter(one.rbpf_settle, one.ekf_settle, s=12)
    ax2.plot([0, K + 1], [0, K + 1], color="k", lw=0.8)
    ax2.set(xlim=(0, K + 10), ylim=(0, K + 10), xlabel="RBPF (paper scheme) settle step",
            ylabel="EKF settle step", title=f"initial condition 1 ({K + 1} = never)")
    fig.tight_layout()
    return fig


def critical_speed(result, settings: Settings):
    """Least-damped eigenvalue's real part against speed for three readings of the 'half'
    masses, with the test speed."""
    crit, m = result.lateral.critical_speed, result.metrics
    names = {"chosen": "our reading (only the body halved)",
             "all_halved": "wheelset and bogie masses halved too",
             "wheelset_bogie_doubled": "wheelset and bogie masses doubled"}
    fig, ax = plt.subplots(figsize=(7, 4.2))
    for key, label in names.items():
        vc = m.get(f"critical_speed_kmh_{key}")          # absent: stable to the search's end
        ax.plot(crit.speed_kmh, crit[key],
                label=f"{label}: " + (f"hunting from {vc:.0f} km/h" if vc is not None
                                      else "no hunting"))
    ax.axhline(0, color="k", lw=0.8)
    ax.axvline(settings.speed_kmh, color="0.5", ls=":", label="test speed")
    ax.set(xlabel="speed (km/h)", ylabel="max real part of eigenvalues (1/s)")
    fig.tight_layout(rect=(0, 0.2, 1, 1))
    legend_below(fig, ax, ncol=1)
    return fig


def normalised_estimates(result, settings: Settings):
    """Top: one record's normalised estimates with the range over the records kept in full (the
    first ``n_records``; the records a scheme filtered alone keep only their rows), per scheme.
    Bottom: each of those records' largest relative error (log), the 0-0.35 s window shaded."""
    lateral, t = result.lateral, result.lateral.t_s
    fig, axes = plt.subplots(2, 2, figsize=(7, 7), sharex=True, sharey="row")
    for col, scheme in enumerate(("working", "paper")):
        ax, ax_err = axes[0, col], axes[1, col]
        stack = lateral.stack(f"rbpf_{scheme}_norm")   # the records kept in full, (R, K, 5)
        for j, name in enumerate(PARAM_NAMES):
            ax.plot(t, stack[0, :, j], color=f"C{j}", lw=1.1, label=PARAM_LABELS[name])
            ax.fill_between(t, stack[:, :, j].min(0), stack[:, :, j].max(0), color=f"C{j}",
                            alpha=0.12)
        ax.axhspan(0.95, 1.05, color="0.8", zorder=0, label="±5 %")
        ax.set_title(f"{SCHEMES[scheme]}:\nrecord {settings.seed}, range of {len(stack)}")
        worst = np.abs(stack - 1).max(axis=2)                       # (records, K)
        ax_err.semilogy(t, worst.T, color="C3" if scheme == "paper" else "C2", lw=0.6, alpha=0.6)
        ax_err.axhline(0.05, color="k", lw=1, label="5 %")
        ax_err.set(xlabel="time (s)", title=f"{SCHEMES[scheme]}: {len(stack)} records")
        for a in (ax, ax_err):
            a.axvspan(0, WINDOW_S, color="0.93", zorder=0)
            a.axvline(WINDOW_S, color="k", ls=":", lw=1)
    axes[0, 0].set_ylabel("estimate / true value (1)")
    axes[1, 0].set_ylabel("max over θ of |θ̂/θ − 1| (1)")
    fig.tight_layout(rect=(0, 0.06, 1, 1))
    legend_below(fig, axes[0, 0], ncol=6)
    return fig


def relative_errors(result, settings: Settings):
    """One record (working scheme): |estimate/true - 1| per parameter (log) with the CRLB std
    after 350 steps (dotted) where the true values are known."""
    m, t = result.metrics, result.lateral.t_s
    main = result.lateral.illustrated.rbpf_working_norm
    fig, ax = plt.subplots(figsize=(7, 4.2))
    for j, name in enumerate(PARAM_NAMES):
        ax.plot(t, np.abs(main[:, j] - 1), color=f"C{j}", lw=1.1, label=PARAM_LABELS[name])
        if result.lateral.crlb is not None:
            ax.axhline(m[f"crlb_rel_350_{name}"], color=f"C{j}", ls=":", lw=1)
    ax.axhline(0.05, color="k", lw=1, label="5 %")
    ax.axvline(WINDOW_S, color="k", ls=":", lw=1)
    ax.set(yscale="log", xlabel="time (s)", ylabel="|estimate / true − 1| (1)")
    fig.tight_layout(rect=(0, 0.08, 1, 1))
    legend_below(fig, ax, ncol=6)
    return fig


def final_errors_over_records(result, settings: Settings):
    """Every record's final relative error per parameter (dots) and the mean with its 95 % t
    interval (bars), per scheme."""
    m, lateral = result.metrics, result.lateral
    fig, axes = plt.subplots(1, 2, figsize=(7, 3.8), sharey=True)
    for ax, (scheme, suffix) in zip(axes, (("paper", "_paper_scheme"),
                                           ("working", "_working_scheme"))):
        finals = lateral.final_relative_errors(scheme)              # every record, (R, 5)
        for j, name in enumerate(PARAM_NAMES):
            ax.scatter(np.full(len(finals), j) + np.linspace(-0.2, 0.2, len(finals)),
                       finals[:, j], s=9, color=f"C{j}", alpha=0.7)
            if f"lateral_bias_{name}{suffix}" not in m:             # a user's single record
                continue
            mean, lo, hi = (m[f"lateral_bias_{name}{suffix}{s}"] for s in ("", "_low", "_high"))
            ax.errorbar(j + 0.3, mean, [[mean - lo], [hi - mean]], fmt="o", ms=4, color="k",
                        capsize=3)
        ax.axhspan(-0.05, 0.05, color="0.88", zorder=0)
        ax.set_xticks(range(5), [PARAM_LABELS[n] for n in PARAM_NAMES])
        ax.set_title(f"{SCHEMES[scheme]}: {len(finals)} records")
    axes[0].set_ylabel("final θ̂/θ − 1 (1)")
    fig.tight_layout()
    return fig


def ekf_lateral(result, settings: Settings):
    """The augmented EKF on one record from every initial guess: normalised estimates."""
    fig, ax = plt.subplots(figsize=(7, 3.8))
    for i, r in enumerate(result.lateral.illustrated.ekf_norm):
        for j, name in enumerate(PARAM_NAMES):
            ax.plot(np.arange(1, len(r) + 1) * settings.dt_s, r[:, j], color=f"C{j}", lw=0.7,
                    label=PARAM_LABELS[name] if i == 0 else None)
    ax.axhspan(0.95, 1.05, color="0.8", zorder=0, label="±5 %")
    ax.set(xlabel="time (s)", ylabel="estimate / true value (1)")
    fig.tight_layout(rect=(0, 0.08, 1, 1))
    legend_below(fig, ax, ncol=6)
    return fig


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


def posterior_vs_filters(result, settings: Settings):
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
    axes[0, 0].set_title(f"record {settings.seed}: the whole record")
    axes[0, 1].set_title("from 0.3 s (step 350 dotted)")
    for ax in axes[-1]:
        ax.set_xlabel("time (s)")
    fig.tight_layout(rect=(0, 0.07, 1, 1))
    legend_below(fig, axes[0, 0], ncol=2)
    return fig


def ekf_model_error(result, settings: Settings):
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
        sub.suptitle(f"{len(runs)} initial guesses, record {settings.seed}: {title}",
                     fontsize=9.5)
        axes = sub.subplots(1, 5, sharex=True)
        for j, (ax, name) in enumerate(zip(axes, PARAM_NAMES)):
            for r in runs:
                ax.plot(np.arange(1, len(r) + 1) * settings.dt_s, r[:, j], color=f"C{j}",
                        lw=0.7, alpha=0.8)
            ax.axhspan(0.95, 1.05, color="0.8", zorder=0)
            ax.axhline(1.0, color="0.3", lw=0.6)
            ax.set_title(PARAM_LABELS[name], fontsize=9.5)
            ax.set_xlabel("time (s)")
            ax.tick_params(labelsize=8.5)
        axes[0].set_ylabel("estimate / true (1)")
    return fig


__all__ = ["ESTIMATORS", "critical_speed", "ekf_lateral", "ekf_model_error", "final_errors_over_records", "normalised_estimates", "posterior_vs_filters", "relative_errors", "toy_errors", "toy_estimates"]
