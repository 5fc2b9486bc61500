"""The MDLT chapter (thesis 6.5): its :class:`Config`, Tables 6.1-6.3 and figures.

* :func:`table_6_1` - the features used by music-to-dance methods (static, from the thesis).
* :func:`run_table_6_2` - AIST++: per genre, leave one music out (6 folds), and "All Genres"
  (fold ``i`` holds out the ``i``-th music of every genre), both variants plus the baselines.
* :func:`run_table_6_3` - PhantomDance: 10 folds by sorted index (26 of 260 songs each).
* :func:`summarize` - mean and std over folds in the thesis's layout; :func:`compare_table_6_2`
  and :func:`compare_table_6_3` beside the thesis.

Each fold fits the feature scaler on its training songs only (``paper_compat=True``: on all
songs, validation included, as the authors' code did), trains each variant with
:class:`~thesis_lib.mdlt.train.MDLTTrainer`, translates every validation song autoregressively
and scores it (:mod:`thesis_lib.mdlt.metrics`). The thesis reports the best validation value
seen during training; we report the final model's (and the best over training as
``aje_best`` when ``eval_every`` > 0).

The folds run through :func:`thesis_lib.sweep.run_tasks`, one task per model x fold
(:func:`fold_task`; the baselines of a fold are one more task), stored under
``results/06_mdlt/tasks``; each task writes its checkpoint (under ``checkpoint_dir``, default
``results/06_mdlt/checkpoints``) and its predictions (``results/06_mdlt/predictions``), named by
the hash of its config, so an interrupted run resumes and no run resumes another's checkpoint.

Used in: MDLT chapter (thesis 6.5).
"""

from __future__ import annotations

import dataclasses
import functools
import io
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal, NamedTuple, cast

import numpy as np
import pandas as pd
import torch

from thesis_lib.book import compare_with_paper, results_dir
from thesis_lib.mdlt.metrics import BASELINES, aje, evaluate_songs, mean_pose_baseline
from thesis_lib.mdlt.models import (
    MDLTConfig,
    MDLTMamba,
    MDLTTransformer,
    build_model,
    init_output_at,
)
from thesis_lib.mdlt.train import DanceWindows, MDLTTrainer
from thesis_lib.seq.trainer import TrainConfig
from thesis_lib.sweep import Task, config_hash, run_tasks

CHAPTER = "06_mdlt"

VARIANT_LABELS = {
    "transformer": "MDLT-T",
    "mamba": "MDLT-M",
    "mamba_audio": "MDLT-M (audio only)",
    "mean_pose": "mean pose",
    "last_pose": "last pose",
    "random": "random",
    "genre_mean": "genre mean pose (oracle)",
}
"""Method names as the tables print them."""
BEAT_COLUMN = 53
"""Index of the beat one-hot in the raw 438-d features (MFCC 20 + delta 20 + chroma 12 + onset 1)."""
ALL_GENRES = "All Genres"

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


