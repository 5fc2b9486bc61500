"""How far ahead of a crash does DEFENDER fire? A diagnostic of one trained policy.

The DEFENDER studies since ``defender-c7c9-v2`` step every filtered action once on a copy of
the state: a *saved crash* is an action that would have ended the episode on that very step, any
other firing a *false alarm*. A filter that fires a few steps before a fall, as a filter of
state trajectories may, counts as a false alarm there. This diagnostic lets the agent's own
policy go on acting on the copy (:func:`~thesis_lib.defender.wrapper.counterfactual_crash_step`)
and asks, for several look-ahead lengths ``k``, what share of the firings would have crashed
within ``k`` steps.

It answers beside a blind control: the same policy without the filter, whose visited states
are followed by a crash within ``k`` steps at a base rate. A filter that fired at random states
would have that share (``control_any``); one that fired at random at the same step of the
episode as DEFENDER did, ``control_same_step`` (does the filter know more than the clock?).

It is exploratory (not a registered study): it reads a checkpointed policy, does not train, and
says nothing of the learning the filter changes.

Used in: ``thesis defender lookahead``; the DEFENDER chapter (its second and third studies).
"""

from __future__ import annotations

import json
import re
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal, cast

import gymnasium as gym
import numpy as np
import pandas as pd

from thesis_lib.chapters.defender.demos import make_env, study_demonstrations
from thesis_lib.chapters.defender.study import study_task
from thesis_lib.defender import DefenderWrapper, DemoSet
from thesis_lib.defender.wrapper import counterfactual_crash_step
from thesis_lib.paths import project_root
from thesis_lib.rl.callbacks import find_horizon, is_crash

LOOKAHEAD_STEPS: tuple[int, ...] = (1, 5, 10, 20, 50, 100)
"""The look-ahead lengths ``k`` of :func:`filter_lookahead` by default (1: the study's own
one-step counterfactual)."""

Policy = Callable[[np.ndarray], Any]


@dataclass
class Lookahead:
    """What :func:`filter_lookahead` found.

    ``table``: one row per look-ahead length ``k``: ``filter`` (the share of firings whose
    held-back action, with the policy acting after it, would have crashed within ``k`` steps),
    ``control_any`` and ``control_same_step`` (the blind controls, module docstring),
    ``lift_any`` / ``lift_same_step`` (``filter`` over each). ``firings``: one row per firing
    (``filter_step``, the real steps taken before it; ``crash_in``, steps to the crash or NaN).
    ``episodes``: the control run's finished episodes (``length``, ``crashed``). ``summary``:
    the counts and rates per 1,000 steps of both runs, the firing step (median, 10th and 90th
    percentiles) and the median steps to the crash, the control's episode length (the same
    three) and its share of crashed episodes (and,
    from :func:`study_lookahead`, the study, the filter and the run a checkpoint was taken of).
    """

    table: pd.DataFrame
    firings: pd.DataFrame
    episodes: pd.DataFrame
    summary: dict[str, Any]


def sb3_policy(
    path: str | Path, algo: str = "SAC", deterministic: bool = False, seed: int = 0
) -> Policy:
    """The policy of a saved stable-baselines3 model (``model.zip``, e.g. a study checkpoint's):
    observation -> action, sampled as in training unless ``deterministic``; torch's generator
    is seeded with ``seed``.

    Raises:
        FileNotFoundError: no such file.
        ValueError: an algorithm stable-baselines3 does not have.
    """
    import stable_baselines3 as sb3
    import torch

    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(
            f"No saved model {path}: give a stable-baselines3 model.zip (a study checkpoint's "
            "studies/<chapter>/<tag>/tasks/partial/<key>/step-*/model.zip)."
        )
    cls = getattr(sb3, algo, None)
    if cls is None:
        raise ValueError(f"Unknown algorithm {algo!r}; stable-baselines3 has SAC, TD3, DDPG, ...")
    torch.manual_seed(seed)
    model = cls.load(path, device="cpu")
    return lambda obs: model.predict(obs, deterministic=deterministic)[0]


def _check(steps: int, lookahead: Sequence[int]) -> list[int]:
    ks = sorted({int(k) for k in lookahead})
    if not ks or ks[0] < 1:
        raise ValueError(f"lookahead must be positive step counts, got {list(lookahead)}.")
    if int(steps) < 1:
        raise ValueError(f"steps must be >= 1, got {steps}.")
    return ks


