"""Tables of the rbpf-parameter-estimation chapter as a reader sees them: MyST Markdown, 3-4
significant digits, units in the headers, no internal metric names."""

from __future__ import annotations

import numpy as np
import pandas as pd

from railpaper.experiments.display import markdown, number

#: Display names of the five lateral parameters (LaTeX, for Markdown tables and plot labels).
PARAM_LABELS = {"csy": "$C_{sy}$", "lambda": r"$\lambda$", "kpy": "$K_{py}$", "ksy": "$K_{sy}$",
                "csaly": "$C_{saly}$"}
#: The same in words (for text where no math renders).
PARAM_WORDS = {"csy": "the secondary lateral damping", "lambda": "the equivalent conicity",
               "kpy": "the primary lateral stiffness", "ksy": "the secondary lateral stiffness",
               "csaly": "the anti-yaw damping"}


#: The toy's statistics the claims read (metric -> what a reader sees).
TOY_EVIDENCE = {
    "toy_ekf_fail_rate_init1": "EKF fails to converge from init. 1 (rate of records)",
    "toy_ekf_blowup_rate_init1": "EKF diverges numerically from init. 1 (rate)",
    "toy_ekf_converge_rate_init2": "EKF converges from init. 2 (rate)",
    "toy_ekf_outcome_differs_rate": "EKF outcome differs between init. 1 and 2 (rate)",
    "toy_rbpf_converge_rate_init1": "RBPF (paper's scheme) converges from init. 1 (rate)",
    "toy_rbpf_converge_both_rate": "RBPF (paper's scheme) converges from both (rate)",
    "toy_error_gap_ekf_minus_rbpf_init1": "EKF − RBPF final max |error|, init. 1 (median)",
    "toy_settle_gap_ekf_minus_rbpf_init1": "EKF − RBPF settle step, init. 1 (median)",
}
_SCHEMES = (("_paper_scheme", "RBPF, paper's scheme"), ("_working_scheme", "RBPF, our scheme"))
#: The lateral vehicle's statistics the claims read (metric -> what a reader sees).
LATERAL_EVIDENCE = {
    **{f"lateral_within_5pct_from_350_rate{s}": f"{w}: every parameter within 5 % from step 350 "
       "(rate of records)" for s, w in _SCHEMES},
    **{f"lateral_within_5pct_at_350_rate{s}": f"{w}: every parameter within 5 % at step 350 "
       "(rate)" for s, w in _SCHEMES},
    **{f"lateral_bias_max_abs{s}": f"{w}: largest |mean final relative error| (1)"
       for s, w in _SCHEMES},
    "lateral_ekf_converge_rate": "EKF ends within 5 % (rate, one guess per record)",
}


def evidence_markdown(metrics: dict, names: dict[str, str]) -> str:
    """The statistics ``names`` (metric -> description) of a run with their 95 % intervals and
    record counts, as a Markdown table (one row per statistic the run has; a sentence if it has
    none: a run on a user's record has no Monte Carlo statistics)."""
    rows = [(text, number(metrics[m]), f"[{number(metrics[m + '_low'])}, "
             f"{number(metrics[m + '_high'])}]", int(metrics[m + "_n"]))
            for m, text in names.items() if m in metrics]
    if not rows:
        return "No Monte Carlo statistics: this run filtered a single record of the user's.\n"
    return markdown(pd.DataFrame(rows, columns=["statistic", "value", "95 % interval",
                                                "records"]))


#: Symbols of the vehicle's quantities as the paper writes them (Markdown math).
SYMBOLS = {"mw": "$m_w$", "iwz": "$I_{wz}$", "mb": "$m_b$", "ib": "$I_b$", "mbd": "$m_{bd}$",
           "kpx": "$K_{px}$", "a": "$a$", "b": "$b$", "lbw": "$L_{bw}$", "l0": "$l_0$",
           "r0": "$r_0$", "f11": "$f_{11}$", "f22": "$f_{22}$", **PARAM_LABELS}


def quantities_markdown(quantities: dict) -> str:
    """The vehicle's quantities (name -> Quantity with value, unit, source) as a Markdown table,
    each named by its symbol."""
    def unit(text: str) -> str:                               # kg*m^2 -> kg m²
        return text.replace("*", " ").replace("^2", "²")
    rows = [(SYMBOLS.get(k, f"`{k}`"), number(v.value), unit(v.unit), v.source)
            for k, v in quantities.items()]
    return markdown(pd.DataFrame(rows, columns=["symbol", "value", "unit", "source"]))


def crlb_markdown(crlb: pd.DataFrame | None, normalised: np.ndarray, steps: int = 350) -> str:
    """CRLB standard deviations (relative, %) beside one record's RBPF errors.

    Parameters
    ----------
    crlb : DataFrame or None
        Column ``parameter`` and columns ``<known|unknown>_<steps>`` of relative CRLB std (1);
        None (a user's record): a sentence instead of the table.
    normalised : ndarray, shape (K, 5)
        One record's estimates divided by the true values (1).
    steps : int
        The step at which the RBPF error is shown beside the final one.
    """
    if crlb is None:
        return "No Cramér–Rao bound: it needs the true parameters of a simulated record.\n"
    head = {"known": "input known", "unknown": "input unknown"}
    out = pd.DataFrame({"parameter": [PARAM_LABELS.get(p, p) for p in crlb.parameter]})
    for col in crlb.columns.drop("parameter"):
        which, n = col.split("_")
        out[f"CRLB std, {head[which]}, {n} steps (%)"] = [number(100 * v, 3) for v in crlb[col]]
    out[f"RBPF |error| at step {steps} (%)"] = [number(100 * abs(normalised[steps - 1, j] - 1), 3)
                                                for j in range(normalised.shape[1])]
    out["RBPF |error| final (%)"] = [number(100 * abs(normalised[-1, j] - 1), 3)
                                     for j in range(normalised.shape[1])]
    return markdown(out)


