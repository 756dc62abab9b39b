"""Figures of appendix ``suspension-fault-detection`` (matplotlib, ≤ 7 in wide, legends below the
axes, outside the data).

Each function takes the run's :class:`FaultDetectionResult` and its settings and returns the
figure; the notebook saves it and shows it as a numbered MyST figure.  Detectors keep one colour
and marker throughout (:data:`DETECTOR_STYLES`); a detector without a metric at a speed is left
out of that speed's panels.
"""

from __future__ import annotations

import matplotlib.pyplot as plt
import numpy as np
import pandas as pd
from matplotlib.lines import Line2D
from matplotlib.patches import Patch

from railpaper.experiments.display import number
from railpaper.experiments.suspension_fault_detection.result import (
    NO_FAULT,
    LongRunningCheck,
    read_censored_median,
    speed_key,
    tail_of,
)
from railpaper.experiments.suspension_fault_detection.spec import (
    DETECTORS,
    LADDER,
    LADDER_MTBFA_H,
    MTBFA_TARGETS_H,
    STORED_DETECTORS,
    STORED_RUNGS,
    Settings,
)
from railpaper.experiments.suspension_fault_detection.tables import (
    DETECTOR_SHORT,
    PARAMETERS,
    fault_short_label,
)
from railpaper.monitoring import fit_exponential_tail

#: Short labels of the ladder's rungs under the ladder figure's axes: what each rung takes
#: away, cumulatively.
RUNG_TICKS = {"ideal": "ideal", "no_axlebox_gyro_001": "− axle-box acc.",
              "accelerometers_only": "− gyro", "track_unknown": "− track input",
              "model_error": "+ model error"}

#: Colour and marker of each detector.
DETECTOR_STYLES = {"cusum": ("C0", "o"), "chi2": ("C1", "v"), "glr": ("C4", "^"),
                   "bayes": ("C2", "s"), "oracle": ("C3", "D"), "hunting": ("C7", "X")}
#: Line styles where detectors' curves coincide (the GLR drawn dashed above Shiryaev–Roberts,
#: whose alarms it often shares).
LINE_STYLES = {"glr": "--"}
#: Where a censored delay ("beyond the record") is drawn, as a multiple of the longest delay a
#: record can show.
BEYOND_FACTOR = 1.6


def _legend_below(fig, handles, labels, ncol: int = 2) -> None:
    """One legend for the figure, below the axes (call after ``tight_layout``)."""
    fig.legend(handles, labels, loc="upper center", bbox_to_anchor=(0.5, 0.0), ncol=ncol,
               frameon=False)


def _fault_named(result, name: str):
    """The run's :class:`Fault` called ``name`` (None: fault-free or unknown)."""
    return next((f for f in result.faults if f.name == name), None)


def _short_name(result, name: str) -> str:
    """The short mathtext label of fault ``name`` (the name itself when it is not a fault)."""
    fault = _fault_named(result, name)
    return fault_short_label(fault, tex=True) if fault is not None else name


def _mark_events(ax, run, monitor_from_s: float) -> None:
    """Shade the time before the monitoring window; mark the fault time and flange contact."""
    ax.axvspan(0.0, monitor_from_s, color="0.92", zorder=0, lw=0)
    ax.axvline(run.fault_time_s, color="grey", lw=1.0, ls="--")
    if run.flange_contact:
        ax.axvline(run.end_s, color="k", lw=1.4)


def _hypothesis_label(result, index: int) -> str:
    """"$C_{saly}$ × 0.3": the GLR's hypothesis ``index``."""
    name, factor = result.bank_hypotheses[index]
    return f"{PARAMETERS.get(name, (name, name, ''))[1]} × {factor:g}"


