"""The DEFENDER chapter's experiments (thesis 4.3.2-4.3.3): the ablation and the training runs.

One task function per experiment, each run through :func:`thesis_lib.sweep.run_tasks` and
stored under ``results/03_defender/tasks`` (an interrupted chapter resumes; a run that Tables
4.3-4.4 and 4.5 share is trained once):

- :func:`ablation_task` the 576-strategy ablation of one task's logged episodes, one trajectory
  kind (:func:`run_ablation` builds the grid);
- :func:`train_task` one training run (:func:`train_run`) as its episode log
  (:func:`run_tables_4_3_4_4`, :func:`run_table_4_5` build the grids;
  :func:`runs_from_episodes` reduces each run to one row, :data:`RUN_COLUMNS`).

The study's runs (:mod:`thesis_lib.chapters.defender.study`) are the same task, asked also for
the final policy's evaluation and with the study's pinned demonstrations, and reduced to one
row (:func:`~thesis_lib.chapters.defender.study.study_row`).

Used in: DEFENDER chapter (thesis 4.3).
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any, Literal, NamedTuple, cast

import numpy as np
import pandas as pd
from stable_baselines3.common.callbacks import StopTrainingOnMaxEpisodes

from thesis_lib.book import results_dir
from thesis_lib.chapters.defender.config import CHAPTER, Config
from thesis_lib.chapters.defender.demos import (
    demos_file,
    demos_subset,
    episode_limit,
    load_demos_file,
    make_env,
    rl_overrides,
    study_demonstrations,
    thesis_env_name,
)
from thesis_lib.defender import DefenderWrapper, DemoRun, DemoSet, RandomFilter, TimerFilter
from thesis_lib.defender.ablation import strategy_ablation
from thesis_lib.rl import config_from_params, evaluate, train
from thesis_lib.sweep import Task, note_resumed_cpu, run_tasks, task_id, task_scratch

RUN_COLUMNS: tuple[str, ...] = (
    "task", "algo", "trajectory", "strategy", "safe_strategy", "unsafe_strategy", "n_demos", "paper_compat",
    "seed", "acc_reward", "crash_pct", "filtered_pct", "mean_last_100", "n_episodes", "wall_time_s",
)  # fmt: skip
"""Columns of one training run's summary row (:func:`train_run`)."""


@task_id("thesis_lib.chapters.defender:ablation_task")
def ablation_task(config: dict[str, Any]) -> pd.DataFrame:
    """Sweep task: the 576-strategy ablation of one task's logged episodes, one trajectory kind.

    Config keys: ``task``, ``trajectory``, ``episodes`` and ``demos`` (:func:`demos_file` names:
    the logged SAC episodes as a safe-only set, and the demonstrations), ``horizon``,
    ``max_trajectory``, ``n_jobs``.

    Used in: DEFENDER chapter (thesis 4.3.2), through :func:`run_ablation`.
    """
    scores = strategy_ablation(
        load_demos_file(config["episodes"]).safe,
        load_demos_file(config["demos"]),
        trajectory=config["trajectory"],
        horizon=config["horizon"],
        max_trajectory=config["max_trajectory"],
        n_jobs=config["n_jobs"],
    )
    scores.insert(0, "trajectory", config["trajectory"])
    scores.insert(0, "task", config["task"])
    return scores


def run_ablation(cfg: Config, runs: dict[str, DemoRun], progress: bool = True) -> pd.DataFrame:
    """The 576-strategy ablation on each task's logged SAC episodes, for both trajectory kinds.

    Returns:
        One row per (task, trajectory, strategy): ``task``, ``trajectory`` and
        :data:`~thesis_lib.defender.ablation.ABLATION_COLUMNS`.

    Used in: DEFENDER chapter (thesis 4.3.2).
    """
    tasks = []
    for task, run in runs.items():
        episodes = demos_file(DemoSet(list(run.episodes), [], task), f"{thesis_env_name(task)}-log")
        demos = demos_file(demos_subset(run, cfg.n_demos))
        horizon = cfg.max_episode_steps or episode_limit(make_env(task, None))
        for trajectory in ("state", "state_action"):
            config = {
                "task": task,
                "trajectory": trajectory,
                "episodes": episodes,
                "demos": demos,
                "horizon": horizon,
                "max_trajectory": cfg.max_trajectory,
                "n_jobs": cfg.n_jobs,
            }
            tasks.append(Task(ablation_task, config))
    rows = run_tasks(
        tasks, store=results_dir(CHAPTER) / "tasks", desc="ablation", progress=progress
    )
    return rows.drop(columns="task_key")


