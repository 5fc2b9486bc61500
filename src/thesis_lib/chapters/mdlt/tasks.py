"""The MDLT chapter's experiments: one model (or the baselines) on one fold, as a sweep task
(:func:`fold_task`), and the tables' grids built of them: Table 6.2 (:func:`run_table_6_2`),
Table 6.3 (:func:`run_table_6_3`), the probe, the ``paper_compat`` re-run, PhantomDance at the
other frame rate, and MDLT-M's train/inference mismatch.

Every fold of every experiment, the C13 study's included (:mod:`.study`), runs
:func:`fold_method`: fit the fold's feature scaler on its training songs, train the variant
(:func:`train_model`), translate the validation songs and score them (or score the baselines).

Used in: MDLT chapter (thesis 6.5).
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any, NamedTuple, cast

import numpy as np
import pandas as pd
import torch

from thesis_lib.book import results_dir
from thesis_lib.mdlt.metrics import BASELINES, aje, evaluate_songs, mean_pose_baseline
from thesis_lib.mdlt.models import MDLTMamba, MDLTTransformer, build_model, init_output_at
from thesis_lib.mdlt.train import DanceWindows, MDLTTrainer, load_checkpoint
from thesis_lib.sweep import Task, config_hash, run_tasks, task_id

from . import data
from .config import (
    ALL_GENRES,
    CHAPTER,
    THESIS_MODEL,
    TRAIN_FIELDS,
    VARIANT_LABELS,
    Config,
    compat_config,
    probe_config,
)
from .data import BEAT_COLUMN, aist_folds, fit_scaler, genre_label, phantomdance_folds
from .tables import summarize_folds

# ----------------------------------------------------------------------------------------------
# one model, one fold


def train_model(
    variant: str,
    train: Sequence,
    val: Sequence,
    cfg: Config,
    scaler: Any = None,
    checkpoint_path: str | None = None,
    seed_offset: int = 0,
) -> tuple[MDLTTransformer | MDLTMamba, pd.DataFrame, Any]:
    """Train one MDLT model on ``train`` (validating on ``val`` every ``cfg.eval_every`` steps).

    Returns ``(model in eval mode, training history, scaler)``.

    Used in: MDLT chapter (thesis 6.5).
    """
    scaler = (
        scaler
        if scaler is not None
        else fit_scaler(train, val, cfg.paper_compat, cfg.mute_features)
    )
    feats = [scaler.transform(s.features).astype(np.float32) for s in train]
    angles = [np.asarray(s.angles, np.float32) for s in train]
    val_feats = [scaler.transform(s.features).astype(np.float32) for s in val]
    val_angles = [np.asarray(s.angles, np.float32) for s in val]
    max_t = int(max(len(f) for f in feats + val_feats)) + 1  # the thesis: longest song + 1
    mcfg = cfg.model_config(variant, max_timestep=max_t)
    seed = cfg.seed + seed_offset
    with torch.random.fork_rng(devices=[]):
        torch.manual_seed(seed)
        model = build_model(mcfg)
        if cfg.init_mean_pose:
            init_output_at(model, np.concatenate(angles).mean(0))
    windows = DanceWindows(
        feats,
        angles,
        K=mcfg.K,
        variant=mcfg.variant,
        seed=seed,
        single_frame=cfg.paper_compat and mcfg.variant == "mamba",
        pose_noise=cfg.pose_noise,
    )

    def eval_fn(m):  # mean AJE over the validation songs (logged as the trainer's eval_return)
        preds = m.generate(val_feats)
        return float(np.mean([aje(p, a) for p, a in zip(preds, val_angles)]))

    tcfg = cfg.train_config(checkpoint_path)
    tcfg.seed = seed
    meta = {
        "variant": variant,
        "fps": int(getattr(train[0], "fps", 60)),
        "train_songs": [str(s.name) for s in train],
        "val_songs": [str(s.name) for s in val],
    }
    trainer = MDLTTrainer(
        model, windows, tcfg, eval_fn=eval_fn if cfg.eval_every else None, scaler=scaler, meta=meta
    )
    history = trainer.train()
    model.eval()
    return model, history, scaler


class FoldResult(NamedTuple):
    """What :func:`run_fold` returns."""

    rows: pd.DataFrame
    """One row per method x validation song."""
    predictions: dict[str, list[np.ndarray]]
    """Method -> predicted angles per validation song."""
    histories: dict[str, pd.DataFrame]
    """Variant -> training history."""


def _score(method: str, preds: list[np.ndarray], val: Sequence, extra: dict[str, float]):
    true = [np.asarray(s.angles, np.float32) for s in val]
    beats = [np.asarray(s.features)[:, BEAT_COLUMN] for s in val]
    df = evaluate_songs(preds, true, [str(s.name) for s in val], beats)
    df.insert(0, "method", VARIANT_LABELS[method])
    for key, value in extra.items():
        df[key] = value
    return df


def fold_model(
    variant: str,
    train: Sequence,
    val: Sequence,
    cfg: Config,
    scaler: Any,
    seed_offset: int,
    checkpoint_path: str | None = None,
    windowed: bool = False,
) -> tuple[pd.DataFrame, list[np.ndarray], pd.DataFrame]:
    """Train one variant on one split and translate the validation songs.

    ``windowed``: for MDLT-M, also translate each song restarting from a zero state every
    ``K_mamba`` frames, as the training windows start (:meth:`MDLTMamba.generate`'s
    ``reset_every``), and add its AJE as ``aje_windowed``: lower than ``aje`` means the
    whole-song recurrence (the thesis's inference) costs accuracy.

    Returns:
        ``(rows, predictions, history)``: one row per validation song (``method, song, aje,
        mae_deg, fid, beat_align, aje_best, train_s``), the predicted angles per song, and the
        training history.
    """
    t0 = time.perf_counter()
    model, history, _ = train_model(
        variant,
        train,
        val,
        cfg,
        scaler=scaler,
        checkpoint_path=checkpoint_path,
        seed_offset=seed_offset,
    )
    train_s = time.perf_counter() - t0
    # a list of songs in, a list of (T, 4) angle arrays out
    val_feats = [scaler.transform(s.features).astype(np.float32) for s in val]
    preds = cast(list[np.ndarray], model.generate(val_feats))
    best = (
        history["eval_return"].min()
        if "eval_return" in history and history["eval_return"].notna().any()
        else np.nan
    )
    rows = _score(variant, preds, val, {"aje_best": float(best), "train_s": train_s})
    if windowed and isinstance(model, MDLTMamba):
        reset = cast(list[np.ndarray], model.generate(val_feats, reset_every=model.config.K))
        rows["aje_windowed"] = [aje(p, np.asarray(s.angles)) for p, s in zip(reset, val)]
    return rows, preds, history


def fold_baselines(
    train: Sequence, val: Sequence, seed: int
) -> tuple[pd.DataFrame, dict[str, list[np.ndarray]]]:
    """The baselines (:data:`~thesis_lib.mdlt.metrics.BASELINES`) and the genre-mean oracle on
    one split: their rows (as :func:`fold_model`'s) and predictions."""
    lengths = [len(s.angles) for s in val]
    preds: dict[str, list[np.ndarray]] = {}
    for name, fn in BASELINES.items():
        preds[name] = fn([np.asarray(s.angles) for s in train], lengths, seed=seed)
    # an oracle reference, not a method: the mean training pose of the validation song's genre
    # (told the genre, which a translator must hear); equal to the mean pose in per-genre rows
    by_genre: dict[str, list[np.ndarray]] = {}
    for s in train:
        by_genre.setdefault(genre_label(s.genre), []).append(np.asarray(s.angles))
    preds["genre_mean"] = [
        mean_pose_baseline(
            by_genre.get(genre_label(s.genre), [np.asarray(x.angles) for x in train]), [n]
        )[0]
        for s, n in zip(val, lengths)
    ]
    no_training = {"aje_best": np.nan, "train_s": np.nan}
    rows = pd.concat([_score(m, p, val, no_training) for m, p in preds.items()], ignore_index=True)
    return rows, preds


def fold_method(
    method: str,
    train: Sequence,
    val: Sequence,
    cfg: Config,
    fold: int,
    seed_offset: int,
    checkpoint_path: str | None = None,
    windowed: bool = False,
) -> tuple[pd.DataFrame, dict[str, list[np.ndarray]], pd.DataFrame | None]:
    """One method on one fold: what every fold of the chapter runs (:func:`fold_task`,
    :func:`run_fold` and the C13 study's :func:`~thesis_lib.chapters.mdlt.study.study_run`).

    ``method``: a variant (the fold's scaler fitted on ``train``, :func:`fold_model` with
    ``seed_offset``, ``checkpoint_path`` and ``windowed``), or ``"baselines"``
    (:func:`fold_baselines`, seed ``cfg.seed + fold``).

    Returns:
        ``(rows, predictions, history)``: one row per method and validation song (as
        :func:`fold_model`'s), method -> predicted angles per song, and the training history
        (``None`` for the baselines).
    """
    if method == "baselines":
        rows, preds = fold_baselines(train, val, cfg.seed + fold)
        return rows, preds, None
    scaler = fit_scaler(train, val, cfg.paper_compat, cfg.mute_features)
    rows, p, history = fold_model(
        method, train, val, cfg, scaler, seed_offset, checkpoint_path, windowed=windowed
    )
    return rows, {method: p}, history


def run_fold(
    train: Sequence,
    val: Sequence,
    cfg: Config,
    experiment: str = "",
    fold: int = 0,
    checkpoint_prefix: str | None = None,
) -> FoldResult:
    """Train every variant on one split, translate the validation songs, score them and the
    baselines, in this process. Rows: ``experiment, fold, method, song, aje, mae_deg, fid,
    beat_align, aje_best, train_s``. (The chapter's tables run the same :func:`fold_method`
    as sweep tasks, :func:`fold_task`.)

    Used in: MDLT chapter (thesis 6.5).
    """
    frames, preds, histories = [], {}, {}
    for k, variant in enumerate(cfg.variants):
        ckpt = f"{checkpoint_prefix}_{variant}.pt" if checkpoint_prefix else None
        rows, p, history = fold_method(variant, train, val, cfg, fold, 1000 * fold + k, ckpt)
        frames.append(rows)
        preds.update(p)
        histories[variant] = cast(pd.DataFrame, history)
    rows, base, _ = fold_method("baselines", train, val, cfg, fold, 0)
    preds.update(base)
    rows = pd.concat([*frames, rows], ignore_index=True)
    rows.insert(0, "fold", fold)
    rows.insert(0, "experiment", experiment)
    return FoldResult(rows, preds, histories)


# ----------------------------------------------------------------------------------------------
# the folds as sweep tasks


def _task_file(folder: str | Path, config: dict[str, Any], suffix: str) -> Path:
    name = f"{config['experiment'].replace(' ', '_')}_fold{config['fold']}_{config['method']}"
    path = Path(folder) / f"{name}-{config_hash(config, 12)}{suffix}"
    path.parent.mkdir(parents=True, exist_ok=True)
    return path


def predictions_path(config: dict[str, Any]) -> Path:
    """Where :func:`fold_task` keeps the predictions of the task of ``config`` (``.npz``)."""
    return _task_file(results_dir(CHAPTER) / "predictions", config, ".npz")


def checkpoint_path(config: dict[str, Any], checkpoint_dir: str | None = None) -> Path:
    """Where :func:`fold_task` keeps the checkpoint of the model of ``config``."""
    return _task_file(checkpoint_dir or results_dir(CHAPTER) / "checkpoints", config, ".pt")


@task_id("thesis_lib.chapters.mdlt:fold_task")  # its name when the chapter was one module
def fold_task(config: dict[str, Any]) -> pd.DataFrame:
    """Sweep task: one variant (or, with ``method="baselines"``, the baselines) on one fold.

    Config keys: ``data`` (``layout, root, size, seed`` of
    :func:`~thesis_lib.chapters.mdlt.data.load_sequences`),
    ``experiment`` (a genre label, "All Genres" or "PhantomDance"), ``genre`` (None: all),
    ``fold``, ``method``, ``seed_offset``, ``checkpoint_dir`` (None: under the results) and
    ``cfg`` (the :data:`TRAIN_FIELDS` of the chapter's :class:`Config`). Writes the
    predictions (:func:`predictions_path`) and the checkpoint (:func:`checkpoint_path`).
    Optional (the C13 study's): ``windowed`` (MDLT-M also translated restarting every
    ``K_mamba`` frames, :func:`fold_model`) and ``keep`` (``False``: write neither file).

    Returns:
        One row per validation song, as :func:`run_fold`'s, with the song's ``song_genre``.

    Used in: MDLT chapter (thesis 6.5), through :func:`run_table_6_2` / :func:`run_table_6_3`,
    and its study (:func:`~thesis_lib.chapters.mdlt.study.study_run`).
    """
    cfg = Config(**config["cfg"])
    keep = bool(config.get("keep", True))
    train, val = data.fold_split(config["data"], config["genre"], config["fold"])
    ckpt = None
    if config["method"] != "baselines" and keep:
        ckpt = str(checkpoint_path(config, config["checkpoint_dir"]))
    rows, preds, _ = fold_method(
        config["method"],
        train,
        val,
        cfg,
        config["fold"],
        config["seed_offset"],
        ckpt,
        windowed=bool(config.get("windowed", False)),
    )
    if keep:
        arrays: dict[str, Any] = {
            f"{m}/{i}": np.asarray(a) for m, ps in preds.items() for i, a in enumerate(ps)
        }
        np.savez_compressed(predictions_path(config), **arrays)
    per_song = len(rows) // len(val)  # the baselines: several methods, each over every song
    rows["song_genre"] = [genre_label(s.genre) for s in val] * per_song
    rows.insert(0, "fold", config["fold"])
    rows.insert(0, "experiment", config["experiment"])
    return rows


def fold_tasks(
    cfg: Config, layout: str, experiment: str, genre: str | None, fold: int
) -> list[Task]:
    """The tasks of one fold: each of ``cfg.variants``, then the baselines."""
    root = cfg.aist_root if layout == "aist" else cfg.phantomdance_root
    spec = {"layout": layout, "root": root, "size": cfg.data_size, "seed": cfg.data_seed}
    if layout == "phantomdance":
        spec["fps"] = cfg.phantom_fps()
    base = {
        "data": spec,
        "experiment": experiment,
        "genre": genre,
        "fold": fold,
        "checkpoint_dir": cfg.checkpoint_dir,
    }
    train = {f: getattr(cfg, f) for f in TRAIN_FIELDS}
    tasks = [
        Task(fold_task, {**base, "method": v, "seed_offset": 1000 * fold + k, "cfg": train})
        for k, v in enumerate(cfg.variants)
    ]
    tasks.append(Task(fold_task, {**base, "method": "baselines", "seed_offset": 0, "cfg": train}))
    return tasks


# ----------------------------------------------------------------------------------------------
# the tables' grids


class TableRun(NamedTuple):
    """What :func:`run_table_6_2` and :func:`run_table_6_3` return."""

    rows: pd.DataFrame
    """Tidy rows: experiment, fold, method, song, metrics."""
    examples: dict[str, Any]
    """For figures: the first fold of the last experiment: ``experiment``, ``songs`` (the
    validation sequences) and ``predictions`` (method -> list of arrays)."""


def _run_splits(
    cfg: Config, layout: str, splits: list[tuple[str, str | None, int]], desc: str
) -> TableRun:
    per_split = [fold_tasks(cfg, layout, e, g, i) for e, g, i in splits]
    tasks = [t for ts in per_split for t in ts]
    rows = run_tasks(tasks, store=results_dir(CHAPTER) / "tasks", desc=desc)
    rows = rows.drop(columns="task_key")
    examples: dict[str, Any] = {}
    firsts = [k for k, (_, _, i) in enumerate(splits) if i == 0]
    if firsts:
        k = firsts[-1]
        experiment, genre, fold = splits[k]
        preds: dict[str, list[np.ndarray]] = {}
        for t in per_split[k]:
            with np.load(predictions_path(dict(t.config))) as z:
                for key in sorted(z.files, key=lambda x: (x.split("/")[0], int(x.split("/")[1]))):
                    preds.setdefault(key.split("/")[0], []).append(z[key])
        songs = data.fold_split(dict(per_split[k][0].config["data"]), genre, fold)[1]
        examples = {"experiment": experiment, "songs": songs, "predictions": preds}
    return TableRun(rows, examples)


def run_table_6_2(cfg: Config) -> TableRun:
    """Table 6.2: AIST++ per genre (leave one music out) and all genres, every variant and baseline.

    Used in: MDLT chapter (thesis 6.5.2).
    """
    sequences = data.cached_sequences("aist", cfg.aist_root, cfg.data_size, cfg.data_seed)
    present = sorted({genre_label(s.genre) for s in sequences})
    genres = present if cfg.genres is None else [genre_label(g) for g in cfg.genres]
    splits: list[tuple[str, str | None, int]] = []
    for g in genres:
        splits += [(g, g, i) for i in range(len(aist_folds(sequences, g, cfg.n_folds)))]
    if cfg.all_genres:
        splits += [
            (ALL_GENRES, None, i) for i in range(len(aist_folds(sequences, None, cfg.n_folds)))
        ]
    return _run_splits(cfg, "aist", splits, "Table 6.2 folds")


def run_table_6_3(cfg: Config) -> TableRun:
    """Table 6.3: PhantomDance, 10 folds by sorted index (the first ``cfg.pd_folds`` of them).

    Used in: MDLT chapter (thesis 6.5.3).
    """
    sequences = data.cached_sequences(
        "phantomdance", cfg.phantomdance_root, cfg.data_size, cfg.data_seed, cfg.phantom_fps()
    )
    n = len(phantomdance_folds(sequences, 10, cfg.pd_folds))
    splits: list[tuple[str, str | None, int]] = [("PhantomDance", None, i) for i in range(n)]
    return _run_splits(cfg, "phantomdance", splits, "Table 6.3 folds")


def run_model_sizes(cfg: Config) -> pd.DataFrame:
    """Parameters of each variant at this run's size and at the thesis's (:data:`THESIS_MODEL`)."""
    thesis_cfg = dataclasses.replace(cfg, **THESIS_MODEL)
    rows = []
    for v in cfg.variants:
        ours, thesis = build_model(cfg.model_config(v)), build_model(thesis_cfg.model_config(v))
        rows.append(
            {
                "variant": VARIANT_LABELS[v],
                "K": ours.config.K,
                "parameters (this run)": sum(p.numel() for p in ours.parameters()),
                "parameters (thesis size)": sum(p.numel() for p in thesis.parameters()),
            }
        )
    return pd.DataFrame(rows)


def run_probe(cfg: Config, summary_6_2: pd.DataFrame) -> pd.DataFrame:
    """The probe (:func:`probe_config`) beside the "All Genres" rows of Table 6.2: AJE, its std,
    FID and AJE / mean pose per method (index: method). Empty when ``probe_mute`` is empty."""
    if not cfg.probe_mute:
        return pd.DataFrame()
    pcfg = probe_config(cfg)
    probe = summarize_folds(run_table_6_2(pcfg).rows)
    label = f"MDLT-M (audio only), {' + '.join(pcfg.mute_features)} muted"
    probe = probe.replace({"variant": {"MDLT-M (audio only)": label}})
    labels = [VARIANT_LABELS[v] for v in cfg.variants]
    thesis_inputs = summary_6_2[
        (summary_6_2.genre == ALL_GENRES) & summary_6_2.variant.isin(labels)
    ]
    table = pd.concat([probe, thesis_inputs]).set_index("variant")[
        ["aje_rad_mean", "aje_rad_std", "fid_mean"]
    ]
    table["AJE / mean pose"] = table.aje_rad_mean / table.loc["mean pose", "aje_rad_mean"]
    return table


def run_paper_compat(cfg: Config, summary_6_2: pd.DataFrame) -> pd.DataFrame:
    """AJE and FID of the "All Genres" rows, default against ``paper_compat=True`` (columns:
    metric x run; empty when ``compat_folds`` is 0)."""
    if not cfg.compat_folds:
        return pd.DataFrame()
    compat = summarize_folds(run_table_6_2(compat_config(cfg)).rows)
    both = pd.concat(
        [
            summary_6_2[summary_6_2.genre == ALL_GENRES].assign(run="default"),
            compat.assign(run="paper_compat"),
        ]
    )
    both = both[both.variant.isin([VARIANT_LABELS[v] for v in cfg.variants])]
    return both.pivot_table(
        index="variant", columns="run", values=["aje_rad_mean", "fid_mean"], sort=False
    ).round(3)


def run_phantomdance_fps(cfg: Config, summary_6_3: pd.DataFrame) -> pd.DataFrame:
    """Table 6.3's AJE at the thesis's 60 fps (``summary_6_3``, this run) beside the same folds
    re-run at the authors' 30 fps (``pd_fps=30``, everything else equal): rows method, columns
    fps (when ``cfg`` already runs at 30: 60 is the re-run).

    Used in: MDLT chapter (the two undocumented choices).
    """
    other = 30 if cfg.phantom_fps() == 60 else 60
    rerun = summarize_folds(run_table_6_3(dataclasses.replace(cfg, pd_fps=other)).rows)
    both = pd.concat(
        [
            summary_6_3.assign(fps=f"{cfg.phantom_fps()} fps"),
            rerun.assign(fps=f"{other} fps"),
        ]
    )
    return both.pivot_table(
        index="variant", columns="fps", values="aje_rad_mean", sort=False
    ).round(3)


def run_mismatch(cfg: Config) -> pd.DataFrame:
    """MDLT-M's train/inference mismatch on Table 6.2's "All Genres" folds (the checkpoints
    :func:`run_table_6_2` wrote; nothing is trained): per variant and fold, the AJE of the
    thesis's whole-song recurrence and of restarting the state every ``K_mamba`` frames (as the
    training windows start), and their difference ``mismatch_cost`` (> 0: the recurrence costs).

    Used in: MDLT chapter (the two undocumented choices).
    """
    out: list[dict[str, Any]] = []
    if not cfg.all_genres:
        return pd.DataFrame(out)
    seqs = data.cached_sequences("aist", *data.data_args(cfg))
    for fold in range(len(aist_folds(seqs, None, cfg.n_folds))):
        _, val = aist_folds(seqs, None, cfg.n_folds)[fold]
        for t in fold_tasks(cfg, "aist", ALL_GENRES, None, fold):
            if t.config["method"] not in ("mamba", "mamba_audio"):
                continue
            path = checkpoint_path(dict(t.config), cfg.checkpoint_dir)
            if not path.is_file():
                continue
            model, scaler, _ = load_checkpoint(path)
            if not isinstance(model, MDLTMamba):  # only MDLT-M restarts its state
                continue
            feats = [scaler.transform(s.features).astype(np.float32) for s in val]
            with torch.no_grad():
                whole = model.generate(feats)
                windowed = model.generate(feats, reset_every=model.config.K)
            a = float(np.mean([aje(p, s.angles) for p, s in zip(whole, val)]))
            w = float(np.mean([aje(p, s.angles) for p, s in zip(windowed, val)]))
            out.append(
                {
                    "method": VARIANT_LABELS[t.config["method"]],
                    "fold": fold,
                    "frames per song (mean)": float(np.mean([len(s.angles) for s in val])),
                    "K": model.config.K,
                    "aje (whole-song recurrence)": a,
                    "aje (restart every K)": w,
                    "mismatch_cost": a - w,
                }
            )
    return pd.DataFrame(out)


def example_checkpoint(cfg: Config, variant: str) -> Path:
    """The checkpoint of ``variant`` trained on "All Genres" fold 0 by :func:`run_table_6_2`."""
    task = next(
        t for t in fold_tasks(cfg, "aist", ALL_GENRES, None, 0) if t.config["method"] == variant
    )
    return checkpoint_path(dict(task.config), cfg.checkpoint_dir)
