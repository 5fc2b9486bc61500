"""The DEFENDER chapter (thesis 4.3.2-4.3.3): its :class:`Config`, tables and figures.

``notebooks/03_defender.ipynb`` calls these in order:

1. :func:`make_demonstrations` one SAC run per task; its roll-outs become the demonstrations and
   its training episodes the ablation's log. A group the short run gives too few roll-outs of is
   topped up from the shipped expert (``demo_source="auto"``); :func:`describe_demonstrations`
   says which recipe each task used.
2. :func:`run_ablation` the 576-strategy ablation for state and state-action trajectories.
3. :func:`run_tables_4_3_4_4` SAC and TD3 with and without DEFENDER; :func:`run_table_4_5`
   SAC with MeanDemoW5/MeanDemoW10 and 10/20/50 demonstrations.
4. :func:`summarise` mean ± std over seeds, % Time; :func:`compare_tables` beside the thesis.

The ablation (one task per task x trajectory kind, :func:`ablation_task`) and the training runs
(one task per task x algorithm x strategy x seed, :func:`train_task`) run through
:func:`thesis_lib.sweep.run_tasks`, stored under ``results/03_defender/tasks``: an interrupted
chapter resumes, and a run that Tables 4.3-4.4 and 4.5 share is trained once. The tasks read
their demonstrations from content-addressed files under ``results/03_defender/demos``
(:func:`demos_file`), so a task's key changes when its demonstrations do.

The pre-registered study of claims C7-C9 (``params/03_defender.study.yml``, ``thesis study
03_defender``) runs :func:`study_tasks`: one :func:`study_run` per training run, reduced to one
row by :func:`training_run_numbers` and a final evaluation without the filter. Its
demonstrations are made once and kept beside its rows (:func:`pinned_demonstrations`), because
a later session on a new machine made other ones for one task. The chapter's
"Evidence at study scale" reads the rows back (:func:`study_summary`, :func:`plot_study_curves`,
:func:`study_topup_table`).

Used in: DEFENDER chapter (thesis 4.3).
"""

from __future__ import annotations

import hashlib
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal, NamedTuple, cast

import gymnasium as gym
import numpy as np
import pandas as pd

from thesis_lib._io import atomic_write, file_lock, hash_arrays
from thesis_lib.book import results_dir
from thesis_lib.book.study import studies_dir
from thesis_lib.defender import (
    METHODS,
    THESIS_STATE_ACTION_STRATEGIES,
    THESIS_STATE_STRATEGIES,
    DefenderWrapper,
    DemoRun,
    DemoSet,
    collect_demonstrations,
    expert_demonstrations,
    load_demonstrations,
    parse_method,
    parse_strategy,
    save_demonstrations,
    save_demonstrations_minari,
    select_diverse,
    shipped_expert_label,
)
from thesis_lib.defender.ablation import (
    plot_strategy_heatmap,
    rank_strategies,
    strategy_ablation,
)
from thesis_lib.sweep import Task, TaskStore, run_tasks

CHAPTER = "03_defender"

__all__ = [
    "CHAPTER",
    "CRASH_DEFINITION",
    "STUDY_CURVE_BINS",
    "STUDY_DATA_NOTE",
    "THESIS_SAC_RETURN",
    "DEMO_SOURCES",
    "RUN_COLUMNS",
    "THESIS_STATE_ACTION_STRATEGIES",
    "THESIS_STATE_STRATEGIES",
    "Config",
    "TableRuns",
    "ablation_task",
    "compare_table_4_5",
    "compare_tables",
    "compare_top_strategies",
    "crash_curves",
    "demo_table",
    "demos_file",
    "demos_subset",
    "describe_demonstrations",
    "describe_effects",
    "make_demonstrations",
    "pinned_demonstrations",
    "plot_ablation_heatmap",
    "plot_curves",
    "plot_curves_table_4_5",
    "plot_study_curves",
    "rank_thesis_strategies",
    "run_ablation",
    "run_methods_table",
    "run_paper_compat_effect",
    "run_table_4_5",
    "run_tables_4_3_4_4",
    "runs_from_episodes",
    "save_demonstration_files",
    "scale_note",
    "study_curves",
    "study_demo_sources",
    "study_demonstrations",
    "study_label",
    "study_run",
    "study_summary",
    "study_task",
    "study_tasks",
    "study_topup_table",
    "summarise",
    "thesis_env_name",
    "top_strategies",
    "train_run",
    "train_task",
    "training_run_numbers",
]

DEMO_SOURCES: tuple[str, ...] = ("sac", "expert", "auto")
"""Where :func:`make_demonstrations` takes demonstrations from: ``"sac"`` the thesis's recipe only
(SAC roll-outs during training; fails when a group gets none), ``"expert"`` the shipped expert
(TQC or ARS, :func:`~thesis_lib.defender.shipped_expert_label`) with action noise
(:func:`~thesis_lib.defender.expert_demonstrations`) only, ``"auto"`` SAC
roll-outs, and a group with fewer than needed topped up from the expert."""

RUN_COLUMNS: tuple[str, ...] = (
    "task", "algo", "trajectory", "strategy", "safe_strategy", "unsafe_strategy", "n_demos", "paper_compat",
    "seed", "acc_reward", "crash_pct", "filtered_pct", "mean_last_100", "n_episodes", "wall_time_s",
)  # fmt: skip
"""Columns of one training run's summary row (:func:`train_run`)."""


