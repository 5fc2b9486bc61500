"""The Decision Mamba chapter's figures: Figs 5.3, 5.5, 5.6 (the architecture sweeps) and Fig 5.4
(the five methods), as bars of the return over the data set's maximum.

Used in: Decision Mamba chapter (Figs 5.3-5.6).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from typing import Any

import numpy as np
import pandas as pd

from thesis_lib.chapters.decision_mamba.config import DM_METHODS, MAMBA_METHODS
from thesis_lib.chapters.decision_mamba.tables import THESIS_METHOD
from thesis_lib.seq.evaluation import target_returns

__all__ = ["plot_methods", "plot_sweep"]


def _max_returns(data: Mapping[tuple[str, str], Any]) -> dict[tuple[str, str], float]:
    return {k: target_returns(v)["max"] for k, v in data.items()}


def _normalised(summary: pd.DataFrame, data: Mapping[tuple[str, str], Any], col: str) -> pd.Series:
    best = _max_returns(data)
    scale = [best.get((t, r), np.nan) for t, r in zip(summary.task, summary.tier)]
    return summary[col] / np.where(np.asarray(scale) > 0, scale, np.nan)


def _one_mode(summary: pd.DataFrame, eval_mode: str) -> pd.DataFrame:
    return summary[(summary.eval_mode == eval_mode) | ~summary.method.isin(MAMBA_METHODS)]


def _grouped_bars(
    ax: Any,
    s: pd.DataFrame,
    key: str,
    groups: Sequence[str],
    sets: Sequence[tuple[str, str]],
    label: Callable[[str], str],
) -> None:
    """One bar per ``s[key]`` group and data set (``value`` with ``err`` bars), grouped by
    data set: what Figs 5.3-5.6 share."""
    width = 0.8 / max(len(groups), 1)
    for i, grp in enumerate(groups):
        g = s[s[key] == grp].set_index(["task", "tier"]).reindex(sets)
        x = np.arange(len(sets)) + i * width
        ax.bar(x, g["value"], width, yerr=g["err"].fillna(0), label=label(grp), capsize=2)
    ax.set_xticks(
        np.arange(len(sets)) + width * (len(groups) - 1) / 2, [f"{t}\n{r}" for t, r in sets]
    )
    ax.set_ylabel("return / data set max")
    ax.legend(fontsize=8)


def plot_sweep(
    summary: pd.DataFrame,
    method: str,
    data: Mapping[tuple[str, str], Any],
    metric: str = "best",
    ax: Any = None,
    eval_mode: str = "recurrent",
) -> Any:
    """Figs 5.3 (HDM), 5.5 (DM), 5.6 (DM with RTG, at the max target): one bar per architecture.

    Bars are the metric (``best`` or ``final`` mean over seeds) divided by the data set's
    maximum return, as the thesis scales its bars; error bars are the std over seeds. DM/HDM
    rows are those evaluated in ``eval_mode``.

    Used in: Decision Mamba chapter (Figs 5.3, 5.5, 5.6).
    """
    import matplotlib.pyplot as plt

    summary = _one_mode(summary, eval_mode)
    s = summary[(summary.method == method) & summary.target.isin(["none", "max"])].copy()
    s["value"] = _normalised(s, data, f"{metric}_mean")
    s["err"] = _normalised(s, data, f"{metric}_std")
    sets = list(dict.fromkeys(zip(s.task, s.tier)))
    archs = sorted(s.arch.unique(), key=lambda a: tuple(int(x[1:]) for x in a.split()))
    if ax is None:
        _, ax = plt.subplots(figsize=(max(5, 1.6 * len(sets) * len(archs) / 2), 3.5))
    _grouped_bars(ax, s, "arch", archs, sets, str)
    ax.set_title(
        f"{method}: architectures ({'best during training' if metric == 'best' else 'final checkpoint'})"
    )
    return ax


def plot_methods(
    summary: pd.DataFrame,
    data: Mapping[tuple[str, str], Any],
    metric: str = "best",
    ax: Any = None,
    eval_mode: str = "recurrent",
) -> Any:
    """Fig 5.4: the five methods side by side per data set (DT and DM with RTG at the max target).

    Used in: Decision Mamba chapter (Fig 5.4).
    """
    import matplotlib.pyplot as plt

    summary = _one_mode(summary, eval_mode)
    s = summary[summary.target.isin(["none", "max"])].copy()
    s["value"] = _normalised(s, data, f"{metric}_mean")
    s["err"] = _normalised(s, data, f"{metric}_std")
    sets = list(dict.fromkeys(zip(s.task, s.tier)))
    methods = [m for m in DM_METHODS if m in set(s.method)]
    if ax is None:
        _, ax = plt.subplots(figsize=(max(5, 2.2 * len(sets)), 3.5))
    _grouped_bars(ax, s, "method", methods, sets, lambda m: THESIS_METHOD[m].replace("_", " "))
    ax.set_title(
        f"Five methods ({'best during training' if metric == 'best' else 'final checkpoint'})"
    )
    return ax
