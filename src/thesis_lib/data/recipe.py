"""Make data sets by D4RL's recipe and store them in the Minari format.

Tiers (D4RL, Fu et al. 2020):

- ``expert``: the shipped expert policy (deterministic actions plus Gaussian action noise
  of :func:`action_noise_for`, which is 0 for the MuJoCo tasks: the reset noise alone
  makes the episodes differ).
- ``medium``: the task's medium run where one is shipped (``policies/<task>-medium``:
  Hopper's SAC, Walker2d's and HalfCheetah's TQC, each at the snapshot whose sampled return
  is nearest D4RL's published medium mean), else a policy of the expert's training run at
  about one third of the expert's return; sampled as D4RL sampled its SAC medium policy, so
  that the returns spread: a TQC/SAC actor draws its actions from its own Gaussian; an ARS
  linear policy (InvertedDoublePendulum) gets ARS's own exploration, new weight noise each
  episode.
- ``medium-replay``: the experience of training up to medium. For the deep runs
  (the medium runs, Ant's CrossQ): uniform random actions for the run's warm-up steps, then
  the shipped snapshots up to the medium one, each sampling from its own Gaussian (SAC's
  exploration), for as many transitions as the training steps it stands for. For the ARS
  experts (Hopper, InvertedDoublePendulum): the zero policy ARS starts from and every
  shipped checkpoint up to the medium one, each with ARS's own ± weight perturbations.
- ``medium-expert``: the ``medium`` and ``expert`` sets concatenated (each of the full
  requested size, as D4RL's 2M-transition sets), so its halves are exactly those sets.
- ``random``: uniform random actions.
- Maze2D ``expert``: the BFS + PD waypoint planner of :mod:`thesis_lib.data.maze` with
  action noise, driven to random goals one after another as D4RL's recorder was; the rewards
  count the layout's fixed evaluation target (D4RL's maze2d); ``random``: uniform random actions.

A set's id carries its size (:func:`~thesis_lib.data.tasks.size_namespace`): the smoke size
(20k transitions) is ``thesis/<task>/<tier>-v0``, the full one (1M) ``thesis-1m/<task>/<tier>-v0``,
any other ``thesis-<n>/...``; sizes never overwrite each other.

Each tier draws from its own ``np.random.default_rng`` seeded by ``(seed, tier)``, so the
same seed gives the same arrays, byte for byte, and no two tiers share initial states (as
D4RL collected them independently). :data:`GENERATOR_VERSION` and the fingerprint of the
shipped policy a set is made from are stored with every set; a cached set of another version,
or made by another expert than the one shipped now, is made again.

Used by HDT 5.2, Decision Mamba 5.3 and DEFENDER 4.3 (InvertedDoublePendulum).
"""

from __future__ import annotations

import time
import warnings
from collections.abc import Callable
from dataclasses import replace
from typing import Any, Literal

import numpy as np

from . import experts  # its functions looked up per call, so a swapped one is seen
from .envs import make_env
from .maze import D4RL_TARGET_CELLS, WaypointExpert
from .robotics import forget_maze_xml, register_robotics
from .storage import (
    DamagedDatasetError,
    Episode,
    OfflineDataset,
    find_dataset,
    load,
    write_dataset,
)
from .tasks import SMOKE_TRANSITIONS, TaskSpec, check_tier, gen_dataset_id, get_task

DatasetSize = Literal["smoke", "full"]

#: version of the recipe, stored in each set's ``thesis_info``. 2: TQC experts for
#: Walker2d/HalfCheetah/Ant, one seed per tier (medium-expert's halves independent).
#: 3: the medium tier samples its policy's own exploration (D4RL's medium sets were sampled
#: from SAC's Gaussian: the returns spread); Maze2D scores D4RL's fixed target and its
#: expert visits random goals; the size is part of the id (:func:`size_namespace`).
#: 4: hopper's medium and medium-replay tiers (and the medium half of medium-expert) come from
#: its SAC medium run at D4RL's level (``policies/hopper-medium``, issue #34), not from ARS.
#: A shipped policy that changes what a tier is made from is caught by its fingerprint (a cached
#: set made by another policy is made again); it moves this version only where a parity
#: comparison reads that set (hopper/medium), since the version is the data recipe that a parity
#: run's key carries (:mod:`thesis_lib.parity`). Halfcheetah's medium run (shipped later, its
#: medium, medium-replay and medium-expert sets remade) left it at 4.
GENERATOR_VERSION = 4

