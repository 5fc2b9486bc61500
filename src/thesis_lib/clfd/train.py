"""Training viewpoint-invariant encoders: CLfD (Algorithm 1) and the TCN and CMC baselines.

:class:`CLfD` is the user-facing object: build it with an encoder and a method, ``fit`` it on
synchronised multi-view videos (:class:`~thesis_lib.clfd.data.MultiViewVideos`), then ``embed``
frames (a feature extractor) or use :meth:`CLfD.reward` (Eq 4.2).

Example:
    >>> import numpy as np
    >>> from thesis_lib.clfd import CLfD, MultiViewVideos
    >>> rng = np.random.default_rng(0)
    >>> vids = MultiViewVideos([rng.integers(0, 255, (6, 2, 32, 32, 3), dtype=np.uint8)], ("a", "b"))
    >>> model = CLfD(encoder="tcn", batch_size=4, seed=0)
    >>> history = model.fit(vids, epochs=1, progress=False)
    >>> model.embed(vids.videos[0][:, 0]).shape
    (6, 32)

Used in: CLfD (thesis 4.2), chapter 02_clfd.
"""

from __future__ import annotations

import copy
from collections.abc import Sequence
from pathlib import Path
from typing import Literal, get_args

import numpy as np
import pandas as pd
import torch
from tqdm.auto import tqdm

from thesis_lib.clfd.data import MultiViewVideos
from thesis_lib.clfd.losses import cmc_loss, nt_xent, triplet_loss
from thesis_lib.clfd.metrics import alignment_error
from thesis_lib.clfd.models import ENCODERS, ProjectionHead, ResNet18, make_encoder, to_tensor

Method = Literal["clfd", "tcn", "cmc"]
METHODS: tuple[str, ...] = get_args(Method)
#: How Table 4.1 names the methods.
METHOD_LABELS = {"clfd": "CLfD", "tcn": "TCN", "cmc": "CMC"}
ENCODER_LABELS = {"resnet18": "Resnet18", "tcn": "TCN"}


def camera_pairs(cameras: Sequence[str]) -> list[tuple[str, str]]:
    """Every unordered pair of ``cameras``, in order.

    >>> camera_pairs(["front", "top", "overhead"])
    [('front', 'top'), ('front', 'overhead'), ('top', 'overhead')]
    """
    return [(a, b) for i, a in enumerate(cameras) for b in cameras[i + 1 :]]


def mean_alignment_error(
    model: CLfD, data: MultiViewVideos, pairs: Sequence[tuple[str, str]] | None = None
) -> float:
    """Alignment error (%) averaged over the videos of ``data`` and the camera ``pairs`` (default: all pairs)."""
    pairs = list(pairs) if pairs is not None else camera_pairs(data.cameras)
    errs = []
    for video in data.videos:
        cams = sorted({c for p in pairs for c in p}, key=data.cameras.index)
        idx = data.camera_index(cams)
        emb = model.embed(video[:, idx])  # (T, len(cams), D)
        for a, b in pairs:
            errs.append(alignment_error(emb[:, cams.index(a)], emb[:, cams.index(b)]))
    return float(np.mean(errs))


