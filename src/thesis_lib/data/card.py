"""Data cards: what a data set holds, how good its episodes are, and how it was made.

The chapters (HDT 5.2, Decision Mamba 5.3, DEFENDER 4.3) call :func:`data_card` /
:func:`cards_table` for their data tables, :func:`plot_return_histograms` for the figure of
episode returns per tier, and :func:`expert_quality` for the shipped experts against the
issue's quality targets.
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from pathlib import Path
from typing import Any, Literal, overload

import numpy as np

from . import experts  # POLICY_DIR looked up per call, as load_policy does
from .d4rl_reference import BAND_MIN_EPISODES, SOURCES, band_transitions, d4rl_stats, in_band
from .experts import has_medium_run, has_policies, load_policy_record
from .maze import WaypointExpert
from .recipe import GENERATOR_VERSION, _random_policy, action_noise_for, make_env, rollout
from .scores import normalized_score
from .storage import OfflineDataset, generate_command, load
from .tasks import TASKS, get_task, is_our_namespace, parse_dataset_id

#: Expert-tier targets over 100 episodes: the D4RL-normalised score where D4RL defines one
#: (its expert tier scores about 90-110), else the mean return (Maze2D: the success rate).
QUALITY_TARGETS: dict[str, float] = {
    "hopper": 90.0,
    "walker2d": 90.0,
    "halfcheetah": 85.0,
    "ant": 90.0,
    "inverted-double-pendulum": 9000.0,
}
MAZE_SUCCESS_TARGET = 0.9
MEDIUM_NORMALIZED_RANGE = (25.0, 60.0)

#: What could and could not be done for the gymnasium-robotics tasks (checked with
#: mujoco 3.11, gymnasium-robotics 1.4.2; re-run with :func:`check_environments`).
FEASIBILITY: dict[str, str] = {
    "antmaze": (
        "AntMaze_*-v5 loads and rolls out. No expert: D4RL used a goal-reaching ant policy "
        "trained with SAC for millions of steps, beyond 2 CPU cores. Random tier only."
    ),
    "adroit": (
        "AdroitHand{Pen,Door,Hammer,Relocate}-v1 load and roll out. No expert: D4RL's came "
        "from human demonstrations (25 per task) plus DAPG fine-tuning; none here. Random tier "
        "only; the D4RL reference scores are indicative (v1 rewards differ from D4RL v0)."
    ),
    "kitchen": (
        "FrankaKitchen-v1 loads and rolls out with mujoco 3.11 (it fails on mujoco >= 3.12). "
        "No data: D4RL's came from human VR teleoperation; a scripted multi-task kitchen "
        "controller is not feasible here. Its goals are nested dicts, not stored."
    ),
}


def _as_dataset(ds: str | OfflineDataset) -> OfflineDataset:
    return load(ds) if isinstance(ds, str) else ds


def data_card(ds: str | OfflineDataset) -> dict[str, Any]:
    """Statistics of one data set.

    Args:
        ds: a data-set id or a loaded :class:`OfflineDataset`.

    Returns:
        A dict: ``id, env_id, episodes, transitions, return_mean, return_std, return_min,
        return_max, normalized_mean/std/min/max`` (``None`` without reference scores),
        ``mean_length``,
        ``success_rate`` (goal-conditioned sets: share of episodes with positive return),
        ``terminations, truncations`` (episodes ending each way) and ``info`` (how it was
        made, for our data sets).
    """
    d = _as_dataset(ds)
    r = d.returns
    norm = d.normalized_scores()
    goal = bool(d.episodes) and d.episodes[0].desired_goals is not None
    return {
        "id": d.id,
        "env_id": d.env_id,
        "episodes": len(d),
        "transitions": d.n_transitions,
        "return_mean": float(r.mean()) if len(r) else float("nan"),
        "return_std": float(r.std()) if len(r) else float("nan"),
        "return_min": float(r.min()) if len(r) else float("nan"),
        "return_max": float(r.max()) if len(r) else float("nan"),
        "normalized_mean": None if norm is None or not len(r) else float(norm.mean()),
        "normalized_std": None if norm is None or not len(r) else float(norm.std()),
        "normalized_min": None if norm is None or not len(r) else float(norm.min()),
        "normalized_max": None if norm is None or not len(r) else float(norm.max()),
        "mean_length": d.n_transitions / len(d) if len(d) else float("nan"),
        "success_rate": float((r > 0).mean()) if goal else None,
        "terminations": int(sum(bool(e.terminations[-1]) for e in d.episodes if len(e))),
        "truncations": int(sum(bool(e.truncations[-1]) for e in d.episodes if len(e))),
        "info": d.metadata.get("thesis_info", {}),
    }


def cards_table(ids: Sequence[str]) -> Any:
    """One row per data set (:func:`data_card` without ``info``), as a pandas DataFrame."""
    import pandas as pd

    rows = []
    for i in ids:
        c = data_card(i)
        c.pop("info")
        rows.append(c)
    return pd.DataFrame(rows)


def format_card(card: dict[str, Any]) -> str:
    """Plain-text rendering of :func:`data_card` (what ``thesis data card`` prints)."""
    lines = [f"# {card['id']}  ({card['env_id']})"]
    for k in ("episodes", "transitions"):
        lines.append(f"{k:>16}: {card[k]}")
    if "mean_length" in card:
        lines.append(f"{'mean length':>16}: {card['mean_length']:.0f}")
    lines.append(
        f"{'return':>16}: {card['return_mean']:.1f} ± {card['return_std']:.1f} "
        f"[{card['return_min']:.1f}, {card['return_max']:.1f}]"
    )
    if card["normalized_mean"] is not None:
        lines.append(
            f"{'D4RL-normalised':>16}: {card['normalized_mean']:.1f} ± {card['normalized_std']:.1f} "
            f"[{card['normalized_min']:.1f}, {card['normalized_max']:.1f}]"
        )
    lines += _d4rl_lines(card)
    if card["success_rate"] is not None:
        lines.append(f"{'success rate':>16}: {card['success_rate']:.2f}")
    lines.append(
        f"{'ends':>16}: {card['terminations']} terminated, {card['truncations']} truncated"
    )
    if card.get("info"):
        lines.append(f"{'made by':>16}: {json.dumps(card['info'], default=str)}")
        lines += _version_lines(card)
    task = _our_task_tier(card["id"])[0]
    ref = maze_reference(task) if task in TASKS and get_task(task).kind == "maze" else None
    if ref is not None and ref.get("random_normalized") is not None:
        lines.append(
            f"{'in this maze':>16}: uniform random actions {ref['random_return_mean']:.1f} "
            f"(normalised {ref['random_normalized']:.1f}), the planner {ref['return_mean']:.1f} "
            f"({ref['normalized']:.1f}): D4RL's references, measured in D4RL's maze2d, put "
            "them at 0 and 100 (thesis data card --experts)"
        )
    if task in TASKS and get_task(task).kind == "robotics":
        fam = "antmaze" if task.startswith("antmaze") else task if task == "kitchen" else "adroit"
        lines.append(f"{'feasibility':>16}: {FEASIBILITY[fam]}")
    return "\n".join(lines)


def _our_task_tier(dataset_id: str) -> tuple[str | None, str | None]:
    """``(task, tier)`` of a set made here (any size), else ``(None, None)``."""
    try:
        ns, task, tier, _ = parse_dataset_id(dataset_id)
    except ValueError:
        return None, None
    return (task, tier) if is_our_namespace(ns) else (None, None)


def d4rl_comparison(card: dict[str, Any]) -> dict[str, Any] | None:
    """Our set's statistics beside D4RL's published ones for the same tier
    (:mod:`thesis_lib.data.d4rl_reference`), or ``None`` where D4RL has no such set.

    Returns:
        ``{"d4rl": D4RLStats, "in_band": bool | None, "why": str, "band_transitions": int |
        None}``: ``in_band`` is ``None`` where D4RL publishes no return statistics (Maze2D),
        else whether our normalised mean is within 10 points of D4RL's and our std at least
        half of D4RL's. ``band_transitions``: where the set holds fewer than
        :data:`~thesis_lib.data.d4rl_reference.BAND_MIN_EPISODES` episodes, the size that would
        (its spread is a rough estimate until then; ``why`` says so), else ``None``.
    """
    task, tier = _our_task_tier(card["id"])
    ref = d4rl_stats(task, tier) if task and tier else None
    if ref is None:
        return None
    if ref.mean is None or card.get("normalized_mean") is None:
        return {"d4rl": ref, "in_band": None, "why": ref.computed, "band_transitions": None}
    ok, why = in_band(card["normalized_mean"], card["normalized_std"], ref)
    # the size it was made at (medium-expert: each half's, as --n-transitions takes it)
    made_at = card.get("info", {}).get("n_transitions") or card["transitions"]
    size = band_transitions(int(made_at), int(card["episodes"]))
    if size is not None:
        why += (
            f" (from {card['episodes']} episodes; the band is judged on {BAND_MIN_EPISODES}: "
            f"--n-transitions {size})"
        )
    return {"d4rl": ref, "in_band": ok, "why": why, "band_transitions": size}


def _version_lines(card: dict[str, Any]) -> list[str]:
    """A line saying the set was made by an older recipe, and how to rebuild it."""
    made = card["info"].get("generator_version")
    if made is None or made == GENERATOR_VERSION:
        return []
    return [
        f"{'OUT OF DATE':>16}: made by recipe version {made}, this is {GENERATOR_VERSION}: "
        f"rebuild with {generate_command(card['id'])}"
    ]


def _d4rl_lines(card: dict[str, Any]) -> list[str]:
    """The card's lines on D4RL's figures for the same tier."""
    cmp = d4rl_comparison(card)
    if cmp is None:
        return []
    ref = cmp["d4rl"]

    def num(x: float | None, fmt: str = ".1f") -> str:
        return "-" if x is None else format(x, fmt)

    lines = [
        f"{'D4RL':>16}: {ref.name}: {num(ref.transitions, ',d')} transitions, "
        f"{num(ref.episodes, ',d')} episodes (mean length {num(ref.mean_length, '.0f')}); "
        f"normalised {num(ref.mean)} ± {num(ref.std)} [{num(ref.min)}, {num(ref.max)}]"
    ]
    verdict = {True: "inside the band", False: "OUTSIDE the band", None: "no band"}
    lines.append(f"{'beside D4RL':>16}: {verdict[cmp['in_band']]}: {cmp['why']}")
    for key in ref.source:
        lines.append(f"{'source':>16}: {SOURCES[key]}")
    return lines


def plot_return_histograms(
    ids: Sequence[str], bins: int = 30, ax: Any = None, normalized: bool = False
) -> Any:
    """Histogram of episode returns, one colour per data set (tier).

    Args:
        ids: data-set ids (e.g. the five tiers of one task).
        bins: histogram bins.
        ax: a matplotlib Axes, or ``None`` for a new figure.
        normalized: plot D4RL-normalised scores instead of raw returns.

    Returns:
        The matplotlib Axes.
    """
    import matplotlib.pyplot as plt

    if ax is None:
        _, ax = plt.subplots(figsize=(6, 3.5))
    for i in ids:
        d = load(i)
        r = d.normalized_scores() if normalized else d.returns
        if r is None:
            r = d.returns
        ax.hist(r, bins=bins, alpha=0.5, label=i.split("/")[-1])
    ax.set_xlabel("D4RL-normalised score" if normalized else "episode return")
    ax.set_ylabel("episodes")
    ax.legend()
    return ax


def expert_quality() -> Any:
    """Shipped expert and medium policies against the quality targets, as a DataFrame.

    Columns: ``task, algorithm, steps_trained, expert_return, expert_normalized, target,
    target_on`` (``normalized`` or ``return``), ``meets_target, shortfall`` (in the
    target's unit), ``medium_source`` (``medium run`` where a separate one ships,
    :func:`~thesis_lib.data.experts.has_medium_run`, else ``expert run``: the policy the medium
    tiers are made from), ``medium_return, medium_normalized`` (deterministic),
    ``medium_sampled_normalized`` (its own Gaussian, as the medium tier samples it; a medium run
    records it), ``medium_in_range`` (of the sampled figure where recorded, else the
    deterministic one), ``n_eval_episodes`` and, for the Maze2D rows (target =
    success rate 0.9), ``success_rate``, ``random_return`` and ``random_normalized``: uniform
    random actions in this project's maze (:func:`random_returns`), where D4RL's normalisation
    puts its own maze's random policy at 0. Here the planner scores 150-520 normalised and random
    actions -4 to 11 (the PointMaze is not D4RL's maze2d), so the Maze2D scores compare the
    models of this project with each other, not with D4RL's tables.
    """
    import pandas as pd

    rows = []
    for task, target in QUALITY_TARGETS.items():
        if not has_policies(task):
            rows.append({"task": task, "target": target, "meets_target": False})
            continue
        rec = load_policy_record(task)
        med = load_policy_record(task, role="medium")
        mn = med.medium_normalized
        # the tier's figure: sampled, as the medium tier rolls its policy out, where recorded
        tier_mn = med.medium_sampled_normalized if med.medium_sampled_normalized is not None else mn
        en = rec.expert_normalized
        score = en if en is not None else rec.expert_return_mean
        rows.append(
            {
                "task": task,
                "algorithm": rec.algorithm_name,
                "steps_trained": rec.steps_trained,
                "expert_return": rec.expert_return_mean,
                "expert_normalized": en,
                "target": target,
                "target_on": "normalized" if en is not None else "return",
                "meets_target": score >= target,
                "shortfall": max(0.0, target - score),
                "medium_source": "medium run" if has_medium_run(task) else "expert run",
                "medium_return": med.medium_return_mean,
                "medium_normalized": mn,
                "medium_sampled_normalized": med.medium_sampled_normalized,
                "medium_in_range": None
                if tier_mn is None
                else MEDIUM_NORMALIZED_RANGE[0] <= tier_mn <= MEDIUM_NORMALIZED_RANGE[1],
                "n_eval_episodes": rec.n_eval_episodes,
            }
        )
    for task, m in _maze_records().items():
        rows.append(
            {
                "task": task,
                "algorithm": "planner",  # BFS waypoints + PD, with its action noise
                "expert_return": m["return_mean"],
                "expert_normalized": normalized_score(task, m["return_mean"], missing="none"),
                "target": MAZE_SUCCESS_TARGET,
                "meets_target": m["success_rate"] >= MAZE_SUCCESS_TARGET,
                "success_rate": m["success_rate"],
                "n_eval_episodes": m["n_episodes"],
                "random_return": m.get("random_return_mean"),
                "random_normalized": m.get("random_normalized"),
            }
        )
    df = pd.DataFrame(rows)
    for col in ("steps_trained", "n_eval_episodes"):
        if col in df:
            df[col] = df[col].astype("Int64")
    return df


RECIPE = """\
Data sets are made here by D4RL's recipe (Fu et al. 2020) and stored in the Minari format
(HDF5), ids `thesis/<task>/<tier>-v0`:

- **expert** / **medium**: the shipped policies, trained here. Walker2d and HalfCheetah:
  TQC (Kuznetsov et al. 2020; SAC's distributional successor, D4RL used SAC) with 256x256
  MLPs, `thesis data train-expert --task walker2d`, exported to NumPy. Ant: CrossQ (Bhatt et
  al. 2024; SAC without target networks, batch-renormalised), a 256x256 actor with its
  normalisation folded in at export, `thesis data train-expert --task ant`. Hopper and
  InvertedDoublePendulum experts: ARS linear policies (sb3-contrib, observation
  normalisation), `thesis data train-experts`. Experts act deterministically; episodes differ
  through the environments' reset noise. **Medium**: Hopper (SAC), Walker2d and HalfCheetah
  (TQC) have a medium run of their own (`thesis data train-expert --task <task> --medium`),
  shipped at the snapshot whose *sampled* return is nearest D4RL's published medium mean;
  Ant and InvertedDoublePendulum take a snapshot of the expert's run at about a third of
  its return. The medium policy is sampled (its own Gaussian; ARS's weight noise), as D4RL
  sampled its SAC medium policies, so that the returns spread.
- **medium-replay**: the experience of training up to medium. Deep runs: the run's uniform-random
  warm-up steps, then its snapshots up to medium, each sampling from its own Gaussian, for as
  many transitions as the training steps it stands for. ARS: the zero policy and every
  checkpoint up to medium, each with ARS's ± weight perturbations, in training order.
- **medium-expert**: the medium set's episodes then the expert set's (twice the size, as
  D4RL); each tier has its own seed, so the halves start from independent states.
- **random**: uniform random actions.
- **Maze2D** (PointMaze umaze/medium/large/open): BFS over the maze cells + PD waypoint
  controller + N(0, 0.5) action noise, driven to random goals one after another as D4RL's
  recorder was; the sparse rewards count D4RL's fixed evaluation target of the layout (its
  `G` cell, reached within 0.5), the target every evaluation scores against.
- Beside D4RL: a set is inside the band when its normalised mean is within 10 points of
  D4RL's and its std at least half of D4RL's, judged on 100 episodes or more (a smaller set's
  line names the size that holds them): part of D4RL's spread is rare failed episodes.
- Deviation from the thesis: its locomotion sets were D4RL's PyBullet ones; these are MuJoCo
  v5 (gymnasium), as D4RL's MuJoCo sets.
"""


SHORTFALL_NOTES = """\
Where a target is missed (see `shortfall`): linear ARS reached D4RL's expert level on Hopper
only (the ARS paper needs 10-75M steps for Walker2d and Ant). The TQC / CrossQ recipe
(`thesis data train-expert --task walker2d`, 0.6-3 CPU-hours per task here) trains in the
background, checkpoints itself and resumes where it stopped; a task still showing ARS has
not been shipped from it yet. A weak expert also squeezes the medium tier: its target is
raised to 25 D4RL-normalised, which can bring it close to the expert's return.

Maze2D's rows set the planner beside uniform random actions (`random_return`,
`random_normalized`) in this project's maze, Gymnasium-Robotics' PointMaze with D4RL's fixed
target. D4RL's references were measured in D4RL's own maze2d: here its scale puts the planner
at 150-520 and random actions at -4 to 11, not at 100 and 0. Normalised Maze2D scores compare
this project's models with each other, not with D4RL's tables.
"""


def render_markdown() -> str:
    """The data card of the shipped policies and feasibility notes, as Markdown."""
    q = expert_quality()
    lines = ["# Data card: thesis_lib.data", "", RECIPE, "## Shipped experts vs targets", ""]
    if _has_tabulate():
        lines.append(q.to_markdown(index=False))
    else:
        lines.append("```\n" + q.to_string(index=False) + "\n```")
    lines += ["", SHORTFALL_NOTES]
    lines += ["", "## AntMaze, Adroit, FrankaKitchen", ""]
    lines += [f"- **{k}**: {v}" for k, v in FEASIBILITY.items()]
    return "\n".join(lines) + "\n"


def _has_tabulate() -> bool:
    try:
        import tabulate  # noqa: F401
    except ImportError:
        return False
    return True


def check_environments(n_steps: int = 50, tasks: Sequence[str] | None = None) -> Any:
    """Make and roll out (random actions) each task's environment; one row per task.

    Columns: ``task, env_id, ok, steps, error``. Used to record what loads with the
    installed mujoco (FrankaKitchen and Fetch need mujoco < 3.12).
    """
    import pandas as pd

    rows = []
    for t in tasks or list(TASKS):
        spec = get_task(t)
        try:
            env = make_env(t)
            env.reset(seed=0)
            env.action_space.seed(0)
            n = 0
            for _ in range(n_steps):
                _, _, term, trunc, _ = env.step(env.action_space.sample())
                n += 1
                if term or trunc:
                    env.reset()
            env.close()
            rows.append({"task": t, "env_id": spec.env_id, "ok": True, "steps": n, "error": ""})
        except Exception as e:
            rows.append(
                {"task": t, "env_id": spec.env_id, "ok": False, "steps": 0, "error": repr(e)}
            )
    return pd.DataFrame(rows)


@overload
def maze_success_rate(
    task: str, n_episodes: int = ..., seed: int = ..., return_returns: Literal[False] = ...
) -> float: ...
@overload
def maze_success_rate(
    task: str, n_episodes: int = ..., seed: int = ..., *, return_returns: Literal[True]
) -> tuple[float, np.ndarray]: ...
def maze_success_rate(
    task: str, n_episodes: int = 100, seed: int = 0, return_returns: bool = False
) -> float | tuple[float, np.ndarray]:
    """Share of episodes in which the scripted Maze2D expert (with its noise) reaches the goal.

    Args:
        task: ``maze2d-umaze`` … ``maze2d-open``.
        n_episodes: episodes (random start and goal each).
        seed: seed of the resets and the action noise.
        return_returns: also return the ``(n_episodes,)`` episode returns.
    """
    env = make_env(task)
    ex = WaypointExpert(noise_std=action_noise_for(task))
    rng = np.random.default_rng(seed)
    hits = 0
    rets = np.zeros(n_episodes)
    for i in range(n_episodes):
        obs, _ = env.reset(seed=int(rng.integers(2**31 - 1)))
        ex.reset(env)
        done, ok = False, False
        while not done:
            obs, r, term, trunc, info = env.step(ex(obs, rng))
            rets[i] += float(r)
            ok = ok or bool(info.get("success", False))
            done = term or trunc
        hits += ok
    env.close()
    return (hits / n_episodes, rets) if return_returns else hits / n_episodes


def _maze_records() -> dict[str, dict[str, Any]]:
    """``policies/maze2d.json`` (:func:`record_maze_experts`), ``{}`` where it is not shipped."""
    path = experts.POLICY_DIR / "maze2d.json"
    return json.loads(path.read_text()) if path.exists() else {}


def maze_reference(task: str) -> dict[str, Any] | None:
    """The shipped Maze2D record of ``task`` (``policies/maze2d.json``, written by
    :func:`record_maze_experts`): the planner's and uniform random actions' returns in this
    project's maze; ``None`` where none is recorded."""
    return _maze_records().get(task)


def random_returns(task: str, n_episodes: int = 100, seed: int = 0) -> np.ndarray:
    """Episode returns of uniform random actions in ``task``'s environment, as evaluated here.

    D4RL's normalisation puts its random policy at 0 (``ref_min_score``), measured in D4RL's
    environments. Where an environment here differs (Gymnasium-Robotics' PointMaze against
    D4RL's maze2d), this is the random score in the environment the models are evaluated in,
    to set beside that reference (the Maze2D rows of :func:`expert_quality`).

    Args:
        task: a task of :data:`~thesis_lib.data.TASKS`.
        n_episodes: episodes, each to its end (termination or the task's step limit).
        seed: seed of the resets and the actions.

    Returns:
        ``(n_episodes,)`` episode returns.
    """
    if n_episodes < 1:
        raise ValueError(f"Expect n_episodes >= 1, actually: {n_episodes}.")
    env = make_env(task)
    # the random tier's roll-out; no episode is cut, since none outlasts the step limit
    cap = n_episodes * get_task(task).max_episode_steps
    eps = rollout(
        env, _random_policy(env), cap, np.random.default_rng(seed), max_episodes=n_episodes
    )
    env.close()
    return np.array([float(e.rewards.sum()) for e in eps])


def record_maze_experts(n_episodes: int = 100, seed: int = 0, out_dir: Any = None) -> dict:
    """Measure the scripted expert, and uniform random actions, on every Maze2D layout; write
    ``policies/maze2d.json``.

    Returns:
        ``{task: {success_rate, return_mean, return_std, normalized, action_noise,
        n_episodes, seed, random_return_mean, random_normalized}}`` (the ``random_`` pair:
        :func:`random_returns` over the same number of episodes and seed).
    """
    out: dict[str, Any] = {}
    for task, spec in TASKS.items():
        if spec.kind != "maze":
            continue
        sr, rets = maze_success_rate(task, n_episodes, seed, return_returns=True)
        rand = float(random_returns(task, n_episodes, seed).mean())
        out[task] = {
            "success_rate": sr,
            "return_mean": round(float(rets.mean()), 2),
            "return_std": round(float(rets.std()), 2),
            "normalized": normalized_score(task, float(rets.mean()), missing="none"),
            "action_noise": action_noise_for(task),
            "n_episodes": n_episodes,
            "seed": seed,
            "random_return_mean": round(rand, 2),
            "random_normalized": normalized_score(task, rand, missing="none"),
        }
    path = Path(out_dir) if out_dir is not None else experts.POLICY_DIR
    path.mkdir(parents=True, exist_ok=True)
    (path / "maze2d.json").write_text(json.dumps(out, indent=1) + "\n")
    return out
