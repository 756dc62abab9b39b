"""Figures of chapter ``partial-state-observer`` (≤ 7 in wide, legends outside the data).

Each function takes the run's :class:`PartialStateObserverResult` and settings and returns a
matplotlib figure; the notebook saves it and shows it as a numbered MyST figure.
"""

from __future__ import annotations

import matplotlib.pyplot as plt
import numpy as np

from railpaper.experiments.display import legend_below
from railpaper.experiments.partial_state_observer.spec import Settings
from railpaper.experiments.partial_state_observer.tables import ESTIMATOR_NAMES

WIDTH_IN = 7.0


def shaping_filters(result, settings: Settings):
    """FRA class-5 PSD of q at each speed and the fitted second-order shaping filters."""
    fig, ax = plt.subplots(figsize=(WIDTH_IN, 4.2))
    for speed in sorted(settings.speeds_kmh):
        filt, w, S = result.design.filters[speed]
        line, = ax.loglog(w / (2 * np.pi), S * 2 * np.pi, lw=2.5, alpha=0.45,
                          label=f"{speed:g} km/h: FRA class 5")
        ax.loglog(w / (2 * np.pi), filt.psd(w) * 2 * np.pi, "--", color=line.get_color(),
                  label=f"{speed:g} km/h: fit, a = {filt.a:.2f}, b = {filt.b:.1f} rad/s")
    ax.set(xlabel="frequency (Hz)", ylabel="one-sided PSD of q (m²/Hz)")
    fig.tight_layout(rect=(0, 0.2, 1, 1))
    legend_below(fig, ax)
    return fig


def displacement(result, settings: Settings, window_s: float = 0.35):
    """Wheelset 1, true and observed, whole run (left) and the first ``window_s`` (right)."""
    speeds = sorted(settings.speeds_kmh)
    fig, axes = plt.subplots(len(speeds), 2, figsize=(WIDTH_IN, 1.7 * len(speeds) + 0.9),
                             sharex="col", squeeze=False, gridspec_kw={"width_ratios": [2, 1]})
    for row, speed in zip(axes, speeds):
        rec, est = result.records[speed], result.estimates[speed]
        for ax, stop in zip(row, (rec.t_s[-1], window_s)):
            k = rec.t_s <= stop
            ax.plot(rec.t_s[k], rec.z_m[k, 0] * 1e3, lw=3, alpha=0.35, color="C0",
                    label="simulated $z_{w1}$")
            ax.plot(rec.t_s[k], est.paper_m[k, 0] * 1e3, lw=0.9, color="C3",
                    label="paper's observer $\\hat z_{w1}$")
        row[0].set_ylabel(f"{speed:g} km/h\n(mm)")
    axes[0, 0].set_title("whole run")
    axes[0, 1].set_title(f"first {window_s:g} s")
    for ax in axes[-1]:
        ax.set_xlabel("time (s)")
    fig.tight_layout(rect=(0, 0.06, 1, 1))
    legend_below(fig, axes[0, 0])
    return fig


def convergence(result, settings: Settings):
    """|error| (max over wheelsets, log-log) of three estimators, threshold, convergence time."""
    speeds = sorted(settings.speeds_kmh)
    fig, axes = plt.subplots(len(speeds), 1, figsize=(WIDTH_IN, 1.8 * len(speeds) + 1.0),
                             sharex=True, squeeze=False)
    for ax, speed in zip(axes[:, 0], speeds):
        rec, est = result.records[speed], result.estimates[speed]
        t = rec.t_s[1:]
        for name, style in (("paper", "-"), ("hb0", "--"), ("kalman", ":")):
            err = np.abs(getattr(est, f"{name}_m") - rec.z_m).max(axis=1)[1:]
            ax.loglog(t, err * 1e3, style, lw=1.0, label=ESTIMATOR_NAMES[name])
        thr = settings.convergence_fraction * np.sqrt(np.mean(rec.z_m**2, axis=0)).min()
        ax.axhline(thr * 1e3, color="grey", lw=0.8, label="threshold: 5 % of RMS($z_w$)")
        tc = result.metrics[f"convergence_time_s_{speed:g}kmh"]
        if tc > 0:
            ax.axvline(tc, color="k", ls="-.", lw=0.8, label="convergence time, paper's observer")
        ax.set_ylabel(f"{speed:g} km/h\n|error| (mm)")
    axes[-1, 0].set_xlabel("time (s, log scale)")
    fig.tight_layout(rect=(0, 0.1, 1, 1))
    legend_below(fig, axes[0, 0])
    return fig


