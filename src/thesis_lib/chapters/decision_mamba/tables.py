"""The Decision Mamba chapter's tables: summaries of the runs' rows, Tables 5.5 and 5.6 beside
the thesis's.

* :func:`summarize_curves` (the notebook's curves) and :func:`summarize_study` (the study's
  one row per run), through one reduction over seeds (:func:`summarize_runs`): per method x
  data set x target (x architecture x evaluation mode), the thesis's metric (best evaluation
  during training, mean +- std over seeds) and the final checkpoint's;
  :func:`summarize_eval_modes`: recurrent vs windowed acting.
* :func:`compare_table_5_5`, :func:`format_table_5_5`, :func:`compare_win_counts_5_5`: Table
  5.5 beside the thesis's, laid out as the thesis prints it, and the "wins out of N settings"
  the thesis quotes (5.3.3).
* :func:`compare_table_5_6`, :func:`summarize_timing_ratios`: Table 5.6 beside the thesis's,
  and as ratios to DT; :func:`summarize_study_timing`: the study's timings (C6).

Used in: Decision Mamba chapter (Tables 5.5, 5.6).
"""

from __future__ import annotations

from typing import Any

import pandas as pd

from thesis_lib.book import compare_with_paper, load_reference
from thesis_lib.chapters.decision_mamba.config import DM_METHODS, MAMBA_METHODS

__all__ = [
    "METRICS",
    "TARGETS",
    "THESIS_METHOD",
    "WIN_COMPARISONS",
    "compare_table_5_5",
    "compare_table_5_6",
    "compare_win_counts_5_5",
    "format_table_5_5",
    "summarize_curves",
    "summarize_eval_modes",
    "summarize_runs",
    "summarize_study",
    "summarize_study_timing",
    "summarize_timing_ratios",
    "thesis_labels_5_5",
]

THESIS_METHOD: dict[str, str] = {
    "DT": "DT",
    "HDT": "HDT",
    "DM-RTG": "DM_with_R",
    "DM-noRTG": "DM_without_R",
    "HDM": "HDM",
}
"""Our names -> the reference tables' (``table_5_5.csv``, ``table_5_6.csv``)."""
TARGETS = ("half", "max", "10k")
"""The RTG targets of Table 5.5, in its order."""
#: The two metrics: the thesis's (best evaluation during training) and the final checkpoint's.
METRICS: dict[str, str] = {"best during training (thesis)": "best", "final checkpoint": "final"}


# ------------------------------------------------------------------------------------ summaries


def summarize_runs(runs: pd.DataFrame, keys: list[str]) -> pd.DataFrame:
    """Mean and std over seeds, per ``keys``, of each run's best and final return.

    Args:
        runs: one row per run: ``keys``, ``seed``, ``return_best``, ``return_final`` (a study
            row's columns).

    Returns:
        ``keys``, ``best_mean``, ``best_std``, ``final_mean``, ``final_std``, ``n_seeds``.

    Used in: Decision Mamba chapter (:func:`summarize_curves`, :func:`summarize_study`).
    """
    g = runs.groupby(keys, sort=False)
    return pd.DataFrame({
        "best_mean": g["return_best"].mean(), "best_std": g["return_best"].std(ddof=0),
        "final_mean": g["return_final"].mean(), "final_std": g["return_final"].std(ddof=0),
        "n_seeds": g["seed"].nunique(),
    }).reset_index()  # fmt: skip


def summarize_curves(curves: pd.DataFrame) -> pd.DataFrame:
    """Both metrics per ``method, task, tier, target, arch, eval_mode`` from
    :func:`~thesis_lib.chapters.decision_mamba.tasks.run_table_5_5` (or ``run_sweeps``) rows.

    * ``best_mean``, ``best_std``: the thesis's metric, each run's highest evaluation average
      during training, mean and std over seeds;
    * ``final_mean``, ``final_std``: the last evaluation of each run, over seeds; ``n_seeds``.

    Evaluations in a non-default ``eval_mode`` (only of the final model) count under that mode.

    Used in: Decision Mamba chapter.
    """
    keys = ["method", "task", "tier", "target", "arch", "eval_mode"]
    per_run = curves.sort_values("iteration").groupby(keys + ["seed"], sort=False)
    runs = pd.DataFrame(
        {"return_best": per_run["return_mean"].max(), "return_final": per_run["return_mean"].last()}
    ).reset_index()
    out = summarize_runs(runs, keys)
    order = {m: i for i, m in enumerate(DM_METHODS)} | {
        t: i for i, t in enumerate((*TARGETS, "none"))
    }
    return out.sort_values(
        ["task", "tier", "arch", "method", "target"],
        key=lambda c: c.map(order) if c.name in ("method", "target") else c,
    ).reset_index(drop=True)


