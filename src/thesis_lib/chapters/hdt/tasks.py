"""The HDT chapter's experiments: the data sets, the sub-goal statistics, the offline runs
(notebook sweep and study alike) and the pre-registered study's grid.

* :func:`load_datasets`, :func:`run_datasets`: the data sets and their cards;
  :func:`run_subgoal_stats`, :func:`run_maze_subgoal_stats`: what the sub-goal rule picks.
* :func:`offline_task`: the one task function of a run (train and evaluate one method on one
  data set with one seed: :func:`thesis_lib.seq.runner.run_offline`), one row per evaluation
  and target. :func:`run_curves` and :func:`run_paper_compat` run it as a resumable sweep
  (``results/04_hdt/tasks``); :func:`study_run` runs it and reduces its rows to the study's one
  row per run (:data:`STUDY_COLUMNS`).
* :func:`study_task`, :func:`study_tasks`: the study's grid (``thesis study 04_hdt``), which
  the Decision Mamba chapter's study shares for its DT/HDT/DM/HDM runs.

Used in: HDT chapter (Tables 5.1-5.3) and the Decision Mamba chapter's study.
"""

from __future__ import annotations

import time
from collections.abc import Mapping, Sequence
from dataclasses import asdict
from typing import Any, Protocol

import numpy as np
import pandas as pd
import torch

from thesis_lib.chapters.hdt.config import CHAPTER, Config, split_dataset
from thesis_lib.data import cards_table
from thesis_lib.data.minari_sets import env_name, open_dataset
from thesis_lib.paths import results_dir
from thesis_lib.seq.registry import LEGACY_INIT, LEGACY_SAMPLING, MAMBA_METHODS, ArchSpec
from thesis_lib.seq.runner import EvalSpec, TrainSpec, run_offline
from thesis_lib.seq.subgoals import select_subgoal_indices
from thesis_lib.sweep import Task, resumed_cpu_s, run_tasks, scratch_file, task_id

__all__ = [
    "ARCH_FIELDS",
    "CURVE_COLUMNS",
    "STUDY_COLUMNS",
    "STUDY_FILE_DEFAULTS",
    "arch_fields",
    "load_datasets",
    "offline_rows",
    "offline_task",
    "run_curves",
    "run_datasets",
    "run_maze_subgoal_stats",
    "run_paper_compat",
    "run_subgoal_stats",
    "run_sweep",
    "study_run",
    "study_task",
    "study_tasks",
    "sweep_tasks",
]

#: The columns of the curves (one row per evaluation and target).
CURVE_COLUMNS = [
    "method", "task", "tier", "seed", "paper_compat", "target", "target_return", "iteration",
    "return_mean", "return_std", "score_mean", "length_mean", "loss",
]  # fmt: skip

STUDY_FILE_DEFAULTS: dict[str, Any] = {"init": LEGACY_INIT, "sampling": LEGACY_SAMPLING}
"""What a study file that does not name these fields ran with (the v1 studies, registered
before the transformers' ``init`` existed): :func:`thesis_lib.book.study.study_config`."""


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


# ------------------------------------------------------------------------------------ the runs


def offline_rows(config: Mapping[str, Any], columns: Sequence[str]) -> list[dict[str, Any]]:
    """Train and evaluate ``config["method"]`` on ``config["dataset"]``: one row per evaluation
    and target, with ``columns`` (of :func:`~thesis_lib.seq.runner.run_offline`'s rows; a
    Minari id's ``task, tier`` as :func:`split_dataset` reads them).

    ``config`` holds ``method, dataset ("task/tier" or a Minari id), dataset_size,
    n_transitions`` and the ``arch``, ``train``, ``eval`` specs as dicts.

    Used in: HDT chapter (:func:`offline_task`), Decision Mamba chapter (its ``offline_task``).
    """
    task, tier = split_dataset(config["dataset"])
    data = open_dataset(config["dataset"], config["dataset_size"], config["n_transitions"])
    ev = dict(config["eval"])
    ev["targets"] = tuple(ev["targets"])
    rows = run_offline(
        config["method"],
        data,
        ArchSpec.from_task(config["arch"]),
        TrainSpec.from_task(config["train"]),
        EvalSpec(**ev),
        task=env_name(config["dataset"]),
        checkpoint=scratch_file("train.pt"),  # in a stored grid: a run cut off resumes
    )
    where = {"task": task, "tier": tier}
    return [{k: where[k] if k in where else r[k] for k in columns} for r in rows]


@task_id("thesis_lib.chapters.hdt:offline_task")  # its sweep tasks' keys (results/04_hdt/tasks)
def offline_task(config: dict[str, Any]) -> list[dict[str, Any]]:
    """One run (a sweep task): :func:`offline_rows` with :data:`CURVE_COLUMNS`.

    Used in: HDT chapter (through :func:`run_curves`, :func:`run_paper_compat`, :func:`study_run`).
    """
    return offline_rows(config, CURVE_COLUMNS)


def sweep_tasks(cfg: Config, datasets: list[str], methods: list[str], compat: bool) -> list[Task]:
    """The :func:`offline_task` tasks of ``datasets`` x their seeds (:meth:`Config.seeds_for`)
    x ``methods``, with ``paper_compat=compat``.

    Used in: HDT chapter (:func:`run_curves`, :func:`run_paper_compat`).
    """
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
                "train": cfg.train_spec(s).task_dict(),
                "eval": ev,
            },
        )
        for d in datasets
        for s in cfg.seeds_for(d)
        for m in methods
    ]