def record_around_fault(result, settings: Settings):
    """The illustrated record (first speed): each detector's alarm statistic in a panel of its
    own, with its alarm threshold and its first alarm in the monitoring window; the true fault
    time (and flange contact, where the record ends at it) marked in every panel, and in the
    GLR's panel the parameter its best hypothesis blames at that alarm."""
    ill = result.illustrated
    run = ill.run
    speed = run.speed_kmh
    stats = run.statistics
    panels = [d for d in DETECTORS if d in stats]
    fig, axes = plt.subplots(len(panels), 1, figsize=(7, 1.45 * len(panels) + 0.8),
                             sharex=True, squeeze=False)
    axes = axes[:, 0]
    K = len(next(iter(stats.values())))
    t = ill.dt_s * np.arange(1, K + 1)
    ylabels = {"cusum": "CUSUM", "chi2": "windowed χ²", "glr": "GLR (nats)",
               "bayes": "log R (nats)", "oracle": "log odds (nats)"}
    for letter, ax, panel in zip("abcdefg", axes, panels):
        ax.set_title(f"({letter}) {DETECTORS[panel]}", fontsize=9, loc="left")
        colour = DETECTOR_STYLES[panel][0]
        values = np.asarray(stats[panel], float)
        shown = np.where(np.isfinite(values), values, np.nan)
        ax.plot(t, shown, color=colour, lw=1.0)
        h = result.thresholds.get((panel, speed))
        if h is not None and np.isfinite(h):
            ax.axhline(h, color="k", ls=":", lw=1.2)
            hits = np.flatnonzero((t >= result.monitor_from_s - 1e-9) & (values >= h))
            if hits.size:
                ax.plot([t[hits[0]]], [h], marker="v", ms=7, color="k", ls="none", zorder=5)
                if panel == "glr" and run.bank_hypothesis is not None \
                        and result.bank_hypotheses:
                    best = int(run.bank_hypothesis[hits[0]])
                    if best >= 0:
                        ax.annotate(f"blames {_hypothesis_label(result, best)}", (t[hits[0]], h),
                                    xytext=(6, 6), textcoords="offset points", fontsize=8)
        ax.set_yscale("symlog", linthresh=10.0)
        ax.set_ylabel(ylabels[panel], fontsize=8)
        _mark_events(ax, run, result.monitor_from_s)
    axes[-1].set_xlabel("time from the record's start (s)")
    axes[-1].set_xlim(0, max(t[-1], run.end_s))
    fault = _fault_named(result, run.fault)
    label = fault.label if fault is not None else run.fault
    fig.suptitle(f"{label}, {speed:g} km/h (seed {run.seed})", fontsize=10)
    handles, labels = [], []
    handles += [Line2D([], [], color="k", ls=":", lw=1.2),
                Line2D([], [], marker="v", ms=7, color="k", ls="none"),
                Line2D([], [], color="grey", ls="--", lw=1.0), Patch(color="0.92")]
    labels += ["alarm threshold", "first alarm in the monitoring window",
               f"true fault time ({number(run.fault_time_s)} s)",
               "before the monitoring window (alarms not counted)"]
    if run.flange_contact:
        handles.append(Line2D([], [], color="k", lw=1.4))
        labels.append(f"flange contact: record ends ({number(run.end_s)} s)")
    fig.tight_layout()
    _legend_below(fig, handles, labels, ncol=2)
    return fig


def _delay_point(ax, x, metrics, tag, beyond, colour, marker) -> bool | None:
    """One detector's median delay with its interval at ``x`` (an end beyond the record drawn
    at ``beyond``); None when the detector did not run, else whether the median lies beyond."""
    median = read_censored_median(metrics, "delay_median", tag)
    if median is None:
        return None
    low_y = median.low if median.low is not None and median.low > 0 else beyond
    high_y = median.high if median.high is not None else beyond
    if median.median is not None and median.median > 0:
        med = median.median
        ax.errorbar([x], [med], yerr=[[med - min(low_y, med)], [high_y - med]], fmt=marker,
                    color=colour, ms=5, capsize=2, lw=1.0)
        if median.high is None:
            ax.plot([x], [beyond], marker="^", ms=4, color=colour, ls="none")
        return False
    ax.vlines(x, low_y, beyond, color=colour, lw=1.0, ls=":")
    ax.plot([x], [beyond], marker="^", ms=7, mfc="white", mec=colour, ls="none")
    return True