def summarize_study(rows: pd.DataFrame, eval_mode: str = "recurrent") -> pd.DataFrame:
    """The study's score rows (:func:`thesis_lib.chapters.hdt.study_run`) as
    :func:`summarize_curves` output (raw returns), so that :func:`compare_table_5_5` sets the
    thesis's Table 5.5 beside them.

    Used in: Decision Mamba chapter ("Evidence at study scale").
    """
    keys = ["method", "task", "tier", "target"]
    runs = rows.dropna(subset=["return_final"]) if "return_final" in rows else rows.iloc[:0]
    if runs.empty:
        cols = ["best_mean", "best_std", "final_mean", "final_std", "n_seeds"]
        return pd.DataFrame(columns=[*keys, "arch", "eval_mode", *cols])
    out = summarize_runs(runs, keys)
    out["eval_mode"] = [eval_mode if m in MAMBA_METHODS else "window" for m in out.method]
    out["arch"] = "study"
    return out


def summarize_eval_modes(summary: pd.DataFrame) -> pd.DataFrame:
    """Final-checkpoint return of each DM/HDM under both evaluation modes, side by side.

    Used in: Decision Mamba chapter (recurrent vs windowed acting).
    """
    s = summary[summary.method.isin(MAMBA_METHODS)]
    wide = s.pivot_table(
        index=["method", "task", "tier", "target", "arch"],
        columns="eval_mode",
        values="final_mean",
        aggfunc="first",
    )
    wide = wide.reset_index()
    if {"recurrent", "window"} <= set(wide.columns):
        wide["recurrent - window"] = wide["recurrent"] - wide["window"]
    return wide


def summarize_study_timing(rows: pd.DataFrame) -> pd.DataFrame:
    """C6 from the study's timing rows: per environment and method, the mean ms per training
    iteration and per action (windowed; DM/HDM also recurrent) over the repeats, and each
    method's times over the DT's on the same environment.

    Used in: Decision Mamba chapter ("Evidence at study scale").
    """
    cols = ["train_ms", "act_ms_window", "act_ms_recurrent"]
    t = rows.dropna(subset=["train_ms"]) if "train_ms" in rows else rows.iloc[:0]
    if t.empty:
        return pd.DataFrame(columns=["setting", "method", *cols])
    out = t.groupby(["setting", "method"], sort=False)[cols].mean()
    out["repeats"] = t.groupby(["setting", "method"], sort=False)["seed"].nunique()
    dt = out.xs("DT", level="method") if "DT" in out.index.get_level_values("method") else None
    if dt is not None:
        envs = out.index.get_level_values("setting")
        out["train / DT"] = out["train_ms"].to_numpy() / dt["train_ms"].reindex(envs).to_numpy()
        out["act (window) / DT"] = (
            out["act_ms_window"].to_numpy() / dt["act_ms_window"].reindex(envs).to_numpy()
        )
        out["act (own way) / DT"] = (
            out["act_ms_recurrent"].fillna(out["act_ms_window"]).to_numpy()
            / dt["act_ms_window"].reindex(envs).to_numpy()
        )
    return out.reset_index()


# ------------------------------------------------------------------------------- Table 5.5


_TASKS_5_5 = {
    "hopper": "Hopper",
    "walker2d": "Walker2D",
    "halfcheetah": "HalfCheetah",
    "ant": "Ant",
}
_TASKS_5_6 = {
    "hopper": "Hopper",
    "walker2d": "Walker2d",
    "halfcheetah": "HalfCheetah",
    "ant": "Ant",
    "maze2d": "Maze2d",
    "antmaze": "Antmaze",
    "kitchen": "Kitchen",
}


def thesis_labels_5_5(task: str, tier: str) -> tuple[str, str]:
    """``(task, dataset)`` as Table 5.5 prints them.

    Example:
        >>> thesis_labels_5_5("maze2d-umaze", "expert")
        ('Maze2D', 'umaze')
        >>> thesis_labels_5_5("walker2d", "medium-replay")
        ('Walker2D', 'medium-replay')
        >>> thesis_labels_5_5("antmaze", "umaze-diverse")
        ('Antmaze', 'umaze-diverse')
    """
    if task.startswith("maze2d-"):
        return "Maze2D", task.split("-", 1)[1]
    if task.startswith("antmaze-"):
        return "Antmaze", task.split("-", 1)[1] + (
            "" if tier in ("expert", "play", "") else f"-{tier}"
        )
    if task == "kitchen":
        return "Kitchen", tier
    if task == "antmaze":  # a real Minari set, D4RL/antmaze/<tier>
        return "Antmaze", tier
    return _TASKS_5_5.get(task, task), tier


