"""Demonstrations for DEFENDER: what one is, how the authors made them, storing them (thesis 4.3).

A :class:`Demonstration` is one episode in Minari's naming (``observations`` has one more row
than ``actions`` and ``rewards``). Anything with those three attributes is accepted too
(Minari's ``EpisodeData``, ``thesis_lib.data`` episodes), as is a dict with those keys.

:func:`collect_demonstrations` makes them as the authors did: train SAC and, every
``every`` training episodes, roll out the current policy once; an episode that reaches the
horizon is *safe*, one that terminates earlier is *unsafe*. :func:`select_diverse` then keeps
a subset that is spread out under DTW (greedy farthest-point selection).
:func:`policy_demonstrations` / :func:`expert_demonstrations` make both groups from a fixed
policy instead (the experts shipped in :mod:`thesis_lib.data`), for a group a short SAC run
does not give. :func:`save_demonstrations` /
:func:`load_demonstrations` store them in one ``.npz``
(a documented, dependency-free layout; see :func:`save_demonstrations`);
:func:`save_demonstrations_minari` / :func:`load_demonstrations_minari` as two Minari data sets
(``thesis/defender-<task>/safe-v0`` and ``unsafe-v0``) with the data-set issue's storage.

Used in: DEFENDER (thesis 4.3).
"""

from __future__ import annotations

import json
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any, Literal, NamedTuple

import gymnasium as gym
import numpy as np

from thesis_lib import dtw as _dtw
from thesis_lib.data.experts import has_policies, load_policy, load_policy_record
from thesis_lib.data.storage import Episode, load, write_dataset
from thesis_lib.data.tasks import TASKS

__all__ = [
    "TRAJECTORIES",
    "DemoRun",
    "DemoSet",
    "Demonstration",
    "EpisodeRecorder",
    "as_demonstration",
    "collect_demonstrations",
    "expert_demonstrations",
    "load_demonstrations",
    "load_demonstrations_minari",
    "policy_demonstrations",
    "rollout",
    "save_demonstrations",
    "save_demonstrations_minari",
    "select_diverse",
    "shipped_expert_label",
    "trajectory_features",
]

Trajectory = Literal["state", "state_action"]
TRAJECTORIES: tuple[str, ...] = ("state", "state_action")
"""What the filter compares: the states visited, or state||action pairs (thesis 4.3.1)."""


class Demonstration(NamedTuple):
    """One demonstration episode (Minari's field names)."""

    observations: np.ndarray
    """(T+1, obs_dim): s_0 ... s_T, the last one the state the episode ended in."""
    actions: np.ndarray
    """(T, act_dim): a_t taken in s_t."""
    rewards: np.ndarray
    """(T,): r_t received for a_t."""
    terminated: bool
    """Ended by the task (an unsafe state) rather than by the horizon."""
    truncated: bool
    """Cut by the horizon (a safe demonstration)."""

    @property
    def length(self) -> int:
        """T, the number of steps."""
        return len(self.actions)


class DemoSet(NamedTuple):
    """Safe and unsafe demonstrations of one task, what :func:`collect_demonstrations` returns."""

    safe: list[Demonstration]
    """Episodes that reached the horizon."""
    unsafe: list[Demonstration]
    """Episodes that terminated before it."""
    env_id: str
    """The gymnasium task they come from."""