@dataclass
class Config:
    """Parameters of ``notebooks/03_defender.ipynb`` (one field per notebook parameter).

    Defaults are the smoke scale (a few minutes on 2 CPU cores; ``params/03_defender.smoke.yml``
    also limits the ``paper_compat`` check to Hopper); ``params/03_defender.full.yml`` holds the
    thesis's (5,000 episodes x 3 seeds, 50 demonstrations, horizon 1000, 256-256 nets).
    """

    seed: int = 0
    """Seed of the demonstration run (and the chapter's other draws)."""
    seeds: list[int] = field(default_factory=lambda: [0])
    """Seeds of every training run in Tables 4.3-4.5 (the thesis: 3)."""
    tasks: list[str] = field(
        default_factory=lambda: ["Hopper-v5", "InvertedDoublePendulum-v5", "Walker2d-v5"]
    )
    """Gymnasium tasks (the thesis: Hopper, InvertedDoublePendulum, Walker2d)."""
    max_episode_steps: int | None = 100
    """Episode horizon; None = the task's own (1000, the thesis's)."""
    demo_timesteps: int = 4000
    """SAC training steps of the demonstration run."""
    demo_every: int = 1
    """Training episodes between two demonstration roll-outs."""
    demo_deterministic: bool = True
    """Roll out the policy's mean action (True) or sample it."""
    demo_source: str = "auto"
    """Where demonstrations come from, one of :data:`DEMO_SOURCES` ("sac" = the thesis's recipe
    only; "auto" = SAC roll-outs, a short group topped up from the shipped expert)."""
    n_demos: int = 10
    """Demonstrations per group in Tables 4.3-4.4 (the thesis: 50)."""
    n_demos_list: list[int] = field(default_factory=lambda: [3, 6, 10])
    """Demonstrations per group in Table 4.5 (the thesis: 10, 20, 50)."""
    algos: list[str] = field(default_factory=lambda: ["SAC", "TD3"])
    """Agents of Tables 4.3-4.4."""
    train_timesteps: int = 500
    """Environment steps per training run (used when ``train_episodes`` is None)."""
    train_episodes: int | None = None
    """Episodes per training run (the thesis: 5000); None = use ``train_timesteps``."""
    state_strategies: list[str] = field(default_factory=lambda: ["MeanDemoW5/MeanDemoW10"])
    """Safe/unsafe strategies run with state trajectories (Table 4.3)."""
    state_action_strategies: list[str] = field(default_factory=lambda: ["MeanBothW5/MeanBothW5"])
    """Safe/unsafe strategies run with state-action trajectories (Table 4.4)."""
    net_arch: list[int] = field(default_factory=lambda: [64, 64])
    """Hidden layers of actor and critics (the thesis: 256, 256)."""
    learning_rate: float = 1e-3
    """Adam learning rate of actor and critics (the thesis: 3e-4)."""
    max_trajectory: int | None = None
    """Cap of the agent's trajectory before each comparison; None = whole episode (the thesis's
    text), 20 = the authors' code."""
    paper_compat_check: bool = True
    """Also run the first state strategy with SAC and ``paper_compat=True`` (FastDTW radius 1,
    20-step cap, strict >, dynamics trained every step) to measure what the authors' code changes."""
    paper_compat_tasks: list[str] | None = None
    """Tasks of that check; None = the first of ``tasks`` only (FastDTW is slow); list them all
    to run it on every task."""
    batch_size: int = 256
    """Minibatch of the agents' updates (the thesis: 256)."""
    dynamics_train_every: int | None = None
    """One dynamics-model update every this many real steps; None = the wrapper's default (4,
    measured in ``benchmarks/bench_defender.py``; 1 = Algorithm 2 to the letter)."""
    n_jobs: int = 1
    """Processes for the ablation replay (training runs stay sequential so % Time is fair)."""
    algo_tasks: dict[str, list[str]] = field(default_factory=dict)
    """Tasks of an algorithm that runs on fewer than all ``tasks`` (e.g. ``{"TD3": ["Hopper-v5"]}``);
    empty: every algorithm on every task."""
    eval_episodes: int = 10
    """Study: evaluation episodes of each run's final policy, without the filter."""
    no_topup_tasks: list[str] = field(default_factory=list)
    """Study: tasks where SAC with the first state strategy also runs on the SAC roll-outs alone
    (no expert top-up), to measure what the top-up changes."""

    def __post_init__(self) -> None:
        from thesis_lib.rl import ALGOS

        for name in ("demo_timesteps", "demo_every", "n_demos", "train_timesteps", "batch_size"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or value < 1:
                raise ValueError(f"Config.{name} must be a positive int, got {value!r}.")
        for name in (
            "max_episode_steps",
            "train_episodes",
            "max_trajectory",
            "dynamics_train_every",
        ):
            value = getattr(self, name)
            if value is not None and (
                isinstance(value, bool) or not isinstance(value, int) or value < 1
            ):
                raise ValueError(f"Config.{name} must be a positive int or None, got {value!r}.")
        if not self.seeds or not self.tasks or not self.algos:
            raise ValueError("Config needs at least one seed, one task and one algo.")
        bad = [a for a in self.algos if a not in ALGOS]
        if bad:
            raise ValueError(f"Unknown algo {bad[0]!r} in Config.algos. Valid: {', '.join(ALGOS)}.")
        if not self.n_demos_list or any(int(n) < 1 for n in self.n_demos_list):
            raise ValueError(f"n_demos_list must list positive counts, got {self.n_demos_list!r}.")
        for s in [*self.state_strategies, *self.state_action_strategies]:
            parse_strategy(s)  # raises with the valid names
        if self.demo_source not in DEMO_SOURCES:
            raise ValueError(
                f"Unknown demo_source {self.demo_source!r}. Valid: {', '.join(DEMO_SOURCES)}."
            )
        if isinstance(self.eval_episodes, bool) or not isinstance(self.eval_episodes, int):
            raise ValueError(f"Config.eval_episodes must be an int, got {self.eval_episodes!r}.")
        if self.eval_episodes < 1:
            raise ValueError(f"Config.eval_episodes must be >= 1, got {self.eval_episodes}.")
        for name, listed in (
            *((f"algo_tasks[{a!r}]", ts) for a, ts in self.algo_tasks.items()),
            ("no_topup_tasks", self.no_topup_tasks),
        ):
            bad = [t for t in listed if t not in self.tasks]
            if bad:
                raise ValueError(f"{name} lists {bad[0]!r}, which is not in tasks {self.tasks}.")
        bad = [a for a in self.algo_tasks if a not in self.algos]
        if bad:
            raise ValueError(f"algo_tasks names {bad[0]!r}, which is not in algos {self.algos}.")
        if self.paper_compat_tasks is not None:
            bad = [t for t in self.paper_compat_tasks if t not in self.tasks]
            if bad:
                raise ValueError(
                    f"paper_compat_tasks lists {bad[0]!r}, which is not in tasks {self.tasks}."
                )


# --------------------------------------------------------------------------- demonstrations
def _episode_limit(env: gym.Env) -> int | None:
    """The environment's registered episode limit, if any."""
    return None if env.spec is None else env.spec.max_episode_steps


def thesis_env_name(task: str) -> str:
    """The thesis's table label of a gymnasium id: ``"Hopper-v5"`` -> ``"Hopper"``.

    >>> thesis_env_name("InvertedDoublePendulum-v5")
    'InvertedDoublePendulum'
    """
    return task.split("-v")[0]


def _make_env(task: str, horizon: int | None) -> gym.Env:
    return gym.make(task, max_episode_steps=horizon) if horizon else gym.make(task)


#: Config fields the demonstrations depend on (each :func:`demonstrations_task` config holds them).
DEMO_FIELDS = (
    "seed", "max_episode_steps", "demo_timesteps", "demo_every", "demo_deterministic",
    "demo_source", "n_demos", "n_demos_list", "net_arch", "learning_rate", "batch_size",
)  # fmt: skip


def collect_task_demonstrations(task: str, cfg: Config, progress: bool = False) -> DemoRun:
    """One SAC run on ``task``, rolled out every ``demo_every`` episodes, topped up from the
    shipped expert as ``cfg.demo_source`` says (see :func:`make_demonstrations`)."""
    n = max(cfg.n_demos, *cfg.n_demos_list)
    run = collect_demonstrations(
        task,
        n_safe=n,
        n_unsafe=n,
        total_timesteps=cfg.demo_timesteps,
        every=cfg.demo_every,
        seed=cfg.seed,
        max_episode_steps=cfg.max_episode_steps,
        deterministic=cfg.demo_deterministic,
        rl_overrides=_rl_overrides(cfg),
        progress=progress,
        allow_missing=cfg.demo_source != "sac",
    )
    if cfg.demo_source == "sac":
        return run
    sac = (
        {"safe": run.pool.safe, "unsafe": run.pool.unsafe}
        if cfg.demo_source == "auto"
        else {"safe": [], "unsafe": []}
    )
    need = {g: max(0, n - len(sac[g])) for g in sac}
    extra = expert_demonstrations(
        task,
        n_safe=need["safe"],
        n_unsafe=need["unsafe"],
        seed=cfg.seed,
        max_episode_steps=cfg.max_episode_steps,
    )
    pool = DemoSet([*sac["safe"], *extra.safe], [*sac["unsafe"], *extra.unsafe], task)
    demos = DemoSet(select_diverse(pool.safe, n), select_diverse(pool.unsafe, n), task)
    return DemoRun(
        demos,
        pool,
        run.episodes,
        run.result,
        {"safe": len(sac["safe"]), "unsafe": len(sac["unsafe"])},
    )


def demonstrations_task(config: dict[str, Any]) -> list[dict[str, Any]]:
    """Sweep task: :func:`collect_task_demonstrations` for ``config["task"]``.

    Writes the pool and the SAC run's training episodes (:func:`demos_file`) and returns one row:
    ``task``, ``pool``, ``episodes`` (file names), ``n_sac_safe`` / ``n_sac_unsafe`` (-1: all
    SAC) and ``safe`` / ``unsafe`` (the kept demonstrations, comma-separated pool indices).

    Used in: DEFENDER chapter (thesis 4.3.3), through :func:`make_demonstrations`.
    """
    task = config["task"]
    run = collect_task_demonstrations(task, Config(**config["cfg"], tasks=[task]))
    row: dict[str, Any] = {
        "task": task,
        "pool": demos_file(run.pool, f"{thesis_env_name(task)}-pool"),
        "episodes": demos_file(
            DemoSet(list(run.episodes), [], task), f"{thesis_env_name(task)}-log"
        ),
    }
    for group in ("safe", "unsafe"):
        pool = getattr(run.pool, group)
        index = {id(d): i for i, d in enumerate(pool)}
        row[group] = ",".join(str(index[id(d)]) for d in getattr(run.demos, group))
        row[f"n_sac_{group}"] = run.n_sac.get(group, -1)
    return [row]


def _demonstrations_tasks(cfg: Config) -> list[Task]:
    fields = {f: getattr(cfg, f) for f in DEMO_FIELDS}
    return [Task(demonstrations_task, {"task": t, "cfg": fields}) for t in cfg.tasks]


def _demo_run_from_row(row: dict[str, Any], folder: Path, episodes: bool = True) -> DemoRun:
    """The :class:`DemoRun` of one :func:`demonstrations_task` row, its files read from
    ``folder``; ``episodes=False`` leaves the SAC run's training episodes out (empty)."""
    pool = load_demonstrations(folder / row["pool"])
    log = load_demonstrations(folder / row["episodes"]).safe if episodes else []
    kept = {
        g: [getattr(pool, g)[int(i)] for i in str(row[g]).split(",") if i != ""]
        for g in ("safe", "unsafe")
    }
    n_sac = {g: int(row[f"n_sac_{g}"]) for g in ("safe", "unsafe") if int(row[f"n_sac_{g}"]) >= 0}
    return DemoRun(DemoSet(kept["safe"], kept["unsafe"], row["task"]), pool, log, None, n_sac)


def make_demonstrations(cfg: Config, progress: bool = True) -> dict[str, DemoRun]:
    """One SAC run per task, rolled out every ``demo_every`` episodes (thesis 4.3.3).

    Keeps ``n = max(n_demos, max(n_demos_list))`` diverse demonstrations per group. The SAC run
    always happens (its training episodes are the ablation's log); where the demonstrations come
    from is ``cfg.demo_source``: with ``"auto"`` a group that got fewer than ``n`` SAC roll-outs is
    topped up to ``n`` with :func:`~thesis_lib.defender.expert_demonstrations` (the shipped ARS
    expert with action noise); ``DemoRun.n_sac`` / ``DemoRun.sources()`` say how many of each.
    Each task is a sweep task (:func:`demonstrations_task`): a rerun reads them back (the
    returned runs then carry no SB3 model: ``DemoRun.result`` is None).

    Used in: DEFENDER chapter (thesis 4.3).
    """
    rows = run_tasks(
        _demonstrations_tasks(cfg),
        store=results_dir(CHAPTER) / "tasks",
        desc="demonstrations",
        progress=progress,
    )
    folder = results_dir(CHAPTER) / "demos"
    return {r["task"]: _demo_run_from_row(r, folder) for r in rows.to_dict(orient="records")}


def _rl_overrides(cfg: Config) -> dict[str, Any]:
    return {
        "net_arch": list(cfg.net_arch),
        "learning_rate": cfg.learning_rate,
        "batch_size": cfg.batch_size,
    }


def demo_table(demo_runs: dict[str, DemoRun], cfg: Config) -> pd.DataFrame:
    """Per task and group: SAC roll-outs seen, demonstrations kept and where they came from.

    Used in: DEFENDER chapter (thesis 4.3).
    """
    rows = []
    for task, run in demo_runs.items():
        src = run.sources()
        for group in ("safe", "unsafe"):
            kept = getattr(run.demos, group)
            n_seen = run.n_sac.get(group, len(getattr(run.pool, group)))
            rows.append(
                {
                    "task": task,
                    "group": group,
                    "SAC roll-outs seen": n_seen,
                    "kept": len(kept),
                    "kept from SAC roll-outs": src[group][0],
                    "kept from the expert": src[group][1],
                    "recipe": _recipe(src[group], task),
                    "mean length": float(np.mean([d.length for d in kept])) if kept else np.nan,
                    "lowest step reward": min(float(d.rewards.min()) for d in kept)
                    if kept
                    else np.nan,
                }
            )
    return pd.DataFrame(rows)


def _recipe(counts: tuple[int, int], task: str) -> str:
    n_sac, n_expert = counts
    if n_expert == 0:
        return "SAC roll-outs (thesis)"
    if n_sac == 0:
        return f"{shipped_expert_label(task)} + noise"
    return f"SAC roll-outs, topped up from {shipped_expert_label(task)}"


def describe_demonstrations(demo_runs: dict[str, DemoRun], cfg: Config) -> list[str]:
    """One sentence per task: which recipe each group used and why.

    Used in: DEFENDER chapter (thesis 4.3), so the narration follows the run.
    """
    n = max(cfg.n_demos, *cfg.n_demos_list)
    lines = []
    for task, run in demo_runs.items():
        src = run.sources()
        parts = []
        for group, what in (("safe", "reached the horizon"), ("unsafe", "fell before it")):
            seen = run.n_sac.get(group, len(getattr(run.pool, group)))
            n_sac, n_exp = src[group]
            if n_exp == 0:
                parts.append(
                    f"{group}: {n_sac} SAC roll-outs (the thesis's recipe; {seen} of them {what})"
                )
            elif cfg.demo_source == "expert":
                parts.append(
                    f"{group}: {n_exp} from the {shipped_expert_label(task)} with noise "
                    "(demo_source='expert')"
                )
            else:
                got = f"only {seen} SAC roll-out(s) {what}" if seen else f"no SAC roll-out {what}"
                parts.append(
                    f"{group}: {got} in {cfg.demo_timesteps} training steps, "
                    f"fewer than the {n} needed, so {n_exp} came from the shipped "
                    f"{shipped_expert_label(task)} "
                    f"({'small' if group == 'safe' else 'heavy'} action noise)"
                )
        lines.append(f"{thesis_env_name(task)}: " + "; ".join(parts) + ".")
    return lines


def demos_subset(run: DemoRun, n: int) -> DemoSet:
    """``n`` diverse demonstrations per group from a run's pool (as the authors picked theirs)."""
    pool = run.pool
    return DemoSet(select_diverse(pool.safe, n), select_diverse(pool.unsafe, n), pool.env_id)


# --------------------------------------------------------------------------- ablation
def demos_file(demos: DemoSet, label: str = "") -> str:
    """Write ``demos`` to ``results/03_defender/demos/<label>-<content hash>.npz`` (once) and
    return the file's name, which a sweep task's config holds (:func:`load_demos_file` reads it).

    The name carries a hash of every array, so a task's key changes when its demonstrations do.
    """
    h = hashlib.sha256(str(demos.env_id).encode())
    for group in ("safe", "unsafe"):
        h.update(group.encode())
        for d in getattr(demos, group):
            hash_arrays(h, (d.observations, d.actions, d.rewards))
            h.update(bytes([bool(d.terminated), bool(d.truncated)]))
    name = f"{label or thesis_env_name(str(demos.env_id))}-{h.hexdigest()[:16]}.npz"
    path = results_dir(CHAPTER) / "demos" / name
    if not path.is_file():
        # two study workers may write the same set at once (same content): each writes a
        # temporary file of its own and renames it atomically over the set
        atomic_write(path, lambda tmp: save_demonstrations(demos, tmp), keep_suffix=True)
    return name


def load_demos_file(name: str) -> DemoSet:
    """Read a file :func:`demos_file` wrote."""
    return load_demonstrations(results_dir(CHAPTER) / "demos" / name)


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
        horizon = cfg.max_episode_steps or _episode_limit(_make_env(task, None))
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


def top_strategies(scores: pd.DataFrame, top: int = 5) -> pd.DataFrame:
    """The ``top`` strategies per trajectory kind, ranked by the score averaged over tasks."""
    return rank_strategies(scores, top=top, by=("trajectory",))


def rank_thesis_strategies(scores: pd.DataFrame) -> pd.DataFrame:
    """Where the thesis's top-5 strategies (Tables 4.3-4.4) land in our ablation.

    Returns:
        One row per thesis strategy: ``trajectory``, ``thesis strategy`` (as printed), ``score``,
        ``kept_fraction``, ``crashes_stopped`` (averaged over tasks) and ``our rank`` among 576.

    Used in: DEFENDER chapter (thesis 4.3.2).
    """
    cols = ["score", "kept_fraction", "crashes_stopped"]
    mean = scores.groupby(["trajectory", "strategy"])[cols].mean()
    mean["our rank"] = mean.groupby(level=0)["score"].rank(ascending=False, method="min")
    rows = []
    for kind, printed in (
        ("state", THESIS_STATE_STRATEGIES),
        ("state_action", THESIS_STATE_ACTION_STRATEGIES),
    ):
        for label in printed:
            key = (kind, parse_strategy(label).name)
            if key in mean.index:
                rows.append(
                    {"trajectory": kind, "thesis strategy": label, **mean.loc[key].to_dict()}
                )
    out = pd.DataFrame(rows, columns=["trajectory", "thesis strategy", *cols, "our rank"])
    out["our rank"] = out["our rank"].astype(int)
    return out


# --------------------------------------------------------------------------- training runs
#: Config fields a training run depends on (each :func:`train_task` config holds them).
TRAIN_FIELDS = (
    "max_episode_steps", "train_timesteps", "train_episodes", "net_arch", "learning_rate",
    "batch_size", "max_trajectory", "dynamics_train_every",
)  # fmt: skip


def train_run(
    task: str,
    algo: str,
    seed: int,
    cfg: Config,
    demos: DemoSet | None = None,
    strategy: str | None = None,
    trajectory: str = "state",
    paper_compat: bool = False,
) -> tuple[dict[str, Any], pd.DataFrame]:
    """Train one agent, with DEFENDER when ``demos`` and ``strategy`` are given.

    Returns:
        ``(row, episodes)``: a summary row (:data:`RUN_COLUMNS`; Acc Reward = best training
        episode return, % Crash = share of training episodes that crashed, filtered episodes not
        counted as crashes) and the episode log with the run's keys and ``wall_time_s``.

    Used in: DEFENDER chapter (thesis 4.3.3).
    """
    row, ep, _ = _train(task, algo, seed, cfg, demos, strategy, trajectory, paper_compat)
    return row, ep


def _train(
    task: str,
    algo: str,
    seed: int,
    cfg: Config,
    demos: DemoSet | None,
    strategy: str | None,
    trajectory: str,
    paper_compat: bool,
) -> tuple[dict[str, Any], pd.DataFrame, Any]:
    """:func:`train_run`, also returning the :class:`~thesis_lib.rl.TrainResult` (its model)."""
    from stable_baselines3.common.callbacks import StopTrainingOnMaxEpisodes

    from thesis_lib.rl import config_from_params, train

    env = _make_env(task, cfg.max_episode_steps)
    safe_s = unsafe_s = None
    if demos is not None and strategy is not None:
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
            seed=seed,
            # what each filtered action would have done (a copy of the state is stepped and
            # restored bit for bit: training is unchanged): saved crashes vs false alarms
            counterfactual=True,
            dynamics_train_every=cfg.dynamics_train_every,
            # "all the networks have 2 hidden layers" of the agent's size (4.3.3)
            dynamics_kwargs={
                "hidden": list(cfg.net_arch),
                "learning_rate": cfg.learning_rate,
                "batch_size": cfg.batch_size,
            },
        )
    callbacks = []
    steps = cfg.train_timesteps
    if cfg.train_episodes:
        horizon = cfg.max_episode_steps or _episode_limit(env) or 1000
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
            **_rl_overrides(cfg),
        }
    )
    res = train(
        rl,
        env=env,
        callbacks=callbacks,
        progress=False,
        info_keys=["filtered", "filter_step", "would_crash"],
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
    return row, ep, res


def _run_numbers(ep: pd.DataFrame) -> dict[str, Any]:
    return {
        "acc_reward": float(ep["return"].max()) if len(ep) else np.nan,
        "crash_pct": 100 * float(ep["crashed"].mean()) if len(ep) else np.nan,
        "filtered_pct": 100 * float(ep["filtered"].mean()) if len(ep) else np.nan,
        "mean_last_100": float(ep["return"].tail(100).mean()) if len(ep) else np.nan,
        "n_episodes": len(ep),
    }


def train_task(config: dict[str, Any]) -> list[dict[str, Any]]:
    """Sweep task: one training run (:func:`train_run`), its episodes as long-format rows.

    Config keys: ``task``, ``algo``, ``seed``, ``strategy`` (None: no filter), ``trajectory``,
    ``paper_compat``, ``demos`` (a :func:`demos_file` name, or None) and ``train`` (the
    :data:`TRAIN_FIELDS` of the chapter's :class:`Config`).

    Returns:
        One row per training episode, with the run's keys and ``wall_time_s``; a run that
        finished no episode gives one row with ``episode`` None.

    Used in: DEFENDER chapter (thesis 4.3.3), through :func:`run_tables_4_3_4_4` and
    :func:`run_table_4_5`.
    """
    cfg = Config(**config["train"])
    demos = load_demos_file(config["demos"]) if config["demos"] else None
    row, ep = train_run(
        config["task"],
        config["algo"],
        config["seed"],
        cfg,
        demos=demos,
        strategy=config["strategy"],
        trajectory=config["trajectory"],
        paper_compat=config["paper_compat"],
    )
    if not len(ep):
        keys = {k: row[k] for k in RUN_COLUMNS[:9]}
        return [{**keys, "episode": None, "wall_time_s": row["wall_time_s"]}]
    return ep.to_dict(orient="records")


_RUN_KEYS = list(RUN_COLUMNS[:9])


def runs_from_episodes(episodes: pd.DataFrame) -> pd.DataFrame:
    """One summary row per run (:data:`RUN_COLUMNS`) from :func:`train_task`'s episode rows."""
    rows = []
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


# --------------------------------------------------------------------------- summaries
def summarise(runs: pd.DataFrame) -> pd.DataFrame:
    """Mean ± std over seeds, and % Time relative to the plain algorithm (thesis Tables 4.3-4.5).

    Returns:
        One row per (task, algo, trajectory, strategy, n_demos, paper_compat) with
        ``acc_reward_mean/std``, ``crash_pct_mean/std``, ``filtered_pct``, ``mean_last_100``,
        ``time_pct`` (100 x wall time / the same algorithm's plain run on the same task and seed,
        averaged over seeds) and ``n_seeds``.

    Used in: DEFENDER chapter (thesis 4.3.3).
    """
    r = runs.copy()
    base = r[r.strategy == "none"].set_index(["task", "algo", "seed"])["wall_time_s"]
    idx = pd.MultiIndex.from_frame(r[["task", "algo", "seed"]])
    r["time_pct"] = 100 * r["wall_time_s"].to_numpy() / base.reindex(idx).to_numpy()
    keys = [
        "task",
        "algo",
        "trajectory",
        "strategy",
        "safe_strategy",
        "unsafe_strategy",
        "n_demos",
        "paper_compat",
    ]
    g = r.groupby(keys, dropna=False, sort=False)
    out = g.agg(
        acc_reward_mean=("acc_reward", "mean"),
        acc_reward_std=("acc_reward", "std"),
        crash_pct_mean=("crash_pct", "mean"),
        crash_pct_std=("crash_pct", "std"),
        filtered_pct=("filtered_pct", "mean"),
        mean_last_100=("mean_last_100", "mean"),
        time_pct=("time_pct", "mean"),
        n_seeds=("seed", "nunique"),
    ).reset_index()
    return out


def compare_tables(summary: pd.DataFrame, differs: dict[str, str] | None = None) -> pd.DataFrame:
    """Tables 4.3 and 4.4 beside the thesis: Acc Reward, % Crash and % Time per row.

    Returns:
        ``compare_with_paper`` rows with extra columns ``table`` and ``metric``.

    Used in: DEFENDER chapter (thesis 4.3.3).
    """
    from thesis_lib.book import compare_with_paper

    s = summary[~summary.paper_compat.astype(bool)].copy()
    s["env"] = s.task.map(thesis_env_name)
    s["algorithm"] = s.algo
    frames = []
    for table, kind in (("4.3", "state"), ("4.4", "state_action")):
        part = s[s.trajectory.isin(["none", kind])].copy()
        for col in ("safe_strategy", "unsafe_strategy"):
            part[col] = part[col].where(part.strategy != "none", np.nan)
        for metric, ours, paper in (
            ("Acc Reward", "acc_reward_mean", "acc_reward_mean"),
            ("% Crash", "crash_pct_mean", "crash_pct_mean"),
            ("% Time", "time_pct", "time_pct"),
        ):
            cmp = compare_with_paper(
                "4_3_4_4",
                part,
                on=["algorithm", "safe_strategy", "unsafe_strategy", "env"],
                value=ours,
                paper_value=paper,
                differs=differs,
                where={"table": table},
            )
            cmp.insert(0, "metric", metric)
            cmp.insert(0, "table", table)
            frames.append(cmp)
    return pd.concat(frames, ignore_index=True)


def compare_table_4_5(summary: pd.DataFrame, differs: dict[str, str] | None = None) -> pd.DataFrame:
    """Table 4.5 beside the thesis (Acc Reward and % Crash per number of demonstrations).

    Our demonstration counts are matched to the thesis's by rank (smallest to 10, ...), since the
    smoke scale uses fewer; the ``n_demos`` column keeps ours.
    """
    from thesis_lib.book import compare_with_paper

    s = summary.copy()
    s["env"] = s.task.map(thesis_env_name)
    thesis_ns = [10, 20, 50]
    ours_ns = sorted(s.n_demos.unique())
    rank = {n: thesis_ns[i] if i < len(thesis_ns) else n for i, n in enumerate(ours_ns)}
    s["n_demos_ours"] = s.n_demos
    s["n_demos"] = s.n_demos.map(rank)
    frames = []
    for metric, col in (("Acc Reward", "acc_reward_mean"), ("% Crash", "crash_pct_mean")):
        cmp = compare_with_paper("4.5", s, on=["n_demos", "env"], value=col, differs=differs)
        cmp.insert(0, "metric", metric)
        frames.append(cmp)
    out = pd.concat(frames, ignore_index=True)
    back = {str(v): k for k, v in rank.items()}
    out.insert(2, "n_demos_ours", out.n_demos.map(back))
    return out


def describe_effects(summary: pd.DataFrame) -> list[str]:
    """One sentence per DEFENDER run group: crash rate, filtered share and best return vs the plain agent.

    Used in: DEFENDER chapter (thesis 4.3.3), so the narration follows the numbers of each run.
    """
    base = summary[summary.strategy == "none"].set_index(["task", "algo"])
    lines = []
    for _, r in summary[summary.strategy != "none"].iterrows():
        if (r.task, r.algo) not in base.index:
            continue
        b = base.loc[(r.task, r.algo)]
        setting = f"{r.trajectory}" + (", paper_compat" if r.paper_compat else "")
        lines.append(
            f"{thesis_env_name(r.task)} {r.algo} with {r.strategy} ({setting}): crashed episodes "
            f"{b.crash_pct_mean:.0f}% -> {r.crash_pct_mean:.0f}%, {r.filtered_pct:.0f}% of episodes ended by "
            f"the filter, best return {b.acc_reward_mean:.0f} -> {r.acc_reward_mean:.0f}, "
            f"time {r.time_pct:.0f}% of the plain run."
            + (
                " The filter never fired, so the agent saw exactly the plain run's episodes (same seed); "
                "only the time differs."
                if r.filtered_pct == 0
                else ""
            )
        )
    return lines


def crash_curves(
    episodes: pd.DataFrame, keys: Sequence[str] = ("task", "algo", "trajectory", "strategy", "seed")
) -> pd.DataFrame:
    """Cumulative crash rate (%) and filter rate (%) after each training episode, per run."""
    e = episodes.copy()
    g = e.groupby(list(keys), sort=False)
    e["episode_in_run"] = g.cumcount() + 1
    e["crash_rate_pct"] = 100 * g["crashed"].cumsum() / e["episode_in_run"]
    e["filter_rate_pct"] = 100 * g["filtered"].cumsum() / e["episode_in_run"]
    return e


def plot_curves(episodes: pd.DataFrame, window: int = 10) -> Any:
    """Learning curves (return vs step, rolling mean) and cumulative crash rate, with and without the filter.

    Two rows per task (return; crashed episodes so far), one column per algorithm; one line per
    strategy and seed (black: no filter).

    Used in: DEFENDER chapter (thesis 4.3.3).
    """
    import matplotlib.pyplot as plt

    e = crash_curves(episodes)
    e = e[~e.paper_compat.astype(bool)] if "paper_compat" in e else e
    tasks, algos = list(dict.fromkeys(e.task)), list(dict.fromkeys(e.algo))
    fig, axes = plt.subplots(
        2 * len(tasks), len(algos), figsize=(5.5 * len(algos), 3.2 * 2 * len(tasks)), squeeze=False
    )
    for i, task in enumerate(tasks):
        for col, algo in enumerate(algos):
            ax_r, ax_c = axes[2 * i, col], axes[2 * i + 1, col]
            sub = e[(e.task == task) & (e.algo == algo)]
            for (traj, strat), run in sub.groupby(["trajectory", "strategy"], sort=False):
                label = "no filter" if strat == "none" else f"{strat} ({traj})"
                style = {"color": "black", "lw": 2} if strat == "none" else {}
                for seed, one in run.groupby("seed"):
                    lab = label if seed == run.seed.min() else None
                    ax_r.plot(
                        one.timestep,
                        one["return"].rolling(window, min_periods=1).mean(),
                        label=lab,
                        **style,
                    )
                    ax_c.plot(one.timestep, one.crash_rate_pct, label=lab, **style)
            ax_r.set_title(f"{thesis_env_name(task)}, {algo}")
            ax_r.set_ylabel(f"return (rolling {window})")
            ax_c.set_ylabel("crashed episodes so far (%)")
            ax_c.set_xlabel("environment step")
            ax_r.legend(fontsize=7)
    fig.tight_layout()
    return fig


# --------------------------------------------------------------------------- the notebook's steps
def scale_note(cfg: Config) -> str:
    """The run's scale in one line (the "what differs" note of every comparison)."""
    return (
        f"{', '.join(cfg.tasks)}, horizon {cfg.max_episode_steps or 1000}, "
        f"{cfg.train_episodes or cfg.train_timesteps} "
        f"{'episodes' if cfg.train_episodes else 'steps'} per run, "
        f"{len(cfg.seeds)} seed(s), {cfg.n_demos} demos per group, nets {cfg.net_arch}"
    )


def run_methods_table() -> pd.DataFrame:
    """The 24 comparison methods: aggregation, windowing, the trajectory's and the
    demonstration's side of the comparison, and whether the cost updates incrementally.

    Used in: DEFENDER chapter (thesis 4.3.1).
    """
    rows = []
    for m in METHODS:
        p = parse_method(m)
        rows.append(
            {
                "method": m,
                "aggregation": p.aggregation,
                "windowing": p.windowing_name,
                "trajectory side": f"last {p.x_window}" if p.x_window else "all",
                "demonstration side": {"Same": "last L (L = trajectory length)", "Full": "all"}.get(
                    p.windowing, f"last {p.y_window(0)}" if p.y_window(0) else "all"
                ),
                "incremental": p.incremental,
            }
        )
    return pd.DataFrame(rows)


def save_demonstration_files(demo_runs: dict[str, DemoRun], folder: str | Path) -> list[Path]:
    """Write each task's demonstrations as ``demos_<Task>.npz`` (read back and checked) and as
    Minari data sets under ``folder/minari`` (``thesis/defender-<task>/{safe,unsafe}-v0``).

    Raises:
        RuntimeError: a file does not read back as written.
    """
    folder = Path(folder)
    paths = []
    for task, run in demo_runs.items():
        path = save_demonstrations(run.demos, folder / f"demos_{thesis_env_name(task)}.npz")
        back = load_demonstrations(path)
        written = run.demos.safe + run.demos.unsafe
        if [d.length for d in back.safe + back.unsafe] != [d.length for d in written]:
            raise RuntimeError(f"{path} does not read back as written.")
        save_demonstrations_minari(run.demos, root=folder / "minari")
        paths.append(path)
    return paths


def compare_top_strategies(top: pd.DataFrame) -> pd.DataFrame:
    """Our top 5 per trajectory kind (:func:`top_strategies`) beside the thesis's Tables 4.3-4.4."""
    thesis_top = pd.DataFrame(
        {
            "rank": range(1, 6),
            "state (Table 4.3)": THESIS_STATE_STRATEGIES,
            "state-action (Table 4.4)": THESIS_STATE_ACTION_STRATEGIES,
        }
    )
    side = (
        top.pivot(index="rank", columns="trajectory", values="strategy")
        .rename(columns={"state": "state (ours)", "state_action": "state-action (ours)"})
        .reset_index()
    )
    return side.merge(thesis_top, on="rank")


def plot_ablation_heatmap(scores: pd.DataFrame):
    """The ablation's scores of the 576 strategies, one heatmap per trajectory kind."""
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(17, 7.5))
    for ax, kind in zip(axes, ("state", "state_action")):
        plot_strategy_heatmap(
            scores[scores.trajectory == kind], title=f"{kind} trajectories", ax=ax
        )
    return fig


