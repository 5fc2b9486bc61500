"""MDLT-T and MDLT-M: music -> UR3 joint angles as sequence-to-sequence translation (thesis 6.4).

Both read windows of 438-d audio features (scaled to [0.1, 0.9]) and the right-shifted joint
angles (a zero start pose first), and predict the next four joint angles as ``tanh(.) * pi``,
trained with an L2 loss on real (non-padded) frames.

* :class:`MDLTTransformer` (MDLT-T, 6.4.1): ``torch.nn.Transformer`` (an encoder-decoder with
  cross-attention; the project's GPT :class:`~thesis_lib.seq.attention_ops.Block` is decoder-only,
  so it does not fit). Encoder = the last K audio frames with a padding mask; decoder =
  ``[zero start pose, a_s .. a_{t-1}]`` with a causal and a padding mask. Inputs are
  ``Linear * sqrt(d)`` plus a learned embedding of each frame's index in the song (the
  thesis's vocabulary: longest song + 1). Inference is autoregressive over the whole song:
  each frame re-windows the last K audio frames and the last K-1 predictions.
* :class:`MDLTMamba` (MDLT-M, 6.4.2): per frame one token ``audio_emb(f_t) + pose_emb(a_{t-1})``
  through the project's :class:`~thesis_lib.seq.mamba.Mamba` stack; no positions (the
  recurrence orders the tokens), no masks (causal by construction; right-padding does not
  change real outputs). Inference is recurrent (:meth:`Mamba.step`), O(1) per frame, over the
  whole song.

Mask convention: a boolean ``mask`` in a batch is ``True`` at real frames (the project's
convention). ``nn.Transformer``'s ``*_key_padding_mask`` wants the opposite (``True`` = pad); the
conversion happens in one place, :meth:`MDLTTransformer._encode`.

Used in: MDLT chapter (thesis 6.4).
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass
from typing import Literal

import numpy as np
import torch
import torch.nn as nn

from thesis_lib.seq.dropout import Dropout
from thesis_lib.seq.mamba import Mamba, MambaConfig, ScanBackend
from thesis_lib.seq.models import SeqOutput, masked_mse

__all__ = [
    "AUDIO_DIM",
    "N_JOINTS",
    "MDLTConfig",
    "MDLTMamba",
    "MDLTTransformer",
    "build_model",
    "init_output_at",
    "MODEL_VARIANTS",
]

AUDIO_DIM = 438
"""Size of the audio feature vector (thesis 6.3.2)."""
N_JOINTS = 4
"""UR3 joints driven by the dance (thesis 6.3.3)."""
MODEL_VARIANTS = ("transformer", "mamba")

Tensors = dict[str, torch.Tensor]
SongInput = np.ndarray | torch.Tensor | list
"""One song's scaled features ``(T, 438)``, or a list of songs."""


