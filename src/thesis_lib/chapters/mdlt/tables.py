"""The MDLT chapter's tables: Table 6.1 (from the thesis), the summaries of the fold rows
(mean and std over folds, AJE against the mean pose), of the study's rows, and Tables 6.2 and
6.3 beside the thesis's.

Used in: MDLT chapter (thesis 6.5).
"""

from __future__ import annotations

import io

import numpy as np
import pandas as pd

from thesis_lib.book import compare_with_paper

from .config import ALL_GENRES, ALL_SCOPE, VARIANT_LABELS, Config

_TABLE_6_1 = """Method\tChromagram\tMFCC\tMFCC Delta\tMel Spectrogram\tOnset Strength\tTempogram\tOthers
AI Choreographer [232]\tx\tx\t\t\t\t\tx
Bailando [233]\tx\tx\tx\t\tx\tx\t
Choreomaster [228]\t\t\t\tx\t\t\t
DanceHat [230]\tx\t\tx\t\tx\tx\tx
DanceFormer [15]\tx\tx\t\t\t\t\t
Dance with Melody [227]\tx\tx\t\t\t\t\t
DeepDance [231]\t\tx\tx\tx\t\t\tx
M2C [224]\tx\tx\tx\t\tx\tx\t
"""


def table_6_1() -> pd.DataFrame:
    """Table 6.1: music features used by music-to-dance methods (copied from the thesis), plus
    the row of MDLT itself (6.3.2: MFCC, MFCC delta, constant-Q chroma, onset strength,
    tempogram; the beat one-hot counted under "Others").

    Used in: MDLT chapter (thesis 6.3.2).
    """
    df = pd.read_csv(io.StringIO(_TABLE_6_1), sep="\t", dtype=str, keep_default_na=False)
    mdlt = {
        "Method": "MDLT (ours, 438-d)",
        "Chromagram": "x",
        "MFCC": "x",
        "MFCC Delta": "x",
        "Mel Spectrogram": "",
        "Onset Strength": "x",
        "Tempogram": "x",
        "Others": "x",
    }
    return pd.concat([df, pd.DataFrame([mdlt])], ignore_index=True)


def scale_note(cfg: Config) -> str:
    """The run's scale against the thesis's, in one line (the comparisons' "what differs")."""
    return (
        f"{cfg.iterations} updates of batch {cfg.batch_size} (thesis: 250k of 16), d {cfg.d_model}, "
        f"{cfg.n_layers} layers, d_ff {cfg.d_ff} (thesis: 128, 6, 2048), {cfg.n_folds} of 6 folds"
    )


def summarize_folds(rows: pd.DataFrame) -> pd.DataFrame:
    """Per experiment and method: metrics averaged over each fold's songs, then mean and std
    over folds (the thesis's "mean +/- std after cross-validation").

    Columns: ``genre, variant, aje_rad_mean, aje_rad_std, fid_mean, fid_std, mae_deg_mean,
    beat_align_mean, aje_best_mean, n_folds``.

    Used in: MDLT chapter (thesis 6.5).
    """
    per_fold = (
        rows.groupby(["experiment", "method", "fold"], sort=False)[
            ["aje", "fid", "mae_deg", "beat_align", "aje_best"]
        ]
        .mean()
        .reset_index()
    )
    g = per_fold.groupby(["experiment", "method"], sort=False)
    out = (
        pd.DataFrame(
            {
                "aje_rad_mean": g["aje"].mean(),
                "aje_rad_std": g["aje"].std(ddof=0),
                "fid_mean": g["fid"].mean(),
                "fid_std": g["fid"].std(ddof=0),
                "mae_deg_mean": g["mae_deg"].mean(),
                "beat_align_mean": g["beat_align"].mean(),
                "aje_best_mean": g["aje_best"].mean(),
                "n_folds": g["fold"].nunique(),
            }
        )
        .reset_index()
        .rename(columns={"experiment": "genre", "method": "variant"})
    )
    return out


