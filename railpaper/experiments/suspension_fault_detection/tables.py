"""Tables of appendix ``suspension-fault-detection`` as the page shows them (MyST Markdown, units
in the headers): the faults and their critical speeds, each detector's detection delay and rates,
false alarms and post-fault estimates, and the short names of faults and detectors that the
figures share.

Every function takes the run's :class:`FaultDetectionResult` (and its settings) and returns
Markdown: numbers to four significant digits, "beyond the record" for a median delay (or an
interval end) that lies beyond it (``delay_median_reached_<tag>`` False: no number is written),
"—" where a detector has no metric (a speed or fault it was not run on).
"""

from __future__ import annotations

import math

import pandas as pd

from railpaper.experiments.display import markdown, number
from railpaper.experiments.suspension_fault_detection.result import (
    NO_FAULT,
    Fault,
    LongRunningCheck,
    read_censored_median,
    speed_key,
)
from railpaper.experiments.suspension_fault_detection.spec import (
    CRITICAL_SEARCH_TOP_KMH,
    DETECTORS,
    LADDER,
    LADDER_MTBFA_H,
    MTBFA_TARGETS_H,
    OPERATING_POINT_H,
    PAIRS,
    RUNNING_CHECK_H,
    STORED_DETECTORS,
    STORED_RUNGS,
    WITHIN_S,
    Settings,
)
from railpaper.monitoring import SECONDS_PER_HOUR, poisson_two_sided_power

#: Short detector names for table headers and legends (full names: ``spec.DETECTORS``).
DETECTOR_SHORT = {"cusum": "variance CUSUM", "chi2": "windowed χ²", "glr": "GLR",
                  "bayes": "Shiryaev–Roberts", "oracle": "oracle", "hunting": "hunting RMS"}

#: What each detector's alarm statistic is (its threshold's meaning, dimensionless).
STATISTICS = {"cusum": "CUSUM log-likelihood ratio of the whitened innovations",
              "chi2": "sum of the squared whitened innovations over the window",
              "glr": "largest log-likelihood ratio of a change in the window (nats)",
              "bayes": "log of the mixture Shiryaev–Roberts statistic (nats)",
              "oracle": "log posterior odds that a fault has happened (nats)"}

#: Model parameters (``lateral_16state.PARAM_NAMES``): plain symbol, mathtext symbol, words.
PARAMETERS = {"csy": ("C_sy", r"$C_{sy}$", "secondary lateral damping"),
              "lambda": ("λ", r"$\lambda$", "wheel conicity"),
              "kpy": ("K_py", r"$K_{py}$", "primary lateral stiffness"),
              "ksy": ("K_sy", r"$K_{sy}$", "secondary lateral stiffness"),
              "csaly": ("C_saly", r"$C_{saly}$", "anti-yaw damping")}

#: Dash of a cell without a metric.
NONE = "—"


def fault_short_label(fault: Fault, tex: bool = False) -> str:
    """A fault in a few characters, e.g. "C_saly 50 %" or "C_saly → 50 % (drift)" (mathtext
    symbols with ``tex``, for figures)."""
    plain, math, _ = PARAMETERS.get(fault.parameter, (fault.parameter, fault.parameter, ""))
    symbol = math if tex else plain
    value = f"{number(100 * fault.factor, 3)} %"
    return f"{symbol} → {value} (drift)" if fault.kind == "drift" else f"{symbol} {value}"


def percent(ratio: float) -> str:
    """A rate as a percentage to three significant digits (0.9667 → "96.7 %")."""
    return f"{number(100 * ratio, 3)} %"


def delay_text(value: float | None) -> str:
    """A delay in s, or "beyond the record" for an end that lies beyond it (``None``)."""
    return "beyond the record" if value is None else number(value)


def delay_cell(metrics: dict, tag: str) -> str:
    """``median [low, high]`` of one detector's delays on one fault (s; "beyond the record" /
    "beyond" where an order statistic lies beyond it); NONE when the detector did not run."""
    median = read_censored_median(metrics, "delay_median", tag)
    if median is None:
        return NONE

    def end(x: float | None) -> str:
        return "beyond" if x is None else number(clean(x))
    return f"{delay_text(median.median)} [{end(median.low)}, {end(median.high)}]"


def clean(value: float) -> float:
    """``value`` with floating-point dust (|x| < 1e-12, e.g. 1.1e-16) set to 0."""
    return 0.0 if abs(value) < 1e-12 else value