def run_sweep(chapter: str, tasks: list[Task], desc: str, progress: bool) -> pd.DataFrame:
    """``tasks`` as a resumable sweep stored under ``results/<chapter>/tasks``: their rows.

    Used in: HDT and Decision Mamba chapters.
    """
    rows = run_tasks(tasks, store=results_dir(chapter) / "tasks", desc=desc, progress=progress)
    return rows.drop(columns="task_key").reset_index(drop=True)


def run_curves(cfg: Config) -> pd.DataFrame:
    """Every data set x seed x method of ``cfg``: one row per evaluation and target.

    A resumable sweep (store ``results/04_hdt/tasks``): a rerun computes only missing runs.

    Used in: HDT chapter (Tables 5.1-5.3).
    """
    tasks = sweep_tasks(cfg, cfg.datasets, cfg.methods, cfg.paper_compat)
    return run_sweep(CHAPTER, tasks, "Tables 5.1-5.3", cfg.progress)


def run_paper_compat(cfg: Config) -> pd.DataFrame:
    """``cfg.compat_methods`` on ``cfg.compat_dataset`` with ``paper_compat=True`` (its seeds).

    Used in: HDT chapter (the authors' behaviours measured, see
    :func:`~thesis_lib.chapters.hdt.tables.summarize_paper_compat`).

    Raises:
        ValueError: If ``cfg.compat_dataset`` is not set.
    """
    if not cfg.compat_dataset:
        raise ValueError("Set compat_dataset='task/tier' to measure the paper_compat behaviours.")
    tasks = sweep_tasks(cfg, [cfg.compat_dataset], cfg.compat_methods, True)
    return run_sweep(CHAPTER, tasks, "paper_compat", cfg.progress)


# ------------------------------------------------------------------------------------ the study

#: The columns of a study run (one row per run: method, setting, seed).
STUDY_COLUMNS = [
    "method", "setting", "task", "tier", "seed", "scale", "base_method", "paper_compat", "target",
    "iterations", "evaluations", "score_final", "score_best", "return_final", "return_best",
    "length_final", "train_s",
]  # fmt: skip
#: The ArchSpec fields each kind of method reads: a study task carries only these, so the
#: same run asked for by two chapters (DT in 04 and 05) has one key.
ARCH_FIELDS = {
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
    kind = "BC" if method == "BC" else "mamba" if method in MAMBA_METHODS else "transformer"
    d = arch.task_dict()  # ``init`` resolved, absent where ``torch`` (the v1 tasks' keys)
    return {k: d[k] for k in ARCH_FIELDS[kind] if k in d}


@task_id("thesis_lib.chapters.hdt:study_run")  # the committed studies' keys (04_hdt, 05_...)
def study_run(config: dict[str, Any]) -> list[dict[str, Any]]:
    """One study task: a whole offline run (:func:`offline_task`) reduced to one row
    (:data:`STUDY_COLUMNS`).

    ``config`` is an :func:`offline_task` config plus ``label`` (the method's name in the
    study, e.g. ``"HDT-compat"``) and ``scale`` (``"check"`` for a study's scale-check runs,
    see :mod:`thesis_lib.book.study`; default ``"study"``). RTG methods are evaluated at the data set's max return
    (CLAIMS.md, C1). ``score_final`` is the last evaluation's mean D4RL-normalised score (the
    primary metric); ``score_best`` the best evaluation during training (the thesis's);
    ``return_*`` the same in raw returns.

    Used in: HDT chapter and Decision Mamba chapter studies (``thesis study``).
    """
    torch.set_num_threads(1)  # small models: one core per run, the study runs one per core
    t0 = time.process_time()
    curves = pd.DataFrame(
        offline_task({k: v for k, v in config.items() if k not in ("label", "scale")})
    )
    train_s = time.process_time() - t0 + resumed_cpu_s()  # a resumed run: its cut-off parts too
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


class OfflineStudyConfig(Protocol):
    """What :func:`study_task` reads of a chapter's Config (the HDT's and the Decision Mamba's)."""

    @property
    def eval_episodes(self) -> int: ...
    @property
    def max_eval_steps(self) -> int | None: ...
    @property
    def dataset_size(self) -> str: ...
    @property
    def n_transitions(self) -> int | None: ...
    def train_spec(self, seed: int) -> TrainSpec: ...


def study_task(
    cfg: OfflineStudyConfig,
    method: str,
    dataset: str,
    seed: int,
    arch: ArchSpec,
    label: str | None = None,
) -> Task:
    """The :class:`~thesis_lib.sweep.Task` of one study run of ``cfg`` (an HDT or DM Config).

    Used in: HDT chapter and Decision Mamba chapter studies.
    """
    ev = EvalSpec(episodes=cfg.eval_episodes, max_steps=cfg.max_eval_steps, targets=("max",))
    train = cfg.train_spec(seed)
    config: dict[str, Any] = {
        "method": method,
        "dataset": dataset,
        "dataset_size": cfg.dataset_size,
        "n_transitions": cfg.n_transitions,
        "arch": arch_fields(method, arch),
        "train": train.task_dict() | {"progress": False},
        "eval": asdict(ev),
    }
    if label and label != method:
        config["label"] = label
    return Task(study_run, config)


def study_tasks(cfg: Config) -> list[Task]:
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
