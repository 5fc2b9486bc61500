"""The CLfD chapter's figures: the ``plot_*`` functions, each returning a matplotlib figure.

Used in: chapter 02_clfd.
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from thesis_lib.clfd.env import CAMERAS, STAGES, MultiViewPickPlace, run_demonstration
from thesis_lib.clfd.metrics import pca_2d
from thesis_lib.clfd.train import CLfD


def plot_example_frames(seed: int = 0, image_size: int = 120, n_times: int = 3):
    """Fig 4.3: one demonstration from the five cameras at ``n_times`` instants."""
    import matplotlib.pyplot as plt

    env = MultiViewPickPlace(image_size=image_size)
    demo = run_demonstration(env, seed, render=True)
    env.close()
    if demo.frames is None:
        raise RuntimeError("the demonstration was run without rendering")
    times = np.linspace(0, len(demo.stages) - 1, n_times).round().astype(int)
    fig, axes = plt.subplots(
        n_times, len(CAMERAS), figsize=(2.2 * len(CAMERAS), 2.3 * n_times), squeeze=False
    )
    for r, t in enumerate(times):
        for c, cam in enumerate(CAMERAS):
            ax = axes[r, c]
            ax.imshow(demo.frames[t, c])
            ax.set_xticks([]), ax.set_yticks([])
            if r == 0:
                ax.set_title(cam)
            if c == 0:
                ax.set_ylabel(f"t = {t} ({STAGES[demo.stages[t]]})")
    fig.tight_layout()
    return fig


def plot_training_curves(histories: pd.DataFrame):
    """Training loss and validation alignment error per epoch, one line per encoder × method."""
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(11, 3.6))
    keys = ["dataset", "encoder", "method"] if "dataset" in histories else ["encoder", "method"]
    for key, g in histories.groupby(keys, sort=False):
        m, enc = key[-1], key[-2]
        label = f"{m} / {enc}" + (f" ({key[0]})" if len(key) == 3 and key[0] != "PickPlace" else "")
        axes[0].plot(g["epoch"], g["loss"], label=label)
        v = g.dropna(subset=["val_alignment_error"])
        axes[1].plot(v["epoch"], v["val_alignment_error"], marker="o", label=label)
    axes[0].set(xlabel="epoch", ylabel="training loss (each method its own)", title="loss")
    axes[1].set(
        xlabel="epoch",
        ylabel="alignment error [%]",
        title="validation alignment error (seen pairs)",
    )
    axes[1].axhline(100 / 3, ls=":", color="grey", label="chance (~33%)")
    axes[1].legend(fontsize=7)
    fig.tight_layout()
    return fig


def plot_rl_curves(episodes: pd.DataFrame):
    """Fig 4.4: accumulated Eq 4.2 reward per episode per encoder (dashed: the demonstration's own
    return under that encoder), and the final gripper-box distance."""
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(11, 3.6))
    for i, (enc, g) in enumerate(episodes.groupby("encoder", sort=False)):
        (line,) = axes[0].plot(g["episode"], g["return"], marker=".", label=enc)
        if "expert_return" in g:
            axes[0].axhline(
                g["expert_return"].iloc[0],
                ls="--",
                lw=1,
                color=line.get_color(),
                label=f"{enc}: the demonstration" if i == 0 else None,
            )
        axes[1].plot(g["episode"], g["final_grip_box_distance"], marker=".", label=enc)
    axes[0].set(xlabel="episode", ylabel="accumulated reward (Eq 4.2)", title="Fig 4.4: pick stage")
    axes[1].set(
        xlabel="episode", ylabel="gripper-box distance at the end [m]", title="task progress"
    )
    axes[0].legend()
    fig.tight_layout()
    return fig


def plot_embedding_pca(
    model: CLfD, video: np.ndarray, cameras: tuple[str, ...], cam_names: list[str]
):
    """PCA of one video's features from two cameras, coloured by time (same-time points should meet)."""
    import matplotlib.pyplot as plt

    idx = [cameras.index(c) for c in cam_names]
    feats = [model.embed(video[:, i]) for i in idx]
    pts = pca_2d(feats)
    t = np.arange(len(video))
    fig, ax = plt.subplots(figsize=(5.2, 4.2))
    for p, name, marker in zip(pts, cam_names, ["o", "^", "s"]):
        sc = ax.scatter(
            p[:, 0],
            p[:, 1],
            c=t,
            cmap="viridis",
            marker=marker,
            label=name,
            edgecolors="k",
            linewidths=0.3,
        )
        ax.plot(p[:, 0], p[:, 1], lw=0.5, color="grey")
    fig.colorbar(sc, ax=ax, label="time step")
    ax.set(xlabel="PC 1", ylabel="PC 2")
    ax.legend()
    fig.tight_layout()
    return fig


def plot_study_rl_curves(curves: pd.DataFrame):
    """Fig 4.4 at study scale: success rate against training episodes per encoder, the mean
    over seeds with its 95% interval shaded (:func:`~thesis_lib.chapters.clfd.tables.summarize_study_rl_curves`).

    Used in: CLfD chapter ("Evidence at study scale").
    """
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6.5, 3.6))
    if curves.empty:
        ax.text(0.5, 0.5, "no study rows yet", ha="center", va="center")
        ax.set_axis_off()
        return fig
    for m, g in curves.groupby("method", sort=False):
        (line,) = ax.plot(g["episode"], g["success"], marker="o", label=f"{m} (n={g.seeds.max()})")
        ax.fill_between(g["episode"], g["ci_low"], g["ci_high"], color=line.get_color(), alpha=0.2)
    ax.set(
        xlabel="training episode (end of window)",
        ylabel="share of episodes ending at the box",
        title="pick stage, DDPG+HER (study)",
        ylim=(-0.03, 1.03),
    )
    ax.legend(fontsize=8)
    fig.tight_layout()
    return fig
