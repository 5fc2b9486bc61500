"""The MDLT chapter's parameters: :class:`Config` (defaults: the smoke scale) and the constants
the rest of the chapter shares (method labels, scopes, the thesis's model size).

The book's runner reads :class:`Config`'s annotations from this file without importing the
package, so it imports neither torch nor the rest of the chapter (the few methods that need the
model's classes import them when called).

Used in: MDLT chapter (thesis 6.5).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Literal

if TYPE_CHECKING:
    from thesis_lib.mdlt.models import MDLTConfig
    from thesis_lib.seq.trainer import TrainConfig

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
ALL_GENRES = "All Genres"
"""The Table 6.2 row of the models trained on every genre."""
PER_GENRE, ALL_SCOPE = "per genre", "all genres"
"""The two scopes of Table 6.2: a model per genre, or one model for all genres."""

THESIS_MODEL: dict[str, Any] = {
    "d_model": 128,
    "n_layers": 6,
    "n_heads": 8,
    "d_ff": 2048,
    "dropout": 0.1,
    "K_transformer": 20,
    "K_mamba": 120,
}
"""The thesis's model size (6.5.1), for :func:`~thesis_lib.chapters.mdlt.tasks.run_model_sizes`."""

#: Config fields a model's training depends on (a :func:`~thesis_lib.chapters.mdlt.tasks.fold_task`
#: config holds them).
TRAIN_FIELDS = (
    "iterations", "batch_size", "lr", "weight_decay", "warmup_steps", "grad_clip", "eval_every",
    "d_model", "n_layers", "n_heads", "d_ff", "dropout", "K_transformer", "K_mamba", "pose_noise",
    "mute_features", "init_mean_pose", "paper_compat", "seed", "device",
)  # fmt: skip


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
        from thesis_lib.mdlt.audio import check_feature_groups  # lazy: torch

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
        from thesis_lib.mdlt.models import MDLTConfig  # lazy: torch

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
        from thesis_lib.seq.trainer import TrainConfig  # lazy: torch

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


def compat_config(cfg: Config) -> Config:
    """The paper_compat re-run: "All Genres" only, ``compat_folds`` folds, ``paper_compat=True``."""
    return dataclasses.replace(
        cfg, paper_compat=True, genres=[], all_genres=True, n_folds=max(1, cfg.compat_folds)
    )
