"""The MDLT chapter's figures: each variant's translation beside the dancer's angles, and the
UR3 arm dancing the best variant's translation.

Used in: MDLT chapter (thesis 6.5).
"""

from __future__ import annotations

from pathlib import Path

import pandas as pd

from thesis_lib.mdlt import animate_arm, plot_angles
from thesis_lib.ur3.dance import map_dance

from .config import VARIANT_LABELS, Config
from .tasks import TableRun


def best_variant(cfg: Config, run: TableRun, ratio: pd.DataFrame) -> str:
    """The variant with the lowest AJE / mean pose in the experiment of ``run.examples``."""
    row = run.examples["experiment"]
    return min(cfg.variants, key=lambda v: ratio.loc[row, VARIANT_LABELS[v]])


def plot_predictions(cfg: Config, run: TableRun):
    """Each variant's translation of the first validation song of ``run.examples`` against the
    dancer's angles, one column per variant."""
    import matplotlib.pyplot as plt

    song, preds = run.examples["songs"][0], run.examples["predictions"]
    fig, axes = plt.subplots(
        4,
        len(cfg.variants),
        figsize=(5 * len(cfg.variants), 7),
        sharex=True,
        sharey="row",
        squeeze=False,
    )
    for k, v in enumerate(cfg.variants):
        plot_angles(preds[v][0], fps=song.fps, true=song.angles, axes=axes[:, k])
        axes[0, k].set_title(f"{VARIANT_LABELS[v]}: {song.name}", fontsize=9)
    fig.tight_layout()
    return fig


def animate_best(cfg: Config, run: TableRun, variant: str, path: str | Path) -> Path:
    """GIF of the UR3 following ``variant``'s translation of the example song (dancer: grey)."""
    song = run.examples["songs"][0]
    animate_arm(  # both arms in the pose `thesis ur3 play` would play (offset and halving)
        map_dance(run.examples["predictions"][variant][0]),
        fps=song.fps,
        true=map_dance(song.angles),
        path=path,
        max_seconds=cfg.animation_seconds,
    )
    return Path(path)