#: Config fields a training run depends on (each :func:`train_task` config holds them).
TRAIN_FIELDS = (
    "max_episode_steps", "train_timesteps", "train_episodes", "net_arch", "learning_rate",
    "batch_size", "max_trajectory", "dynamics_train_every",
)  # fmt: skip


class TrainedRun(NamedTuple):
    """One training run (:func:`train_run`): its summary row, its episode log and its result."""

    row: dict[str, Any]
    """The run's summary row, :data:`RUN_COLUMNS`."""
    episodes: pd.DataFrame
    """One row per finished training episode, with the run's keys and ``wall_time_s``."""
    result: Any
    """The :class:`~thesis_lib.rl.TrainResult` (its ``model`` is the trained agent)."""


def train_run(
    task: str,
    algo: str,
    seed: int,
    cfg: Config,
    demos: DemoSet | None = None,
    strategy: str | None = None,
    trajectory: str = "state",
    paper_compat: bool = False,
    checkpoint: str | Path | None = None,
) -> TrainedRun:
    """Train one agent, with DEFENDER when ``demos`` and ``strategy`` are given.

    With ``checkpoint`` (a folder), the run saves itself there every
    :data:`CHECKPOINT_EVERY` steps and continues from there when run again
    (:mod:`thesis_lib.rl.resume`): the same run, bit for bit. A run bounded by
    ``cfg.train_episodes`` is not checkpointed (its stopping callback keeps no state).

    The one training function of the chapter, run by its one training task, :func:`train_task`
    (Tables 4.3-4.5, and the study through
    :func:`~thesis_lib.chapters.defender.study.study_run`).

    Returns:
        ``(row, episodes, result)``: a summary row (:data:`RUN_COLUMNS`; Acc Reward = best
        training episode return, % Crash = share of training episodes that crashed, filtered
        episodes not counted as crashes), the episode log with the run's keys and
        ``wall_time_s``, and the :class:`~thesis_lib.rl.TrainResult` (its model).

    Used in: DEFENDER chapter (thesis 4.3.3).
    """
    env = make_env(task, cfg.max_episode_steps)
    safe_s = unsafe_s = None
    rate = random_filter_rate(strategy)
    # both filters alike: the seed, and what each filtered action would have done (a copy of the
    # state is stepped and restored bit for bit: training is unchanged): saved crashes vs false
    # alarms; a dynamics model with "2 hidden layers" of the agent's size (4.3.3)
    filter_kwargs: dict[str, Any] = {
        "seed": seed,
        "counterfactual": True,
        "dynamics_train_every": cfg.dynamics_train_every,
        "dynamics_kwargs": {
            "hidden": list(cfg.net_arch),
            "learning_rate": cfg.learning_rate,
            "batch_size": cfg.batch_size,
        },
    }
    timing = timer_filter_params(strategy)
    if demos is not None and rate is not None:  # the control: a filter firing at random
        env = RandomFilter(env, demos.safe, demos.unsafe, rate=rate, **filter_kwargs)
    elif demos is not None and timing is not None:  # the control: firing at DEFENDER's steps
        env = TimerFilter(
            env, demos.safe, demos.unsafe, p_episode=timing[0], step_deciles=timing[1],
            **filter_kwargs,
        )  # fmt: skip
    elif demos is not None and strategy is not None:
        safe_s, unsafe_s = strategy.split("/")
        env = DefenderWrapper(
            env,
            demos.safe,
            demos.unsafe,
            safe_method=safe_s,
            unsafe_method=unsafe_s,
            trajectory=cast(Literal["state", "state_action"], trajectory),
            max_trajectory=cfg.max_trajectory,
            paper_compat=paper_compat,
            **filter_kwargs,
        )
    callbacks = []
    steps = cfg.train_timesteps
    if cfg.train_episodes:
        horizon = cfg.max_episode_steps or episode_limit(env) or 1000
        steps = (
            cfg.train_episodes * horizon
        )  # an upper bound; the callback stops at the episode count
        callbacks.append(StopTrainingOnMaxEpisodes(cfg.train_episodes))
    rl = config_from_params(
        {
            "algo": algo,
            "env_id": None,
            "total_timesteps": int(steps),
            "seed": int(seed),
            **rl_overrides(cfg),
        }
    )
    res = train(
        rl,
        env=env,
        callbacks=callbacks,
        progress=False,
        info_keys=["filtered", "filter_step", "would_crash"],
        checkpoint=None if callbacks else checkpoint,
        checkpoint_every=CHECKPOINT_EVERY,
    )
    ep = res.episodes
    ep["filtered"] = ep["filtered"].astype("boolean").fillna(False).astype(bool)
    ep["crashed"] = ep["crashed"] & ~ep["filtered"]  # a filtered episode is not a crash (4.3.3)
    keys = {
        "task": task,
        "algo": algo,
        "trajectory": trajectory if strategy else "none",
        "strategy": strategy or "none",
        "safe_strategy": safe_s,
        "unsafe_strategy": unsafe_s,
        "n_demos": len(demos.safe) if demos is not None and strategy else 0,
        "paper_compat": bool(paper_compat),
        "seed": int(seed),
    }
    row = {**keys, **_run_numbers(ep), "wall_time_s": res.wall_time_s}
    for k, v in reversed(keys.items()):
        ep.insert(0, k, v)
    ep["wall_time_s"] = res.wall_time_s
    return TrainedRun(row, ep, res)


