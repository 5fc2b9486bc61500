"""The CLfD chapter's parameters: :class:`Config` (its defaults are the smoke scale).

Read without importing the chapter (``thesis run`` checks a notebook's parameters against the
type hints of this file), so it imports neither torch nor the rest of the chapter; the names
it checks the encoders, methods and cameras against are imported when a ``Config`` is made.

Used in: chapter 02_clfd (the notebook's parameters cell, ``params/02_clfd.*.yml``).
"""

from __future__ import annotations

from dataclasses import dataclass, field

#: The chapter's notebook (``notebooks/02_clfd.ipynb``, ``results/02_clfd``, ``studies/02_clfd``).
CHAPTER = "02_clfd"


@dataclass
class Config:
    """Parameters of notebook 02_clfd (the smoke defaults; ``params/02_clfd.full.yml`` = the thesis's scale)."""

    seed: int = 0
    """Seeds the demonstrations, the networks, pair sampling and the RL agents."""
    n_demos: int = 18
    """Demonstrations rendered (thesis: 150), split train/val/test as 100/25/25 scaled."""
    image_size: int = 48
    """Side of the square frames in pixels."""
    encoders: list[str] = field(default_factory=lambda: ["resnet18", "tcn"])
    """Encoders of Table 4.1: "resnet18", "tcn" (the TCN-style encoder)."""
    methods: list[str] = field(default_factory=lambda: ["tcn", "cmc", "clfd"])
    """Training methods of Table 4.1: "clfd", "tcn" (triplet), "cmc"."""
    epochs: int = 16
    """Training epochs per model (thesis: 1000)."""
    batch_size: int = 32
    """Anchor-positive pairs per batch (thesis text: 32; Table 4.1's caption says 50)."""
    lr: float = 0.001
    """Adam learning rate (authors' code: 3e-4)."""
    temperature: float = 0.5
    """NT-Xent temperature τ (thesis: 0.5)."""
    resnet_width: int = 16
    """ResNet-18 channel width (64 = the real ResNet-18)."""
    tcn_width: int = 16
    """Width of the TCN-style encoder's trunk."""
    eval_every: int = 4
    """Validation alignment error every this many epochs; the best checkpoint is kept (thesis: 25)."""
    seen_cameras: list[str] = field(default_factory=lambda: ["front", "top", "overhead"])
    """Cameras the encoders train on (thesis 4.2.2.2: three "seen" viewpoints)."""
    unseen_cameras: list[str] = field(default_factory=lambda: ["gripper", "right"])
    """Cameras never shown to the encoders ("unseen")."""
    paper_compat: bool = False
    """Train CLfD with the authors' bug (anchor view never in the loss) in Tables 4.1/4.2 and Fig 4.4."""
    compat_encoders: list[str] = field(default_factory=lambda: ["tcn"])
    """Encoders on which CLfD is also trained the other way (bug on/off) to measure the difference."""
    mlp_epochs: int = 300
    """Epochs of the stage-classification MLP (thesis: 500)."""
    rl_encoder: str = "tcn"
    """Backbone of the encoders that give the RL state and reward (thesis Fig 4.4: TCN)."""
    rl_methods: list[str] = field(default_factory=lambda: ["clfd", "cmc", "tcn"])
    """Encoders (by training method) compared in Fig 4.4."""
    rl_episodes: int = 12
    """DDPG training episodes per encoder (thesis: 3000)."""
    rl_steps: int = 20
    """Steps per RL episode (the pick stage of a demonstration takes about 15)."""
    rl_camera: str = "front"
    """Camera whose image the RL agent's encoder sees."""
    rl_her: bool = True
    """Use hindsight experience replay (the thesis text's choice)."""
    pouring_dir: str | None = None
    """Folder with Multi-View Pouring's ``train``/``val``/``test`` sub-folders of ``<seq>_view<k>``
    videos (e.g. ``.../multiview-pouring/videos``); when given, Table 4.1's Pouring rows are run."""
    pouring_max_frames: int = 100
    """Frames kept per Pouring sequence (evenly subsampled)."""
    device: str = "cpu"
    """Torch device for the encoders ("cpu", "cuda" or "auto")."""
    progress: bool = False
    """Show progress bars."""
    seeds: list[int] = field(default_factory=lambda: [0])
    """Seeds of the pre-registered study (``thesis study 02_clfd``); each renders its own data set
    and guiding demonstration and trains its own encoders and agents (the chapter runs ``seed``)."""
    rl_success_m: float = 0.03
    """Study: an RL episode succeeds when it ends with the grasp point this close to the box centre (m)."""
    rl_checkpoints: int = 10
    """Study: the RL success curve cuts the training episodes into this many equal windows."""
    study_controls: bool = True
    """Study: also run an untrained encoder (same backbone) through stage classification and RL."""
    alignment_controls: bool = False
    """Study: also measure C10's alignment error with an untrained encoder of each backbone
    (``method: untrained``), the trivial answer each trained method must beat (clfd-c10-v2;
    off in v1, whose grid had no such task)."""
    rl_oracle: bool = False
    """Study: also run C12's positive control, DDPG+HER with the grasp point's true position as
    state and its true distance to the demonstration's grasp as reward
    (:class:`~thesis_lib.clfd.rl.GraspPointOracle`; method ``oracle``): can the RL budget learn
    the pick stage at all (clfd-c12-v4; off before, whose grids had no such task)."""
    study_claims: list[str] = field(default_factory=lambda: ["C10", "C11", "C12"])
    """Study: the claims whose tasks run (C10 alignment, C11 stage classification, C12 RL); a
    later study of one claim names it alone (the encoders come from the chapter's store)."""

    def __post_init__(self) -> None:
        from thesis_lib.clfd.env import CAMERAS  # lazy: mujoco
        from thesis_lib.clfd.models import ENCODERS  # lazy: torch
        from thesis_lib.clfd.train import METHODS  # lazy: torch

        bad = sorted(set(self.study_claims) - {"C10", "C11", "C12"})
        if bad or isinstance(self.study_claims, str) or not self.study_claims:
            raise ValueError(
                f"Expect `study_claims` to be a non-empty list of C10, C11, C12, got {self.study_claims!r}."
            )

        for e in [*self.encoders, *self.compat_encoders, self.rl_encoder]:
            if e not in ENCODERS:
                raise ValueError(f"Unknown encoder {e!r}. Valid: {', '.join(ENCODERS)}.")
        for m in [*self.methods, *self.rl_methods]:
            if m not in METHODS:
                raise ValueError(f"Unknown method {m!r}. Valid: {', '.join(METHODS)}.")
        for c in [*self.seen_cameras, *self.unseen_cameras, self.rl_camera]:
            if c not in CAMERAS:
                raise ValueError(f"Unknown camera {c!r}. Valid: {', '.join(CAMERAS)}.")
        if len(self.seen_cameras) < 2:
            raise ValueError(
                f"seen_cameras needs at least two cameras to pair, got {self.seen_cameras}."
            )
        if set(self.seen_cameras) & set(self.unseen_cameras):
            raise ValueError(
                "A camera cannot be both seen and unseen: "
                f"{sorted(set(self.seen_cameras) & set(self.unseen_cameras))}."
            )
        if not self.seeds or len(set(self.seeds)) != len(self.seeds):
            raise ValueError(f"seeds must be distinct and not empty, got {self.seeds}.")
        if self.rl_success_m <= 0 or self.rl_checkpoints < 1:
            raise ValueError(
                f"Need rl_success_m > 0 and rl_checkpoints >= 1; got {self.rl_success_m}, "
                f"{self.rl_checkpoints}."
            )
        if self.n_demos < 3 or self.epochs < 1 or self.image_size < 16:
            raise ValueError(
                f"Need n_demos >= 3, epochs >= 1, image_size >= 16; got {self.n_demos}, "
                f"{self.epochs}, {self.image_size}."
            )
