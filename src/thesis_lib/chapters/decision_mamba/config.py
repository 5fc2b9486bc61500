"""The Decision Mamba chapter's parameters: :class:`Config` (defaults = the smoke scale), the
architectures of its sweeps (:class:`Arch`, :func:`parse_arch`) and its methods.

Read without importing the chapter (``thesis run`` checks a parameter file against the type
hints here at once), so this module imports neither torch nor the rest of the chapter; the
helpers that build the runner's specs import them when called.

Used in: Decision Mamba chapter (notebook ``05_decision_mamba``; ``params/05_decision_mamba.*.yml``).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Literal, NamedTuple

from thesis_lib.book.params import spec_from
from thesis_lib.chapters.seq_config import SeqTraining

if TYPE_CHECKING:
    from thesis_lib.seq.registry import ArchSpec
    from thesis_lib.seq.runner import TrainSpec

__all__ = [
    "CHAPTER",
    "DM_METHODS",
    "HIERARCHICAL",
    "MAMBA_METHODS",
    "RTG_METHODS",
    "Arch",
    "Config",
    "parse_arch",
]

CHAPTER = "05_decision_mamba"
"""The notebook's name (``results/05_decision_mamba/``, ``studies/05_decision_mamba/``)."""
DM_METHODS: tuple[str, ...] = ("DT", "HDT", "DM-RTG", "DM-noRTG", "HDM")
"""Our method names: DT (with RTG), HDT, DM with RTG, DM without RTG (DM-noRTG), HDM."""
RTG_METHODS = ("DT", "DM-RTG")
"""The methods conditioned on a desired return."""
HIERARCHICAL = ("HDT", "HDM")
"""The methods trained on sub-goals."""
MAMBA_METHODS = ("DM-RTG", "DM-noRTG", "HDM")
"""The methods that can act recurrently (``eval_mode``)."""


class Arch(NamedTuple):
    """An architecture of the sweeps: layers (per level), embedding size, context length."""

    n_layers: int
    d_model: int
    K: int

    @property
    def label(self) -> str:
        """``"L6 D128 K20"`` as the thesis's figure legends."""
        return f"L{self.n_layers} D{self.d_model} K{self.K}"


def parse_arch(text: str | Arch) -> Arch:
    """``"6/128/20"`` (layers/d_model/K) -> :class:`Arch`.

    Example:
        >>> parse_arch("6/128/20")
        Arch(n_layers=6, d_model=128, K=20)
        >>> parse_arch("6-128")
        Traceback (most recent call last):
        ...
        ValueError: Expect an architecture as 'layers/d_model/K', e.g. '6/128/20'; got '6-128'.
    """
    if isinstance(text, Arch):
        return text
    parts = str(text).split("/")
    try:
        values = [int(p) for p in parts]
    except ValueError:
        values = []
    if len(values) != 3 or min(values) < 1:
        raise ValueError(
            f"Expect an architecture as 'layers/d_model/K', e.g. '6/128/20'; got '{text}'."
        )
    return Arch(*values)