RANDOM_STRATEGY = "random:"
"""The prefix of a control arm's ``strategy``: ``"random:0.01"`` is a filter that fires at
random with probability 0.01 per step (:class:`~thesis_lib.defender.RandomFilter`)."""


MATCHED_RANDOM_STRATEGY = "random:matched"
"""The ``strategy`` of the matched control (``Config.random_filter_matched``): a filter firing
at random at the rate DEFENDER fired in the run it matches. The study resolves it to a
:func:`random_strategy` when the run starts
(:func:`~thesis_lib.chapters.defender.study.matched_rate`); it never reaches :func:`train_run`."""


def random_strategy(rate: float) -> str:
    """The ``strategy`` of the random-filter control firing with probability ``rate``.

    >>> random_strategy(0.01)
    'random:0.01'
    """
    return f"{RANDOM_STRATEGY}{float(rate):g}"


def random_filter_rate(strategy: str | None) -> float | None:
    """The firing probability of a :func:`random_strategy`, None for any other strategy.

    >>> random_filter_rate("random:0.01"), random_filter_rate("MeanDemoW5/MeanDemoW10")
    (0.01, None)
    """
    if not strategy or not strategy.startswith(RANDOM_STRATEGY):
        return None
    if strategy == MATCHED_RANDOM_STRATEGY:
        raise ValueError(
            f"{strategy!r} has no rate of its own: the study resolves it from the run it "
            "matches (thesis_lib.chapters.defender.study.matched_rate)."
        )
    return float(strategy[len(RANDOM_STRATEGY) :])


TIMER_STRATEGY = "timer:"
"""The prefix of a timing control's ``strategy``: ``"timer:0.6:50,51,...,58"`` is a blind filter
that arms 60% of the episodes and fires in each at a step drawn from those 11 deciles
(:class:`~thesis_lib.defender.TimerFilter`)."""


