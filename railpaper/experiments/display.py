"""Numbers and tables as a reader sees them on a chapter page (shared by the chapters):
3-4 significant digits, "never" for a convergence that did not happen, MyST tables whose text is
never cut."""

from __future__ import annotations

import math

import pandas as pd


def number(value, digits: int = 4) -> str:
    """``value`` to ``digits`` significant digits (integers as they are; NaN as "—")."""
    if isinstance(value, (bool, str)):
        return str(value)
    if isinstance(value, int):
        return str(value)
    value = float(value)
    if math.isnan(value):
        return "—"
    if value == 0.0:
        return "0"
    text = f"{value:.{digits}g}"
    if 1e-4 <= abs(value) < 1e6:                          # plain digits, no exponent
        decimals = max(digits - 1 - math.floor(math.log10(abs(float(text)))), 0)
        plain = f"{float(text):.{decimals}f}"
        return plain.rstrip("0").rstrip(".") if "." in plain else plain
    if "e" in text:
        mantissa, exponent = text.split("e")
        return f"${mantissa} \\times 10^{{{int(exponent)}}}$"
    return text


def seconds(value: float) -> str:
    """A time in s, or "never" for the -1 of a convergence that did not happen."""
    return "never" if value < 0 else number(value)


def markdown(frame: pd.DataFrame) -> str:
    """A DataFrame as a MyST table: header from the column names, cells as they are (strings)."""
    def cell(text) -> str:
        return str(text).replace("|", "\\|").replace("\n", " ")
    lines = ["| " + " | ".join(cell(c) for c in frame.columns) + " |",
             "|" + "---|" * len(frame.columns)]
    lines += ["| " + " | ".join(cell(v) for v in row) + " |"
              for row in frame.itertuples(index=False)]
    return "\n".join(lines) + "\n"


def legend_below(fig, ax, ncol: int = 2) -> None:
    """One legend for the whole figure, below the axes (outside the data), with the handles
    and labels of ``ax``; the caller leaves room with ``fig.tight_layout(rect=(0, b, 1, 1))``."""
    handles, labels = ax.get_legend_handles_labels()
    fig.legend(handles, labels, loc="lower center", ncol=ncol, frameon=False)
