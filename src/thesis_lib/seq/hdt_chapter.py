"""Helpers of the HDT chapter notebook (``notebooks/04_hdt.ipynb``, thesis 5.2).

* :data:`HDTChapterConfig`: the notebook's parameters, an alias of
  :class:`thesis_lib.seq.experiments.HDTExperimentConfig` (one config for the chapter and
  its experiments); :func:`run_chapter_experiments` = ``run_hdt_experiments``.
* :func:`thesis_table_5_1`, :func:`thesis_table_5_2`, :func:`thesis_table_5_3`: our
  :func:`~thesis_lib.seq.experiments.summarize` output labelled as the thesis labels its tables
  and put beside its numbers with :func:`thesis_lib.book.compare_with_paper`, for both metrics.
* :func:`win_counts`: the "Count" row of Table 5.3 (a tie counts for every tied method).
* Figures: :func:`plot_maze_subgoals`, :func:`plot_subgoal_index`, :func:`plot_training_curves`.

Used in: HDT chapter (Tables 5.1-5.3, Figures of 5.2.2).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np
import pandas as pd

from thesis_lib.seq.experiments import HDTExperimentConfig, run_hdt_experiments
from thesis_lib.seq.subgoals import select_subgoal_indices

__all__ = [
    "HDTChapterConfig",
    "METRICS",
    "METRIC_STD",
    "plot_maze_subgoals",
    "plot_subgoal_index",
    "plot_training_curves",
    "run_chapter_experiments",
    "thesis_labels",
    "thesis_table_5_1",
    "thesis_table_5_2",
    "thesis_table_5_3",
    "win_counts",
]

#: Our summary columns for the two metrics: the thesis's and the honest one.
METRICS: dict[str, str] = {
    "best during training (thesis)": "best_return",
    "final checkpoint": "final_return_mean",
}
#: The std over seeds of each metric's column.
METRIC_STD: dict[str, str] = {
    "best_return": "best_return_std",
    "final_return_mean": "final_return_std",
}

# Task spellings of each thesis table (reference/README.md keeps them as printed).
_TASK_NAMES = {
    "hopper": "Hopper",
    "halfcheetah": "Half-Cheetah",
    "ant": "Ant",
    "walker2d": {"5.1": "Walker-2D", "5.2": "Walker 2D", "5.3": "Walker 2D"},
}
_TIER_NAMES = {"medium-replay": "replay"}


HDTChapterConfig = HDTExperimentConfig
"""The chapter's parameters: the one config of :mod:`thesis_lib.seq.experiments` (former name)."""


def run_chapter_experiments(cfg: HDTExperimentConfig) -> pd.DataFrame:
    """Every data set x seed x method of ``cfg``: :func:`~thesis_lib.seq.experiments.run_hdt_experiments`."""
    return run_hdt_experiments(cfg)


def thesis_labels(task: str, tier: str, table: str) -> tuple[str, str]:
    """``(task, dataset)`` as thesis Table ``table`` prints them, e.g. ``('Maze 2D', 'umaze')``."""
    if task.startswith("maze2d-"):
        return "Maze 2D", task.split("-", 1)[1]
    name = _TASK_NAMES.get(task, task)
    if isinstance(name, dict):
        name = name[table]
    return name, _TIER_NAMES.get(tier, tier)


def _labelled(summary: pd.DataFrame, table: str) -> pd.DataFrame:
    s = summary.copy()
    lab = [thesis_labels(t, r, table) for t, r in zip(s["task"], s["tier"])]
    s["task_id"], s["tier_id"] = s["task"], s["tier"]
    s["task"] = [a for a, _ in lab]
    s["dataset"] = [b for _, b in lab]
    return s


def _paper_targets(table: str) -> pd.DataFrame:
    """The thesis's desired returns of Table 5.1/5.2 labelled half/max/10k per setting."""
    from thesis_lib.book import load_reference

    ref = load_reference(table)
    rows = []
    for (task, ds), g in ref.groupby(["task", "dataset"], sort=False):
        vals = sorted(g["desired_return"].unique(), key=float)
        names = ["half", "max", "10k"] if len(vals) == 3 else ["half", "max"]
        rows += [
            {"task": task, "dataset": ds, "target": n, "desired_return": v}
            for n, v in zip(names, vals)
        ]
    return pd.DataFrame(rows)


def _compare(
    table: str,
    ours: pd.DataFrame,
    on: list[str],
    paper_value: str,
    differs: Mapping[str, str] | str | None,
) -> pd.DataFrame:
    from thesis_lib.book import compare_with_paper

    frames = []
    for metric, col in METRICS.items():
        c = compare_with_paper(
            table,
            ours.assign(ours=ours[col]),
            on=on,
            value="ours",
            paper_value=paper_value,
            differs=differs,
        )
        extra = [x for x in (METRIC_STD.get(col), "n_seeds") if x in ours]
        if extra:  # ours: mean over seeds; beside it the std over seeds and their number
            spread = ours[on + extra].rename(columns={METRIC_STD.get(col): "ours_std"})
            spread[on] = spread[on].astype(str)  # compare_with_paper's keys are text
            c = c.merge(spread.drop_duplicates(on), on=on, how="left")
        frames.append(c.assign(metric=metric))
    return pd.concat(frames, ignore_index=True)


