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
import hashlib
import io
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal, NamedTuple, cast

import numpy as np
import pandas as pd
import torch

from thesis_lib._io import hash_arrays
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
THESIS_FOLDS = 6
"""Folds of a Table 6.2 row (AIST++ has 6 pieces per genre: leave one out)."""

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
    data_size: Literal["smoke", "full", "study"] = "smoke"
    """Size of the default data sets (ignored with a root); ``study``: the C13 study's AIST++-layout
    set (12 pieces of 60 s with a song form per genre, :data:`thesis_lib.mdlt.synth.SIZES`; its
    PhantomDance-layout set is the smoke one)."""
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
    frames without poses, PhantomDance features at 30 fps (unless ``pd_fps`` says). The
    reported value stays the final model's."""
    pd_fps: int | None = None
    """Feature (and angle) frames per second of the PhantomDance-layout data: ``None``: 60, as
    the thesis says (6.3.2), or 30 with ``paper_compat`` (the authors' code); 30 or 60 to
    choose."""
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
    study_seeds: list[int] = field(default_factory=lambda: [0, 1, 2])
    """Seeds of the C13 study (``params/06_mdlt.study.yml``; :func:`study_tasks`)."""
    study_probe: bool = True
    """The C13 study also runs the probe (:func:`probe_config`) on "All Genres", reported apart."""
    study_teacher_forcing: bool = False
    """The C13 study also trains each variant on "All Genres" with the thesis's plain teacher
    forcing (``pose_noise`` 0), labelled ``"<variant> TF"`` and reported apart."""
    profile: str = "smoke"
    """Name of the parameter profile (recorded only)."""

    def __post_init__(self) -> None:
        if self.data_size not in ("smoke", "full", "study"):
            raise ValueError(f"Unknown data_size {self.data_size!r}. Valid: smoke, full, study.")
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
        if self.pd_fps is not None and self.pd_fps not in (30, 60):
            raise ValueError(f"Expect pd_fps None, 30 or 60, actually: {self.pd_fps!r}.")

    def phantom_fps(self) -> int:
        """Frames per second of the PhantomDance-layout data under these parameters."""
        if self.pd_fps is not None:
            return int(self.pd_fps)
        return 30 if self.paper_compat else 60

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
    fps: int | None = None,
) -> list:
    """Music-dance pairs of ``layout``: read ``root``, or make the default data set first.

    ``fps``: feature frames per second of the PhantomDance layout (``None``: the reader's 60);
    AIST++ is always at 60. The ``study`` size exists for AIST++ only: PhantomDance gets its
    smoke set.

    Used in: MDLT chapter (thesis 6.3).
    """
    from thesis_lib.mdlt import readers
    from thesis_lib.mdlt.synth import default_dataset

    if layout == "phantomdance" and size == "study":
        size = "smoke"
    where = default_dataset(layout=layout, size=size, seed=seed) if root is None else root
    if layout == "aist":
        return readers.load_aist(where)
    return readers.load_phantomdance(where, fps=fps)