def delay_by_fault(result, settings: Settings):
    """Per speed (columns), the median detection delay of each detector (offset markers) on
    each fault (x), with its 95 % interval over records, log scale; a median or interval end
    beyond the record (fewer than half the records alarmed after the fault) is drawn as an
    upward triangle in the grey band at the top. A grey bar marks the median time from the fault
    to flange contact, where the fault's records reach it."""
    speeds = settings.speeds_kmh
    m = result.metrics
    longest = settings.duration_s - result.monitor_from_s
    beyond = BEYOND_FACTOR * longest
    fig, axes = plt.subplots(1, len(speeds), figsize=(7, 3.9), sharey=True, squeeze=False)
    axes = axes[0]
    offsets = dict(zip(DETECTORS, np.linspace(-0.24, 0.24, len(DETECTORS))))
    drawn, flange, censored = set(), False, False
    for ax, speed in zip(axes, speeds):
        sk = speed_key(speed)
        ran = []
        for i, f in enumerate(result.faults):
            for det in DETECTORS:
                colour, marker = DETECTOR_STYLES[det]
                point = _delay_point(ax, i + offsets[det], m, f"{det}_{f.name}_{sk}", beyond,
                                     colour, marker)
                if point is not None:
                    drawn.add(det)
                    ran.append(det)
                    censored |= point
            rate = m.get(f"flange_contact_rate_{f.name}_{sk}", 0.0)
            after = m.get(f"flange_contact_after_s_{f.name}_{sk}")
            if rate > 0 and after is not None:
                ax.hlines(max(after, result.dt_s), i - 0.4, i + 0.4, color="grey", lw=2.5,
                          alpha=0.7)
                flange = True
        ax.axhspan(longest, 2.2 * longest, color="0.9", zorder=0)
        missing = [DETECTOR_SHORT[d] for d in DETECTORS if d not in ran]
        ax.set_title(f"{speed:g} km/h" + (f" (no {', '.join(missing)})" if missing else ""),
                     fontsize=9)
        ax.set_xticks(range(len(result.faults)))
        ax.set_xticklabels([fault_short_label(f, tex=True) for f in result.faults],
                           rotation=35, ha="right", fontsize=8)
        ax.set_xlim(-0.6, len(result.faults) - 0.4)
        ax.set_xlabel("fault")
    axes[0].set_yscale("log")
    axes[0].set_ylim(0.5 * result.dt_s, 2.2 * longest)
    decades = 10.0 ** np.arange(np.ceil(np.log10(0.5 * result.dt_s)),
                                np.floor(np.log10(longest)) + 1)
    axes[0].set_yticks(list(decades) + [beyond])
    axes[0].set_yticklabels([f"{d:g}" for d in decades] + ["beyond\nthe record"])
    axes[0].minorticks_off()
    axes[0].set_ylabel("detection delay after the fault (s)")
    handles = [Line2D([], [], color=DETECTOR_STYLES[d][0], marker=DETECTOR_STYLES[d][1],
                      ls="-", lw=1.0, ms=5) for d in DETECTORS if d in drawn]
    labels = [f"{DETECTOR_SHORT[d]}: median, 95 % interval" for d in DETECTORS if d in drawn]
    if censored:
        handles.append(Line2D([], [], marker="^", ms=7, mfc="white", mec="k", ls="none"))
        labels.append("median beyond the record (dotted: its interval)")
    if flange:
        handles.append(Line2D([], [], color="grey", lw=2.5, alpha=0.7))
        labels.append("median time from the fault to flange contact")
    fig.tight_layout()
    _legend_below(fig, handles, labels, ncol=2)
    return fig


