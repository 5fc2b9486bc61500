"""The MDLT experiments of thesis 6.5: Tables 6.1-6.3 as functions returning DataFrames.

* :func:`table_6_1` - the features used by music-to-dance methods (static, from the thesis).
* :func:`run_table_6_2` - AIST++: per genre, leave one music out (6 folds), and "All Genres"
  (fold ``i`` holds out the ``i``-th music of every genre), both variants plus the baselines.
* :func:`run_table_6_3` - PhantomDance: 10 folds by sorted index (26 of 260 songs each).
* :func:`summarize` - mean and std over folds in the thesis's layout.

Each fold fits the feature scaler on its training songs only (``paper_compat=True``: on all
songs, validation included, as the authors' code did), trains each variant with
:class:`~thesis_lib.mdlt.train.MDLTTrainer`, translates every validation song autoregressively
and scores it (:mod:`thesis_lib.mdlt.metrics`). The thesis reports the best validation value
seen during training; we report the final model's (and the best over training as
``aje_best`` when ``eval_every`` > 0).

Used in: MDLT chapter (thesis 6.5).
"""

from __future__ import annotations

import dataclasses
import io
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal, NamedTuple

import numpy as np
import pandas as pd
import torch
from tqdm.auto import tqdm

from thesis_lib.mdlt.metrics import BASELINES, aje, evaluate_songs, mean_pose_baseline
from thesis_lib.mdlt.models import MDLTConfig, build_model, init_output_at
from thesis_lib.mdlt.train import DanceWindows, MDLTTrainer
from thesis_lib.seq.trainer import TrainConfig

__all__ = [
    "BEAT_COLUMN",
    "FoldResult",
    "MDLTChapterConfig",
    "MDLTExperimentConfig",
    "VARIANT_LABELS",
    "aist_folds",
    "genre_label",
    "load_sequences",
    "phantomdance_folds",
    "run_fold",
    "run_table_6_2",
    "run_table_6_3",
    "summarize",
    "table_6_1",
    "train_model",
]

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
class MDLTExperimentConfig:
    """Parameters of the MDLT chapter; defaults are the thesis's scale (6.5.1).

    Used in: MDLT chapter (thesis 6.5).
    """

    aist_root: str | None = None
    """An AIST++ folder in the real layout; ``None``: the project's default data set."""
    phantomdance_root: str | None = None
    """A PhantomDance folder; ``None``: the project's default data set in that layout."""
    data_size: Literal["smoke", "full"] = "full"
    """Size of the default data sets (ignored with a root)."""
    data_seed: int = 0
    """Seed of the default data sets."""
    genres: list[str] | None = None
    """Music genres for the per-genre rows of Table 6.2 (e.g. ``["mBR", "mHO"]``); ``None``: all."""
    all_genres: bool = True
    """Also run the "All Genres" row."""
    n_folds: int = 6
    """Folds per Table 6.2 row (the first ``n_folds`` of the 6)."""
    pd_folds: int = 10
    """Folds of Table 6.3 to run (the first ``pd_folds`` of the 10)."""
    variants: list[str] = field(default_factory=lambda: ["transformer", "mamba"])
    """Which MDLT variants to train: ``transformer`` (MDLT-T), ``mamba`` (MDLT-M), and
    ``mamba_audio`` (MDLT-M without the pose input, as the authors' code)."""
    iterations: int = 250_000
    """Gradient steps per model (250k in the thesis)."""
    batch_size: int = 16
    """Windows per batch (16)."""
    lr: float = 0.0001
    """Learning rate (1e-4)."""
    weight_decay: float = 0.0001
    """AdamW weight decay (the authors used Adam: 0 reproduces it)."""
    warmup_steps: int = 1
    """Linear warm-up steps (the authors had none)."""
    grad_clip: float = 0.25
    """Max gradient norm (0: off)."""
    eval_every: int = 1000
    """Validate every this many steps (0: only at the end); gives ``aje_best``."""
    d_model: int = 128
    """Embedding size (128)."""
    n_layers: int = 6
    """Encoder/decoder layers or Mamba blocks (6)."""
    n_heads: int = 8
    """Attention heads of MDLT-T (8)."""
    d_ff: int = 2048
    """Feed-forward width of MDLT-T (2048)."""
    dropout: float = 0.1
    """Dropout (0.1)."""
    K_transformer: int = 20
    """MDLT-T window (20)."""
    K_mamba: int = 120
    """MDLT-M window (120)."""
    pose_noise: float = 0.0
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
    progress: bool = True
    """tqdm bars."""
    checkpoint_dir: str | None = None
    """Write each trained model's checkpoint (with its scaler) here; ``None``: none."""

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

    if root is None:
        try:
            from thesis_lib.mdlt.synth import default_dataset
        except ImportError:
            from thesis_lib.mdlt.dataset import default_dataset
        root = default_dataset(layout=layout, size=size, seed=seed)
    return readers.load_aist(root) if layout == "aist" else readers.load_phantomdance(root)


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
    cfg: MDLTExperimentConfig,
    scaler: Any = None,
    checkpoint_path: str | None = None,
    seed_offset: int = 0,
) -> tuple[torch.nn.Module, pd.DataFrame, Any]:
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