def max_error_vs_speed(result, settings: Settings):
    """Max error after 1 s against speed: one record (line) and 5-95 % over seeds (band)."""
    m, speeds = result.metrics, sorted(settings.speeds_kmh)
    own = result.monte_carlo[result.monte_carlo.reading == settings.suspension_reading]
    fig, ax = plt.subplots(figsize=(WIDTH_IN, 4.6))
    markers = {"paper": "o", "hb0": "s", "kalman": "^", "q": "D"}
    for name, suf in (("paper", ""), ("hb0", "_hb0"), ("kalman", "_kalman"), ("q", "_q")):
        g = own[own.estimator == name].groupby("speed_kmh")["max_error_after_1s_m"]
        shift = 2.0 if name == "hb0" else 0.0     # drawn beside the paper's, which it nearly equals
        line, = ax.plot([s + shift for s in speeds],
                        [m[f"max_error_after_1s_m_{s:g}kmh{suf}"] * 1e3 for s in speeds],
                        marker=markers[name], ms=6 if name == "paper" else 5,
                        ls="--" if name == "hb0" else "-", mfc="none" if name == "hb0" else None,
                        label=ESTIMATOR_NAMES[name] + (" (drawn 2 km/h right)" if shift else ""))
        ax.fill_between(g.quantile(0.05).index, g.quantile(0.05) * 1e3, g.quantile(0.95) * 1e3,
                        color=line.get_color(), alpha=0.2)
    for suf, style, hold in (("_noisefree", "k--", "zero-order hold"),
                             ("_noisefree_foh", "k:", "first-order hold")):
        ax.plot(speeds, [m[f"max_error_after_1s_m_{s:g}kmh{suf}"] * 1e3 for s in speeds], style,
                marker="x", ms=5, label=f"paper's observer, noise-free, {hold}")
    ax.set(yscale="log", xlabel="speed (km/h)", ylabel="max |error| after 1 s (mm)")
    fig.tight_layout(rect=(0, 0.18, 1, 1))
    legend_below(fig, ax)
    return fig


def speed_trends(result, settings: Settings):
    """Monte Carlo medians (25-75 % band) against speed, both readings (columns)."""
    mc = result.monte_carlo
    panels = [("convergence_time_s", "convergence_time_fixed_s", "convergence\ntime (s)", 1),
              ("max_error_after_1s_m", None, "max |error|\nafter 1 s (mm)", 1e3),
              ("relative_rms_error", None, "RMS(error) /\nRMS($z_w$)", 1),
              ("rms_error_m", None, "RMS error\nafter 1 s (mm)", 1e3)]
    variants = (("paper", "-", False, "paper's noise, run's threshold"),
                ("paper_fixednoise", "--", True, "speed-independent noise (and threshold)"),
                ("paper_noisefree", ":", True, "noise-free (speed-independent threshold)"))
    fig, axes = plt.subplots(4, 2, figsize=(WIDTH_IN, 8.5), sharex=True, sharey="row")
    for col, reading in zip(axes.T, ("labels", "symbols")):
        col[0].set_title(f"reading '{reading}'")
        for ax, (name, fixed_name, ylabel, scale) in zip(col, panels):
            for est, style, use_fixed, label in variants:
                c = fixed_name if (fixed_name and use_fixed) else name
                g = mc[(mc.reading == reading) & (mc.estimator == est)].groupby("speed_kmh")[c]
                med = g.median()
                line, = ax.plot(med.index, med * scale, style, marker="o", ms=3, label=label)
                ax.fill_between(med.index, g.quantile(0.25) * scale, g.quantile(0.75) * scale,
                                color=line.get_color(), alpha=0.15)
            if name != "convergence_time_s":
                ax.set_yscale("log")
            if reading == "labels":
                ax.set_ylabel(ylabel)
    for ax in axes[-1]:
        ax.set_xlabel("speed (km/h)")
    fig.tight_layout(rect=(0, 0.07, 1, 1))
    legend_below(fig, axes[0, 0], ncol=1)
    return fig


def convergence_vs_alpha(result, settings: Settings):
    """Convergence time of one record against the slowest designed decay rate."""
    sw, m = result.alpha_sweep, result.metrics
    speeds = sorted(settings.speeds_kmh)
    fig, ax = plt.subplots(figsize=(WIDTH_IN, 4.8))
    for speed in speeds:
        s = sw[(sw.speed_kmh == speed) & sw.noisy]
        line, = ax.loglog(s.slowest_rate_per_s, s.convergence_time_s, "o-", ms=4,
                          label=f"{speed:g} km/h, with noise")
        s0 = sw[(sw.speed_kmh == speed) & ~sw.noisy]
        ax.loglog(s0.slowest_rate_per_s, s0.predicted_s, ":", color=line.get_color())
    ax.plot([], [], "k:", label="error dynamics alone")
    ax.axhline(0.15, color="grey", ls="--", label="paper: 0.15 s")
    corner = -m["hb0_fixed_pole_per_s"]
    ax.axvline(corner, color="k", lw=0.8, ls="-.", label=f"H B = 0 poles: {corner:.3g} 1/s")
    ax.plot([corner] * len(speeds), [m[f"convergence_time_s_{s:g}kmh_hb0"] for s in speeds],
            "ks", ms=5, label="observer with H B = 0, with noise")
    ax.set(xlabel="slowest decay rate of N (1/s)", ylabel="convergence time (s)")
    fig.tight_layout(rect=(0, 0.2, 1, 1))
    legend_below(fig, ax)
    return fig


def noise_free_error(result, settings: Settings):
    """Noise-free error (max over wheelsets) at the highest speed: ZOH, FOH, Kalman, ẑ = q."""
    speed = max(settings.speeds_kmh)
    rec, est = result.records[speed], result.noise_free[speed]
    fig, ax = plt.subplots(figsize=(WIDTH_IN, 4.0))
    for field_name, label in (("paper_m", "paper's observer, zero-order hold"),
                              ("paper_foh_m", "paper's observer, first-order hold"),
                              ("kalman_m", "Kalman filter (no q)"), ("q_m", "ẑ = q")):
        err = np.abs(getattr(est, field_name) - rec.z_m).max(axis=1)
        ax.semilogy(rec.t_s, err * 1e3, lw=0.9, label=label)
    ax.set(xlabel="time (s)", ylabel="max |error| over wheelsets (mm)")
    fig.tight_layout(rect=(0, 0.14, 1, 1))
    legend_below(fig, ax)
    return fig