@dataclass
class Config:
    """Parameters of ``notebooks/06_mdlt.ipynb``; defaults are the smoke scale
    (``params/06_mdlt.full.yml`` holds the thesis's, 6.5.1; :data:`THESIS_MODEL` its model size).

    Used in: MDLT chapter (thesis 6.5).
    """

    aist_root: str | None = None
    """An AIST++ folder in the real layout; ``None``: the project's default data set."""
    phantomdance_root: str | None = None
    """A PhantomDance folder; ``None``: the project's default data set in that layout."""
    data_size: Literal["smoke", "full"] = "smoke"
    """Size of the default data sets (ignored with a root)."""
    data_seed: int = 0
    """Seed of the default data sets."""
    genres: list[str] | None = field(default_factory=lambda: ["mHO"])
    """Music genres for the per-genre rows of Table 6.2 (e.g. ``["mBR", "mHO"]``); ``None``: all."""
    all_genres: bool = True
    """Also run the "All Genres" row."""
    n_folds: int = 2
    """Folds per Table 6.2 row (the first ``n_folds`` of the 6)."""
    pd_folds: int = 1
    """Folds of Table 6.3 to run (the first ``pd_folds`` of the 10)."""
    variants: list[str] = field(default_factory=lambda: ["transformer", "mamba", "mamba_audio"])
    """Which MDLT variants to train: ``transformer`` (MDLT-T), ``mamba`` (MDLT-M), and
    ``mamba_audio`` (MDLT-M without the pose input, as the authors' code)."""
    iterations: int = 200
    """Gradient steps per model (250k in the thesis)."""
    batch_size: int = 16
    """Windows per batch (16)."""
    lr: float = 0.001
    """Learning rate (1e-4)."""
    weight_decay: float = 0.0001
    """AdamW weight decay (the authors used Adam: 0 reproduces it)."""
    warmup_steps: int = 1
    """Linear warm-up steps (the authors had none)."""
    grad_clip: float = 0.25
    """Max gradient norm (0: off)."""
    eval_every: int = 0
    """Validate every this many steps (0: only at the end); gives ``aje_best``."""
    d_model: int = 64
    """Embedding size (128)."""
    n_layers: int = 2
    """Encoder/decoder layers or Mamba blocks (6)."""
    n_heads: int = 4
    """Attention heads of MDLT-T (8)."""
    d_ff: int = 256
    """Feed-forward width of MDLT-T (2048)."""
    dropout: float = 0.1
    """Dropout (0.1)."""
    K_transformer: int = 20
    """MDLT-T window (20)."""
    K_mamba: int = 60
    """MDLT-M window (120)."""
    pose_noise: float = 0.3
    """Std (rad) of noise on the input poses in training (not in the thesis; against exposure
    bias, see :class:`~thesis_lib.mdlt.train.DanceWindows`)."""
    mute_features: list[str] = field(default_factory=list)
    """Feature groups the models get as a constant (``"tempogram"``, ``"mfcc"``, ... see
    :data:`~thesis_lib.mdlt.audio.FEATURE_SLICES`); empty: all 438 dimensions (the thesis)."""
    init_mean_pose: bool = True
    """Start each model's output at the training songs' mean pose
    (:func:`~thesis_lib.mdlt.models.init_output_at`); ``False``: PyTorch's default
    initialisation (the thesis's; output near the zero pose at first)."""
    paper_compat: bool = False
    """The authors' code: scaler fitted on all songs (validation too), MDLT-M trained on single
    frames without poses. The reported value stays the final model's."""
    seed: int = 0
    """Seed of model init, sampling and dropout."""
    device: str = "cpu"
    """``cpu``, ``cuda`` or ``auto``."""
    progress: bool = False
    """tqdm bars."""
    checkpoint_dir: str | None = None
    """Folder of each trained model's checkpoint (with its scaler; an interrupted training
    resumes from it); ``None``: ``results/06_mdlt/checkpoints``."""
    compat_folds: int = 1
    """"All Genres" folds re-run with ``paper_compat=True`` to measure the authors' behaviours
    (0: skip)."""
    animation_seconds: float = 6.0
    """Seconds of the arm animation."""
    probe_mute: list[str] = field(default_factory=lambda: ["tempogram"])
    """The chapter's probe: "All Genres" re-run with MDLT-M (audio only) and these feature groups
    muted (e.g. ``["tempogram"]``); empty: no probe."""
    probe_batch_size: int = 64
    """Batch size of the probe's training."""
    probe_iterations: int = 400
    """Updates of the probe's training."""
    probe_grad_clip: float = 1.0
    """Gradient clipping of the probe's training."""
    profile: str = "smoke"
    """Name of the parameter profile (recorded only)."""

    def __post_init__(self) -> None:
        if self.data_size not in ("smoke", "full"):
            raise ValueError(f"Unknown data_size {self.data_size!r}. Valid: smoke, full.")
        unknown = [v for v in self.variants if v not in ("transformer", "mamba", "mamba_audio")]
        if unknown or not self.variants:
            raise ValueError(
                f"Unknown variant(s) {unknown or self.variants!r}. Valid: transformer, mamba, mamba_audio."
            )
        from thesis_lib.mdlt.audio import check_feature_groups

        check_feature_groups(self.mute_features, "in mute_features")
        if not 1 <= self.n_folds <= 6:
            raise ValueError(
                f"Expect 1 <= n_folds <= 6 (leave one of 6 pieces out), actually: {self.n_folds!r}."
            )
        if not 1 <= self.pd_folds <= 10:
            raise ValueError(f"Expect 1 <= pd_folds <= 10, actually: {self.pd_folds!r}.")
        for name in ("iterations", "batch_size", "warmup_steps", "K_transformer", "K_mamba"):
            if int(getattr(self, name)) < 1:
                raise ValueError(f"Expect `{name}` >= 1, actually: {getattr(self, name)!r}.")
        if not 0 <= self.compat_folds <= 6:
            raise ValueError(f"Expect 0 <= compat_folds <= 6, actually: {self.compat_folds!r}.")
        check_feature_groups(self.probe_mute, "in probe_mute")

    def model_config(self, variant: str, max_timestep: int = 8192) -> MDLTConfig:
        """The :class:`MDLTConfig` of ``variant`` under these parameters."""
        mamba = variant in ("mamba", "mamba_audio")
        return MDLTConfig(
            variant="mamba" if mamba else "transformer",
            K=self.K_mamba if mamba else self.K_transformer,
            d_model=self.d_model,
            n_layers=self.n_layers,
            n_heads=self.n_heads,
            d_ff=self.d_ff,
            dropout=self.dropout,
            max_timestep=max_timestep,
            pose_input=variant == "mamba" and not self.paper_compat,
        )

    def train_config(self, checkpoint_path: str | None = None) -> TrainConfig:
        """The :class:`TrainConfig` of every model."""
        return TrainConfig(
            iterations=self.iterations,
            batch_size=self.batch_size,
            lr=self.lr,
            weight_decay=self.weight_decay,
            warmup_steps=self.warmup_steps,
            grad_clip=self.grad_clip,
            eval_every=self.eval_every,
            checkpoint_path=checkpoint_path,
            checkpoint_every=max(self.eval_every, 1000),
            resume=True,
            seed=self.seed,
            device=self.device,
            progress=self.progress,
        )


