"""The Decision Mamba chapter (thesis 5.3; notebook ``05_decision_mamba``): Tables 5.5, 5.6, Figs 5.3-5.6.

* :class:`Config`: the notebook's parameters; defaults are the smoke scale.
* :func:`run_parameter_counts`: the five models' sizes at the thesis's architecture.
* :func:`run_table_5_5`: every data set x seed x method at the chapter's architecture, trained
  and evaluated by the one offline runner (:func:`thesis_lib.seq.runner.run_offline`) as a
  resumable sweep (``results/05_decision_mamba/tasks``); RTG methods at the data set's max
  return, half of it and 10,000; :func:`run_sweeps`: the architectures of Figs 5.3, 5.5, 5.6
  (reusing the Table 5.5 runs where the architecture is the same).
* :func:`summarize_dm`: per method x data set x target x architecture x evaluation mode, the
  thesis's metric (best evaluation during training, mean +- std over seeds) and the final
  checkpoint's.
* :func:`compare_table_5_5`, :func:`compare_win_counts_5_5`: Table 5.5 beside the thesis's,
  and the "wins out of N settings" the thesis quotes (5.3.3).
* :func:`run_table_5_6`, :func:`compare_table_5_6`, :func:`run_timing_ratios`: Table 5.6
  (train ms/iteration, inference ms/step) plus the recurrent-step inference the thesis did not
  have, and the ratios to DT.
* :func:`plot_sweep` (Figs 5.3, 5.5, 5.6) and :func:`plot_methods` (Fig 5.4).

Used in: Decision Mamba chapter (thesis 5.3; Tables 5.5, 5.6; Figs 5.3-5.6).
"""

from __future__ import annotations

import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import asdict, dataclass, field
from typing import Any, Literal, NamedTuple

import numpy as np
import pandas as pd
import torch
from tqdm.auto import tqdm

from thesis_lib.chapters.hdt import STUDY_COLUMNS as HDT_STUDY_COLUMNS
from thesis_lib.seq.evaluation import evaluate, target_returns
from thesis_lib.seq.registry import LEGACY_INIT, ArchSpec, build_model, check_methods
from thesis_lib.seq.runner import EvalSpec, TrainSpec, run_offline
from thesis_lib.seq.subgoals import subgoal_fn
from thesis_lib.seq.trainer import TrainConfig, Trainer

CHAPTER = "05_decision_mamba"

__all__ = [
    "DM_METHODS",
    "METRICS",
    "THESIS_METHOD",
    "WIN_COMPARISONS",
    "Arch",
    "Config",
    "compare_table_5_5",
    "compare_table_5_6",
    "compare_win_counts_5_5",
    "eval_mode_effect",
    "format_table_5_5",
    "load_datasets",
    "offline_task",
    "parse_arch",
    "plot_methods",
    "plot_sweep",
    "run_parameter_counts",
    "run_sweeps",
    "run_table_5_5",
    "run_table_5_6",
    "run_timing_ratios",
    "study_summary_dm",
    "study_tasks",
    "study_timing",
    "summarize_dm",
    "thesis_labels_5_5",
    "timing_task",
]

DM_METHODS: tuple[str, ...] = ("DT", "HDT", "DM-RTG", "DM-noRTG", "HDM")
"""Our method names: DT (with RTG), HDT, DM with RTG, DM without RTG (DM-noRTG), HDM."""
THESIS_METHOD: dict[str, str] = {
    "DT": "DT",
    "HDT": "HDT",
    "DM-RTG": "DM_with_R",
    "DM-noRTG": "DM_without_R",
    "HDM": "HDM",
}
"""Our names -> the reference tables' (``table_5_5.csv``, ``table_5_6.csv``)."""
RTG_METHODS = ("DT", "DM-RTG")
HIERARCHICAL = ("HDT", "HDM")
MAMBA_METHODS = ("DM-RTG", "DM-noRTG", "HDM")
TARGETS = ("half", "max", "10k")
#: The two metrics: the thesis's (best evaluation during training) and the final checkpoint's.
METRICS: dict[str, str] = {"best during training (thesis)": "best", "final checkpoint": "final"}


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


STUDY_FILE_DEFAULTS: dict[str, Any] = {"init": LEGACY_INIT}
"""What a study file that does not name these fields ran with (the v1 studies, registered
before the transformers' ``init`` existed): :func:`thesis_lib.book.study.study_config`."""


