"""The CLfD chapter's tables: summaries of the experiments' rows and comparisons with the thesis.

``compare_*`` put our numbers beside the thesis's (:func:`thesis_lib.book.compare_with_paper`),
``summarize_*`` reduce rows (the smoke run's, or the study's) to what the chapter shows.

Used in: chapter 02_clfd.
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from thesis_lib.book import compare_with_paper
from thesis_lib.chapters.clfd.config import Config
from thesis_lib.stats import mean_interval


def compare_table_4_1(table: pd.DataFrame, differs: dict[str, str]) -> pd.DataFrame:
    """Table 4.1 beside the thesis (the Pouring rows are 'not run' unless ``pouring_dir`` was given)."""
    ours = table[table["method"] != "untrained"]
    return compare_with_paper(
        "4.1",
        ours,
        on=["dataset", "encoder", "method"],
        value="alignment_error_pct",
        differs=differs,
    )


def compare_table_4_2(table: pd.DataFrame, differs: dict[str, str]) -> pd.DataFrame:
    """Table 4.2 beside the thesis."""
    return compare_with_paper(
        "4.2", table, on=["viewpoints"], value="accuracy_pct", differs=differs
    )


#: C12's final success rate (and Fig 4.4's numbers) are measured over this last share of the
#: training episodes.
RL_FINAL_SHARE = 0.2


def rl_final_numbers(episodes: pd.DataFrame, success_m: float) -> dict[str, float]:
    """One RL run's end of training, over its last :data:`RL_FINAL_SHARE` of episodes:
    ``success_final`` (share that ended with the grasp point within ``success_m`` of the box
    centre), ``final_distance_m`` (mean final gripper-box distance), ``lifted_final`` (share
    that lifted the box) and ``return_final`` (mean Eq 4.2 return). The one reduction of a run
    that Fig 4.4's table and the C12 study's rows share.

    >>> ep = pd.DataFrame({"final_grip_box_distance": [0.2, 0.1, 0.02, 0.01, 0.5],
    ...                    "box_lifted": [0, 0, 1, 1, 0], "return": [-5, -4, -1, 0, -9]})
    >>> rl_final_numbers(ep, 0.03)
    {'success_final': 0.0, 'final_distance_m': 0.5, 'lifted_final': 0.0, 'return_final': -9.0}
    """
    last = episodes.iloc[-max(1, int(np.ceil(RL_FINAL_SHARE * len(episodes)))) :]
    dist = last["final_grip_box_distance"].to_numpy(dtype=float)
    return {
        "success_final": float((dist < success_m).mean()),
        "final_distance_m": float(dist.mean()),
        "lifted_final": float(last["box_lifted"].astype(float).mean()),
        "return_final": float(last["return"].mean()),
    }


def summarize_rl_episodes(cfg: Config, episodes: pd.DataFrame) -> pd.DataFrame:
    """Fig 4.4 in numbers: per encoder, :func:`rl_final_numbers` of its run (the last
    :data:`RL_FINAL_SHARE` of the episodes, as the C12 study measures it)."""
    rows = [
        {"encoder": enc, **rl_final_numbers(g, cfg.rl_success_m)}
        for enc, g in episodes.groupby("encoder", sort=False)
    ]
    return pd.DataFrame(rows, columns=["encoder", *RL_FINAL_COLUMNS])


#: The columns of :func:`rl_final_numbers`.
RL_FINAL_COLUMNS = ("success_final", "final_distance_m", "lifted_final", "return_final")


def describe_numbers(t41: pd.DataFrame, compat: pd.DataFrame, t42: pd.DataFrame) -> list[str]:
    """The lines the chapter prints under "Reading the numbers": test alignment error per
    encoder and method, the untrained floor, the paper_compat effect and the stage accuracy."""
    lines = []
    for enc, g in t41[t41["method"] != "untrained"].groupby("encoder"):
        row = g.set_index("method")["alignment_error_pct"].round(2).to_dict()
        lines.append(f"{enc}: test alignment error (%) by method: {row}")
    floor = (
        t41[t41.method == "untrained"]
        .set_index("encoder")["alignment_error_pct"]
        .round(1)
        .to_dict()
    )
    lines.append(f"untrained floor: {floor}")
    bug = compat.set_index(["encoder", "paper_compat"])["alignment_error_pct"].round(1).to_dict()
    lines.append(f"paper_compat (bug) vs fixed: {bug}")
    acc = t42.set_index("viewpoints")["accuracy_pct"].round(1).to_dict()
    lines.append(f"stage accuracy (%): {acc}")
    return lines


# -- the study's rows (thesis_lib.chapters.clfd.tasks.study_tasks) ---------------------------------


def compare_study_tables(
    rows: pd.DataFrame, differs: dict[str, str]
) -> tuple[pd.DataFrame, pd.DataFrame]:
    """The study's rows as Tables 4.1 and 4.2, beside the thesis's numbers.

    Table 4.1: per encoder x method, the mean test alignment error over seeds (``ours``) with
    its 95% bootstrap interval, the number of seeds and the mean of the lowest validation
    error (the thesis's way); the Pouring rows say ``not run``. Table 4.2: per viewpoint set,
    the mean stage accuracy of the CLfD encoder's MLPs, the same way (the ``Seen->Unseen``
    transfer and the untrained encoder have no thesis value).

    Used in: CLfD chapter ("Evidence at study scale").
    """
    cols41 = ["dataset", "encoder", "method", "alignment_error_pct", "ci_low", "ci_high"]
    t41 = pd.DataFrame(columns=[*cols41, "seeds", "val_best_pct"])
    t42 = pd.DataFrame(columns=["viewpoints", "accuracy_pct", "ci_low", "ci_high", "seeds"])
    if "claim" in rows:
        out = []
        c10 = rows[rows["claim"] == "C10"]  # mid-study: maybe no alignment row (nor column) yet
        for (enc, m), g in c10.groupby(["encoder", "method"], sort=False) if len(c10) else []:
            mean, lo, hi = mean_interval(g["alignment_error_pct"])
            out.append(
                ["PickPlace", enc, m, mean, lo, hi, g["seed"].nunique(), g["val_best_pct"].mean()]
            )
        t41 = pd.DataFrame(out, columns=t41.columns) if out else t41
        c11 = rows[rows["claim"] == "C11"]
        c11 = c11[c11["features"] == "CLfD"] if "features" in c11 else c11.iloc[:0]
        out = []
        for v, g in c11.groupby("method", sort=False):
            mean, lo, hi = mean_interval(g["stage_accuracy"])
            out.append([v, mean, lo, hi, g["seed"].nunique()])
        t42 = pd.DataFrame(out, columns=t42.columns) if out else t42
    extra41 = ["dataset", "encoder", "method", "ci_low", "ci_high", "seeds", "val_best_pct"]
    cmp41 = compare_table_4_1(t41.assign(method=t41["method"].astype(str)), differs)
    cmp41 = cmp41.merge(t41[extra41], on=["dataset", "encoder", "method"], how="left")
    cmp42 = compare_table_4_2(t42, differs).merge(
        t42[["viewpoints", "ci_low", "ci_high", "seeds"]], on="viewpoints", how="left"
    )
    return cmp41, cmp42


def summarize_study_inputs(rows: pd.DataFrame) -> pd.DataFrame:
    """Whether the study's tasks saw the same inputs, per seed: ``data_sets`` (distinct
    ``data_sha`` among its rows; each machine renders a seed's data set anew, so more than one
    means two machines rendered different frames) and ``encoder_matches`` ("k/n": of the stage
    and RL rows on a trained encoder, those whose ``encoder_sha`` is the one the seed's
    alignment task trained; :func:`~thesis_lib.chapters.clfd.encoders.pinned_encoder` keeps
    them equal). Empty before the study ran, and for rows made before the two hashes were
    recorded.

    Used in: CLfD chapter ("Evidence at study scale").
    """
    cols = ["seed", "data_sets", "encoder_matches"]
    if rows.empty or "encoder_sha" not in rows or "claim" not in rows:
        return pd.DataFrame(columns=cols)
    out = []
    for seed, g in rows.groupby("seed"):
        if "scale" in g:
            g = g[g["scale"] == "study"]
        trained = g[(g["claim"] == "C10") & g["encoder_sha"].notna()]
        sha = dict(zip(trained["method"], trained["encoder_sha"]))
        later = g[g["claim"].isin(["C11", "C12"]) & g["encoder_sha"].notna()]
        label = later["method"].where(later["claim"] == "C12", "CLfD")  # C11: CLfD's features
        match = sum(sha.get(m) == e for m, e in zip(label, later["encoder_sha"]))
        out.append([int(seed), int(g["data_sha"].nunique()), f"{match}/{len(later)}"])
    return pd.DataFrame(out, columns=cols)


def summarize_study_rl_curves(rows: pd.DataFrame) -> pd.DataFrame:
    """The C12 success curves: per method and checkpoint episode, the mean share of successful
    training episodes over seeds with its 95% bootstrap interval.

    Used in: CLfD chapter ("Evidence at study scale").
    """
    cols = ["method", "episode", "success", "ci_low", "ci_high", "seeds"]
    if "claim" not in rows:
        return pd.DataFrame(columns=cols)
    c12 = rows[rows["claim"] == "C12"]
    curve = sorted(
        (int(c.removeprefix("success_ep")), c) for c in c12.columns if c.startswith("success_ep")
    )
    out = []
    for m, g in c12.groupby("method", sort=False):
        for episode, col in curve:
            v = g[col].dropna()
            if len(v):
                out.append([m, episode, *mean_interval(v), g.loc[v.index, "seed"].nunique()])
    return pd.DataFrame(out, columns=cols)