def delay_vs_mtbfa(result, settings: Settings):
    """The standard picture of a change detector: per speed (rows) and fault (columns), each
    detector's Kaplan–Meier median detection delay (log y) against the mean time between false
    alarms its threshold is set to (log x, hours), thresholds from each detector's exponential
    tail of fault-free block maxima; the calibration records' own running marked (to its right
    the tail is extrapolated), and the operating points of :data:`MTBFA_TARGETS_H` dotted.  A
    curve stops where fewer than half the records are detected."""
    curve = result.delay_curve
    speeds, faults = settings.speeds_kmh, list(result.faults)
    fig, axes = plt.subplots(len(speeds), len(faults), figsize=(7, 1.7 * len(speeds) + 1.3),
                             sharex=True, sharey=True, squeeze=False)
    drawn = set()
    longest = settings.duration_s - result.monitor_from_s
    for i, speed in enumerate(speeds):
        sk = speed_key(speed)
        for j, f in enumerate(faults):
            ax = axes[i, j]
            if curve is not None and len(curve):
                for det in DETECTORS:
                    rows = curve[(curve["detector"] == det) & (curve["speed_kmh"] == speed)
                                 & (curve["fault"] == f.name)].sort_values("mtbfa_h")
                    if not len(rows):
                        continue
                    colour, marker = DETECTOR_STYLES[det]
                    ax.plot(rows["mtbfa_h"], rows["km_delay_median_s"], color=colour, lw=1.0,
                            marker=marker, ms=2.5, ls=LINE_STYLES.get(det, "-"),
                            zorder=3 if det in LINE_STYLES else 2)
                    drawn.add(det)
            running = [result.metrics.get(f"tail_blocks_{d}_{sk}", 0)
                       * settings.false_alarm_block_s / 3600.0 for d in DETECTORS]
            if max(running) > 0:
                ax.axvspan(1e-3, max(running), color="0.92", zorder=0, lw=0)
            for target in MTBFA_TARGETS_H:
                ax.axvline(target, color="0.6", lw=0.8, ls=":")
            ax.set_xscale("log")
            ax.set_yscale("log")
            ax.set_xlim(1e-3, 1e4)
            ax.set_ylim(0.5 * result.dt_s, longest)
            if i == 0:
                ax.set_title(fault_short_label(f, tex=True), fontsize=8)
            if j == 0:
                ax.set_ylabel(f"{speed:g} km/h\ndelay (s)", fontsize=8)
            if i == len(speeds) - 1:
                ax.set_xlabel("MTBFA (h)", fontsize=8)
            ax.set_xticks([1e-2, 1, 1e2, 1e4])
            ax.tick_params(labelsize=7)
            ax.minorticks_off()
    handles = [Line2D([], [], color=DETECTOR_STYLES[d][0], marker=DETECTOR_STYLES[d][1], ms=3,
                      lw=1.0, ls=LINE_STYLES.get(d, "-")) for d in DETECTORS if d in drawn]
    labels = [DETECTOR_SHORT[d] for d in DETECTORS if d in drawn]
    handles += [Patch(color="0.92"), Line2D([], [], color="0.6", lw=0.8, ls=":")]
    labels += ["the calibration records' running (beyond: the tail extrapolated)",
               "operating points: " + ", ".join(f"{t:g} h" for t in MTBFA_TARGETS_H)]
    fig.tight_layout()
    _legend_below(fig, handles, labels, ncol=3)
    return fig


def ladder_figure(result, settings: Settings):
    """The realism ladder at ``ladder_speed_kmh`` and thresholds for :data:`LADDER_MTBFA_H`
    hours between false alarms (recalibrated on each rung): per fault (columns), each
    detector's Kaplan–Meier median delay (top, log; missing where fewer than half the records
    are detected) and its share detected within 2 s (bottom; dotted: at the ideal rung's
    thresholds) on each rung (x; a rung the run left out is not drawn)."""
    table = result.ladder
    ran = set(table["rung"]) if table is not None and len(table) else set()
    rungs = [r for r in ["ideal"] + list(LADDER) if r == "ideal" or r in ran]
    return rung_figure(result.ladder, list(result.faults), rungs, settings,
                       f"{settings.ladder_speed_kmh:g} km/h, thresholds for {LADDER_MTBFA_H:g} h "
                       "between false alarms on each rung")


