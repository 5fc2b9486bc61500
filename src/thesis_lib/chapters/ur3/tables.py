"""The UR3 deployment chapter's tables: Table 5.4 from the runs, the success curves, the dance's
limit checks, and the comparison with the thesis's Table 5.4.

Table 5.4 is computed one way: each run's test episodes are reduced to one row
(:func:`~thesis_lib.chapters.ur3.tasks.run_row`, the study's row), and the runs pooled
(:func:`summarize_study`); :func:`summarize_reach` does both for the notebook's
one-row-per-test-start table.

Used in: UR3 deployment chapter (Table 5.4, success curves, dance playback, "Evidence at study
scale").
"""

from __future__ import annotations

from typing import Any

import numpy as np
import pandas as pd

from thesis_lib.book import compare_with_paper
from thesis_lib.chapters.ur3.tasks import run_row

__all__ = [
    "compare_table_5_4",
    "summarize_dance_checks",
    "summarize_reach",
    "summarize_study",
    "summarize_success_curves",
]


def summarize_study(runs: pd.DataFrame) -> pd.DataFrame:
    """Table 5.4 from one row per run (the study's rows, :func:`~thesis_lib.chapters.ur3.tasks.run_row`):
    mean and std of goals reached over every test start of every seed, per method and count.

    The runs are pooled: the mean of the run means, the std from the runs' moments (every run
    has the same test starts).

    Returns:
        Columns ``method, train_demos, goals_mean, goals_std, all_five`` (share of test
        episodes that reached all goals), ``n_seeds``, for :func:`compare_table_5_4`.

    Used in: UR3 deployment chapter ("Evidence at study scale").
    """
    if runs.empty:
        return pd.DataFrame(columns=["method", "train_demos", "goals_mean", "goals_std"])
    g = runs.groupby(["method", "train_demos"], sort=False)
    # pooled over test starts: the mean of the run means; the std from the runs' moments
    mean = g["goals_mean"].mean()
    second = g.apply(lambda x: float(np.mean(x["goals_std"] ** 2 + x["goals_mean"] ** 2)))
    out = pd.DataFrame({
        "goals_mean": mean,
        "goals_std": np.sqrt(np.maximum(second - mean**2, 0.0)),
        "all_five": g["all_five"].mean(),
        "n_seeds": g["seed"].nunique(),
    }).reset_index()  # fmt: skip
    return out


def summarize_reach(rows: pd.DataFrame) -> pd.DataFrame:
    """Table 5.4 from one row per test start (:func:`~thesis_lib.chapters.ur3.tasks.run_table_5_4`):
    each run reduced as the study's (:func:`~thesis_lib.chapters.ur3.tasks.run_row`), then
    pooled (:func:`summarize_study`): mean and std over test starts and seeds per method and
    count.

    Used in: UR3 deployment chapter (Table 5.4).

    Returns:
        Columns ``method, train_demos, goals_mean, goals_std, all_five`` (share of test
        episodes that reached all goals), ``n_episodes``, as the reference ``table_5_4.csv``.
    """
    if rows.empty:
        return pd.DataFrame(
            columns=["method", "train_demos", "goals_mean", "goals_std", "all_five", "n_episodes"]
        )
    keys = ["method", "train_demos", "seed"]
    runs = pd.DataFrame(
        [dict(zip(keys, k, strict=True)) | run_row(g) for k, g in rows.groupby(keys, sort=False)]
    )
    n_episodes = runs.groupby(["method", "train_demos"], sort=False)["episodes"].sum()
    out = summarize_study(runs).drop(columns="n_seeds")
    out["n_episodes"] = n_episodes.to_numpy()
    return out


def summarize_success_curves(rows: pd.DataFrame, horizon: int = 200) -> pd.DataFrame:
    """Mean number of goals reached by each step ``0..horizon``, per method and count.

    Used in: UR3 deployment chapter (success over the test steps).

    Returns:
        Long table ``method, train_demos, step, goals_mean``.
    """
    out = []
    steps = np.arange(horizon + 1)
    for (m, n), g in rows.groupby(["method", "train_demos"], sort=False):
        reach = np.array(
            [[int(x) for x in s.split()] for s in g["reach_steps"]]
        )  # (episodes, goals)
        hit = (reach[:, :, None] >= 0) & (reach[:, :, None] <= steps[None, None, :])
        mean = hit.sum(axis=1).mean(axis=0)
        out.append(pd.DataFrame({"method": m, "train_demos": n, "step": steps, "goals_mean": mean}))
    return pd.concat(out, ignore_index=True)


def summarize_dance_checks(playback: Any) -> pd.DataFrame:
    """The limit checks of the mapped dance and of what is played: counts, peak speed, lowest tool.

    Used in: UR3 deployment chapter (dance playback).
    """
    return pd.DataFrame(
        [
            {
                "trajectory": name,
                **report.counts(),
                "peak speed / allowed": report.max_speed_ratio,
                "lowest tool z (m)": report.min_tcp_z,
            }
            for name, report in (
                ("mapped dance angles", playback.before),
                (f"played ({playback.mode})", playback.after),
            )
        ]
    )


def compare_table_5_4(ours: pd.DataFrame, differs: dict[str, str]) -> pd.DataFrame:
    """Our Table 5.4 beside the thesis's, mean and std of goals reached, with what differs."""
    mean = compare_with_paper(
        "5.4", ours, on=["method", "train_demos"], value="goals_mean", differs=differs
    )
    std = compare_with_paper("5.4", ours, on=["method", "train_demos"], value="goals_std")
    out = mean.rename(columns={"paper": "paper_mean", "ours": "ours_mean"})
    out.insert(out.columns.get_loc("difference"), "paper_std", std["paper"].to_numpy())
    out.insert(out.columns.get_loc("difference"), "ours_std", std["ours"].to_numpy())
    return out