# ----------------------------------------------------------------------------------------------
# data


def genre_label(genre: str) -> str:
    """AIST++ music-genre label as Table 6.2 prints it: ``gBR``/``BR``/``mBR`` -> ``mBR``.

    Example:
        >>> genre_label("gHO"), genre_label("mHO"), genre_label("HO")
        ('mHO', 'mHO', 'mHO')
    """
    g = str(genre)
    if len(g) == 3 and g[0] in "gm":
        return "m" + g[1:]
    if len(g) == 2:
        return "m" + g
    return g


def load_sequences(
    layout: Literal["aist", "phantomdance"],
    root: str | None = None,
    size: str = "full",
    seed: int = 0,
) -> list:
    """Music-dance pairs of ``layout``: read ``root``, or make the default data set first.

    Used in: MDLT chapter (thesis 6.3).
    """
    from thesis_lib.mdlt import readers
    from thesis_lib.mdlt.synth import default_dataset

    where = default_dataset(layout=layout, size=size, seed=seed) if root is None else root
    return readers.load_aist(where) if layout == "aist" else readers.load_phantomdance(where)


def aist_folds(sequences: Sequence, genre: str | None, n_folds: int = 6) -> list[tuple[list, list]]:
    """Thesis 6.5.1 splits: per genre, fold ``i`` validates on the genre's ``i``-th music (by id);
    ``genre=None`` ("All Genres"): fold ``i`` validates on the ``i``-th music of every genre.

    Used in: MDLT chapter (thesis 6.5.1).
    """
    by_genre: dict[str, list] = {}
    for s in sequences:
        by_genre.setdefault(genre_label(s.genre), []).append(s)
    for g in by_genre:
        by_genre[g].sort(key=lambda s: str(s.music_id))
    if genre is not None:
        label = genre_label(genre)
        if label not in by_genre:
            raise ValueError(
                f"No sequences of genre {genre!r}. Genres present: {', '.join(sorted(by_genre))}."
            )
        by_genre = {label: by_genre[label]}
    n_min = min(len(v) for v in by_genre.values())
    if n_min < 2:
        raise ValueError(
            f"Leave-one-music-out needs >= 2 pieces per genre; some genre has {n_min}."
        )
    folds = []
    for i in range(min(n_folds, n_min)):
        val = [v[i] for v in by_genre.values()]
        train = [s for v in by_genre.values() for j, s in enumerate(v) if j != i]
        folds.append((train, val))
    return folds