def stored_ladder_figure(table: pd.DataFrame, faults, settings: Settings):
    """:func:`ladder_figure` of the stored rungs beside the ideal rung of the run's records at
    the ladder's speed (the table of
    :func:`~railpaper.experiments.suspension_fault_detection.experiment.stored_ladder`)."""
    n = int(table["records"].max()) if len(table) else 0
    return rung_figure(table, list(faults), ["ideal"] + list(STORED_RUNGS), settings,
                       f"{settings.ladder_speed_kmh:g} km/h, {n} records per fault, thresholds "
                       f"for {LADDER_MTBFA_H:g} h between false alarms on each rung (stored "
                       "evidence)", ticks={"track_unknown": "acc. only, − track"},
                       detectors=STORED_DETECTORS)


def rung_figure(table: pd.DataFrame, faults: list, rungs: list[str], settings: Settings,
                title: str, ticks: dict | None = None, detectors: dict = DETECTORS):
    """The picture of :func:`ladder_figure` for ``rungs`` from a ladder table's rows
    (``ticks``: tick labels that replace :data:`RUNG_TICKS`'; ``detectors``: those drawn)."""
    ticks = {**RUNG_TICKS, **(ticks or {})}
    fig, axes = plt.subplots(2, len(faults), figsize=(7, 4.6), sharex=True, sharey="row",
                             squeeze=False)
    x = np.arange(len(rungs))
    drawn = set()
    for j, f in enumerate(faults):
        top, bottom = axes[0, j], axes[1, j]
        for det in detectors:
            rows = table[(table["detector"] == det) & (table["fault"] == f.name)] \
                if table is not None and len(table) else None
            if rows is None or not len(rows):
                continue
            rows = rows.set_index("rung").reindex(rungs)
            colour, marker = DETECTOR_STYLES[det]
            ls = LINE_STYLES.get(det, "-")
            top.plot(x, rows["km_delay_median_s"], color=colour, marker=marker, ms=3, lw=1.0,
                     ls=ls)
            bottom.plot(x, 100 * rows["detected_within_2s"], color=colour, marker=marker, ms=3,
                        lw=1.0, ls=ls)
            bottom.plot(x, 100 * rows["detected_within_2s_at_ideal_thresholds"], color=colour,
                        lw=1.0, ls=":")
            drawn.add(det)
        top.set_title(fault_short_label(f, tex=True), fontsize=8)
        top.set_yscale("log")
        top.set_ylim(0.5 * settings.dt_s, settings.duration_s)
        bottom.set_ylim(-5, 105)
        bottom.set_xticks(x)
        bottom.set_xticklabels([ticks.get(r, r) for r in rungs], fontsize=6, rotation=45,
                               ha="right", rotation_mode="anchor")
        for ax in (top, bottom):
            ax.tick_params(labelsize=7)
    axes[0, 0].set_ylabel("median delay (s)", fontsize=8)
    axes[1, 0].set_ylabel("detected within 2 s (%)", fontsize=8)
    handles = [Line2D([], [], color=DETECTOR_STYLES[d][0], marker=DETECTOR_STYLES[d][1], ms=3,
                      lw=1.0, ls=LINE_STYLES.get(d, "-")) for d in detectors if d in drawn]
    labels = [DETECTOR_SHORT[d] for d in detectors if d in drawn]
    handles.append(Line2D([], [], color="k", lw=1.0, ls=":"))
    labels.append("at the ideal rung's thresholds")
    fig.suptitle(title, fontsize=9)
    fig.tight_layout()
    _legend_below(fig, handles, labels, ncol=3)
    return fig


