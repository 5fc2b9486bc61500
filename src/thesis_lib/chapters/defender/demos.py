"""The DEFENDER chapter's environments and demonstrations (thesis 4.3.3).

:func:`make_demonstrations` runs one SAC training per task (:func:`demonstrations_task`, a sweep
task), keeps its roll-outs as safe and unsafe demonstrations and tops a short group up from the
shipped expert (``Config.demo_source``). The tasks of the chapter read their demonstrations from
content-addressed files (:func:`demos_file`), so a task's key changes when its demonstrations do.
The study's demonstrations are made once and kept beside its rows
(:func:`pinned_demonstrations`, :func:`study_demonstrations`).

Used in: DEFENDER chapter (thesis 4.3).
"""

from __future__ import annotations

import hashlib
from pathlib import Path
from typing import Any

import gymnasium as gym

from thesis_lib._io import atomic_write, file_lock, hash_arrays
from thesis_lib.book import results_dir
from thesis_lib.book.study import studies_dir
from thesis_lib.chapters.defender.config import CHAPTER, Config
from thesis_lib.defender import (
    DemoRun,
    DemoSet,
    collect_demonstrations,
    expert_demonstrations,
    load_demonstrations,
    save_demonstrations,
    save_demonstrations_minari,
    select_diverse,
)
from thesis_lib.sweep import Task, TaskStore, run_tasks, task_id


def thesis_env_name(task: str) -> str:
    """The thesis's table label of a gymnasium id: ``"Hopper-v5"`` -> ``"Hopper"``.

    >>> thesis_env_name("InvertedDoublePendulum-v5")
    'InvertedDoublePendulum'
    """
    return task.split("-v")[0]


def episode_limit(env: gym.Env) -> int | None:
    """The environment's registered episode limit, if any."""
    return None if env.spec is None else env.spec.max_episode_steps


def make_env(task: str, horizon: int | None) -> gym.Env:
    """``task`` with episodes cut at ``horizon`` steps (None: the task's own limit)."""
    return gym.make(task, max_episode_steps=horizon) if horizon else gym.make(task)


def rl_overrides(cfg: Config) -> dict[str, Any]:
    """The agent's settings ``cfg`` overrides (nets, learning rate, minibatch): the same for the
    demonstration run and every training run."""
    return {
        "net_arch": list(cfg.net_arch),
        "learning_rate": cfg.learning_rate,
        "batch_size": cfg.batch_size,
    }


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
        rl_overrides=rl_overrides(cfg),
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


@task_id("thesis_lib.chapters.defender:demonstrations_task")
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


def demos_subset(run: DemoRun, n: int) -> DemoSet:
    """``n`` diverse demonstrations per group from a run's pool (as the authors picked theirs)."""
    pool = run.pool
    return DemoSet(select_diverse(pool.safe, n), select_diverse(pool.unsafe, n), pool.env_id)


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


def _demo_lock(task: str) -> Any:
    """An exclusive file lock per task, so that two study workers do not both make the same
    task's demonstrations (the second waits, then reads them from the sweep store)."""
    return file_lock(results_dir(CHAPTER) / "demos" / f".{thesis_env_name(task)}.lock")