#: order of the tiers in the per-tier seed (never reorder: it would change every set).
_TIER_INDEX = {"expert": 0, "medium": 1, "medium-replay": 2, "medium-expert": 3, "random": 4}


def tier_seed(seed: int, tier: str) -> int:
    """The seed of one tier's generator, derived from the data-set seed and the tier.

    >>> tier_seed(0, "medium") != tier_seed(0, "expert")
    True
    """
    ss = np.random.SeedSequence([int(seed), _TIER_INDEX[tier]])
    return int(ss.generate_state(1)[0])


#: transitions per data set by size (D4RL's full size is 1M; medium-expert doubles).
DATASET_SIZES: dict[str, int] = {"smoke": SMOKE_TRANSITIONS, "full": 1_000_000}

#: default action-noise std per task kind. Maze: D4RL's maze2d used a noisy planner.
#: MuJoCo: 0, because the linear ARS policies are brittle (measured on 30k transitions:
#: std 0.01 costs Hopper 5% and InvertedDoublePendulum 6% of the return, std 0.1 costs
#: Hopper 35%); episodes still differ through the environments' reset noise.
DEFAULT_NOISE: dict[str, float] = {"mujoco": 0.0, "maze": 0.5, "robotics": 0.0}
#: per-task overrides where the kind's default breaks the policy (measured, see the card).
TASK_NOISE: dict[str, float] = {}


def action_noise_for(task: str) -> float:
    """Default action-noise std of ``task``'s expert/medium tiers."""
    return TASK_NOISE.get(task, DEFAULT_NOISE[get_task(task).kind])


#: the old name, kept for ``tests/fixtures/make_minari_fixtures.py``
_register_robotics = register_robotics

Policy = Callable[[Any, np.random.Generator], np.ndarray]


def rollout(
    env: object,
    policy: Policy,
    n_transitions: int,
    rng: np.random.Generator,
    on_reset: Callable[[object], None] | None = None,
    first_id: int = 0,
    max_episodes: int | None = None,
) -> list[Episode]:
    """Roll ``policy`` out until ``n_transitions`` actions are collected.

    The last episode is cut at exactly ``n_transitions`` (its last step marked truncated),
    as D4RL cut its data sets at 1M steps. Each episode resets with a seed drawn from
    ``rng``; the policy draws its noise from ``rng`` too.

    Args:
        env: a Gymnasium environment.
        policy: ``policy(obs, rng) -> action``.
        n_transitions: actions to collect.
        rng: the only source of randomness.
        on_reset: called with ``env`` after each reset (the maze expert reads the goal).
        first_id: id of the first episode.
        max_episodes: stop after this many episodes even if short of ``n_transitions``.

    Returns:
        The episodes; their lengths sum to ``n_transitions`` (unless ``max_episodes`` hit).
    """
    episodes: list[Episode] = []
    total = 0
    while total < n_transitions and (max_episodes is None or len(episodes) < max_episodes):
        obs, _ = env.reset(seed=int(rng.integers(2**31 - 1)))  # type: ignore[attr-defined]
        if on_reset is not None:
            on_reset(env)
        obs_l: list[Any] = []
        dg_l: list[Any] = []
        ag_l: list[Any] = []
        act_l, rew_l, term_l, trunc_l = [], [], [], []

        def keep(o: object, obs_l=obs_l, dg_l=dg_l, ag_l=ag_l) -> None:
            if isinstance(o, dict):
                obs_l.append(o["observation"])
                dg_l.append(o["desired_goal"])
                ag_l.append(o["achieved_goal"])
            else:
                obs_l.append(o)

        keep(obs)
        done = False
        while not done:
            a = np.asarray(policy(obs, rng), dtype=np.float32)
            obs, r, term, trunc, _ = env.step(a)  # type: ignore[attr-defined]
            keep(obs)
            act_l.append(a)
            rew_l.append(r)
            term_l.append(term)
            total += 1
            cut = total >= n_transitions
            trunc_l.append(bool(trunc) or (cut and not term))
            done = term or trunc or cut
        goals = bool(dg_l)
        episodes.append(
            Episode(
                id=first_id + len(episodes),
                observations=np.asarray(obs_l, dtype=np.float64),
                actions=np.asarray(act_l, dtype=np.float32),
                rewards=np.asarray(rew_l, dtype=np.float64),
                terminations=np.asarray(term_l, dtype=bool),
                truncations=np.asarray(trunc_l, dtype=bool),
                desired_goals=np.asarray(dg_l, dtype=np.float64) if goals else None,
                achieved_goals=np.asarray(ag_l, dtype=np.float64) if goals else None,
            )
        )
    return episodes


