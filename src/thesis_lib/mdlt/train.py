"""Training MDLT with the project's one trainer: windows of music-dance pairs, checkpoints.

:class:`DanceWindows` samples training windows as thesis 6.4.1 describes (a random song, a
random frame ``t``, the frames ``max(0, t-K+1) .. t`` right-padded to K) and hands them to
:class:`~thesis_lib.seq.trainer.Trainer` (AdamW, warm-up, gradient clipping, its own dropout
RNG, tqdm, atomic checkpoints, exact resume). :class:`MDLTTrainer` adds what the ``dance``
command needs to the checkpoint: the feature scaler and the model config, so one file both
resumes training and translates new music (:func:`load_checkpoint`).

Used in: MDLT chapter (thesis 6.4, 6.5).
"""

from __future__ import annotations

import os
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np
import torch

from thesis_lib.mdlt.audio import FeatureScaler
from thesis_lib.mdlt.models import MDLTConfig, MDLTMamba, MDLTTransformer, build_model
from thesis_lib.seq.trainer import TrainConfig, Trainer

__all__ = [
    "DanceBatch",
    "DanceWindows",
    "MDLTTrainer",
    "check_device",
    "load_checkpoint",
    "save_checkpoint",
]


@dataclass
class DanceBatch:
    """A batch of windows (numpy); :meth:`to_torch` gives the model's input dict.

    ``audio (B, K, 438)``, ``poses_in (B, K, 4)`` (right-shifted, start pose 0), ``poses (B, K, 4)``
    (targets), ``timesteps (B, K)`` (frame index in the song + 1, 0 at padding), ``mask (B, K)``
    (``True`` = real frame).
    """

    audio: np.ndarray
    poses_in: np.ndarray
    poses: np.ndarray
    timesteps: np.ndarray
    mask: np.ndarray
    subgoals: None = None  # the Trainer's batch_to_torch checks for HDT sub-goals

    def to_torch(self, device: str | torch.device = "cpu") -> dict[str, torch.Tensor]:
        return {
            k: torch.from_numpy(getattr(self, k)).to(device)
            for k in ("audio", "poses_in", "poses", "timesteps", "mask")
        }