#: Colour of a check of the tail on the long running, by outcome.
OUTCOME_STYLES = {"consistent": ("k", "o"), "more alarms": ("C3", "^"),
                  "fewer alarms": ("C0", "v")}


def no_stored_running_figure():
    """What the page shows in place of :func:`long_running_figure` when the store holds no
    running for the run's settings (it holds the defaults' only)."""
    fig, ax = plt.subplots(figsize=(7, 1.0))
    ax.axis("off")
    ax.text(0.5, 0.5, "No stored fault-free running for these settings (the store holds the "
            "appendix's defaults only)", ha="center", va="center", fontsize=9)
    return fig


def long_running_figure(check: LongRunningCheck, result, settings: Settings):
    """Each detector's mean time between false alarms against its threshold (panels: speeds in
    rows, detectors in columns): measured on the stored long running (a step per exceeding
    block: k blocks above the threshold, running / k), the run's tail model (solid) and the
    same tail refitted to the running (dashed), the checks at the run's thresholds for
    :data:`RUNNING_CHECK_H` hours with their 95 % Poisson intervals (coloured by outcome), and
    the running measured (dotted)."""
    speeds = list(check.running_h)
    fig, axes = plt.subplots(len(speeds), len(DETECTORS), figsize=(7, 1.9 * len(speeds) + 0.9),
                             squeeze=False, sharey=True)
    for i, speed in enumerate(speeds):
        running_h = check.running_h[speed]
        for j, det in enumerate(DETECTORS):
            ax = axes[i, j]
            maxima = check.maxima.get((det, speed), np.zeros(0))
            tail = tail_of(result.metrics, f"{det}_{speed_key(speed)}", check.block_s)
            shown = maxima[:max(2, int(0.2 * maxima.size))]
            if shown.size:
                k = np.arange(1, shown.size + 1)
                ax.step(shown, running_h / k, where="post", color="k", lw=0.8)
            if tail is not None:
                h = np.linspace(tail.level, tail.threshold(MTBFA_TARGETS_H[-1]), 60)
                ax.plot(h, [tail.mtbfa_h(x) for x in h], color=DETECTOR_STYLES[det][0],
                        lw=1.2)
            if shown.size > 2:
                try:
                    again = fit_exponential_tail(maxima, check.block_s)
                    h = np.linspace(again.level, again.threshold(MTBFA_TARGETS_H[-1]), 60)
                    ax.plot(h, [again.mtbfa_h(x) for x in h], color="0.4", lw=1.0, ls="--")
                except ValueError:
                    pass
            rows = check.checks[(check.checks["speed_kmh"] == speed)
                                & (check.checks["detector"] == det)]
            for row in rows.itertuples():
                colour, marker = OUTCOME_STYLES[row.outcome]
                if row.alarms == 0:            # no alarm: only a lower bound, drawn as one
                    ax.plot([row.threshold, row.threshold], [row.mtbfa_low_h, 10 * running_h],
                            color=colour, lw=0.8)
                    ax.plot([row.threshold], [row.mtbfa_low_h], marker="^", ms=4, color=colour,
                            mfc="white", ls="")
                    continue
                ax.errorbar([row.threshold], [row.mtbfa_direct_h],
                            yerr=[[row.mtbfa_direct_h - row.mtbfa_low_h],
                                  [row.mtbfa_high_h - row.mtbfa_direct_h]],
                            fmt=marker, ms=3, color=colour, lw=0.8)
            ax.axhline(running_h, color="0.5", lw=0.8, ls=":")
            ax.set_yscale("log")
            ax.tick_params(labelsize=6)
            if i == 0:
                ax.set_title(DETECTOR_SHORT[det], fontsize=8)
            if j == 0:
                ax.set_ylabel(f"{speed:g} km/h\nMTBFA (h)", fontsize=8)
            if i == len(speeds) - 1:
                ax.set_xlabel("threshold", fontsize=7)
    axes[0, 0].set_ylim(1e-4, 3e3)
    handles = [Line2D([], [], color="k", lw=0.8), Line2D([], [], color="C7", lw=1.2),
               Line2D([], [], color="0.4", lw=1.0, ls="--"),
               Line2D([], [], color="0.5", lw=0.8, ls=":")]
    labels = ["measured on the stored running", "tail model of the run (detector's colour)",
              "tail refitted to the running", "running measured"]
    handles.append(Line2D([], [], color="k", marker="^", mfc="white", ms=4, ls=""))
    labels.append("no alarm: lower end of the interval")
    for outcome, (colour, marker) in OUTCOME_STYLES.items():
        handles.append(Line2D([], [], color=colour, marker=marker, ms=3, ls=""))
        labels.append(f"check: {outcome}")
    fig.tight_layout()
    _legend_below(fig, handles, labels, ncol=3)
    return fig