class DemoRun(NamedTuple):
    """What :func:`collect_demonstrations` returns."""

    demos: DemoSet
    """The diverse subset: ``n_safe`` safe and ``n_unsafe`` unsafe demonstrations."""
    pool: DemoSet
    """Every roll-out, before selection (draw other subset sizes from it, as for Table 4.5)."""
    episodes: list[Demonstration]
    """The SAC run's own training episodes (for the strategy ablation, thesis 4.3.2)."""
    result: Any
    """The SAC run's :class:`~thesis_lib.rl.TrainResult` (model, episode log, wall time)."""
    n_sac: dict[str, int] = {}
    """Per group ("safe", "unsafe"): how many of ``pool``'s demonstrations (its first ones) are SAC
    roll-outs; the rest came from a policy (:func:`policy_demonstrations`). Empty = all SAC."""

    def sources(self, demos: DemoSet | None = None) -> dict[str, tuple[int, int]]:
        """Per group: (from SAC roll-outs, from the policy) among ``demos`` (default: :attr:`demos`)."""
        demos = self.demos if demos is None else demos
        out = {}
        for group in ("safe", "unsafe"):
            pool = getattr(self.pool, group)
            policy_ids = {id(d) for d in pool[self.n_sac.get(group, len(pool)) :]}
            kept = getattr(demos, group)
            n_policy = sum(id(d) in policy_ids for d in kept)
            out[group] = (len(kept) - n_policy, n_policy)
        return out


def as_demonstration(item: Any, name: str = "demonstration") -> Demonstration:
    """Read a :class:`Demonstration`, an object with observations/actions/rewards, or such a dict."""
    if isinstance(item, Demonstration):
        return item
    get = item.get if isinstance(item, Mapping) else lambda k, d=None: getattr(item, k, d)
    obs, actions, rewards = get("observations"), get("actions"), get("rewards")
    if obs is None or actions is None or rewards is None:
        raise TypeError(
            f"{name} must be a Demonstration, or have 'observations', 'actions' and 'rewards' "
            f"(like a Minari EpisodeData), got {type(item).__name__}."
        )
    obs = np.asarray(obs, dtype=np.float64)
    actions = np.asarray(actions, dtype=np.float64)
    rewards = np.asarray(rewards, dtype=np.float64).reshape(-1)
    if (
        obs.ndim != 2
        or actions.ndim != 2
        or len(obs) != len(actions) + 1
        or len(rewards) != len(actions)
    ):
        raise ValueError(
            f"{name} needs observations (T+1, obs_dim), actions (T, act_dim) and rewards (T,), got "
            f"shapes {obs.shape}, {actions.shape} and {rewards.shape}."
        )
    if len(actions) == 0:
        raise ValueError(f"{name} is empty (0 steps); a demonstration needs at least one step.")
    term, trunc = get("terminations"), get("truncations")
    terminated = bool(np.asarray(term)[-1]) if term is not None else bool(get("terminated", False))
    truncated = bool(np.asarray(trunc)[-1]) if trunc is not None else bool(get("truncated", False))
    return Demonstration(obs, actions, rewards, terminated, truncated)


def trajectory_features(demo: Demonstration, trajectory: Trajectory = "state") -> np.ndarray:
    """The sequence the filter compares with: (T, obs_dim) states or (T, obs_dim + act_dim).

    The states are s_0 ... s_{T-1}, those an action was taken in, because the agent's trajectory
    is built the same way (the filter decides before each action; it never sees a final state).

    >>> d = Demonstration(np.zeros((3, 2)), np.ones((2, 1)), np.zeros(2), True, False)
    >>> trajectory_features(d).shape, trajectory_features(d, "state_action").shape
    ((2, 2), (2, 3))
    """
    if trajectory == "state":
        return demo.observations[:-1]
    if trajectory == "state_action":
        return np.concatenate([demo.observations[:-1], demo.actions], axis=1)
    raise ValueError(f"Unknown trajectory {trajectory!r}. Valid: {', '.join(TRAJECTORIES)}.")


