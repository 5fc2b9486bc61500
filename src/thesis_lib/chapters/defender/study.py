"""The DEFENDER chapter's pre-registered study of claims C7-C9 (``thesis study 03_defender``).

:func:`study_tasks` is the grid (``params/03_defender.study.yml``): one :func:`study_run` per
training run. Each runs :func:`~thesis_lib.chapters.defender.tasks.train_task`, the task of
Tables 4.3-4.5, with the final policy's evaluation without the filter, and reduces its rows to
one (:func:`study_row`: :func:`training_run_numbers` and the evaluation). Its demonstrations are
pinned beside the study's rows
(:func:`~thesis_lib.chapters.defender.demos.pinned_demonstrations`).

Used in: DEFENDER chapter study (``thesis study 03_defender``).
"""

from __future__ import annotations

from typing import Any

import numpy as np
import pandas as pd
import torch

from thesis_lib.book.study import studies_dir
from thesis_lib.chapters.defender.config import CHAPTER, Config
from thesis_lib.chapters.defender.demos import (
    DEMO_FIELDS,
    thesis_env_name,
)
from thesis_lib.chapters.defender.tasks import (
    MATCHED_RANDOM_STRATEGY,
    MATCHED_TIMER_STRATEGY,
    RANDOM_STRATEGY,
    RUN_COLUMNS,
    TIMER_STRATEGY,
    TRAIN_FIELDS,
    random_filter_rate,
    random_strategy,
    runs_from_episodes,
    timer_strategy,
    train_task,
)
from thesis_lib.sweep import Task, TaskStore, task_id

#: The thesis's Table 4.3 plain-SAC Acc Reward per task: ``*_score`` columns are returns in
#: percent of it (the tasks' returns differ by a factor 3, so raw returns would let
#: InvertedDoublePendulum decide every aggregate).
THESIS_SAC_RETURN: dict[str, float] = {
    "Hopper-v5": 3474.0,
    "InvertedDoublePendulum-v5": 9359.0,
    "Walker2d-v5": 3326.0,
}


STUDY_CURVE_BINS = 10
"""Training is cut into this many equal spans of environment steps; each study row carries the
crash rate, filtered rate and mean return of the episodes that ended in each span."""


FILTER_STEP_COLUMNS = [f"filter_step_q{q:03d}" for q in range(0, 101, 10)]
"""The deciles (0-100%) of the steps at which a run's filter ended its episodes: each filtered
episode's length, the filtered step included (:func:`filter_step_numbers`). A blind control
that fires at the filter's steps, not at its states, can be drawn from them."""


def filter_step_numbers(episodes: pd.DataFrame) -> dict[str, float]:
    """The deciles of the steps at which the filter ended its episodes
    (:data:`FILTER_STEP_COLUMNS`): the ``length`` of each ``filtered`` episode of a training log
    (one row per episode, as :func:`training_run_numbers` reads it). All NaN where no episode
    was filtered or the log has no ``length`` (a plain run's rows have them NaN).

    >>> log = pd.DataFrame({"filtered": [True, False, True, True], "length": [50, 140, 54, 58]})
    >>> q = filter_step_numbers(log)
    >>> q["filter_step_q000"], q["filter_step_q050"], q["filter_step_q100"]
    (50.0, 54.0, 58.0)
    """
    nan = dict.fromkeys(FILTER_STEP_COLUMNS, float("nan"))
    if "length" not in episodes or "filtered" not in episodes:
        return nan
    lengths = episodes.loc[episodes["filtered"].astype(bool), "length"].to_numpy(dtype=float)
    if not len(lengths):
        return nan
    qs = np.percentile(lengths, np.arange(0, 101, 10))
    return {c: float(v) for c, v in zip(FILTER_STEP_COLUMNS, qs, strict=True)}


CRASH_DEFINITION = (
    "A training episode **crashed** when the task terminated it before the horizon "
    "(an unsafe state: Hopper or Walker2d fell, the pendulum tipped over) and the filter did "
    "not end it first; an episode the filter ended is **filtered**, not crashed, and one that "
    "reached the horizon is neither (thesis 4.3.3: an episode 'can end early if the agent "
    "reaches an unsafe state, leading to a crash if the transition was not filtered'). The "
    "crash rate is the share of a run's training episodes that crashed, the filtered rate the "
    "share the filter ended."
)
"""The thesis's definition of a crash, as the chapter prints it."""