def compare_table_5_5(
    summary: pd.DataFrame, eval_mode: str = "recurrent", differs: Any = None
) -> pd.DataFrame:
    """Table 5.5 beside the thesis's, for both metrics.

    DT and HDT rows are windowed (they have no other mode); DM/HDM rows use ``eval_mode``.

    Args:
        summary: :func:`summarize_curves` output at the Table 5.5 architecture (one ``arch``).
        eval_mode: Which DM/HDM evaluation to show.
        differs: What differs, for every row (see :func:`thesis_lib.book.compare_with_paper`).

    Returns:
        ``metric, method, task, dataset, desired_return, paper, paper_std, ours, ours_std,
        difference, what differs`` (``method`` as the reference table names it).
    """
    s = summary[(summary.eval_mode == eval_mode) | ~summary.method.isin(MAMBA_METHODS)].copy()
    lab = [thesis_labels_5_5(t, r) for t, r in zip(s.task, s.tier)]
    s["task"], s["dataset"] = [a for a, _ in lab], [b for _, b in lab]
    s["method"] = s["method"].map(THESIS_METHOD)
    s["desired_return"] = s["target"]
    ref = load_reference("5.5")
    frames = []
    for metric, col in METRICS.items():
        ours = s.assign(ours=s[f"{col}_mean"])
        c = compare_with_paper(
            "5.5",
            ours,
            on=["task", "dataset", "method", "desired_return"],
            value="ours",
            paper_value="return_mean",
            differs=differs,
        )
        c = c.merge(
            ref.rename(columns={"return_std": "paper_std"})[
                ["task", "dataset", "method", "desired_return", "paper_std"]
            ].astype({"desired_return": str}),
            on=["task", "dataset", "method", "desired_return"],
            how="left",
        )
        std = ours.assign(ours_std=ours[f"{col}_std"])[
            ["task", "dataset", "method", "desired_return", "ours_std"]
        ]
        c = c.merge(
            std.astype({"desired_return": str}),
            on=["task", "dataset", "method", "desired_return"],
            how="left",
        )
        frames.append(c.assign(metric=metric))
    out = pd.concat(frames, ignore_index=True)
    return out[
        [
            "metric",
            "method",
            "task",
            "dataset",
            "desired_return",
            "paper",
            "paper_std",
            "ours",
            "ours_std",
            "difference",
            "what differs",
        ]
    ]


#: The comparisons the thesis quotes in 5.3.3 and its counts (out of 27 settings).
WIN_COMPARISONS: dict[str, tuple[tuple[str, str], tuple[str, str], int]] = {
    "DM wo/ R beats DT (all three targets)": (("DM_without_R", "none"), ("DT", "all"), 15),
    "HDM beats HDT": (("HDM", "none"), ("HDT", "none"), 22),
    "DM wo/ R beats DT at 10k": (("DM_without_R", "none"), ("DT", "10k"), 17),
}


def _wins(wide: pd.DataFrame, a: tuple[str, str], b: tuple[str, str]) -> tuple[int, int]:
    if a not in wide.columns:
        return 0, 0
    if b[1] == "all":
        cols = [(b[0], t) for t in TARGETS if (b[0], t) in wide.columns]
        if not cols:
            return 0, 0
        sub = wide[[a, *cols]].dropna()
        return int((sub[a].values[:, None] > sub[cols].values).all(axis=1).sum()), len(sub)
    if b not in wide.columns:
        return 0, 0
    sub = wide[[a, b]].dropna()
    return int((sub[a] > sub[b]).sum()), len(sub)


def compare_win_counts_5_5(table: pd.DataFrame) -> pd.DataFrame:
    """The thesis's "wins out of N settings" (5.3.3): quoted, recounted from its Table 5.5, and ours.

    Args:
        table: :func:`compare_table_5_5` output.

    Returns:
        One row per comparison and metric: ``comparison, metric, thesis text, thesis table
        (all settings), thesis table (our settings), ours`` as ``"wins/settings"``.
    """
    ref = load_reference("5.5")
    paper_all = ref.pivot_table(
        index=["task", "dataset"], columns=["method", "desired_return"], values="return_mean"
    )
    rows = []
    for metric in table.metric.unique():
        t = table[table.metric == metric]
        ours = t.pivot_table(
            index=["task", "dataset"], columns=["method", "desired_return"], values="ours"
        )
        ran = t.dropna(subset=["ours"])[["task", "dataset"]].drop_duplicates()
        keys = set(zip(ran.task, ran.dataset))
        paper_ours = paper_all[[k in keys for k in paper_all.index]]
        for name, (a, b, quoted) in WIN_COMPARISONS.items():
            w_all, n_all = _wins(paper_all, a, b)
            w_sub, n_sub = _wins(paper_ours, a, b)
            w_ours, n_ours = _wins(ours, a, b)
            rows.append(
                {
                    "comparison": name,
                    "metric": metric,
                    "thesis text": f"{quoted}/27",
                    "thesis table (all settings)": f"{w_all}/{n_all}",
                    "thesis table (our settings)": f"{w_sub}/{n_sub}",
                    "ours": f"{w_ours}/{n_ours}",
                }
            )
    return pd.DataFrame(rows)