def interval_text(metrics: dict, key: str, show=number) -> str:
    """``value [low, high]`` of a metric with its 95 % interval; NONE when it is missing."""
    if key not in metrics:
        return NONE
    nan = float("nan")
    value, low, high = (clean(metrics.get(key + tail, nan)) for tail in ("", "_low", "_high"))
    return f"{show(value)} [{show(low)}, {show(high)}]"


def faults_table(result) -> str:
    """One row per fault (and the fault-free vehicle first): its label, the parameter it changes,
    the parameter's value after the fault (% of nominal), abrupt or drifting, and the model's
    critical (hunting) speed once the fault has fully developed ("above 600" where the model is
    stable up to the top of the search, :data:`CRITICAL_SEARCH_TOP_KMH`)."""
    critical = {}
    if result.critical_speeds is not None:
        critical = dict(zip(result.critical_speeds["fault"],
                            result.critical_speeds["critical_speed_kmh"]))

    def speed(name: str) -> str:
        value = critical.get(name)
        if value is None:
            if f"critical_speed_found_{name}" not in result.metrics:
                return NONE
            value = result.metrics.get(f"critical_speed_kmh_{name}", math.nan)
        return f"above {CRITICAL_SEARCH_TOP_KMH:g}" if not math.isfinite(value) else number(value)

    rows = [("fault-free", NONE, "100", NONE, speed(NO_FAULT))]
    for f in result.faults:
        plain, _, words = PARAMETERS.get(f.parameter, (f.parameter, "", ""))
        rows.append((f.label, f"{words} {plain}".strip(), number(100 * f.factor, 3), f.kind,
                     speed(f.name)))
    return markdown(pd.DataFrame(rows, columns=[
        "fault", "parameter", "value after the fault (% of nominal)", "kind",
        "critical speed after the fault (km/h)"]))


def _delay_text(metrics: dict, tag: str) -> str:
    """"median [95 %]; within the shortest / longest horizon" of the metrics tagged ``tag``."""
    short, long_ = WITHIN_S[0], WITHIN_S[-1]
    delay = delay_cell(metrics, tag)
    a = metrics.get(f"detected_within_{short:g}s_{tag}")
    b = metrics.get(f"detected_within_{long_:g}s_{tag}")
    return delay if a is None or b is None else f"{delay}; {percent(a)} / {percent(b)}"


def _delay_table(result, settings: Settings, suffix: str) -> str:
    """One row per fault and detector (the fault named on its first row), one column per speed:
    :func:`_delay_text` of the metrics tagged ``<detector>_<fault>_<speed><suffix>``."""
    short, long_ = WITHIN_S[0], WITHIN_S[-1]
    rows = []
    for f in result.faults:
        for i, det in enumerate(DETECTORS):
            rows.append([f.label if i == 0 else "", DETECTOR_SHORT[det]]
                        + [_delay_text(result.metrics, f"{det}_{f.name}_{speed_key(v)}{suffix}")
                           for v in settings.speeds_kmh])
    return markdown(pd.DataFrame(rows, columns=["fault", "detector"] + [
        f"{v:g} km/h: median delay [95 %] (s); within {short:g} s / {long_:g} s"
        for v in settings.speeds_kmh]))


def detection_table(result, settings: Settings) -> str:
    """One row per fault and detector, one column per speed: the median detection delay with
    its 95 % interval over records (s; "beyond the record" where fewer than half the records
    alarm after the fault), then the shares of records detected within the shortest and the
    longest horizon, at the thresholds of one false-alarm probability per window; "—" for a
    detector not run at that speed."""
    return _delay_table(result, settings, "")


def operating_point_table(result, settings: Settings, mtbfa_h: float = 100.0) -> str:
    """As :func:`detection_table`, at each detector's threshold for ``mtbfa_h`` hours between
    false alarms (a value of :data:`MTBFA_TARGETS_H`; its fault-free tail model)."""
    return _delay_table(result, settings, f"_at_{mtbfa_h:g}h")


def _with_metric(metrics: dict, settings: Settings, prefix: str):
    """(speed, detector, ``<detector>_<speed>``) of every speed and detector with a metric
    ``<prefix><detector>_<speed>``, in the run's order."""
    for speed in settings.speeds_kmh:
        for det in DETECTORS:
            tag = f"{det}_{speed_key(speed)}"
            if prefix + tag in metrics:
                yield speed, det, tag


