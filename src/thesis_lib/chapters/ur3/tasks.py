"""The UR3 deployment chapter's experiments: the reaching data set, Table 5.4's runs (one task
function, :func:`reach_task`, for the notebook's sweep and the study) and the dance's source.

* :func:`run_demonstrations`: the reaching demonstrations' statistics.
* :func:`run_reach`: train one method and run it from every test start; :func:`reach_task`, the
  sweep task around it; :func:`run_table_5_4`, the notebook's resumable sweep
  (``results/07_ur3_deployment/tasks``), one row per test start.
* :func:`study_run`: the study's task, :func:`reach_task` reduced to one row per run
  (:func:`run_row`); :func:`study_tasks`, the study's grid.
* :func:`dance_angles`: MDLT's dance (or a stand-in) as the arm's four angles.

Used in: UR3 deployment chapter (Table 5.4, dance playback) and ``thesis study
07_ur3_deployment`` (C14).
"""

from __future__ import annotations

from functools import partial
from typing import Any

import gymnasium as gym
import numpy as np
import pandas as pd
import torch

from thesis_lib.chapters.ur3.config import CHAPTER, N_DEMOS, N_GOALS, Config
from thesis_lib.mdlt import readers as mdlt_readers
from thesis_lib.mdlt import synth as mdlt_synth
from thesis_lib.paths import results_dir
from thesis_lib.seq.registry import LEGACY_INIT, LEGACY_SAMPLING, ArchSpec
from thesis_lib.seq.runner import EvalSpec, TrainSpec, run_offline
from thesis_lib.sweep import Task, run_tasks, task_id
from thesis_lib.ur3.dance import demo_angles
from thesis_lib.ur3.reach import UR3ReachEnv, get_reach_dataset, split_demonstrations

__all__ = [
    "RUN_COLUMNS",
    "STUDY_COLUMNS",
    "STUDY_FILE_DEFAULTS",
    "dance_angles",
    "reach_config",
    "reach_demos",
    "reach_record",
    "reach_task",
    "run_demonstrations",
    "run_reach",
    "run_row",
    "run_table_5_4",
    "study_run",
    "study_tasks",
]

#: The columns of Table 5.4's runs (one row per test start).
RUN_COLUMNS = [
    "method",
    "train_demos",
    "seed",
    "start",
    "goals_reached",
    "steps",
    "reach_steps",
    "loss",
]

#: The columns of a study run's row (:func:`study_run`); the study engine checks the study
#: file's metrics against them.
STUDY_COLUMNS = [
    "method", "setting", "train_demos", "seed", "scale", "goals_mean", "goals_std", "all_five",
    "episodes",
]  # fmt: skip

STUDY_FILE_DEFAULTS: dict[str, Any] = {"init": LEGACY_INIT, "sampling": LEGACY_SAMPLING}
"""What a study file that does not name these fields ran with (the v1 studies, registered
before the transformers' ``init`` existed): :func:`thesis_lib.book.study.study_config`."""


# ------------------------------------------------------------------------------ the data set


def reach_demos(seed: int, reach_set: str = "teleop") -> Any:
    """The reaching demonstrations of ``seed`` (the set ``reach_set``) split as the thesis's: 80
    train, 10 validation, 10 test starts (:func:`thesis_lib.ur3.reach.split_demonstrations`)."""
    return split_demonstrations(get_reach_dataset(N_DEMOS, seed, reach_set=reach_set).episodes)


def run_demonstrations(cfg: Config) -> pd.DataFrame:
    """The reaching data set in one row: demonstrations, steps, lengths, returns, all goals reached.

    Used in: UR3 deployment chapter.
    """
    ds = get_reach_dataset(N_DEMOS, cfg.seed, reach_set=cfg.reach_set)
    lengths = np.array([len(e) for e in ds.episodes])
    return pd.DataFrame(
        [
            {
                "data set": ds.id,
                "demonstrations": len(ds),
                "steps": ds.n_transitions,
                "length mean": lengths.mean(),
                "length max": lengths.max(),
                "return mean": ds.returns.mean(),
                "return max": ds.returns.max(),
                "all goals reached": int(
                    sum(e.observations[-1, 6:].sum() == 5 for e in ds.episodes)
                ),
            }
        ]
    )


# ------------------------------------------------------------------------------ Table 5.4's runs


