"""Figures of chapter ``reduced-order-observer`` (matplotlib, ≤ 7 in wide, legends outside the data).

Each function takes the run's named results (:class:`ReducedOrderObserverResult`) and its
settings and returns the figure; the notebook saves it and shows it as a numbered MyST figure.
"""

from __future__ import annotations

import matplotlib.pyplot as plt
import numpy as np
from matplotlib.lines import Line2D
from matplotlib.ticker import LogLocator, NullFormatter, ScalarFormatter

from railpaper.experiments.reduced_order_observer.spec import Settings

#: Display names of the two discretisations of the paper's observer.
OBSERVER_NAMES = {"paper": "paper's observer (ZOH)", "foh": "observer, FOH discretisation"}


def _legend_below(fig, handles, labels, ncol: int = 3) -> None:
    fig.legend(handles, labels, loc="upper center", bbox_to_anchor=(0.5, 0.0), ncol=ncol,
               frameon=False)


def _never_as_nan(values) -> np.ndarray:
    values = np.asarray(values, float)
    return np.where(values < 0, np.nan, values)


def displacement(result, settings: Settings):
    """Per speed: true and observed z_w (top) and |error| on a log scale with the convergence
    threshold and time (bottom)."""
    speeds = settings.speeds_kmh
    fig, axes = plt.subplots(2, len(speeds), figsize=(7, 4.8), squeeze=False, sharex=True)
    for j, speed in enumerate(speeds):
        r = result.runs[speed]
        t, z = r.record.t_s, r.record.x_true[:, 3]
        est = r.observer(settings.observer_form)
        top, bottom = axes[0, j], axes[1, j]
        top.plot(t, z * 1e3, lw=2.0, color="C0")
        top.plot(t, est.z_w_est_m * 1e3, lw=0.9, ls="--", color="C1")
        bottom.semilogy(t, np.abs(est.z_w_est_m - z) * 1e3, lw=0.7, color="C1")
        bottom.axhline(settings.convergence_fraction * r.z_w_rms_m * 1e3, color="k", ls=":", lw=1.2)
        if est.convergence_time_s >= 0:
            for ax in (top, bottom):
                ax.axvline(est.convergence_time_s, color="grey", lw=1.0)
        top.set_title(f"{speed:g} km/h")
        bottom.set_xlabel("time (s)")
    axes[0, 0].set_ylabel("$z_w$ (mm)")
    axes[1, 0].set_ylabel("$|\\hat z_w - z_w|$ (mm)")
    handles = [Line2D([], [], lw=2.0, color="C0"), Line2D([], [], lw=0.9, ls="--", color="C1"),
               Line2D([], [], color="k", ls=":", lw=1.2), Line2D([], [], color="grey", lw=1.0)]
    labels = ["simulated $z_w$", f"estimate, {OBSERVER_NAMES[settings.observer_form]}",
              "threshold: 5 % of RMS $z_w$", "convergence time"]
    fig.tight_layout()
    _legend_below(fig, handles, labels, ncol=2)
    return fig


def force(result, settings: Settings, metrics, window_s: float = 0.1,
          moving_rms_s: float = 0.01):
    """Per speed: true and observed force over ``window_s`` after the error window starts (left)
    and the moving RMS of the force and of the error over the whole run, log scale (right)."""
    speeds = settings.speeds_kmh
    fig, axes = plt.subplots(len(speeds), 2, figsize=(7, 2.5 * len(speeds) + 0.4), squeeze=False,
                             gridspec_kw={"width_ratios": [1, 1]})
    n = int(round(moving_rms_s / settings.dt_s))
    moving = lambda x: np.sqrt(np.convolve(x**2, np.ones(n) / n, mode="same"))  # noqa: E731
    start = settings.error_window_start_s
    for (left, right), speed in zip(axes, speeds):
        r = result.runs[speed]
        t, f_true = r.record.t_s, r.record.force_true_N
        f_est = r.observer(settings.observer_form).force_est_N
        shown = (t >= start) & (t <= start + window_s)
        left.plot(t[shown], f_est[shown] / 1e3, lw=0.6, color="C1")
        left.plot(t[shown], f_true[shown] / 1e3, lw=1.6, color="C0")
        ratio = metrics[f"force_relative_rms_error_{speed:g}kmh"]
        left.set(title=f"{speed:g} km/h: RMS error = {ratio:.3g} × RMS force",
                 ylabel="force (kN)")
        right.semilogy(t, moving(f_true) / 1e3, lw=1.2, color="C0")
        right.semilogy(t, moving(f_est - f_true) / 1e3, lw=0.8, color="C3")
        right.axvline(start, color="grey", lw=0.8, ls=":")
        right.set(title=f"{speed:g} km/h, {moving_rms_s * 1e3:g} ms moving RMS", ylabel="kN")
    axes[-1, 0].set_xlabel("time (s)")
    axes[-1, 1].set_xlabel("time (s)")
    handles = [Line2D([], [], lw=1.6, color="C0"), Line2D([], [], lw=0.6, color="C1"),
               Line2D([], [], lw=0.8, color="C3"), Line2D([], [], color="grey", lw=0.8, ls=":")]
    labels = ["simulated dynamic force", "observed force", "error (observed − simulated)",
              "start of the error window"]
    fig.tight_layout()
    _legend_below(fig, handles, labels, ncol=2)
    return fig