class EpisodeRecorder(gym.Wrapper):
    """Records every finished episode (observations, actions, rewards, flags) as a Demonstration.

    Put it under the agent's env to log a training run for :func:`~thesis_lib.defender.ablation.strategy_ablation`.

    Used in: DEFENDER (thesis 4.3.2).
    """

    def __init__(self, env: gym.Env) -> None:
        super().__init__(env)
        self.episodes: list[Demonstration] = []
        self._obs: list[np.ndarray] = []
        self._act: list[np.ndarray] = []
        self._rew: list[float] = []

    def reset(self, **kwargs: Any) -> tuple[Any, dict]:
        obs, info = self.env.reset(**kwargs)
        self._obs, self._act, self._rew = [np.asarray(obs, dtype=np.float64)], [], []
        return obs, info

    def step(self, action: Any) -> tuple[Any, Any, bool, bool, dict]:
        obs, reward, terminated, truncated, info = self.env.step(action)
        self._obs.append(np.asarray(obs, dtype=np.float64))
        self._act.append(np.asarray(action, dtype=np.float64).reshape(-1))
        self._rew.append(float(reward))
        if terminated or truncated:
            self.episodes.append(
                Demonstration(
                    np.stack(self._obs),
                    np.stack(self._act),
                    np.asarray(self._rew),
                    bool(terminated),
                    bool(truncated and not terminated),
                )
            )
        return obs, reward, terminated, truncated, info


def rollout(
    model: Any, env: gym.Env, *, seed: int | None = None, deterministic: bool = True
) -> Demonstration:
    """Run one episode of ``model.predict`` in ``env`` and record it as a :class:`Demonstration`."""
    obs, _ = env.reset(seed=seed)
    observations, actions, rewards = [np.asarray(obs, dtype=np.float64)], [], []
    terminated = truncated = False
    while not (terminated or truncated):
        action, _ = model.predict(obs, deterministic=deterministic)
        obs, reward, terminated, truncated, _ = env.step(action)
        observations.append(np.asarray(obs, dtype=np.float64))
        actions.append(np.asarray(action, dtype=np.float64).reshape(-1))
        rewards.append(float(reward))
    return Demonstration(
        np.stack(observations),
        np.stack(actions),
        np.asarray(rewards),
        bool(terminated),
        bool(truncated and not terminated),
    )


def select_diverse(
    demos: Sequence[Demonstration],
    n: int,
    *,
    trajectory: Trajectory = "state",
    metric: _dtw.Metric = "l1",
) -> list[Demonstration]:
    """Keep ``n`` demonstrations spread out under DTW (greedy farthest-point selection).

    Starts from the longest one, then repeatedly adds the demonstration whose smallest DTW cost
    to those already kept is largest. All of them when there are at most ``n``.

    Used in: DEFENDER (thesis 4.3), as the authors picked their demonstration subset.
    """
    demos = list(demos)
    if n <= 0:
        raise ValueError(f"select_diverse needs n >= 1, got {n}.")
    if len(demos) <= n:
        return demos
    feats = [trajectory_features(d, trajectory) for d in demos]
    packed = _dtw.pack_references(feats)
    # Only distances from the chosen ones are needed: n x N DTWs, not the N x N matrix.
    chosen = [int(np.argmax([d.length for d in demos]))]
    nearest = _dtw.dtw_batch(feats[chosen[0]], packed, metric=metric)
    while len(chosen) < n:
        nearest[chosen] = -np.inf
        k = int(np.argmax(nearest))
        chosen.append(k)
        nearest = np.minimum(nearest, _dtw.dtw_batch(feats[k], packed, metric=metric))
    return [demos[k] for k in sorted(chosen)]