def phantomdance_folds(
    sequences: Sequence, n_folds: int = 10, run: int | None = None
) -> list[tuple[list, list]]:
    """Thesis 6.5.3: songs sorted by name, fold ``i`` validates on the ``i``-th tenth.

    ``run``: only the first ``run`` folds (default all).
    """
    seqs = sorted(sequences, key=lambda s: str(s.name))
    if len(seqs) < n_folds:
        raise ValueError(f"{n_folds} folds need >= {n_folds} sequences, got {len(seqs)}.")
    bounds = np.linspace(0, len(seqs), n_folds + 1).round().astype(int)
    folds = []
    for i in range(n_folds if run is None else min(run, n_folds)):
        val = seqs[bounds[i] : bounds[i + 1]]
        train = seqs[: bounds[i]] + seqs[bounds[i + 1] :]
        folds.append((train, val))
    return folds


def _fit_scaler(train: Sequence, val: Sequence, paper_compat: bool, mute: Sequence[str] = ()):
    from thesis_lib.mdlt.audio import fit_feature_scaler

    return fit_feature_scaler(
        [s.features for s in train],
        [s.features for s in val],
        paper_compat=paper_compat,
        mute=tuple(mute),
    )


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
        else _fit_scaler(train, val, cfg.paper_compat, cfg.mute_features)
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
        "fps": 60,
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
) -> tuple[pd.DataFrame, list[np.ndarray], pd.DataFrame]:
    """Train one variant on one split and translate the validation songs.

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
    preds = cast(
        list[np.ndarray],
        model.generate([scaler.transform(s.features).astype(np.float32) for s in val]),
    )
    best = (
        history["eval_return"].min()
        if "eval_return" in history and history["eval_return"].notna().any()
        else np.nan
    )
    rows = _score(variant, preds, val, {"aje_best": float(best), "train_s": train_s})
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
    beat_align, aje_best, train_s``. (The chapter's tables run the same steps as sweep tasks.)

    Used in: MDLT chapter (thesis 6.5).
    """
    scaler = _fit_scaler(train, val, cfg.paper_compat, cfg.mute_features)
    frames, preds, histories = [], {}, {}
    for k, variant in enumerate(cfg.variants):
        ckpt = f"{checkpoint_prefix}_{variant}.pt" if checkpoint_prefix else None
        rows, preds[variant], histories[variant] = fold_model(
            variant, train, val, cfg, scaler, 1000 * fold + k, ckpt
        )
        frames.append(rows)
    rows, base = fold_baselines(train, val, cfg.seed + fold)
    preds.update(base)
    rows = pd.concat([*frames, rows], ignore_index=True)
    rows.insert(0, "fold", fold)
    rows.insert(0, "experiment", experiment)
    return FoldResult(rows, preds, histories)


# ----------------------------------------------------------------------------------------------
# the folds as sweep tasks

#: Config fields a model's training depends on (a :func:`fold_task` config holds them).
TRAIN_FIELDS = (
    "iterations", "batch_size", "lr", "weight_decay", "warmup_steps", "grad_clip", "eval_every",
    "d_model", "n_layers", "n_heads", "d_ff", "dropout", "K_transformer", "K_mamba", "pose_noise",
    "mute_features", "init_mean_pose", "paper_compat", "seed", "device",
)  # fmt: skip


@functools.lru_cache(maxsize=4)
def _cached_sequences(layout: str, root: str | None, size: str, seed: int) -> tuple:
    return tuple(load_sequences(layout, root, size, seed))  # type: ignore[arg-type]


def _split(data: dict[str, Any], genre: str | None, fold: int) -> tuple[list, list]:
    seqs = _cached_sequences(data["layout"], data["root"], data["size"], data["seed"])
    if data["layout"] == "phantomdance":
        return phantomdance_folds(seqs, 10, run=fold + 1)[fold]
    return aist_folds(seqs, genre, fold + 1)[fold]


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