def run_paper_compat_effect(cfg: Config, summary: pd.DataFrame) -> pd.DataFrame:
    """SAC with the first state strategy, default and ``paper_compat=True``, on the tasks of the
    check: Acc Reward, % Crash, % filtered and % Time side by side.

    Used in: DEFENDER chapter (thesis 4.3.3, the authors' setting).
    """
    pc = summary[
        (summary.algo == "SAC")
        & (summary.strategy == cfg.state_strategies[0])
        & (summary.trajectory == "state")
    ]
    pc = pc[pc.task.isin(pc[pc.paper_compat.astype(bool)].task)]  # the tasks of the check
    cols = ["task", "strategy", "paper_compat", "acc_reward_mean", "crash_pct_mean"]
    return pc[[*cols, "filtered_pct", "time_pct"]]


def plot_curves_table_4_5(episodes: pd.DataFrame):
    """Learning and crash-rate curves of the Table 4.5 runs, one line per number of demonstrations."""
    return plot_curves(episodes.assign(strategy=episodes.n_demos.map(lambda n: f"{n} demos")))


# --------------------------------------------------------------------------- the study (C7-C9)
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

EVAL_SEED = 100_000
"""The final evaluation of a study run with training seed ``s`` resets its task with
``EVAL_SEED + s``."""

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
    episodes: pd.DataFrame, total_steps: int, bins: int = STUDY_CURVE_BINS
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
    out.update(_counterfactual_numbers(ep, crashed, filtered))
    return out