def tail_table(result, settings: Settings) -> str:
    """Per speed and detector: the exponential tail of its fault-free block maxima (level,
    scale, the share of blocks above the level, blocks) and the check against the evaluation
    records (the mean time between false alarms checked, alarms expected and counted, the
    Poisson p-value)."""
    rows = []
    m = result.metrics
    for speed, det, tag in _with_metric(m, settings, "tail_level_"):
        check = NONE
        if f"tail_check_alarms_{tag}" in m:
            check = (f"at {number(m[f'tail_check_mtbfa_h_{tag}'], 2)} h: "
                     f"{number(m[f'tail_check_expected_{tag}'], 2)} expected, "
                     f"{m[f'tail_check_alarms_{tag}']} counted "
                     f"(p = {number(m[f'tail_check_p_{tag}'], 2)})")
        rows.append((number(speed), DETECTOR_SHORT[det],
                     f"{number(m[f'tail_level_{tag}'])} + Exp({number(m[f'tail_scale_{tag}'])})",
                     f"{percent(m[f'tail_exceed_{tag}'])} of {number(m[f'tail_blocks_{tag}'])}",
                     check))
    return markdown(pd.DataFrame(rows, columns=[
        "speed (km/h)", "detector", "tail of the block maxima", "blocks in the tail",
        "check on the evaluation records"]))


def threshold_table(result, settings: Settings) -> str:
    """Per speed and detector, its threshold for each of :data:`MTBFA_TARGETS_H` with its 95 %
    interval over calibration records resampled, the range of mean times the resampled tails
    give at it, and for ``bayes`` the Shiryaev–Roberts lower bound on the mean time."""
    rows = []
    m = result.metrics
    for speed, det, tag in _with_metric(m, settings, f"threshold_at_{MTBFA_TARGETS_H[0]:g}h_"):
        cells = []
        for target in MTBFA_TARGETS_H:
            key = f"threshold_at_{target:g}h_{tag}"
            text = number(m[key])
            if key + "_low" in m:
                high = m.get(f"mtbfa_h_at_{target:g}h_{tag}_high")
                text += (f" [{number(m[key + '_low'])}, {number(m[key + '_high'])}]; "
                         f"{number(m[f'mtbfa_h_at_{target:g}h_{tag}_low'], 2)} to "
                         + ("unbounded" if high is None else f"{number(high, 2)} h"))
            bound = m.get(f"sr_bound_mtbfa_h_at_{target:g}h_{tag}")
            if bound is not None:
                text += f"; bound ≥ {number(bound, 2)} h"
            cells.append(text)
        rows.append((number(speed), DETECTOR_SHORT[det], *cells))
    return markdown(pd.DataFrame(rows, columns=["speed (km/h)", "detector"] + [
        f"for {t:g} h: threshold [95 %]; the mean time it gives [95 %]" for t in MTBFA_TARGETS_H]))


#: How a check's outcome is shown in :func:`long_running_table`.
OUTCOME_MARK = {"consistent": "", "more alarms": " **more**", "fewer alarms": " *fewer*"}


def long_running_table(check: LongRunningCheck) -> str:
    """Per speed and detector, each check of its tail model on the stored running (alarms
    counted / predicted at the thresholds for each mean time, a column per mean time, the
    outcome where the count contradicts the tail) and the mean time between false alarms the
    tail refitted to the running gives the run's threshold for 100 h."""
    if not len(check.checks):
        return "*No checks: the run has no tail model (too few calibration records).*"
    rows = []
    for (speed, det), group in check.checks.groupby(["speed_kmh", "detector"], sort=False):
        cells = {}
        for row in group.itertuples():
            cells[row.mtbfa_h] = (f"{row.alarms} / {number(row.expected_alarms, 2)}"
                                  + OUTCOME_MARK[row.outcome])
        refit = check.refits[(check.refits["speed_kmh"] == speed)
                             & (check.refits["detector"] == det)
                             & (check.refits["mtbfa_h"] == 100.0)]
        hours = refit["mtbfa_h_of_run_threshold"].iloc[0] if len(refit) else math.nan
        rows.append((f"{DETECTOR_SHORT[det]}, {number(speed)} km/h",
                     *[cells.get(t, NONE) for t in RUNNING_CHECK_H],
                     NONE if not math.isfinite(hours) else number(hours, 2)))
    return markdown(pd.DataFrame(rows, columns=[
        "detector, speed", *[f"{t:g} h" for t in RUNNING_CHECK_H],
        "'100 h' under the refit (h)"]))