@dataclass
class Config(SeqTraining):
    """Parameters of the Decision Mamba chapter; defaults are the smoke scale.

    ``params/05_decision_mamba.smoke.yml`` equals these defaults; ``.full.yml`` holds the
    thesis's scale (5.3.3: batch 16, lr 1e-4, up to 1M iterations, evaluation every 1,000 on
    100 episodes, 4 seeds, 6 layers, d 128, K 20).

    The sequence models' training options (``init``, ``sampling``, ``device``, ``precision``,
    ``kernels``) are :class:`~thesis_lib.chapters.seq_config.SeqTraining`'s.

    Used in: Decision Mamba chapter.
    """

    seed: int = 0
    """Seed of the chapter (figures); runs use ``seeds``."""
    datasets: list[str] = field(default_factory=lambda: ["hopper/medium", "maze2d-umaze/expert"])
    """``task/tier`` pairs of Table 5.5 and Fig 5.4, or real Minari ids (``D4RL/kitchen/mixed-v2``,
    ``D4RL/antmaze/umaze-v1``: downloads under ``$MINARI_DATASETS_PATH``; evaluated in their own
    environment, scored by D4RL's references; :mod:`thesis_lib.data.minari_sets`)."""
    methods: list[str] = field(default_factory=lambda: list(DM_METHODS))
    """Subset of :data:`DM_METHODS`."""
    seeds: list[int] = field(default_factory=lambda: [0])
    """One run per seed (4 in the thesis)."""
    iterations: int = 100
    """Training iterations per run (the thesis: up to 1M)."""
    batch_size: int = 16
    """Windows per batch (16 in the thesis)."""
    arch: str = "2/32/20"
    """Architecture of Table 5.5 and Fig 5.4, ``layers/d_model/K`` (the thesis: ``6/128/20``)."""
    n_heads: int = 1
    """Attention heads of DT/HDT."""
    dropout: float = 0.1
    """Dropout of DT/HDT (the DM/HDM have none, as the authors' code)."""
    gated_mlp: bool = True
    """Gated MLP in each Mamba block (the authors' later DM/HDM code)."""
    lr: float = 0.001
    """Peak AdamW learning rate (1e-4 in the thesis)."""
    warmup_steps: int = 30
    """Linear warm-up steps (10k in the authors' code)."""
    eval_every: int = 50
    """Evaluate every this many iterations and at the end (1000 in the thesis)."""
    eval_episodes: int = 4
    """Episodes per evaluation (100 in the thesis)."""
    max_eval_steps: int | None = 100
    """Cap on evaluation episode length (``None``: the task's time limit). Maze2D always runs
    whole episodes (:func:`~thesis_lib.seq.evaluation.eval_step_cap`)."""
    eval_mode: str = "recurrent"
    """How the DM/HDM act: ``recurrent`` (one O(1) step per action) or ``window`` (re-run the
    last K steps, as the authors' code: ``paper_compat``)."""
    compare_eval_modes: bool = True
    """Also evaluate each final DM/HDM in the other mode (the difference is a table)."""
    sweep_datasets: list[str] = field(default_factory=lambda: ["hopper/medium"])
    """Data sets of the architecture sweeps (Figs 5.3, 5.5, 5.6)."""
    sweep_methods: list[str] = field(default_factory=lambda: ["HDM", "DM-noRTG", "DM-RTG"])
    """Methods swept (Fig 5.3: HDM, 5.5: DM, 5.6: DM with RTG)."""
    sweep_archs: list[str] = field(default_factory=lambda: ["1/32/10", "2/32/20", "2/64/20"])
    """Architectures swept, ``layers/d_model/K`` (the thesis: layers 2-12, d 128/256, K 10/20/60)."""
    timing_datasets: list[str] = field(default_factory=lambda: ["maze2d-umaze/expert"])
    """Data sets (environments) of Table 5.6."""
    timing_arch: str = "6/128/20"
    """Architecture timed in Table 5.6 (the thesis's 6/128/20)."""
    timing_batch_size: int = 16
    """Batch size of the timed training iterations (16 in the thesis)."""
    timing_train_iters: int = 2
    """Timed training iterations per method (1000 in the thesis), after one untimed."""
    timing_infer_steps: int = 40
    """Environment steps per timed inference episode."""
    timing_infer_episodes: int = 2
    """Timed inference episodes per method and mode (after one untimed)."""
    dataset_size: Literal["smoke", "full"] = "smoke"
    """Size of the generated data sets: a key of ``thesis_lib.data.DATASET_SIZES`` (``smoke``
    20k transitions, ``full`` D4RL's 1M). Not the chapter's profile (``thesis run --profile``),
    which picks the parameter file."""
    n_transitions: int | None = None
    """Data-set size override."""
    paper_compat: bool = False
    """The authors' behaviours (a_{t-1} tokens, left-padded time-steps, last sub-goal = state 0,
    HDM Tanh sub-goal head); with ``eval_mode`` ``window`` that is the authors' code."""
    progress: bool = False
    """Progress bars of the runs."""

    def __post_init__(self) -> None:
        from thesis_lib.data.minari_sets import is_minari_id  # lazy: gymnasium
        from thesis_lib.seq.registry import check_methods  # lazy: torch

        for name in ("methods", "sweep_methods"):
            check_methods(getattr(self, name), DM_METHODS)

        for name in ("datasets", "sweep_datasets", "timing_datasets"):
            for d in getattr(self, name):
                if str(d).count("/") != 1 and not is_minari_id(d):
                    raise ValueError(
                        f"Expect {name} as 'task/tier', e.g. 'hopper/medium', or as a Minari id "
                        f"'namespace/task/tier-vN', e.g. 'D4RL/kitchen/mixed-v2'; got '{d}'."
                    )
        for a in [self.arch, self.timing_arch, *self.sweep_archs]:
            parse_arch(a)
        if self.eval_mode not in ("recurrent", "window"):
            raise ValueError(f"Unknown eval_mode {self.eval_mode!r}. Valid: recurrent, window.")
        for name in (
            "iterations",
            "batch_size",
            "eval_every",
            "eval_episodes",
            "timing_batch_size",
            "timing_train_iters",
            "timing_infer_steps",
            "timing_infer_episodes",
            "warmup_steps",
        ):
            if int(getattr(self, name)) < 1:
                raise ValueError(f"Expect `{name}` >= 1, actually: {getattr(self, name)!r}.")

    @property
    def main_arch(self) -> Arch:
        """:attr:`arch` parsed."""
        return parse_arch(self.arch)

    def arch_spec(self, arch: str | Arch | None = None) -> ArchSpec:
        """The :class:`~thesis_lib.seq.registry.ArchSpec` of ``arch`` (default :attr:`arch`)."""
        from thesis_lib.seq.registry import ArchSpec  # lazy: torch

        a = parse_arch(arch or self.arch)
        return spec_from(self, ArchSpec, d_model=a.d_model, n_layers=a.n_layers, K=a.K)

    def train_spec(self, seed: int) -> TrainSpec:
        """The :class:`~thesis_lib.seq.runner.TrainSpec` of the run with ``seed``."""
        from thesis_lib.seq.runner import TrainSpec  # lazy: torch

        return spec_from(self, TrainSpec, seed=seed)