def _random_policy(env: object) -> Policy:
    space = env.action_space  # type: ignore[attr-defined]
    low, high = space.low.astype(np.float64), space.high.astype(np.float64)
    return lambda obs, rng: rng.uniform(low, high)


def _noisy(pol: Callable[[np.ndarray], np.ndarray], std: float, low, high) -> Policy:
    def act(obs: object, rng: np.random.Generator) -> np.ndarray:
        a = pol(obs)  # type: ignore[arg-type]
        if std > 0:
            a = a + std * rng.standard_normal(a.shape)
        return np.clip(a, low, high)

    return act


class _EpisodePerturbed:
    """A linear policy whose weights are perturbed anew each episode (ARS's exploration: each
    roll-out of ARS's training uses ``W ± std·δ``); the draw comes from the roll-out's ``rng``
    at the episode's first step."""

    def __init__(self, base: Any, std: float):
        self.base, self.std = base, std
        self._current: Any = None

    def reset(self, env: object) -> None:
        self._current = None

    def __call__(self, obs: Any, rng: np.random.Generator) -> np.ndarray:
        if self._current is None:
            self._current = self.base.perturbed(rng, self.std)
        return self._current(obs)


def _renumber(episodes: list[Episode]) -> list[Episode]:
    return [replace(e, id=i) for i, e in enumerate(episodes)]