def trim_pool(run: DemoRun, n: int) -> tuple[DemoRun, dict[str, int]]:
    """The demonstrations of ``run``'s pool that a study can ever pick with ``n`` or fewer per
    group: per group, :func:`select_diverse` of ``n`` from the whole pool (the top-up path) and
    of ``n`` from its SAC roll-outs alone (``top_up=False``), in pool order.

    :func:`select_diverse` is a greedy farthest-point selection from the longest demonstration,
    so its first ``m`` picks from this subset are its first ``m`` picks from the whole pool, for
    every ``m <= n`` and either path: :func:`demos_subset` and :func:`study_demonstrations`
    pick the same demonstrations from the trimmed pool as from the whole one (tested). A SAC run
    rolled out after every episode yields thousands of roll-outs (tens of MB); the trimmed pool
    holds at most ``2 n`` per group.

    Returns:
        ``(trimmed run, counts)``: ``counts`` has ``pool_safe`` / ``pool_unsafe`` (the whole
        pool's size) and ``sac_rollouts_safe`` / ``sac_rollouts_unsafe`` (its SAC roll-outs),
        which the trimmed run no longer shows.
    """
    groups: dict[str, list[Any]] = {}
    picked: dict[str, list[Any]] = {}
    n_sac: dict[str, int] = {}
    counts: dict[str, int] = {}
    for g in ("safe", "unsafe"):
        pool = getattr(run.pool, g)
        k = run.n_sac.get(g, len(pool))
        picked[g] = select_diverse(pool, n) if pool else []  # the top-up path's n
        keep = {id(d) for d in picked[g]}
        if k:
            keep |= {id(d) for d in select_diverse(pool[:k], n)}
        groups[g] = [d for d in pool if id(d) in keep]
        n_sac[g] = sum(id(d) in keep for d in pool[:k])
        counts[f"pool_{g}"] = len(pool)
        counts[f"sac_rollouts_{g}"] = k
    pool = DemoSet(groups["safe"], groups["unsafe"], run.pool.env_id)
    demos = DemoSet(picked["safe"], picked["unsafe"], run.pool.env_id)  # nested: the trim's own
    return DemoRun(demos, pool, [], None, n_sac), counts


def _pinned_record(
    task: str, recipe: dict[str, Any], folder: str | Path | None
) -> tuple[DemoRun, dict[str, Any]]:
    """:func:`pinned_demonstrations` and the pinned record's row."""
    pinned = TaskStore(Path(folder) if folder is not None else studies_dir(CHAPTER) / "demos")
    cfg = Config(**recipe, tasks=[task])
    (t,) = _demonstrations_tasks(cfg)
    if not pinned.has(t.key):
        make_demonstrations(cfg, progress=False)
        record = TaskStore(results_dir(CHAPTER) / "tasks").read(t.key)
        row = record["rows"][0]
        made = _demo_run_from_row(row, results_dir(CHAPTER) / "demos", episodes=False)
        trimmed, counts = trim_pool(made, max(cfg.n_demos, *cfg.n_demos_list))
        name = demos_file(trimmed.pool, f"{thesis_env_name(task)}-pinned")
        data = (results_dir(CHAPTER) / "demos" / name).read_bytes()
        pinned.root.mkdir(parents=True, exist_ok=True)
        atomic_write(pinned.root / name, lambda tmp: tmp.write_bytes(data))
        index = {
            g: {id(d): i for i, d in enumerate(getattr(trimmed.pool, g))}
            for g in ("safe", "unsafe")
        }
        row = {
            **row,
            "pool": name,
            **{
                g: ",".join(str(index[g][id(d)]) for d in getattr(trimmed.demos, g))
                for g in ("safe", "unsafe")
            },
            **{f"n_sac_{g}": trimmed.n_sac[g] for g in ("safe", "unsafe")},
            **counts,
            "trimmed": True,
        }
        pinned.write({**record, "rows": [row]})  # last: a record here means its pool is here
    row = pinned.read(t.key)["rows"][0]
    return _demo_run_from_row(row, pinned.root, episodes=False), row


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
    sweep record and the pool into ``folder`` (default ``studies/03_defender/demos/``,
    committed with the study's rows); every later call, on any machine, reads them from there.
    The run's training-episode log is not kept (the study does not use it; ``episodes`` is
    empty).

    A pin made since defender-c7c9-v4 keeps only the part of the pool a study can pick from
    (:func:`trim_pool`; its record's row says ``trimmed``, the whole pool's size and its SAC
    roll-outs); the earlier pins (v1-v3) hold their whole pools and are read as they are.

    Used in: DEFENDER chapter study, through :func:`study_demonstrations` (which holds the
    task's lock).
    """
    return _pinned_record(task, recipe, folder)[0]


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
        run, row = _pinned_record(task, recipe, None)
    seen = {g: run.n_sac.get(g, len(getattr(run.pool, g))) for g in ("safe", "unsafe")}
    rollouts = {g: int(row.get(f"sac_rollouts_{g}", seen[g])) for g in ("safe", "unsafe")}
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
        "sac_rollouts_safe": rollouts["safe"],
        "sac_rollouts_unsafe": rollouts["unsafe"],
    }
    return demos, info