def running_delay_table(check: LongRunningCheck, faults: tuple[Fault, ...]) -> str:
    """Per fault and detector, at each speed: the Kaplan–Meier median delay and the share
    detected within 2 s at the threshold for :data:`OPERATING_POINT_H` hours of the run's tail,
    then (→) of the tail refitted to the stored running."""
    table = check.delays
    if table is None or not len(table):
        return "*No delays: the run's records were not given.*"
    speeds = list(check.running_h)
    rows = []
    for fault in faults:
        for i, det in enumerate(DETECTORS):
            cells = []
            for speed in speeds:
                hit = table[(table["speed_kmh"] == speed) & (table["detector"] == det)
                            & (table["fault"] == fault.name)]
                if not len(hit):
                    cells.append(NONE)
                    continue
                row = hit.iloc[0]
                cells.append(
                    f"{_median_text(row['km_delay_median_s_run'])} → "
                    f"{_median_text(row['km_delay_median_s_running'])}; "
                    f"{percent(row['km_detected_within_2s_run'])} → "
                    f"{percent(row['km_detected_within_2s_running'])}")
            rows.append((fault_short_label(fault) if i == 0 else "", DETECTOR_SHORT[det],
                         *cells))
    return markdown(pd.DataFrame(rows, columns=["fault", "detector"] + [
        f"{speed:g} km/h: median delay (s); within 2 s" for speed in speeds]))


def _median_text(value: float) -> str:
    """A Kaplan–Meier median delay, s, or "beyond the record" (NaN: fewer than half detected)."""
    return "beyond the record" if not math.isfinite(value) else number(value)


def _share_text(metrics: dict, key: str) -> str:
    """"35 % [15, 59]": a share with its interval, in percent."""
    return (f"{percent(metrics[key])} [{100 * metrics[key + '_low']:.0f}, "
            f"{100 * metrics[key + '_high']:.0f}]")


def paired_cell(metrics: dict, tag: str) -> str:
    """One pair at one speed: "same sample on all 20 records" where neither ever alarms
    earlier, else the shares of records on which A alarms earlier and later than B (the rest
    are ties) with their intervals, the sign test's share of A among the records where they
    differ, and the median of B − A over the records both detect (s), with the records."""
    m, n = metrics, int(metrics[f"paired_earlier_{tag}_n"])
    both = int(metrics.get(f"paired_both_detected_{tag}", 0))
    if m[f"paired_earlier_{tag}"] == 0 and m[f"paired_later_{tag}"] == 0:
        return (f"same sample on all {n} records" if both == n else
                f"tied on all {n} records ({n - both} detected by neither)")
    text = (f"earlier {_share_text(m, f'paired_earlier_{tag}')}, later "
            f"{_share_text(m, f'paired_later_{tag}')} of {n}")
    if f"paired_sign_share_{tag}" in m:
        text += f"; A first in {_share_text(m, f'paired_sign_share_{tag}')} where they differ"
    key = f"paired_difference_median_s_{tag}"
    if key in m:
        text += (f"; B − A {number(m[key])} [{number(m[key + '_low'])}, "
                 f"{number(m[key + '_high'])}] s on the {both} both detect")
    return text


def paired_table(result, settings: Settings) -> str:
    """Per fault and pair (A, B) of :data:`PAIRS`, at each speed and each detector's threshold
    for :data:`OPERATING_POINT_H` hours of its own tail model, on the same records
    (:func:`paired_cell`)."""
    m = result.metrics
    rows = []
    for fault in result.faults:
        for i, (a, b) in enumerate(PAIRS):
            cells = []
            for speed in settings.speeds_kmh:
                tag = (f"{a}_vs_{b}_{fault.name}_{speed_key(speed)}_at_{OPERATING_POINT_H:g}h")
                cells.append(paired_cell(m, tag) if f"paired_earlier_{tag}" in m else NONE)
            rows.append((fault_short_label(fault) if i == 0 else "",
                         f"{DETECTOR_SHORT[a]} (A) vs {DETECTOR_SHORT[b]} (B)", *cells))
    return markdown(pd.DataFrame(rows, columns=["fault", "pair"] + [
        f"{speed:g} km/h: records on which A alarms earlier, later (% [95 %]); sign test; "
        "median B − A where both detect (s [95 %])" for speed in settings.speeds_kmh]))


def long_running_facts(check: LongRunningCheck, metrics: dict, settings: Settings,
                       power_check_h: float = 0.1) -> dict[str, str]:
    """What the page says of the stored running, as text: the power of the consistency rule
    (two-sided, on the running watched) against twice the alarms predicted at
    ``power_check_h`` hours, per speed (``power``); the orders of magnitude from each tail's
    running to 100 h (``orders_run``: the calibration records', ``orders_refit``: the stored
    running's, the smallest over speeds) and how many times as many blocks the refit has
    (``block_ratio``, the smallest over speeds)."""
    speeds = list(check.running_h)
    calibration_h = [metrics[f"tail_blocks_cusum_{speed_key(v)}"] * check.block_s
                     / SECONDS_PER_HOUR for v in speeds]
    ratio = min(len(check.maxima[("cusum", v)]) / metrics[f"tail_blocks_cusum_{speed_key(v)}"]
                for v in speeds)
    return {"power": ", ".join(f"{poisson_two_sided_power(h / power_check_h, 2.0):.2f} at "
                               f"{v:g} km/h" for v, h in check.running_h.items()),
            "orders_run": f"{math.log10(OPERATING_POINT_H / max(calibration_h)):.1f}",
            "orders_refit": f"{math.log10(OPERATING_POINT_H / max(check.running_h.values())):.1f}",
            "block_ratio": f"{ratio:.0f}" if ratio >= 10 else f"{ratio:.2g}"}