def run_fold(
    train: Sequence,
    val: Sequence,
    cfg: MDLTExperimentConfig,
    experiment: str = "",
    fold: int = 0,
    checkpoint_prefix: str | None = None,
) -> FoldResult:
    """Train every variant on one split, translate the validation songs, score them and the
    baselines. Rows: ``experiment, fold, method, song, aje, mae_deg, fid, beat_align, aje_best,
    train_s``.

    Used in: MDLT chapter (thesis 6.5).
    """
    scaler = _fit_scaler(train, val, cfg.paper_compat, cfg.mute_features)
    true = [np.asarray(s.angles, np.float32) for s in val]
    names = [str(s.name) for s in val]
    beats = [np.asarray(s.features)[:, BEAT_COLUMN] for s in val]
    preds: dict[str, list[np.ndarray]] = {}
    extra: dict[str, dict[str, float]] = {}
    histories: dict[str, pd.DataFrame] = {}
    for k, variant in enumerate(cfg.variants):
        ckpt = f"{checkpoint_prefix}_{variant}.pt" if checkpoint_prefix else None
        t0 = time.perf_counter()
        model, history, _ = train_model(
            variant,
            train,
            val,
            cfg,
            scaler=scaler,
            checkpoint_path=ckpt,
            seed_offset=1000 * fold + k,
        )
        train_s = time.perf_counter() - t0
        preds[variant] = model.generate(
            [scaler.transform(s.features).astype(np.float32) for s in val]
        )
        best = (
            history["eval_return"].min()
            if "eval_return" in history and history["eval_return"].notna().any()
            else np.nan
        )
        extra[variant] = {"aje_best": float(best), "train_s": train_s}
        histories[variant] = history
    for name, fn in BASELINES.items():
        preds[name] = fn(
            [np.asarray(s.angles) for s in train], [len(t) for t in true], seed=cfg.seed + fold
        )
    # an oracle reference, not a method: the mean training pose of the validation song's genre
    # (told the genre, which a translator must hear); equal to the mean pose in per-genre rows
    by_genre: dict[str, list[np.ndarray]] = {}
    for s in train:
        by_genre.setdefault(genre_label(s.genre), []).append(np.asarray(s.angles))
    preds["genre_mean"] = [
        mean_pose_baseline(
            by_genre.get(genre_label(s.genre), [np.asarray(x.angles) for x in train]), [len(t)]
        )[0]
        for s, t in zip(val, true)
    ]
    frames = []
    for method, p in preds.items():
        df = evaluate_songs(p, true, names, beats)
        df.insert(0, "method", VARIANT_LABELS[method])
        for key, value in extra.get(method, {"aje_best": np.nan, "train_s": np.nan}).items():
            df[key] = value
        frames.append(df)
    rows = pd.concat(frames, ignore_index=True)
    rows.insert(0, "fold", fold)
    rows.insert(0, "experiment", experiment)
    return FoldResult(rows, preds, histories)


# ----------------------------------------------------------------------------------------------
# tables


class TableRun(NamedTuple):
    """What :func:`run_table_6_2` and :func:`run_table_6_3` return."""

    rows: pd.DataFrame
    """Tidy rows: experiment, fold, method, song, metrics."""
    examples: dict[str, Any]
    """For figures: the first fold of the last experiment: ``songs`` (the validation
    sequences), ``predictions`` (method -> list of arrays), ``histories``."""