MATCHED_TIMER_STRATEGY = "timer:matched"
"""The ``strategy`` of the timing control (``Config.timer_filter_matched``): a blind filter
that ends the share of episodes DEFENDER ended in the run it matches, each at a step drawn
from that filter's own firing steps. The study resolves it to a :func:`timer_strategy` when
the run starts (:func:`~thesis_lib.chapters.defender.study.matched_timing`); it never reaches
:func:`train_run`."""


def timer_strategy(p_episode: float, step_deciles: Sequence[float]) -> str:
    """The ``strategy`` of the timing control: arm a share ``p_episode`` of the episodes, fire
    at a step drawn from ``step_deciles`` (11 values).

    >>> timer_strategy(0.5, [50, 51, 52, 53, 54, 54, 55, 56, 57, 58, 60])
    'timer:0.5:50,51,52,53,54,54,55,56,57,58,60'
    """
    steps = ",".join(f"{float(q):g}" for q in step_deciles)
    return f"{TIMER_STRATEGY}{float(p_episode):g}:{steps}"


def timer_filter_params(strategy: str | None) -> tuple[float, list[float]] | None:
    """``(p_episode, step_deciles)`` of a :func:`timer_strategy`, None for any other strategy.

    >>> timer_filter_params("timer:0.5:" + ",".join(["7"] * 11))[0]
    0.5
    >>> timer_filter_params("MeanDemoW5/MeanDemoW10") is None
    True
    """
    if not strategy or not strategy.startswith(TIMER_STRATEGY):
        return None
    if strategy == MATCHED_TIMER_STRATEGY:
        raise ValueError(
            f"{strategy!r} has no steps of its own: the study resolves it from the run it "
            "matches (thesis_lib.chapters.defender.study.matched_timing)."
        )
    p, _, steps = strategy[len(TIMER_STRATEGY) :].partition(":")
    return float(p), [float(q) for q in steps.split(",")]


def _run_numbers(ep: pd.DataFrame) -> dict[str, Any]:
    return {
        "acc_reward": float(ep["return"].max()) if len(ep) else np.nan,
        "crash_pct": 100 * float(ep["crashed"].mean()) if len(ep) else np.nan,
        "filtered_pct": 100 * float(ep["filtered"].mean()) if len(ep) else np.nan,
        "mean_last_100": float(ep["return"].tail(100).mean()) if len(ep) else np.nan,
        "n_episodes": len(ep),
    }


CHECKPOINT_EVERY = 20_000
"""Env steps between the checkpoints of a study's training run (:func:`train_run`): about six
minutes of one core for a filtered Hopper run, the most a stopped session loses per run."""

EVAL_SEED = 100_000
"""The final evaluation of a run with training seed ``s`` (:func:`train_task` with
``eval_episodes``) resets its task with ``EVAL_SEED + s``."""