@dataclass
class MDLTConfig:
    """Architecture of an MDLT model; defaults are the thesis's MDLT-T (6.4.1, 6.5.1).

    ``state_dim``/``act_dim``/``K`` carry the names :class:`~thesis_lib.seq.trainer.Trainer`
    checks against the data set. MDLT-M in the thesis: ``variant="mamba", K=120``.

    Used in: MDLT chapter (thesis 6.4).
    """

    variant: Literal["transformer", "mamba"] = "transformer"
    """``"transformer"`` (MDLT-T) or ``"mamba"`` (MDLT-M)."""
    state_dim: int = AUDIO_DIM
    """Audio feature size (438)."""
    act_dim: int = N_JOINTS
    """Joint angles predicted per frame (4)."""
    K: int = 20
    """Window length in frames: 20 for MDLT-T, 120 for MDLT-M (thesis 6.5.1)."""
    d_model: int = 128
    """Embedding size."""
    n_layers: int = 6
    """Encoder and decoder layers (MDLT-T) or Mamba blocks (MDLT-M)."""
    n_heads: int = 8
    """Attention heads (MDLT-T)."""
    d_ff: int = 2048
    """Feed-forward width (MDLT-T; MDLT-M only with ``gated_mlp``)."""
    dropout: float = 0.1
    """Dropout (MDLT-T: inside the Transformer; MDLT-M: on the token embeddings)."""
    max_timestep: int = 8192
    """MDLT-T's time-step vocabulary (the thesis: the longest song + 1). A longer song is
    translated with a sliding window of time steps that restarts inside the table, with a
    warning (:meth:`MDLTTransformer.window_timesteps`)."""
    pose_input: bool = True
    """MDLT-M reads the previous pose as the thesis text says (6.4.2). ``False``: audio only,
    as the authors' MDLT-M code (``Linear(438->d) -> Mamba -> Linear(d->4)``)."""
    gated_mlp: bool = False
    """MDLT-M: add a gated MLP of width ``d_ff`` after each Mamba mixer. The thesis lists
    "feed-forward layers with 2048 neurons" for MDLT-M too; Mamba-1 blocks have none."""
    d_state: int = 16
    """MDLT-M: SSM state size per channel."""

    def __post_init__(self) -> None:
        if self.variant not in MODEL_VARIANTS:
            raise ValueError(
                f"Unknown MDLT variant {self.variant!r}. Valid: {', '.join(MODEL_VARIANTS)}."
            )
        for name in (
            "state_dim",
            "act_dim",
            "K",
            "d_model",
            "n_layers",
            "n_heads",
            "d_ff",
            "max_timestep",
            "d_state",
        ):
            value = getattr(self, name)
            if not isinstance(value, (int, np.integer)) or isinstance(value, bool) or value <= 0:
                raise ValueError(f"Expect `{name}` to be a positive int, actually: {value!r}.")
        if self.variant == "transformer" and self.d_model % self.n_heads:
            raise ValueError(
                f"Expect d_model ({self.d_model}) divisible by n_heads ({self.n_heads})."
            )
        if not 0.0 <= self.dropout < 1.0:
            raise ValueError(f"Expect 0 <= dropout < 1, actually: {self.dropout!r}.")


def _check_batch(model: MDLTTransformer | MDLTMamba, batch: Tensors) -> tuple[int, int]:
    """Check the batch keys and shapes against the config; return ``(B, L)``."""
    cfg = model.config
    for key in ("audio", "poses_in", "mask"):
        if key not in batch:
            raise ValueError(
                f"{type(model).__name__} needs batch['{key}'] (have: {sorted(batch)})."
            )
    audio = batch["audio"]
    if audio.ndim != 3 or audio.shape[-1] != cfg.state_dim:
        raise ValueError(
            f"Expect audio of shape (B, L, {cfg.state_dim}), got {tuple(audio.shape)}."
        )
    B, L, _ = audio.shape
    if batch["poses_in"].shape != (B, L, cfg.act_dim):
        raise ValueError(
            f"Expect poses_in of shape {(B, L, cfg.act_dim)}, got {tuple(batch['poses_in'].shape)}."
        )
    if batch["mask"].shape != (B, L):
        raise ValueError(f"Expect mask of shape {(B, L)}, got {tuple(batch['mask'].shape)}.")
    return B, L


def _head(d_model: int, act_dim: int) -> nn.Linear:
    return nn.Linear(d_model, act_dim)


def init_output_at(model: MDLTTransformer | MDLTMamba, pose: np.ndarray) -> None:
    """Start the output head at ``pose`` (4,): weights scaled by 0.1, bias ``atanh(pose / pi)``.

    The output is ``tanh(head(h)) * pi``; from the default initialisation it starts near the
    zero pose, far from where dancers' arms are, and a short run spends its updates getting to
    the mean pose before it learns anything about the music. Starting there (the usual
    initialisation of a regression head at the target mean) leaves the updates for the music.
    """
    pose = np.asarray(pose, dtype=np.float64).reshape(-1)
    if pose.shape != (model.config.act_dim,) or not np.isfinite(pose).all():
        raise ValueError(
            f"Expect a finite pose of shape ({model.config.act_dim},), got {pose.shape}."
        )
    with torch.no_grad():
        model.head.weight.mul_(0.1)  # small, not zero: the output still depends on the input
        model.head.bias.copy_(torch.as_tensor(np.arctanh(np.clip(pose / math.pi, -0.99, 0.99))))


def _loss(
    pred: torch.Tensor, targets: Tensors | None, mask: torch.Tensor
) -> tuple[torch.Tensor | None, dict | None]:
    if targets is None:
        return None, None
    loss = masked_mse(pred, targets["poses"], mask)  # L2 on real frames (thesis 6.4.1)
    return loss, {"pose": loss.item()}


# ----------------------------------------------------------------------------------------------
# MDLT-T