def fold_task(config: dict[str, Any]) -> pd.DataFrame:
    """Sweep task: one variant (or, with ``method="baselines"``, the baselines) on one fold.

    Config keys: ``data`` (``layout, root, size, seed`` of :func:`load_sequences`),
    ``experiment`` (a genre label, "All Genres" or "PhantomDance"), ``genre`` (None: all),
    ``fold``, ``method``, ``seed_offset``, ``checkpoint_dir`` (None: under the results) and
    ``cfg`` (the :data:`TRAIN_FIELDS` of the chapter's :class:`Config`). Writes the
    predictions (:func:`predictions_path`) and the checkpoint (:func:`checkpoint_path`).

    Returns:
        One row per validation song, as :func:`run_fold`'s.

    Used in: MDLT chapter (thesis 6.5), through :func:`run_table_6_2` / :func:`run_table_6_3`.
    """
    cfg = Config(**config["cfg"])
    train, val = _split(config["data"], config["genre"], config["fold"])
    if config["method"] == "baselines":
        rows, preds = fold_baselines(train, val, cfg.seed + config["fold"])
    else:
        scaler = _fit_scaler(train, val, cfg.paper_compat, cfg.mute_features)
        ckpt = str(checkpoint_path(config, config["checkpoint_dir"]))
        rows, p, _ = fold_model(
            config["method"], train, val, cfg, scaler, config["seed_offset"], ckpt
        )
        preds = {config["method"]: p}
    arrays: dict[str, Any] = {
        f"{m}/{i}": np.asarray(a) for m, ps in preds.items() for i, a in enumerate(ps)
    }
    np.savez_compressed(predictions_path(config), **arrays)
    rows.insert(0, "fold", config["fold"])
    rows.insert(0, "experiment", config["experiment"])
    return rows


