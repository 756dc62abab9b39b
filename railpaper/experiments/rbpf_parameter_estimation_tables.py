"""Tables of the rbpf-parameter-estimation chapter as a reader sees them: MyST Markdown, 3-4
significant digits, units in the headers, no internal metric names."""

from __future__ import annotations

import numpy as np
import pandas as pd

from railpaper.experiments.display import markdown, number

#: Display names of the five lateral parameters (LaTeX, for Markdown tables and plot labels).
PARAM_LABELS = {"csy": "$C_{sy}$", "lambda": r"$\lambda$", "kpy": "$K_{py}$", "ksy": "$K_{sy}$",
                "csaly": "$C_{saly}$"}


def evidence_markdown(metrics: dict, names: dict[str, str]) -> str:
    """The statistics ``names`` (metric -> description) of a run with their 95 % intervals and
    record counts, as a Markdown table (one row per statistic)."""
    rows = [(text, number(metrics[m]), f"[{number(metrics[m + '_low'])}, "
             f"{number(metrics[m + '_high'])}]", int(metrics[m + "_n"]))
            for m, text in names.items()]
    return markdown(pd.DataFrame(rows, columns=["statistic", "value", "95 % interval",
                                                "records"]))


def quantities_markdown(quantities: dict) -> str:
    """The vehicle's quantities (name -> Quantity with value, unit, source) as a Markdown table."""
    rows = [(f"`{k}`", number(v.value), v.unit, v.source) for k, v in quantities.items()]
    return markdown(pd.DataFrame(rows, columns=["quantity", "value", "unit", "source"]))


def crlb_markdown(crlb: pd.DataFrame, normalised: np.ndarray, steps: int = 350) -> str:
    """CRLB standard deviations (relative, %) beside one record's RBPF errors.

    Parameters
    ----------
    crlb : DataFrame
        Column ``parameter`` and columns ``<known|unknown>_<steps>`` of relative CRLB std (1).
    normalised : ndarray, shape (K, 5)
        One record's estimates divided by the true values (1).
    steps : int
        The step at which the RBPF error is shown beside the final one.
    """
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


def text_markdown(frame: pd.DataFrame) -> str:
    """A table of text (e.g. the errata) as Markdown, empty cells blank, nothing cut."""
    return markdown(frame.fillna("").astype(str))


__all__ = ["PARAM_LABELS", "crlb_markdown", "evidence_markdown", "quantities_markdown",
           "text_markdown"]