def make_episodes(
    task: str,
    tier: str,
    n_transitions: int,
    seed: int = 0,
    action_noise: float | None = None,
) -> tuple[list[Episode], dict]:
    """Roll out the episodes of one tier (no storage).

    Args:
        task: task name (see :data:`thesis_lib.data.tasks.TASKS`).
        tier: one of the task's tiers.
        n_transitions: actions per data set (``medium-expert``: twice this).
        seed: seed of the whole roll-out.
        action_noise: Gaussian action-noise std; :func:`action_noise_for` when ``None``.

    Returns:
        ``(episodes, info)``, ``info`` a JSON-able record of how they were made.
    """
    spec: TaskSpec = get_task(task)
    check_tier(task, tier)
    _check_n_transitions(n_transitions)
    noise = action_noise_for(task) if action_noise is None else float(action_noise)
    info: dict = {
        "task": task,
        "tier": tier,
        "env_id": spec.env_id,
        "seed": seed,
        "n_transitions": n_transitions,
        "action_noise": noise,
        "generator_version": GENERATOR_VERSION,
        "policy_fingerprint": _policy_fingerprint(task, tier),
    }
    env = make_env(task)
    low = env.action_space.low.astype(np.float64)
    high = env.action_space.high.astype(np.float64)
    rng = np.random.default_rng(tier_seed(seed, tier))
    if tier == "random":
        info["algorithm"] = "uniform random actions"
        info["action_noise"] = 0.0
        eps = rollout(env, _random_policy(env), n_transitions, rng)
    elif spec.kind == "maze":
        ex = WaypointExpert(noise_std=noise, random_goals=True, rng=rng)
        info["algorithm"] = (
            f"BFS waypoints + PD (p={ex.p_gain}, d={ex.d_gain}) + N(0, {noise}) action noise, "
            "driven to random goals one after another (D4RL's maze2d recorder); rewards count "
            "the layout's fixed target"
        )
        info["target_cell"] = list(D4RL_TARGET_CELLS[spec.env_id])
        eps = rollout(env, ex, n_transitions, rng, on_reset=ex.reset)
    elif tier == "medium-expert":
        env.close()
        med, _ = make_episodes(task, "medium", n_transitions, seed, action_noise)
        exp, _ = make_episodes(task, "expert", n_transitions, seed, action_noise)
        info["algorithm"] = "the medium set's episodes, then the expert set's"
        return _renumber(med + exp), info
    else:
        load_policy = experts.load_policy
        rec = experts.load_policy_record(
            task, "medium" if tier in ("medium", "medium-replay") else "expert"
        )
        info["policy"] = {
            "role": rec.role,
            "algorithm": rec.algorithm,
            "steps_trained": rec.steps_trained,
            "seed": rec.config.get("seed"),
            "expert_return_mean": rec.expert_return_mean,
            "medium_return_mean": rec.medium_return_mean,
        }
        kind = "ARS linear" if rec.policy_kind == "linear" else rec.algorithm.split(",")[0]
        if tier == "expert":
            pol = load_policy(task, tier)
            info["algorithm"] = f"{kind} {tier} policy + N(0, {noise}) action noise"
            eps = rollout(env, _noisy(pol, noise, low, high), n_transitions, rng)
        elif tier == "medium" and rec.policy_kind == "mlp":
            pol = load_policy(task, tier)
            info["action_noise"] = 0.0  # the actor's own Gaussian is the noise
            info["algorithm"] = f"{kind} medium policy, actions sampled from its Gaussian"
            eps = rollout(env, pol.sample, n_transitions, rng)
        elif tier == "medium":
            std = float(rec.config["delta_std"])
            sampler = _EpisodePerturbed(load_policy(task, tier), std)
            info["action_noise"] = 0.0  # ARS explores in weight space, not action space
            info["algorithm"] = (
                f"ARS linear medium policy, its weights perturbed by N(0, {std}) per episode "
                "(ARS's own exploration)"
            )
            eps = rollout(env, sampler, n_transitions, rng, on_reset=sampler.reset)
        elif tier == "medium-replay" and rec.policy_kind == "mlp":
            info["action_noise"] = 0.0  # the actor's own Gaussian is the exploration
            eps = _mlp_replay(task, env, rec, n_transitions, rng, info)
        elif tier == "medium-replay":
            std = float(rec.config["delta_std"])
            n_ck = rec.medium_checkpoint + 1
            pols = [load_policy(task, f"ckpt{i}") for i in range(n_ck)]
            zero = pols[0].__class__(
                np.zeros_like(pols[0].weights), pols[0].obs_mean, pols[0].obs_var, low, high
            )
            pols = [zero] + pols
            info["action_noise"] = 0.0  # ARS explores in weight space, not action space
            info["algorithm"] = (
                f"ARS training replay: zero policy + checkpoints 0..{n_ck - 1}, each with "
                f"±{std} weight perturbations"
            )
            share = np.full(len(pols), n_transitions // len(pols))
            share[: n_transitions - share.sum()] += 1
            eps = []
            for pol, n in zip(pols, share):
                got = 0
                while got < n:
                    d = std * rng.standard_normal(pol.weights.shape)
                    for sign in (1.0, -1.0):
                        if got >= n:
                            break
                        cand = pol.__class__(
                            pol.weights + sign * d, pol.obs_mean, pol.obs_var, low, high
                        )
                        e = rollout(
                            env,
                            _noisy(cand, 0.0, low, high),
                            int(n - got),
                            rng,
                            first_id=len(eps),
                            max_episodes=1,
                        )
                        got += len(e[0])
                        eps += e
        else:  # pragma: no cover - check_tier guards this
            raise ValueError(tier)
    env.close()
    return eps, info


def _mlp_replay(
    task: str, env: object, rec: object, n_transitions: int, rng: np.random.Generator, info: dict
) -> list[Episode]:
    """medium-replay for a TQC/SAC run: warm-up random actions, then the snapshots sampled."""
    steps = list(rec.checkpoint_steps)  # type: ignore[attr-defined]
    warm = int(rec.config.get("learning_starts", 0))  # type: ignore[attr-defined]
    edges = [0, min(warm, steps[0]), *steps]
    seg = np.diff(edges).astype(float)
    share = np.floor(n_transitions * seg / seg.sum()).astype(int)
    share[-1] += n_transitions - share.sum()
    pols: list[Policy] = [_random_policy(env)]
    for i in range(len(steps)):
        p = experts.load_policy(task, f"ckpt{i}")
        pols.append(p.sample)
    info["algorithm"] = (
        f"training replay: {warm} warm-up steps of uniform random actions, then snapshots "
        f"at steps {steps} sampling from the actor's Gaussian, {share.tolist()} transitions each"
    )
    eps: list[Episode] = []
    for pol, n in zip(pols, share):
        if n > 0:
            eps += rollout(env, pol, int(n), rng, first_id=len(eps))
    return eps


def _size(size: str, n_transitions: Any) -> int:
    """The number of transitions of ``size`` (``smoke``/``full``), or ``n_transitions`` checked."""
    if n_transitions is not None:
        return _check_n_transitions(n_transitions)
    if size not in DATASET_SIZES:
        raise ValueError(f"Unknown size {size!r}. Valid: {', '.join(DATASET_SIZES)}.")
    return DATASET_SIZES[size]


def _check_n_transitions(n: Any) -> int:
    """``n`` as an int, or a ``ValueError`` naming ``n_transitions`` unless it is a whole number ≥ 1
    (``20000.0`` from a YAML ``2e4`` passes)."""
    try:
        ok = not isinstance(n, bool) and int(n) == n and n >= 1
    except (TypeError, ValueError, OverflowError):
        ok = False
    if not ok:
        raise ValueError(f"Expect `n_transitions` to be a whole number ≥ 1, actually: {n!r}.")
    return int(n)


def generate(
    task: str,
    tier: str,
    n_transitions: int | None = None,
    size: DatasetSize = "smoke",
    seed: int = 0,
    action_noise: float | None = None,
    overwrite: bool = True,
) -> str:
    """Make one data set and store it as ``<size namespace>/<task>/<tier>-v0``
    (:func:`~thesis_lib.data.tasks.size_namespace`: ``thesis/`` at the smoke size).

    Args:
        task: e.g. ``"hopper"``, ``"maze2d-umaze"``.
        tier: ``expert``, ``medium``, ``medium-replay``, ``medium-expert``, ``random``.
        n_transitions: size; ``DATASET_SIZES[size]`` when ``None``.
        size: ``smoke`` (20k transitions) or ``full`` (D4RL's 1M); not a chapter profile.
        seed: roll-out seed; same seed, same arrays.
        action_noise: action-noise std; per-kind default when ``None``.
        overwrite: replace an existing set.

    Returns:
        The data-set id.

    Raises:
        ValueError: unknown task or tier (lists the valid ones), or ``n_transitions < 1``.
            An existing set is replaced only once the new one is written whole.
    """
    spec = get_task(task)
    n = _size(size, n_transitions)
    dataset_id = gen_dataset_id(task, tier, n_transitions=n)
    t0 = time.time()
    eps, info = make_episodes(task, tier, n, seed, action_noise)
    rets = np.array([e.episode_return for e in eps])
    info.update(
        size=size if n_transitions is None else "custom",
        rollout_s=round(time.time() - t0, 2),
        return_mean=float(rets.mean()),
        return_std=float(rets.std()),
    )
    env = make_env(task)
    write_dataset(
        dataset_id,
        eps,
        env.spec,
        spec.ref_min_score,
        spec.ref_max_score,
        description=f"{spec.env_id} {tier}: {info.get('algorithm', '')}",
        info=info,
        overwrite=overwrite,
    )
    env.close()
    return dataset_id


def _policy_fingerprint(task: str, tier: str) -> str | None:
    """The fingerprint of the shipped policy a set of ``task``/``tier`` is made from (``None``
    for the random tier and the Maze2D planner, which use no shipped policy)."""
    if tier == "random" or get_task(task).kind != "mujoco":
        return None
    return experts.policy_fingerprint(task)


def get_dataset(
    task: str,
    tier: str,
    size: DatasetSize = "smoke",
    seed: int = 0,
    n_transitions: int | None = None,
) -> OfflineDataset:
    """Load ``thesis/<task>/<tier>-v0``, generating it first if missing or of another
    size, seed, :data:`GENERATOR_VERSION` or shipped policy (a set made by an earlier expert
    is made again from the one shipped now: :func:`~thesis_lib.data.experts.policy_fingerprint`).

    This is what chapter notebooks call: on a fresh machine the data set is made on first
    use at the chosen scale and cached under :func:`thesis_lib.data.storage.data_dir`.
    A damaged cached set (unreadable HDF5 file or metadata) is made again, with a warning.

    Raises:
        ValueError: unknown task or tier, or ``n_transitions < 1``.
    """
    n = _size(size, n_transitions)
    dataset_id = gen_dataset_id(task, tier, n_transitions=n)
    if find_dataset(dataset_id) is not None:
        try:
            ds: OfflineDataset | None = load(dataset_id)
        except DamagedDatasetError as err:
            warnings.warn(
                f"Data set '{dataset_id}' is damaged ({err.__cause__}); making it again.",
                stacklevel=2,
            )
            ds = None
        ti = ds.metadata.get("thesis_info", {}) if ds is not None else None
        if (
            ds is not None
            and isinstance(ti, dict)
            and ti.get("n_transitions") == n
            and ti.get("seed") == seed
            and ti.get("generator_version") == GENERATOR_VERSION
            and ti.get("policy_fingerprint") == _policy_fingerprint(task, tier)
        ):
            return ds
    generate(task, tier, n_transitions=n, seed=seed)
    return load(dataset_id)


__all__ = [
    "GENERATOR_VERSION",
    "forget_maze_xml",
    "DATASET_SIZES",
    "generate",
    "get_dataset",
    "make_env",
    "make_episodes",
    "rollout",
    "tier_seed",
]