def _counterfactual_numbers(
    ep: pd.DataFrame, crashed: np.ndarray, filtered: np.ndarray
) -> dict[str, float]:
    """What the filter saved, from the episode log's ``would_crash`` (a filtered action stepped
    on a copy of the state, :class:`~thesis_lib.defender.DefenderWrapper`'s counterfactual):
    ``saved_crashes`` (it would have crashed), ``false_alarms`` (it would not),
    ``filter_precision`` = saved / filtered, ``filter_recall`` = saved / (saved + real
    crashes), and ``crash_rate_without_filter`` = (saved + real crashes) / episodes. NaN where
    the log has no counterfactual (no filter, or a run made before it existed)."""
    nan = float("nan")
    names = (
        "saved_crashes",
        "false_alarms",
        "filter_precision",
        "filter_recall",
        "crash_rate_without_filter",
    )
    if (
        "would_crash" not in ep
        or not filtered.any()
        or ep.loc[filtered, "would_crash"].isna().any()
    ):
        return dict.fromkeys(names, nan)
    saved = int(ep.loc[filtered, "would_crash"].astype(bool).sum())
    alarms = int(filtered.sum()) - saved
    real = int(crashed.sum())
    return {
        "saved_crashes": saved,
        "false_alarms": alarms,
        "filter_precision": saved / (saved + alarms),
        "filter_recall": saved / (saved + real) if saved + real else nan,
        "crash_rate_without_filter": (saved + real) / len(ep),
    }