@task_id("thesis_lib.chapters.defender:train_task")
def train_task(config: dict[str, Any]) -> list[dict[str, Any]]:
    """Sweep task: one training run (:func:`train_run`), its episodes as long-format rows.

    Config keys: ``task``, ``algo``, ``seed``, ``strategy`` (None: no filter), ``trajectory``,
    ``paper_compat``, ``demos`` and ``train`` (the :data:`TRAIN_FIELDS` of the chapter's
    :class:`Config`). ``demos`` is a :func:`demos_file` name, None, or (the study's) a
    demonstration recipe (:data:`~thesis_lib.chapters.defender.demos.DEMO_FIELDS`) with
    ``n_demos`` and ``top_up`` beside it: the pinned demonstrations of
    :func:`~thesis_lib.chapters.defender.demos.study_demonstrations`, whose figures
    (``demos_file``, ``demos_safe``, ...) every row then carries. ``eval_episodes`` (optional,
    default 0): evaluate the final policy without the filter over that many episodes, reset
    with ``EVAL_SEED + seed``.

    Returns:
        One row per training episode (``phase == "train"``), with the run's keys,
        ``wall_time_s``, ``steps`` (environment steps trained) and ``train_cpu_s``; a run that
        finished no episode gives one such row with ``episode`` None. Then, with
        ``eval_episodes``, one row per evaluation episode (``phase == "eval"``: ``episode``,
        ``return``, ``crashed``, ``length``).

    Used in: DEFENDER chapter (thesis 4.3.3), through :func:`run_tables_4_3_4_4` and
    :func:`run_table_4_5`, and its study (:func:`~thesis_lib.chapters.defender.study.study_run`).
    """
    task, seed = config["task"], int(config["seed"])
    cfg = Config(**config["train"], tasks=[task])
    demos: DemoSet | None = None
    info: dict[str, Any] = {}
    if isinstance(config["demos"], dict):
        if config["strategy"]:
            demos, info = study_demonstrations(
                task, config["demos"], int(config["n_demos"]), bool(config.get("top_up", True))
            )
    elif config["demos"]:
        demos = load_demos_file(config["demos"])
    c0 = time.process_time()
    row, ep, res = train_run(
        task,
        config["algo"],
        seed,
        cfg,
        demos=demos,
        strategy=config["strategy"],
        trajectory=config["trajectory"],
        paper_compat=config["paper_compat"],
        checkpoint=task_scratch(),  # inside a study: resumable; elsewhere None
    )
    if res.resumed_cpu_s:
        note_resumed_cpu(res.resumed_cpu_s)  # the task's cost includes its earlier parts
    run = {
        "steps": int(res.model.num_timesteps),
        "train_cpu_s": time.process_time() - c0 + res.resumed_cpu_s,
        **info,
    }
    keys = {k: row[k] for k in RUN_COLUMNS[:9]}
    if not len(ep):
        rows = [{**keys, "episode": None, "wall_time_s": row["wall_time_s"]}]
    else:
        rows = ep.to_dict(orient="records")
    rows = [{**r, "phase": "train", **run} for r in rows]
    n_eval = int(config.get("eval_episodes", 0))
    if n_eval:
        ev = evaluate(
            res.model,
            make_env(task, cfg.max_episode_steps),
            n_episodes=n_eval,
            seed=EVAL_SEED + seed,
        )
        rows += [
            {
                **keys,
                "phase": "eval",
                "episode": i,
                "return": float(e["return"]),
                "crashed": bool(e["crashed"]),
                "length": float(e["length"]),
            }
            for i, e in enumerate(ev.to_dict(orient="records"))
        ]
    return rows


_RUN_KEYS = list(RUN_COLUMNS[:9])


def runs_from_episodes(episodes: pd.DataFrame) -> pd.DataFrame:
    """One summary row per run (:data:`RUN_COLUMNS`) from :func:`train_task`'s episode rows."""
    rows = []
    if "phase" in episodes:  # a run's evaluation episodes are not training episodes
        episodes = episodes[episodes["phase"].fillna("train") == "train"]
    for _, ep in episodes.groupby("task_key", sort=False):
        first = ep.iloc[0]
        ep = ep[ep["episode"].notna()]
        keys = {k: first[k] for k in _RUN_KEYS}
        keys["paper_compat"] = bool(keys["paper_compat"])
        rows.append({**keys, **_run_numbers(ep), "wall_time_s": float(first["wall_time_s"])})
    return pd.DataFrame(rows, columns=list(RUN_COLUMNS))


class TableRuns(NamedTuple):
    """Training runs: one summary row each, and every episode of every run."""

    runs: pd.DataFrame
    """One row per run, :data:`RUN_COLUMNS`."""
    episodes: pd.DataFrame
    """Every training episode, with the run's keys."""


def _train_spec(cfg: Config, spec: dict[str, Any], demos: DemoSet | None) -> Task:
    strategy = spec.get("strategy")
    config = {
        "task": spec["task"],
        "algo": spec["algo"],
        "seed": int(spec["seed"]),
        "strategy": strategy,
        "trajectory": spec.get("trajectory", "state") if strategy else "state",
        "paper_compat": bool(spec.get("paper_compat", False)),
        "demos": demos_file(demos) if strategy and demos is not None else None,
        "train": {f: getattr(cfg, f) for f in TRAIN_FIELDS},
    }
    return Task(train_task, config)


