"""The HDT chapter's tables: summaries of the runs' rows and Tables 5.1-5.3 beside the thesis's.

* :func:`summarize_curves` (the notebook's curves), :func:`summarize_study` (the study's one
  row per run): both metrics per method x task x tier x target through one reduction over
  seeds (:func:`summarize_runs`): the thesis's (``best_return``: the best evaluation average
  during training, mean +- std over seeds) and the honest one (``final_return_mean`` +-
  ``final_return_std``, the last evaluation).
* :func:`summarize_paper_compat`: the default behaviour beside ``paper_compat=True``;
  :func:`summarize_seed_spread`: settings run with several seeds, as ``mean ± std``.
* :func:`compare_table_5_1`, :func:`compare_table_5_2`, :func:`compare_table_5_3`,
  :func:`compare_win_counts_5_3`: our numbers beside the thesis's.

Used in: HDT chapter (Tables 5.1-5.3), Decision Mamba chapter (:func:`thesis_labels`).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import pandas as pd

from thesis_lib.book import compare_with_paper, load_reference
from thesis_lib.chapters.hdt.config import METHODS

__all__ = [
    "METRICS",
    "METRIC_STD",
    "TARGET_ORDER",
    "compare_table_5_1",
    "compare_table_5_2",
    "compare_table_5_3",
    "compare_win_counts_5_3",
    "summarize_curves",
    "summarize_paper_compat",
    "summarize_runs",
    "summarize_seed_spread",
    "summarize_study",
    "thesis_labels",
]

TARGET_ORDER = ("max", "half", "10k", "none")
"""The RTG targets in the tables' order (``none``: a method without RTG)."""

# ------------------------------------------------------------------------------------ summaries


def summarize_runs(runs: pd.DataFrame, keys: list[str]) -> pd.DataFrame:
    """Mean and std over seeds, per ``keys``, of each run's best and final return and score.

    Args:
        runs: one row per run: ``keys``, ``seed``, ``return_best``, ``score_best``,
            ``return_final``, ``score_final`` (a study row's columns).

    Returns:
        ``keys``, ``best_return``, ``best_return_std``, ``best_score``, ``final_return_mean``,
        ``final_return_std``, ``final_score_mean``, ``final_score_std``, ``n_seeds``.

    Used in: HDT chapter (:func:`summarize_curves`, :func:`summarize_study`).
    """
    g = runs.groupby(keys, sort=False)
    return pd.DataFrame({
        "best_return": g["return_best"].mean(),
        "best_return_std": g["return_best"].std(ddof=0),
        "best_score": g["score_best"].mean(),
        "final_return_mean": g["return_final"].mean(),
        "final_return_std": g["return_final"].std(ddof=0),
        "final_score_mean": g["score_final"].mean(),
        "final_score_std": g["score_final"].std(ddof=0),
        "n_seeds": g["seed"].nunique(),
    }).reset_index()  # fmt: skip


def summarize_curves(curves: pd.DataFrame) -> pd.DataFrame:
    """Both metrics per ``method, task, tier, target`` from :func:`~thesis_lib.chapters.hdt.tasks.run_curves` rows.

    * ``best_return`` (+- ``best_return_std``): the thesis's metric, the highest evaluation
      average seen during training (mean and std over seeds of each run's best);
      ``best_score`` likewise.
    * ``final_return_mean``, ``final_return_std``: the last evaluation, mean and std over
      seeds (``final_score_*`` likewise); ``n_seeds``.

    Rows with and without ``paper_compat`` (when the column is there) are kept apart.

    Used in: HDT chapter (Tables 5.1-5.3).
    """
    keys = ["method", "task", "tier", "target"] + (
        ["paper_compat"] if "paper_compat" in curves else []
    )
    per_run = curves.sort_values("iteration", kind="stable").groupby(keys + ["seed"], sort=False)
    runs = pd.DataFrame({
        "return_best": per_run["return_mean"].max(),
        "score_best": per_run["score_mean"].max(),
        "return_final": per_run["return_mean"].last(),
        "score_final": per_run["score_mean"].last(),
    }).reset_index()  # fmt: skip
    out = summarize_runs(runs, keys)
    order = {m: i for i, m in enumerate(METHODS)} | {t: i for i, t in enumerate(TARGET_ORDER)}
    out = out.sort_values(
        ["task", "tier", "method", "target"],
        kind="stable",
        key=lambda c: c.map(order) if c.name in ("method", "target") else c,
    )
    return out.reset_index(drop=True)


def summarize_study(rows: pd.DataFrame) -> pd.DataFrame:
    """Study rows (one per run, :func:`~thesis_lib.chapters.hdt.tasks.study_run`) as
    :func:`summarize_curves` output, so that the thesis's tables can be set beside them
    (:func:`compare_table_5_1`, :func:`compare_table_5_3`).

    Used in: HDT chapter ("Evidence at study scale").
    """
    keys = ["method", "task", "tier", "target"]
    if rows.empty:
        return pd.DataFrame(columns=keys + ["best_return", "final_return_mean", "n_seeds"])
    return summarize_runs(rows, keys)