@dataclass
class Config:
    """Parameters of the Decision Mamba chapter; defaults are the smoke scale.

    ``params/05_decision_mamba.smoke.yml`` equals these defaults; ``.full.yml`` holds the
    thesis's scale (5.3.3: batch 16, lr 1e-4, up to 1M iterations, evaluation every 1,000 on
    100 episodes, 4 seeds, 6 layers, d 128, K 20).

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
    init: Literal["auto", "normal", "original", "torch"] = "auto"
    """Initialisation of the transformers (DT, HDT): ``auto`` (the authors' ``original`` with
    ``paper_compat``, else ``normal``: every Linear and Embedding N(0, 0.02), as CORL's and
    Hugging Face's DT) or ``torch`` (PyTorch's defaults, the v1 studies'; a study file that
    names no ``init`` ran with it)."""
    device: str = "cpu"
    """Training device (``cpu``, ``cuda``, ``auto``)."""
    progress: bool = False
    """Progress bars of the runs."""

    def __post_init__(self) -> None:
        for name in ("methods", "sweep_methods"):
            check_methods(getattr(self, name), DM_METHODS)
        from thesis_lib.data.minari_sets import is_minari_id

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
        a = parse_arch(arch or self.arch)
        return ArchSpec(
            d_model=a.d_model,
            n_layers=a.n_layers,
            n_heads=self.n_heads,
            K=a.K,
            dropout=self.dropout,
            gated_mlp=self.gated_mlp,
            eval_mode=self.eval_mode,
            paper_compat=self.paper_compat,
            init=self.init,
        )

    def train_spec(self, seed: int) -> TrainSpec:
        """The :class:`~thesis_lib.seq.runner.TrainSpec` of the run with ``seed``."""
        return TrainSpec(
            seed=seed,
            iterations=self.iterations,
            batch_size=self.batch_size,
            lr=self.lr,
            warmup_steps=self.warmup_steps,
            eval_every=self.eval_every,
            device=self.device,
            progress=self.progress,
        )


# ----------------------------------------------------------------------------------------------
# The runs


def split_dataset(name: str) -> tuple[str, str]:
    """``"hopper/medium"`` -> ``("hopper", "medium")``; a real Minari id keeps its task and tier
    (``"D4RL/antmaze/umaze-diverse-v1"`` -> ``("antmaze", "umaze-diverse")``)."""
    from thesis_lib.data.minari_sets import dataset_key

    return dataset_key(name)


def load_datasets(
    names: list[str], cfg: Config, data: Mapping[tuple[str, str], Any] | None = None
) -> dict[tuple[str, str], Any]:
    """``{(task, tier): OfflineDataset}`` of ``names`` (those not already in ``data``).

    A real Minari id (``D4RL/kitchen/mixed-v2``) is read from its download and keyed by its
    task and tier (``("kitchen", "mixed")``).

    Used in: Decision Mamba chapter.

    Raises:
        FileNotFoundError: a Minari id not downloaded (the message names the id and where
            Minari looks).
    """
    from thesis_lib.data.minari_sets import open_dataset

    out = dict(data or {})
    for name in names:
        key = split_dataset(name)
        if key not in out:
            out[key] = open_dataset(name, cfg.dataset_size, cfg.n_transitions)
    return out


#: The columns of the curves (one row per evaluation and target).
CURVE_COLUMNS = [
    "method", "task", "tier", "seed", "arch", "n_layers", "d_model", "K", "eval_mode", "target",
    "target_return", "iteration", "return_mean", "return_std", "score_mean", "length_mean",
    "loss",
]  # fmt: skip


def offline_task(config: dict[str, Any]) -> list[dict[str, Any]]:
    """One sweep task: train and evaluate ``config["method"]`` on ``config["dataset"]``.

    ``config`` holds ``method, dataset ("task/tier" or a Minari id), dataset_size,
    n_transitions`` and the ``arch``, ``train``, ``eval`` specs as dicts. Returns
    :data:`CURVE_COLUMNS` rows.

    Used in: Decision Mamba chapter (through :func:`run_table_5_5`, :func:`run_sweeps`).
    """
    from thesis_lib.data.minari_sets import env_name, open_dataset

    task, tier = split_dataset(config["dataset"])
    data = open_dataset(config["dataset"], config["dataset_size"], config["n_transitions"])
    ev = dict(config["eval"])
    ev["targets"] = tuple(ev["targets"])
    rows = run_offline(
        config["method"],
        data,
        ArchSpec.from_task(config["arch"]),
        TrainSpec(**config["train"]),
        EvalSpec(**ev),
        task=env_name(config["dataset"]),
    )
    where = {"task": task, "tier": tier}
    return [{k: where[k] if k in where else r[k] for k in CURVE_COLUMNS} for r in rows]


def _task(cfg: Config, method: str, dataset: str, seed: int, arch: Any, ev: EvalSpec) -> Any:
    from thesis_lib.sweep import Task

    return Task(
        offline_task,
        {
            "method": method,
            "dataset": dataset,
            "dataset_size": cfg.dataset_size,
            "n_transitions": cfg.n_transitions,
            "arch": cfg.arch_spec(arch).task_dict(),
            "train": asdict(cfg.train_spec(seed)),
            "eval": asdict(ev),
        },
    )


def _run(cfg: Config, tasks: list[Any], desc: str) -> pd.DataFrame:
    from thesis_lib.paths import results_dir
    from thesis_lib.sweep import run_tasks

    if not tasks:
        return pd.DataFrame(columns=CURVE_COLUMNS)
    rows = run_tasks(tasks, store=results_dir(CHAPTER) / "tasks", desc=desc, progress=cfg.progress)
    return rows.drop(columns="task_key").reset_index(drop=True)


def run_table_5_5(cfg: Config) -> pd.DataFrame:
    """Every data set x seed x method of ``cfg`` at ``cfg.arch``: one row per evaluation and target.

    A resumable sweep (store ``results/05_decision_mamba/tasks``).

    Used in: Decision Mamba chapter (Table 5.5, Fig 5.4).
    """
    ev = EvalSpec(
        episodes=cfg.eval_episodes,
        max_steps=cfg.max_eval_steps,
        targets=("max", "half", "10k"),
        compare_eval_modes=cfg.compare_eval_modes,
    )
    tasks = [
        _task(cfg, m, d, s, cfg.arch, ev)
        for d in cfg.datasets
        for s in cfg.seeds
        for m in cfg.methods
    ]
    return _run(cfg, tasks, "Table 5.5")


def run_sweeps(cfg: Config, reuse: pd.DataFrame | None = None) -> pd.DataFrame:
    """The architecture sweeps of Figs 5.3 (HDM), 5.5 (DM) and 5.6 (DM with RTG, at the max target only).

    Runs already in ``reuse`` (e.g. :func:`run_table_5_5`'s, same method, data set, seed and
    architecture) are taken from there instead of trained again.

    Used in: Decision Mamba chapter (Figs 5.3, 5.5, 5.6).
    """
    ev = EvalSpec(episodes=cfg.eval_episodes, max_steps=cfg.max_eval_steps, targets=("max",))
    frames, tasks = [], []
    for d in cfg.sweep_datasets:
        task, tier = split_dataset(d)
        for a in map(parse_arch, cfg.sweep_archs):
            for s in cfg.seeds:
                for m in cfg.sweep_methods:
                    if reuse is not None and len(reuse):
                        hit = reuse[
                            (reuse.method == m)
                            & (reuse.task == task)
                            & (reuse.tier == tier)
                            & (reuse.seed == s)
                            & (reuse.arch == a.label)
                        ]
                        if len(hit):
                            frames.append(hit)
                            continue
                    tasks.append(_task(cfg, m, d, s, a, ev))
    frames.append(_run(cfg, tasks, "Figs 5.3, 5.5, 5.6"))
    return pd.concat([f for f in frames if len(f)], ignore_index=True)


def run_parameter_counts(
    state_dim: int = 11, act_dim: int = 3, K: int = 20, d_model: int = 128, n_layers: int = 6
) -> pd.DataFrame:
    """Trainable parameters of DT, HDT, DM (with and without the gated MLP) and HDM at one size.

    Used in: Decision Mamba chapter (the models' sizes at the thesis's 6/128/20).
    """
    from thesis_lib.seq import (
        HDM,
        HDT,
        DecisionMamba,
        DecisionTransformer,
        DMConfig,
        DTConfig,
        HDMConfig,
        HDTConfig,
    )

    size: dict[str, Any] = dict(
        state_dim=state_dim, act_dim=act_dim, K=K, d_model=d_model, n_layers=n_layers
    )

    def n_params(model: torch.nn.Module) -> int:
        return sum(p.numel() for p in model.parameters())

    models = {
        f"DT ({n_layers} GPT blocks)": lambda: DecisionTransformer(DTConfig(**size)),
        f"HDT (2 x {n_layers} GPT blocks)": lambda: HDT(HDTConfig(**size)),
        "DM, gated MLP (authors' later code)": lambda: DecisionMamba(DMConfig(**size)),
        "DM, plain Mamba blocks": lambda: DecisionMamba(DMConfig(**size, gated_mlp=False)),
        "HDM, gated MLP": lambda: HDM(HDMConfig(**size)),
    }
    return pd.DataFrame([{"model": k, "parameters": n_params(f())} for k, f in models.items()])


# ----------------------------------------------------------------------------------------------
# Summaries and the thesis's tables


def summarize_dm(curves: pd.DataFrame) -> pd.DataFrame:
    """Both metrics per ``method, task, tier, target, arch, eval_mode`` from :func:`run_table_5_5` rows.

    * ``best_mean``, ``best_std``: the thesis's metric, each run's highest evaluation average
      during training, mean and std over seeds;
    * ``final_mean``, ``final_std``: the last evaluation of each run, over seeds; ``n_seeds``.

    Evaluations in a non-default ``eval_mode`` (only of the final model) count under that mode.

    Used in: Decision Mamba chapter.
    """
    keys = ["method", "task", "tier", "target", "arch", "eval_mode"]
    per_run = curves.sort_values("iteration").groupby(keys + ["seed"], sort=False)
    runs = pd.DataFrame(
        {"best": per_run["return_mean"].max(), "final": per_run["return_mean"].last()}
    ).reset_index()
    g = runs.groupby(keys, sort=False)
    out = pd.DataFrame({
        "best_mean": g["best"].mean(), "best_std": g["best"].std(ddof=0),
        "final_mean": g["final"].mean(), "final_std": g["final"].std(ddof=0),
        "n_seeds": g["seed"].nunique(),
    }).reset_index()  # fmt: skip
    order = {m: i for i, m in enumerate(DM_METHODS)} | {
        t: i for i, t in enumerate((*TARGETS, "none"))
    }
    return out.sort_values(
        ["task", "tier", "arch", "method", "target"],
        key=lambda c: c.map(order) if c.name in ("method", "target") else c,
    ).reset_index(drop=True)


_TASKS_5_5 = {
    "hopper": "Hopper",
    "walker2d": "Walker2D",
    "halfcheetah": "HalfCheetah",
    "ant": "Ant",
}
_TASKS_5_6 = {
    "hopper": "Hopper",
    "walker2d": "Walker2d",
    "halfcheetah": "HalfCheetah",
    "ant": "Ant",
    "maze2d": "Maze2d",
    "antmaze": "Antmaze",
    "kitchen": "Kitchen",
}


def thesis_labels_5_5(task: str, tier: str) -> tuple[str, str]:
    """``(task, dataset)`` as Table 5.5 prints them.

    Example:
        >>> thesis_labels_5_5("maze2d-umaze", "expert")
        ('Maze2D', 'umaze')
        >>> thesis_labels_5_5("walker2d", "medium-replay")
        ('Walker2D', 'medium-replay')
        >>> thesis_labels_5_5("antmaze", "umaze-diverse")
        ('Antmaze', 'umaze-diverse')
    """
    if task.startswith("maze2d-"):
        return "Maze2D", task.split("-", 1)[1]
    if task.startswith("antmaze-"):
        return "Antmaze", task.split("-", 1)[1] + (
            "" if tier in ("expert", "play", "") else f"-{tier}"
        )
    if task == "kitchen":
        return "Kitchen", tier
    if task == "antmaze":  # a real Minari set, D4RL/antmaze/<tier>
        return "Antmaze", tier
    return _TASKS_5_5.get(task, task), tier


def compare_table_5_5(
    summary: pd.DataFrame, eval_mode: str = "recurrent", differs: Any = None
) -> pd.DataFrame:
    """Table 5.5 beside the thesis's, for both metrics.

    DT and HDT rows are windowed (they have no other mode); DM/HDM rows use ``eval_mode``.

    Args:
        summary: :func:`summarize_dm` output at the Table 5.5 architecture (one ``arch``).
        eval_mode: Which DM/HDM evaluation to show.
        differs: What differs, for every row (see :func:`thesis_lib.book.compare_with_paper`).

    Returns:
        ``metric, method, task, dataset, desired_return, paper, paper_std, ours, ours_std,
        difference, what differs`` (``method`` as the reference table names it).
    """
    from thesis_lib.book import compare_with_paper, load_reference

    s = summary[(summary.eval_mode == eval_mode) | ~summary.method.isin(MAMBA_METHODS)].copy()
    lab = [thesis_labels_5_5(t, r) for t, r in zip(s.task, s.tier)]
    s["task"], s["dataset"] = [a for a, _ in lab], [b for _, b in lab]
    s["method"] = s["method"].map(THESIS_METHOD)
    s["desired_return"] = s["target"]
    ref = load_reference("5.5")
    frames = []
    for metric, col in METRICS.items():
        ours = s.assign(ours=s[f"{col}_mean"])
        c = compare_with_paper(
            "5.5",
            ours,
            on=["task", "dataset", "method", "desired_return"],
            value="ours",
            paper_value="return_mean",
            differs=differs,
        )
        c = c.merge(
            ref.rename(columns={"return_std": "paper_std"})[
                ["task", "dataset", "method", "desired_return", "paper_std"]
            ].astype({"desired_return": str}),
            on=["task", "dataset", "method", "desired_return"],
            how="left",
        )
        std = ours.assign(ours_std=ours[f"{col}_std"])[
            ["task", "dataset", "method", "desired_return", "ours_std"]
        ]
        c = c.merge(
            std.astype({"desired_return": str}),
            on=["task", "dataset", "method", "desired_return"],
            how="left",
        )
        frames.append(c.assign(metric=metric))
    out = pd.concat(frames, ignore_index=True)
    return out[
        [
            "metric",
            "method",
            "task",
            "dataset",
            "desired_return",
            "paper",
            "paper_std",
            "ours",
            "ours_std",
            "difference",
            "what differs",
        ]
    ]


#: The comparisons the thesis quotes in 5.3.3 and its counts (out of 27 settings).
WIN_COMPARISONS: dict[str, tuple[tuple[str, str], tuple[str, str], int]] = {
    "DM wo/ R beats DT (all three targets)": (("DM_without_R", "none"), ("DT", "all"), 15),
    "HDM beats HDT": (("HDM", "none"), ("HDT", "none"), 22),
    "DM wo/ R beats DT at 10k": (("DM_without_R", "none"), ("DT", "10k"), 17),
}


def _wins(wide: pd.DataFrame, a: tuple[str, str], b: tuple[str, str]) -> tuple[int, int]:
    if a not in wide.columns:
        return 0, 0
    if b[1] == "all":
        cols = [(b[0], t) for t in TARGETS if (b[0], t) in wide.columns]
        if not cols:
            return 0, 0
        sub = wide[[a, *cols]].dropna()
        return int((sub[a].values[:, None] > sub[cols].values).all(axis=1).sum()), len(sub)
    if b not in wide.columns:
        return 0, 0
    sub = wide[[a, b]].dropna()
    return int((sub[a] > sub[b]).sum()), len(sub)


def compare_win_counts_5_5(table: pd.DataFrame) -> pd.DataFrame:
    """The thesis's "wins out of N settings" (5.3.3): quoted, recounted from its Table 5.5, and ours.

    Args:
        table: :func:`compare_table_5_5` output.

    Returns:
        One row per comparison and metric: ``comparison, metric, thesis text, thesis table
        (all settings), thesis table (our settings), ours`` as ``"wins/settings"``.
    """
    from thesis_lib.book import load_reference

    ref = load_reference("5.5")
    paper_all = ref.pivot_table(
        index=["task", "dataset"], columns=["method", "desired_return"], values="return_mean"
    )
    rows = []
    for metric in table.metric.unique():
        t = table[table.metric == metric]
        ours = t.pivot_table(
            index=["task", "dataset"], columns=["method", "desired_return"], values="ours"
        )
        ran = t.dropna(subset=["ours"])[["task", "dataset"]].drop_duplicates()
        keys = set(zip(ran.task, ran.dataset))
        paper_ours = paper_all[[k in keys for k in paper_all.index]]
        for name, (a, b, quoted) in WIN_COMPARISONS.items():
            w_all, n_all = _wins(paper_all, a, b)
            w_sub, n_sub = _wins(paper_ours, a, b)
            w_ours, n_ours = _wins(ours, a, b)
            rows.append(
                {
                    "comparison": name,
                    "metric": metric,
                    "thesis text": f"{quoted}/27",
                    "thesis table (all settings)": f"{w_all}/{n_all}",
                    "thesis table (our settings)": f"{w_sub}/{n_sub}",
                    "ours": f"{w_ours}/{n_ours}",
                }
            )
    return pd.DataFrame(rows)


# ----------------------------------------------------------------------------------------------
# Table 5.6: time


def _timing_env(task: str) -> Any:
    """One environment of ``task`` (a Minari id: its recorded evaluation environment)."""
    import gymnasium as gym

    from thesis_lib.data import make_env
    from thesis_lib.data.minari_sets import is_minari_id, make_minari_env

    make = make_minari_env if is_minari_id(task) else make_env
    return gym.vector.SyncVectorEnv([lambda: make(task)])


def run_table_5_6(cfg: Config, data: Mapping[tuple[str, str], Any] | None = None) -> pd.DataFrame:
    """Table 5.6: ms per training iteration and per inference step of each method, at ``cfg.timing_arch``.

    * train: one gradient step of the :class:`~thesis_lib.seq.trainer.Trainer` (sampling the
      batch of ``timing_batch_size`` windows included; HDT/HDM: both levels), timed
      ``timing_train_iters`` times after one untimed step;
    * inference: an episode of at most ``timing_infer_steps`` steps in one environment through
      :func:`~thesis_lib.seq.evaluation.evaluate` (building the history, the action, the
      environment's transition), as ms per step, ``timing_infer_episodes`` episodes after one
      untimed. DT/HDT re-run the window (``window``); DM/HDM are timed re-running the window, as
      the authors' code, and with the recurrent step (``recurrent``, not in the thesis).

    The models are untrained (time does not depend on the weights, only on episode lengths).

    Used in: Decision Mamba chapter (Table 5.6).

    Returns:
        One row per data set x method x phase x mode: ``task, tier, method, phase, mode,
        time_ms_mean, time_ms_std, n``.
    """
    from thesis_lib.data import SequenceDataset
    from thesis_lib.data.minari_sets import env_name

    arch = cfg.arch_spec(cfg.timing_arch)
    data = load_datasets(cfg.timing_datasets, cfg, data)
    rows = []
    for name in cfg.timing_datasets:
        task, tier = split_dataset(name)
        for method in tqdm(cfg.methods, desc=f"timing {name}", disable=not cfg.progress):
            sg = subgoal_fn(cfg.paper_compat) if method in HIERARCHICAL else None
            seq = SequenceDataset(
                data[(task, tier)],
                K=arch.K,
                subgoal_fn=sg,
                paper_compat=cfg.paper_compat,
                seed=cfg.seed,
            )
            venv = _timing_env(env_name(name))
            torch.manual_seed(cfg.seed)
            model: Any = build_model(
                method, seq, arch, float(np.max(venv.single_action_space.high))
            )
            trainer = Trainer(
                model,
                seq,
                TrainConfig(
                    iterations=10**9,
                    batch_size=cfg.timing_batch_size,
                    lr=cfg.lr,
                    warmup_steps=cfg.warmup_steps,
                    progress=False,
                    device=cfg.device,
                ),
            )
            times = []
            for i in range(cfg.timing_train_iters + 1):
                t0 = time.perf_counter()
                trainer.step()
                if i:
                    times.append((time.perf_counter() - t0) * 1e3)
            rows.append(
                {
                    "task": task,
                    "tier": tier,
                    "method": method,
                    "phase": "train",
                    "mode": "",
                    "time_ms_mean": float(np.mean(times)),
                    "time_ms_std": float(np.std(times)),
                    "n": len(times),
                }
            )
            target = target_returns(data[(task, tier)])["max"] if method in RTG_METHODS else None
            modes = ("window", "recurrent") if method in MAMBA_METHODS else ("window",)
            try:
                for mode in modes:
                    if method in MAMBA_METHODS:
                        model.config.eval_mode = mode
                    per_step = []
                    for i in range(cfg.timing_infer_episodes + 1):
                        t0 = time.perf_counter()
                        res = evaluate(
                            model,
                            venv,
                            1,
                            target_return=target,
                            dataset=seq,
                            seed=cfg.seed + i,
                            max_steps=cfg.timing_infer_steps,
                        )
                        if i:
                            per_step.append(
                                (time.perf_counter() - t0) * 1e3 / max(int(res.lengths[0]), 1)
                            )
                    rows.append(
                        {
                            "task": task,
                            "tier": tier,
                            "method": method,
                            "phase": "inference",
                            "mode": mode,
                            "time_ms_mean": float(np.mean(per_step)),
                            "time_ms_std": float(np.std(per_step)),
                            "n": len(per_step),
                        }
                    )
            finally:
                venv.close()
    return pd.DataFrame(rows)


def compare_table_5_6(timing: pd.DataFrame, differs: Any = None) -> pd.DataFrame:
    """Table 5.6 beside the thesis's GPU numbers.

    The thesis's inference times re-ran the window, so they sit beside our ``window`` rows;
    our ``recurrent`` rows are added as ``<method> (recurrent step)``, not in the thesis.

    Used in: Decision Mamba chapter (Table 5.6).
    """
    from thesis_lib.book import compare_with_paper

    t = timing.copy()
    t["env"] = [_TASKS_5_6.get(task.split("-")[0], task) for task in t.task]
    t["method"] = [
        THESIS_METHOD[m] + (" (recurrent step)" if mode == "recurrent" else "")
        for m, mode in zip(t.method, t["mode"])
    ]
    out = compare_with_paper(
        "5.6", t, on=["env", "phase", "method"], value="time_ms_mean", differs=differs
    )
    std = t[["env", "phase", "method", "time_ms_std"]].rename(columns={"time_ms_std": "ours_std"})
    return out.merge(std, on=["env", "phase", "method"], how="left")


def run_timing_ratios(timing: pd.DataFrame) -> pd.DataFrame:
    """Table 5.6 as ratios: each method's times over DT's, and windowed over recurrent acting.

    Args:
        timing: :func:`run_table_5_6` output.

    Returns:
        One row per ``task, method``: the times (ms) per phase (and mode) and the ratios
        ``train / DT``, ``inference (window) / DT``, ``inference (recurrent) / DT`` (DT windowed)
        and ``window / recurrent``.

    Used in: Decision Mamba chapter (Table 5.6).
    """
    t = timing.assign(
        key=[p if not m else f"{p} ({m})" for p, m in zip(timing["phase"], timing["mode"])]
    )
    wide = t.pivot_table(index=["task", "method"], columns="key", values="time_ms_mean")
    dt = wide.xs("DT", level="method")
    ratios = wide.copy()
    tasks = wide.index.get_level_values("task")
    for col in ("train", "inference (window)"):
        ratios[f"{col} / DT"] = wide[col] / dt[col].reindex(tasks).values
    if "inference (recurrent)" in wide:
        ratios["inference (recurrent) / DT"] = (
            wide["inference (recurrent)"] / dt["inference (window)"].reindex(tasks).values
        )
        ratios["window / recurrent"] = wide["inference (window)"] / wide["inference (recurrent)"]
    return ratios.reset_index()


# ----------------------------------------------------------------------------------------------
# Figures


def _max_returns(data: Mapping[tuple[str, str], Any]) -> dict[tuple[str, str], float]:
    return {k: target_returns(v)["max"] for k, v in data.items()}


def _normalised(summary: pd.DataFrame, data: Mapping[tuple[str, str], Any], col: str) -> pd.Series:
    best = _max_returns(data)
    scale = [best.get((t, r), np.nan) for t, r in zip(summary.task, summary.tier)]
    return summary[col] / np.where(np.asarray(scale) > 0, scale, np.nan)


def _one_mode(summary: pd.DataFrame, eval_mode: str) -> pd.DataFrame:
    return summary[(summary.eval_mode == eval_mode) | ~summary.method.isin(MAMBA_METHODS)]


def _grouped_bars(
    ax: Any,
    s: pd.DataFrame,
    key: str,
    groups: Sequence[str],
    sets: Sequence[tuple[str, str]],
    label: Callable[[str], str],
) -> None:
    """One bar per ``s[key]`` group and data set (``value`` with ``err`` bars), grouped by
    data set: what Figs 5.3-5.6 share."""
    width = 0.8 / max(len(groups), 1)
    for i, grp in enumerate(groups):
        g = s[s[key] == grp].set_index(["task", "tier"]).reindex(sets)
        x = np.arange(len(sets)) + i * width
        ax.bar(x, g["value"], width, yerr=g["err"].fillna(0), label=label(grp), capsize=2)
    ax.set_xticks(
        np.arange(len(sets)) + width * (len(groups) - 1) / 2, [f"{t}\n{r}" for t, r in sets]
    )
    ax.set_ylabel("return / data set max")
    ax.legend(fontsize=8)


def plot_sweep(
    summary: pd.DataFrame,
    method: str,
    data: Mapping[tuple[str, str], Any],
    metric: str = "best",
    ax: Any = None,
    eval_mode: str = "recurrent",
) -> Any:
    """Figs 5.3 (HDM), 5.5 (DM), 5.6 (DM with RTG, at the max target): one bar per architecture.

    Bars are the metric (``best`` or ``final`` mean over seeds) divided by the data set's
    maximum return, as the thesis scales its bars; error bars are the std over seeds. DM/HDM
    rows are those evaluated in ``eval_mode``.

    Used in: Decision Mamba chapter (Figs 5.3, 5.5, 5.6).
    """
    import matplotlib.pyplot as plt

    summary = _one_mode(summary, eval_mode)
    s = summary[(summary.method == method) & summary.target.isin(["none", "max"])].copy()
    s["value"] = _normalised(s, data, f"{metric}_mean")
    s["err"] = _normalised(s, data, f"{metric}_std")
    sets = list(dict.fromkeys(zip(s.task, s.tier)))
    archs = sorted(s.arch.unique(), key=lambda a: tuple(int(x[1:]) for x in a.split()))
    if ax is None:
        _, ax = plt.subplots(figsize=(max(5, 1.6 * len(sets) * len(archs) / 2), 3.5))
    _grouped_bars(ax, s, "arch", archs, sets, str)
    ax.set_title(
        f"{method}: architectures ({'best during training' if metric == 'best' else 'final checkpoint'})"
    )
    return ax


def plot_methods(
    summary: pd.DataFrame,
    data: Mapping[tuple[str, str], Any],
    metric: str = "best",
    ax: Any = None,
    eval_mode: str = "recurrent",
) -> Any:
    """Fig 5.4: the five methods side by side per data set (DT and DM with RTG at the max target).

    Used in: Decision Mamba chapter (Fig 5.4).
    """
    import matplotlib.pyplot as plt

    summary = _one_mode(summary, eval_mode)
    s = summary[summary.target.isin(["none", "max"])].copy()
    s["value"] = _normalised(s, data, f"{metric}_mean")
    s["err"] = _normalised(s, data, f"{metric}_std")
    sets = list(dict.fromkeys(zip(s.task, s.tier)))
    methods = [m for m in DM_METHODS if m in set(s.method)]
    if ax is None:
        _, ax = plt.subplots(figsize=(max(5, 2.2 * len(sets)), 3.5))
    _grouped_bars(ax, s, "method", methods, sets, lambda m: THESIS_METHOD[m].replace("_", " "))
    ax.set_title(
        f"Five methods ({'best during training' if metric == 'best' else 'final checkpoint'})"
    )
    return ax


def eval_mode_effect(summary: pd.DataFrame) -> pd.DataFrame:
    """Final-checkpoint return of each DM/HDM under both evaluation modes, side by side.

    Used in: Decision Mamba chapter (recurrent vs windowed acting).
    """
    s = summary[summary.method.isin(MAMBA_METHODS)]
    wide = s.pivot_table(
        index=["method", "task", "tier", "target", "arch"],
        columns="eval_mode",
        values="final_mean",
        aggfunc="first",
    )
    wide = wide.reset_index()
    if {"recurrent", "window"} <= set(wide.columns):
        wide["recurrent - window"] = wide["recurrent"] - wide["window"]
    return wide


def format_table_5_5(
    table: pd.DataFrame, metric: str = "best during training (thesis)"
) -> pd.DataFrame:
    """Table 5.5 laid out as the thesis prints it: one row per setting, one column per method/target,
    each cell ``"ours ± std  (thesis ± std)"``; settings we did not run are left out.

    Used in: Decision Mamba chapter (Table 5.5).
    """
    t = table[(table.metric == metric)].dropna(subset=["ours"]).copy()
    order = [
        ("DT", "half"),
        ("DT", "max"),
        ("DT", "10k"),
        ("HDT", "none"),
        ("DM_with_R", "half"),
        ("DM_with_R", "max"),
        ("DM_with_R", "10k"),
        ("DM_without_R", "none"),
        ("HDM", "none"),
    ]

    def cell(r: pd.Series) -> str:
        paper = "" if pd.isna(r.paper) else f"  ({r.paper:.1f} ± {r.paper_std:.1f})"
        return f"{r.ours:.1f} ± {0.0 if pd.isna(r.ours_std) else r.ours_std:.1f}{paper}"

    t["cell"] = t.apply(cell, axis=1)
    t["column"] = [f"{m} {d}" if d != "none" else m for m, d in zip(t.method, t.desired_return)]
    wide = t.pivot_table(
        index=["task", "dataset"], columns="column", values="cell", aggfunc="first"
    )
    cols = [f"{m} {d}" if d != "none" else m for m, d in order]
    return wide[[c for c in cols if c in wide.columns]]


#: The columns of the study's rows: a run's (:func:`thesis_lib.chapters.hdt.study_run`, the
#: HDT chapter's ``STUDY_COLUMNS``) and a C6 timing's (:func:`timing_task`); the study engine
#: checks the study file's metrics against them.
STUDY_COLUMNS = [
    *HDT_STUDY_COLUMNS,
    "arch", "train_ms", "act_ms_window", "act_ms_recurrent", "train_per_s", "act_per_s_window",
    "act_per_s_recurrent", "act_per_s",
]  # fmt: skip

#: The Config fields a C6 timing task carries (its config, so its key).
_TIMING_FIELDS = (
    "timing_arch",
    "timing_batch_size",
    "timing_train_iters",
    "timing_infer_steps",
    "timing_infer_episodes",
    "dataset_size",
    "n_transitions",
)


def study_tasks(cfg: Config) -> list[Any]:
    """The tasks of the chapter's pre-registered study (``params/05_decision_mamba.study.yml``).

    Every data set x seed x method of ``cfg`` at ``cfg.arch``, each reduced to one row by
    :func:`thesis_lib.chapters.hdt.study_run`, and the timings of C6 (:func:`timing_task`)
    on every ``timing_datasets`` x seed x method. A DT or HDT run here has the same task key as
    the HDT chapter's study run of the same settings, so the study file's ``reuse: [04_hdt]``
    copies it instead of training it again.

    Used in: ``thesis study 05_decision_mamba``.
    """
    from thesis_lib.chapters.hdt import study_task
    from thesis_lib.sweep import Task

    arch = cfg.arch_spec()
    tasks = [
        study_task(cfg, m, d, s, arch) for d in cfg.datasets for s in cfg.seeds for m in cfg.methods
    ]
    timing = {k: getattr(cfg, k) for k in _TIMING_FIELDS}
    tasks += [
        Task(timing_task, {"method": m, "dataset": d, "seed": s, **timing})
        for d in cfg.timing_datasets
        for s in cfg.seeds
        for m in cfg.methods
    ]
    return tasks


def timing_task(config: dict[str, Any]) -> list[dict[str, Any]]:
    """One C6 study task: Table 5.6's timings of one method on one environment, one repeat.

    ``config`` holds ``method, dataset, seed`` (the repeat: model init and episode starts) and
    the ``timing_*``, ``dataset_size`` and ``n_transitions`` fields of :class:`Config`. Returns
    one row: ``method, setting ("<task/tier> (timing)"), seed, scale``, the ms per training
    iteration (``train_ms``) and per action (``act_ms_window``; DM/HDM also
    ``act_ms_recurrent``), and the speeds ``train_per_s``, ``act_per_s_window``,
    ``act_per_s_recurrent`` and ``act_per_s`` (each method's own way: DM/HDM recurrent,
    DT/HDT window); higher is better, as the study's comparisons read them.

    Used in: ``thesis study 05_decision_mamba`` (C6).
    """
    cfg = Config(
        methods=[config["method"]],
        seed=int(config["seed"]),
        timing_datasets=[config["dataset"]],
        **{k: config[k] for k in _TIMING_FIELDS},
    )
    t = run_table_5_6(cfg)
    ms = {
        ("train" if p == "train" else f"act_{m}"): float(v)
        for p, m, v in zip(t.phase, t["mode"], t.time_ms_mean)
    }
    row: dict[str, Any] = {
        "method": config["method"],
        "setting": f"{config['dataset']} (timing)",
        "seed": int(config["seed"]),
        "scale": config.get("scale", "study"),
        "arch": config["timing_arch"],
        "train_ms": ms["train"],
        "act_ms_window": ms["act_window"],
        "act_ms_recurrent": ms.get("act_recurrent", np.nan),
    }
    row["train_per_s"] = 1e3 / row["train_ms"]
    row["act_per_s_window"] = 1e3 / row["act_ms_window"]
    row["act_per_s_recurrent"] = 1e3 / row["act_ms_recurrent"]
    own = "act_ms_recurrent" if config["method"] in MAMBA_METHODS else "act_ms_window"
    row["act_per_s"] = 1e3 / row[own]  # each method acting its own way (DM/HDM: recurrent)
    return [row]


def study_summary_dm(rows: pd.DataFrame, eval_mode: str = "recurrent") -> pd.DataFrame:
    """The study's score rows as :func:`summarize_dm` output (raw returns), so that
    :func:`compare_table_5_5` sets the thesis's Table 5.5 beside them.

    Used in: Decision Mamba chapter ("Evidence at study scale").
    """
    keys = ["method", "task", "tier", "target"]
    runs = rows.dropna(subset=["return_final"]) if "return_final" in rows else rows.iloc[:0]
    if runs.empty:
        cols = ["best_mean", "best_std", "final_mean", "final_std", "n_seeds"]
        return pd.DataFrame(columns=[*keys, "arch", "eval_mode", *cols])
    g = runs.groupby(keys, sort=False)
    out = pd.DataFrame({
        "best_mean": g["return_best"].mean(), "best_std": g["return_best"].std(ddof=0),
        "final_mean": g["return_final"].mean(), "final_std": g["return_final"].std(ddof=0),
        "n_seeds": g["seed"].nunique(),
    }).reset_index()  # fmt: skip
    out["eval_mode"] = [eval_mode if m in MAMBA_METHODS else "window" for m in out.method]
    out["arch"] = "study"
    return out


def study_timing(rows: pd.DataFrame) -> pd.DataFrame:
    """C6 from the study's timing rows: per environment and method, the mean ms per training
    iteration and per action (windowed; DM/HDM also recurrent) over the repeats, and each
    method's times over the DT's on the same environment.

    Used in: Decision Mamba chapter ("Evidence at study scale").
    """
    cols = ["train_ms", "act_ms_window", "act_ms_recurrent"]
    t = rows.dropna(subset=["train_ms"]) if "train_ms" in rows else rows.iloc[:0]
    if t.empty:
        return pd.DataFrame(columns=["setting", "method", *cols])
    out = t.groupby(["setting", "method"], sort=False)[cols].mean()
    out["repeats"] = t.groupby(["setting", "method"], sort=False)["seed"].nunique()
    dt = out.xs("DT", level="method") if "DT" in out.index.get_level_values("method") else None
    if dt is not None:
        envs = out.index.get_level_values("setting")
        out["train / DT"] = out["train_ms"].to_numpy() / dt["train_ms"].reindex(envs).to_numpy()
        out["act (window) / DT"] = (
            out["act_ms_window"].to_numpy() / dt["act_ms_window"].reindex(envs).to_numpy()
        )
        out["act (own way) / DT"] = (
            out["act_ms_recurrent"].fillna(out["act_ms_window"]).to_numpy()
            / dt["act_ms_window"].reindex(envs).to_numpy()
        )
    return out.reset_index()
