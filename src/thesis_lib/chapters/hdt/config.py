"""The HDT chapter's parameters: :class:`Config` (defaults = the smoke scale) and its methods.

Read without importing the chapter (``thesis run`` checks a parameter file against the type
hints here at once), so this module imports neither torch nor the rest of the chapter; the
helpers that build the runner's specs import them when called.

Used in: HDT chapter (notebook ``04_hdt``; ``params/04_hdt.*.yml``).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Literal

from thesis_lib.book.params import spec_from
from thesis_lib.chapters.seq_config import SeqTraining

if TYPE_CHECKING:
    from thesis_lib.seq.registry import ArchSpec
    from thesis_lib.seq.runner import EvalSpec, TrainSpec

__all__ = ["CHAPTER", "METHODS", "Config", "split_dataset"]

CHAPTER = "04_hdt"
"""The notebook's name (``results/04_hdt/``, ``studies/04_hdt/``)."""
METHODS: tuple[str, ...] = ("BC", "DT", "DT-noRTG", "HDT", "HDT-RTG")
"""The chapter's methods, as the tables' columns."""

_EXTRA_SEED_DEFAULT = ("hopper/medium", "maze2d-umaze/expert")
_COMPAT_DEFAULT = "hopper/medium"


def split_dataset(name: str) -> tuple[str, str]:
    """``"hopper/medium"`` -> ``("hopper", "medium")``; a real Minari id keeps its task and tier
    (``"D4RL/door/human-v2"`` -> ``("door", "human")``); a clear error otherwise
    (:func:`thesis_lib.data.minari_sets.dataset_key`)."""
    from thesis_lib.data.minari_sets import dataset_key  # lazy: gymnasium

    return dataset_key(name)


