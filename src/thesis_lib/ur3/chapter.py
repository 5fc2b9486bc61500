"""The UR3 deployment chapter's configuration, dance source and figures (notebook 07_ur3_deployment).

Used in: UR3 deployment chapter (Table 5.4, dance playback, 3-D viewer).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np
import pandas as pd

from .experiments import REACH_METHODS, ReachConfig

__all__ = [
    "UR3ChapterConfig",
    "dance_angles",
    "plot_dance",
    "plot_goals",
    "plot_success_curves",
    "plot_table_5_4",
    "table_5_4_vs_thesis",
]


@dataclass
class UR3ChapterConfig:
    """The notebook's parameters (``params/07_ur3_deployment.*.yml``).

    Used in: UR3 deployment chapter.
    """

    seed: int = 0
    """Seed of the demonstrations and of the stand-in dance."""
    seeds: tuple[int, ...] = (0,)
    """Training seeds of Table 5.4."""
    train_demos: tuple[int, ...] = (10, 80)
    """Numbers of training demonstrations (the thesis: 10, 20, ..., 80)."""
    methods: tuple[str, ...] = REACH_METHODS
    """HDT and/or DT."""
    iterations: int = 1000
    """Training iterations per run."""
    batch_size: int = 32
    """Windows per batch."""
    K: int = 20
    """Context length."""
    d_model: int = 32
    """Embedding size."""
    n_layer: int = 1
    """GPT blocks (per HDT level)."""
    n_head: int = 1
    """Attention heads."""
    dropout: float = 0.0
    """Dropout (0.1 in the thesis; off at the smoke scale, where it slows the few hundred steps badly)."""
    lr: float = 0.001
    """Peak learning rate."""
    warmup_steps: int = 50
    """Warm-up steps."""
    max_eval_steps: int = 200
    """Steps per test episode (200 in the thesis)."""
    paper_compat: bool = False
    """The authors' behaviours in the sequence models (see the HDT chapter)."""
    dance_source: Literal["mdlt", "demo"] = "mdlt"
    """``"mdlt"``: the first sequence of MDLT's default AIST++-layout data set; ``"demo"``: a stand-in dance."""
    dance_seconds: float = 6.0
    """Seconds of dance to play."""
    dance_fps: int = 60
    """Frame rate of the dance angles (MDLT: 60)."""
    dance_mode: Literal["clip", "reject"] = "clip"
    """Limits: clip (clamp and rate-limit) or reject."""
    viewer_frames: int = 180
    """Frames stored in the 3-D viewer (subsampled)."""
    device: str = "cpu"
    """Training device."""
    progress: bool = False
    """Progress bars."""

    def __post_init__(self) -> None:
        if self.dance_source not in ("mdlt", "demo"):
            raise ValueError(f"Unknown dance_source {self.dance_source!r}. Valid: mdlt, demo.")
        if self.dance_mode not in ("clip", "reject"):
            raise ValueError(f"Unknown dance_mode {self.dance_mode!r}. Valid: clip, reject.")
        self.reach_config()  # validates methods and counts

    def reach_config(self) -> ReachConfig:
        """The :class:`~thesis_lib.ur3.experiments.ReachConfig` of Table 5.4."""
        return ReachConfig(
            train_demos=tuple(self.train_demos),
            methods=tuple(self.methods),
            seeds=tuple(self.seeds),
            data_seed=self.seed,
            iterations=self.iterations,
            batch_size=self.batch_size,
            K=self.K,
            d_model=self.d_model,
            n_layer=self.n_layer,
            n_head=self.n_head,
            dropout=self.dropout,
            lr=self.lr,
            warmup_steps=self.warmup_steps,
            max_eval_steps=self.max_eval_steps,
            paper_compat=self.paper_compat,
            device=self.device,
            progress=self.progress,
        )


def dance_angles(
    source: str = "mdlt", seconds: float = 6.0, fps: int = 60, seed: int = 0
) -> tuple[np.ndarray, str]:
    """``(T, 4)`` dance angles and where they came from.

    ``"mdlt"``: the choreography of the first sequence of MDLT's default data set in the AIST++
    layout (:func:`thesis_lib.mdlt.synth.default_dataset`, read by
    :func:`thesis_lib.mdlt.readers.load_aist`), the same angles MDLT learns to generate;
    ``"demo"``: :func:`thesis_lib.ur3.dance.demo_angles`.

    Used in: UR3 deployment chapter.
    """
    from .dance import demo_angles

    if source == "demo":
        return demo_angles(
            seconds, fps, seed=seed
        ), f"stand-in dance (thesis_lib.ur3.dance.demo_angles, seed {seed})"
    if source != "mdlt":
        raise ValueError(f"Unknown dance source {source!r}. Valid: mdlt, demo.")
    from thesis_lib.mdlt import readers, synth

    root = synth.default_dataset("aist", "smoke", seed=seed, progress=False)
    genre = readers.AIST_GENRES[0] if hasattr(readers, "AIST_GENRES") else None
    seqs = readers.load_aist(root, genres=[genre] if genre else None, progress=False)
    s = seqs[0]
    if int(s.fps) != int(fps):
        raise ValueError(f"MDLT sequence {s.name} is at {s.fps} fps, the chapter asked for {fps}.")
    n = min(len(s.angles), int(round(seconds * fps)))
    return np.asarray(
        s.angles[:n], dtype=np.float64
    ), f"MDLT default data set (AIST++ layout), sequence {s.name}"


def table_5_4_vs_thesis(ours: pd.DataFrame, differs: dict[str, str]) -> pd.DataFrame:
    """Our Table 5.4 beside the thesis's, mean and std of goals reached, with what differs."""
    from thesis_lib.book import compare_with_paper

    mean = compare_with_paper(
        "5.4", ours, on=["method", "train_demos"], value="goals_mean", differs=differs
    )
    std = compare_with_paper("5.4", ours, on=["method", "train_demos"], value="goals_std")
    out = mean.rename(columns={"paper": "paper_mean", "ours": "ours_mean"})
    out.insert(out.columns.get_loc("difference"), "paper_std", std["paper"].to_numpy())
    out.insert(out.columns.get_loc("difference"), "ours_std", std["ours"].to_numpy())
    return out


def plot_table_5_4(ours: pd.DataFrame, ax=None):
    """Goals reached vs. training demonstrations: ours (solid, ± std) and the thesis's (dashed)."""
    import matplotlib.pyplot as plt

    from thesis_lib.book import load_reference

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

    from .model import UR3Kinematics
    from .reach import GOALS
    from .render import plot_arm

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

    from .dance import map_dance

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