def long_running_summary(check: LongRunningCheck) -> str:
    """"3 of 50 checks contradict their tail (2 with more alarms, 1 with fewer)"."""
    outcomes = check.checks["outcome"] if len(check.checks) else pd.Series([], dtype=str)
    more, fewer = int((outcomes == "more alarms").sum()), int((outcomes == "fewer alarms").sum())
    return (f"{more + fewer} of {len(outcomes)} checks contradict their tail ({more} with more "
            f"alarms than predicted, {fewer} with fewer)")


def long_running_outcomes(check: LongRunningCheck, mtbfa_h: float) -> str:
    """"GLR at 200 km/h (more alarms)": the detectors and speeds whose tail the stored running
    contradicts at the threshold for ``mtbfa_h`` hours, or "no detector"."""
    if not len(check.checks):
        return "no detector"
    rows = check.checks[(check.checks["mtbfa_h"] == mtbfa_h)
                        & (check.checks["outcome"] != "consistent")]
    if not len(rows):
        return "no detector"
    return ", ".join(f"{DETECTOR_SHORT[r.detector]} at {number(r.speed_kmh)} km/h ({r.outcome})"
                     for r in rows.itertuples())


def tail_check_failures(metrics: dict, speeds_kmh, level: float = 0.05) -> str:
    """"GLR and Shiryaev–Roberts at 200 km/h": the detectors and speeds whose tail model the
    evaluation records refute (two-sided Poisson p-value of its check below ``level``), or
    "no detector" when there is none."""
    parts = []
    for speed in speeds_kmh:
        failed = [DETECTOR_SHORT[d] for d in DETECTORS
                  if metrics.get(f"tail_check_p_{d}_{speed_key(speed)}", 1.0) < level]
        if failed:
            names = failed[0] if len(failed) == 1 else ", ".join(failed[:-1]) + " and " + failed[-1]
            parts.append(f"{names} at {speed:g} km/h")
    return "; ".join(parts) if parts else "no detector"


#: Short names of the realism ladder's rungs.
RUNG_SHORT = {"ideal": "ideal (five channels)",
              "no_axlebox_gyro_001": "no axle-box accelerometers, gyro 0.01 rad/s",
              "accelerometers_only": "bogie and car-body accelerometers only",
              "track_unknown": "accelerometers only, the track input unknown",
              "model_error": "… and the truth with model error"}


def ladder_table(result, settings: Settings) -> str:
    """The realism ladder at ``ladder_speed_kmh``, thresholds for :data:`LADDER_MTBFA_H` hours
    between false alarms recalibrated on each rung: one row per fault and detector, one column
    per rung: the Kaplan–Meier median delay with its 95 % interval (s; "not reached" where fewer
    than half the records are detected), the share detected within 2 s, and in brackets the
    share within 2 s at the ideal rung's thresholds; "—" where the ladder did not run; a rung
    the run left out has no column."""
    m = result.metrics
    rungs = [r for r in ["ideal"] + list(LADDER)
             if r == "ideal" or any(k.startswith(f"ladder_{r}_") for k in m)]
    return rung_table(m, result.faults, settings, rungs, "ladder_")


def stored_ladder_table(metrics: dict, faults, settings: Settings) -> str:
    """:func:`ladder_table` of the stored rungs beside the ideal rung of the run's records at
    the ladder's speed (metrics ``stored_ladder_…`` of
    :func:`~railpaper.experiments.suspension_fault_detection.experiment.stored_ladder`)."""
    return rung_table(metrics, faults, settings, ["ideal"] + list(STORED_RUNGS),
                      "stored_ladder_", STORED_DETECTORS)


