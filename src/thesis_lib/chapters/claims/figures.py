"""The Claims page's figures: :func:`plot_claims`, each judged claim's effect with its interval,
and :func:`plot_ladder_curves`, the learning curves of ladder runs.

Used in: the Claims page of the book.
"""

from __future__ import annotations

import textwrap
from typing import Any

import numpy as np
import pandas as pd

from thesis_lib.chapters.claims.tables import headline
from thesis_lib.stats.claims import VERDICT_COLOURS

__all__ = ["plot_claims", "plot_ladder_curves"]


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


def plot_ladder_curves(curves: pd.DataFrame, checkpoints: tuple[int, ...] = ()) -> Any:
    """Score against updates, one panel per (data set, size, method), one line per seed
    (``thesis ladder --curve``'s ``curves.csv``), with the ladder's ``checkpoints`` marked:
    whether a score at a checkpoint is a point or a trend.

    Raises:
        ValueError: ``curves`` lacks a column the plot needs.
    """
    import matplotlib.pyplot as plt

    need = {"dataset", "rung", "method", "seed", "updates", "score"}
    missing = sorted(need - set(curves.columns))
    if missing:
        raise ValueError(f"The curves table lacks column(s) {missing}.")
    panels = list(curves.groupby(["dataset", "rung", "method"], sort=False))
    if not panels:
        fig, ax = plt.subplots(figsize=(6.5, 1.5))
        ax.text(0.5, 0.5, "no learning curve stored yet", ha="center", va="center")
        ax.set_axis_off()
        return fig
    fig, axes = plt.subplots(1, len(panels), figsize=(4.2 * len(panels), 3.0), squeeze=False)
    for ax, ((d, rung, m), g) in zip(axes[0], panels):
        for seed, c in g.groupby("seed"):
            c = c.sort_values("updates")
            ax.plot(c["updates"], c["score"], lw=1.2, marker=".", ms=3, label=f"seed {seed}")
        for x in checkpoints:
            ax.axvline(x, color="0.6", lw=0.8, ls="--")
        ax.set_title(f"{m}, {d}, {rung}", fontsize=9)
        ax.set_xlabel("updates")
        ax.tick_params(labelsize=8)
    axes[0, 0].set_ylabel("D4RL-normalised score (10 episodes)")
    axes[0, -1].legend(fontsize=7)
    fig.tight_layout()
    return fig