def reach_record(env: Any) -> dict[str, Any]:
    """What one test episode achieved, read from its ``UR3ReachEnv``: ``goals_reached, steps,
    reach_steps`` (the step each goal was reached, -1 if never, as text for CSV).

    Used in: UR3 deployment chapter (Table 5.4).
    """
    u = env.unwrapped
    done = u.completed
    rec = (
        done[0]
        if done
        else {"goals_reached": int(u.reached.sum()), "reach_steps": u.reach_steps, "steps": u.t}
    )
    return {
        "goals_reached": rec["goals_reached"],
        "steps": rec["steps"],
        "reach_steps": " ".join(str(int(s)) for s in rec["reach_steps"]),
    }


def run_reach(
    method: str,
    episodes: Any,
    test_starts: Any,
    arch: ArchSpec,
    train: TrainSpec,
    max_eval_steps: int = 200,
) -> list[dict[str, Any]]:
    """Train ``method`` on ``episodes`` and run it once from each of ``test_starts``.

    DT is evaluated at the training demonstrations' best return; the episodes' reset seed is
    the run's seed. Returns one row per test start: ``method, seed, start, goals_reached,
    steps, reach_steps, loss``.

    Used in: UR3 deployment chapter (Table 5.4).
    """
    venv = gym.vector.SyncVectorEnv(
        [partial(UR3ReachEnv, start=s, max_steps=max_eval_steps) for s in test_starts]
    )

    def envs(n: int) -> Any:
        if n != len(test_starts):
            raise ValueError(
                f"Expect one environment per test start ({len(test_starts)}), asked {n}."
            )
        return venv

    try:
        rows = run_offline(
            method,
            episodes,
            arch,
            train,
            EvalSpec(
                episodes=len(test_starts),
                max_steps=max_eval_steps,
                targets=("max",),
                episode_seed="run",
            ),
            envs=envs,
            episode_info=reach_record,
        )
    finally:
        venv.close()
    return [r | {"start": r["episode"]} for r in rows]


@task_id("thesis_lib.chapters.ur3:reach_task")
def reach_task(config: dict[str, Any]) -> list[dict[str, Any]]:
    """One sweep task: train ``config["method"]`` on the first ``train_demos`` demonstrations
    and run it from every test start (:func:`run_reach`).

    ``config`` (:func:`reach_config`) holds ``method, train_demos, data_seed, max_eval_steps``,
    the ``arch`` and ``train`` specs as dicts and, for a set other than ``teleop``,
    ``reach_set``. Returns :data:`RUN_COLUMNS` rows, one per
    test start.

    Used in: UR3 deployment chapter (Table 5.4) and, through :func:`study_run`, its study.
    """
    demos = reach_demos(config["data_seed"], config.get("reach_set", "teleop"))
    rows = run_reach(
        config["method"],
        demos.train[: config["train_demos"]],
        demos.test_starts,
        ArchSpec.from_task(config["arch"]),
        TrainSpec.from_task(config["train"]),
        config["max_eval_steps"],
    )
    n = config["train_demos"]
    return [{k: (n if k == "train_demos" else r[k]) for k in RUN_COLUMNS} for r in rows]


def reach_config(cfg: Config, method: str, train_demos: int, seed: int) -> dict[str, Any]:
    """The config of :func:`reach_task` (and :func:`study_run`) for one run of ``cfg``'s grid:
    ``method`` trained with the first ``train_demos`` demonstrations, training seed ``seed``
    (``reach_set`` only where it is not ``teleop``: the v1 study's tasks keep their keys)."""
    config = {
        "method": method,
        "train_demos": train_demos,
        "data_seed": cfg.seed,
        "max_eval_steps": cfg.max_eval_steps,
        "arch": cfg.arch().task_dict(),
        "train": cfg.train_spec(seed).task_dict(),
    }
    if cfg.reach_set != "teleop":
        config["reach_set"] = cfg.reach_set
    return config


def run_table_5_4(cfg: Config) -> pd.DataFrame:
    """Every demonstration count x method x seed of ``cfg``: one row per test start.

    A resumable sweep (store ``results/07_ur3_deployment/tasks``).

    Used in: UR3 deployment chapter (Table 5.4).
    """
    tasks = [
        Task(reach_task, reach_config(cfg, m, n, s))
        for n in cfg.train_demos
        for m in cfg.methods
        for s in cfg.seeds
    ]
    rows = run_tasks(
        tasks, store=results_dir(CHAPTER) / "tasks", desc="Table 5.4", progress=cfg.progress
    )
    return rows.drop(columns="task_key").reset_index(drop=True)