def stored_ladder_facts(metrics: dict, table: pd.DataFrame | None, faults, summary: dict,
                        provenance: dict, settings: Settings) -> dict[str, str]:
    """What the page says of the stored rungs, as text, keyed by its glue names:

    * the truth's model error (``me_…`` of ``summary``,
      :func:`~railpaper.experiments.suspension_fault_detection.faults.model_error_summary`, its
      critical speeds with the series stiffness halved and doubled and with a pure damper);
    * the store's records per fault and fault-free (``stored_records``, ``stored_free``), those
      this run pairs (``paired_records``, and ``stored_paired_note``: a warning where it pairs
      fewer) and their cost (``stored_cpu_min``);
    * the fault-free flange contacts and the fault records ended before their fault
      (``stored_free_flange``, ``stored_before_fault``), and per stored rung the fault records
      that reach flange contact after their fault and how soon (``stored_flange_<rung>``, of
      the records that reached their fault);
    * each detector's threshold for :data:`LADDER_MTBFA_H` hours rung by rung
      (``stored_thresholds``), the faults a detector not knowing the fault finds within 2 s on
      at least half the records (``stored_found_<rung>``), the false alarms per hour at the
      ideal rung's thresholds with their 95 % intervals (``stored_ideal_false_alarms``), and
      the tail checks that fail at p < 0.05 with the mean time they check
      (``stored_tail_checks``).

    "—" where nothing is stored."""
    def kmh(v):
        return "above the search's end" if not math.isfinite(v) else f"{v:.0f}"
    rungs = list(STORED_RUNGS)
    out = {"me_friction": f"{summary['friction']:g}",
           "me_yc_mm": f"{1e3 * summary['conicity_scale_m']:g}",
           "me_conicity": f"{summary['conicity']:.2g}",
           "me_conicity_filters": f"{summary['conicity_filters']:.2g}",
           "me_ks_mn": f"{summary['series_stiffness_N_per_m'] / 1e6:g}",
           "me_tau_ms": f"{1e3 * summary['maxwell_time_s']:.3g}",
           "me_corner_hz": f"{1 / (2 * math.pi * summary['maxwell_time_s']):.2g}",
           "me_critical": kmh(summary["critical_speed_kmh"]),
           "me_critical_half": kmh(summary["critical_speed_csaly_half_kmh"]),
           "me_critical_stiffness": ", ".join(
               f"{kmh(v)} km/h at "
               f"{float(k.rsplit('_x', 1)[1]) * summary['series_stiffness_N_per_m'] / 1e6:g} MN/m"
               for k, v in summary.items() if k.startswith("critical_speed_kmh_stiffness_x")),
           "me_critical_pure": kmh(summary["critical_speed_kmh_pure_damper"]),
           "stored_cpu_min": f"{provenance.get('cpu_s', 0.0) / 60:.2g}"}
    keys = ["stored_records", "stored_free", "paired_records", "stored_paired_note",
            "stored_free_flange", "stored_before_fault", "stored_tail_checks",
            "stored_ideal_false_alarms", "stored_thresholds"] + [
        f"stored_{kind}_{r}" for kind in ("found", "flange") for r in rungs]
    if table is None or not len(table):
        return dict(out, **{k: NONE for k in keys})
    sk = speed_key(settings.ladder_speed_kmh)
    per_seed = len(faults) + 2                       # each fault, calibration, evaluation
    stored_per_fault = min(metrics[f"stored_ladder_{r}_stored_records"] for r in rungs) \
        // per_seed
    paired = int(table["records"].max())
    out["stored_records"] = f"{stored_per_fault}"
    out["stored_free"] = f"{2 * stored_per_fault}"
    out["paired_records"] = f"{paired}"
    out["stored_paired_note"] = "" if paired >= stored_per_fault else (
        f" This run holds only {paired} records per fault at the ladder's speed, so only "
        f"{paired} of the stored ones per fault are paired with it and read below: with so "
        "few, what follows is a smoke test, and the default run's page is the reading.")
    out["stored_free_flange"] = ", ".join(
        f"{metrics[f'stored_ladder_{r}_fault_free_flange_contacts']} of "
        f"{metrics[f'stored_ladder_{r}_fault_free_records']} on the {RUNG_WORDS[r]}"
        for r in ["ideal"] + rungs if f"stored_ladder_{r}_fault_free_records" in metrics)
    ended = table.drop_duplicates(["rung", "fault"]).groupby("rung", sort=False)
    out["stored_before_fault"] = ", ".join(
        f"{int(g['ended_before_fault'].sum())} of {int(g['records'].sum())} on the "
        f"{RUNG_WORDS[r]}" for r, g in ended)
    label = {f.name: fault_short_label(f) for f in faults}
    for r in rungs:
        parts = []
        for f in faults:
            tag = f"{f.name}_{sk}"
            rate_key = f"stored_ladder_{r}_flange_contact_rate_{tag}"
            if rate_key not in metrics:
                continue
            n = metrics.get(f"{rate_key}_n", paired)
            text = f"{label[f.name]} {round(metrics[rate_key] * n)} of {n}"
            after = metrics.get(f"stored_ladder_{r}_flange_contact_after_s_{tag}")
            parts.append(text + ("" if after is None else f" (median {number(after, 2)} s "
                                                          "after the fault)"))
        out[f"stored_flange_{r}"] = ", ".join(parts) or NONE
        out[f"stored_found_{r}"] = found_within_2s(table[table["rung"] == r], faults)
    out["stored_ideal_false_alarms"] = "; ".join(
        f"on the {RUNG_WORDS[r]} " + ", ".join(
            f"{DETECTOR_SHORT[d]} {number(metrics[key], 3)} "
            f"[{number(metrics[key + '_low'], 3)}, {number(metrics[key + '_high'], 3)}]"
            for d in STORED_DETECTORS
            if (key := f"stored_ladder_{r}_ideal_thresholds_false_alarms_per_hour_{d}_{sk}")
            in metrics)
        for r in rungs)
    out["stored_thresholds"] = "; ".join(
        f"{DETECTOR_SHORT[d]} " + " → ".join(
            number(metrics[k], 3) if (k := f"stored_ladder_{r}_threshold_at_"
                                            f"{LADDER_MTBFA_H:g}h_{d}_{sk}") in metrics else NONE
            for r in ["ideal"] + rungs) for d in STORED_DETECTORS)
    failed, checked_h = [], []
    for r in ["ideal"] + rungs:
        for d in STORED_DETECTORS:
            tag = f"{d}_{sk}"
            if f"stored_ladder_{r}_tail_check_mtbfa_h_{tag}" in metrics:
                checked_h.append(metrics[f"stored_ladder_{r}_tail_check_mtbfa_h_{tag}"])
            if metrics.get(f"stored_ladder_{r}_tail_check_p_{tag}", 1.0) < 0.05:
                alarms = metrics[f"stored_ladder_{r}_tail_check_alarms_{tag}"]
                expected = metrics[f"stored_ladder_{r}_tail_check_expected_{tag}"]
                side = "too low, favourable to it" if alarms > expected else "too high"
                failed.append(f"{DETECTOR_SHORT[d]} on the {RUNG_WORDS[r]} ({alarms} exceeding "
                              f"blocks where {number(expected, 2)} were predicted; its "
                              f"thresholds are {side})")
    where = ("" if not checked_h else f" at about {number(max(checked_h), 2)} h between false "
             f"alarms, {math.log10(LADDER_MTBFA_H / max(checked_h)):.1f} orders of magnitude "
             f"short of {LADDER_MTBFA_H:g} h")
    out["stored_tail_checks"] = (f"checked{where}, the tail fails (p < 0.05) for "
                                 + "; ".join(failed) if failed
                                 else f"checked{where}, no tail fails at p < 0.05")
    return out