def format_summary(summary: pd.DataFrame) -> pd.DataFrame:
    """:func:`summarize_folds`'s rows as the thesis prints them: "mean ± std" strings."""
    return pd.DataFrame(
        {
            "genre": summary.genre,
            "method": summary.variant,
            "AJE (rad)": [
                f"{m:.2f} ± {s:.2f}" for m, s in zip(summary.aje_rad_mean, summary.aje_rad_std)
            ],
            "FID": [f"{m:.2f} ± {s:.2f}" for m, s in zip(summary.fid_mean, summary.fid_std)],
            "MAE (deg)": summary.mae_deg_mean.round(1),
            "beat align": summary.beat_align_mean.round(2),
        }
    )


def compare_table_6_2(summary: pd.DataFrame, cfg: Config) -> pd.DataFrame:
    """Table 6.2 beside the thesis: AJE and FID of MDLT-T and MDLT-M per genre (``metric``)."""
    differs = {
        "data": "project's synthesised AIST++-layout set, not the real AIST++",
        "scale": scale_note(cfg),
    }
    ours = summary[summary.variant.isin(["MDLT-T", "MDLT-M"])]
    on = ["genre", "variant"]
    cmp_aje = compare_with_paper("6.2", ours, on=on, value="aje_rad_mean", differs=differs)
    cmp_fid = compare_with_paper(
        "6.2",
        ours,
        on=on,
        value="fid_mean",
        paper_value="fid_pct_mean",
        differs={
            **differs,
            "implementation": "the thesis prints FID in %; both are plain Fréchet distances",
        },
    )
    return pd.concat(
        [cmp_aje.assign(metric="AJE (rad)"), cmp_fid.assign(metric="FID")], ignore_index=True
    )


def compare_table_6_3(summary: pd.DataFrame, cfg: Config) -> pd.DataFrame:
    """Table 6.3 beside the thesis: AJE and FID of MDLT-T and MDLT-M (``metric``)."""
    ours = summary.rename(columns={"aje_rad_mean": "aje_mean", "aje_rad_std": "aje_std"})
    ours = ours[ours.variant.isin(["MDLT-T", "MDLT-M"])]
    differs = {"data": "project's synthesised PhantomDance-layout set", "scale": scale_note(cfg)}
    return pd.concat(
        [
            compare_with_paper("6.3", ours, on=["variant"], value=v, differs=differs).assign(
                metric=m
            )
            for v, m in (("aje_mean", "AJE (rad)"), ("fid_mean", "FID"))
        ],
        ignore_index=True,
    )


def summarize_aje_vs_mean_pose(summary: pd.DataFrame) -> tuple[pd.DataFrame, pd.DataFrame]:
    """AJE per row (genre) and method, and its ratio to the mean training pose's (both rounded)."""
    piv = summary.pivot_table(index="genre", columns="variant", values="aje_rad_mean", sort=False)
    ratio = piv.div(piv["mean pose"], axis=0)
    return piv.round(3), ratio.round(2)


def describe_mean_pose(cfg: Config, ratio: pd.DataFrame) -> list[str]:
    """How many rows each variant beats the mean pose in (AJE at least 10% lower), and the best
    variant's ratio per row: the lines the chapter prints under the table."""
    labels = [VARIANT_LABELS[v] for v in cfg.variants]
    beaten = {m: int((ratio[m] < 0.9).sum()) for m in labels}
    lines = [
        f"rows where the method's AJE is at least 10% below the mean pose's (of {len(ratio)}): "
        f"{beaten}"
    ]
    if not any(beaten.values()):
        lines.append(
            "No MDLT variant trained as the thesis did beats the mean pose in these rows at this "
            "scale; see the probe below and 'Reading the numbers'."
        )
    best = ratio[labels].min(axis=1)
    lines.append(f"best MDLT variant / mean pose, per row: {best.round(2).to_dict()}")
    return lines