def _run_all(tasks: list[Task], desc: str, progress: bool) -> TableRuns:
    unique = list({t.key: t for t in tasks}.values())
    episodes = run_tasks(unique, store=results_dir(CHAPTER) / "tasks", desc=desc, progress=progress)
    runs = runs_from_episodes(episodes)
    eps = episodes[episodes["episode"].notna()].drop(columns="task_key").reset_index(drop=True)
    return TableRuns(runs, eps)


def run_tables_4_3_4_4(
    cfg: Config, demo_runs: dict[str, DemoRun], progress: bool = True
) -> TableRuns:
    """SAC and TD3 with and without DEFENDER on every task and seed (Tables 4.3 and 4.4).

    Runs each algorithm (on its ``algo_tasks``, default every task) plain, with each of
    ``state_strategies`` on state trajectories, with
    each of ``state_action_strategies`` on state-action trajectories, and (``paper_compat_check``)
    SAC with the first state strategy in the authors' setting.

    Used in: DEFENDER chapter (thesis 4.3.3).
    """
    specs: list[dict[str, Any]] = []
    for task in cfg.tasks:
        for seed in cfg.seeds:
            for algo in cfg.algos:
                if task not in cfg.algo_tasks.get(algo, cfg.tasks):
                    continue
                specs.append({"task": task, "algo": algo, "seed": seed})
                specs += [
                    {"task": task, "algo": algo, "seed": seed, "strategy": s, "trajectory": "state"}
                    for s in cfg.state_strategies
                ]
                specs += [
                    {
                        "task": task,
                        "algo": algo,
                        "seed": seed,
                        "strategy": s,
                        "trajectory": "state_action",
                    }
                    for s in cfg.state_action_strategies
                ]
            if (
                cfg.paper_compat_check
                and cfg.state_strategies
                and "SAC" in cfg.algos
                and task
                in (cfg.tasks[:1] if cfg.paper_compat_tasks is None else cfg.paper_compat_tasks)
            ):
                specs.append(
                    {
                        "task": task,
                        "algo": "SAC",
                        "seed": seed,
                        "strategy": cfg.state_strategies[0],
                        "trajectory": "state",
                        "paper_compat": True,
                    }
                )
    subsets = {task: demos_subset(run, cfg.n_demos) for task, run in demo_runs.items()}
    tasks = [_train_spec(cfg, spec, subsets[spec["task"]]) for spec in specs]
    return _run_all(tasks, "Tables 4.3-4.4", progress)


def run_table_4_5(
    cfg: Config,
    demo_runs: dict[str, DemoRun],
    strategy: str = "MeanDemoW5/MeanDemoW10",
    progress: bool = True,
) -> TableRuns:
    """SAC with DEFENDER (state trajectories, ``strategy``) and each of ``n_demos_list`` demonstrations.

    A run Tables 4.3-4.4 already made (same task, seed, strategy and demonstrations) is read
    back from the sweep store, not repeated; so is a count larger than the pool (it gives the
    same demonstrations as the whole pool).

    Used in: DEFENDER chapter (thesis 4.3.3, Table 4.5).
    """
    tasks = []
    for task in cfg.tasks:
        for n in cfg.n_demos_list:
            demos = demos_subset(demo_runs[task], n)
            for seed in cfg.seeds:
                spec = {
                    "task": task,
                    "algo": "SAC",
                    "seed": seed,
                    "strategy": strategy,
                    "trajectory": "state",
                }
                tasks.append(_train_spec(cfg, spec, demos))
    out = _run_all(tasks, "Table 4.5", progress)
    runs = out.runs.sort_values(["task", "n_demos", "seed"], kind="stable")
    return TableRuns(runs.reset_index(drop=True), out.episodes)