class DanceWindows:
    """Training windows over music-dance pairs, with its own random generator.

    Used in: MDLT chapter (thesis 6.4).

    Args:
        features: Scaled audio features per song, each ``(T_i, 438)``.
        angles: Joint angles per song, each ``(T_i, 4)`` radians, frame-aligned with ``features``.
        K: Window length.
        variant: ``"transformer"``: the decoder input always starts with the zero start pose
            (as at inference, which re-windows every frame); ``"mamba"``: the previous true pose
            (zero only at the song's start), as the recurrent inference feeds its previous
            output.
        seed: Seed of the sampling generator.
        single_frame: The authors' MDLT-M code trained on single frames padded to K (a bug):
            windows of length 1 (``paper_compat``).
        pose_noise: Std (radians) of Gaussian noise added to the input poses (not the targets)
            of training windows. Not in the thesis: teacher forcing alone teaches the model to
            copy the previous pose, which drifts when it feeds on its own predictions at
            inference (exposure bias); 0 = the thesis's training.

    Example:
        >>> w = DanceWindows([np.zeros((5, 438), np.float32)], [np.ones((5, 4), np.float32)], K=3)
        >>> b = w.sample(2)
        >>> b.audio.shape, b.poses_in[0, 0].tolist(), bool(b.mask[:, 0].all())
        ((2, 3, 438), [0.0, 0.0, 0.0, 0.0], True)
    """

    prepend_zero_action = True  # the zero start pose (the Trainer checks this name)

    def __init__(
        self,
        features: Sequence[np.ndarray],
        angles: Sequence[np.ndarray],
        K: int,
        variant: str = "transformer",
        seed: int = 0,
        single_frame: bool = False,
        pose_noise: float = 0.0,
    ) -> None:
        if len(features) != len(angles) or len(features) == 0:
            raise ValueError(
                f"Expect as many feature as angle sequences (>= 1), got {len(features)} and {len(angles)}."
            )
        for i, (f, a) in enumerate(zip(features, angles)):
            if f.ndim != 2 or a.ndim != 2 or len(f) != len(a) or len(f) == 0:
                raise ValueError(
                    f"Song {i}: expect features (T, D) and angles (T, J) of the same T >= 1, got "
                    f"{f.shape} and {a.shape}."
                )
            if not (np.isfinite(f).all() and np.isfinite(a).all()):
                raise ValueError(
                    f"Song {i}: features or angles contain NaN/inf; drop or repair those frames first."
                )
        if variant not in ("transformer", "mamba"):
            raise ValueError(f"Unknown variant {variant!r}. Valid: transformer, mamba.")
        if pose_noise < 0:
            raise ValueError(f"Expect pose_noise >= 0 (radians), actually: {pose_noise!r}.")
        self.K, self.variant, self.single_frame, self.pose_noise = (
            int(K),
            variant,
            bool(single_frame),
            float(pose_noise),
        )
        self.lengths = np.array([len(f) for f in features])
        self.offsets = np.concatenate([[0], np.cumsum(self.lengths)[:-1]])
        self.states = np.concatenate(features).astype(np.float32)  # (N, 438) all songs' frames
        self.actions = np.concatenate(angles).astype(np.float32)  # (N, 4)
        self.subgoals = None
        self.rng = np.random.default_rng(seed)

    def __len__(self) -> int:
        return int(self.lengths.sum())

    def sample(self, batch_size: int) -> DanceBatch:
        """``batch_size`` windows: a song uniformly, then a frame ``t`` uniformly in it."""
        K, D, J = self.K, self.states.shape[1], self.actions.shape[1]
        songs = self.rng.integers(len(self.lengths), size=batch_size)
        ends = (self.rng.random(batch_size) * self.lengths[songs]).astype(np.int64)  # t in [0, T-1]
        audio = np.zeros((batch_size, K, D), np.float32)
        poses_in = np.zeros((batch_size, K, J), np.float32)
        poses = np.zeros((batch_size, K, J), np.float32)
        times = np.zeros((batch_size, K), np.int64)
        mask = np.zeros((batch_size, K), bool)
        for b, (song, t) in enumerate(zip(songs, ends)):
            s = t if self.single_frame else max(0, t - K + 1)
            n, off = t - s + 1, self.offsets[song]
            audio[b, :n] = self.states[off + s : off + t + 1]
            poses[b, :n] = self.actions[off + s : off + t + 1]
            poses_in[b, 1:n] = self.actions[off + s : off + t]
            if self.variant == "mamba" and s > 0 and not self.single_frame:
                poses_in[b, 0] = self.actions[off + s - 1]
            times[b, :n] = np.arange(s, t + 1) + 1
            mask[b, :n] = True
        if (
            self.pose_noise > 0
        ):  # only where a real pose is fed (not the zero start pose, not padding)
            real = np.zeros((batch_size, K), bool)
            real[:, 1:] = mask[:, 1:]
            real[:, 0] = poses_in[:, 0].any(-1)
            noise = self.rng.normal(0.0, self.pose_noise, size=poses_in.shape).astype(np.float32)
            poses_in = poses_in + noise * real[..., None]
        return DanceBatch(audio, poses_in, poses, times, mask)