class CLfD:
    """A viewpoint-invariant encoder trained on synchronised multi-view videos (thesis 4.2).

    Args:
        encoder: ``"resnet18"`` or ``"tcn"`` (the TCN-style encoder), each ending in
            ``feature_dim`` features.
        method: ``"clfd"`` (NT-Xent on same-time frames of two cameras, with the projection head),
            ``"tcn"`` (triplet loss, negatives from other times of the anchor's camera) or
            ``"cmc"`` (cross-view contrastive loss).
        feature_dim: N, the embedding size (thesis: 32).
        proj_dim: output of the projection head (thesis: 64).
        temperature: τ of NT-Xent (thesis: 0.5); CMC uses ``cmc_temperature``.
        lr: Adam learning rate (authors' code: 3e-4).
        batch_size: anchor-positive pairs per batch (thesis text: 32).
        width: encoder channel width (None = ResNet-18's 64 / the TCN-style trunk's 32).
        weights: optional local torchvision ``resnet18`` state dict (e.g. ImageNet) to start from.
        paper_compat: reproduce the authors' bug (the model returned ``(h_a, h_a, z_p, z_p)``):
            the loss compares the positive view with itself and the anchor view never enters it.
            Only for ``method="clfd"``.
        triplet_margin: margin of the TCN triplet loss (on unit-normalised embeddings).
        negative_gap: TCN negatives are at least this fraction of the video length away in time.
        seed: seeds the networks and the pair sampling.
        device: ``"cpu"``, ``"cuda"`` or ``"auto"``.

    Used in: CLfD (thesis 4.2), chapter 02_clfd.
    """

    def __init__(
        self,
        encoder: str = "tcn",
        method: str = "clfd",
        feature_dim: int = 32,
        proj_dim: int = 64,
        temperature: float = 0.5,
        cmc_temperature: float = 0.07,
        lr: float = 3e-4,
        batch_size: int = 32,
        width: int | None = None,
        weights: str | Path | None = None,
        paper_compat: bool = False,
        triplet_margin: float = 0.2,
        negative_gap: float = 0.1,
        seed: int = 0,
        device: str = "cpu",
    ) -> None:
        if encoder not in ENCODERS:
            raise ValueError(f"Unknown encoder {encoder!r}. Valid: {', '.join(ENCODERS)}.")
        if method not in METHODS:
            raise ValueError(f"Unknown method {method!r}. Valid: {', '.join(METHODS)}.")
        if paper_compat and method != "clfd":
            raise ValueError(
                "paper_compat reproduces a bug of the CLfD model; it applies to method='clfd' only."
            )
        if batch_size < 2:
            raise ValueError(
                f"batch_size must be >= 2 (the other pairs are the negatives), got {batch_size}."
            )
        if temperature <= 0 or cmc_temperature <= 0:
            raise ValueError(f"Temperatures must be > 0, got {temperature} and {cmc_temperature}.")
        self.encoder_name, self.method = encoder, method
        self.feature_dim, self.temperature, self.cmc_temperature = (
            feature_dim,
            temperature,
            cmc_temperature,
        )
        self.lr, self.batch_size, self.paper_compat = lr, batch_size, paper_compat
        self.triplet_margin, self.negative_gap, self.seed = triplet_margin, negative_gap, seed
        if device == "auto":
            device = "cuda" if torch.cuda.is_available() else "cpu"
        self.device = torch.device(device)
        torch.manual_seed(seed)
        self.encoder = make_encoder(encoder, feature_dim, width).to(self.device)
        if weights is not None:
            if not isinstance(self.encoder, ResNet18):
                raise ValueError(
                    "weights= loads a torchvision resnet18 state dict; use encoder='resnet18'."
                )
            self.encoder.load_imagenet(weights)
        self.projection = ProjectionHead(feature_dim, feature_dim, proj_dim).to(self.device)
        self.history = pd.DataFrame()

    # -- inference -----------------------------------------------------------------------------
    @torch.no_grad()
    def embed(self, frames: np.ndarray, batch_size: int = 256) -> np.ndarray:
        """Features f(x) of uint8 frames (..., H, W, 3) → float32 (..., feature_dim)."""
        frames = np.asarray(frames)
        lead = frames.shape[:-3]
        x = to_tensor(frames)
        was = self.encoder.training
        self.encoder.eval()
        out = [
            self.encoder(x[i : i + batch_size].to(self.device)).cpu()
            for i in range(0, len(x), batch_size)
        ]
        self.encoder.train(was)
        return torch.cat(out).numpy().reshape(*lead, self.feature_dim)

    def reward(self, frame: np.ndarray, goal_embedding: np.ndarray) -> float:
        """Eq 4.2: ``-||f(s_t) - f(s_goal)||`` for one uint8 frame (H, W, 3)."""
        return -float(np.linalg.norm(self.embed(frame[None])[0] - goal_embedding))

    # -- training ------------------------------------------------------------------------------
    def _sample_epoch(
        self, data: MultiViewVideos, cams: list[int], rng: np.random.Generator
    ) -> np.ndarray:
        """One epoch of anchor-positive pairs: every (video, t) once, two distinct cameras, shuffled.

        Returns int rows (video, t, cam_anchor, cam_positive, t_negative).
        """
        rows = []
        for v, video in enumerate(data.videos):
            n = len(video)
            gap = max(1, int(round(self.negative_gap * n)))
            for t in range(n):
                a, p = rng.choice(cams, 2, replace=False)
                far = np.r_[0 : max(0, t - gap + 1), min(n, t + gap) : n]
                t_neg = int(rng.choice(far)) if len(far) else (t + n // 2) % n
                rows.append((v, t, a, p, t_neg))
        arr = np.array(rows)
        return arr[rng.permutation(len(arr))]

    def _loss(self, data: MultiViewVideos, batch: np.ndarray) -> torch.Tensor:
        def frames(t_col: int, c_col: int) -> torch.Tensor:
            imgs = np.stack([data.videos[r[0]][r[t_col], r[c_col]] for r in batch])
            return to_tensor(imgs).to(self.device)

        if self.method == "tcn":
            x = torch.cat([frames(1, 2), frames(1, 3), frames(4, 2)])  # anchor, positive, negative
            h = self.encoder(x)
            a, p, n = h.chunk(3)
            return triplet_loss(a, p, n, self.triplet_margin)
        if self.paper_compat:
            # The authors' model returned (h_a, h_a, z_p, z_p): the loss saw the positive view twice.
            z_p = self.projection(self.encoder(frames(1, 3)))
            return nt_xent(z_p, z_p, self.temperature)
        h = self.encoder(
            torch.cat([frames(1, 2), frames(1, 3)])
        )  # one pass: BatchNorm sees both views
        z_a, z_p = self.projection(h).chunk(2)
        if self.method == "cmc":
            return cmc_loss(z_a, z_p, self.cmc_temperature)
        return nt_xent(z_a, z_p, self.temperature)

    def fit(
        self,
        data: MultiViewVideos,
        epochs: int = 10,
        cameras: Sequence[str] | None = None,
        val: MultiViewVideos | None = None,
        eval_every: int | None = None,
        eval_pairs: Sequence[tuple[str, str]] | None = None,
        keep_best: bool = True,
        progress: bool = True,
    ) -> pd.DataFrame:
        """Train for ``epochs`` passes over the anchor-positive pairs (Algorithm 1, Adam).

        Args:
            data: training videos.
            epochs: passes over every (video, time) pair.
            cameras: the cameras pairs are drawn from (default: all of ``data``); the others stay
                unseen.
            val: validation videos; with ``eval_every`` the alignment error on ``eval_pairs``
                (default: pairs of ``cameras``) is measured every ``eval_every`` epochs and after
                the last, and with ``keep_best`` the lowest-error weights are kept (thesis:
                every 25 epochs, lowest value reported).

        Returns:
            One row per epoch: ``epoch``, ``loss`` (mean over batches), ``val_alignment_error``
            (NaN when not measured). Also stored in ``self.history``.
        """
        cameras = list(cameras) if cameras is not None else list(data.cameras)
        cams = data.camera_index(cameras)
        if len(cams) < 2:
            raise ValueError(f"CLfD needs at least two cameras to pair, got {cameras}.")
        if epochs < 1:
            raise ValueError(f"epochs must be >= 1, got {epochs}.")
        if val is not None and eval_every:
            eval_pairs = list(eval_pairs) if eval_pairs is not None else camera_pairs(cameras)
        rng = np.random.default_rng(self.seed)
        torch.manual_seed(self.seed)
        params = list(self.encoder.parameters()) + list(self.projection.parameters())
        opt = torch.optim.Adam(params, lr=self.lr)
        rows, best, best_state = [], np.inf, None
        bar = tqdm(
            range(1, epochs + 1), desc=f"{self.method}/{self.encoder_name}", disable=not progress
        )
        for epoch in bar:
            self.encoder.train()
            self.projection.train()
            pairs = self._sample_epoch(data, cams, rng)
            losses = []
            for i in range(0, len(pairs), self.batch_size):
                batch = pairs[i : i + self.batch_size]
                if len(batch) < 2:
                    continue
                loss = self._loss(data, batch)
                opt.zero_grad()
                loss.backward()
                opt.step()
                losses.append(loss.item())
            ae = np.nan
            if val is not None and eval_every and (epoch % eval_every == 0 or epoch == epochs):
                ae = mean_alignment_error(self, val, eval_pairs)
                if keep_best and ae < best:
                    best = ae
                    best_state = copy.deepcopy(
                        (self.encoder.state_dict(), self.projection.state_dict())
                    )
            rows.append({"epoch": epoch, "loss": float(np.mean(losses)), "val_alignment_error": ae})
            bar.set_postfix(loss=f"{rows[-1]['loss']:.3f}")
        if best_state is not None:
            self.encoder.load_state_dict(best_state[0])
            self.projection.load_state_dict(best_state[1])
        self.history = pd.DataFrame(rows)
        return self.history

    # -- persistence ---------------------------------------------------------------------------
    def save(self, path: str | Path) -> Path:
        """Save the encoder and projection head weights (``torch.save``)."""
        path = Path(path)
        torch.save(
            {"encoder": self.encoder.state_dict(), "projection": self.projection.state_dict()}, path
        )
        return path

    def load(self, path: str | Path) -> CLfD:
        """Load weights written by :meth:`save` into this (identically built) model."""
        state = torch.load(Path(path), map_location=self.device, weights_only=True)
        self.encoder.load_state_dict(state["encoder"])
        self.projection.load_state_dict(state["projection"])
        return self