def _demo_lock(task: str) -> Any:
    """An exclusive file lock per task, so that two study workers do not both make the same
    task's demonstrations (the second waits, then reads them from the sweep store)."""
    return file_lock(results_dir(CHAPTER) / "demos" / f".{thesis_env_name(task)}.lock")


def pinned_demonstrations(
    task: str, recipe: dict[str, Any], folder: str | Path | None = None
) -> DemoRun:
    """The study's demonstration run of ``task``: the same pool on every machine and in every
    session.

    The SAC run that makes the demonstrations (:func:`make_demonstrations`) is seeded, yet a
    later session on a new machine of the same kind, with the same package versions, made
    another pool for InvertedDoublePendulum (the same numbers of safe and unsafe roll-outs, but
    other ones; Hopper's and Walker2d's came out the same, bit for bit). The first pool was made
    from a working tree with uncommitted changes, so whether the machine or those changes made
    the difference cannot be told now. Either way: the first call makes them and copies the
    sweep record and the pool file into ``folder`` (default ``studies/03_defender/demos/``,
    committed with the study's rows); every later call, on any machine, reads them from there.
    The run's training-episode log is not kept (the study does not use it; ``episodes`` is
    empty).

    Used in: DEFENDER chapter study, through :func:`study_demonstrations` (which holds the
    task's lock).
    """
    pinned = TaskStore(Path(folder) if folder is not None else studies_dir(CHAPTER) / "demos")
    (t,) = _demonstrations_tasks(Config(**recipe, tasks=[task]))
    if not pinned.has(t.key):
        make_demonstrations(Config(**recipe, tasks=[task]), progress=False)
        record = TaskStore(results_dir(CHAPTER) / "tasks").read(t.key)
        name = record["rows"][0]["pool"]
        pinned.root.mkdir(parents=True, exist_ok=True)
        data = (results_dir(CHAPTER) / "demos" / name).read_bytes()
        atomic_write(pinned.root / name, lambda tmp: tmp.write_bytes(data))
        pinned.write(record)  # last: a record in the folder means its pool is there too
    row = pinned.read(t.key)["rows"][0]
    return _demo_run_from_row(row, pinned.root, episodes=False)


