"""The claims ledger as a figure: each claim's paper value against our interval, by verdict.

One panel per chapter, one line per claim (its headline row, see :mod:`railpaper.pipeline.ledger`).
Scales differ between claims (steps, seconds, rates, correlations), so each line is drawn on a
common scale: our interval (the prediction interval for a single-run claim, the confidence
interval otherwise) maps to [−1, 1], and the paper's value (or, for a claim without a number,
the first threshold its rule compares our interval with) is marked where it falls on that scale (clipped at ±4, an
arrow beyond).  Inside [−1, 1]: our evidence holds the paper's value; far outside: it does not.
Deterministic claims have no interval and are drawn at 0 when exact agreement, at the edge when
not.  The marker's colour is the verdict's (the badge colours of ``book/_static/verdicts.css``).
"""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

#: Marker colours of the verdicts (the text colours of the ledger's badges).
VERDICT_COLOURS = {"reproduced": "#15803d", "attainable": "#6d28d9", "artefact": "#b45309",
                   "differs": "#b91c1c", "undecided": "#1d4ed8", "not testable": "#6b7280",
                   "missing": "#9ca3af"}
CLIP = 4.0


def claim_position(row) -> float | None:
    """Where the paper's value falls on the common scale (our interval = [−1, 1]); None when
    there is nothing to place (no number on either side)."""
    reference = row.reference
    if isinstance(reference, bool) or not isinstance(reference, (int, float)):
        return None
    if row.ours_low is None or row.ours_high is None:        # deterministic: exact or not
        if not isinstance(row.ours_value, (int, float)) or isinstance(row.ours_value, bool) \
                or row.paper_value is None:
            return None                                       # a check with no paper number
        return 0.0 if row.ours_value == reference else CLIP if row.ours_value > reference \
            else -CLIP
    low, high = float(row.ours_low), float(row.ours_high)
    if row.kind == "single-run" and row.paper_value is not None:
        reference = abs(reference) if low >= 0 else reference     # |errors| against |paper|
    centre, half = (low + high) / 2, (high - low) / 2
    if half <= 0:
        return 0.0 if reference == centre else (CLIP if reference > centre else -CLIP)
    return max(-CLIP, min(CLIP, (reference - centre) / half))


def plot_ledger(rows, titles: dict[str, str], path: str | Path) -> Path:
    """Draw the headline rows of every chapter in ``rows`` and save the PNG at ``path``."""
    chapters = list(dict.fromkeys(r.chapter for r in rows)) or ["(no claims)"]
    heads = {c: [r for r in rows if r.chapter == c and r.headline] for c in chapters}
    heights = [max(len(h), 1) for h in heads.values()]
    fig, axes = plt.subplots(len(chapters), 1, figsize=(9, 0.28 * sum(heights) + 1.2 * len(chapters)),
                             gridspec_kw={"height_ratios": heights}, squeeze=False)
    for ax, chapter in zip(axes[:, 0], chapters):
        mine = heads[chapter]
        ax.axvspan(-1, 1, color="#e5e7eb", zorder=0)
        for y, r in enumerate(mine):
            x = claim_position(r)
            label = r.claim if len(r.claim) <= 62 else r.claim[:60] + "…"
            ax.text(-CLIP - 0.3, y, f"{label} ({r.kind})", ha="right", va="center", fontsize=7)
            if x is None:
                ax.text(0, y, "no number to place (exact check or no paper number)", ha="center", va="center", fontsize=6,
                        color=VERDICT_COLOURS[r.verdict])
                continue
            marker = ">" if x >= CLIP else "<" if x <= -CLIP else "o"
            ax.plot([x], [y], marker=marker, color=VERDICT_COLOURS[r.verdict], markersize=6)
        ax.set_ylim(len(mine) - 0.5, -0.5)
        ax.set_xlim(-CLIP - 0.2, CLIP + 0.2)
        ax.set_yticks([])
        title = titles.get(chapter, chapter)
        ax.set_title(title if len(title) <= 60 else title[:58] + "…", fontsize=9, loc="left")
        ax.axvline(0, color="#9ca3af", lw=0.5)
    axes[-1, 0].set_xlabel("paper's value on our interval's scale (interval = [−1, 1])", fontsize=8)
    handles = [plt.Line2D([], [], marker="o", ls="", color=c, label=v)
               for v, c in VERDICT_COLOURS.items() if any(r.verdict == v and r.headline for r in rows)]
    if handles:
        fig.legend(handles=handles, fontsize=7, loc="upper right", ncol=len(handles),
                   frameon=False)
    height = fig.get_figheight()
    fig.subplots_adjust(left=0.5, right=0.98, top=1 - 0.5 / height, bottom=0.55 / height,
                        hspace=0.6)
    path = Path(path)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path