def aist_folds(sequences: Sequence, genre: str | None, n_folds: int = 6) -> list[tuple[list, list]]:
    """Thesis 6.5.1 splits: per genre, fold ``i`` validates on the genre's ``i``-th music (by id);
    ``genre=None`` ("All Genres"): fold ``i`` validates on the ``i``-th music of every genre.

    With more than :data:`THESIS_FOLDS` (6) pieces per genre (the ``study`` data size), the
    folds stay six: fold ``i`` validates on every piece ``j`` of the genre with ``j % 6 == i``.

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
    groups = min(n_min, THESIS_FOLDS)
    folds = []
    for i in range(min(n_folds, groups)):
        val = [s for v in by_genre.values() for j, s in enumerate(v) if j % groups == i]
        train = [s for v in by_genre.values() for j, s in enumerate(v) if j % groups != i]
        folds.append((train, val))
    return folds


def piece_fingerprint(
    sequences: Sequence, group: str = "tempogram", frames_per_piece: int = 200, seed: int = 0
) -> dict[str, Any]:
    """How much a feature group names the piece it comes from: the memorisation risk of C13.

    The features are min-max scaled over all ``sequences`` (as
    :class:`~thesis_lib.mdlt.audio.FeatureScaler` does) and restricted to ``group``
    (:data:`~thesis_lib.mdlt.audio.FEATURE_SLICES`). Then:

    * ``between_share``: the share of the group's total variance (summed over its dimensions)
      that lies between the pieces' means; 1 = constant within a piece, 0 = the same mean in
      every piece;
    * ``id_accuracy``: for ``frames_per_piece`` random frames of each piece, how often the
      nearest piece mean (Euclidean) is the frame's own piece; ``chance`` = 1 / pieces.

    A group with a high share and accuracy lets a model recognise each training piece and
    memorise its dance instead of learning what the music asks for.

    Used in: MDLT chapter (the data; the C13 study's data size).

    Example:
        >>> from types import SimpleNamespace as NS
        >>> x = np.zeros((4, 438), np.float32)
        >>> a, b = NS(features=x), NS(features=x + np.eye(1, 438, 100, dtype=np.float32))
        >>> piece_fingerprint([a, b])["between_share"]
        1.0
    """
    from thesis_lib.mdlt.audio import FEATURE_SLICES

    if group not in FEATURE_SLICES:
        raise ValueError(f"Unknown feature group {group!r}. Valid: {', '.join(FEATURE_SLICES)}.")
    if len(sequences) < 2:
        raise ValueError(f"Expect >= 2 pieces, got {len(sequences)}.")
    sl = FEATURE_SLICES[group]
    feats = [np.asarray(s.features, np.float64)[:, sl] for s in sequences]
    lo = np.min([f.min(0) for f in feats], axis=0)
    hi = np.max([f.max(0) for f in feats], axis=0)
    span = np.where(hi > lo, hi - lo, 1.0)
    feats = [(f - lo) / span for f in feats]
    n = np.array([len(f) for f in feats], dtype=np.float64)
    means = np.stack([f.mean(0) for f in feats])
    grand = (means * n[:, None]).sum(0) / n.sum()
    between = float((n * ((means - grand) ** 2).sum(1)).sum())
    total = float(sum(((f - grand) ** 2).sum() for f in feats))
    rng = np.random.default_rng(seed)
    hits, tried = 0, 0
    for i, f in enumerate(feats):
        idx = rng.choice(len(f), size=min(frames_per_piece, len(f)), replace=False)
        d = ((f[idx, None, :] - means[None]) ** 2).sum(-1)  # (frames, pieces)
        hits += int((d.argmin(1) == i).sum())
        tried += len(idx)
    return {
        "group": group,
        "pieces": len(feats),
        "seconds_per_piece": float(
            np.mean([len(s.features) / getattr(s, "fps", 60) for s in sequences])
        ),
        "between_share": between / total if total > 0 else float("nan"),
        "id_accuracy": hits / tried,
        "chance": 1.0 / len(feats),
    }


def fingerprint_table(
    cfg: Config, sizes: Sequence[str] = ("smoke", "study"), make: bool = False
) -> pd.DataFrame:
    """:func:`piece_fingerprint` of the tempogram (and, for contrast, the MFCC deltas) on the
    default AIST++-layout set at each of ``sizes`` (``cfg.data_seed``); with ``cfg.aist_root``,
    that folder instead. One row per size x group.

    ``make``: make a default set that does not exist yet (the study size costs about 5
    CPU-minutes); ``False``: report it as not made (``thesis study 06_mdlt`` makes it) unless it
    is the run's own ``data_size``.

    Used in: MDLT chapter (the data) and its study section.
    """
    from thesis_lib.mdlt.synth import default_root

    out: list[dict[str, Any]] = []
    for size in [cfg.data_size] if cfg.aist_root else sizes:
        made = (default_root("aist", size, cfg.data_seed) / ".complete.json").is_file()
        if not (cfg.aist_root or made or make or size == cfg.data_size):
            out.append({"data size": size, "group": "not made yet (thesis study 06_mdlt makes it)"})
            continue
        seqs = _cached_sequences("aist", cfg.aist_root, size, cfg.data_seed)
        for group in ("tempogram", "mfcc_delta"):
            out.append({"data size": size, **piece_fingerprint(seqs, group)})
    return pd.DataFrame(out)


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
def _cached_sequences(
    layout: str, root: str | None, size: str, seed: int, fps: int | None = None
) -> tuple:
    return tuple(load_sequences(layout, root, size, seed, fps))  # type: ignore[arg-type]


@functools.lru_cache(maxsize=4)
def _data_sha(layout: str, root: str | None, size: str, seed: int, fps: int | None = None) -> str:
    """A short hash of every piece's name, features and angles (:func:`_cached_sequences`).

    The study's rows record it: each machine synthesises and featurises the data set anew, and
    this says whether two machines made the same numbers.
    """
    h = hashlib.sha256()
    for s in _cached_sequences(layout, root, size, seed, fps):
        h.update(str(s.name).encode())
        hash_arrays(h, (s.features, s.angles))
    return h.hexdigest()[:16]


def _split(data: dict[str, Any], genre: str | None, fold: int) -> tuple[list, list]:
    seqs = _cached_sequences(
        data["layout"], data["root"], data["size"], data["seed"], data.get("fps")
    )
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
    data = {"layout": layout, "root": root, "size": cfg.data_size, "seed": cfg.data_seed}
    if layout == "phantomdance":
        data["fps"] = cfg.phantom_fps()
    base = {
        "data": data,
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
        "phantomdance", cfg.phantomdance_root, cfg.data_size, cfg.data_seed, cfg.phantom_fps()
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
    phantom = _cached_sequences(
        "phantomdance", cfg.phantomdance_root, cfg.data_size, cfg.data_seed, cfg.phantom_fps()
    )
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
    from thesis_lib.ur3.dance import map_dance

    song = run.examples["songs"][0]
    animate_arm(  # both arms in the pose `thesis ur3 play` would play (offset and halving)
        map_dance(run.examples["predictions"][variant][0]),
        fps=song.fps,
        true=map_dance(song.angles),
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


# ----------------------------------------------------------------------------------------------
# the pre-registered study (claim C13, params/06_mdlt.study.yml)

PER_GENRE, ALL_SCOPE = "per genre", "all genres"
"""The two scopes of Table 6.2: a model per genre, or one model for all genres."""
_METHOD_INDEX = {"transformer": 0, "mamba": 1, "mamba_audio": 2}
PROBE_LABEL = "MDLT-M probe"
TF_SUFFIX = "TF"
"""Label suffix of the study's plain teacher-forcing runs (``study_teacher_forcing``)."""
"""The probe (:func:`probe_config`: audio-only MDLT-M, tempogram muted, batch 64) in the study."""


def study_label(label: str, scope: str) -> str:
    """A method's name in the study's rows: ``label`` per genre, ``"label (all genres)"`` else.

    >>> study_label("MDLT-M", "all genres"), study_label("mean pose", "per genre")
    ('MDLT-M (all genres)', 'mean pose')
    """
    return label if scope == PER_GENRE else f"{label} ({ALL_SCOPE})"


def neg_aje(aje_rad: float) -> float:
    """The study's higher-is-better metric: minus the AJE (rad); 0 is a perfect translation.

    >>> neg_aje(0.25)
    -0.25
    """
    return -float(aje_rad)


def gain_vs_mean_pose(aje_rad: float, aje_mean_pose: float) -> float:
    """``1 - AJE / AJE(mean training pose)`` on the same songs: 0 = no better than standing in
    the mean pose, 1 = perfect, < 0 = worse (higher is better).

    >>> gain_vs_mean_pose(0.3, 0.5)
    0.4
    """
    return float(1.0 - aje_rad / aje_mean_pose) if aje_mean_pose > 0 else float("nan")


def _study_songs(
    method: str, train: Sequence, val: Sequence, cfg: Config, seed_offset: int
) -> list[dict[str, Any]]:
    """Per validation song of one fold: its genre and the scores of ``method`` (a variant, or
    ``"mean_pose"`` / ``"genre_mean"``), with the mean pose's AJE on the same song."""
    true = [np.asarray(s.angles, np.float32) for s in val]
    lengths = [len(a) for a in true]
    mean_pose = mean_pose_baseline([np.asarray(s.angles) for s in train], lengths)
    extra: list[dict[str, float]] = [{} for _ in val]
    if method in ("mean_pose", "genre_mean"):
        rows, base = fold_baselines(train, val, cfg.seed)
        preds = base[method]
        train_s = 0.0
    else:
        scaler = _fit_scaler(train, val, cfg.paper_compat, cfg.mute_features)
        rows, preds, _ = fold_model(method, train, val, cfg, scaler, seed_offset, windowed=True)
        train_s = float(rows["train_s"].iloc[0])
        if "aje_windowed" in rows:  # MDLT-M: the train/inference mismatch (fold_model)
            extra = [{"aje_windowed": float(w)} for w in rows["aje_windowed"]]
    beats = [np.asarray(s.features)[:, BEAT_COLUMN] for s in val]
    scored = evaluate_songs(preds, true, [str(s.name) for s in val], beats)
    return [
        {
            "genre": genre_label(s.genre),
            "aje": float(r.aje),
            "fid": float(r.fid),
            "beat_align": float(r.beat_align),
            "aje_mean_pose": aje(mp, t),
            "frames": len(t),
            "train_s": train_s,
            **e,
        }
        for s, r, mp, t, e in zip(val, scored.itertuples(), mean_pose, true, extra)
    ]


#: The columns of a study run's rows (:func:`study_run`; ``aje_windowed`` and ``mismatch_cost``
#: in MDLT-M's rows only); the study engine checks the study file's metrics against them.
STUDY_COLUMNS = [
    "method", "setting", "seed", "scope", "scale", "folds", "songs", "aje", "neg_aje",
    "aje_mean_pose", "gain_vs_mean_pose", "fid", "beat_align", "train_s", "data_sha",
    "aje_windowed", "mismatch_cost",
]  # fmt: skip


def study_run(config: dict[str, Any]) -> list[dict[str, Any]]:
    """One C13 study task: one method, one scope (and genre), one seed, over every fold.

    Config keys: ``data`` (as :func:`fold_task`'s), ``scope`` (:data:`PER_GENRE` or
    :data:`ALL_SCOPE`), ``genre`` (the genre of a per-genre task; ``None`` for all genres),
    ``method`` (a variant, ``"probe"``, or ``"baselines"``: the mean pose and, for all
    genres, the genre-mean pose), ``folds`` (fold indices), ``seed``, ``cfg`` (the
    :data:`TRAIN_FIELDS` of the chapter's :class:`Config`; ``seed`` is overridden),
    ``scale`` (``study`` or ``check``) and, for the plain teacher-forcing runs, ``recipe``
    (``"teacher forcing"``: the method's label gains :data:`TF_SUFFIX`).

    Each fold trains the method on the fold's training pieces (held-out music: the fold's
    validation pieces are never trained on) and translates every validation piece from its
    first frame to its last; the per-song scores are averaged per genre of the song over all
    folds (every song weighs the same).

    Returns:
        One row per method and genre (a per-genre task: one; all genres: one per genre):
        ``method`` (:func:`study_label`), ``setting`` (the genre), ``seed``, ``scope``,
        ``scale``, ``folds``, ``songs``, ``aje`` (rad, lower is better), ``neg_aje``
        (:func:`neg_aje`, the primary, higher-is-better metric), ``aje_mean_pose`` (the mean
        training pose on the same songs), ``gain_vs_mean_pose`` (:func:`gain_vs_mean_pose`,
        secondary, higher is better), ``fid``, ``beat_align``, ``train_s``, and for MDLT-M
        ``aje_windowed`` and ``mismatch_cost`` (``aje - aje_windowed``: what the whole-song
        recurrence costs against restarting every ``K_mamba`` frames; > 0 = it costs), and
        ``data_sha`` (:func:`_data_sha`: which numbers the data set held on this machine).

    Used in: ``thesis study 06_mdlt`` (C13).
    """
    torch.set_num_threads(1)  # small models: one core per run
    seed = int(config["seed"])
    cfg = Config(**{**config["cfg"], "seed": seed})
    method, scope = config["method"], config["scope"]
    if method == "probe":  # the task's cfg is already probe_config's
        variants, labels = ["mamba_audio"], [PROBE_LABEL]
    elif config.get("recipe") == "teacher forcing":  # the task's cfg has pose_noise 0
        variants, labels = [method], [f"{VARIANT_LABELS[method]} {TF_SUFFIX}"]
    elif method == "baselines":
        variants = ["mean_pose"] + (["genre_mean"] if scope == ALL_SCOPE else [])
        labels = [VARIANT_LABELS["mean_pose"], "genre mean"][: len(variants)]
    else:
        variants, labels = [method], [VARIANT_LABELS[method]]
    genre = config["genre"] if scope == PER_GENRE else None
    d = config["data"]
    data_sha = _data_sha(d["layout"], d["root"], d["size"], d["seed"], d.get("fps"))
    out: list[dict[str, Any]] = []
    for variant, label in zip(variants, labels):
        songs: list[dict[str, Any]] = []
        for fold in config["folds"]:
            train, val = _split(config["data"], genre, int(fold))
            offset = 1000 * int(fold) + _METHOD_INDEX.get(variant, 0)
            songs += _study_songs(variant, train, val, cfg, offset)
        df = pd.DataFrame(songs)
        for g, grp in df.groupby("genre", sort=True):
            a, mp = float(grp["aje"].mean()), float(grp["aje_mean_pose"].mean())
            row = {
                "method": study_label(label, scope),
                "setting": str(g),
                "seed": seed,
                "scope": scope,
                "scale": config.get("scale", "study"),
                "folds": len(config["folds"]),
                "songs": len(grp),
                "aje": a,
                "neg_aje": neg_aje(a),
                "aje_mean_pose": mp,
                "gain_vs_mean_pose": gain_vs_mean_pose(a, mp),
                "fid": float(grp["fid"].mean()),
                "beat_align": float(grp["beat_align"].mean()),
                "train_s": float(grp["train_s"].drop_duplicates().sum()),
                "data_sha": data_sha,
            }
            if "aje_windowed" in grp and grp["aje_windowed"].notna().all():
                w = float(grp["aje_windowed"].mean())
                row.update(aje_windowed=w, mismatch_cost=a - w)
            out.append(row)
    return out


def study_tasks(cfg: Config) -> list[Task]:
    """The tasks of the chapter's pre-registered study (``params/06_mdlt.study.yml``, C13):
    per genre (each of ``cfg.genres``, all when ``None``) and, with ``cfg.all_genres``, all
    genres; each of ``cfg.variants`` and the baselines (and, with ``cfg.study_probe``, the
    probe on all genres; with ``cfg.study_teacher_forcing``, each variant trained with plain
    teacher forcing on all genres), each of ``cfg.study_seeds``, every one of the first ``cfg.n_folds``
    folds inside one task (:func:`study_run`).

    Used in: ``thesis study 06_mdlt`` (C13).
    """
    data = {"layout": "aist", "root": cfg.aist_root, "size": cfg.data_size, "seed": cfg.data_seed}
    if cfg.genres is None:
        present = sorted({genre_label(s.genre) for s in _cached_sequences("aist", *data_args(cfg))})
    else:
        present = [genre_label(g) for g in cfg.genres]
    train = {f: getattr(cfg, f) for f in TRAIN_FIELDS}
    probe = {f: getattr(probe_config(cfg), f) for f in TRAIN_FIELDS}
    folds = list(range(cfg.n_folds))
    scopes: list[tuple[str, str | None]] = [(PER_GENRE, g) for g in present]
    if cfg.all_genres:
        scopes.append((ALL_SCOPE, None))
    tasks = []
    for seed in cfg.study_seeds:
        for scope, genre in scopes:
            base = {"data": data, "scope": scope, "genre": genre, "folds": folds, "seed": int(seed)}
            methods = ["baselines", *cfg.variants]
            if cfg.study_probe and scope == ALL_SCOPE:
                methods.append("probe")
            for m in methods:
                run = {**base, "method": m, "cfg": probe if m == "probe" else train}
                tasks.append(Task(study_run, run))
            if cfg.study_teacher_forcing and scope == ALL_SCOPE:
                tf = {"cfg": {**train, "pose_noise": 0.0}, "recipe": "teacher forcing"}
                for m in cfg.variants:
                    tasks.append(Task(study_run, {**base, "method": m, **tf}))
    return tasks


def data_args(cfg: Config) -> tuple[str | None, str, int]:
    """``(root, size, seed)`` of the AIST++-layout data of ``cfg`` (for :func:`load_sequences`)."""
    return cfg.aist_root, cfg.data_size, cfg.data_seed


def study_table_6_2(rows: pd.DataFrame) -> pd.DataFrame:
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


def study_table_6_3() -> pd.DataFrame:
    """Table 6.3 (PhantomDance) of the thesis beside the study: not run (the study is AIST++
    only; the chapter's Table 6.3 runs the PhantomDance layout at smoke scale).

    Used in: MDLT chapter ("Evidence at study scale").
    """
    empty = pd.DataFrame(columns=["variant", "aje_mean"])
    return compare_with_paper(
        "6.3", empty, on=["variant"], value="aje_mean", differs={"data": "not in the C13 study"}
    )


def study_mismatch(rows: pd.DataFrame) -> pd.DataFrame:
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


# ----------------------------------------------------------------------------------------------
# a translator for new music: `thesis mdlt train`, the packaged checkpoint, recorded music


def train_translator(
    cfg: Config, variant: str, out: str | Path, half: bool = True
) -> tuple[Path, pd.DataFrame]:
    """Train one translator on every piece of the AIST++-layout data of ``cfg`` (all genres,
    nothing held out) with ``cfg``'s recipe, and write a model-only checkpoint (with its
    feature scaler) that :func:`thesis_lib.mdlt.dance` reads.

    ``thesis mdlt train`` calls it with the study's recipe (``params/06_mdlt.study.yml``);
    the packaged checkpoint (:func:`thesis_lib.mdlt.translate.packaged_checkpoint`) was made
    with it (see the README).

    Returns:
        ``(checkpoint path, training history)``.

    Used in: ``thesis mdlt train``; MDLT chapter.
    """
    from thesis_lib.mdlt.train import save_checkpoint

    if variant not in _METHOD_INDEX:
        raise ValueError(f"Unknown variant {variant!r}. Valid: {', '.join(_METHOD_INDEX)}.")
    seqs = list(_cached_sequences("aist", *data_args(cfg)))
    model, history, scaler = train_model(variant, seqs, [], dataclasses.replace(cfg, eval_every=0))
    meta = {
        "variant": variant,
        "fps": int(getattr(seqs[0], "fps", 60)),
        "data": f"aist {cfg.aist_root or cfg.data_size} seed {cfg.data_seed}",
        "pieces": len(seqs),
        "iterations": cfg.iterations,
        "recipe": {f: getattr(cfg, f) for f in TRAIN_FIELDS},
    }
    path = save_checkpoint(out, model, scaler, meta, half=half)
    return path, history


def beat_check(
    angles: np.ndarray,
    features: np.ndarray,
    translate: Any,
    shuffles: int = 5,
    seed: int = 0,
    block_s: float = 0.37,
    fps: int = 60,
) -> dict[str, float]:
    """Does a translation move with the beat? Bailando's beat-align score of ``angles`` against
    the music's beats (the beat one-hot of the raw ``features``), beside a shuffled-audio
    control: the same translator (``translate: scaled-or-raw features -> angles``) run on the
    features cut into blocks of ``block_s`` seconds in a random order (the music's sounds kept,
    its beat structure broken), scored against the same beats; ``shuffles`` times. The blocks
    are 0.37 s by default, not a multiple of common beat periods (0.5 s is exactly one beat at
    120 bpm, so such a "control" keeps the beat's timing). See also
    :func:`thesis_lib.mdlt.metrics.beat_alignment_null`: a null that can fail.

    Returns ``beat_align``, ``beat_align_shuffled`` (mean of the controls),
    ``shuffled_max`` and ``beats`` (music beats found).

    Used in: MDLT chapter (recorded music; the packaged checkpoint's test).
    """
    from thesis_lib.mdlt.metrics import beat_alignment

    beats = np.asarray(features)[:, BEAT_COLUMN]
    score = beat_alignment(angles, beats)
    rng = np.random.default_rng(seed)
    n, b = len(features), max(1, int(round(block_s * fps)))
    blocks = [np.arange(i, min(i + b, n)) for i in range(0, n, b)]
    controls = []
    for _ in range(shuffles):
        order = np.concatenate([blocks[i] for i in rng.permutation(len(blocks))])
        controls.append(beat_alignment(translate(np.asarray(features)[order]), beats))
    return {
        "beat_align": float(score),
        "beat_align_shuffled": float(np.nanmean(controls)) if controls else float("nan"),
        "shuffled_max": float(np.nanmax(controls)) if controls else float("nan"),
        "beats": int((beats > 0.5).sum()),
    }


def recorded_music_check(
    audio: str | Path, checkpoint: str | Path | None = None, shuffles: int = 5, seed: int = 0
) -> dict[str, Any]:
    """Translate a recorded music file (decoded at its own sample rate, then resampled to the
    feature rate as any input) with ``checkpoint`` (``None``: the packaged one) and check what a
    robot needs: ``inside_position_limits``, the angles inside the UR3's joint-position limits
    (after the playback mapping of :func:`thesis_lib.ur3.dance.map_dance`); the joint-speed limits
    as ``thesis ur3 check`` applies them (``speed_limit_frames``: frames over a limit,
    ``peak_speed_ratio``: the fastest joint over its limit; ``workspace_frames``); how much each
    joint moves, and the beat alignment
    against a shuffled-audio control (:func:`beat_check`); ``beat_above_control``: the score
    beats every shuffled control (a weak check: busy motion scores high against any beat grid);
    and the null that can fail (:func:`thesis_lib.mdlt.metrics.beat_alignment_null`, columns
    ``null_*``): ``null_p_shift``, the motion's own timing shifted against the music, and
    ``null_follows_beat``.

    Used in: MDLT chapter (recorded music).
    """
    from thesis_lib.mdlt.audio import audio_features, load_audio
    from thesis_lib.mdlt.metrics import beat_alignment_null
    from thesis_lib.mdlt.train import load_checkpoint
    from thesis_lib.mdlt.translate import packaged_checkpoint
    from thesis_lib.ur3.dance import map_dance, prepare_dance
    from thesis_lib.ur3.model import POSITION_LIMITS

    ckpt = Path(checkpoint) if checkpoint is not None else packaged_checkpoint()
    model, scaler, meta = load_checkpoint(ckpt)
    fps = int(meta.get("fps", 60))
    y, sr = load_audio(audio)  # its own sample rate
    raw = audio_features(y, sr=sr, fps=fps)

    def translate(f: np.ndarray) -> np.ndarray:
        with torch.no_grad():
            return np.asarray(model.generate(scaler.transform(f).astype(np.float32)), np.float64)

    angles = translate(raw)
    q = map_dance(angles)
    inside = bool(
        np.all(np.abs(angles) <= np.pi)
        and np.all((q >= POSITION_LIMITS[:, 0]) & (q <= POSITION_LIMITS[:, 1]))
    )
    speeds = prepare_dance(angles, fps, mode="clip").before  # as `thesis ur3 check` reports it
    return {
        "file": Path(audio).name,
        "sample_rate": int(sr),
        "seconds": len(y) / sr,
        "checkpoint": ckpt.name,
        "frames": len(angles),
        "inside_position_limits": inside,
        "speed_limit_frames": len(speeds.speed_frames),
        "peak_speed_ratio": float(speeds.max_speed_ratio),
        "workspace_frames": len(speeds.workspace_frames),
        "max_abs_angle": float(np.abs(angles).max()),
        **{f"std_{j}": float(angles[:, j].std()) for j in range(angles.shape[1])},
        **(beats := beat_check(angles, raw, translate, shuffles=shuffles, seed=seed, fps=fps)),
        "beat_above_control": bool(beats["beat_align"] > beats["shuffled_max"]),
        **{
            f"null_{k}": v
            for k, v in beat_alignment_null(angles, raw[:, BEAT_COLUMN], seed=seed).items()
            if k != "score"
        },
    }


def find_packaged_music(min_seconds: float = 20.0) -> list[Path]:
    """Audio files of at least ``min_seconds`` shipped inside the installed Python packages
    (site-packages: ``.ogg``, ``.flac``, ``.wav``, ``.mp3``), for :func:`recorded_music_check`;
    thesis_lib's own recording is left out (:func:`recorded_music_table` adds it first).
    Nothing is downloaded; on this project's environment the list is empty.

    Used in: MDLT chapter (recorded music).
    """
    import site

    import soundfile as sf

    from thesis_lib.mdlt.translate import ASSETS

    found = []
    roots = {Path(p) for p in site.getsitepackages() + [site.getusersitepackages()]}
    for root in sorted(r for r in roots if r.is_dir()):
        for ext in ("ogg", "flac", "wav", "mp3"):
            for p in root.rglob(f"*.{ext}"):
                if p.resolve().parent == ASSETS:  # thesis_lib's own (a non-editable install)
                    continue
                try:
                    if sf.info(str(p)).duration >= min_seconds:
                        found.append(p)
                except Exception:  # not readable by libsndfile
                    continue
    return sorted(found)


def recorded_music_table(checkpoint: str | Path | None = None) -> pd.DataFrame:
    """:func:`recorded_music_check` of the recording shipped with the package
    (:func:`thesis_lib.mdlt.translate.packaged_recording`, with its credit) and of every
    :func:`find_packaged_music` file found in the installed packages: one row each.

    Used in: MDLT chapter (recorded music).
    """
    from thesis_lib.mdlt.translate import PACKAGED_RECORDING_CREDIT, packaged_recording

    rows = [{**recorded_music_check(packaged_recording(), checkpoint), **PACKAGED_RECORDING_CREDIT}]
    rows += [recorded_music_check(f, checkpoint) for f in find_packaged_music()]
    return pd.DataFrame(rows)


def run_phantomdance_fps(cfg: Config, summary_6_3: pd.DataFrame) -> pd.DataFrame:
    """Table 6.3's AJE at the thesis's 60 fps (``summary_6_3``, this run) beside the same folds
    re-run at the authors' 30 fps (``pd_fps=30``, everything else equal): rows method, columns
    fps (when ``cfg`` already runs at 30: 60 is the re-run).

    Used in: MDLT chapter (the two undocumented choices).
    """
    other = 30 if cfg.phantom_fps() == 60 else 60
    rerun = summarize(run_table_6_3(dataclasses.replace(cfg, pd_fps=other)).rows)
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
    from thesis_lib.mdlt.models import MDLTMamba
    from thesis_lib.mdlt.train import load_checkpoint

    out: list[dict[str, Any]] = []
    if not cfg.all_genres:
        return pd.DataFrame(out)
    seqs = _cached_sequences("aist", *data_args(cfg))
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
