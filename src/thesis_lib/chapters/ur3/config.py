"""The UR3 deployment chapter's parameters: :class:`Config` (defaults are the smoke scale) and the
constants of Table 5.4's data set and methods.

Read without importing the chapter (``thesis run`` checks a parameter against the type hints
here before a kernel starts), so nothing here imports torch at module level: the sequence
models' registry is imported where a method's name is checked or a spec is built.

Used in: UR3 deployment chapter.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Literal

from thesis_lib.book.params import spec_from
from thesis_lib.chapters.seq_config import SeqTraining

if TYPE_CHECKING:
    from thesis_lib.seq.registry import ArchSpec
    from thesis_lib.seq.runner import TrainSpec

__all__ = ["CHAPTER", "METHODS", "N_DEMOS", "N_GOALS", "RTG_SCALE", "Config"]

CHAPTER = "07_ur3_deployment"
"""The chapter's notebook (``results/07_ur3_deployment/``)."""
METHODS: tuple[str, ...] = ("HDT", "DT")
"""The two methods of Table 5.4."""
N_DEMOS = 100
"""Demonstrations made: 80 train, 10 validation, 10 test starts (the thesis's split)."""
N_GOALS = 5
"""Goal positions of the reaching task (a test episode reaches 0 to 5)."""
RTG_SCALE = 10.0
"""Returns-to-go divisor (returns are about -30 to -60 here, not thousands)."""


@dataclass
class Config(SeqTraining):
    """The notebook's parameters (``params/07_ur3_deployment.*.yml``); defaults are the smoke scale.

    The sequence models' training options (``init``, ``sampling``, ``device``, ``precision``,
    ``kernels``) are :class:`~thesis_lib.chapters.seq_config.SeqTraining`'s.

    Used in: UR3 deployment chapter.
    """

    seed: int = 0
    """Seed of the demonstrations and of the stand-in dance."""
    seeds: list[int] = field(default_factory=lambda: [0])
    """Training seeds of Table 5.4."""
    reach_set: Literal["teleop", "any-order"] = "teleop"
    """The reaching demonstrations (:data:`thesis_lib.ur3.reach.REACH_SETS`): ``teleop``, the
    goals in one sequence (Table 5.4's), or ``any-order``, each demonstration in an order of its
    own (harder: no ceiling at 20 demonstrations; the C14 study v2)."""
    train_demos: list[int] = field(default_factory=lambda: [10, 80])
    """Numbers of training demonstrations, the first n of the 80 (the thesis: 10, 20, ..., 80)."""
    methods: list[str] = field(default_factory=lambda: list(METHODS))
    """HDT and/or DT."""
    iterations: int = 1000
    """Training iterations per run (10k in the thesis)."""
    batch_size: int = 32
    """Windows per batch."""
    K: int = 20
    """Context length."""
    d_model: int = 32
    """Embedding size (128 in the thesis)."""
    n_layers: int = 1
    """GPT blocks (per HDT level; 3 in the thesis)."""
    n_heads: int = 1
    """Attention heads."""
    dropout: float = 0.0
    """Dropout (0.1 in the thesis; off at the smoke scale, where it slows the few hundred steps badly)."""
    lr: float = 0.001
    """Peak learning rate."""
    warmup_steps: int = 50
    """Warm-up steps."""
    max_eval_steps: int = 200
    """Steps per test episode (200 in the thesis)."""
    paper_compat: bool = False
    """The authors' behaviours in the sequence models (see the HDT chapter)."""
    dance_source: Literal["mdlt", "demo"] = "mdlt"
    """``"mdlt"``: the first sequence of MDLT's default AIST++-layout data set; ``"demo"``: a stand-in dance."""
    dance_seconds: float = 6.0
    """Seconds of dance to play."""
    dance_fps: int = 60
    """Frame rate of the dance angles (MDLT: 60)."""
    dance_mode: Literal["clip", "reject"] = "clip"
    """Limits: clip (clamp and rate-limit) or reject."""
    viewer_frames: int = 180
    """Frames stored in the 3-D viewer (subsampled)."""
    progress: bool = False
    """Progress bars."""

    def __post_init__(self) -> None:
        from thesis_lib.seq.registry import check_methods  # lazy: torch

        for name in ("seeds", "train_demos", "methods"):
            value = getattr(self, name)
            if isinstance(value, str):
                raise ValueError(f"Expect `{name}` to be a list, got the string {value!r}.")
            setattr(self, name, list(value))
        check_methods(self.methods, METHODS)
        if self.dance_source not in ("mdlt", "demo"):
            raise ValueError(f"Unknown dance_source {self.dance_source!r}. Valid: mdlt, demo.")
        if self.reach_set not in ("teleop", "any-order"):
            raise ValueError(f"Unknown reach_set {self.reach_set!r}. Valid: teleop, any-order.")
        if self.dance_mode not in ("clip", "reject"):
            raise ValueError(f"Unknown dance_mode {self.dance_mode!r}. Valid: clip, reject.")
        n_train = N_DEMOS - 20
        bad = [n for n in self.train_demos if not 1 <= n <= n_train]
        if bad:
            raise ValueError(
                f"train_demos must lie in 1..{n_train} ({N_DEMOS} demonstrations - 10 validation - 10 test), got {bad}."
            )

    def arch(self) -> ArchSpec:
        """The :class:`~thesis_lib.seq.registry.ArchSpec` of both methods."""
        from thesis_lib.seq.registry import ArchSpec  # lazy: torch

        return spec_from(self, ArchSpec, max_timestep=max(256, self.max_eval_steps + 1))

    def train_spec(self, seed: int) -> TrainSpec:
        """The :class:`~thesis_lib.seq.runner.TrainSpec` of the run with ``seed`` (no evaluation
        during training)."""
        from thesis_lib.seq.runner import TrainSpec  # lazy: torch

        return spec_from(self, TrainSpec, seed=seed, eval_every=0, rtg_scale=RTG_SCALE)