def filter_lookahead(
    policy: Policy,
    env_fn: Callable[[], gym.Env],
    demos: DemoSet,
    strategy: str = "MeanDemoW5/MeanDemoW10",
    trajectory: Literal["state", "state_action"] = "state",
    steps: int = 20_000,
    lookahead: Sequence[int] = LOOKAHEAD_STEPS,
    seed: int = 0,
    progress: bool = False,
    max_trajectory: int | None = None,
    paper_compat: bool = False,
) -> Lookahead:
    """Run ``policy`` for ``steps`` steps with DEFENDER (``strategy`` on ``trajectory``, the
    ``demos``) and ``steps`` without it; for every firing, look up to ``max(lookahead)`` steps
    ahead on a copy of the state (:func:`counterfactual_crash_step`, bounded by the horizon:
    a termination at the horizon is no crash); compare with the blind controls (module
    docstring). Nothing learns: the dynamics model of the filter is never updated.

    Args:
        policy: observation -> action (:func:`sb3_policy`).
        env_fn: makes a new environment (with its ``TimeLimit``), e.g. the study's ``make_env``.
        demos: the safe and unsafe demonstrations (the study's pinned ones).
        strategy: ``"<safe method>/<unsafe method>"``.
        trajectory: ``state`` or ``state_action``.
        steps: environment steps of each run (a filtered step counts as one, as in training).
        lookahead: the look-ahead lengths ``k`` of the table.
        seed: the first reset's seed of each run.
        progress: a progress bar per run.
        max_trajectory: compare only the trajectory's last this-many steps (the authors' code:
            20); None, the thesis's text: the whole episode so far.
        paper_compat: the authors' filter (:class:`DefenderWrapper`'s ``paper_compat``:
            FastDTW, the 20-step cap, fire only on ``>``); slow.

    Raises:
        ValueError: a look-ahead length below 1, ``steps`` below 1, a strategy without ``/``.
    """
    from tqdm.auto import tqdm

    ks = _check(steps, lookahead)
    if strategy.count("/") != 1:
        raise ValueError(
            f"strategy must be '<safe>/<unsafe>', e.g. MeanDemoW5/MeanDemoW10; got {strategy!r}."
        )
    safe_m, unsafe_m = strategy.split("/")
    env = DefenderWrapper(
        env_fn(),
        demos.safe,
        demos.unsafe,
        safe_method=safe_m,
        unsafe_method=unsafe_m,
        trajectory=trajectory,
        max_trajectory=max_trajectory,
        paper_compat=paper_compat,
        dynamics_train_every=2**62,  # nothing learns here
    )
    horizon = env.horizon
    firings: list[dict[str, Any]] = []
    obs, _ = env.reset(seed=seed)
    for _ in tqdm(range(int(steps)), desc="with the filter", disable=not progress):
        action = policy(np.asarray(obs))
        obs, _, term, trunc, info = env.step(action)
        if info["filtered"]:
            j = int(info["filter_step"])
            left = ks[-1] if horizon is None else min(ks[-1], horizon - j)
            k = counterfactual_crash_step(env.env, action, policy, max_steps=max(left, 1))
            crash_in = float(k) if k is not None and is_crash(True, j + k, horizon) else np.nan
            firings.append({"filter_step": j, "crash_in": crash_in})
        if term or trunc:
            obs, _ = env.reset()
    filtered_eps = len(env.episodes)
    env.close()

    plain = env_fn()
    horizon_plain = find_horizon(plain)
    episodes: list[dict[str, Any]] = []
    obs, _ = plain.reset(seed=seed)
    length = 0
    for _ in tqdm(range(int(steps)), desc="without it", disable=not progress):
        obs, _, term, trunc, _ = plain.step(policy(np.asarray(obs)))
        length += 1
        if term or trunc:
            episodes.append({"length": length, "crashed": is_crash(term, length, horizon_plain)})
            obs, _ = plain.reset()
            length = 0
    plain.close()
    fire = pd.DataFrame(firings, columns=["filter_step", "crash_in"])
    eps = pd.DataFrame(episodes, columns=["length", "crashed"])
    table = lookahead_table(fire, eps, ks)
    summary = {
        "steps": float(steps),
        "firings": float(len(fire)),
        "firings_per_1k_steps": 1000 * len(fire) / steps,
        "filtered_run_episodes": float(filtered_eps),
        "control_episodes": float(len(eps)),
        "control_crashes_per_1k_steps": 1000 * float(eps["crashed"].sum()) / steps,
        # where the filter fires and the plain episodes end (NaN where there is none)
        "filter_step_median": float(fire["filter_step"].median()),
        "filter_step_p10": float(fire["filter_step"].quantile(0.1)),
        "filter_step_p90": float(fire["filter_step"].quantile(0.9)),
        "crash_in_median": float(fire["crash_in"].median()),
        "control_length_median": float(eps["length"].median()),
        "control_length_p10": float(eps["length"].quantile(0.1)),
        "control_length_p90": float(eps["length"].quantile(0.9)),
        "control_crashed_share": float(eps["crashed"].mean()),
    }
    return Lookahead(table, fire, eps, summary)


