"""The HDT chapter's figures: what the sub-goal rule picks (thesis 5.2.2) and the training curves.

* :func:`plot_subgoal_index`, :func:`plot_subgoal_weights`: the rule on a locomotion episode;
* :func:`plot_maze_subgoals`: on a Maze2D episode (sparse rewards);
* :func:`plot_training_curves`: evaluation return vs iteration per method and data set.

Used in: HDT chapter (Figures of 5.2.2, the training curves).
"""

from __future__ import annotations

from typing import Any

import numpy as np
import pandas as pd

from thesis_lib.seq.subgoals import select_subgoal_indices

__all__ = [
    "plot_maze_subgoals",
    "plot_subgoal_index",
    "plot_subgoal_weights",
    "plot_training_curves",
]


def plot_maze_subgoals(episode: Any, ax: Any = None, paper_compat: bool = False) -> Any:
    """A Maze2D episode's (x, y) path with the sub-goals the rule selects on it.

    Points are coloured by reward; each selected sub-goal is a star, with an arrow from the
    state where it was selected.
    """
    import matplotlib.pyplot as plt

    if ax is None:
        _, ax = plt.subplots(figsize=(5, 5))
    obs = np.asarray(episode.observations)
    r = np.asarray(episode.rewards, dtype=float)
    idx = select_subgoal_indices(
        r, n_states=None if paper_compat else obs.shape[0], paper_compat=paper_compat
    )
    xy = obs[:, :2]
    ax.plot(xy[:, 0], xy[:, 1], color="0.7", lw=1, zorder=1)
    sc = ax.scatter(
        xy[:-1, 0], xy[:-1, 1], c=r, cmap="coolwarm", s=10, zorder=2, vmin=0, vmax=max(1.0, r.max())
    )
    starts = np.flatnonzero(np.r_[True, idx[1:] != idx[:-1]])
    for s in starts:
        g = idx[s]
        ax.annotate(
            "", xy=xy[g], xytext=xy[s], arrowprops=dict(arrowstyle="->", color="green", alpha=0.5)
        )
    ax.scatter(
        xy[np.unique(idx), 0],
        xy[np.unique(idx), 1],
        marker="*",
        s=120,
        c="green",
        zorder=3,
        label=f"sub-goals ({len(np.unique(idx))} distinct)",
    )
    ax.scatter(*xy[0], marker="o", s=60, c="k", zorder=4, label="start")
    ax.set_xlabel("x")
    ax.set_ylabel("y")
    ax.set_aspect("equal")
    ax.legend(loc="best", fontsize=8)
    plt.colorbar(sc, ax=ax, label="reward", fraction=0.046)
    return ax


def plot_subgoal_weights(episode: Any, ax: Any = None) -> Any:
    """``W_0(j)``, the average reward from ``s_0`` to ``s_j``: the weights of the first selection.

    Used in: HDT chapter (sub-goal selection).
    """
    import matplotlib.pyplot as plt

    if ax is None:
        _, ax = plt.subplots(figsize=(6, 4))
    r = np.asarray(episode.rewards, dtype=float)
    w0 = np.cumsum(r) / np.arange(1, len(r) + 1)  # W_0(j) for j = 1 .. T
    ax.plot(np.arange(1, len(r) + 1), w0)
    j = int(np.argmax(w0)) + 1
    ax.axvline(j, ls="--", color="green", label=f"argmax j = {j}")
    ax.set_xlabel("candidate j")
    ax.set_ylabel("W_0(j): average reward from s_0 to s_j")
    ax.set_title("why: the weights of the first selection")
    ax.legend(fontsize=8)
    return ax


def plot_subgoal_index(episode: Any, ax: Any = None, label: str | None = None) -> Any:
    """Sub-goal index vs time step for one episode (a staircase), with the rewards below."""
    import matplotlib.pyplot as plt

    if ax is None:
        _, ax = plt.subplots(figsize=(7, 4))
    r = np.asarray(episode.rewards, dtype=float)
    idx = select_subgoal_indices(r, n_states=np.asarray(episode.observations).shape[0])
    t = np.arange(len(r))
    ax.step(t, idx, where="post", label=label or "sub-goal index")
    ax.plot(t, t, ls=":", color="0.5", label="current step")
    ax.set_xlabel("time step t")
    ax.set_ylabel("sub-goal index j")
    ax2 = ax.twinx()
    ax2.plot(t, r, color="tab:red", alpha=0.35, lw=0.8)
    ax2.set_ylabel("reward r_t", color="tab:red")
    ax.legend(loc="upper left", fontsize=8)
    return ax


def plot_training_curves(curves: pd.DataFrame, ncols: int = 4) -> Any:
    """Evaluation return vs iteration per method (mean over seeds), one panel per data set.

    RTG methods are drawn at their ``max`` target; panels fill ``ncols`` columns.
    """
    import matplotlib.pyplot as plt

    c = curves[curves["target"].isin(["none", "max"])]
    sets = list(dict.fromkeys(zip(c["task"], c["tier"])))
    ncols = max(1, min(ncols, len(sets)))
    nrows = -(-len(sets) // ncols)
    fig, axes = plt.subplots(nrows, ncols, figsize=(4.5 * ncols, 3.4 * nrows), squeeze=False)
    for ax in axes.flat[len(sets) :]:
        ax.set_visible(False)
    for ax, (task, tier) in zip(axes.flat, sets):
        g = c[(c.task == task) & (c.tier == tier)]
        for method, gm in g.groupby("method", sort=False):
            m = gm.groupby("iteration")["return_mean"].agg(["mean", "std"]).reset_index()
            ax.plot(m["iteration"], m["mean"], marker="o", label=method)
            if gm["seed"].nunique() > 1:
                ax.fill_between(
                    m["iteration"], m["mean"] - m["std"], m["mean"] + m["std"], alpha=0.15
                )
        ax.set_title(f"{task}/{tier}", fontsize=10)
        ax.set_xlabel("iteration")
        ax.set_ylabel("evaluation return")
    handles, labels = axes.flat[0].get_legend_handles_labels()
    fig.legend(
        handles,
        labels,
        loc="lower center",
        ncol=len(labels),
        fontsize=9,
        bbox_to_anchor=(0.5, -0.02),
    )
    fig.tight_layout(rect=(0, 0.03, 1, 1))
    return fig