def trends(result, settings: Settings):
    """One record over the sweep speeds: convergence time (left), RMS force error (right)."""
    sweep = result.speed_sweep
    form = settings.observer_form
    other = "foh" if form == "paper" else "paper"
    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(7, 3.2))
    v = sweep.speed_kmh
    ax1.plot(v, _never_as_nan(sweep.convergence_time_s), "o-", ms=7, color="C1")
    ax1.plot(v, _never_as_nan(sweep[f"convergence_time_s_{other}"]), "s--", ms=4, color="C2")
    ax1.plot(v, _never_as_nan(sweep.predicted_convergence_time_s), "k:", lw=1.5)
    ax1.set(xlabel="speed (km/h)", ylabel="convergence time (s)")
    ax2.semilogy(v, sweep.force_rms_error_N / 1e3, "o-", ms=7, color="C1")
    ax2.semilogy(v, sweep[f"force_rms_error_N_{other}"] / 1e3, "s--", ms=4, color="C2")
    ax2.semilogy(v, sweep.force_rms_N / 1e3, "^-", ms=5, color="C0")
    ax2.set(xlabel="speed (km/h)", ylabel="RMS (kN)")
    handles = [Line2D([], [], marker="o", ms=7, color="C1"),
               Line2D([], [], marker="s", ms=4, ls="--", color="C2"),
               Line2D([], [], ls=":", lw=1.5, color="k"), Line2D([], [], marker="^", color="C0")]
    labels = [OBSERVER_NAMES[form], OBSERVER_NAMES[other], "error equation alone (left)",
              "RMS of the force itself (right)"]
    fig.tight_layout()
    _legend_below(fig, handles, labels, ncol=2)
    return fig


def monte_carlo(result, settings: Settings):
    """Over seeds, the chapter's reading of P0: convergence time (boxes), RMS force error at
    both noise models with the RMS force (median, 5–95 % band), relative force error (boxes)."""
    t = result.monte_carlo[result.monte_carlo.reading == settings.p0_basis]
    speeds = sorted(t.speed_kmh.unique())
    width = 0.25 * min(np.diff(speeds)) if len(speeds) > 1 else 5.0
    med = t.groupby("speed_kmh").median(numeric_only=True)
    fig, (ax1, ax2, ax3) = plt.subplots(3, 1, figsize=(7, 8), sharex=True)
    ax1.boxplot([t[t.speed_kmh == s].convergence_time_s for s in speeds], positions=speeds,
                widths=width, whis=(5, 95), manage_ticks=False)
    ax1.plot(speeds, med.predicted_convergence_time_s, "k:", lw=1.5,
             label="error equation alone (median)")
    ax1.set(ylabel="convergence time (s)", title="convergence time over seeds (boxes: quartiles, "
            "whiskers 5–95 %)")
    for column, label, style in (
            ("force_rms_error_N", "error, noise σ ∝ channel RMS at each speed", "o-"),
            ("force_rms_error_N_fixed_noise", "error, noise fixed at its 60 km/h level", "s--"),
            ("force_rms_N", "RMS of the force itself", "^-")):
        band = t.groupby("speed_kmh")[column].quantile([0.05, 0.95]).unstack() / 1e3
        line, = ax2.plot(speeds, med[column] / 1e3, style, ms=4, label=label)
        ax2.fill_between(band.index, band[0.05], band[0.95], alpha=0.2, color=line.get_color())
    ax2.set(ylabel="RMS force / error (kN)", yscale="log",
            title="RMS force error over seeds (median, 5–95 % band)")
    ax3.boxplot([t[t.speed_kmh == s].force_relative_rms_error for s in speeds], positions=speeds,
                widths=width, whis=(5, 95), manage_ticks=False)
    ax3.set(xlabel="speed (km/h)", ylabel="RMS error / RMS force", yscale="log",
            title="relative RMS force error over seeds")
    for ax in (ax2, ax3):
        ax.yaxis.set_major_locator(LogLocator(base=10, subs=(1.0, 2.0, 5.0)))
        ax.yaxis.set_major_formatter(ScalarFormatter())
        ax.yaxis.set_minor_formatter(NullFormatter())
    handles, labels = ax1.get_legend_handles_labels()
    more = ax2.get_legend_handles_labels()
    fig.tight_layout()
    _legend_below(fig, handles + more[0], labels + more[1], ncol=2)
    return fig