def lookahead_table(
    firings: pd.DataFrame, episodes: pd.DataFrame, lookahead: Sequence[int] = LOOKAHEAD_STEPS
) -> pd.DataFrame:
    """The table of :class:`Lookahead` from its ``firings`` and the control's ``episodes``.

    ``control_any``: of all states the control run visited (finished episodes; ``j`` real
    steps taken, ``0 <= j < length``), the share followed by a crash within ``k`` steps
    (``crashed`` and ``length - j <= k``). ``control_same_step``: for each firing at step
    ``j``, that share among the control episodes that reached step ``j``, averaged over the
    firings (firings at a step no control episode reached are left out).
    """
    ks = _check(1, lookahead)
    lengths = episodes["length"].to_numpy(int)
    crashed = episodes["crashed"].to_numpy(bool)
    visited = int(lengths.sum())
    crash_in = firings["crash_in"].to_numpy(float)
    at = firings["filter_step"].to_numpy(int)
    rows = []
    for k in ks:
        filt = float(np.mean(crash_in <= k)) if len(crash_in) else np.nan  # NaN <= k is False
        any_ = float(np.minimum(lengths[crashed], k).sum() / visited) if visited else np.nan
        same = []
        for j in at:
            reached = lengths > j
            if reached.any():
                same.append(float(np.mean(crashed[reached] & (lengths[reached] - j <= k))))
        same_step = float(np.mean(same)) if same else np.nan
        rows.append(
            {
                "k": k,
                "filter": filt,
                "control_any": any_,
                "control_same_step": same_step,
                "lift_any": filt / any_ if any_ else np.nan,
                "lift_same_step": filt / same_step if same_step else np.nan,
            }
        )
    return pd.DataFrame(rows)


def study_lookahead(
    model: str | Path,
    study: str = "03_defender:v6",
    strategy: str | None = None,
    trajectory: str = "state",
    n_demos: int | None = None,
    steps: int = 20_000,
    lookahead: Sequence[int] = LOOKAHEAD_STEPS,
    seed: int = 0,
    progress: bool = False,
    max_trajectory: int | None = None,
    paper_compat: bool = False,
) -> Lookahead:
    """:func:`filter_lookahead` of a saved SAC model on a DEFENDER study's first task, with the
    study's pinned demonstrations (``n_demos`` per group; default the study's) and its first
    state strategy (default); ``max_trajectory`` None is the study's own (``paper_compat``
    sets 20).

    Raises:
        FileNotFoundError: no such model or study file.
    """
    from thesis_lib.book import study as st  # cycle: the book reads the chapters
    from thesis_lib.chapters import get_chapter  # cycle: the registry imports this chapter

    s = st.load_study(st.study_chapter(study))
    chapter = get_chapter(s.chapter)
    cfg = st.study_config(s, chapter)
    policy = sb3_policy(model, cfg.algos[0], seed=seed)  # a wrong path fails before the demos
    strategy = strategy or cfg.state_strategies[0]
    count = int(n_demos or cfg.n_demos)
    task = cfg.tasks[0]
    recipe = study_task(cfg, task, cfg.algos[0], cfg.seed, strategy, trajectory, count)
    demos, _ = study_demonstrations(task, recipe.config["demos"], count)
    cap = max_trajectory if max_trajectory is not None else cfg.max_trajectory
    out = filter_lookahead(
        policy,
        lambda: make_env(task, cfg.max_episode_steps),
        demos,
        strategy,
        cast(Literal["state", "state_action"], trajectory),
        steps,
        lookahead,
        seed,
        progress,
        max_trajectory=cap,
        paper_compat=paper_compat,
    )
    out.summary.update(
        {
            "study": s.study,
            "strategy": strategy,
            "trajectory": trajectory,
            "n_demos": count,
            "max_trajectory": cap,
            "paper_compat": paper_compat,
        }
    )
    found = re.search(r"([0-9a-f]{16})/step-(\d+)", Path(model).as_posix())
    if found:  # a study checkpoint: name the run it was taken of
        key, step = found.group(1), int(found.group(2))
        runs = {t.key: t.config for t in st.study_tasks(s, chapter)}
        if key in runs:
            c = runs[key]
            out.summary.update(
                {
                    "run_key": key,
                    "run_label": c["label"],
                    "run_seed": int(c["seed"]),
                    "run_scale": c.get("scale", "study"),
                    "run_step": step,
                }
            )
    return out