def _to_safe(obj: Any) -> Any:
    """numpy arrays -> tensors, recursively (``torch.load(weights_only=True)`` refuses numpy)."""
    if isinstance(obj, np.ndarray):
        return torch.from_numpy(np.ascontiguousarray(obj))
    if isinstance(obj, np.generic):
        return obj.item()
    if isinstance(obj, dict):
        return {k: _to_safe(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return type(obj)(_to_safe(v) for v in obj)
    return obj


def _from_safe(obj: Any) -> Any:
    if torch.is_tensor(obj):
        return obj.numpy()
    if isinstance(obj, dict):
        return {k: _from_safe(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return type(obj)(_from_safe(v) for v in obj)
    return obj


class MDLTTrainer(Trainer):
    """The project's :class:`~thesis_lib.seq.trainer.Trainer`, whose checkpoints also carry the
    feature scaler and metadata, so :func:`load_checkpoint` can translate new music with them.

    Used in: MDLT chapter (thesis 6.5).

    Args:
        model, dataset, config, eval_fn: as :class:`Trainer`.
        scaler: The fitted feature scaler (anything with ``state_dict()``; the data side's
            ``FeatureScaler``).
        meta: Extra JSON-able facts to store (fps, training songs, ...).
    """

    def __init__(
        self,
        model,
        dataset,
        config: TrainConfig | None = None,
        eval_fn: Callable[[torch.nn.Module], Any] | None = None,
        scaler: Any = None,
        meta: dict[str, Any] | None = None,
    ) -> None:
        self.scaler, self.meta = scaler, dict(meta or {})
        super().__init__(model, dataset, config, eval_fn)

    def state_dict(self) -> dict[str, Any]:
        state = super().state_dict()
        state["scaler"] = _to_safe(self.scaler.state_dict()) if self.scaler is not None else None
        state["meta"] = _to_safe(self.meta)
        return state


def save_checkpoint(
    path: str | Path,
    model: MDLTTransformer | MDLTMamba,
    scaler: Any = None,
    meta: dict | None = None,
    half: bool = False,
) -> Path:
    """Write a model-only checkpoint that :func:`load_checkpoint` (and ``thesis mdlt dance``) reads.

    ``half``: store the floating-point weights as float16 (half the file; loading casts them
    back to the model's float32), as the packaged checkpoint does.

    Used in: MDLT chapter (thesis 6.5).
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    state = model.state_dict()
    if half:
        state = {k: v.half() if v.is_floating_point() else v for k, v in state.items()}
    torch.save(
        {
            "model_class": type(model).__name__,
            "model_config": asdict(model.config),
            "model": state,
            "scaler": _to_safe(scaler.state_dict()) if scaler is not None else None,
            "meta": _to_safe(dict(meta or {})),
        },
        path,
    )
    return path


def check_device(device: str | torch.device) -> torch.device:
    """``device`` as a ``torch.device``, or a ``ValueError`` naming it when it is not a device
    name or not available on this machine (``cuda`` without a CUDA GPU or build).

    Used in: ``thesis mdlt dance``, :func:`load_checkpoint`.
    """
    try:
        dev = torch.device(device)
    except (RuntimeError, TypeError, ValueError) as err:
        raise ValueError(
            f"Expect `device` to be a torch device such as 'cpu' or 'cuda', actually: {device!r} "
            f"({err})."
        ) from None
    if dev.type == "cuda":
        n = torch.cuda.device_count() if torch.cuda.is_available() else 0
        if n == 0:
            raise ValueError(
                f"Expect `device` {str(device)!r} to be available, actually: torch sees no CUDA "
                f"GPU here (torch {torch.__version__}, CUDA build: {torch.version.cuda}). "
                "Use --device cpu."
            )
        if dev.index is not None and dev.index >= n:
            raise ValueError(
                f"Expect `device` {str(device)!r} to be available, actually: torch sees {n} "
                f"CUDA GPU(s) (cuda:0 … cuda:{n - 1})."
            )
    return dev


def load_checkpoint(
    path: str | os.PathLike[str], device: str = "cpu"
) -> tuple[MDLTTransformer | MDLTMamba, Any, dict[str, Any]]:
    """Rebuild ``(model in eval mode, feature scaler, meta)`` from a checkpoint.

    Reads both :class:`MDLTTrainer` checkpoints and :func:`save_checkpoint` files.

    Used in: MDLT chapter (thesis 6.5); ``thesis mdlt dance``.

    Raises:
        FileNotFoundError: No file at ``path``.
        ValueError: ``device`` is not usable here (checked first), not an MDLT checkpoint, or
            one without a feature scaler.
    """
    check_device(device)  # a missing GPU is not the checkpoint's fault
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(
            f"No checkpoint at '{path}'. Train one with 'thesis mdlt train --out {path}' "
            "(thesis_lib.chapters.mdlt.train_translator), or leave out --checkpoint for the "
            "packaged one."
        )
    try:
        ckpt = torch.load(path, map_location=device, weights_only=True)
    except Exception as err:  # not a torch file
        raise ValueError(
            f"'{path}' is not a readable torch checkpoint ({type(err).__name__}: {err})."
        ) from err
    if not isinstance(ckpt, dict) or ckpt.get("model_class") not in (
        "MDLTTransformer",
        "MDLTMamba",
    ):
        got = ckpt.get("model_class") if isinstance(ckpt, dict) else type(ckpt).__name__
        raise ValueError(
            f"'{path}' is not an MDLT checkpoint (it holds {got!r}; expected MDLTTransformer or MDLTMamba)."
        )
    if ckpt.get("scaler") is None:
        raise ValueError(
            f"Checkpoint '{path}' carries no feature scaler; new music cannot be scaled like the "
            "training data. Save it with MDLTTrainer(scaler=...) or save_checkpoint(..., scaler=...)."
        )
    cfg = dict(ckpt["model_config"])
    model = build_model(MDLTConfig(**cfg)).to(device)
    model.load_state_dict(ckpt["model"])
    model.eval()

    scaler = FeatureScaler.from_state_dict(_from_safe(ckpt["scaler"]))
    return model, scaler, _from_safe(ckpt.get("meta") or {})