def roc_curves(result, settings: Settings):
    """At the first speed, one panel per fault: each detector's rate of detection within 1 s
    against its false alarms per hour on the fault-free records as the threshold varies (log x;
    zero false alarms drawn at the left edge, tick "0"), with the calibrated threshold's
    operating point (false alarms on the evaluation records) as a large open marker."""
    speed = settings.speeds_kmh[0]
    sk = speed_key(speed)
    m = result.metrics
    roc = result.roc
    roc = roc[roc["speed_kmh"] == speed] if roc is not None and len(roc) else None
    faults = list(result.faults)
    operating = [m.get(f"false_alarms_per_hour_{d}_{sk}") for d in DETECTORS]
    values = [v for v in operating if v is not None]
    if roc is not None:
        values += list(roc["false_alarms_per_hour"])
    positive = [v for v in values if v > 0]
    floor = min(positive) / 10 if positive else 1.0
    top = max(positive) * 2 if positive else 10.0
    ncol = min(3, len(faults))
    nrow = int(np.ceil(len(faults) / ncol))
    fig, axes = plt.subplots(nrow, ncol, figsize=(7, 2.3 * nrow + 0.8), sharex=True,
                             sharey=True, squeeze=False)
    drawn = set()
    for ax, f in zip(axes.flat, faults):
        for det in DETECTORS:
            colour, marker = DETECTOR_STYLES[det]
            if roc is not None:
                c = roc[(roc["detector"] == det) & (roc["fault"] == f.name)]
                c = c.sort_values("threshold")
                if len(c):
                    x = np.maximum(c["false_alarms_per_hour"].to_numpy(), floor)
                    ax.plot(x, 100 * c["detected_within_1s"].to_numpy(), color=colour, lw=1.0,
                            marker=marker, ms=2.5)
                    drawn.add(det)
            fa = m.get(f"false_alarms_per_hour_{det}_{sk}")
            hit = m.get(f"detected_within_1s_{det}_{f.name}_{sk}")
            if fa is not None and hit is not None:
                ax.plot([max(fa, floor)], [100 * hit], marker=marker, ms=10, mfc="none",
                        mec=colour, mew=1.6, ls="none")
                drawn.add(det)
        ax.set_title(fault_short_label(f, tex=True), fontsize=9)
        ax.set_xscale("log")
        ax.set_xlim(floor / 1.5, top)
        ax.set_ylim(-5, 105)
    for ax in axes.flat[len(faults):]:
        ax.set_visible(False)
    decades = 10.0 ** np.arange(np.ceil(np.log10(floor * 1.5)), np.floor(np.log10(top)) + 1)
    ticks = [floor] + list(decades)
    for ax in axes.flat[:len(faults)]:
        ax.set_xticks(ticks)
        ax.set_xticklabels(["0"] + [f"{d:g}" for d in decades], fontsize=8)
        ax.minorticks_off()
    for ax in axes[:, 0]:
        ax.set_ylabel("detected within 1 s (%)")
    for j in range(ncol):
        shown = [i for i in range(nrow) if i * ncol + j < len(faults)]
        if shown:
            axes[shown[-1], j].set_xlabel("false alarms per hour (1/h)")
            axes[shown[-1], j].xaxis.set_tick_params(labelbottom=True)
    fig.suptitle(f"{speed:g} km/h: detection within 1 s against false alarms", fontsize=10)
    handles = [Line2D([], [], color=DETECTOR_STYLES[d][0], marker=DETECTOR_STYLES[d][1],
                      ms=2.5, lw=1.0) for d in DETECTORS if d in drawn]
    labels = [f"{DETECTOR_SHORT[d]}: over thresholds" for d in DETECTORS if d in drawn]
    handles += [Line2D([], [], color="k", marker="o", ms=10, mfc="none", mew=1.6, ls="none")]
    labels += ["operating point at the calibrated threshold"]
    fig.tight_layout()
    _legend_below(fig, handles, labels, ncol=2)
    return fig


