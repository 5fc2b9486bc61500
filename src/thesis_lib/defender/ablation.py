"""The strategy ablation of thesis 4.3.2: replay every filtering strategy over logged episodes.

The authors trained SAC, saved its training episodes, and simulated each of the 576 strategies
on them offline: for every episode, where would the filter have fired first? Each strategy gets

    score = mean over episodes (kept length / logged length) x (share of crashed episodes it stopped)

where *kept length* is the number of real steps before the filter fires (the whole episode if it
never fires) and a crashed episode is *stopped* if the filter fires anywhere in it. A strategy
that never fires scores 0 (it stops no crash); one that fires at the first step scores 0 (it
keeps nothing). Strategies are ranked by their score averaged over tasks.

One pass computes all 24 methods' cost curves per episode and group (:func:`~thesis_lib.defender.cost_curves`),
after which all 576 first-fire steps are a single array comparison. Episodes are joblib tasks.

Used in: DEFENDER (thesis 4.3.2).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
import pandas as pd

from thesis_lib import dtw as _dtw
from thesis_lib.defender.compare import Backend, cost_curves
from thesis_lib.defender.demos import (
    Demonstration,
    DemoSet,
    EpisodeRecorder,
    Trajectory,
    trajectory_features,
)
from thesis_lib.defender.methods import METHODS

__all__ = [
    "ABLATION_COLUMNS",
    "EpisodeRecorder",
    "first_fire_steps",
    "plot_strategy_heatmap",
    "rank_strategies",
    "strategy_ablation",
]

ABLATION_COLUMNS: tuple[str, ...] = (
    "safe", "unsafe", "strategy", "score", "kept_fraction", "crashes_stopped", "safe_episodes_cut",
    "n_episodes", "n_crashed",
)  # fmt: skip
"""Columns of :func:`strategy_ablation`."""


def first_fire_steps(
    trajectory: np.ndarray,
    safe: _dtw.PackedReferences,
    unsafe: _dtw.PackedReferences,
    *,
    metric: _dtw.Metric = "l1",
    max_trajectory: int | None = None,
    backend: Backend = "exact",
    paper_compat: bool = False,
) -> np.ndarray:
    """(24, 24) int array: for safe method i and unsafe method j, the first step the filter fires.

    Entry = number of real steps taken before firing (0 = at the first decision); ``T`` (the
    episode's length) when it never fires. Methods are in :data:`~thesis_lib.defender.METHODS` order.
    """
    cs = cost_curves(
        trajectory, safe, metric=metric, max_trajectory=max_trajectory, backend=backend
    )
    cu = cost_curves(
        trajectory, unsafe, metric=metric, max_trajectory=max_trajectory, backend=backend
    )
    c_safe = np.stack([cs[m] for m in METHODS])  # (24, T)
    c_unsafe = np.stack([cu[m] for m in METHODS])  # (24, T)
    if paper_compat:
        fire = c_safe[:, None, :] > c_unsafe[None, :, :]  # (24, 24, T) the authors' code
    else:
        fire = ~(
            c_safe[:, None, :] < c_unsafe[None, :, :]
        )  # Algorithm 2: steps only if Safe < Unsafe
    any_fire = fire.any(axis=2)
    return np.where(any_fire, fire.argmax(axis=2), trajectory.shape[0])


def _fire_chunk(trajs: list[np.ndarray], safe: Any, unsafe: Any, kw: dict) -> list[np.ndarray]:
    return [first_fire_steps(t, safe, unsafe, **kw) for t in trajs]


def strategy_ablation(
    episodes: Sequence[Demonstration],
    demos: DemoSet,
    *,
    trajectory: Trajectory = "state",
    horizon: int | None = None,
    metric: _dtw.Metric = "l1",
    max_trajectory: int | None = None,
    paper_compat: bool = False,
    n_jobs: int = 1,
) -> pd.DataFrame:
    """Score all 576 strategies on logged episodes (thesis 4.3.2).

    Args:
        episodes: the logged training episodes (e.g. :class:`EpisodeRecorder` output).
        demos: the safe and unsafe demonstrations.
        trajectory: ``"state"`` or ``"state_action"``.
        horizon: episode horizon; an episode that terminated before it crashed (None: every
            terminated episode crashed).
        metric, max_trajectory: as :class:`~thesis_lib.defender.DefenderWrapper`.
        paper_compat: FastDTW radius 1, 20-step cap and a strict ">" (the authors' code).
        n_jobs: joblib processes (-1 = all cores).

    Returns:
        576 rows, columns :data:`ABLATION_COLUMNS`: ``kept_fraction`` mean kept/logged length,
        ``crashes_stopped`` share of crashed episodes in which it fired, ``safe_episodes_cut``
        share of the other episodes in which it fired, ``score`` their product (first two).

    Used in: DEFENDER (thesis 4.3.2).
    """
    from joblib import Parallel, delayed

    if not episodes:
        raise ValueError("strategy_ablation needs at least one logged episode.")
    backend: Backend = "fastdtw" if paper_compat else "exact"
    if paper_compat and max_trajectory is None:
        max_trajectory = 20
    safe = _dtw.pack_references([trajectory_features(d, trajectory) for d in demos.safe])
    unsafe = _dtw.pack_references([trajectory_features(d, trajectory) for d in demos.unsafe])
    trajs = [trajectory_features(e, trajectory) for e in episodes]
    lengths = np.array([len(t) for t in trajs])
    crashed = np.array([e.terminated and (horizon is None or e.length < horizon) for e in episodes])
    kw = dict(
        metric="l1" if paper_compat else metric,
        max_trajectory=max_trajectory,
        backend=backend,
        paper_compat=paper_compat,
    )
    n_chunks = max(1, min(len(trajs), 4 * (abs(n_jobs) if n_jobs > 0 else 8)))
    order = np.argsort(-lengths)  # longest first, dealt round-robin: balanced chunks
    chunks = [[int(i) for i in order[k::n_chunks]] for k in range(n_chunks)]
    parts = Parallel(n_jobs=n_jobs)(
        delayed(_fire_chunk)([trajs[i] for i in c], safe, unsafe, kw) for c in chunks
    )
    fires = np.empty((len(trajs), len(METHODS), len(METHODS)), dtype=np.int64)
    for c, part in zip(chunks, parts):
        for i, f in zip(c, part):
            fires[i] = f
    fired = fires < lengths[:, None, None]  # (E, 24, 24)
    kept = (fires / lengths[:, None, None]).mean(axis=0)
    n_crashed = int(crashed.sum())
    stopped = fired[crashed].mean(axis=0) if n_crashed else np.full(kept.shape, np.nan)
    cut = fired[~crashed].mean(axis=0) if (~crashed).any() else np.full(kept.shape, np.nan)
    rows = []
    for i, s in enumerate(METHODS):
        for j, u in enumerate(METHODS):
            rows.append(
                {
                    "safe": s,
                    "unsafe": u,
                    "strategy": f"{s}/{u}",
                    "score": kept[i, j] * stopped[i, j],
                    "kept_fraction": kept[i, j],
                    "crashes_stopped": stopped[i, j],
                    "safe_episodes_cut": cut[i, j],
                    "n_episodes": len(trajs),
                    "n_crashed": n_crashed,
                }
            )
    return pd.DataFrame(rows, columns=list(ABLATION_COLUMNS))


def rank_strategies(
    scores: pd.DataFrame, top: int = 5, by: Sequence[str] = ("trajectory",)
) -> pd.DataFrame:
    """Average the score over tasks (and any other rows) and keep the ``top`` per group.

    Args:
        scores: :func:`strategy_ablation` rows with extra key columns (e.g. ``task``, ``trajectory``).
        top: strategies to keep per group.
        by: columns to rank within (default: per trajectory kind, as the thesis did).

    Returns:
        Columns ``[*by, "rank", "safe", "unsafe", "strategy", "score", "kept_fraction",
        "crashes_stopped"]``; ties broken by the strategy name.

    Used in: DEFENDER (thesis 4.3.2).
    """
    by = [b for b in by if b in scores.columns]
    cols = ["score", "kept_fraction", "crashes_stopped"]
    mean = scores.groupby([*by, "safe", "unsafe", "strategy"], as_index=False)[cols].mean()
    mean = mean.sort_values([*by, "score", "strategy"], ascending=[True] * len(by) + [False, True])
    ranked = mean.groupby(by).head(top) if by else mean.head(top)
    ranked = ranked.copy()
    ranked.insert(
        len(by), "rank", ranked.groupby(by).cumcount() + 1 if by else np.arange(1, len(ranked) + 1)
    )
    return ranked.reset_index(drop=True)


def plot_strategy_heatmap(scores: pd.DataFrame, title: str = "", ax: Any = None) -> Any:
    """The 24 x 24 heat map of scores (rows: safe method, columns: unsafe method).

    Used in: DEFENDER (thesis 4.3.2).
    """
    import matplotlib.pyplot as plt

    grid = scores.pivot_table(index="safe", columns="unsafe", values="score", aggfunc="mean")
    grid = grid.reindex(index=list(METHODS), columns=list(METHODS))
    if ax is None:
        fig, ax = plt.subplots(figsize=(8.5, 7.5))
    else:
        fig = ax.figure
    im = ax.imshow(grid.to_numpy(dtype=float), cmap="viridis", vmin=0, aspect="auto")
    ax.set_xticks(range(len(METHODS)), METHODS, rotation=90, fontsize=7)
    ax.set_yticks(range(len(METHODS)), METHODS, fontsize=7)
    ax.set_xlabel("unsafe-group method")
    ax.set_ylabel("safe-group method")
    ax.set_title(title or "strategy score (kept length x crashes stopped)")
    fig.colorbar(im, ax=ax, fraction=0.04)
    fig.tight_layout()
    return fig