def _run_experiments(
    splits: list[tuple[str, int, list, list]], cfg: MDLTExperimentConfig
) -> TableRun:
    frames, examples = [], {}
    bar = tqdm(splits, desc="folds", disable=not cfg.progress)
    for experiment, fold, train, val in bar:
        bar.set_postfix_str(f"{experiment} fold {fold}")
        prefix = None
        if cfg.checkpoint_dir:
            prefix = str(Path(cfg.checkpoint_dir) / f"{experiment.replace(' ', '_')}_fold{fold}")
        result = run_fold(train, val, cfg, experiment, fold, checkpoint_prefix=prefix)
        frames.append(result.rows)
        if fold == 0:
            examples = {
                "experiment": experiment,
                "songs": val,
                "predictions": result.predictions,
                "histories": result.histories,
            }
    return TableRun(pd.concat(frames, ignore_index=True), examples)


def run_table_6_2(cfg: MDLTExperimentConfig, sequences: Sequence | None = None) -> TableRun:
    """Table 6.2: AIST++ per genre (leave one music out) and all genres, every variant and baseline.

    Used in: MDLT chapter (thesis 6.5.2).
    """
    if sequences is None:
        sequences = load_sequences("aist", cfg.aist_root, cfg.data_size, cfg.data_seed)
    present = sorted({genre_label(s.genre) for s in sequences})
    genres = present if cfg.genres is None else [genre_label(g) for g in cfg.genres]
    splits = []
    for g in genres:
        for i, (tr, va) in enumerate(aist_folds(sequences, g, cfg.n_folds)):
            splits.append((g, i, tr, va))
    if cfg.all_genres:
        for i, (tr, va) in enumerate(aist_folds(sequences, None, cfg.n_folds)):
            splits.append((ALL_GENRES, i, tr, va))
    return _run_experiments(splits, cfg)


def run_table_6_3(cfg: MDLTExperimentConfig, sequences: Sequence | None = None) -> TableRun:
    """Table 6.3: PhantomDance, 10 folds by sorted index (the first ``cfg.pd_folds`` of them).

    Used in: MDLT chapter (thesis 6.5.3).
    """
    if sequences is None:
        sequences = load_sequences(
            "phantomdance", cfg.phantomdance_root, cfg.data_size, cfg.data_seed
        )
    splits = [
        ("PhantomDance", i, tr, va)
        for i, (tr, va) in enumerate(phantomdance_folds(sequences, 10, cfg.pd_folds))
    ]
    return _run_experiments(splits, cfg)


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


@dataclass
class MDLTChapterConfig(MDLTExperimentConfig):
    """The 06_mdlt notebook's parameters: :class:`MDLTExperimentConfig` plus the chapter's extras.

    Used in: MDLT chapter (thesis 6).
    """

    compat_folds: int = 1
    """"All Genres" folds re-run with ``paper_compat=True`` to measure the authors' behaviours
    (0: skip)."""
    animation_seconds: float = 8.0
    """Seconds of the arm animation."""
    probe_mute: list[str] = field(default_factory=list)
    """The chapter's probe: "All Genres" re-run with MDLT-M (audio only) and these feature groups
    muted (e.g. ``["tempogram"]``); empty: no probe."""
    probe_batch_size: int = 64
    """Batch size of the probe's training."""
    probe_iterations: int = 400
    """Updates of the probe's training."""
    probe_grad_clip: float = 1.0
    """Gradient clipping of the probe's training."""
    profile: str = "full"
    """Name of the parameter profile (recorded only)."""

    def __post_init__(self) -> None:
        super().__post_init__()
        if not 0 <= self.compat_folds <= 6:
            raise ValueError(f"Expect 0 <= compat_folds <= 6, actually: {self.compat_folds!r}.")
        self.probe_config()  # checks the probe's groups and sizes

    def probe_config(self) -> MDLTExperimentConfig:
        """The probe's experiment: "All Genres" only, MDLT-M (audio only), ``probe_mute`` muted,
        the probe's batch size, updates and clipping, checkpoints under ``checkpoint_dir/probe``;
        everything else as this config."""
        return MDLTExperimentConfig(
            **{
                **{f.name: getattr(self, f.name) for f in dataclasses.fields(MDLTExperimentConfig)},
                "variants": ["mamba_audio"],
                "mute_features": list(self.probe_mute),
                "genres": [],
                "all_genres": True,
                "batch_size": self.probe_batch_size,
                "iterations": self.probe_iterations,
                "grad_clip": self.probe_grad_clip,
                # its own folder: the main run's checkpoints of the same name must not be resumed
                "checkpoint_dir": str(Path(self.checkpoint_dir) / "probe")
                if self.checkpoint_dir
                else None,
            }
        )
