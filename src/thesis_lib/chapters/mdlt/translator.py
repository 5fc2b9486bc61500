"""A translator for new music: ``thesis mdlt train``'s training on every piece
(:func:`train_translator`, the packaged checkpoint), and the checks of a translation of recorded
music (inside the UR3's limits, moving with the beat against a shuffled-audio control).

Used in: ``thesis mdlt train``; MDLT chapter (recorded music).
"""

from __future__ import annotations

import dataclasses
import site
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
import torch

from thesis_lib.mdlt.audio import audio_features, load_audio
from thesis_lib.mdlt.metrics import beat_alignment, beat_alignment_null
from thesis_lib.mdlt.train import load_checkpoint, save_checkpoint
from thesis_lib.mdlt.translate import (
    ASSETS,
    PACKAGED_RECORDING_CREDIT,
    packaged_checkpoint,
    packaged_recording,
)
from thesis_lib.ur3.dance import map_dance, prepare_dance
from thesis_lib.ur3.model import POSITION_LIMITS

from . import data
from .config import TRAIN_FIELDS, Config
from .data import BEAT_COLUMN
from .study import METHOD_INDEX
from .tasks import train_model


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
    if variant not in METHOD_INDEX:
        raise ValueError(f"Unknown variant {variant!r}. Valid: {', '.join(METHOD_INDEX)}.")
    seqs = list(data.cached_sequences("aist", *data.data_args(cfg)))
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
    import soundfile as sf

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
    rows = [{**recorded_music_check(packaged_recording(), checkpoint), **PACKAGED_RECORDING_CREDIT}]
    rows += [recorded_music_check(f, checkpoint) for f in find_packaged_music()]
    return pd.DataFrame(rows)