@dataclass
class Config(SeqTraining):
    """Every setting of the HDT chapter (thesis 5.2.5); the notebook's parameters.

    Defaults are the smoke scale; ``params/04_hdt.full.yml`` holds the thesis's.

    The sequence models' training options (``init``, ``sampling``, ``device``, ``precision``,
    ``kernels``) are :class:`~thesis_lib.chapters.seq_config.SeqTraining`'s.

    Used in: HDT chapter (Tables 5.1-5.3).
    """

    seed: int = 0
    """Seed of the chapter's figures (episode choice); runs use ``seeds``."""
    datasets: list[str] = field(
        default_factory=lambda: (
            [
                f"{t}/{tier}"
                for t in ("hopper", "walker2d", "halfcheetah", "ant")
                for tier in ("medium", "medium-replay", "medium-expert", "expert")
            ]
            + [f"maze2d-{m}/expert" for m in ("umaze", "medium", "large", "open")]
        )
    )
    """``task/tier`` pairs (``thesis_lib.data.TASKS``; a Maze2D task has other tiers than a
    locomotion task, so this is a list of pairs, not a task x tier product), or real Minari ids
    (``D4RL/door/human-v2``, ``D4RL/kitchen/complete-v2``: downloads under
    ``$MINARI_DATASETS_PATH``, evaluated in their own environment, scored by D4RL's
    references; :mod:`thesis_lib.data.minari_sets`)."""
    methods: list[str] = field(default_factory=lambda: list(METHODS))
    """Subset of :data:`METHODS`."""
    seeds: list[int] = field(default_factory=lambda: [0])
    """Seeds run on every data set (model init, batches, dropout, evaluation episodes)."""
    extra_seeds: list[int] = field(default_factory=lambda: [1])
    """More seeds, run only on ``extra_seed_datasets`` (the smoke scale: a second seed on a subset)."""
    extra_seed_datasets: list[str] = field(default_factory=lambda: list(_EXTRA_SEED_DEFAULT))
    """The ``task/tier`` pairs that also run ``extra_seeds`` (each must be in ``datasets``;
    the default keeps those of its two that are)."""
    compat_dataset: str | None = _COMPAT_DEFAULT
    """``task/tier`` where ``compat_methods`` also run with ``paper_compat=True`` (the authors'
    behaviours) to measure the difference; ``None``: skip (the default, hopper/medium, is
    skipped when ``datasets`` leaves it out)."""
    compat_methods: list[str] = field(default_factory=lambda: ["DT", "HDT"])
    """Methods of the ``paper_compat`` measurement."""
    iterations: int = 100
    """Training iterations (100k in the thesis)."""
    batch_size: int = 16
    """Batch size (64 in the thesis text)."""
    K: int = 20
    """Context length."""
    d_model: int = 32
    """Embedding size of the transformers (128 in the thesis)."""
    n_layers: int = 1
    """GPT blocks per transformer (per HDT level; 3 in the thesis)."""
    n_heads: int = 1
    """Attention heads."""
    dropout: float = 0.1
    """Dropout."""
    bc_hidden_dim: int = 64
    """Width of BC's two hidden layers (256 in the thesis)."""
    lr: float = 0.001
    """Peak learning rate (1e-4 in the thesis)."""
    warmup_steps: int = 20
    """Linear warm-up steps (10k in the thesis)."""
    eval_every: int = 50
    """Evaluate every this many iterations (and at the end)."""
    eval_episodes: int = 2
    """Episodes per evaluation (per target for RTG methods; 100 in the thesis)."""
    max_eval_steps: int | None = 100
    """Cap on evaluation episode length (``None``: the task's time limit). Maze2D always runs
    whole episodes (:func:`~thesis_lib.seq.evaluation.eval_step_cap`)."""
    dataset_size: Literal["smoke", "full"] = "smoke"
    """Size of the generated data sets: a key of ``thesis_lib.data.DATASET_SIZES`` (``smoke``
    20k transitions, ``full`` D4RL's 1M). Not the chapter's profile (``thesis run --profile``),
    which picks the parameter file."""
    n_transitions: int | None = None
    """Data-set size override (transitions)."""
    paper_compat: bool = False
    """Run everything with the authors' behaviours: a_{t-1} tokens, left-padded time-steps,
    last sub-goal = state 0 (``compat_dataset`` measures them beside the default instead)."""
    progress: bool = False
    """Progress bars of the runs."""

    def __post_init__(self) -> None:
        from thesis_lib.data import DATASET_SIZES  # lazy: gymnasium
        from thesis_lib.seq.registry import check_methods  # lazy: torch

        for name in (
            "datasets",
            "methods",
            "seeds",
            "extra_seeds",
            "extra_seed_datasets",
            "compat_methods",
        ):
            value = getattr(self, name)
            if isinstance(value, str):
                raise ValueError(f"Expect `{name}` to be a list, got the string {value!r}.")
            setattr(self, name, list(value))
        if not self.datasets:
            raise ValueError("Expect at least one data set in `datasets`, e.g. ['hopper/medium'].")
        # the defaults follow `datasets` (e.g. -p datasets '["D4RL/door/human-v2"]' alone);
        # a list or data set the user names must be in `datasets`
        if self.extra_seed_datasets == list(_EXTRA_SEED_DEFAULT):
            self.extra_seed_datasets = [d for d in _EXTRA_SEED_DEFAULT if d in self.datasets]
        if self.compat_dataset == _COMPAT_DEFAULT and _COMPAT_DEFAULT not in self.datasets:
            self.compat_dataset = None
        if self.compat_dataset and self.compat_dataset not in self.datasets:
            raise ValueError(
                f"compat_dataset '{self.compat_dataset}' is not in datasets "
                f"({', '.join(self.datasets)}); name one of them, or none (compat_dataset=None)."
            )
        for d in (
            self.datasets
            + self.extra_seed_datasets
            + ([self.compat_dataset] if self.compat_dataset else [])
        ):
            split_dataset(d)
        for d in self.extra_seed_datasets:
            if d not in self.datasets:
                raise ValueError(
                    f"extra_seed_datasets entry '{d}' is not in datasets ({', '.join(self.datasets)}); "
                    "list only data sets of `datasets`, or none (extra_seed_datasets=[])."
                )
        check_methods(self.methods, METHODS)
        check_methods(self.compat_methods, METHODS)
        if self.dataset_size not in DATASET_SIZES:
            raise ValueError(
                f"Unknown dataset_size {self.dataset_size!r}. Valid: {', '.join(DATASET_SIZES)}."
            )
        if (
            self.iterations < 1
            or self.eval_every < 1
            or self.eval_episodes < 1
            or self.batch_size < 1
        ):
            raise ValueError(
                f"Expect iterations, eval_every, eval_episodes and batch_size >= 1, got {self.iterations}, "
                f"{self.eval_every}, {self.eval_episodes}, {self.batch_size}."
            )

    def seeds_for(self, dataset: str) -> list[int]:
        """The seeds run on ``dataset`` (``task/tier``): ``seeds`` plus ``extra_seeds`` where listed."""
        extra = self.extra_seeds if dataset in self.extra_seed_datasets else []
        return list(dict.fromkeys(self.seeds + extra))

    def arch(self, paper_compat: bool | None = None) -> ArchSpec:
        """The :class:`~thesis_lib.seq.registry.ArchSpec` of every method."""
        from thesis_lib.seq.registry import ArchSpec  # lazy: torch

        if paper_compat is None:
            return spec_from(self, ArchSpec)
        return spec_from(self, ArchSpec, paper_compat=bool(paper_compat))

    def train_spec(self, seed: int) -> TrainSpec:
        """The :class:`~thesis_lib.seq.runner.TrainSpec` of the run with ``seed``."""
        from thesis_lib.seq.runner import TrainSpec  # lazy: torch

        return spec_from(self, TrainSpec, seed=seed)

    def eval_spec(self) -> EvalSpec:
        """The :class:`~thesis_lib.seq.runner.EvalSpec` of every run."""
        from thesis_lib.seq.runner import EvalSpec  # lazy: torch

        return EvalSpec(episodes=self.eval_episodes, max_steps=self.max_eval_steps)