def found_within_2s(rows: pd.DataFrame, faults) -> str:
    """"lost damper (GLR, Shiryaev–Roberts), …": the faults that some detector not knowing the
    fault detects within 2 s on at least half of their records, with those detectors; "none"."""
    found, label = [], {f.name: fault_short_label(f) for f in faults}
    for fault, group in rows.groupby("fault", sort=False):
        who = [DETECTOR_SHORT[d] for d in STORED_DETECTORS if d != "oracle"
               and (group.loc[group["detector"] == d, "detected_within_2s"] >= 0.5).any()]
        if who:
            found.append(f"{label.get(fault, fault)} ({', '.join(who)})")
    return ", ".join(found) if found else "none"


#: The rungs in words, for sentences.
RUNG_WORDS = {"ideal": "ideal rung", "track_unknown": "track-unknown rung",
              "model_error": "model-error rung"}


def rung_table(m: dict, faults, settings: Settings, rungs: list[str], prefix: str,
               detectors: dict = DETECTORS) -> str:
    """The table of :func:`ladder_table` for ``rungs`` and ``detectors`` from metrics
    ``<prefix><rung>_…``."""
    sk = speed_key(settings.ladder_speed_kmh)
    rows = []
    for f in faults:
        for i, det in enumerate(detectors):
            row = [f.label if i == 0 else "", DETECTOR_SHORT[det]]
            tag = f"{det}_{f.name}_{sk}_at_{LADDER_MTBFA_H:g}h"
            for rung in rungs:
                key = f"{prefix}{rung}_km_delay_median_s_{tag}"
                if f"{prefix}{rung}_km_delay_median_reached_{tag}" not in m:
                    row.append(NONE)
                    continue
                text = interval_text(m, key) if key in m else "not reached"
                within = m.get(f"{prefix}{rung}_detected_within_2s_{tag}")
                text += "" if within is None else f"; {percent(within)}"
                ideal = m.get(f"{prefix}{rung}_ideal_thresholds_detected_within_2s_{tag}")
                row.append(text + ("" if ideal is None else f" ({percent(ideal)})"))
            rows.append(row)
    return markdown(pd.DataFrame(rows, columns=["fault", "detector"] + [
        f"{RUNG_SHORT.get(r, r)}: median delay [95 %] (s); within 2 s" for r in rungs]))