def fault_time_posterior(result, settings: Settings):
    """The illustrated record's oracle posterior: (left) P(fault time | the whole record, a fault
    happened) over the prior's grid of fault times, with the true fault time marked; (right)
    P(which fault | the record, a fault happened) over the abrupt faults of the Kalman bank,
    the true fault highlighted. Log scales: the posterior is usually sure to many orders of
    magnitude; values below 1e-300 (or exactly 0) sit on the axis."""
    ill = result.illustrated
    run = ill.run
    floor = 1e-300
    fig, (left, right) = plt.subplots(1, 2, figsize=(7, 3.2),
                                      gridspec_kw={"width_ratios": [3, 2]})
    times = np.asarray(ill.fault_times_s, float)
    p = np.maximum(np.asarray(ill.fault_time_posterior, float), floor)
    width = 0.8 * (np.min(np.diff(times)) if times.size > 1 else 0.1)
    left.bar(times, p, width=width, color="C0", bottom=floor)
    if run.fault_time_s >= 0:
        left.axvline(run.fault_time_s, color="grey", ls="--", lw=1.0)
    ticks = [1e-300, 1e-200, 1e-100, 1.0]
    left.set_yscale("log")
    left.set_ylim(floor, 10)
    left.set_yticks(ticks)
    left.minorticks_off()
    left.set(xlabel="fault time (s)", ylabel="posterior probability")
    left.set_title("when: P(fault time | record)", fontsize=9)
    names = list(ill.value_posterior)
    values = np.maximum([ill.value_posterior[n] for n in names], floor)
    colours = ["C3" if n == run.fault else "0.7" for n in names]
    y = np.arange(len(names))
    right.barh(y, values, color=colours, left=floor)
    right.set_xscale("log")
    right.set_xlim(floor, 10)
    right.set_xticks(ticks)
    right.minorticks_off()
    right.set_yticks(y)
    right.set_yticklabels([f"{_short_name(result, n)}\nP = {number(ill.value_posterior[n], 2)}"
                           for n in names], fontsize=8)
    right.invert_yaxis()
    right.set(xlabel="posterior probability")
    right.set_title("which: P(fault | record)", fontsize=9)
    fault = _fault_named(result, run.fault)
    truth = fault.label if fault is not None else run.fault
    fig.suptitle(f"Exact posterior of the illustrated record: {truth}, {run.speed_kmh:g} km/h",
                 fontsize=10)
    handles = [Line2D([], [], color="grey", ls="--", lw=1.0), Patch(color="C3"),
               Patch(color="0.7")]
    labels = [f"true fault time ({number(run.fault_time_s)} s)", "true fault",
              "other faults of the bank"]
    if run.fault != NO_FAULT and run.fault not in names:
        labels[1] = "true fault (not in the bank: a drift)"
    fig.tight_layout()
    _legend_below(fig, handles, labels, ncol=3)
    return fig


__all__ = ["DETECTOR_STYLES", "delay_by_fault", "delay_vs_mtbfa", "fault_time_posterior",
           "ladder_figure", "record_around_fault", "rung_figure", "stored_ladder_figure",
           "roc_curves"]