def study_demonstrations(
    task: str, recipe: dict[str, Any], n_demos: int, top_up: bool = True
) -> tuple[DemoSet, dict[str, Any]]:
    """The demonstrations of one study run: :func:`make_demonstrations` with ``recipe`` (the
    :data:`DEMO_FIELDS` of a :class:`Config`), then ``n_demos`` diverse ones per group
    (:func:`demos_subset`); ``top_up=False`` picks them from the SAC roll-outs alone, leaving out
    what the shipped expert added.

    Returns:
        ``(demos, info)``; ``info`` holds ``demos_file`` (the :func:`demos_file` name),
        ``demos_safe`` / ``demos_unsafe`` (kept), ``demos_safe_expert`` /
        ``demos_unsafe_expert`` (of them, from the expert) and ``sac_rollouts_safe`` /
        ``sac_rollouts_unsafe`` (the SAC run's roll-outs of each group).

    Raises:
        RuntimeError: ``top_up=False`` and the SAC run gave no roll-out of a group.

    Used in: DEFENDER chapter study, through :func:`study_run`.
    """
    with _demo_lock(task):
        run = pinned_demonstrations(task, recipe)
    seen = {g: run.n_sac.get(g, len(getattr(run.pool, g))) for g in ("safe", "unsafe")}
    if top_up:
        demos = demos_subset(run, n_demos)
    else:
        if min(seen.values()) == 0:
            raise RuntimeError(
                f"{task}: the SAC run gave {seen['safe']} safe and {seen['unsafe']} unsafe "
                "roll-outs; without the expert top-up DEFENDER has no group to compare with. "
                "Take the task out of no_topup_tasks."
            )
        demos = DemoSet(
            select_diverse(run.pool.safe[: seen["safe"]], n_demos),
            select_diverse(run.pool.unsafe[: seen["unsafe"]], n_demos),
            task,
        )
    src = run.sources(demos)
    info = {
        "demos_file": demos_file(demos),
        "demos_safe": len(demos.safe),
        "demos_unsafe": len(demos.unsafe),
        "demos_safe_expert": src["safe"][1],
        "demos_unsafe_expert": src["unsafe"][1],
        "sac_rollouts_safe": seen["safe"],
        "sac_rollouts_unsafe": seen["unsafe"],
    }
    return demos, info


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
    "eval_return", "eval_return_std", "eval_crash_rate", "eval_length", "eval_score",
    "best_score", "steps", "train_wall_s", "train_cpu_s", "log_speed",
    # study_demonstrations
    "demos_file", "demos_safe", "demos_unsafe", "demos_safe_expert", "demos_unsafe_expert",
    "sac_rollouts_safe", "sac_rollouts_unsafe",
]  # fmt: skip


