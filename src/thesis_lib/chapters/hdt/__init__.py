"""The HDT chapter (thesis 5.2; notebook ``04_hdt``): Tables 5.1-5.3 and the sub-goal figures.

* :class:`Config`: every setting of the chapter, the notebook's parameters; defaults are the
  smoke scale (``params/04_hdt.smoke.yml``).
* :func:`run_datasets`: the data sets and their statistics (``data.cards_table``);
  :func:`run_subgoal_stats`, :func:`run_maze_subgoal_stats`: what the sub-goal rule picks.
* :func:`run_curves`: every data set x seed x method, trained and evaluated by the one offline
  runner (:func:`thesis_lib.seq.runner.run_offline`), as a resumable sweep
  (``results/04_hdt/tasks``); :func:`run_paper_compat`: the ``paper_compat=True`` variants.
* :func:`summarize`: both metrics per method x task x tier x target: the thesis's
  (``best_return``: the best evaluation average during training, mean +- std over seeds) and
  the honest one (``final_return_mean`` +- ``final_return_std``, the last evaluation).
* :func:`compare_table_5_1`, :func:`compare_table_5_2`, :func:`compare_table_5_3`,
  :func:`compare_win_counts`, :func:`compare_paper_compat`: our numbers beside the thesis's.
* :func:`plot_subgoal_index`, :func:`plot_subgoal_weights`, :func:`plot_maze_subgoals`,
  :func:`plot_training_curves`.

Methods: ``BC``; ``DT`` (RTG, Tables 5.1, 5.3); ``DT-noRTG`` (Table 5.1); ``HDT`` (Tables
5.2, 5.3); ``HDT-RTG`` (Table 5.2).

Used in: HDT chapter (Tables 5.1-5.3, Figures of 5.2.2).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import asdict, dataclass, field
from typing import Any, Literal

import numpy as np
import pandas as pd

from thesis_lib.seq.registry import LEGACY_INIT, ArchSpec, check_methods
from thesis_lib.seq.runner import EvalSpec, TrainSpec, run_offline
from thesis_lib.seq.subgoals import select_subgoal_indices

__all__ = [
    "METHODS",
    "METRICS",
    "METRIC_STD",
    "Config",
    "compare_paper_compat",
    "compare_table_5_1",
    "compare_table_5_2",
    "compare_table_5_3",
    "compare_win_counts",
    "arch_fields",
    "load_datasets",
    "offline_task",
    "plot_maze_subgoals",
    "plot_subgoal_index",
    "plot_subgoal_weights",
    "plot_training_curves",
    "run_curves",
    "run_datasets",
    "run_maze_subgoal_stats",
    "run_paper_compat",
    "run_seed_spread",
    "run_subgoal_stats",
    "study_run",
    "study_summary",
    "study_task",
    "study_tasks",
    "summarize",
    "thesis_labels",
]

CHAPTER = "04_hdt"
METHODS: tuple[str, ...] = ("BC", "DT", "DT-noRTG", "HDT", "HDT-RTG")
"""The chapter's methods, as the tables' columns."""
TARGET_ORDER = ("max", "half", "10k", "none")
#: The columns of the curves (one row per evaluation and target).
CURVE_COLUMNS = [
    "method", "task", "tier", "seed", "paper_compat", "target", "target_return", "iteration",
    "return_mean", "return_std", "score_mean", "length_mean", "loss",
]  # fmt: skip


def split_dataset(name: str) -> tuple[str, str]:
    """``"hopper/medium"`` -> ``("hopper", "medium")``; a real Minari id keeps its task and tier
    (``"D4RL/door/human-v2"`` -> ``("door", "human")``); a clear error otherwise
    (:func:`thesis_lib.data.minari_sets.dataset_key`)."""
    from thesis_lib.data.minari_sets import dataset_key

    return dataset_key(name)


_EXTRA_SEED_DEFAULT = ("hopper/medium", "maze2d-umaze/expert")
_COMPAT_DEFAULT = "hopper/medium"


STUDY_FILE_DEFAULTS: dict[str, Any] = {"init": LEGACY_INIT}
"""What a study file that does not name these fields ran with (the v1 studies, registered
before the transformers' ``init`` existed): :func:`thesis_lib.book.study.study_config`."""


@dataclass
class Config:
    """Every setting of the HDT chapter (thesis 5.2.5); the notebook's parameters.

    Defaults are the smoke scale; ``params/04_hdt.full.yml`` holds the thesis's.

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
        from thesis_lib.data import DATASET_SIZES

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
        return ArchSpec(
            d_model=self.d_model,
            n_layers=self.n_layers,
            n_heads=self.n_heads,
            K=self.K,
            dropout=self.dropout,
            bc_hidden_dim=self.bc_hidden_dim,
            paper_compat=self.paper_compat if paper_compat is None else bool(paper_compat),
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

    def eval_spec(self) -> EvalSpec:
        """The :class:`~thesis_lib.seq.runner.EvalSpec` of every run."""
        return EvalSpec(episodes=self.eval_episodes, max_steps=self.max_eval_steps)


# ------------------------------------------------------------------------------------ data sets


def load_datasets(cfg: Config, names: list[str] | None = None) -> dict[tuple[str, str], Any]:
    """``{(task, tier): OfflineDataset}`` of ``names`` (default ``cfg.datasets``), made on first use.

    A real Minari id (``D4RL/door/human-v2``) is read from its download and keyed by its task
    and tier (``("door", "human")``).

    Used in: HDT chapter.

    Raises:
        FileNotFoundError: a Minari id not downloaded (the message names the id and where
            Minari looks).
        ValueError: two names with the same ``(task, tier)``.
    """
    from thesis_lib.data.minari_sets import open_dataset

    out: dict[tuple[str, str], Any] = {}
    seen: dict[tuple[str, str], str] = {}
    for name in cfg.datasets if names is None else names:
        key = split_dataset(name)
        if key in seen and seen[key] != name:
            raise ValueError(
                f"Data sets {seen[key]!r} and {name!r} both read as {'/'.join(key)}; keep one."
            )
        seen[key] = name
        out[key] = open_dataset(name, cfg.dataset_size, cfg.n_transitions)
    return out


def run_datasets(data: Mapping[tuple[str, str], Any], targets: bool = True) -> pd.DataFrame:
    """One row per data set: ``task, tier`` and its card (``thesis_lib.data.cards_table``).

    Args:
        data: :func:`load_datasets` output.
        targets: Add the RTG targets (half / max / 10k) as text.

    Used in: HDT chapter, Decision Mamba chapter (their data-set tables).
    """
    from thesis_lib.data import cards_table

    cards = cards_table(list(data.values()))
    keys = pd.DataFrame(list(data.keys()), columns=["task", "tier"])
    out = pd.concat([keys, cards], axis=1)
    if targets:
        out["targets (half / max / 10k)"] = [
            f"{m / 2:.0f} / {m:.0f} / 10000" for m in out["return_max"]
        ]
    return out


# ------------------------------------------------------------------------------------ sub-goals


def run_subgoal_stats(episode: Any) -> dict[str, Any]:
    """How far ahead the sub-goal rule looks on one episode (thesis 5.2.2).

    Returns:
        ``steps, distinct_subgoals, ahead_mean, ahead_max`` (steps between a state and its
        sub-goal) and ``w0_argmax`` (the first selection: ``argmax_j W_0(j)``, 1-based).

    Used in: HDT chapter (sub-goal selection).
    """
    r = np.asarray(episode.rewards, dtype=float)
    idx = select_subgoal_indices(r)
    ahead = idx - np.arange(len(idx))
    w0 = np.cumsum(r) / np.arange(1, len(r) + 1)
    return {
        "steps": len(idx),
        "distinct_subgoals": len(np.unique(idx)),
        "ahead_mean": float(ahead.mean()),
        "ahead_max": int(ahead.max()),
        "w0_argmax": int(np.argmax(w0)) + 1,
    }


def run_maze_subgoal_stats(episodes: Any) -> tuple[pd.DataFrame, pd.DataFrame]:
    """The sub-goal rule on sparse rewards (Maze2D): per episode, and grouped by goal reached.

    Returns:
        ``(per_episode, summary)``: per episode ``reached goal, distinct sub-goals, sub-goal
        before the goal = last state`` (``None`` when the goal is never reached), ``share of
        steps whose sub-goal is the next state``; the summary per ``reached goal``:
        ``episodes, distinct_subgoals, next_state_share``.

    Used in: HDT chapter (sparse rewards).
    """
    rows = []
    for e in episodes:
        r = np.asarray(e.rewards)
        i = select_subgoal_indices(r)
        first = int(np.argmax(r > 0)) if r.any() else None
        rows.append(
            {
                "reached goal": r.any(),
                "distinct sub-goals": len(np.unique(i)),
                "sub-goal before the goal = last state": (
                    bool((i[:first] == len(r)).all()) if first else None
                ),
                "share of steps whose sub-goal is the next state": float(
                    np.mean(i == np.arange(len(r)) + 1)
                ),
            }
        )
    per_episode = pd.DataFrame(rows)
    summary = (
        per_episode.groupby("reached goal")
        .agg(
            episodes=("distinct sub-goals", "size"),
            distinct_subgoals=("distinct sub-goals", "mean"),
            next_state_share=("share of steps whose sub-goal is the next state", "mean"),
        )
        .reset_index()
    )
    return per_episode, summary


def plot_subgoal_weights(episode: Any, ax: Any = None) -> Any:
    """``W_0(j)``, the average reward from ``s_0`` to ``s_j``: the weights of the first selection.

    Used in: HDT chapter (sub-goal selection).
    """
    import matplotlib.pyplot as plt

    if ax is None:
        _, ax = plt.subplots(figsize=(6, 4))
    r = np.asarray(episode.rewards, dtype=float)
    w0 = np.cumsum(r) / np.arange(1, len(r) + 1)  # W_0(j) for j = 1 .. T
    ax.plot(np.arange(1, len(r) + 1), w0)
    j = int(np.argmax(w0)) + 1
    ax.axvline(j, ls="--", color="green", label=f"argmax j = {j}")
    ax.set_xlabel("candidate j")
    ax.set_ylabel("W_0(j): average reward from s_0 to s_j")
    ax.set_title("why: the weights of the first selection")
    ax.legend(fontsize=8)
    return ax


# ------------------------------------------------------------------------------------ the runs


def offline_task(config: dict[str, Any]) -> list[dict[str, Any]]:
    """One sweep task: train and evaluate ``config["method"]`` on ``config["dataset"]``.

    ``config`` holds ``method, dataset ("task/tier" or a Minari id), dataset_size,
    n_transitions`` and the ``arch``, ``train``, ``eval`` specs as dicts. Returns
    :data:`CURVE_COLUMNS` rows (a Minari id's ``task, tier`` as :func:`split_dataset` reads them).

    Used in: HDT chapter (through :func:`run_curves`).
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
    return [
        {k: (task if k == "task" else tier if k == "tier" else r[k]) for k in CURVE_COLUMNS}
        for r in rows
    ]


def _tasks(cfg: Config, datasets: list[str], methods: list[str], compat: bool) -> list[Any]:
    from thesis_lib.sweep import Task

    arch, ev = cfg.arch(compat).task_dict(), asdict(cfg.eval_spec())
    return [
        Task(
            offline_task,
            {
                "method": m,
                "dataset": d,
                "dataset_size": cfg.dataset_size,
                "n_transitions": cfg.n_transitions,
                "arch": arch,
                "train": asdict(cfg.train_spec(s)),
                "eval": ev,
            },
        )
        for d in datasets
        for s in cfg.seeds_for(d)
        for m in methods
    ]


def _run(cfg: Config, tasks: list[Any], desc: str) -> pd.DataFrame:
    from thesis_lib.paths import results_dir
    from thesis_lib.sweep import run_tasks

    rows = run_tasks(tasks, store=results_dir(CHAPTER) / "tasks", desc=desc, progress=cfg.progress)
    return rows.drop(columns="task_key").reset_index(drop=True)


def run_curves(cfg: Config) -> pd.DataFrame:
    """Every data set x seed x method of ``cfg``: one row per evaluation and target.

    A resumable sweep (store ``results/04_hdt/tasks``): a rerun computes only missing runs.

    Used in: HDT chapter (Tables 5.1-5.3).
    """
    return _run(cfg, _tasks(cfg, cfg.datasets, cfg.methods, cfg.paper_compat), "Tables 5.1-5.3")


def run_paper_compat(cfg: Config) -> pd.DataFrame:
    """``cfg.compat_methods`` on ``cfg.compat_dataset`` with ``paper_compat=True`` (its seeds).

    Used in: HDT chapter (the authors' behaviours measured, see :func:`compare_paper_compat`).

    Raises:
        ValueError: If ``cfg.compat_dataset`` is not set.
    """
    if not cfg.compat_dataset:
        raise ValueError("Set compat_dataset='task/tier' to measure the paper_compat behaviours.")
    tasks = _tasks(cfg, [cfg.compat_dataset], cfg.compat_methods, True)
    return _run(cfg, tasks, "paper_compat")


def _over_seeds(g: Any, column: Callable[[str, str], str]) -> pd.DataFrame:
    """Mean and std over seeds of each run's best and final return and score, from a groupby
    of one row per run; ``column("return", "best")`` names a run's column (the chapter's runs
    and the study's rows name them differently)."""
    rb, sb = column("return", "best"), column("score", "best")
    rf, sf = column("return", "final"), column("score", "final")
    return pd.DataFrame({
        "best_return": g[rb].mean(),
        "best_return_std": g[rb].std(ddof=0),
        "best_score": g[sb].mean(),
        "final_return_mean": g[rf].mean(),
        "final_return_std": g[rf].std(ddof=0),
        "final_score_mean": g[sf].mean(),
        "final_score_std": g[sf].std(ddof=0),
        "n_seeds": g["seed"].nunique(),
    }).reset_index()  # fmt: skip


def summarize(curves: pd.DataFrame) -> pd.DataFrame:
    """Both metrics per ``method, task, tier, target`` from :func:`run_curves` rows.

    * ``best_return`` (+- ``best_return_std``): the thesis's metric, the highest evaluation
      average seen during training (mean and std over seeds of each run's best);
      ``best_score`` likewise.
    * ``final_return_mean``, ``final_return_std``: the last evaluation, mean and std over
      seeds (``final_score_*`` likewise); ``n_seeds``.

    Rows with and without ``paper_compat`` (when the column is there) are kept apart.

    Used in: HDT chapter (Tables 5.1-5.3).
    """
    keys = ["method", "task", "tier", "target"] + (
        ["paper_compat"] if "paper_compat" in curves else []
    )
    per_run = curves.sort_values("iteration", kind="stable").groupby(keys + ["seed"], sort=False)
    runs = pd.DataFrame({
        "best_return": per_run["return_mean"].max(),
        "best_score": per_run["score_mean"].max(),
        "final_return": per_run["return_mean"].last(),
        "final_score": per_run["score_mean"].last(),
    }).reset_index()  # fmt: skip
    out = _over_seeds(runs.groupby(keys, sort=False), lambda q, which: f"{which}_{q}")
    order = {m: i for i, m in enumerate(METHODS)} | {t: i for i, t in enumerate(TARGET_ORDER)}
    out = out.sort_values(
        ["task", "tier", "method", "target"],
        kind="stable",
        key=lambda c: c.map(order) if c.name in ("method", "target") else c,
    )
    return out.reset_index(drop=True)


def compare_paper_compat(curves: pd.DataFrame, compat_curves: pd.DataFrame) -> pd.DataFrame:
    """The default behaviour beside ``paper_compat=True``, per method and target, both metrics.

    Used in: HDT chapter (the authors' behaviours measured).

    Args:
        curves: :func:`run_curves` rows (default behaviour); only the data set and
            methods of ``compat_curves`` are used.
        compat_curves: :func:`run_paper_compat` rows.

    Returns:
        One row per ``metric, method, task, tier, target``: ``correct``, ``correct_std``,
        ``paper_compat``, ``paper_compat_std``, ``difference`` (paper_compat - correct),
        ``n_seeds``.
    """
    keys = ["method", "task", "tier", "target"]
    a = summarize(curves.assign(paper_compat=False))
    b = summarize(compat_curves.assign(paper_compat=True))
    a = a.merge(b[keys], on=keys)  # the settings measured both ways
    frames = []
    for metric, (col, std) in {
        "best during training (thesis)": ("best_return", "best_return_std"),
        "final checkpoint": ("final_return_mean", "final_return_std"),
    }.items():
        m = a[keys + [col, std, "n_seeds"]].merge(
            b[keys + [col, std]], on=keys, suffixes=("", "_compat")
        )
        frames.append(pd.DataFrame({
            "metric": metric, **{k: m[k] for k in keys},
            "correct": m[col], "correct_std": m[std],
            "paper_compat": m[f"{col}_compat"], "paper_compat_std": m[f"{std}_compat"],
            "difference": m[f"{col}_compat"] - m[col], "n_seeds": m["n_seeds"],
        }))  # fmt: skip
    return pd.concat(frames, ignore_index=True)


def run_seed_spread(summary: pd.DataFrame) -> pd.DataFrame:
    """Settings run with several seeds: both metrics as ``"mean ± std"`` (RTG methods at max).

    Used in: HDT chapter (seeds: mean ± std).
    """
    multi = summary[(summary.n_seeds > 1) & summary.target.isin(["none", "max"])]
    return pd.DataFrame(
        {
            "task": multi.task,
            "tier": multi.tier,
            "method": multi.method,
            "seeds": multi.n_seeds,
            "best during training (thesis)": [
                f"{m:.1f} ± {s:.1f}" for m, s in zip(multi.best_return, multi.best_return_std)
            ],
            "final checkpoint": [
                f"{m:.1f} ± {s:.1f}"
                for m, s in zip(multi.final_return_mean, multi.final_return_std)
            ],
        }
    )


#: Our summary columns for the two metrics: the thesis's and the honest one.
METRICS: dict[str, str] = {
    "best during training (thesis)": "best_return",
    "final checkpoint": "final_return_mean",
}
#: The std over seeds of each metric's column.
METRIC_STD: dict[str, str] = {
    "best_return": "best_return_std",
    "final_return_mean": "final_return_std",
}

# Task spellings of each thesis table (reference/README.md keeps them as printed).
_TASK_NAMES = {
    "hopper": "Hopper",
    "halfcheetah": "Half-Cheetah",
    "ant": "Ant",
    "walker2d": {"5.1": "Walker-2D", "5.2": "Walker 2D", "5.3": "Walker 2D"},
    # Table 5.3's Adroit and Kitchen rows (real Minari D4RL/<task>/<tier> sets).
    "pen": "Pen",
    "door": "Door",
    "hammer": "Hammer",
    "relocate": "Relocate",
    "kitchen": "Kitchen",
    "antmaze": "Antmaze",
}
_TIER_NAMES = {"medium-replay": "replay"}


def thesis_labels(task: str, tier: str, table: str) -> tuple[str, str]:
    """``(task, dataset)`` as thesis Table ``table`` prints them, e.g. ``('Maze 2D', 'umaze')``.

    Example:
        >>> thesis_labels("door", "human", "5.3"), thesis_labels("walker2d", "medium-replay", "5.3")
        (('Door', 'human'), ('Walker 2D', 'replay'))
    """
    if task.startswith("maze2d-"):
        return "Maze 2D", task.split("-", 1)[1]
    name: Any = _TASK_NAMES.get(task, task)
    if isinstance(name, dict):
        name = name[table]
    return name, _TIER_NAMES.get(tier, tier)


def _labelled(summary: pd.DataFrame, table: str) -> pd.DataFrame:
    s = summary.copy()
    lab = [thesis_labels(t, r, table) for t, r in zip(s["task"], s["tier"])]
    s["task_id"], s["tier_id"] = s["task"], s["tier"]
    s["task"] = [a for a, _ in lab]
    s["dataset"] = [b for _, b in lab]
    return s


def _paper_targets(table: str) -> pd.DataFrame:
    """The thesis's desired returns of Table 5.1/5.2 labelled half/max/10k per setting."""
    from thesis_lib.book import load_reference

    ref = load_reference(table)
    rows = []
    for (task, ds), g in ref.groupby(["task", "dataset"], sort=False):
        vals = sorted(g["desired_return"].unique(), key=float)
        names = ["half", "max", "10k"] if len(vals) == 3 else ["half", "max"]
        rows += [
            {"task": task, "dataset": ds, "target": n, "desired_return": v}
            for n, v in zip(names, vals)
        ]
    return pd.DataFrame(rows)


def _compare(
    table: str,
    ours: pd.DataFrame,
    on: list[str],
    paper_value: str,
    differs: Mapping[str, str] | str | None,
) -> pd.DataFrame:
    from thesis_lib.book import compare_with_paper

    frames = []
    for metric, col in METRICS.items():
        c = compare_with_paper(
            table,
            ours.assign(ours=ours[col]),
            on=on,
            value="ours",
            paper_value=paper_value,
            differs=differs,
        )
        extra = [x for x in (METRIC_STD.get(col), "n_seeds") if x in ours]
        if extra:  # ours: mean over seeds; beside it the std over seeds and their number
            spread = ours[on + extra].rename(columns={METRIC_STD.get(col): "ours_std"})
            spread[on] = spread[on].astype(str)  # compare_with_paper's keys are text
            c = c.merge(spread.drop_duplicates(on), on=on, how="left")
        frames.append(c.assign(metric=metric))
    return pd.concat(frames, ignore_index=True)


def _with_target_rows(
    summary: pd.DataFrame, table: str, methods: Mapping[str, str]
) -> pd.DataFrame:
    s = _labelled(summary, table)
    s = s[s["method"].isin(list(methods))]
    targets = _paper_targets(table)
    rows = []
    for _, r in s.iterrows():
        t = targets[(targets.task == r.task) & (targets.dataset == r.dataset)]
        # RTG methods have one row per target; the others are repeated on every target row.
        for _, tr in t.iterrows():
            if r["target"] in ("none", tr["target"]):
                our_target = "" if r["target"] == "none" else f"our target {tr['target']}"
                rows.append(
                    {
                        **r.to_dict(),
                        "desired_return": tr["desired_return"],
                        "column": methods[r["method"]],
                        "differs": our_target,
                    }
                )
        if t.empty:  # a setting the thesis did not run: keep our own target label
            rows.append(
                {
                    **r.to_dict(),
                    "desired_return": r["target"],
                    "column": methods[r["method"]],
                    "differs": "",
                }
            )
    return pd.DataFrame(rows)


def _by_column(table: str, rows: pd.DataFrame, differs: Any) -> pd.DataFrame:
    frames = []
    for col, g in rows.groupby("column", sort=False):
        c = _compare(table, g, ["task", "dataset", "desired_return"], col, differs)
        frames.append(c.assign(method=col))
    out = pd.concat(frames, ignore_index=True)
    cols = [
        "metric",
        "method",
        "task",
        "dataset",
        "desired_return",
        "paper",
        "ours",
        "ours_std",
        "n_seeds",
        "difference",
        "what differs",
    ]
    return out.reindex(columns=cols)


def compare_table_5_1(summary: pd.DataFrame, differs: Any = None) -> pd.DataFrame:
    """Table 5.1 (DT at the half/max/10k targets vs DT without RTG), beside the thesis's.

    ``desired_return`` holds the thesis's target; ours (from our data set's max return) is
    named in ``what differs``. Rows for both metrics (column ``metric``).
    """
    rows = _with_target_rows(
        summary, "5.1", {"DT": "original_dt", "DT-noRTG": "dt_without_returns"}
    )
    return _by_column("5.1", rows, differs)


def compare_table_5_2(summary: pd.DataFrame, differs: Any = None) -> pd.DataFrame:
    """Table 5.2 (HDT vs HDT with RTG at the half/max targets), beside the thesis's."""
    s = summary[summary["target"] != "10k"]
    rows = _with_target_rows(s, "5.2", {"HDT": "hdt", "HDT-RTG": "hdt_with_returns"})
    return _by_column("5.2", rows, differs)


def compare_table_5_3(
    summary: pd.DataFrame, data_avg: Mapping[tuple[str, str], float], differs: Any = None
) -> pd.DataFrame:
    """Table 5.3 (BC, DT at the max target, HDT, and the data set's average return).

    Args:
        summary: :func:`summarize` output.
        data_avg: ``{(task, tier): average episode return of the data set}``.
    """
    s = summary[
        summary["method"].isin(["BC", "DT", "HDT"]) & summary["target"].isin(["none", "max"])
    ]
    s = _labelled(s, "5.3")
    paper_cols = {"BC": "bc", "DT": "dt", "HDT": "hdt"}
    frames = []
    for method, g in s.groupby("method", sort=False):
        c = _compare("5.3", g, ["task", "dataset"], paper_cols[method], differs)
        frames.append(c.assign(method=paper_cols[method]))
    avg = pd.DataFrame(
        [{"task_id": t, "tier_id": r, "data_avg": v} for (t, r), v in data_avg.items()]
    )
    lab = [thesis_labels(t, r, "5.3") for t, r in zip(avg.task_id, avg.tier_id)]
    avg["task"], avg["dataset"] = [a for a, _ in lab], [b for _, b in lab]
    for metric in METRICS:
        c = _compare(
            "5.3",
            avg.assign(best_return=avg.data_avg, final_return_mean=avg.data_avg),
            ["task", "dataset"],
            "data_avg",
            differs,
        )
        frames.append(c[c.metric == metric].assign(method="data_avg"))
    out = pd.concat(frames, ignore_index=True).drop_duplicates(
        ["metric", "method", "task", "dataset"]
    )
    cols = [
        "metric",
        "method",
        "task",
        "dataset",
        "paper",
        "ours",
        "ours_std",
        "n_seeds",
        "difference",
        "what differs",
    ]
    return out.reindex(columns=cols)


def compare_win_counts(
    table_5_3: pd.DataFrame, metric: str = "best during training (thesis)"
) -> pd.DataFrame:
    """Settings each of BC, DT and HDT wins, ours and the thesis's (ties count for each)."""
    t = table_5_3[(table_5_3.metric == metric) & table_5_3.method.isin(["bc", "dt", "hdt"])]
    out = {}
    for side in ("paper", "ours"):
        wide = t.pivot_table(index=["task", "dataset"], columns="method", values=side).dropna()
        best = wide.max(axis=1)
        out[side] = {m: int((wide[m] == best).sum()) for m in wide.columns}
        out[side]["settings"] = len(wide)
    ran = t.dropna(subset=["ours"])[["task", "dataset"]].drop_duplicates()
    t_ran = t.merge(ran, on=["task", "dataset"])
    wide = t_ran.pivot_table(index=["task", "dataset"], columns="method", values="paper").dropna()
    best = wide.max(axis=1)
    out["paper, our settings only"] = {m: int((wide[m] == best).sum()) for m in wide.columns} | {
        "settings": len(wide)
    }
    return pd.DataFrame(out).T.rename_axis("counted on").reset_index()


# ----------------------------------------------------------------------------------------- figures


def plot_maze_subgoals(episode: Any, ax: Any = None, paper_compat: bool = False) -> Any:
    """A Maze2D episode's (x, y) path with the sub-goals the rule selects on it.

    Points are coloured by reward; each selected sub-goal is a star, with an arrow from the
    state where it was selected.
    """
    import matplotlib.pyplot as plt

    if ax is None:
        _, ax = plt.subplots(figsize=(5, 5))
    obs = np.asarray(episode.observations)
    r = np.asarray(episode.rewards, dtype=float)
    idx = select_subgoal_indices(
        r, n_states=None if paper_compat else obs.shape[0], paper_compat=paper_compat
    )
    xy = obs[:, :2]
    ax.plot(xy[:, 0], xy[:, 1], color="0.7", lw=1, zorder=1)
    sc = ax.scatter(
        xy[:-1, 0], xy[:-1, 1], c=r, cmap="coolwarm", s=10, zorder=2, vmin=0, vmax=max(1.0, r.max())
    )
    starts = np.flatnonzero(np.r_[True, idx[1:] != idx[:-1]])
    for s in starts:
        g = idx[s]
        ax.annotate(
            "", xy=xy[g], xytext=xy[s], arrowprops=dict(arrowstyle="->", color="green", alpha=0.5)
        )
    ax.scatter(
        xy[np.unique(idx), 0],
        xy[np.unique(idx), 1],
        marker="*",
        s=120,
        c="green",
        zorder=3,
        label=f"sub-goals ({len(np.unique(idx))} distinct)",
    )
    ax.scatter(*xy[0], marker="o", s=60, c="k", zorder=4, label="start")
    ax.set_xlabel("x")
    ax.set_ylabel("y")
    ax.set_aspect("equal")
    ax.legend(loc="best", fontsize=8)
    plt.colorbar(sc, ax=ax, label="reward", fraction=0.046)
    return ax


def plot_subgoal_index(episode: Any, ax: Any = None, label: str | None = None) -> Any:
    """Sub-goal index vs time step for one episode (a staircase), with the rewards below."""
    import matplotlib.pyplot as plt

    if ax is None:
        _, ax = plt.subplots(figsize=(7, 4))
    r = np.asarray(episode.rewards, dtype=float)
    idx = select_subgoal_indices(r, n_states=np.asarray(episode.observations).shape[0])
    t = np.arange(len(r))
    ax.step(t, idx, where="post", label=label or "sub-goal index")
    ax.plot(t, t, ls=":", color="0.5", label="current step")
    ax.set_xlabel("time step t")
    ax.set_ylabel("sub-goal index j")
    ax2 = ax.twinx()
    ax2.plot(t, r, color="tab:red", alpha=0.35, lw=0.8)
    ax2.set_ylabel("reward r_t", color="tab:red")
    ax.legend(loc="upper left", fontsize=8)
    return ax


def plot_training_curves(curves: pd.DataFrame, ncols: int = 4) -> Any:
    """Evaluation return vs iteration per method (mean over seeds), one panel per data set.

    RTG methods are drawn at their ``max`` target; panels fill ``ncols`` columns.
    """
    import matplotlib.pyplot as plt

    c = curves[curves["target"].isin(["none", "max"])]
    sets = list(dict.fromkeys(zip(c["task"], c["tier"])))
    ncols = max(1, min(ncols, len(sets)))
    nrows = -(-len(sets) // ncols)
    fig, axes = plt.subplots(nrows, ncols, figsize=(4.5 * ncols, 3.4 * nrows), squeeze=False)
    for ax in axes.flat[len(sets) :]:
        ax.set_visible(False)
    for ax, (task, tier) in zip(axes.flat, sets):
        g = c[(c.task == task) & (c.tier == tier)]
        for method, gm in g.groupby("method", sort=False):
            m = gm.groupby("iteration")["return_mean"].agg(["mean", "std"]).reset_index()
            ax.plot(m["iteration"], m["mean"], marker="o", label=method)
            if gm["seed"].nunique() > 1:
                ax.fill_between(
                    m["iteration"], m["mean"] - m["std"], m["mean"] + m["std"], alpha=0.15
                )
        ax.set_title(f"{task}/{tier}", fontsize=10)
        ax.set_xlabel("iteration")
        ax.set_ylabel("evaluation return")
    handles, labels = axes.flat[0].get_legend_handles_labels()
    fig.legend(
        handles,
        labels,
        loc="lower center",
        ncol=len(labels),
        fontsize=9,
        bbox_to_anchor=(0.5, -0.02),
    )
    fig.tight_layout(rect=(0, 0.03, 1, 1))
    return fig


# ------------------------------------------------------------------------------------ the study

#: The columns of a study run (one row per run: method, setting, seed).
STUDY_COLUMNS = [
    "method", "setting", "task", "tier", "seed", "scale", "base_method", "paper_compat", "target",
    "iterations", "evaluations", "score_final", "score_best", "return_final", "return_best",
    "length_final", "train_s",
]  # fmt: skip
#: The ArchSpec fields each kind of method reads: a study task carries only these, so the
#: same run asked for by two chapters (DT in 04 and 05) has one key.
_ARCH_FIELDS = {
    "BC": ("K", "dropout", "bc_hidden_dim", "paper_compat"),
    "transformer": ("d_model", "n_layers", "n_heads", "K", "dropout", "max_timestep", "paper_compat", "init"),
    "mamba": ("d_model", "n_layers", "K", "gated_mlp", "eval_mode", "paper_compat"),
}  # fmt: skip


def arch_fields(method: str, arch: ArchSpec) -> dict[str, Any]:
    """The fields of ``arch`` that ``method`` reads (the rest are the ArchSpec defaults).

    Example:
        >>> arch_fields("BC", ArchSpec(d_model=64))
        {'K': 20, 'dropout': 0.1, 'bc_hidden_dim': 256, 'paper_compat': False}
    """
    from thesis_lib.seq.registry import MAMBA_METHODS

    kind = "BC" if method == "BC" else "mamba" if method in MAMBA_METHODS else "transformer"
    d = arch.task_dict()  # ``init`` resolved, absent where ``torch`` (the v1 tasks' keys)
    return {k: d[k] for k in _ARCH_FIELDS[kind] if k in d}


def study_run(config: dict[str, Any]) -> list[dict[str, Any]]:
    """One study task: a whole offline run reduced to one row (:data:`STUDY_COLUMNS`).

    ``config`` is an :func:`offline_task` config plus ``label`` (the method's name in the
    study, e.g. ``"HDT-compat"``) and ``scale`` (``"check"`` for a study's scale-check runs,
    see :mod:`thesis_lib.book.study`; default ``"study"``). RTG methods are evaluated at the data set's max return
    (CLAIMS.md, C1). ``score_final`` is the last evaluation's mean D4RL-normalised score (the
    primary metric); ``score_best`` the best evaluation during training (the thesis's);
    ``return_*`` the same in raw returns.

    Used in: HDT chapter and Decision Mamba chapter studies (``thesis study``).
    """
    import time

    import torch

    torch.set_num_threads(1)  # small models: one core per run, the study runs one per core
    t0 = time.process_time()
    curves = pd.DataFrame(
        offline_task({k: v for k, v in config.items() if k not in ("label", "scale")})
    )
    train_s = time.process_time() - t0
    curves = curves.sort_values("iteration", kind="stable")
    target = "none" if curves["target"].eq("none").all() else "max"
    run = curves[curves["target"] == target]
    last = run.iloc[-1]
    return [
        {
            "method": config.get("label", config["method"]),
            "setting": config["dataset"],
            "task": last["task"],
            "tier": last["tier"],
            "seed": int(last["seed"]),
            "scale": config.get("scale", "study"),
            "base_method": config["method"],
            "paper_compat": bool(config["arch"].get("paper_compat", False)),
            "target": target,
            "iterations": int(last["iteration"]),
            "evaluations": len(run),
            "score_final": float(last["score_mean"]),
            "score_best": float(run["score_mean"].max()),
            "return_final": float(last["return_mean"]),
            "return_best": float(run["return_mean"].max()),
            "length_final": float(last["length_mean"]),
            "train_s": round(train_s, 1),
        }
    ]


def study_task(
    cfg: Any,
    method: str,
    dataset: str,
    seed: int,
    arch: ArchSpec,
    label: str | None = None,
) -> Any:
    """The :class:`~thesis_lib.sweep.Task` of one study run of ``cfg`` (an HDT or DM Config).

    Used in: HDT chapter and Decision Mamba chapter studies.
    """
    from thesis_lib.sweep import Task

    ev = EvalSpec(episodes=cfg.eval_episodes, max_steps=cfg.max_eval_steps, targets=("max",))
    train = cfg.train_spec(seed)
    config: dict[str, Any] = {
        "method": method,
        "dataset": dataset,
        "dataset_size": cfg.dataset_size,
        "n_transitions": cfg.n_transitions,
        "arch": arch_fields(method, arch),
        "train": asdict(train) | {"progress": False},
        "eval": asdict(ev),
    }
    if label and label != method:
        config["label"] = label
    return Task(study_run, config)


def study_tasks(cfg: Config) -> list[Any]:
    """The tasks of the chapter's pre-registered study (``params/04_hdt.study.yml``).

    Every data set x seed x method of ``cfg`` (``seeds`` only; no extra seeds), and
    ``compat_methods`` with ``paper_compat=True`` (as ``"<method>-compat"``) on
    ``compat_dataset`` (the authors' behaviours measured beside the thesis's text).

    Used in: ``thesis study 04_hdt``.
    """
    tasks = [
        study_task(cfg, m, d, s, cfg.arch(False))
        for d in cfg.datasets
        for s in cfg.seeds
        for m in cfg.methods
    ]
    if cfg.compat_dataset:
        tasks += [
            study_task(cfg, m, cfg.compat_dataset, s, cfg.arch(True), label=f"{m}-compat")
            for s in cfg.seeds
            for m in cfg.compat_methods
        ]
    return tasks


def study_summary(rows: pd.DataFrame) -> pd.DataFrame:
    """Study rows (one per run) as :func:`summarize` output, so that the thesis's tables can
    be set beside them (:func:`compare_table_5_1`, :func:`compare_table_5_3`).

    Used in: HDT chapter and Decision Mamba chapter ("Evidence at study scale").
    """
    keys = ["method", "task", "tier", "target"]
    if rows.empty:
        return pd.DataFrame(columns=keys + ["best_return", "final_return_mean", "n_seeds"])
    return _over_seeds(rows.groupby(keys, sort=False), lambda q, which: f"{q}_{which}")