def final_estimates_markdown(estimates: dict[str, np.ndarray], labels: list[str],
                             reference: np.ndarray, what: str) -> str:
    """The last row of each estimator's estimates against a reference, one row per estimator.

    Parameters
    ----------
    estimates : dict of str to ndarray, each (K, d)
        Display name -> estimates per step.
    labels : list of str
        Display names of the d parameters (Markdown).
    reference : ndarray, shape (d,)
        The true values (a first row), in the unit of the estimates.
    what : str
        ``"error"``: last column the largest absolute error; ``"relative"``: the estimates are
        θ̂/θ and the last column the largest relative error in %.
    """
    rows = [["true value", *[number(v) for v in reference], "—"]]
    for name, est in estimates.items():
        last = np.asarray(est)[-1]
        worst = np.max(np.abs(last - reference))
        rows.append([name, *[number(v) for v in last],
                     number(100 * worst, 3) if what == "relative" else number(worst, 3)])
    head = "largest error (%)" if what == "relative" else "largest absolute error (1)"
    corner = "final estimate / true value" if what == "relative" else "final estimate"
    return markdown(pd.DataFrame(rows, columns=[corner, *labels, head]))


def caption_values(result, params: dict) -> dict[str, str]:
    """Numbers of this run for the captions and the text (Markdown strings, glued by name)."""
    toy, lat, m = result.toy, result.lateral, result.metrics
    out = {"seed": str(params["seed"]), "toy_records": str(params["toy_seeds"]),
           "toy_steps": str(toy.steps), "toy_never": str(toy.steps + 1),
           "toy_tol": number(params["toy_bias_tol"]),
           "speed": f"{number(params['speed_kmh'])} km/h",
           "prior_box": f"{number(params['prior_low'])}–{number(params['prior_high'])}"}
    one = toy.records[toy.records.seed == toy.seed].set_index("init")
    for ic in (1, 2):
        out[f"toy_err_paper_{ic}"] = number(one.rbpf_err_max[ic], 3)
        out[f"toy_err_ekf_{ic}"] = number(one.ekf_err_max[ic], 3)
    if lat is None:
        return out | posterior_values(result, params)
    hunting = {k: m[f"critical_speed_kmh_{k}"] for k in ("chosen", "all_halved",
                                                            "wheelset_bogie_doubled")}
    for key, v in hunting.items():
        top = lat.critical_speed.speed_kmh.max()
        out[f"hunting_{key}"] = f"at {v:.0f} km/h" if v > 0 else f"at no speed up to {top:.0f} km/h"
    n, K = len(lat.runs), len(lat.t_s)
    out.update(lat_records=str(n), lat_steps=str(K),
               least_damped=number(m["least_damped_real_at_speed_per_s"], 3))
    for scheme in ("paper", "working"):                       # the claims' statistics
        rate = m.get(f"lateral_within_5pct_from_350_rate_{scheme}_scheme")
        out[f"within_{scheme}"] = "—" if rate is None else f"{round(rate * n)} of {n}"
        bias = m.get(f"lateral_bias_max_abs_{scheme}_scheme")
        out[f"bias_{scheme}"] = "—" if bias is None else f"{number(100 * bias, 2)} %"
    out.update(crlb_worst="—", crlb_worst_name="—", ekf_count="none (a user's record)")
    if lat.crlb is not None:                                  # simulated records
        worst = lat.crlb.set_index("parameter")["known_350"]
        out["crlb_worst"] = f"{number(100 * worst.max(), 2)} %"
        out["crlb_worst_name"] = PARAM_WORDS[worst.idxmax()]
        out["ekf_count"] = f"{lat.ekf_converged_count} of {len(lat.illustrated.ekf_norm)}"
    return out | posterior_values(result, params)


def posterior_values(result, params: dict) -> dict[str, str]:
    """The exact-posterior, calibration and model-error sections' numbers
    (:func:`~railpaper.experiments.rbpf_parameter_estimation_tables_posterior.caption_values`)."""
    from railpaper.experiments import rbpf_parameter_estimation_tables_posterior as posterior
    return posterior.caption_values(result, params)


def text_markdown(frame: pd.DataFrame) -> str:
    """A table of text (e.g. the errata) as Markdown, empty cells blank, nothing cut."""
    return markdown(frame.fillna("").astype(str))


__all__ = ["LATERAL_EVIDENCE", "PARAM_LABELS", "PARAM_WORDS", "SYMBOLS", "TOY_EVIDENCE",
           "caption_values", "crlb_markdown", "evidence_markdown", "final_estimates_markdown",
           "quantities_markdown", "text_markdown"]