def compare_study_table_6_2(rows: pd.DataFrame) -> pd.DataFrame:
    """The study's rows as Table 6.2 (mean and std of AJE over folds): per genre and "All
    Genres" for MDLT-T and MDLT-M, beside the thesis (:func:`thesis_lib.book.compare_with_paper`).

    Ours: per (genre row, method), the mean over seeds of each run's AJE (itself a mean over
    the six folds' held-out songs); ``aje_rad_std`` is the std over seeds (the thesis's is over
    folds). The "All Genres" row averages the all-genres model over every genre's songs.

    Used in: MDLT chapter ("Evidence at study scale").
    """
    cols = ["genre", "variant", "aje_rad_mean", "aje_rad_std", "n_seeds"]
    if rows.empty:
        ours = pd.DataFrame(columns=cols)
    else:
        r = rows[rows["scale"].fillna("study") == "study"]
        r = r[
            r["method"].str.replace(f" ({ALL_SCOPE})", "", regex=False).isin(["MDLT-T", "MDLT-M"])
        ]
        r = r.assign(
            variant=r["method"].str.replace(f" ({ALL_SCOPE})", "", regex=False),
            genre=np.where(r["scope"] == ALL_SCOPE, ALL_GENRES, r["setting"]),
        )
        per_seed = r.groupby(["genre", "variant", "seed"], sort=False)["aje"].mean().reset_index()
        g = per_seed.groupby(["genre", "variant"], sort=False)
        ours = pd.DataFrame(
            {
                "aje_rad_mean": g["aje"].mean(),
                "aje_rad_std": g["aje"].std(ddof=0),
                "n_seeds": g["seed"].nunique(),
            }
        ).reset_index()
    differs = {
        "data": "project's synthesised AIST++-layout set (study size: 12 pieces of 60 s per genre)",
        "scale": "the study's (params/06_mdlt.study.yml); std over seeds, not folds",
    }
    return compare_with_paper(
        "6.2", ours, on=["genre", "variant"], value="aje_rad_mean", differs=differs
    )


def compare_study_table_6_3() -> pd.DataFrame:
    """Table 6.3 (PhantomDance) of the thesis beside the study: not run (the study is AIST++
    only; the chapter's Table 6.3 runs the PhantomDance layout at smoke scale).

    Used in: MDLT chapter ("Evidence at study scale").
    """
    empty = pd.DataFrame(columns=["variant", "aje_mean"])
    return compare_with_paper(
        "6.3", empty, on=["variant"], value="aje_mean", differs={"data": "not in the C13 study"}
    )


def summarize_study_mismatch(rows: pd.DataFrame) -> pd.DataFrame:
    """MDLT-M's train/inference mismatch at study scale: per scope, the mean AJE of the
    thesis's whole-song recurrence and of restarting every ``K_mamba`` frames, and their
    difference (``mismatch_cost`` > 0: the recurrence costs), over seeds and genres.

    Used in: MDLT chapter ("Evidence at study scale").
    """
    cols = ["method", "runs", "aje", "aje_windowed", "mismatch_cost", "cost_low", "cost_high"]
    if rows.empty or "mismatch_cost" not in rows:
        return pd.DataFrame(columns=cols)
    r = rows[rows["mismatch_cost"].notna() & (rows["scale"].fillna("study") == "study")]
    out = []
    for m, g in r.groupby("method", sort=False):
        c = g["mismatch_cost"].to_numpy(float)
        lo, hi = np.percentile(
            [np.random.default_rng(k).choice(c, len(c)).mean() for k in range(2000)], [2.5, 97.5]
        )
        out.append(
            {
                "method": m,
                "runs": len(g),
                "aje": g["aje"].mean(),
                "aje_windowed": g["aje_windowed"].mean(),
                "mismatch_cost": c.mean(),
                "cost_low": lo,
                "cost_high": hi,
            }
        )
    return pd.DataFrame(out, columns=cols)