def format_table_5_5(
    table: pd.DataFrame, metric: str = "best during training (thesis)"
) -> pd.DataFrame:
    """Table 5.5 laid out as the thesis prints it: one row per setting, one column per method/target,
    each cell ``"ours ± std  (thesis ± std)"``; settings we did not run are left out.

    Used in: Decision Mamba chapter (Table 5.5).
    """
    t = table[(table.metric == metric)].dropna(subset=["ours"]).copy()
    order = [
        ("DT", "half"),
        ("DT", "max"),
        ("DT", "10k"),
        ("HDT", "none"),
        ("DM_with_R", "half"),
        ("DM_with_R", "max"),
        ("DM_with_R", "10k"),
        ("DM_without_R", "none"),
        ("HDM", "none"),
    ]

    def cell(r: pd.Series) -> str:
        paper = "" if pd.isna(r.paper) else f"  ({r.paper:.1f} ± {r.paper_std:.1f})"
        return f"{r.ours:.1f} ± {0.0 if pd.isna(r.ours_std) else r.ours_std:.1f}{paper}"

    t["cell"] = t.apply(cell, axis=1)
    t["column"] = [f"{m} {d}" if d != "none" else m for m, d in zip(t.method, t.desired_return)]
    wide = t.pivot_table(
        index=["task", "dataset"], columns="column", values="cell", aggfunc="first"
    )
    cols = [f"{m} {d}" if d != "none" else m for m, d in order]
    return wide[[c for c in cols if c in wide.columns]]


# ------------------------------------------------------------------------------- Table 5.6


def compare_table_5_6(timing: pd.DataFrame, differs: Any = None) -> pd.DataFrame:
    """Table 5.6 beside the thesis's GPU numbers.

    The thesis's inference times re-ran the window, so they sit beside our ``window`` rows;
    our ``recurrent`` rows are added as ``<method> (recurrent step)``, not in the thesis.

    Used in: Decision Mamba chapter (Table 5.6).
    """
    t = timing.copy()
    t["env"] = [_TASKS_5_6.get(task.split("-")[0], task) for task in t.task]
    t["method"] = [
        THESIS_METHOD[m] + (" (recurrent step)" if mode == "recurrent" else "")
        for m, mode in zip(t.method, t["mode"])
    ]
    out = compare_with_paper(
        "5.6", t, on=["env", "phase", "method"], value="time_ms_mean", differs=differs
    )
    std = t[["env", "phase", "method", "time_ms_std"]].rename(columns={"time_ms_std": "ours_std"})
    return out.merge(std, on=["env", "phase", "method"], how="left")


def summarize_timing_ratios(timing: pd.DataFrame) -> pd.DataFrame:
    """Table 5.6 as ratios: each method's times over DT's, and windowed over recurrent acting.

    Args:
        timing: :func:`run_table_5_6` output.

    Returns:
        One row per ``task, method``: the times (ms) per phase (and mode) and the ratios
        ``train / DT``, ``inference (window) / DT``, ``inference (recurrent) / DT`` (DT windowed)
        and ``window / recurrent``.

    Used in: Decision Mamba chapter (Table 5.6).
    """
    t = timing.assign(
        key=[p if not m else f"{p} ({m})" for p, m in zip(timing["phase"], timing["mode"])]
    )
    wide = t.pivot_table(index=["task", "method"], columns="key", values="time_ms_mean")
    dt = wide.xs("DT", level="method")
    ratios = wide.copy()
    tasks = wide.index.get_level_values("task")
    for col in ("train", "inference (window)"):
        ratios[f"{col} / DT"] = wide[col] / dt[col].reindex(tasks).values
    if "inference (recurrent)" in wide:
        ratios["inference (recurrent) / DT"] = (
            wide["inference (recurrent)"] / dt["inference (window)"].reindex(tasks).values
        )
        ratios["window / recurrent"] = wide["inference (window)"] / wide["inference (recurrent)"]
    return ratios.reset_index()