def collect_demonstrations(
    env_id: str,
    *,
    n_safe: int,
    n_unsafe: int,
    total_timesteps: int,
    every: int = 5,
    seed: int = 0,
    max_episode_steps: int | None = None,
    rl_overrides: Mapping[str, Any] | None = None,
    deterministic: bool = False,
    progress: bool = False,
    allow_missing: bool = False,
) -> DemoRun:
    """Make safe and unsafe demonstrations as the authors did: SAC roll-outs during training.

    Trains SAC (``thesis_lib.rl``) for ``total_timesteps`` steps; after every ``every``-th
    training episode the current policy runs one episode in a separate copy of the task.
    Roll-outs that reach the horizon are safe, those that terminate earlier unsafe. Finally
    :func:`select_diverse` keeps ``n_safe`` and ``n_unsafe`` of them.

    Args:
        env_id: gymnasium task, e.g. ``"InvertedDoublePendulum-v5"``.
        n_safe, n_unsafe: how many of each to keep.
        total_timesteps: SAC training steps.
        every: training episodes between two roll-outs (the authors: 50 in their code, 1 in the text).
        seed: training and roll-out seed.
        max_episode_steps: horizon (None = the task's, 1000 for MuJoCo).
        rl_overrides: further :class:`~thesis_lib.rl.RLConfig` fields (e.g. ``net_arch``).
        deterministic: roll out the policy's mean action (False: sample, as in training).
        allow_missing: return a group with no roll-outs empty instead of raising (the caller
            fills it, e.g. with :func:`expert_demonstrations`).

    Returns:
        :class:`DemoRun`: the selected demonstrations, every roll-out, the SAC run's training
        episodes (reused by the strategy ablation) and its ``TrainResult``.

    Raises:
        RuntimeError: if no safe or no unsafe roll-out was seen (train longer or lower the horizon).

    Used in: DEFENDER (thesis 4.3).
    """
    from stable_baselines3.common.callbacks import BaseCallback

    from thesis_lib.rl import RLConfig, config_from_params, train  # lazy: stable_baselines3

    make = (
        (lambda: gym.make(env_id, max_episode_steps=max_episode_steps))
        if max_episode_steps
        else (lambda: gym.make(env_id))
    )
    demo_env = make()
    demo_env.action_space.seed(seed)
    found: list[Demonstration] = []

    class _Roll(BaseCallback):
        def __init__(self) -> None:
            super().__init__()
            self.n_done = 0

        def _on_step(self) -> bool:
            for done in self.locals["dones"]:
                if done:
                    self.n_done += 1
                    if self.n_done % every == 0:
                        found.append(
                            rollout(
                                self.model,
                                demo_env,
                                seed=seed + 10_000 + len(found),
                                deterministic=deterministic,
                            )
                        )
            return True

    params = {
        "algo": "SAC",
        "env_id": None,
        "total_timesteps": int(total_timesteps),
        "seed": seed,
        **dict(rl_overrides or {}),
    }
    config: RLConfig = config_from_params(params)
    recorder = EpisodeRecorder(make())
    result = train(config, env=recorder, callbacks=[_Roll()], progress=progress)
    safe = [d for d in found if d.truncated]
    unsafe = [d for d in found if d.terminated]
    if (not safe or not unsafe) and not allow_missing:
        raise RuntimeError(
            f"collect_demonstrations saw {len(safe)} safe and {len(unsafe)} unsafe roll-outs of "
            f"{env_id} in {total_timesteps} steps ({len(found)} roll-outs); DEFENDER needs both. "
            "Train longer (total_timesteps), roll out more often (every), lower max_episode_steps, "
            "or fill the missing group with expert_demonstrations(...)."
        )
    demoset = DemoSet(
        select_diverse(safe, n_safe) if safe else [],
        select_diverse(unsafe, n_unsafe) if unsafe else [],
        env_id,
    )
    return DemoRun(
        demoset,
        DemoSet(safe, unsafe, env_id),
        recorder.episodes,
        result,
        {"safe": len(safe), "unsafe": len(unsafe)},
    )


def _policy_rollout(
    policy: Any,
    env: gym.Env,
    rng: np.random.Generator,
    *,
    seed: int,
    noise: float,
    switch_at: int | None,
    switch_noise: float,
) -> Demonstration:
    """One episode of ``policy(obs)`` with Gaussian action noise (std as a fraction of the half-range).

    From step ``switch_at`` on (if given) the noise std becomes ``switch_noise``.
    """
    space = env.action_space
    if not isinstance(space, gym.spaces.Box):
        raise TypeError(f"Expect a Box action space, got {space}.")
    low, high = space.low.astype(np.float64), space.high.astype(np.float64)
    half = (high - low) / 2
    obs, _ = env.reset(seed=seed)
    observations, actions, rewards = [np.asarray(obs, dtype=np.float64)], [], []
    terminated = truncated = False
    t = 0
    while not (terminated or truncated):
        std = switch_noise if switch_at is not None and t >= switch_at else noise
        action = np.asarray(policy(np.asarray(obs, dtype=np.float64)), dtype=np.float64).reshape(-1)
        if std > 0:
            action = action + std * half * rng.standard_normal(action.shape)
        action = np.clip(action, low, high)
        obs, reward, terminated, truncated, _ = env.step(action.astype(env.action_space.dtype))
        observations.append(np.asarray(obs, dtype=np.float64))
        actions.append(action)
        rewards.append(float(reward))
        t += 1
    return Demonstration(
        np.stack(observations),
        np.stack(actions),
        np.asarray(rewards),
        bool(terminated),
        bool(truncated and not terminated),
    )