#: Where the lookahead diagnostics of the study runs' checkpoints are kept (CSV + JSON each).
LOOKAHEAD_DIR = Path("studies") / "03_defender" / "diagnostics" / "lookahead"


def lookahead_results(folder: str | Path | None = None) -> pd.DataFrame:
    """The committed lookahead diagnostics (``thesis defender lookahead --out``) in ``folder``
    (default :data:`LOOKAHEAD_DIR` of the project): one row per file and look-ahead length,
    the table's columns beside the run it was taken of (``run_label``, ``run_seed``,
    ``run_scale``, ``run_step``) and the summary's rates. Empty where there are none.
    """
    root = Path(folder) if folder is not None else project_root() / LOOKAHEAD_DIR
    keep = (
        "run_label", "run_seed", "run_scale", "run_step", "firings_per_1k_steps",
        "control_crashes_per_1k_steps", "control_crashed_share", "filter_step_median",
        "filter_step_p10", "filter_step_p90", "control_length_median", "control_length_p10",
        "control_length_p90",
    )  # fmt: skip
    frames = []
    for csv in sorted(root.glob("*.csv")) if root.is_dir() else []:
        meta = json.loads(csv.with_suffix(".json").read_text())
        summary = meta.get("summary", {})
        t = pd.read_csv(csv)
        for k in reversed(keep):
            t.insert(0, k, summary.get(k))
        frames.append(t)
    cols = [*keep, "k", "filter", "control_any", "control_same_step", "lift_any", "lift_same_step"]
    if not frames:
        return pd.DataFrame(columns=cols)
    out = pd.concat(frames, ignore_index=True)[cols]
    return out.sort_values(["run_label", "run_scale", "run_seed", "run_step", "k"]).reset_index(
        drop=True
    )


def summarize_lookahead(
    results: pd.DataFrame, lookahead: Sequence[int] = (1, 10, 20, 50)
) -> pd.DataFrame:
    """:func:`lookahead_results` wide: one row per checkpoint (run, seed, step) with its firing
    rate, the step it fires at and the control's episode length (10th percentile, median, 90th
    percentile) and crashed share, and for
    each ``k`` of ``lookahead`` the filter's share of firings that would have crashed within
    ``k`` steps beside the blind filter at the same step (``same step``). Empty where
    ``results`` is.

    Used in: DEFENDER chapter (the second study, "How far ahead ...").
    """
    index = ["run_label", "run_scale", "run_seed", "run_step"]
    fixed = [
        "firings_per_1k_steps", "filter_step_p10", "filter_step_median", "filter_step_p90",
        "control_length_p10", "control_length_median", "control_length_p90",
        "control_crashed_share",
    ]  # fmt: skip
    names = {
        "run_label": "run", "run_scale": "scale", "run_seed": "seed", "run_step": "step",
        "firings_per_1k_steps": "firings per 1k steps", "filter_step_p10": "fires at p10",
        "filter_step_median": "fires at", "filter_step_p90": "fires at p90",
        "control_length_p10": "length without p10", "control_length_median": "length without",
        "control_length_p90": "length without p90", "control_crashed_share": "crashed without",
    }  # fmt: skip
    cols = [names[c] for c in index + fixed] + [
        f"{w} k={k}" for k in lookahead for w in ("filter", "same step")
    ]
    if results.empty:
        return pd.DataFrame(columns=cols)
    # a diagnostic written before a summary figure existed shows it as NaN
    results = results.reindex(columns=[*results.columns, *(c for c in fixed if c not in results)])
    base = results.drop_duplicates(index)[index + fixed].set_index(index)
    for k in lookahead:
        at = results[results["k"] == k].set_index(index)
        base[f"filter k={k}"] = at["filter"]
        base[f"same step k={k}"] = at["control_same_step"]
    return base.reset_index().rename(columns=names)[cols]
