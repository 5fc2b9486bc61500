"""Demonstrations for DEFENDER: what one is, how the authors made them, storing them (thesis 4.3).

A :class:`Demonstration` is one episode in Minari's naming (``observations`` has one more row
than ``actions`` and ``rewards``). Anything with those three attributes is accepted too
(Minari's ``EpisodeData``, ``thesis_lib.data`` episodes), as is a dict with those keys.

:func:`collect_demonstrations` makes them as the authors did: train SAC and, every
``every`` training episodes, roll out the current policy once; an episode that reaches the
horizon is *safe*, one that terminates earlier is *unsafe*. :func:`select_diverse` then keeps
a subset that is spread out under DTW (greedy farthest-point selection), and
:func:`save_demonstrations` / :func:`load_demonstrations` store them in one ``.npz``
(a documented, dependency-free layout; see :func:`save_demonstrations`).

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

__all__ = [
    "TRAJECTORIES",
    "DemoRun",
    "DemoSet",
    "Demonstration",
    "EpisodeRecorder",
    "as_demonstration",
    "collect_demonstrations",
    "load_demonstrations",
    "rollout",
    "save_demonstrations",
    "select_diverse",
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
    if obs.ndim != 2 or actions.ndim != 2 or len(obs) != len(actions) + 1 or len(rewards) != len(actions):
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

    Put it under the agent's env to log a training run for :func:`strategy_ablation`.

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
            self.episodes.append(Demonstration(np.stack(self._obs), np.stack(self._act), np.asarray(self._rew),
                                               bool(terminated), bool(truncated and not terminated)))
        return obs, reward, terminated, truncated, info


def rollout(model: Any, env: gym.Env, *, seed: int | None = None, deterministic: bool = True) -> Demonstration:
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
    return Demonstration(np.stack(observations), np.stack(actions), np.asarray(rewards), bool(terminated),
                         bool(truncated and not terminated))


def select_diverse(
    demos: Sequence[Demonstration], n: int, *, trajectory: Trajectory = "state", metric: _dtw.Metric = "l1"
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

    Returns:
        :class:`DemoRun`: the selected demonstrations, every roll-out, the SAC run's training
        episodes (reused by the strategy ablation) and its ``TrainResult``.

    Raises:
        RuntimeError: if no safe or no unsafe roll-out was seen (train longer or lower the horizon).

    Used in: DEFENDER (thesis 4.3).
    """
    from stable_baselines3.common.callbacks import BaseCallback

    from thesis_lib.rl import RLConfig, config_from_params, train

    make = (lambda: gym.make(env_id, max_episode_steps=max_episode_steps)) if max_episode_steps else (
        lambda: gym.make(env_id))
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
                        found.append(rollout(self.model, demo_env, seed=seed + 10_000 + len(found),
                                             deterministic=deterministic))
            return True

    params = {"algo": "SAC", "env_id": None, "total_timesteps": int(total_timesteps), "seed": seed,
              **dict(rl_overrides or {})}
    config: RLConfig = config_from_params(params)
    recorder = EpisodeRecorder(make())
    result = train(config, env=recorder, callbacks=[_Roll()], progress=progress)
    safe = [d for d in found if d.truncated]
    unsafe = [d for d in found if d.terminated]
    if not safe or not unsafe:
        raise RuntimeError(
            f"collect_demonstrations saw {len(safe)} safe and {len(unsafe)} unsafe roll-outs of "
            f"{env_id} in {total_timesteps} steps ({len(found)} roll-outs); DEFENDER needs both. "
            "Train longer (total_timesteps), roll out more often (every), or lower max_episode_steps."
        )
    demoset = DemoSet(select_diverse(safe, n_safe), select_diverse(unsafe, n_unsafe), env_id)
    return DemoRun(demoset, DemoSet(safe, unsafe, env_id), recorder.episodes, result)


def save_demonstrations(demoset: DemoSet, path: str | Path) -> Path:
    """Write a :class:`DemoSet` to one ``.npz``.

    Layout: for group g in (safe, unsafe) and episode i, arrays ``g/i/observations``,
    ``g/i/actions``, ``g/i/rewards``, ``g/i/flags`` ([terminated, truncated]); plus ``meta``,
    a JSON string with ``env_id`` and the counts. The field names are Minari's, so the episodes
    can be copied into a Minari data set unchanged.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    arrays: dict[str, np.ndarray] = {}
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
                    data[f"{group}/{i}/observations"], data[f"{group}/{i}/actions"], data[f"{group}/{i}/rewards"],
                    bool(data[f"{group}/{i}/flags"][0]), bool(data[f"{group}/{i}/flags"][1]),
                )
                for i in range(n)
            ]
    return DemoSet(groups["safe"], groups["unsafe"], meta["env_id"])


def _features_list(demos: Sequence[Any], trajectory: Trajectory, group: str) -> list[np.ndarray]:
    return [trajectory_features(as_demonstration(d, f"{group} demonstration {i}"), trajectory)
            for i, d in enumerate(demos)]