def policy_demonstrations(
    env_id: str,
    policy: Any,
    *,
    n_safe: int,
    n_unsafe: int,
    seed: int = 0,
    max_episode_steps: int | None = None,
    safe_noise: float = 0.05,
    unsafe_noise: float = 1.0,
    max_tries: int = 20,
) -> DemoSet:
    """Safe and unsafe demonstrations from a fixed policy (an alternative to the authors' SAC roll-outs).

    *Safe*: the policy with small Gaussian action noise (``safe_noise`` x the action half-range,
    so the episodes differ); kept if it reaches the horizon. *Unsafe*: the same policy for a random
    number of steps (uniform in [0, horizon / 2)), then with heavy noise (``unsafe_noise``) until it
    falls; kept if it terminates before the horizon. So an unsafe demonstration starts like a safe
    one and then goes wrong, as a failing SAC roll-out does.

    Used where the thesis's recipe gives no roll-outs of a group in a short run, e.g. no SAC
    roll-out of InvertedDoublePendulum balances for the whole horizon after a few thousand steps
    (see :func:`expert_demonstrations` for the shipped experts).

    Args:
        env_id: gymnasium task.
        policy: callable ``obs (obs_dim,) -> action (act_dim,)``.
        n_safe, n_unsafe: how many of each to make (0 is allowed).
        seed: seeds the episodes' resets and the noise.
        max_episode_steps: horizon (None = the task's).
        safe_noise, unsafe_noise: action-noise std as a fraction of the action half-range.
        max_tries: attempts per wanted demonstration before giving up.

    Raises:
        RuntimeError: if the policy did not give enough episodes of a group in
            ``max_tries x n`` attempts (e.g. a policy too weak to reach the horizon).

    Used in: DEFENDER (thesis 4.3).
    """
    if n_safe < 0 or n_unsafe < 0:
        raise ValueError(
            f"policy_demonstrations needs n_safe, n_unsafe >= 0, got {n_safe}, {n_unsafe}."
        )
    env = (
        gym.make(env_id, max_episode_steps=max_episode_steps)
        if max_episode_steps
        else gym.make(env_id)
    )
    horizon = (
        env.spec.max_episode_steps if env.spec is not None and env.spec.max_episode_steps else 1000
    )
    rng = np.random.default_rng(seed)
    out: dict[str, list[Demonstration]] = {"safe": [], "unsafe": []}
    for group, n in (("safe", n_safe), ("unsafe", n_unsafe)):
        tries = 0
        while len(out[group]) < n:
            if tries >= max_tries * n:
                raise RuntimeError(
                    f"policy_demonstrations made only {len(out[group])} of {n} {group} demonstrations of "
                    f"{env_id} in {tries} attempts (horizon {horizon}); "
                    + (
                        "the policy does not reach the horizon: lower safe_noise or use a better policy."
                        if group == "safe"
                        else "the policy does not fall: raise unsafe_noise."
                    )
                )
            ep_seed = seed + 20_000 + 1_000 * (group == "unsafe") * max_tries + tries
            switch = None if group == "safe" else int(rng.integers(0, max(1, horizon // 2)))
            d = _policy_rollout(
                policy,
                env,
                rng,
                seed=ep_seed,
                noise=safe_noise,
                switch_at=switch,
                switch_noise=unsafe_noise,
            )
            tries += 1
            if (group == "safe" and d.truncated) or (group == "unsafe" and d.terminated):
                out[group].append(d)
    env.close()
    return DemoSet(out["safe"], out["unsafe"], env_id)


def expert_demonstrations(
    env_id: str,
    *,
    n_safe: int,
    n_unsafe: int,
    seed: int = 0,
    max_episode_steps: int | None = None,
    **kwargs: Any,
) -> DemoSet:
    """:func:`policy_demonstrations` with the expert shipped in :mod:`thesis_lib.data`.

    Experts ship for Hopper, Walker2d, HalfCheetah, Ant and InvertedDoublePendulum (v5): TQC or
    CrossQ MLPs, or linear ARS policies (:func:`shipped_expert_label` says which); their training
    records are in ``thesis_lib/data/policies/<task>.json``.

    Raises:
        ValueError: no shipped expert for ``env_id`` (the message lists the tasks that have one).

    Used in: DEFENDER (thesis 4.3).
    """
    return policy_demonstrations(
        env_id,
        load_policy(_expert_task(env_id), "expert"),
        n_safe=n_safe,
        n_unsafe=n_unsafe,
        seed=seed,
        max_episode_steps=max_episode_steps,
        **kwargs,
    )


def save_demonstrations(demoset: DemoSet, path: str | Path) -> Path:
    """Write a :class:`DemoSet` to one ``.npz``.

    Layout: for group g in (safe, unsafe) and episode i, arrays ``g/i/observations``,
    ``g/i/actions``, ``g/i/rewards``, ``g/i/flags`` ([terminated, truncated]); plus ``meta``,
    a JSON string with ``env_id`` and the counts. The field names are Minari's, so the episodes
    can be copied into a Minari data set unchanged.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    arrays: dict[str, Any] = {}  # Any: np.savez_compressed(**dict[str, ndarray]) trips mypy
    for group in ("safe", "unsafe"):
        for i, d in enumerate(getattr(demoset, group)):
            arrays[f"{group}/{i}/observations"] = d.observations
            arrays[f"{group}/{i}/actions"] = d.actions
            arrays[f"{group}/{i}/rewards"] = d.rewards
            arrays[f"{group}/{i}/flags"] = np.array([d.terminated, d.truncated])
    meta = {"env_id": demoset.env_id, "n_safe": len(demoset.safe), "n_unsafe": len(demoset.unsafe)}
    arrays["meta"] = np.array(json.dumps(meta))
    np.savez_compressed(path, **arrays)
    return path


def load_demonstrations(path: str | Path) -> DemoSet:
    """Read what :func:`save_demonstrations` wrote.

    Raises:
        FileNotFoundError: naming the path and how to make the file.
    """
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(
            f"No DEFENDER demonstrations at {path}. Make them with "
            "thesis_lib.defender.collect_demonstrations(...) and save_demonstrations(demoset, path)."
        )
    with np.load(path, allow_pickle=False) as data:
        meta = json.loads(str(data["meta"]))
        groups = {}
        for group, n in (("safe", meta["n_safe"]), ("unsafe", meta["n_unsafe"])):
            groups[group] = [
                Demonstration(
                    data[f"{group}/{i}/observations"],
                    data[f"{group}/{i}/actions"],
                    data[f"{group}/{i}/rewards"],
                    bool(data[f"{group}/{i}/flags"][0]),
                    bool(data[f"{group}/{i}/flags"][1]),
                )
                for i in range(n)
            ]
    return DemoSet(groups["safe"], groups["unsafe"], meta["env_id"])


def _minari_ids(env_id: str, name: str | None) -> dict[str, str]:
    name = name or "defender-" + env_id.split("-v")[0].lower()
    return {g: f"thesis/{name}/{g}-v0" for g in ("safe", "unsafe")}


class _DataDir:
    """Temporarily point ``thesis_lib.data`` at ``root`` (``THESIS_DATA_DIR``); no-op for None."""

    def __init__(self, root: str | Path | None) -> None:
        self.root = root
        self.old: str | None = None

    def __enter__(self) -> None:
        import os

        if self.root is not None:
            self.old = os.environ.get("THESIS_DATA_DIR")
            os.environ["THESIS_DATA_DIR"] = str(self.root)

    def __exit__(self, *exc: Any) -> None:
        import os

        if self.root is not None:
            if self.old is None:
                os.environ.pop("THESIS_DATA_DIR", None)
            else:
                os.environ["THESIS_DATA_DIR"] = self.old


def save_demonstrations_minari(
    demoset: DemoSet,
    *,
    name: str | None = None,
    root: str | Path | None = None,
    info: Mapping[str, Any] | None = None,
) -> dict[str, str]:
    """Write a :class:`DemoSet` as two Minari data sets, one per group.

    Ids: ``thesis/<name>/safe-v0`` and ``thesis/<name>/unsafe-v0``, ``name`` defaulting to
    ``defender-<task>`` (e.g. ``defender-hopper``); written with
    :func:`thesis_lib.data.storage.write_dataset` under ``root`` (default: the data-set
    directory, ``$THESIS_DATA_DIR`` or ``~/.minari/datasets``), replacing older ones.

    Returns:
        ``{"safe": id, "unsafe": id}``.

    Used in: DEFENDER (thesis 4.3).
    """
    ids = _minari_ids(demoset.env_id, name)
    for group, dataset_id in ids.items():
        demos = getattr(demoset, group)
        if not demos:
            raise ValueError(
                f"The {group} group is empty; a Minari data set needs at least one episode."
            )
        episodes = []
        for i, d in enumerate(demos):
            terminations, truncations = (
                np.zeros(d.length, dtype=bool),
                np.zeros(d.length, dtype=bool),
            )
            terminations[-1], truncations[-1] = (
                d.terminated,
                d.truncated,
            )  # the flags of the last step
            episodes.append(
                Episode(i, d.observations, d.actions, d.rewards, terminations, truncations)
            )
        write_dataset(
            dataset_id,
            episodes,
            demoset.env_id,
            description=f"DEFENDER {group} demonstrations",
            info={"group": group, **dict(info or {})},
            root=Path(root) if root is not None else None,
        )
    return ids


def load_demonstrations_minari(
    env_id: str, *, name: str | None = None, root: str | Path | None = None
) -> DemoSet:
    """Read what :func:`save_demonstrations_minari` wrote for ``env_id``.

    Raises:
        FileNotFoundError: no such data set (the message says how to make it).

    Used in: DEFENDER (thesis 4.3).
    """
    groups = {}
    with _DataDir(root):
        for group, dataset_id in _minari_ids(env_id, name).items():
            data = load(dataset_id)
            groups[group] = [
                as_demonstration(e, f"{group} episode {e.id} of {dataset_id}")
                for e in data.episodes
            ]
    return DemoSet(groups["safe"], groups["unsafe"], env_id)


def _features_list(demos: Sequence[Any], trajectory: Trajectory, group: str) -> list[np.ndarray]:
    return [
        trajectory_features(as_demonstration(d, f"{group} demonstration {i}"), trajectory)
        for i, d in enumerate(demos)
    ]


def _expert_task(env_id: str) -> str:
    """The :mod:`thesis_lib.data` task whose shipped expert plays ``env_id``."""
    names = [name for name, spec in TASKS.items() if spec.env_id == env_id and has_policies(name)]
    if not names:
        have = sorted(spec.env_id for name, spec in TASKS.items() if has_policies(name))
        raise ValueError(
            f"No shipped expert policy for {env_id!r}; experts ship for: {', '.join(have)}."
        )
    return names[0]


def shipped_expert_label(env_id: str) -> str:
    """What the shipped expert of ``env_id`` is, for tables and prose: ``"TQC expert"`` or
    ``"ARS expert"`` (its training record's :attr:`~thesis_lib.data.experts.PolicyRecord.algorithm_name`).

    Raises:
        ValueError: no shipped expert for ``env_id``.
    """
    return f"{load_policy_record(_expert_task(env_id)).algorithm_name} expert"