def false_alarm_table(result, settings: Settings) -> str:
    """Per speed and detector: its alarm threshold (set on the calibration records at the run's
    false-alarm probability; dimensionless, the statistic named), the false alarms per hour on
    the evaluation records with their 95 % interval, and how many evaluation records there
    were; detectors not run at a speed are left out."""
    rows = []
    for speed in settings.speeds_kmh:
        sk = speed_key(speed)
        for det in DETECTORS:
            key = f"false_alarms_per_hour_{det}_{sk}"
            if key not in result.metrics:
                continue
            h = result.thresholds.get((det, speed), result.metrics.get(f"threshold_{det}_{sk}"))
            rows.append((number(speed), DETECTOR_SHORT[det], STATISTICS[det],
                         NONE if h is None else number(h), interval_text(result.metrics, key),
                         number(result.metrics.get(key + "_n", float("nan")))))
    return markdown(pd.DataFrame(rows, columns=[
        "speed (km/h)", "detector", "alarm statistic", "threshold",
        "false alarms per hour [95 %] (1/h)", "evaluation records"]))


def estimate_table(result, settings: Settings) -> str:
    """Per speed and fault: the median |post-fault estimate − truth| of the faulted parameter at
    the record's end (fraction of nominal) with its 95 % interval and the number of records, of
    the oracle (its posterior mean) and of the GLR's best hypothesis (its factor when it names
    the faulted parameter, else 1); then the share of records alarmed after the fault whose
    GLR's best hypothesis at the alarm of ``glr`` and of ``bayes`` names the faulted parameter,
    with its 95 % interval and count ("—": none alarmed)."""
    estimators = [d for d in ("oracle", "glr") if d in DETECTORS]
    blamers = [d for d in ("glr", "bayes") if d in DETECTORS]
    rows = []
    for speed in settings.speeds_kmh:
        sk = speed_key(speed)
        for f in result.faults:
            row = [number(speed), f.label]
            for det in estimators:
                key = f"post_fault_error_{det}_{f.name}_{sk}"
                text = interval_text(result.metrics, key)
                if key + "_n" in result.metrics:
                    text += f" (n = {number(result.metrics[key + '_n'])})"
                row.append(text)
            for det in blamers:
                key = f"isolated_{det}_{f.name}_{sk}"
                text = interval_text(result.metrics, key, percent)
                if key + "_n" in result.metrics:
                    text += f" (n = {number(result.metrics[key + '_n'])})"
                row.append(text)
            rows.append(row)
    return markdown(pd.DataFrame(rows, columns=["speed (km/h)", "fault"] + [
        f"{DETECTOR_SHORT[d]}: error [95 %]" for d in estimators] + [
        f"{DETECTOR_SHORT[d]}: right parameter [95 %]" for d in blamers]))


def fault_free_flange_text(metrics: dict, speeds_kmh) -> str:
    """"2 of 60 records at 300 km/h, 0 of 60 at 200 km/h": the fault-free records that reach
    flange contact, per speed."""
    parts = []
    for speed in speeds_kmh:
        tag = speed_key(speed)
        n = metrics.get(f"flange_contact_rate_fault_free_{tag}_n")
        if n is None:
            continue
        hits = metrics[f"flange_contacts_fault_free_{tag}"]
        parts.append(f"{hits} of {n}" + (" records" if not parts else "")
                     + f" at {speed:g} km/h")
    return ", ".join(parts) if parts else "no fault-free records"


__all__ = ["DETECTOR_SHORT", "PARAMETERS", "RUNG_SHORT", "STATISTICS", "clean", "delay_cell",
           "RUNG_WORDS", "found_within_2s", "rung_table", "stored_ladder_facts",
           "stored_ladder_table",
           "delay_text", "detection_table", "estimate_table", "false_alarm_table",
           "fault_free_flange_text", "fault_short_label", "faults_table", "interval_text",
           "ladder_table", "long_running_facts", "long_running_outcomes",
           "long_running_summary", "long_running_table", "operating_point_table", "paired_cell",
           "paired_table", "percent", "running_delay_table", "tail_check_failures", "tail_table",
           "threshold_table"]
