"""The DEFENDER chapter's figures: learning and crash-rate curves, the ablation's heatmap.

Used in: DEFENDER chapter (thesis 4.3).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import pandas as pd

from thesis_lib.chapters.defender.demos import thesis_env_name
from thesis_lib.chapters.defender.tables import summarize_study_curves
from thesis_lib.defender.ablation import plot_strategy_heatmap


def crash_curves(
    episodes: pd.DataFrame, keys: Sequence[str] = ("task", "algo", "trajectory", "strategy", "seed")
) -> pd.DataFrame:
    """Cumulative crash rate (%) and filter rate (%) after each training episode, per run."""
    e = episodes.copy()
    g = e.groupby(list(keys), sort=False)
    e["episode_in_run"] = g.cumcount() + 1
    e["crash_rate_pct"] = 100 * g["crashed"].cumsum() / e["episode_in_run"]
    e["filter_rate_pct"] = 100 * g["filtered"].cumsum() / e["episode_in_run"]
    return e


def plot_curves(episodes: pd.DataFrame, window: int = 10) -> Any:
    """Learning curves (return vs step, rolling mean) and cumulative crash rate, with and without the filter.

    Two rows per task (return; crashed episodes so far), one column per algorithm; one line per
    strategy and seed (black: no filter).

    Used in: DEFENDER chapter (thesis 4.3.3).
    """
    import matplotlib.pyplot as plt

    e = crash_curves(episodes)
    e = e[~e.paper_compat.astype(bool)] if "paper_compat" in e else e
    tasks, algos = list(dict.fromkeys(e.task)), list(dict.fromkeys(e.algo))
    fig, axes = plt.subplots(
        2 * len(tasks), len(algos), figsize=(5.5 * len(algos), 3.2 * 2 * len(tasks)), squeeze=False
    )
    for i, task in enumerate(tasks):
        for col, algo in enumerate(algos):
            ax_r, ax_c = axes[2 * i, col], axes[2 * i + 1, col]
            sub = e[(e.task == task) & (e.algo == algo)]
            for (traj, strat), run in sub.groupby(["trajectory", "strategy"], sort=False):
                label = "no filter" if strat == "none" else f"{strat} ({traj})"
                style = {"color": "black", "lw": 2} if strat == "none" else {}
                for seed, one in run.groupby("seed"):
                    lab = label if seed == run.seed.min() else None
                    ax_r.plot(
                        one.timestep,
                        one["return"].rolling(window, min_periods=1).mean(),
                        label=lab,
                        **style,
                    )
                    ax_c.plot(one.timestep, one.crash_rate_pct, label=lab, **style)
            ax_r.set_title(f"{thesis_env_name(task)}, {algo}")
            ax_r.set_ylabel(f"return (rolling {window})")
            ax_c.set_ylabel("crashed episodes so far (%)")
            ax_c.set_xlabel("environment step")
            ax_r.legend(fontsize=7)
    fig.tight_layout()
    return fig


def plot_curves_table_4_5(episodes: pd.DataFrame):
    """Learning and crash-rate curves of the Table 4.5 runs, one line per number of demonstrations."""
    return plot_curves(episodes.assign(strategy=episodes.n_demos.map(lambda n: f"{n} demos")))


def plot_ablation_heatmap(scores: pd.DataFrame):
    """The ablation's scores of the 576 strategies, one heatmap per trajectory kind."""
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(17, 7.5))
    for ax, kind in zip(axes, ("state", "state_action")):
        plot_strategy_heatmap(
            scores[scores.trajectory == kind], title=f"{kind} trajectories", ax=ax
        )
    return fig


def plot_study_curves(
    rows: pd.DataFrame, methods: Sequence[str] | None = None, reps: int = 1000
) -> Any:
    """Crash rate, filtered rate and return over training, one column per setting: each
    method's mean over seeds per span of training with its 95% interval (shaded).

    Used in: DEFENDER chapter ("Evidence at study scale").
    """
    import matplotlib.pyplot as plt

    curves = summarize_study_curves(rows, reps=reps)
    if methods is not None and not curves.empty:
        curves = curves[curves["method"].isin(methods)]
    if curves.empty:  # before the study, or while it has no run of these methods yet
        fig, ax = plt.subplots(figsize=(5, 1.5))
        ax.text(0.5, 0.5, "no study rows of these methods yet", ha="center", va="center")
        ax.set_axis_off()
        return fig
    settings = list(dict.fromkeys(curves["setting"]))
    measures = (
        ("crash_rate", "crash rate"),
        ("filtered_rate", "filtered rate"),
        ("return", "return"),
    )
    fig, axes = plt.subplots(
        len(measures), len(settings), figsize=(4.8 * len(settings), 8.5), squeeze=False
    )
    for j, setting in enumerate(settings):
        for i, (measure, name) in enumerate(measures):
            ax = axes[i, j]
            sub = curves[(curves["setting"] == setting) & (curves["measure"] == measure)]
            for k, (method, g) in enumerate(sub.groupby("method", sort=False)):
                colour = "black" if "+" not in method else f"C{k % 10}"
                ax.plot(g["step"], g["mean"], color=colour, label=method, lw=1.5)
                ax.fill_between(g["step"], g["ci_low"], g["ci_high"], color=colour, alpha=0.15)
            ax.set_ylabel(f"{name} (per span)")
            if i == 0:
                ax.set_title(setting)
            if i == len(measures) - 1:
                ax.set_xlabel("environment steps")
    axes[0, 0].legend(fontsize=6)
    fig.tight_layout()
    return fig