def study_run(config: dict[str, Any]) -> list[dict[str, Any]]:
    """One study task: a training run (:func:`train_run`), reduced to one row.

    ``config`` (:func:`study_task` builds it): ``label`` (the method's name in the study),
    ``task``, ``algo``, ``seed``, ``strategy`` (None: no filter), ``trajectory``, ``n_demos``,
    ``top_up``, ``demos`` (the demonstration recipe, :data:`DEMO_FIELDS`; None without a
    filter), ``train`` (:data:`TRAIN_FIELDS`), ``eval_episodes``, ``bins`` and, for a scale
    check, ``scale``.

    Returns:
        One row: ``method`` (the label), ``setting`` (the thesis's task name), ``seed``,
        ``scale``; the :data:`RUN_COLUMNS` of :func:`train_run` (``acc_reward``, ``crash_pct``,
        ...: the chapter's tables read them); :func:`training_run_numbers`; the final policy's
        evaluation **without the filter** over ``eval_episodes`` episodes (``eval_return``,
        ``eval_return_std``, ``eval_crash_rate``, ``eval_length``); ``eval_score`` and
        ``best_score`` (``eval_return`` and ``return_best`` in % of the thesis's plain-SAC
        return on the task, :data:`THESIS_SAC_RETURN`); ``steps``, ``train_wall_s``,
        ``train_cpu_s``, ``log_speed`` (ln of training steps per CPU-second: higher is
        cheaper); and where the demonstrations came from (:func:`study_demonstrations`).

    Used in: DEFENDER chapter study (``thesis study 03_defender``).
    """
    import time

    import torch

    from thesis_lib.rl import evaluate

    torch.set_num_threads(1)  # small nets: one core per run; the study runs one run per core
    task, seed = config["task"], int(config["seed"])
    cfg = Config(**config["train"], tasks=[task])
    demos: Any = None
    info: dict[str, Any] = {}
    if config["strategy"]:
        demos, info = study_demonstrations(
            task, config["demos"], int(config["n_demos"]), bool(config["top_up"])
        )
    c0 = time.process_time()
    row, ep, res = _train(
        task, config["algo"], seed, cfg, demos, config["strategy"], config["trajectory"], False
    )
    cpu = time.process_time() - c0
    steps = int(res.model.num_timesteps)
    ev = evaluate(
        res.model,
        _make_env(task, cfg.max_episode_steps),
        n_episodes=int(config["eval_episodes"]),
        seed=EVAL_SEED + seed,
    )
    ref = THESIS_SAC_RETURN.get(task, np.nan)
    numbers = training_run_numbers(ep, steps, int(config["bins"]))
    out: dict[str, Any] = {
        "method": config["label"],
        "setting": thesis_env_name(task),
        "seed": seed,
        "scale": config.get("scale", "study"),
        "top_up": bool(config["top_up"]) if config["strategy"] else None,
        **row,
        **numbers,
        "eval_return": float(ev["return"].mean()),
        "eval_return_std": float(ev["return"].std(ddof=0)),
        "eval_crash_rate": float(ev["crashed"].mean()),
        "eval_length": float(ev["length"].mean()),
        "eval_score": 100.0 * float(ev["return"].mean()) / ref,
        "best_score": 100.0 * numbers["return_best"] / ref,
        "steps": steps,
        "train_wall_s": float(res.wall_time_s),
        "train_cpu_s": float(cpu),
        "log_speed": float(np.log(steps / max(cpu, 1e-9))),
        **info,
    }
    return [out]


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
    ``cfg.seed``, topped up to ``max(n_demos, n_demos_list)`` per group) and the count.

    Used in: DEFENDER chapter study.
    """
    n = max(cfg.n_demos, *cfg.n_demos_list)
    recipe = {f: getattr(cfg, f) for f in DEMO_FIELDS} | {"n_demos": n, "n_demos_list": [n]}
    count = cfg.n_demos if n_demos is None else n_demos
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
        "train": {f: getattr(cfg, f) for f in TRAIN_FIELDS},
        "eval_episodes": cfg.eval_episodes,
        "bins": STUDY_CURVE_BINS,
    }
    return Task(study_run, config)


def study_tasks(cfg: Config) -> list[Task]:
    """The tasks of the chapter's pre-registered study (``params/03_defender.study.yml``).

    For each seed and task: the first of ``algos`` (SAC) plain, with each of
    ``state_strategies`` (state trajectories) and ``state_action_strategies`` (state-action),
    all with ``n_demos`` demonstrations per group, and with the first state strategy and each
    other count of ``n_demos_list`` (Table 4.5); on ``no_topup_tasks`` also with the first
    state strategy on the SAC roll-outs alone. The other algorithms (TD3) run plain and with
    the first state strategy, on their ``algo_tasks``. Seeds are the outer loop, so a study
    stopped part-way has whole seeds.

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
    return tasks


def study_summary(rows: pd.DataFrame) -> pd.DataFrame:
    """Study rows (one per run) as :func:`summarise` output (``time_pct``: wall time in % of
    the plain agent's on the same task and seed), with the final evaluation and the CPU time
    (``cpu_s``, ``cpu_pct`` likewise) beside, so that :func:`compare_tables` and :func:`compare_table_4_5` set the thesis's tables beside
    them. Runs without the expert top-up are left out (they repeat a method's keys).

    Used in: DEFENDER chapter ("Evidence at study scale").
    """
    keep = rows[rows["top_up"].fillna(True).astype(bool)] if "top_up" in rows else rows
    if keep.empty:
        return summarise(pd.DataFrame(columns=list(RUN_COLUMNS)))
    out = summarise(keep[list(RUN_COLUMNS)])
    keys = ["task", "algo", "trajectory", "strategy", "n_demos"]
    plain = keep[keep.strategy == "none"].set_index(["task", "algo", "seed"])["train_cpu_s"]
    idx = pd.MultiIndex.from_frame(keep[["task", "algo", "seed"]])
    keep = keep.assign(cpu_pct=100 * keep["train_cpu_s"].to_numpy() / plain.reindex(idx).to_numpy())
    ev = keep.groupby(keys, sort=False).agg(
        eval_return_mean=("eval_return", "mean"),
        eval_return_std=("eval_return", "std"),
        eval_crash_rate=("eval_crash_rate", "mean"),
        cpu_s=("train_cpu_s", "mean"),
        cpu_pct=("cpu_pct", "mean"),
    )
    return out.merge(ev.reset_index(), on=keys, how="left")