def summarize_paper_compat(curves: pd.DataFrame, compat_curves: pd.DataFrame) -> pd.DataFrame:
    """The default behaviour beside ``paper_compat=True``, per method and target, both metrics.

    Used in: HDT chapter (the authors' behaviours measured).

    Args:
        curves: :func:`~thesis_lib.chapters.hdt.tasks.run_curves` rows (default behaviour);
            only the data set and methods of ``compat_curves`` are used.
        compat_curves: :func:`~thesis_lib.chapters.hdt.tasks.run_paper_compat` rows.

    Returns:
        One row per ``metric, method, task, tier, target``: ``correct``, ``correct_std``,
        ``paper_compat``, ``paper_compat_std``, ``difference`` (paper_compat - correct),
        ``n_seeds``.
    """
    keys = ["method", "task", "tier", "target"]
    a = summarize_curves(curves.assign(paper_compat=False))
    b = summarize_curves(compat_curves.assign(paper_compat=True))
    a = a.merge(b[keys], on=keys)  # the settings measured both ways
    frames = []
    for metric, (col, std) in {
        "best during training (thesis)": ("best_return", "best_return_std"),
        "final checkpoint": ("final_return_mean", "final_return_std"),
    }.items():
        m = a[keys + [col, std, "n_seeds"]].merge(
            b[keys + [col, std]], on=keys, suffixes=("", "_compat")
        )
        frames.append(pd.DataFrame({
            "metric": metric, **{k: m[k] for k in keys},
            "correct": m[col], "correct_std": m[std],
            "paper_compat": m[f"{col}_compat"], "paper_compat_std": m[f"{std}_compat"],
            "difference": m[f"{col}_compat"] - m[col], "n_seeds": m["n_seeds"],
        }))  # fmt: skip
    return pd.concat(frames, ignore_index=True)


def summarize_seed_spread(summary: pd.DataFrame) -> pd.DataFrame:
    """Settings run with several seeds: both metrics as ``"mean ± std"`` (RTG methods at max).

    Used in: HDT chapter (seeds: mean ± std).
    """
    multi = summary[(summary.n_seeds > 1) & summary.target.isin(["none", "max"])]
    return pd.DataFrame(
        {
            "task": multi.task,
            "tier": multi.tier,
            "method": multi.method,
            "seeds": multi.n_seeds,
            "best during training (thesis)": [
                f"{m:.1f} ± {s:.1f}" for m, s in zip(multi.best_return, multi.best_return_std)
            ],
            "final checkpoint": [
                f"{m:.1f} ± {s:.1f}"
                for m, s in zip(multi.final_return_mean, multi.final_return_std)
            ],
        }
    )


# ------------------------------------------------------------------------- the thesis's tables
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
    # Table 5.3's Adroit and Kitchen rows (real Minari D4RL/<task>/<tier> sets).
    "pen": "Pen",
    "door": "Door",
    "hammer": "Hammer",
    "relocate": "Relocate",
    "kitchen": "Kitchen",
    "antmaze": "Antmaze",
}
_TIER_NAMES = {"medium-replay": "replay"}


def thesis_labels(task: str, tier: str, table: str) -> tuple[str, str]:
    """``(task, dataset)`` as thesis Table ``table`` prints them, e.g. ``('Maze 2D', 'umaze')``.

    Example:
        >>> thesis_labels("door", "human", "5.3"), thesis_labels("walker2d", "medium-replay", "5.3")
        (('Door', 'human'), ('Walker 2D', 'replay'))
    """
    if task.startswith("maze2d-"):
        return "Maze 2D", task.split("-", 1)[1]
    name: Any = _TASK_NAMES.get(task, task)
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


def compare_table_5_1(summary: pd.DataFrame, differs: Any = None) -> pd.DataFrame:
    """Table 5.1 (DT at the half/max/10k targets vs DT without RTG), beside the thesis's.

    ``desired_return`` holds the thesis's target; ours (from our data set's max return) is
    named in ``what differs``. Rows for both metrics (column ``metric``).
    """
    rows = _with_target_rows(
        summary, "5.1", {"DT": "original_dt", "DT-noRTG": "dt_without_returns"}
    )
    return _by_column("5.1", rows, differs)


def compare_table_5_2(summary: pd.DataFrame, differs: Any = None) -> pd.DataFrame:
    """Table 5.2 (HDT vs HDT with RTG at the half/max targets), beside the thesis's."""
    s = summary[summary["target"] != "10k"]
    rows = _with_target_rows(s, "5.2", {"HDT": "hdt", "HDT-RTG": "hdt_with_returns"})
    return _by_column("5.2", rows, differs)


def compare_table_5_3(
    summary: pd.DataFrame, data_avg: Mapping[tuple[str, str], float], differs: Any = None
) -> pd.DataFrame:
    """Table 5.3 (BC, DT at the max target, HDT, and the data set's average return).

    Args:
        summary: :func:`summarize_curves` (or :func:`summarize_study`) output.
        data_avg: ``{(task, tier): average episode return of the data set}``.
    """
    s = summary[
        summary["method"].isin(["BC", "DT", "HDT"]) & summary["target"].isin(["none", "max"])
    ]
    s = _labelled(s, "5.3")
    paper_cols = {"BC": "bc", "DT": "dt", "HDT": "hdt"}
    frames = []
    for method, g in s.groupby("method", sort=False):
        c = _compare("5.3", g, ["task", "dataset"], paper_cols[method], differs)
        frames.append(c.assign(method=paper_cols[method]))
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


def compare_win_counts_5_3(
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