class MDLTTransformer(nn.Module):
    """MDLT-T: encoder-decoder Transformer translating audio windows into joint angles (6.4.1).

    Batch (``B`` windows of ``L <= K`` frames, right-padded):
    ``audio (B, L, 438)``, ``poses_in (B, L, 4)`` = ``[0, a_s, .., a_{t-1}]``,
    ``timesteps (B, L)`` long (frame index in the song + 1; 0 at padding), ``mask (B, L)``
    bool (``True`` = real frame); targets ``poses (B, L, 4)`` = ``a_s .. a_t``.

    Used in: MDLT chapter (thesis 6.4.1).

    Example:
        >>> _ = torch.manual_seed(0)
        >>> m = MDLTTransformer(MDLTConfig(K=4, d_model=16, n_layers=1, n_heads=2, d_ff=32)).eval()
        >>> angles = m.generate(np.random.rand(10, 438).astype(np.float32))
        >>> angles.shape, bool(np.abs(angles).max() <= np.pi)
        ((10, 4), True)
    """

    def __init__(self, config: MDLTConfig) -> None:
        super().__init__()
        if config.variant != "transformer":
            raise ValueError(
                f"MDLTTransformer needs variant='transformer', got {config.variant!r}."
            )
        self.config = c = config
        self.audio_emb = nn.Linear(c.state_dim, c.d_model)
        self.pose_emb = nn.Linear(c.act_dim, c.d_model)
        # index 0 = padding, 1..max_timestep = frames 0..max_timestep-1 of a song
        self.time_emb = nn.Embedding(c.max_timestep + 1, c.d_model)
        self.transformer = nn.Transformer(
            d_model=c.d_model,
            nhead=c.n_heads,
            num_encoder_layers=c.n_layers,
            num_decoder_layers=c.n_layers,
            dim_feedforward=c.d_ff,
            dropout=c.dropout,
            batch_first=True,
        )
        # the nested-tensor fast path warns (prototype API) and changes nothing in the results
        self.transformer.encoder.use_nested_tensor = False
        self.head = _head(c.d_model, c.act_dim)

    def timesteps(self, frame_index: torch.Tensor) -> torch.Tensor:
        """Embedding indices of song frames ``0, 1, ..``: ``index + 1``, capped at ``max_timestep``.

        The authors used 0-based steps in training and 1-based ones at inference (a bug); here
        both are 1-based. In a training batch frames past the vocabulary share its last entry
        rather than failing; :meth:`generate` keeps whole songs inside the table with
        :meth:`window_timesteps` instead.
        """
        return (frame_index + 1).clamp(max=self.config.max_timestep)

    def window_timesteps(self, idx: torch.Tensor, valid: torch.Tensor) -> torch.Tensor:
        """Embedding indices ``(T, K)`` of the inference windows of a ``T``-frame song.

        ``idx``/``valid``: each frame's window ``s..t`` left-aligned in ``K`` slots (song frame
        index, real slot). A window inside the table (``t < max_timestep``) gets
        :meth:`timesteps` (``index + 1``), as in training. A window past it has its steps
        shifted back by a multiple of ``P = max_timestep - K`` frames: they restart every
        ``P`` frames and stay consecutive and inside ``1..max_timestep - 1``, the steps a
        model whose longest training song set ``max_timestep`` (longest + 1) was trained on;
        its last entry is never trained. (Capping at that last entry, as :meth:`timesteps`
        does, gives every slot of every later window that one untrained embedding, and a
        trained MDLT-T then nearly stops moving.) Padding slots get 0.

        Example:
            >>> cfg = MDLTConfig(K=3, max_timestep=5, d_model=8, n_layers=1, n_heads=2, d_ff=8)
            >>> m = MDLTTransformer(cfg)
            >>> idx, valid = _window_index(8, 3, "cpu")
            >>> m.window_timesteps(idx, valid).tolist()
            [[1, 0, 0], [1, 2, 0], [1, 2, 3], [2, 3, 4], [3, 4, 5], [2, 3, 4], [1, 2, 3], [2, 3, 4]]
        """
        table = self.config.max_timestep
        period = max(1, table - self.config.K)
        start = idx[:, :1]  # the window's first frame (slot 0 is always real)
        end = torch.where(valid, idx, -1).amax(dim=1, keepdim=True)  # its last: the frame t
        shift = torch.where(end >= table, (start // period) * period, 0)
        return torch.where(valid, self.timesteps(idx - shift), torch.zeros_like(idx))

    def _encode(self, audio: torch.Tensor, times: torch.Tensor, mask: torch.Tensor) -> torch.Tensor:
        scale = math.sqrt(self.config.d_model)
        src = self.audio_emb(audio) * scale + self.time_emb(times)  # (B, L, d)
        # nn.Transformer: key_padding_mask True = ignore, the opposite of our mask
        return self.transformer.encoder(src, src_key_padding_mask=~mask)

    def _decode(
        self,
        memory: torch.Tensor,
        mem_mask: torch.Tensor,
        poses_in: torch.Tensor,
        times: torch.Tensor,
        mask: torch.Tensor,
    ) -> torch.Tensor:
        L = poses_in.shape[1]
        scale = math.sqrt(self.config.d_model)
        tgt = self.pose_emb(poses_in) * scale + self.time_emb(times)  # (B, L, d)
        causal = torch.ones(L, L, dtype=torch.bool, device=tgt.device).triu(
            1
        )  # True = may NOT attend (nn.Transformer)
        h = self.transformer.decoder(
            tgt,
            memory,
            tgt_mask=causal,
            tgt_is_causal=True,
            tgt_key_padding_mask=~mask,
            memory_key_padding_mask=~mem_mask,
        )
        return torch.tanh(self.head(h)) * math.pi  # (B, L, 4) in (-pi, pi)

    def forward(self, batch: Tensors, targets: Tensors | None = None) -> SeqOutput:
        """Predict ``a_s .. a_t`` for each window (teacher forcing); the loss with ``targets``."""
        B, L = _check_batch(self, batch)
        if L > self.config.K:
            raise ValueError(f"Windows of {L} frames exceed the model's K={self.config.K}.")
        mask = batch["mask"].bool()
        times = batch.get("timesteps")
        if times is None:
            raise ValueError(
                "MDLTTransformer needs batch['timesteps'] (frame index in the song + 1; 0 at padding)."
            )
        times = times.long().clamp(
            0, self.config.max_timestep
        )  # songs past the vocabulary share its last entry
        memory = self._encode(batch["audio"], times, mask)
        pred = self._decode(memory, mask, batch["poses_in"], times, mask)
        loss, losses = _loss(pred, targets, mask)
        return SeqOutput(actions=pred, loss=loss, losses=losses)

    @torch.no_grad()
    def generate(
        self, features: SongInput, chunk: int = 256, progress: bool = False
    ) -> np.ndarray | list[np.ndarray]:
        """Translate whole songs autoregressively: scaled ``features (T, 438)`` -> angles ``(T, 4)``.

        Frame ``t`` sees the audio frames ``max(0, t-K+1) .. t`` and the decoder input
        ``[0, â_s .. â_{t-1}]`` of its own earlier predictions. The encoder memories of all
        windows are computed first (they do not depend on the predictions), in chunks. A list
        of songs is translated as one batch (a list comes back).

        A song longer than the time-step table (``max_timestep`` frames) warns once and is
        translated with a sliding window of time steps (:meth:`window_timesteps`).
        """
        from tqdm.auto import tqdm

        songs, single = _as_songs(features, self.config.state_dim)
        device = next(self.parameters()).device
        K, d, n_songs = self.config.K, self.config.act_dim, len(songs)
        lengths = [len(x) for x in songs]
        T = max(lengths)
        idx, valid = _window_index(
            T, K, device
        )  # (T, K) frame index of each window slot, (T, K) real?
        if T > self.config.max_timestep:
            warnings.warn(
                f"MDLT-T's time-step table has {self.config.max_timestep} frames (max_timestep: "
                f"its longest training song + 1) and this song {T}: past frame "
                f"{self.config.max_timestep} its windows' time steps restart every "
                f"{max(1, self.config.max_timestep - K)} frames (a sliding window); train "
                f"with longer songs to cover it.",
                stacklevel=3,  # the caller of generate (under torch.no_grad's wrapper)
            )
        times = self.window_timesteps(idx, valid)
        x = torch.zeros(n_songs, T, self.config.state_dim, device=device)
        for i, song in enumerate(songs):
            x[i, : lengths[i]] = song.to(device)
        preds = torch.zeros(n_songs, T, d, device=device)
        bar = tqdm(total=T, disable=not progress, desc="MDLT-T")
        for lo in range(0, T, chunk):  # encoder memories of `chunk` frames' windows at a time
            hi = min(T, lo + chunk)
            m = valid[lo:hi].repeat(n_songs, 1)  # (n_songs * c, K)
            audio = (x[:, idx[lo:hi]] * valid[lo:hi, :, None]).flatten(
                0, 1
            )  # (n_songs * c, K, 438)
            memory = self._encode(audio, times[lo:hi].repeat(n_songs, 1), m).unflatten(
                0, (n_songs, hi - lo)
            )
            for t in range(lo, hi):
                n = min(t + 1, K)  # frames in this window (the same for every song)
                s = t - n + 1
                poses_in = torch.zeros(n_songs, n, d, device=device)
                if n > 1:
                    poses_in[:, 1:] = preds[:, s:t]
                vm = valid[t : t + 1].expand(n_songs, K)
                out = self._decode(
                    memory[:, t - lo],
                    vm,
                    poses_in,
                    times[t : t + 1, :n].expand(n_songs, n),
                    vm[:, :n],
                )
                preds[:, t] = out[:, n - 1]
                bar.update(1)
        bar.close()
        songs_out = [preds[i, : lengths[i]].cpu().numpy() for i in range(n_songs)]
        return songs_out[0] if single else songs_out


def _window_index(T: int, K: int, device) -> tuple[torch.Tensor, torch.Tensor]:
    """For each frame ``t``: the song indices of its window ``s..t`` left-aligned in K slots."""
    t = torch.arange(T, device=device)[:, None]
    s = (t - K + 1).clamp(min=0)
    idx = s + torch.arange(K, device=device)[None, :]  # (T, K)
    valid = idx <= t
    return torch.where(valid, idx, torch.zeros_like(idx)), valid


def _as_songs(features, dim: int) -> tuple[list[torch.Tensor], bool]:
    """One song ``(T, dim)`` or a list of them -> list of float tensors, and whether it was one."""
    single = not isinstance(features, (list, tuple))
    items = [features] if single else list(features)
    if not items:
        raise ValueError("Expect at least one song, got an empty list.")
    songs = []
    for x in items:
        x = torch.as_tensor(x if torch.is_tensor(x) else np.asarray(x, dtype=np.float32)).float()
        if x.ndim != 2 or x.shape[1] != dim or x.shape[0] == 0:
            raise ValueError(
                f"Expect song features of shape (T, {dim}) with T >= 1, got {tuple(x.shape)}."
            )
        if not torch.isfinite(x).all():
            raise ValueError(
                "Song features contain NaN or inf; check the audio file and the feature scaler."
            )
        songs.append(x)
    return songs, single


# ----------------------------------------------------------------------------------------------
# MDLT-M


class MDLTMamba(nn.Module):
    """MDLT-M: the project's Mamba stack over per-frame tokens (6.4.2).

    Token ``t`` = ``audio_emb(f_t) + pose_emb(a_{t-1})`` (``a_{-1}`` = 0, the start pose; with
    ``pose_input=False`` only the audio), then ``Mamba -> Linear -> tanh * pi``. Batch keys as
    :class:`MDLTTransformer` (``timesteps`` unused).

    Used in: MDLT chapter (thesis 6.4.2).

    Example:
        >>> _ = torch.manual_seed(0)
        >>> m = MDLTMamba(MDLTConfig(variant="mamba", K=8, d_model=16, n_layers=1)).eval()
        >>> m.generate(np.random.rand(10, 438).astype(np.float32)).shape
        (10, 4)
    """

    def __init__(self, config: MDLTConfig, scan_backend: ScanBackend = "auto") -> None:
        super().__init__()
        if config.variant != "mamba":
            raise ValueError(f"MDLTMamba needs variant='mamba', got {config.variant!r}.")
        self.config = c = config
        self.audio_emb = nn.Linear(c.state_dim, c.d_model)
        self.pose_emb = nn.Linear(c.act_dim, c.d_model) if c.pose_input else None
        self.drop = Dropout(c.dropout)
        self.backbone = Mamba(
            MambaConfig(
                d_model=c.d_model,
                n_layers=c.n_layers,
                d_state=c.d_state,
                gated_mlp=c.gated_mlp,
                mlp_hidden=c.d_ff,
            ),
            scan_backend=scan_backend,
        )
        self.head = _head(c.d_model, c.act_dim)

    def embed(self, audio: torch.Tensor, poses_in: torch.Tensor | None) -> torch.Tensor:
        """Tokens ``(..., d_model)`` from audio ``(..., 438)`` and previous poses ``(..., 4)``."""
        x = self.audio_emb(audio)
        if self.pose_emb is not None:
            x = x + self.pose_emb(poses_in)
        return self.drop(x)

    def _out(self, h: torch.Tensor) -> torch.Tensor:
        return torch.tanh(self.head(h)) * math.pi

    def forward(self, batch: Tensors, targets: Tensors | None = None) -> SeqOutput:
        """Predict every frame of each window in one parallel scan; the loss with ``targets``."""
        _check_batch(self, batch)
        mask = batch["mask"].bool()
        pred = self._out(self.backbone(self.embed(batch["audio"], batch["poses_in"])))
        loss, losses = _loss(pred, targets, mask)
        return SeqOutput(actions=pred, loss=loss, losses=losses)

    @torch.no_grad()
    def generate(
        self,
        features: SongInput,
        teacher_poses: np.ndarray | list[np.ndarray] | None = None,
        progress: bool = False,
        reset_every: int | None = None,
    ) -> np.ndarray | list[np.ndarray]:
        """Translate whole songs with the recurrent step, O(1) per frame: ``(T, 438)`` -> ``(T, 4)``.

        Each frame feeds back the model's previous prediction (``teacher_poses (T, 4)``: feed
        the true previous poses instead, which makes the result equal :meth:`forward` over the
        whole song). Without ``pose_input`` each song goes through one parallel scan, which
        the recurrence equals. A list of songs is stepped as one batch (a list comes back).

        ``reset_every``: restart from a zero state every this many frames (the previous pose is
        kept), so that no state holds more history than a training window of that length had
        (training windows start from a zero state); ``None``: one recurrence over the whole
        song (the thesis's inference). Used to measure what that mismatch costs.
        """
        from tqdm.auto import tqdm

        if reset_every is not None and int(reset_every) < 1:
            raise ValueError(f"Expect reset_every >= 1 or None, actually: {reset_every!r}.")
        songs, single = _as_songs(features, self.config.state_dim)
        device = next(self.parameters()).device
        d, n_songs = self.config.act_dim, len(songs)
        lengths = [len(x) for x in songs]
        if self.pose_emb is None:
            step = int(reset_every) if reset_every else max(max(lengths), 1)
            out = [
                np.concatenate(
                    [
                        self._out(
                            self.backbone(self.embed(x[i : i + step].to(device)[None], None))
                        )[0]
                        .cpu()
                        .numpy()
                        for i in range(0, len(x), step)
                    ]
                )
                for x in songs
            ]
            return out[0] if single else out
        T = max(lengths)
        x = torch.zeros(n_songs, T, self.config.state_dim, device=device)
        for i, song in enumerate(songs):
            x[i, : lengths[i]] = song.to(device)
        tp = None
        if teacher_poses is not None:
            tps = [teacher_poses] if single else list(teacher_poses)
            tp = torch.zeros(n_songs, T, d, device=device)
            for i, p in enumerate(tps):
                p = torch.as_tensor(np.asarray(p, dtype=np.float32))
                if p.shape != (lengths[i], d):
                    raise ValueError(
                        f"Expect teacher_poses of shape {(lengths[i], d)}, got {tuple(p.shape)}."
                    )
                tp[i, : lengths[i]] = p
        state = self.backbone.allocate_state(n_songs, device=device, dtype=x.dtype)
        prev = torch.zeros(n_songs, d, device=device)  # the zero start pose
        preds = torch.zeros(n_songs, T, d, device=device)
        for t in tqdm(range(T), disable=not progress, desc="MDLT-M"):
            if reset_every and t and t % int(reset_every) == 0:
                state = self.backbone.allocate_state(n_songs, device=device, dtype=x.dtype)
            y, state = self.backbone.step(self.embed(x[:, t], prev), state)
            preds[:, t] = self._out(y)
            prev = preds[:, t] if tp is None else tp[:, t]
        out = [preds[i, : lengths[i]].cpu().numpy() for i in range(n_songs)]
        return out[0] if single else out


def build_model(config: MDLTConfig) -> MDLTTransformer | MDLTMamba:
    """The model of ``config.variant``.

    Used in: MDLT chapter (thesis 6.4).
    """
    return MDLTTransformer(config) if config.variant == "transformer" else MDLTMamba(config)