def training_run_numbers(
    episodes: pd.DataFrame,
    total_steps: int,
    bins: int = STUDY_CURVE_BINS,
    has_filter: bool = True,
) -> dict[str, Any]:
    """Reduce one training run's episode log to the study's per-run measures.

    A *crash* is the thesis's (4.3.3, :data:`CRASH_DEFINITION`): the task terminated the
    episode before the horizon and the filter did not end it first (``crashed``, as
    :class:`~thesis_lib.defender.DefenderWrapper` and :func:`train_run` label it); an episode the
    filter ended is *filtered*.

    Args:
        episodes: one row per finished training episode with ``return``, ``crashed``,
            ``filtered`` and ``timestep`` (the environment step at which it ended, 1-based).
        total_steps: the run's environment steps (the curve's spans are ``total_steps / bins``).
        bins: spans of the curve.
        has_filter: whether the run had a filter; without one the counterfactual columns are
            NaN (a plain agent's log has an empty ``would_crash`` column too).

    Returns:
        ``episodes``, ``crashes``, ``filtered``; ``crash_rate`` and ``filtered_rate`` (shares of
        the episodes, 0-1); ``crash_free_rate`` = 1 - ``crash_rate`` (higher is better, for the
        comparisons); ``crashes_per_1k_steps``; ``return_best`` (the thesis's Acc Reward) and
        ``return_last`` (mean return of the last span's episodes); and per span ``b``
        ``crash_rate_b{b}``, ``filtered_rate_b{b}``, ``return_b{b}`` (NaN where no episode
        ended in the span); and, where the log has the filter's counterfactual
        (``would_crash``), ``saved_crashes``, ``false_alarms``, ``filter_precision``,
        ``filter_recall`` and ``crash_rate_without_filter`` (:func:`_counterfactual_numbers`).

    Raises:
        ValueError: a column is missing, or ``total_steps`` / ``bins`` is not positive.

    Used in: DEFENDER chapter study (``thesis study 03_defender``).
    """
    need = {"return", "crashed", "filtered", "timestep"}
    if missing := sorted(need - set(episodes.columns)):
        raise ValueError(f"the episode log lacks {missing}; it has {list(episodes.columns)}")
    if total_steps < 1 or bins < 1:
        raise ValueError(f"total_steps and bins must be positive, got {total_steps}, {bins}")
    ep = episodes
    n = len(ep)
    crashed = ep["crashed"].astype(bool).to_numpy()
    filtered = ep["filtered"].astype(bool).to_numpy()
    if (crashed & filtered).any():
        raise ValueError("an episode is both crashed and filtered; a filtered one never crashes")
    ret = ep["return"].to_numpy(dtype=float)
    span = np.minimum((ep["timestep"].to_numpy(dtype=float) - 1) * bins // total_steps, bins - 1)
    out: dict[str, Any] = {
        "episodes": n,
        "crashes": int(crashed.sum()),
        "filtered": int(filtered.sum()),
        "crash_rate": float(crashed.mean()) if n else np.nan,
        "filtered_rate": float(filtered.mean()) if n else np.nan,
    }
    out["crash_free_rate"] = 1.0 - out["crash_rate"]
    out["crashes_per_1k_steps"] = 1000.0 * out["crashes"] / total_steps
    out["return_best"] = float(ret.max()) if n else np.nan
    last = ret[span == bins - 1]
    out["return_last"] = float(last.mean()) if len(last) else np.nan
    for b in range(bins):
        m = span == b
        k = int(m.sum())
        out[f"crash_rate_b{b}"] = float(crashed[m].mean()) if k else np.nan
        out[f"filtered_rate_b{b}"] = float(filtered[m].mean()) if k else np.nan
        out[f"return_b{b}"] = float(ret[m].mean()) if k else np.nan
    out.update(_counterfactual_numbers(ep, crashed, filtered, has_filter))
    return out


def _counterfactual_numbers(
    ep: pd.DataFrame, crashed: np.ndarray, filtered: np.ndarray, has_filter: bool = True
) -> dict[str, float]:
    """What the filter saved, from the episode log's ``would_crash`` (a filtered action stepped
    on a copy of the state, :class:`~thesis_lib.defender.DefenderWrapper`'s counterfactual):
    ``saved_crashes`` (it would have crashed on that step), ``false_alarms`` (it would not; it
    may have crashed a few steps on: ``thesis defender lookahead`` measures how many),
    ``filter_precision`` = saved / filtered, ``filter_recall`` = saved / (saved + real
    crashes), and ``crash_rate_without_filter`` = (saved + real crashes) / episodes. A filter
    that never fired saved nothing and raised no false alarm (precision NaN). NaN without a
    filter (``has_filter=False``: a plain agent's log has an empty ``would_crash`` column too)
    or where the log has no counterfactual (a run made before it existed)."""
    nan = float("nan")
    names = (
        "saved_crashes",
        "false_alarms",
        "filter_precision",
        "filter_recall",
        "crash_rate_without_filter",
    )
    if not has_filter or "would_crash" not in ep or ep.loc[filtered, "would_crash"].isna().any():
        return dict.fromkeys(names, nan)
    saved = int(ep.loc[filtered, "would_crash"].astype(bool).sum())
    alarms = int(filtered.sum()) - saved
    real = int(crashed.sum())
    return {
        "saved_crashes": saved,
        "false_alarms": alarms,
        "filter_precision": saved / (saved + alarms) if saved + alarms else nan,
        "filter_recall": saved / (saved + real) if saved + real else nan,
        "crash_rate_without_filter": (saved + real) / len(ep) if len(ep) else nan,
    }


#: The columns of a study run's row (:func:`study_run`; the ``demos_*`` and ``sac_rollouts_*``
#: in filtered runs only); the study engine checks the study file's metrics against them.
STUDY_COLUMNS = [
    "method", "setting", "seed", "scale", "top_up",
    *(c for c in RUN_COLUMNS if c != "seed"),
    # training_run_numbers
    "episodes", "crashes", "filtered", "crash_rate", "filtered_rate", "crash_free_rate",
    "crashes_per_1k_steps", "return_best", "return_last",
    "saved_crashes", "false_alarms", "filter_precision", "filter_recall",
    "crash_rate_without_filter",
    *(f"{k}_b{b}" for b in range(STUDY_CURVE_BINS) for k in ("crash_rate", "filtered_rate", "return")),
    # filter_step_numbers
    *FILTER_STEP_COLUMNS,
    "eval_return", "eval_return_std", "eval_crash_rate", "eval_length", "eval_score",
    "best_score", "steps", "train_wall_s", "train_cpu_s", "log_speed",
    # study_demonstrations
    "demos_file", "demos_safe", "demos_unsafe", "demos_safe_expert", "demos_unsafe_expert",
    "sac_rollouts_safe", "sac_rollouts_unsafe",
    # the matched controls (study_run)
    "random_rate", "matched_to", "timer_p_episode",
]  # fmt: skip


def matched_rate(key: str) -> float:
    """The firing rate a matched control (:data:`MATCHED_RANDOM_STRATEGY`) takes from the run
    it matches: that run's filtered episodes per training step (each firing ends an episode),
    read from its finished task record, task ``key``, in any store under
    ``studies/03_defender/`` (a key names one task whichever study ran it).

    Raises:
        RuntimeError: no store holds a finished record of ``key`` (the control runs after the
            run it matches: resume the study once that has finished), or the record is
            damaged or not a training run's (:meth:`TaskStore.read`).
    """
    _, row = _matched_row(key)
    return float(row["filtered"]) / float(row["steps"])


def _matched_row(key: str) -> tuple[Any, dict[str, Any]]:
    """The path and row of the finished run ``key`` a matched control reads, from any store
    under ``studies/03_defender/`` (:func:`matched_rate`'s errors)."""
    root = studies_dir(CHAPTER)
    found = sorted(p for p in root.glob(f"**/tasks/{key}.json") if p.parent.name == "tasks")
    if not found:
        raise RuntimeError(
            f"the matched control needs the finished run {key} (the filter it matches) under "
            f"{root}; it has not finished. The study orders the controls last: resume it once "
            "that run has finished."
        )
    rows = TaskStore(found[0].parent).read(key)["rows"]
    if len(rows) != 1 or not {"filtered", "steps"} <= set(rows[0]) or not rows[0]["steps"]:
        raise RuntimeError(
            f"{found[0]} is not a finished DEFENDER training run (one row with 'filtered' and "
            "'steps' > 0), so a matched control cannot take its rate from it"
        )
    return found[0], rows[0]


def matched_timing(key: str) -> tuple[float, list[float]]:
    """What the timing control (:data:`MATCHED_TIMER_STRATEGY`) takes from the run it
    matches, task ``key``: the share of its episodes its filter ended (``filtered_rate``) and
    the deciles of the steps it ended them at (:data:`FILTER_STEP_COLUMNS`).

    A filter that never fired is matched by a timer that never fires (``p_episode`` 0).

    Raises:
        RuntimeError: as :func:`matched_rate`; or the run fired but its row has no firing
            steps (a run stored before the study rows recorded them).
    """
    path, row = _matched_row(key)
    if not row["filtered"]:
        return 0.0, [1.0] * len(FILTER_STEP_COLUMNS)
    deciles = np.array([row.get(c, np.nan) for c in FILTER_STEP_COLUMNS], dtype=float)
    if not np.isfinite(deciles).all():  # JSON keeps a NaN as NaN, a missing column as absent
        raise RuntimeError(
            f"{path} has no firing steps ({FILTER_STEP_COLUMNS[0]}..): its run was stored "
            "before the study rows recorded them, so a timing control cannot be matched to it"
        )
    return float(row["filtered_rate"]), deciles.tolist()


@task_id("thesis_lib.chapters.defender:study_run")
def study_run(config: dict[str, Any]) -> list[dict[str, Any]]:
    """One study task: the chapter's training run (:func:`train_task`, with the study's pinned
    demonstrations and the final policy's evaluation), reduced to one row (:func:`study_row`).

    ``config`` (:func:`study_task` builds it): ``label`` (the method's name in the study),
    ``task``, ``algo``, ``seed``, ``strategy`` (None: no filter), ``trajectory``, ``n_demos``,
    ``top_up``, ``demos`` (the demonstration recipe, :data:`DEMO_FIELDS`; None without a
    filter), ``train`` (:data:`TRAIN_FIELDS`), ``eval_episodes``, ``bins`` and, for a scale
    check, ``scale``. A matched control (``strategy`` :data:`MATCHED_RANDOM_STRATEGY`) also has
    ``match``: it fires at :func:`matched_rate` of that run, and its row says the rate
    (``random_rate``) and the run (``matched_to``); so has the timing control
    (:data:`MATCHED_TIMER_STRATEGY`), which fires at that run's own steps
    (:func:`matched_timing`; its row says ``timer_p_episode`` and ``matched_to``).

    Used in: DEFENDER chapter study (``thesis study 03_defender``).
    """
    torch.set_num_threads(1)  # small nets: one core per run; the study runs one run per core
    run = {k: config[k] for k in ("task", "algo", "seed", "strategy", "trajectory")}
    matched: dict[str, Any] = {}
    if config["strategy"] == MATCHED_RANDOM_STRATEGY:
        run["strategy"] = random_strategy(matched_rate(config["match"]))
        rate = random_filter_rate(run["strategy"])  # as the filter reads it (6 digits)
        # the row keeps the method's strategy (one method over seeds), and says the rate apart
        matched = {
            "strategy": config["strategy"],
            "random_rate": rate,
            "matched_to": config["match"],
        }
    elif config["strategy"] == MATCHED_TIMER_STRATEGY:
        p_episode, deciles = matched_timing(config["match"])
        run["strategy"] = timer_strategy(p_episode, deciles)
        matched = {
            "strategy": config["strategy"],
            "timer_p_episode": p_episode,
            "matched_to": config["match"],
        }
    rows = train_task(
        {
            **run,
            "paper_compat": False,
            "demos": config["demos"],
            "n_demos": config["n_demos"],
            "top_up": config["top_up"],
            "train": config["train"],
            "eval_episodes": config["eval_episodes"],
        }
    )
    return [{**study_row(config, rows), **matched}]


#: What :func:`train_task` says of a run's pinned demonstrations (in a filtered run's rows).
DEMO_INFO = (
    "demos_file", "demos_safe", "demos_unsafe", "demos_safe_expert", "demos_unsafe_expert",
    "sac_rollouts_safe", "sac_rollouts_unsafe",
)  # fmt: skip


def study_row(config: dict[str, Any], rows: list[dict[str, Any]]) -> dict[str, Any]:
    """A study run's row: :func:`train_task`'s ``rows`` of one run (its training episodes and
    its final evaluation) reduced.

    Returns:
        ``method`` (the label), ``setting`` (the thesis's task name), ``seed``, ``scale``;
        the :data:`RUN_COLUMNS` of the run (``acc_reward``, ``crash_pct``, ...: the chapter's
        tables read them, :func:`runs_from_episodes`); :func:`training_run_numbers`; the final
        policy's evaluation **without the filter** (``eval_return``, ``eval_return_std``,
        ``eval_crash_rate``, ``eval_length``); ``eval_score`` and ``best_score``
        (``eval_return`` and ``return_best`` in % of the thesis's plain-SAC return on the task,
        :data:`THESIS_SAC_RETURN`); ``steps``, ``train_wall_s``, ``train_cpu_s``,
        ``log_speed`` (ln of training steps per CPU-second: higher is cheaper); the deciles of
        the steps at which the filter ended its episodes (:func:`filter_step_numbers`); and
        where the demonstrations came from (:data:`DEMO_INFO`).
    """
    train = [r for r in rows if r.get("phase", "train") == "train"]
    ev = pd.DataFrame([r for r in rows if r.get("phase") == "eval"])
    first = train[0]
    ep = pd.DataFrame([r for r in train if r["episode"] is not None])
    if ep.empty:
        ep = pd.DataFrame(columns=["return", "crashed", "filtered", "timestep"])
    summary = runs_from_episodes(pd.DataFrame(train).assign(task_key="run")).iloc[0]
    run_row = {k: summary[k] for k in RUN_COLUMNS}
    for k in ("seed", "n_demos", "n_episodes"):
        run_row[k] = int(run_row[k])
    run_row["paper_compat"] = bool(run_row["paper_compat"])
    for k in ("safe_strategy", "unsafe_strategy"):
        run_row[k] = None if pd.isna(run_row[k]) else run_row[k]
    steps, cpu = int(first["steps"]), float(first["train_cpu_s"])
    ref = THESIS_SAC_RETURN.get(first["task"], np.nan)
    numbers = training_run_numbers(ep, steps, int(config["bins"]), bool(config["strategy"]))
    return {
        "method": config["label"],
        "setting": thesis_env_name(first["task"]),
        "seed": int(first["seed"]),
        "scale": config.get("scale", "study"),
        "top_up": bool(config["top_up"]) if config["strategy"] else None,
        **run_row,
        **numbers,
        **filter_step_numbers(ep),
        "eval_return": float(ev["return"].mean()),
        "eval_return_std": float(ev["return"].std(ddof=0)),
        "eval_crash_rate": float(ev["crashed"].mean()),
        "eval_length": float(ev["length"].mean()),
        "eval_score": 100.0 * float(ev["return"].mean()) / ref,
        "best_score": 100.0 * numbers["return_best"] / ref,
        "steps": steps,
        "train_wall_s": float(first["wall_time_s"]),
        "train_cpu_s": cpu,
        "log_speed": float(np.log(steps / max(cpu, 1e-9))),
        **{k: first[k] for k in DEMO_INFO if k in first},
    }


def study_label(
    algo: str,
    strategy: str | None = None,
    trajectory: str = "state",
    n_demos: int | None = None,
    top_up: bool = True,
) -> str:
    """A study method's name: ``"SAC"``, ``"SAC+MeanDemoW5/MeanDemoW10"``, with
    ``" state-action"``, ``" n=10"`` (a count other than the study's ``n_demos``) or
    ``" no top-up"`` appended.

    >>> study_label("SAC", "MeanBothW5/MeanBothW5", "state_action")
    'SAC+MeanBothW5/MeanBothW5 state-action'
    >>> study_label("SAC", "MeanDemoW5/MeanDemoW10", n_demos=10)
    'SAC+MeanDemoW5/MeanDemoW10 n=10'
    """
    if not strategy:
        return algo
    label = f"{algo}+{strategy}"
    if trajectory == "state_action":
        label += " state-action"
    if n_demos is not None:
        label += f" n={n_demos}"
    if not top_up:
        label += " no top-up"
    return label


def study_task(
    cfg: Config,
    task: str,
    algo: str,
    seed: int,
    strategy: str | None = None,
    trajectory: str = "state",
    n_demos: int | None = None,
    top_up: bool = True,
) -> Task:
    """The :class:`~thesis_lib.sweep.Task` of one study run (:func:`study_run`) of ``cfg``.

    Its config holds everything the run depends on: the training fields, and for a filtered
    run the demonstration recipe (the same for every run of a task: one SAC run, seed
    ``cfg.seed``, topped up to ``max(n_demos, n_demos_list)`` per group) and the count; for
    the matched control (``strategy`` :data:`MATCHED_RANDOM_STRATEGY`) also ``match``, the key
    of the run whose firing rate it takes (the first state strategy, same task, seed and
    count).

    Used in: DEFENDER chapter study.
    """
    n = max(cfg.n_demos, *cfg.n_demos_list)
    recipe = {f: getattr(cfg, f) for f in DEMO_FIELDS} | {"n_demos": n, "n_demos_list": [n]}
    count = cfg.n_demos if n_demos is None else n_demos
    train = {f: getattr(cfg, f) for f in TRAIN_FIELDS}
    if not strategy or strategy.startswith((RANDOM_STRATEGY, TIMER_STRATEGY)):
        # the trajectory cap is DEFENDER's own: a plain run or a blind filter never reads it,
        # so their keys (and a later study's reuse of them) do not change with it
        train["max_trajectory"] = None
    config: dict[str, Any] = {
        "label": study_label(
            algo, strategy, trajectory, None if count == cfg.n_demos else count, top_up
        ),
        "task": task,
        "algo": algo,
        "seed": int(seed),
        "strategy": strategy,
        "trajectory": trajectory if strategy else "state",
        "n_demos": count if strategy else 0,
        "top_up": bool(top_up) if strategy else True,
        "demos": recipe if strategy else None,
        "train": train,
        "eval_episodes": cfg.eval_episodes,
        "bins": STUDY_CURVE_BINS,
    }
    if strategy in (MATCHED_RANDOM_STRATEGY, MATCHED_TIMER_STRATEGY):
        if not cfg.state_strategies:
            raise ValueError("the matched control needs a state strategy to match")
        config["match"] = study_task(
            cfg, task, algo, seed, cfg.state_strategies[0], n_demos=n_demos, top_up=top_up
        ).key
    return Task(study_run, config)


def study_tasks(cfg: Config) -> list[Task]:
    """The tasks of the chapter's pre-registered study (``params/03_defender.study.yml``).

    For each seed and task: the first of ``algos`` (SAC) plain, with each of
    ``state_strategies`` (state trajectories) and ``state_action_strategies`` (state-action),
    all with ``n_demos`` demonstrations per group, and with the first state strategy and each
    other count of ``n_demos_list`` (Table 4.5); on ``no_topup_tasks`` also with the first
    state strategy on the SAC roll-outs alone; and with a filter firing at random at each of
    ``random_filter_rates`` (the control, :func:`random_strategy`). The other algorithms (TD3)
    run plain and with the first state strategy, on their ``algo_tasks``. With
    ``random_filter_matched``, the matched controls (:data:`MATCHED_RANDOM_STRATEGY`) come
    last, seed by seed, after every run they match; with ``timer_filter_matched`` the timing
    controls (:data:`MATCHED_TIMER_STRATEGY`) after them.

    Order: the plain runs of the first algorithm for every seed come first, since the study's
    level gates read them alone (plain SAC's return): a gate that fails is then known before
    the filtered runs are paid for. The other runs follow with seeds as the outer loop, so a
    study stopped part-way has whole seeds (each beside its plain run). The order changes no
    task's key.

    Used in: ``thesis study 03_defender``.
    """
    main, first = cfg.algos[0], cfg.state_strategies[0] if cfg.state_strategies else None
    tasks = []
    for seed in cfg.seeds:
        for task in cfg.tasks:
            for algo in cfg.algos:
                if task not in cfg.algo_tasks.get(algo, cfg.tasks):
                    continue
                tasks.append(study_task(cfg, task, algo, seed))
                if algo != main:
                    if first:
                        tasks.append(study_task(cfg, task, algo, seed, first))
                    continue
                for s in cfg.state_strategies:
                    tasks.append(study_task(cfg, task, algo, seed, s))
                for s in cfg.state_action_strategies:
                    tasks.append(study_task(cfg, task, algo, seed, s, "state_action"))
                if first:
                    for n in cfg.n_demos_list:
                        if n != cfg.n_demos:
                            tasks.append(study_task(cfg, task, algo, seed, first, n_demos=n))
                    if task in cfg.no_topup_tasks:
                        tasks.append(study_task(cfg, task, algo, seed, first, top_up=False))
                for rate in cfg.random_filter_rates:  # the control arms
                    tasks.append(study_task(cfg, task, algo, seed, random_strategy(rate)))
    gated = [t.config["algo"] == main and not t.config["strategy"] for t in tasks]
    ordered = [t for t, g in zip(tasks, gated) if g] + [t for t, g in zip(tasks, gated) if not g]
    controls = [MATCHED_RANDOM_STRATEGY] if cfg.random_filter_matched else []
    controls += [MATCHED_TIMER_STRATEGY] if cfg.timer_filter_matched else []
    for control in controls:
        ordered += [
            study_task(cfg, task, main, seed, control)
            for seed in cfg.seeds
            for task in cfg.tasks
            if task in cfg.algo_tasks.get(main, cfg.tasks)
        ]
    return ordered