#: Display style of each estimator: name, colour, marker, line style.
ESTIMATOR_STYLES = {"observer": ("paper's observer", "C1", "o", "-"),
                    "kalman": ("Kalman filter", "C2", "s", "-"),
                    "smoother": ("RTS smoother (offline)", "C4", "D", "--")}


def force_error_vs_noise(result, settings: Settings):
    """RMS force error / RMS force of each estimator against the sensor noise (top, median and
    5–95 % band over seeds) and against the noise on the irregularity record (bottom), per speed."""
    s = result.estimators.samples
    speeds = settings.speeds_kmh
    fig, axes = plt.subplots(2, len(speeds), figsize=(7, 6), squeeze=False, sharey="row")
    for row, (sweep, column, xlabel) in enumerate((
            ("sensor", "noise_fraction", "sensor noise σ on $\\dot z_c$, $z_c$ (% of RMS)"),
            ("track", "track_noise_fraction", "noise σ on the $q$ record (% of RMS of $q$)"))):
        for ax, speed in zip(axes[row], speeds):
            t = s[(s.sweep == sweep) & (s.speed_kmh == speed)]
            for name, (label, colour, marker, ls) in ESTIMATOR_STYLES.items():
                by = t[t.estimator == name].groupby(column).ratio
                x = by.median().index.to_numpy() * 100
                ax.fill_between(x, by.quantile(0.05), by.quantile(0.95), color=colour, alpha=0.2)
                ax.plot(x, by.median(), marker=marker, ls=ls, color=colour, ms=5, label=label)
            ax.axhline(1.0, color="grey", ls=":", lw=1.0, label="error = force")
            ax.set(xscale="log", yscale="log", xlabel=xlabel,
                   title=f"{speed:g} km/h, {t.seed.nunique()} seeds")
        axes[row, 0].set_ylabel("RMS force error / RMS force")
    for ax in axes[0]:
        ax.axvline(100 * settings.noise_fraction, color="k", lw=0.8, ls="--")
    handles, labels = axes[0, 0].get_legend_handles_labels()
    handles.append(Line2D([], [], color="k", lw=0.8, ls="--"))
    labels.append("the run's sensor noise")
    fig.tight_layout()
    _legend_below(fig, handles, labels, ncol=3)
    return fig


def force_estimates(result, settings: Settings, window_s: float = 0.05,
                    moving_rms_s: float = 0.01):
    """One record at the run's noise, per speed: the Kalman filter's and the smoother's force
    against the simulated one over ``window_s`` after the error window starts (left) and the
    moving RMS of every estimator's error over the whole run, log scale (right)."""
    speeds = settings.speeds_kmh
    fig, axes = plt.subplots(len(speeds), 2, figsize=(7, 2.6 * len(speeds) + 0.4), squeeze=False)
    n = int(round(moving_rms_s / settings.dt_s))
    moving = lambda x: np.sqrt(np.convolve(x**2, np.ones(n) / n, mode="same"))  # noqa: E731
    start = settings.error_window_start_s
    for (left, right), speed in zip(axes, speeds):
        e = result.estimators.examples[speed]
        shown = (e.t_s >= start) & (e.t_s <= start + window_s)
        left.plot(e.t_s[shown], e.force_true_N[shown] / 1e3, lw=3.0, color="C0", alpha=0.5)
        for name in ("kalman", "smoother"):
            label, colour, marker, ls = ESTIMATOR_STYLES[name]
            left.plot(e.t_s[shown], getattr(e, f"{name}_N")[shown] / 1e3, lw=1.0, ls=ls,
                      color=colour)
        left.set(title=f"{speed:g} km/h", ylabel="force (kN)")
        right.semilogy(e.t_s, moving(e.force_true_N) / 1e3, lw=1.4, color="C0")
        for name, (label, colour, marker, ls) in ESTIMATOR_STYLES.items():
            right.semilogy(e.t_s, moving(getattr(e, f"{name}_N") - e.force_true_N) / 1e3,
                           lw=0.9, ls=ls, color=colour)
        right.axvline(start, color="grey", lw=0.8, ls=":")
        right.set(title=f"{speed:g} km/h, {moving_rms_s * 1e3:g} ms moving RMS", ylabel="kN")
    axes[-1, 0].set_xlabel("time (s)")
    axes[-1, 1].set_xlabel("time (s)")
    handles = [Line2D([], [], lw=3.0, color="C0", alpha=0.5)]
    labels = ["simulated dynamic force"]
    for name, (label, colour, marker, ls) in ESTIMATOR_STYLES.items():
        handles.append(Line2D([], [], lw=1.0, ls=ls, color=colour))
        labels.append(f"{label}: estimate (left), error (right)" if name != "observer"
                      else f"{label}: error (right)")
    fig.tight_layout()
    _legend_below(fig, handles, labels, ncol=2)
    return fig