# ------------------------------------------------------------------------------------ the study


def run_row(episodes: pd.DataFrame) -> dict[str, Any]:
    """One run's test episodes (:data:`RUN_COLUMNS` rows of one method, count and seed)
    reduced: ``goals_mean`` (goals reached, mean over the test starts), ``goals_std``
    (population std), ``all_five`` (share of test starts that reached all five goals) and
    ``episodes``.

    >>> run_row(pd.DataFrame({"goals_reached": [5, 3]}))
    {'goals_mean': 4.0, 'goals_std': 1.0, 'all_five': 0.5, 'episodes': 2}
    """
    goals = episodes["goals_reached"].to_numpy(dtype=float)
    return {
        "goals_mean": float(goals.mean()),
        "goals_std": float(goals.std()),
        "all_five": float(np.mean(goals >= N_GOALS)),
        "episodes": len(goals),
    }


@task_id("thesis_lib.chapters.ur3:study_run")
def study_run(config: dict[str, Any]) -> list[dict[str, Any]]:
    """One C14 study task: :func:`reach_task` reduced to one row per run (:func:`run_row`).

    Returns ``method, setting ("<n> demos"), train_demos, seed, scale, goals_mean`` (goals
    reached, mean over the 10 test starts; the primary metric), ``goals_std``, ``all_five``
    (share of test starts that reached all five goals) and ``episodes``.

    Used in: ``thesis study 07_ur3_deployment`` (C14).
    """
    torch.set_num_threads(1)  # small models: one core per run
    rows = pd.DataFrame(reach_task({k: v for k, v in config.items() if k != "scale"}))
    n = int(config["train_demos"])
    return [
        {
            "method": config["method"],
            "setting": f"{n} demos",
            "train_demos": n,
            "seed": int(config["train"]["seed"]),
            "scale": config.get("scale", "study"),
        }
        | run_row(rows)
    ]


def study_tasks(cfg: Config) -> list[Task]:
    """The tasks of the chapter's pre-registered study (``params/07_ur3_deployment.study.yml``):
    every demonstration count x method x seed of ``cfg``, one row per run (:func:`study_run`).

    Used in: ``thesis study 07_ur3_deployment`` (C14).
    """
    tasks = []
    for n in cfg.train_demos:
        for s in cfg.seeds:
            for m in cfg.methods:
                config = reach_config(cfg, m, n, s)
                config["train"]["progress"] = False  # no bars in a study's workers
                tasks.append(Task(study_run, config))
    return tasks


# ------------------------------------------------------------------------------------ the dance


def dance_angles(
    source: str = "mdlt", seconds: float = 6.0, fps: int = 60, seed: int = 0
) -> tuple[np.ndarray, str]:
    """``(T, 4)`` dance angles and where they came from.

    ``"mdlt"``: the choreography of the first sequence of MDLT's default data set in the AIST++
    layout (:func:`thesis_lib.mdlt.synth.default_dataset`, read by
    :func:`thesis_lib.mdlt.readers.load_aist`), the same angles MDLT learns to generate;
    ``"demo"``: :func:`thesis_lib.ur3.dance.demo_angles`.

    Used in: UR3 deployment chapter.
    """
    if source == "demo":
        return demo_angles(
            seconds, fps, seed=seed
        ), f"stand-in dance (thesis_lib.ur3.dance.demo_angles, seed {seed})"
    if source != "mdlt":
        raise ValueError(f"Unknown dance source {source!r}. Valid: mdlt, demo.")
    root = mdlt_synth.default_dataset("aist", "smoke", seed=seed, progress=False)
    genre = mdlt_readers.AIST_GENRES[0] if hasattr(mdlt_readers, "AIST_GENRES") else None
    seqs = mdlt_readers.load_aist(root, genres=[genre] if genre else None, progress=False)
    s = seqs[0]
    if int(s.fps) != int(fps):
        raise ValueError(f"MDLT sequence {s.name} is at {s.fps} fps, the chapter asked for {fps}.")
    n = min(len(s.angles), int(round(seconds * fps)))
    return np.asarray(
        s.angles[:n], dtype=np.float64
    ), f"MDLT default data set (AIST++ layout), sequence {s.name}"