def fold_tasks(
    cfg: Config, layout: str, experiment: str, genre: str | None, fold: int
) -> list[Task]:
    """The tasks of one fold: each of ``cfg.variants``, then the baselines."""
    root = cfg.aist_root if layout == "aist" else cfg.phantomdance_root
    base = {
        "data": {"layout": layout, "root": root, "size": cfg.data_size, "seed": cfg.data_seed},
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
# tables


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
        songs = _split(dict(per_split[k][0].config["data"]), genre, fold)[1]
        examples = {"experiment": experiment, "songs": songs, "predictions": preds}
    return TableRun(rows, examples)


def run_table_6_2(cfg: Config) -> TableRun:
    """Table 6.2: AIST++ per genre (leave one music out) and all genres, every variant and baseline.

    Used in: MDLT chapter (thesis 6.5.2).
    """
    sequences = _cached_sequences("aist", cfg.aist_root, cfg.data_size, cfg.data_seed)
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
    sequences = _cached_sequences(
        "phantomdance", cfg.phantomdance_root, cfg.data_size, cfg.data_seed
    )
    n = len(phantomdance_folds(sequences, 10, cfg.pd_folds))
    splits: list[tuple[str, str | None, int]] = [("PhantomDance", None, i) for i in range(n)]
    return _run_splits(cfg, "phantomdance", splits, "Table 6.3 folds")


def summarize(rows: pd.DataFrame) -> pd.DataFrame:
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


# ----------------------------------------------------------------------------------------------
# the notebook's steps

THESIS_MODEL: dict[str, Any] = {
    "d_model": 128,
    "n_layers": 6,
    "n_heads": 8,
    "d_ff": 2048,
    "dropout": 0.1,
    "K_transformer": 20,
    "K_mamba": 120,
}
"""The thesis's model size (6.5.1), for :func:`run_model_sizes`."""


def scale_note(cfg: Config) -> str:
    """The run's scale against the thesis's, in one line (the comparisons' "what differs")."""
    return (
        f"{cfg.iterations} updates of batch {cfg.batch_size} (thesis: 250k of 16), d {cfg.d_model}, "
        f"{cfg.n_layers} layers, d_ff {cfg.d_ff} (thesis: 128, 6, 2048), {cfg.n_folds} of 6 folds"
    )


def load_datasets(cfg: Config) -> tuple[list, list]:
    """The AIST++-layout and PhantomDance-layout music-dance pairs of ``cfg`` (read once per
    process; the default data sets are made on first use)."""
    aist = _cached_sequences("aist", cfg.aist_root, cfg.data_size, cfg.data_seed)
    phantom = _cached_sequences("phantomdance", cfg.phantomdance_root, cfg.data_size, cfg.data_seed)
    return list(aist), list(phantom)


def run_dataset_table(cfg: Config) -> pd.DataFrame:
    """Per data set: music-dance pairs, genres, mean length (s) and frames."""
    aist, phantom = load_datasets(cfg)
    return pd.DataFrame(
        [
            {
                "data set": name,
                "pairs": len(seqs),
                "genres": len({genre_label(s.genre) for s in seqs}),
                "seconds (mean)": np.mean([len(s.angles) / s.fps for s in seqs]),
                "frames": sum(len(s.angles) for s in seqs),
            }
            for name, seqs in (("AIST++ layout", aist), ("PhantomDance layout", phantom))
        ]
    )


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


def format_table(summary: pd.DataFrame) -> pd.DataFrame:
    """:func:`summarize`'s rows as the thesis prints them: "mean ± std" strings."""
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


def aje_against_mean_pose(summary: pd.DataFrame) -> tuple[pd.DataFrame, pd.DataFrame]:
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


def probe_config(cfg: Config) -> Config:
    """The probe's experiment: "All Genres" only, MDLT-M (audio only), ``probe_mute`` muted,
    the probe's batch size, updates and clipping; everything else as ``cfg``."""
    return dataclasses.replace(
        cfg,
        variants=["mamba_audio"],
        mute_features=list(cfg.probe_mute),
        genres=[],
        all_genres=True,
        batch_size=cfg.probe_batch_size,
        iterations=cfg.probe_iterations,
        grad_clip=cfg.probe_grad_clip,
    )


def run_probe(cfg: Config, summary_6_2: pd.DataFrame) -> pd.DataFrame:
    """The probe (:func:`probe_config`) beside the "All Genres" rows of Table 6.2: AJE, its std,
    FID and AJE / mean pose per method (index: method). Empty when ``probe_mute`` is empty."""
    if not cfg.probe_mute:
        return pd.DataFrame()
    pcfg = probe_config(cfg)
    probe = summarize(run_table_6_2(pcfg).rows)
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


def compat_config(cfg: Config) -> Config:
    """The paper_compat re-run: "All Genres" only, ``compat_folds`` folds, ``paper_compat=True``."""
    return dataclasses.replace(
        cfg, paper_compat=True, genres=[], all_genres=True, n_folds=max(1, cfg.compat_folds)
    )


def run_paper_compat(cfg: Config, summary_6_2: pd.DataFrame) -> pd.DataFrame:
    """AJE and FID of the "All Genres" rows, default against ``paper_compat=True`` (columns:
    metric x run; empty when ``compat_folds`` is 0)."""
    if not cfg.compat_folds:
        return pd.DataFrame()
    compat = summarize(run_table_6_2(compat_config(cfg)).rows)
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


def best_variant(cfg: Config, run: TableRun, ratio: pd.DataFrame) -> str:
    """The variant with the lowest AJE / mean pose in the experiment of ``run.examples``."""
    row = run.examples["experiment"]
    return min(cfg.variants, key=lambda v: ratio.loc[row, VARIANT_LABELS[v]])


def plot_predictions(cfg: Config, run: TableRun):
    """Each variant's translation of the first validation song of ``run.examples`` against the
    dancer's angles, one column per variant."""
    import matplotlib.pyplot as plt

    from thesis_lib.mdlt import plot_angles

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
    from thesis_lib.mdlt import animate_arm

    song = run.examples["songs"][0]
    animate_arm(
        run.examples["predictions"][variant][0],
        fps=song.fps,
        true=song.angles,
        path=path,
        max_seconds=cfg.animation_seconds,
    )
    return Path(path)


def example_checkpoint(cfg: Config, variant: str) -> Path:
    """The checkpoint of ``variant`` trained on "All Genres" fold 0 by :func:`run_table_6_2`."""
    task = next(
        t for t in fold_tasks(cfg, "aist", ALL_GENRES, None, 0) if t.config["method"] == variant
    )
    return checkpoint_path(dict(task.config), cfg.checkpoint_dir)