def study_curves(rows: pd.DataFrame, reps: int = 1000) -> pd.DataFrame:
    """The per-span curves of the study rows (:func:`training_run_numbers`) in long form: per
    method, setting and span, the mean over seeds of the crash rate, filtered rate and return,
    each with a 95% bootstrap interval over seeds.

    Returns:
        Columns ``method, setting, span, step`` (the span's end, environment steps),
        ``measure`` (``crash_rate``, ``filtered_rate``, ``return``), ``mean``, ``ci_low``,
        ``ci_high``, ``seeds``.

    Used in: DEFENDER chapter ("Evidence at study scale").
    """
    from thesis_lib.stats import bootstrap_ci

    cols = ["method", "setting", "span", "step", "measure", "mean", "ci_low", "ci_high", "seeds"]
    spans = sorted(int(c.rsplit("_b", 1)[1]) for c in rows.columns if c.startswith("crash_rate_b"))
    if rows.empty or not spans:
        return pd.DataFrame(columns=cols)
    out = []
    for (method, setting), g in rows.groupby(["method", "setting"], sort=False):
        steps = float(g["steps"].mean())
        for b in spans:
            for measure in ("crash_rate", "filtered_rate", "return"):
                v = g[f"{measure}_b{b}"].dropna().to_numpy(dtype=float)
                if len(v) >= 2:
                    m, lo, hi = bootstrap_ci(lambda a: float(a.mean()), v[:, None], reps=reps)
                else:
                    m, lo, hi = (float(v.mean()) if len(v) else np.nan), np.nan, np.nan
                out.append(
                    {
                        "method": method,
                        "setting": setting,
                        "span": b,
                        "step": steps * (b + 1) / len(spans),
                        "measure": measure,
                        "mean": m,
                        "ci_low": lo,
                        "ci_high": hi,
                        "seeds": len(v),
                    }
                )
    return pd.DataFrame(out, columns=cols)


def plot_study_curves(
    rows: pd.DataFrame, methods: Sequence[str] | None = None, reps: int = 1000
) -> Any:
    """Crash rate, filtered rate and return over training, one column per setting: each
    method's mean over seeds per span of training with its 95% interval (shaded).

    Used in: DEFENDER chapter ("Evidence at study scale").
    """
    import matplotlib.pyplot as plt

    curves = study_curves(rows, reps=reps)
    if methods is not None and not curves.empty:
        curves = curves[curves["method"].isin(methods)]
    if curves.empty:  # before the study, or while it has no run of these methods yet
        fig, ax = plt.subplots(figsize=(5, 1.5))
        ax.text(0.5, 0.5, "no study rows of these methods yet", ha="center", va="center")
        ax.set_axis_off()
        return fig
    settings = list(dict.fromkeys(curves["setting"]))
    measures = (
        ("crash_rate", "crash rate"),
        ("filtered_rate", "filtered rate"),
        ("return", "return"),
    )
    fig, axes = plt.subplots(
        len(measures), len(settings), figsize=(4.8 * len(settings), 8.5), squeeze=False
    )
    for j, setting in enumerate(settings):
        for i, (measure, name) in enumerate(measures):
            ax = axes[i, j]
            sub = curves[(curves["setting"] == setting) & (curves["measure"] == measure)]
            for k, (method, g) in enumerate(sub.groupby("method", sort=False)):
                colour = "black" if "+" not in method else f"C{k % 10}"
                ax.plot(g["step"], g["mean"], color=colour, label=method, lw=1.5)
                ax.fill_between(g["step"], g["ci_low"], g["ci_high"], color=colour, alpha=0.15)
            ax.set_ylabel(f"{name} (per span)")
            if i == 0:
                ax.set_title(setting)
            if i == len(measures) - 1:
                ax.set_xlabel("environment steps")
    axes[0, 0].legend(fontsize=6)
    fig.tight_layout()
    return fig


def study_topup_table(rows: pd.DataFrame) -> pd.DataFrame:
    """What the expert top-up changes: per setting, the first state strategy with the topped-up
    demonstrations and on the SAC roll-outs alone, mean over seeds of the crash rate, filtered
    rate, evaluation return and the demonstrations' sources.

    Used in: DEFENDER chapter ("Evidence at study scale").
    """
    cols = [
        "setting", "method", "seeds", "crash_rate", "filtered_rate", "eval_return",
        "demos_safe", "demos_safe_expert", "demos_unsafe", "demos_unsafe_expert",
    ]  # fmt: skip
    if rows.empty or "top_up" not in rows or not (rows["top_up"] == False).any():  # noqa: E712
        return pd.DataFrame(columns=cols)
    off = rows[rows["top_up"] == False]  # noqa: E712
    pairs = rows[
        rows["setting"].isin(off["setting"])
        & rows["strategy"].isin(off["strategy"])
        & rows["n_demos"].isin(off["n_demos"])
        & (rows["trajectory"] == "state")
        & (rows["algo"].isin(off["algo"]))
    ]
    g = pairs.groupby(["setting", "method"], sort=False)
    out = g.agg(
        seeds=("seed", "nunique"),
        crash_rate=("crash_rate", "mean"),
        filtered_rate=("filtered_rate", "mean"),
        eval_return=("eval_return", "mean"),
        demos_safe=("demos_safe", "mean"),
        demos_safe_expert=("demos_safe_expert", "mean"),
        demos_unsafe=("demos_unsafe", "mean"),
        demos_unsafe_expert=("demos_unsafe_expert", "mean"),
    ).reset_index()
    return out[cols]


def study_demo_sources(rows: pd.DataFrame) -> pd.DataFrame:
    """Per setting, demonstration count and draw: how many of the kept demonstrations came from
    the SAC run and how many from the shipped expert (the top-up), how many roll-outs of each
    group the SAC run gave, and which runs (``runs``, ``seeds``) used them. Empty before the
    study ran.

    A draw is one ``demos_file`` (its name is a hash of every array). A study that moved
    machines before its demonstrations were pinned (:func:`pinned_demonstrations`) can have
    more than one draw per setting; this table says which runs used which.

    Used in: DEFENDER chapter ("Evidence at study scale").
    """
    cols = [
        "setting", "n_demos", "top_up", "demos_file", "runs", "seeds", "sac_rollouts_safe",
        "sac_rollouts_unsafe", "demos_safe", "demos_safe_expert", "demos_unsafe",
        "demos_unsafe_expert",
    ]  # fmt: skip
    if rows.empty or "demos_file" not in rows:
        return pd.DataFrame(columns=cols)
    d = rows[rows["demos_file"].notna()]
    keys = [c for c in cols if c not in ("runs", "seeds")]
    out = (
        d.groupby(keys, sort=False, dropna=False)["seed"]
        .agg(runs="size", seeds=lambda s: ",".join(str(int(v)) for v in sorted(set(s))))
        .reset_index()
    )
    out["_first"] = d.groupby(keys, sort=False, dropna=False)["seed"].min().to_numpy()
    out = out.sort_values(["setting", "n_demos", "top_up", "_first"])
    return out[cols].reset_index(drop=True)


STUDY_DATA_NOTE = (
    "the setting (SB3's SAC v2 and TD3 with 64-64 networks for 30,000 steps per run, not the "
    "authors' SAC v1 for 5,000 episodes; demonstrations from a 30,000-step SAC run, a group "
    "with too few roll-outs topped up from the ARS expert then shipped)"
)
"""What may make the study's answer differ from the thesis's (the readings' last reason)."""
