"""The Claims page's figure: :func:`plot_claims`, each judged claim's effect with its interval.

Used in: the Claims page of the book.
"""

from __future__ import annotations

import textwrap
from typing import Any

import numpy as np
import pandas as pd

from thesis_lib.chapters.claims.tables import headline
from thesis_lib.stats.claims import VERDICT_COLOURS

__all__ = ["plot_claims"]


def plot_claims(claims: pd.DataFrame) -> Any:
    """Effects with their 95% intervals, one panel per judged claim, coloured by verdict.

    The effects are in different units (score points, goals reached, actions per second), so
    each claim has its own x-axis, labelled with its headline comparison and metric. The
    solid line is "no effect"; the grey band is a ``superior`` claim's margin (an interval
    inside it is "no effect that matters": fails); the dashed line is a ``noninferior``
    claim's margin (the interval must stay right of it to hold).
    """
    import matplotlib.pyplot as plt

    judged = claims.dropna(subset=["effect"]) if "effect" in claims else claims.iloc[:0]
    if judged.empty:
        fig, ax = plt.subplots(figsize=(6.5, 1.5))
        ax.text(0.5, 0.5, "no claim judged yet", ha="center", va="center")
        ax.set_axis_off()
        return fig
    fig, axes = plt.subplots(len(judged), 1, figsize=(6.5, 1.2 * len(judged) + 0.6), squeeze=False)
    for ax, r in zip(axes[:, 0], judged.itertuples()):
        c = VERDICT_COLOURS.get(r.verdict, "k")
        ax.plot([r.ci_low, r.ci_high], [0, 0], color=c, lw=2)
        ax.plot([r.effect], [0], "o", color=c)
        ax.axvline(0, color="k", lw=0.8)
        m = float(getattr(r, "margin", 0.0) or 0.0)
        m = 0.0 if np.isnan(m) else m
        kind = getattr(r, "kind", "superior")
        if m > 0 and kind == "noninferior":
            ax.axvline(-m, color="0.4", lw=0.8, ls="--")
        elif m > 0:
            ax.axvspan(-m, m, color="0.9", zorder=0)
        lo = min(r.ci_low, r.effect, -m)
        hi = max(r.ci_high, r.effect, m if kind == "superior" else 0.0)
        pad = 0.08 * (hi - lo) or 1.0
        ax.set_xlim(lo - pad, hi + pad)
        ax.set_ylim(-1, 1)
        ax.set_yticks([0], [f"{r.claim}\n{r.verdict}"], fontsize=8)
        ax.tick_params(axis="x", labelsize=7)
        title = headline(getattr(r, "comparisons", ""))
        decided = getattr(r, "decided_by", "")
        if isinstance(decided, str) and decided:
            title += f"; the verdict: {decided}"
        ax.set_title(textwrap.fill(title, 100), fontsize=7, loc="left")
    axes[-1, 0].set_xlabel("effect (x - y) with its 95% interval, in each comparison's unit")
    fig.tight_layout()
    return fig
