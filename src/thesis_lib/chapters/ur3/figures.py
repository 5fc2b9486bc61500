"""The UR3 deployment chapter's figures: Table 5.4 beside the thesis's, the success curves, the
goals with a demonstration's tool path, a demonstration's sub-goals, and the dance.

Used in: UR3 deployment chapter.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import pandas as pd

from thesis_lib.book import load_reference
from thesis_lib.seq.subgoals import select_subgoal_indices
from thesis_lib.ur3.dance import map_dance
from thesis_lib.ur3.model import UR3Kinematics
from thesis_lib.ur3.reach import GOALS
from thesis_lib.ur3.render import plot_arm

__all__ = [
    "plot_dance",
    "plot_demo_subgoals",
    "plot_goals",
    "plot_success_curves",
    "plot_table_5_4",
]


def plot_table_5_4(ours: pd.DataFrame, ax=None):
    """Goals reached vs. training demonstrations: ours (solid, ± std) and the thesis's (dashed)."""
    import matplotlib.pyplot as plt

    if ax is None:
        fig, ax = plt.subplots(figsize=(6.5, 4))
    else:
        fig = ax.figure
    paper = load_reference("5.4")
    colors = {"HDT": "tab:green", "DT": "tab:blue"}
    for m, g in paper.groupby("method", sort=False):
        ax.plot(
            g.train_demos,
            g.goals_mean,
            "--",
            color=colors.get(m),
            alpha=0.6,
            label=f"{m} (thesis, real UR3)",
        )
    for m, g in ours.groupby("method", sort=False):
        g = g.sort_values("train_demos")
        ax.errorbar(
            g.train_demos,
            g.goals_mean,
            yerr=g.goals_std,
            fmt="-o",
            capsize=3,
            color=colors.get(m),
            label=f"{m} (ours, simulation)",
        )
    ax.set_xlabel("training demonstrations")
    ax.set_ylabel("goal positions reached (of 5)")
    ax.set_ylim(-0.2, 5.5)
    ax.legend(fontsize=8)
    ax.set_title("Table 5.4: UR3 reaching within 200 steps")
    return fig


def plot_success_curves(curves: pd.DataFrame, ax=None):
    """Mean goals reached by each step of the test episodes, per method and demonstration count."""
    import matplotlib.pyplot as plt

    if ax is None:
        fig, ax = plt.subplots(figsize=(6.5, 4))
    else:
        fig = ax.figure
    styles = {"HDT": "-", "DT": "--"}
    counts = sorted(curves.train_demos.unique())
    cmap = plt.get_cmap("viridis")
    for (m, n), g in curves.groupby(["method", "train_demos"], sort=False):
        c = cmap(counts.index(n) / max(1, len(counts) - 1))
        ax.plot(g.step, g.goals_mean, styles.get(m, "-"), color=c, label=f"{m}, {n} demos")
    ax.set_xlabel("step of the test episode")
    ax.set_ylabel("goals reached so far (mean)")
    ax.set_ylim(-0.2, 5.2)
    ax.legend(fontsize=7, ncol=2)
    ax.set_title("Reaching success over the 200 test steps")
    return fig


def plot_goals(demo, ax=None):
    """The goals and one demonstration's tool path in 3-D (forward kinematics)."""
    import matplotlib.pyplot as plt

    if ax is None:
        fig = plt.figure(figsize=(6, 5))
        ax = fig.add_subplot(projection="3d")
    else:
        fig = ax.figure
    kin = UR3Kinematics()
    for k, g in enumerate(GOALS):
        plot_arm(ax, g, color="0.6", alpha=0.5, kin=kin)
        p = kin.tcp(g)
        ax.text(*p, f" G{k + 1}", fontsize=8)
    path = np.array([kin.tcp(o[:6]) for o in demo.observations])
    ax.plot(
        path[:, 0],
        path[:, 1],
        path[:, 2],
        color="tab:red",
        lw=1.5,
        label="tool path of a demonstration",
    )
    plot_arm(ax, demo.observations[0][:6], color="tab:blue", label="start", kin=kin)
    ax.set_xlim(-0.5, 0.5), ax.set_ylim(-0.5, 0.5), ax.set_zlim(0, 0.7)
    ax.set_xlabel("x (m)"), ax.set_ylabel("y (m)"), ax.set_zlabel("z (m)")
    ax.legend(fontsize=8)
    return fig


def plot_dance(angles: np.ndarray, playback, fps: float):
    """MDLT's four angles and the UR3 joints actually played (after the limit checks), over time."""
    import matplotlib.pyplot as plt

    mapped = map_dance(angles)
    t = np.arange(len(angles)) / fps
    fig, axes = plt.subplots(2, 2, figsize=(11, 5), sharex=True)
    names = ("shoulder pan (j1)", "shoulder lift (j2)", "elbow (j3)", "wrist 1 (j4)")
    for j, ax in enumerate(axes.flat):
        ax.plot(t, mapped[:, j], color="0.6", label="mapped MDLT angle")
        ax.plot(t, playback.q[:, j], color="tab:red", lw=1, label=f"played ({playback.mode})")
        ax.set_title(names[j], fontsize=9)
        ax.set_ylabel("rad")
    for ax in axes[1]:
        ax.set_xlabel("s")
    axes[0, 0].legend(fontsize=8)
    fig.tight_layout()
    return fig


def plot_demo_subgoals(episode: Any, ax: Any = None) -> tuple[Any, list[int], list[int]]:
    """One demonstration's rewards with its sub-goal states (green) and goals reached (red).

    Returns:
        ``(figure, sub-goal states, steps where a goal was reached)``.

    Used in: UR3 deployment chapter (sub-goals on the reaching task).
    """
    import matplotlib.pyplot as plt

    if ax is None:
        fig, ax = plt.subplots(figsize=(8, 3))
    else:
        fig = ax.figure
    idx = select_subgoal_indices(episode.rewards)
    reached_at = np.flatnonzero(np.diff(episode.observations[:, 6:].sum(axis=1))) + 1
    ax.plot(episode.rewards, label="reward")
    for j in np.unique(idx):
        ax.axvline(j, color="tab:green", ls="--", lw=1)
    for j in reached_at:
        ax.plot(j, 0, "rv")
    ax.set_xlabel("step"), ax.set_ylabel("reward")
    ax.set_title("one demonstration: sub-goal states (green) and goals reached (red)")
    return fig, np.unique(idx).tolist(), reached_at.tolist()