def _with_target_rows(
    summary: pd.DataFrame, table: str, methods: Mapping[str, str]
) -> pd.DataFrame:
    s = _labelled(summary, table)
    s = s[s["method"].isin(list(methods))]
    targets = _paper_targets(table)
    rows = []
    for _, r in s.iterrows():
        t = targets[(targets.task == r.task) & (targets.dataset == r.dataset)]
        # RTG methods have one row per target; the others are repeated on every target row.
        for _, tr in t.iterrows():
            if r["target"] in ("none", tr["target"]):
                our_target = "" if r["target"] == "none" else f"our target {tr['target']}"
                rows.append(
                    {
                        **r.to_dict(),
                        "desired_return": tr["desired_return"],
                        "column": methods[r["method"]],
                        "differs": our_target,
                    }
                )
        if t.empty:  # a setting the thesis did not run: keep our own target label
            rows.append(
                {
                    **r.to_dict(),
                    "desired_return": r["target"],
                    "column": methods[r["method"]],
                    "differs": "",
                }
            )
    return pd.DataFrame(rows)


def _by_column(table: str, rows: pd.DataFrame, differs: Any) -> pd.DataFrame:
    frames = []
    for col, g in rows.groupby("column", sort=False):
        c = _compare(table, g, ["task", "dataset", "desired_return"], col, differs)
        frames.append(c.assign(method=col))
    out = pd.concat(frames, ignore_index=True)
    cols = [
        "metric",
        "method",
        "task",
        "dataset",
        "desired_return",
        "paper",
        "ours",
        "ours_std",
        "n_seeds",
        "difference",
        "what differs",
    ]
    return out.reindex(columns=cols)


def thesis_table_5_1(summary: pd.DataFrame, differs: Any = None) -> pd.DataFrame:
    """Table 5.1 (DT at the half/max/10k targets vs DT without RTG), beside the thesis's.

    ``desired_return`` holds the thesis's target; ours (from our data set's max return) is
    named in ``what differs``. Rows for both metrics (column ``metric``).
    """
    rows = _with_target_rows(
        summary, "5.1", {"DT": "original_dt", "DT-noRTG": "dt_without_returns"}
    )
    return _by_column("5.1", rows, differs)


def thesis_table_5_2(summary: pd.DataFrame, differs: Any = None) -> pd.DataFrame:
    """Table 5.2 (HDT vs HDT with RTG at the half/max targets), beside the thesis's."""
    s = summary[summary["target"] != "10k"]
    rows = _with_target_rows(s, "5.2", {"HDT": "hdt", "HDT-RTG": "hdt_with_returns"})
    return _by_column("5.2", rows, differs)


def thesis_table_5_3(
    summary: pd.DataFrame, data_avg: Mapping[tuple[str, str], float], differs: Any = None
) -> pd.DataFrame:
    """Table 5.3 (BC, DT at the max target, HDT, and the data set's average return).

    Args:
        summary: :func:`summarize` output.
        data_avg: ``{(task, tier): average episode return of the data set}``.
    """
    s = summary[
        summary["method"].isin(["BC", "DT", "HDT"]) & summary["target"].isin(["none", "max"])
    ]
    s = _labelled(s, "5.3")
    cols = {"BC": "bc", "DT": "dt", "HDT": "hdt"}
    frames = []
    for method, g in s.groupby("method", sort=False):
        c = _compare("5.3", g, ["task", "dataset"], cols[method], differs)
        frames.append(c.assign(method=cols[method]))
    avg = pd.DataFrame(
        [{"task_id": t, "tier_id": r, "data_avg": v} for (t, r), v in data_avg.items()]
    )
    lab = [thesis_labels(t, r, "5.3") for t, r in zip(avg.task_id, avg.tier_id)]
    avg["task"], avg["dataset"] = [a for a, _ in lab], [b for _, b in lab]
    for metric in METRICS:
        c = _compare(
            "5.3",
            avg.assign(best_return=avg.data_avg, final_return_mean=avg.data_avg),
            ["task", "dataset"],
            "data_avg",
            differs,
        )
        frames.append(c[c.metric == metric].assign(method="data_avg"))
    out = pd.concat(frames, ignore_index=True).drop_duplicates(
        ["metric", "method", "task", "dataset"]
    )
    cols = [
        "metric",
        "method",
        "task",
        "dataset",
        "paper",
        "ours",
        "ours_std",
        "n_seeds",
        "difference",
        "what differs",
    ]
    return out.reindex(columns=cols)


def win_counts(
    table_5_3: pd.DataFrame, metric: str = "best during training (thesis)"
) -> pd.DataFrame:
    """Settings each of BC, DT and HDT wins, ours and the thesis's (ties count for each)."""
    t = table_5_3[(table_5_3.metric == metric) & table_5_3.method.isin(["bc", "dt", "hdt"])]
    out = {}
    for side in ("paper", "ours"):
        wide = t.pivot_table(index=["task", "dataset"], columns="method", values=side).dropna()
        best = wide.max(axis=1)
        out[side] = {m: int((wide[m] == best).sum()) for m in wide.columns}
        out[side]["settings"] = len(wide)
    ran = t.dropna(subset=["ours"])[["task", "dataset"]].drop_duplicates()
    t_ran = t.merge(ran, on=["task", "dataset"])
    wide = t_ran.pivot_table(index=["task", "dataset"], columns="method", values="paper").dropna()
    best = wide.max(axis=1)
    out["paper, our settings only"] = {m: int((wide[m] == best).sum()) for m in wide.columns} | {
        "settings": len(wide)
    }
    return pd.DataFrame(out).T.rename_axis("counted on").reset_index()


# ----------------------------------------------------------------------------------------- figures


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
