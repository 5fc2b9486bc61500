"""DEFENDER as a ``gymnasium.Wrapper``: any RL library gets the filter (thesis 4.3.1, Algorithm 2).

Before each step the wrapper appends the current state (or state||action) to the episode's
trajectory and compares it with both demonstration groups. If the cost to the safe group is
lower, the real environment steps. Otherwise it is **not** stepped: the wrapper returns the
next state predicted by a dynamics model, the lowest single-step reward found in the
demonstrations, ``terminated=True`` and ``info["filtered"] = True``. The dynamics model trains
online on real transitions only (one update every :data:`DYNAMICS_TRAIN_EVERY` real steps by
default, every step with ``paper_compat=True`` or ``dynamics_train_every=1``).

Used in: DEFENDER (thesis 4.3).
"""

from __future__ import annotations

import contextlib
import copy
from collections.abc import Callable, Iterator, Mapping, Sequence
from typing import Any, Literal, SupportsFloat, cast

import gymnasium as gym
import numpy as np
import pandas as pd

from thesis_lib import dtw as _dtw
from thesis_lib.defender.compare import GroupCost
from thesis_lib.defender.demos import (
    TRAJECTORIES,
    Trajectory,
    as_demonstration,
    trajectory_features,
)
from thesis_lib.defender.dynamics import DynamicsModel
from thesis_lib.defender.methods import parse_method
from thesis_lib.rl.callbacks import find_horizon, is_crash

__all__ = [
    "DYNAMICS_TRAIN_EVERY",
    "EPISODE_LOG_COLUMNS",
    "PAPER_MAX_TRAJECTORY",
    "RANDOM_FILTER_STREAM",
    "TIMER_FILTER_STREAM",
    "DefenderWrapper",
    "RandomFilter",
    "TimerFilter",
    "counterfactual_crash_step",
    "counterfactual_terminates",
]

PAPER_MAX_TRAJECTORY = 20
"""The authors' code cut the agent's trajectory to its last 20 steps before every comparison."""

DYNAMICS_TRAIN_EVERY = 4
"""Default: one dynamics-model update every 4 real steps. Algorithm 2 updates it every step (1,
the ``paper_compat`` setting); with it the whole filter added 15-18% to a SAC training step, with
every 4th step 4-7% (``benchmarks/bench_defender.py``, target <= 10%). A filtered step is terminal, so
SB3's SAC/TD3 never bootstrap from the predicted next state; its accuracy does not enter the
agent's targets."""

EPISODE_LOG_COLUMNS: tuple[str, ...] = (
    "episode", "return", "length", "terminated", "truncated", "crashed", "filtered", "filter_step",
    "would_crash",
)  # fmt: skip
"""Columns of :attr:`DefenderWrapper.episodes`."""


@contextlib.contextmanager
def _state_kept(env: gym.Env) -> Iterator[gym.Env]:
    """The unwrapped core of ``env``, to step freely: its state is put back exactly afterwards.

    A MuJoCo environment (``env.unwrapped.model``/``.data``) is stepped in place and its whole
    ``MjData`` restored bit for bit (``mujoco.mj_copyData``: positions, velocities, controls,
    warm start); any other environment is stepped as a ``copy.deepcopy`` of its unwrapped core.
    Wrappers are not stepped (no ``TimeLimit`` count is spent).
    """
    u = env.unwrapped
    model, data = getattr(u, "model", None), getattr(u, "data", None)
    try:
        import mujoco
    except ImportError:  # pragma: no cover - mujoco is a dependency
        mujoco = None
    if mujoco is not None and isinstance(data, mujoco.MjData):
        saved = mujoco.MjData(model)
        mujoco.mj_copyData(saved, model, data)
        try:
            yield u
        finally:
            mujoco.mj_copyData(data, model, saved)
    else:
        yield copy.deepcopy(u)


def counterfactual_terminates(env: gym.Env, action: Any) -> bool:
    """Whether stepping ``env`` with ``action`` would end the episode (``terminated``), found
    on a copy of its state: ``env`` is left exactly as it was (:func:`_state_kept`); the
    one-step :func:`counterfactual_crash_step`.
    """
    return counterfactual_crash_step(env, action) is not None


def counterfactual_crash_step(
    env: gym.Env,
    action: Any,
    policy: Callable[[np.ndarray], Any] | None = None,
    max_steps: int = 1,
) -> int | None:
    """After how many steps the episode would have terminated had ``action`` been taken and
    ``policy`` acted after it: 1 where ``action`` itself terminates, ``k`` where the ``k``-th
    step does, None where none of the first ``max_steps`` does. Found on a copy of the state:
    ``env`` is left exactly as it was.

    With ``max_steps=1`` it is :func:`counterfactual_terminates` (the study's one-step
    counterfactual). A longer look asks whether a filtered episode was about to crash a few
    steps later: the agent's policy keeps acting on the copy. The caller bounds ``max_steps``
    by the steps left before the horizon (the copy has no ``TimeLimit``).

    Args:
        env: the environment the action was meant for (any wrappers; none may change
            observations, since ``policy`` is given the unwrapped core's).
        action: the action the filter held back.
        policy: observation -> action, e.g. ``lambda o: model.predict(o)[0]``; needed for
            ``max_steps > 1``.
        max_steps: how many steps to look at, >= 1.

    Raises:
        ValueError: ``max_steps < 1``; ``max_steps > 1`` without a policy; an observation
            wrapper in ``env``.
    """
    if int(max_steps) < 1:
        raise ValueError(f"max_steps must be >= 1, got {max_steps}.")
    if max_steps > 1:
        if policy is None:
            raise ValueError(f"Looking {max_steps} steps ahead needs the agent's policy.")
        e: Any = env
        while isinstance(e, gym.Wrapper):
            if isinstance(e, gym.ObservationWrapper):
                raise ValueError(
                    f"{type(e).__name__} changes observations; the policy would be given the "
                    "unwrapped environment's. Look ahead on an environment without one."
                )
            e = e.env
    with _state_kept(env) as core:
        obs, _, terminated, _, _ = core.step(action)
        k = 1
        while not terminated and k < max_steps:
            assert policy is not None
            obs, _, terminated, _, _ = core.step(policy(np.asarray(obs)))
            k += 1
    return k if terminated else None


class DefenderWrapper(gym.Wrapper):
    """Filter unsafe episodes with DTW against safe and unsafe demonstrations (DEFENDER).

    Args:
        env: the task, with flat ``Box`` observations and actions (and usually a ``TimeLimit``).
        safe_demos: demonstrations that reached the horizon: :class:`~thesis_lib.defender.Demonstration`
            objects, Minari-like episodes (``observations``, ``actions``, ``rewards``) or dicts.
        unsafe_demos: demonstrations that ended in an unsafe state.
        safe_method: how to compare the trajectory with the safe group (one of the 24
            :data:`~thesis_lib.defender.METHODS`, e.g. ``"MeanDemoW5"``).
        unsafe_method: the same for the unsafe group (e.g. ``"MeanDemoW10"``).
        trajectory: ``"state"`` (states only) or ``"state_action"`` (state||action).
        max_trajectory: compare only the trajectory's last this-many steps; None (default, the
            thesis's text) = the whole episode so far; the authors' code used 20.
        metric: DTW local cost (the authors' code: L1).
        paper_compat: the authors' code: FastDTW radius 1 with L1, trajectory cut to its last 20
            steps, and the filter fires only when safe cost > unsafe cost (the thesis's Algorithm 2
            also fires on a tie). Default False: exact DTW, the whole trajectory, ties fire.
        filter_reward: reward of a filtered step; None = the lowest single-step reward in the
            demonstrations (the thesis: "the lowest reward from the reward function").
        dynamics: a :class:`DynamicsModel` to use (e.g. pre-trained); None builds one.
        dynamics_kwargs: keyword arguments for the :class:`DynamicsModel` built when ``dynamics``
            is None (e.g. ``{"hidden": [64, 64]}``).
        dynamics_train_every: one update of that model every this many real steps; None =
            :data:`DYNAMICS_TRAIN_EVERY` (4), or 1 (every step, Algorithm 2) with ``paper_compat``.
        seed: seed of the dynamics model.
        counterfactual: before each filtered action, step a copy of the environment's state with
            it (:func:`counterfactual_terminates`) and record whether it would have crashed on
            that very step (``info["would_crash"]``, the episode log's ``would_crash``): what
            the filter saved and what it blocked for nothing (:meth:`filter_confusion`). It
            measures the claim ("fewer crashes") rather than the filter's own firing rate. One
            step only: a firing a few steps before a fall counts as a false alarm here;
            :func:`counterfactual_crash_step` looks further with the agent's policy.

    Each step's ``info`` has ``"filtered"`` (bool); a filtered step also has ``"filter_step"``
    (how many real steps the episode had taken), ``"cost_safe"`` and ``"cost_unsafe"``.
    :attr:`episodes` logs every finished episode. A crash is a real termination before the
    horizon; a filtered episode is not a crash.

    Raises:
        ValueError: an empty group, demonstrations whose feature size does not match the
            environment, an unknown method name (with the valid ones), a non-Box space.

    Used in: DEFENDER (thesis 4.3).

    Example::

        env = DefenderWrapper(gym.make("Hopper-v5"), demos.safe, demos.unsafe,
                              safe_method="MeanDemoW5", unsafe_method="MeanDemoW10")
        SAC("MlpPolicy", env).learn(10_000)
        env.episodes  # return, length, crashed, filtered, filter_step per episode
    """

    def __init__(
        self,
        env: gym.Env,
        safe_demos: Sequence[Any],
        unsafe_demos: Sequence[Any],
        *,
        safe_method: str = "MeanDemoW5",
        unsafe_method: str = "MeanDemoW10",
        trajectory: Trajectory = "state",
        max_trajectory: int | None = None,
        metric: _dtw.Metric = "l1",
        paper_compat: bool = False,
        filter_reward: float | None = None,
        dynamics: DynamicsModel | None = None,
        dynamics_kwargs: Mapping[str, Any] | None = None,
        dynamics_train_every: int | None = None,
        seed: int = 0,
        counterfactual: bool = False,
    ) -> None:
        super().__init__(env)
        self.counterfactual = bool(counterfactual)
        if trajectory not in TRAJECTORIES:
            raise ValueError(
                f"Unknown trajectory {trajectory!r}. Valid: {', '.join(TRAJECTORIES)}."
            )
        obs_space, act_space = env.observation_space, env.action_space
        for name, space in (("observation", obs_space), ("action", act_space)):
            if not isinstance(space, gym.spaces.Box) or len(space.shape) != 1:
                raise ValueError(
                    f"DefenderWrapper needs a flat Box {name} space (1-D), got {space}. Flatten it first "
                    "(e.g. gymnasium.wrappers.FlattenObservation) or encode images into features."
                )
        self.safe_method = parse_method(safe_method).name
        self.unsafe_method = parse_method(unsafe_method).name
        self.trajectory: Trajectory = trajectory
        self.paper_compat = bool(paper_compat)
        if self.paper_compat and max_trajectory is None:
            max_trajectory = PAPER_MAX_TRAJECTORY
        self.max_trajectory = max_trajectory
        self.metric = "l1" if self.paper_compat else metric
        backend: Literal["exact", "fastdtw"] = "fastdtw" if self.paper_compat else "exact"
        obs_box, act_box = cast(gym.spaces.Box, obs_space), cast(gym.spaces.Box, act_space)
        self.obs_dim, self.act_dim = int(obs_box.shape[0]), int(act_box.shape[0])
        n_features = self.obs_dim + (self.act_dim if trajectory == "state_action" else 0)

        groups = {}
        min_reward = np.inf
        for group, demos in (("safe", safe_demos), ("unsafe", unsafe_demos)):
            demos = list(demos) if demos is not None else []
            if not demos:
                raise ValueError(
                    f"DefenderWrapper needs at least one {group} demonstration, got none. DEFENDER compares "
                    "the trajectory with both groups; make them with "
                    "thesis_lib.defender.collect_demonstrations or expert_demonstrations."
                )
            parsed = [
                as_demonstration(d, f"{group} demonstration {i}") for i, d in enumerate(demos)
            ]
            for i, d in enumerate(parsed):
                if d.observations.shape[1] != self.obs_dim or d.actions.shape[1] != self.act_dim:
                    raise ValueError(
                        f"{group} demonstration {i} has states of size {d.observations.shape[1]} and actions "
                        f"of size {d.actions.shape[1]}, but the environment has observations of size "
                        f"{self.obs_dim} and actions of size {self.act_dim}; the demonstrations must "
                        f"come from the same task ({getattr(env.spec, 'id', env)})."
                    )
                min_reward = min(min_reward, float(np.min(d.rewards)))
            features = [trajectory_features(d, trajectory) for d in parsed]
            assert features[0].shape[1] == n_features, (features[0].shape, n_features)
            groups[group] = _dtw.pack_references(features)
        self.n_safe, self.n_unsafe = groups["safe"].n_sequences, groups["unsafe"].n_sequences
        self.filter_reward = float(min_reward if filter_reward is None else filter_reward)
        self._safe = GroupCost(
            groups["safe"],
            self.safe_method,
            metric=self.metric,
            max_trajectory=self.max_trajectory,
            backend=backend,
        )
        self._unsafe = GroupCost(
            groups["unsafe"],
            self.unsafe_method,
            metric=self.metric,
            max_trajectory=self.max_trajectory,
            backend=backend,
        )
        if dynamics is None:
            kwargs = dict(dynamics_kwargs or {})
            if dynamics_train_every is not None and "train_every" in kwargs:
                raise ValueError(
                    "Give the dynamics update rate once: dynamics_train_every or "
                    "dynamics_kwargs['train_every'], not both."
                )
            if "train_every" not in kwargs:
                kwargs["train_every"] = dynamics_train_every or (
                    1 if self.paper_compat else DYNAMICS_TRAIN_EVERY
                )
            dynamics = DynamicsModel(self.obs_dim, self.act_dim, seed=seed, **kwargs)
        self.dynamics = dynamics
        self.horizon = find_horizon(env)
        self._step = np.empty(n_features)
        self._obs: np.ndarray | None = None
        self._ended = False
        self._rows: list[dict[str, Any]] = []
        self._would_crash: bool | None = None
        self._return, self._length = 0.0, 0
        self.n_filtered_steps = 0
        self.n_real_steps = 0

    # ------------------------------------------------------------------ gymnasium API
    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[Any, dict]:
        """Reset the real environment and clear the trajectory."""
        obs, info = self.env.reset(seed=seed, options=options)
        self._safe.reset()
        self._unsafe.reset()
        self._obs = np.asarray(obs)
        self._ended = False
        self._would_crash = None
        self._return, self._length = 0.0, 0
        info = dict(info)
        info["filtered"] = False
        return obs, info

    def step(self, action: Any) -> tuple[Any, SupportsFloat, bool, bool, dict[str, Any]]:
        """Filter, then step the real environment or answer with the dynamics model."""
        if self._obs is None or self._ended:
            raise RuntimeError(
                "DefenderWrapper.step called before reset() or after the episode ended; call reset()."
            )
        action_arr = np.asarray(action, dtype=np.float64).reshape(-1)
        fire, costs = self._decide(action_arr)
        reward: SupportsFloat
        if fire:
            would = (
                is_crash(
                    counterfactual_terminates(self.env, action), self._length + 1, self.horizon
                )
                if self.counterfactual
                else None
            )
            next_obs = self.dynamics.predict(self._obs, action_arr).astype(
                self.observation_space.dtype
            )
            reward, terminated, truncated = self.filter_reward, True, False
            info: dict[str, Any] = {
                "filtered": True,
                "filter_step": self._length,
                **costs,
                "would_crash": would,
            }
            self._would_crash = would
            self.n_filtered_steps += 1
        else:
            next_obs, reward, terminated, truncated, info = self.env.step(action)
            self.dynamics.observe(self._obs, action_arr, next_obs)  # real transitions only
            info = dict(info)
            info["filtered"] = False
            self.n_real_steps += 1
        self._obs = np.asarray(next_obs)
        self._return += float(reward)
        self._length += 1
        if terminated or truncated:
            self._ended = True
            self._log(bool(terminated), bool(truncated), fire)
        return next_obs, reward, terminated, truncated, info

    def _decide(self, action: np.ndarray) -> tuple[bool, dict[str, float]]:
        """Whether the filter fires before ``action``, and what it measured: the trajectory
        (with ``action`` on state-action trajectories) against both groups."""
        self._step[: self.obs_dim] = np.asarray(self._obs).reshape(-1)
        if self.trajectory == "state_action":
            self._step[self.obs_dim :] = action
        cost_safe = self._safe.append(self._step)
        cost_unsafe = self._unsafe.append(self._step)
        # Algorithm 2: step only if Safe(tau) < Unsafe(tau); the authors' code filtered only on ">".
        fire = cost_safe > cost_unsafe if self.paper_compat else not cost_safe < cost_unsafe
        return bool(fire), {"cost_safe": cost_safe, "cost_unsafe": cost_unsafe}

    # ------------------------------------------------------------------ episode log
    def _log(self, terminated: bool, truncated: bool, filtered: bool) -> None:
        crashed = not filtered and is_crash(terminated, self._length, self.horizon)
        self._rows.append(
            {
                "episode": len(self._rows),
                "return": self._return,
                "length": self._length,
                "terminated": terminated,
                "truncated": truncated,
                "crashed": crashed,
                "filtered": filtered,
                "filter_step": self._length - 1 if filtered else None,
                "would_crash": self._would_crash if filtered else None,
            }
        )

    # ------------------------------------------------------------------ checkpoints
    def state_dict(self) -> dict[str, Any]:
        """What lasts across episodes: the dynamics model, the episode log and the step counts
        (a checkpoint between episodes, :mod:`thesis_lib.rl.resume`; the trajectory's costs
        start again at every reset)."""
        return {
            "dynamics": self.dynamics.state_dict(),
            "rows": [dict(r) for r in self._rows],
            "n_filtered_steps": self.n_filtered_steps,
            "n_real_steps": self.n_real_steps,
        }

    def load_state_dict(self, state: dict[str, Any]) -> None:
        """Continue from :meth:`state_dict`'s ``state`` (the next call is ``reset``)."""
        self.dynamics.load_state_dict(state["dynamics"])
        self._rows = [dict(r) for r in state["rows"]]
        self.n_filtered_steps = int(state["n_filtered_steps"])
        self.n_real_steps = int(state["n_real_steps"])

    def filter_confusion(self) -> dict[str, float | int]:
        """The filter judged against what would have happened (needs ``counterfactual=True``).

        Per finished episode: a filtered step whose action would have crashed on that step is a
        saved crash (``tp``); one that would not is a false alarm (``fp``: it may still precede
        a crash a few steps on, :func:`counterfactual_crash_step`); a real crash the filter let
        through is a miss (``fn``). ``precision = tp / (tp + fp)``, ``recall = tp / (tp + fn)``
        (NaN where undefined), ``crashes_without_filter = tp + fn``: the crashes the episodes
        would have had, against the ``fn`` they had.

        Raises:
            RuntimeError: the wrapper was made without ``counterfactual=True``.
        """
        if not self.counterfactual:
            raise RuntimeError(
                "filter_confusion needs DefenderWrapper(..., counterfactual=True): without it a "
                "filtered step's outcome is unknown."
            )
        log = self.episodes
        filt = log[log["filtered"].astype(bool)]
        tp = int(filt["would_crash"].astype(bool).sum())
        fp = len(filt) - tp
        fn = int(log["crashed"].astype(bool).sum())
        nan = float("nan")
        return {
            "episodes": len(log),
            "tp": tp,
            "fp": fp,
            "fn": fn,
            "precision": tp / (tp + fp) if tp + fp else nan,
            "recall": tp / (tp + fn) if tp + fn else nan,
            "crashes_without_filter": tp + fn,
        }

    @property
    def episodes(self) -> pd.DataFrame:
        """One row per finished episode, columns :data:`EPISODE_LOG_COLUMNS`.

        ``crashed``: a real termination before the horizon (a filtered episode is never one);
        ``filter_step``: real steps taken before the filter fired (None if it did not);
        ``would_crash``: with ``counterfactual=True``, whether the filtered action would have
        crashed (None if the filter did not fire, or without the counterfactual).
        """
        return pd.DataFrame(self._rows, columns=list(EPISODE_LOG_COLUMNS))

    def __repr__(self) -> str:
        return (
            f"DefenderWrapper({self.env}, safe={self.n_safe}x{self.safe_method}, "
            f"unsafe={self.n_unsafe}x{self.unsafe_method}, trajectory={self.trajectory!r}, "
            f"max_trajectory={self.max_trajectory}, paper_compat={self.paper_compat})"
        )


class _BlindFilter(DefenderWrapper):
    """A filter that fires without reading the trajectory (the controls :class:`RandomFilter`
    and :class:`TimerFilter`): :class:`DefenderWrapper` to the letter when it fires, its
    decisions drawn from its own generator, seeded ``[seed, stream]`` (the dynamics model's
    torch generator is seeded with ``seed`` too), which a checkpoint saves (:meth:`_rng_state`).
    ``counterfactual``, ``filter_reward``, ``dynamics``, ``dynamics_kwargs`` and
    ``dynamics_train_every`` are :class:`DefenderWrapper`'s."""

    def __init__(
        self,
        env: gym.Env,
        safe_demos: Sequence[Any],
        unsafe_demos: Sequence[Any],
        *,
        stream: int,
        seed: int = 0,
        counterfactual: bool = False,
        filter_reward: float | None = None,
        dynamics: DynamicsModel | None = None,
        dynamics_kwargs: Mapping[str, Any] | None = None,
        dynamics_train_every: int | None = None,
    ) -> None:
        super().__init__(
            env,
            safe_demos,
            unsafe_demos,
            seed=seed,
            counterfactual=counterfactual,
            filter_reward=filter_reward,
            dynamics=dynamics,
            dynamics_kwargs=dynamics_kwargs,
            dynamics_train_every=dynamics_train_every,
        )
        self._rng = np.random.default_rng([int(seed), stream])

    def _rng_state(self) -> dict[str, Any]:
        """The generator's state a checkpoint saves: its state now."""
        return dict(self._rng.bit_generator.state)

    def state_dict(self) -> dict[str, Any]:
        """:meth:`DefenderWrapper.state_dict` and the draws' generator (:meth:`_rng_state`)."""
        return {**super().state_dict(), "rng": self._rng_state()}

    def load_state_dict(self, state: dict[str, Any]) -> None:
        super().load_state_dict(state)
        self._rng.bit_generator.state = state["rng"]


class RandomFilter(_BlindFilter):
    """A filter that fires at random: the control of CLAIMS.md for DEFENDER ("a filter firing
    at random at the same rate").

    Before each step it fires with probability ``rate``, drawn from its own seeded generator,
    whatever the trajectory; otherwise it is :class:`DefenderWrapper` to the letter: a firing
    does not step the environment, ends the episode with the lowest single-step reward of the
    demonstrations and a dynamics-model next state, and with ``counterfactual=True`` records
    whether the held-back action would have crashed. Its firings per step are ``rate`` in
    expectation, whatever the policy does, so ``rate`` is matched to DEFENDER's measured
    firings per training step. A crash cut that DEFENDER shares with this filter comes from
    ending episodes, not from the demonstrations.

    Args:
        env, safe_demos, unsafe_demos: as :class:`DefenderWrapper` (the demonstrations give the
            filtered step's reward and check the spaces; no DTW is computed).
        rate: the probability of firing before each step, in [0, 1) (0: it never fires, the
            control of a filter that never fired).
        seed: seeds the firing draws and the dynamics model.
        counterfactual, filter_reward, dynamics, dynamics_kwargs, dynamics_train_every: as
            :class:`DefenderWrapper`.

    Raises:
        ValueError: ``rate`` outside [0, 1), and :class:`DefenderWrapper`'s errors.

    Used in: DEFENDER chapter, the control arm of the C7 study.
    """

    def __init__(
        self,
        env: gym.Env,
        safe_demos: Sequence[Any],
        unsafe_demos: Sequence[Any],
        *,
        rate: float,
        seed: int = 0,
        **options: Any,
    ) -> None:
        rate = float(rate)
        if not 0.0 <= rate < 1.0:
            raise ValueError(f"rate must be a probability in [0, 1), got {rate}.")
        super().__init__(
            env, safe_demos, unsafe_demos, stream=RANDOM_FILTER_STREAM, seed=seed, **options
        )
        self.rate = rate

    def _decide(self, action: np.ndarray) -> tuple[bool, dict[str, float]]:
        return bool(self._rng.random() < self.rate), {}

    def __repr__(self) -> str:
        return f"RandomFilter({self.env}, rate={self.rate})"


RANDOM_FILTER_STREAM = 0x5EED
"""The second word of :class:`RandomFilter`'s generator seed, ``[seed, RANDOM_FILTER_STREAM]``."""


class TimerFilter(_BlindFilter):
    """A blind filter that fires at DEFENDER's steps, not at its states: the stronger control
    for a filter that fires at about the same step of every episode.

    :class:`RandomFilter` fires uniformly over steps; a filter that ends most episodes near
    one step (DEFENDER with the 20-step cap on a policy whose episodes fall alike,
    ``studies/03_defender/diagnostics/``) cuts more crashes than that at the same rate by its
    timing alone. At each reset this filter arms itself with probability ``p_episode`` (the
    share of the matched run's episodes its filter ended) and then fires at the step drawn
    from ``step_deciles`` (the deciles of the matched filter's firing steps, as episode
    lengths: the filtered step included; drawn by linear interpolation between them), whatever
    the trajectory. An episode that ends before that step is not filtered. A firing is
    :class:`DefenderWrapper`'s to the letter (the demonstrations' lowest reward, a
    dynamics-model next state, the counterfactual).

    Args:
        env, safe_demos, unsafe_demos: as :class:`RandomFilter`.
        p_episode: the probability that an episode is armed, in [0, 1].
        step_deciles: 11 non-decreasing episode lengths >= 1, the 0th to 100th percentiles
            of the matched filter's firing steps.
        seed: seeds the draws and the dynamics model.
        counterfactual, filter_reward, dynamics, dynamics_kwargs, dynamics_train_every: as
            :class:`DefenderWrapper`.

    Raises:
        ValueError: ``p_episode`` outside [0, 1], deciles that are not 11 finite,
            non-decreasing values >= 1, and :class:`DefenderWrapper`'s errors.

    Used in: DEFENDER chapter, the timing control of the C7 study.
    """

    def __init__(
        self,
        env: gym.Env,
        safe_demos: Sequence[Any],
        unsafe_demos: Sequence[Any],
        *,
        p_episode: float,
        step_deciles: Sequence[float],
        seed: int = 0,
        **options: Any,
    ) -> None:
        p_episode = float(p_episode)
        if not 0.0 <= p_episode <= 1.0:
            raise ValueError(f"p_episode must be a probability in [0, 1], got {p_episode}.")
        q = np.asarray(step_deciles, dtype=float)
        if q.shape != (11,) or not np.isfinite(q).all() or q[0] < 1 or (np.diff(q) < 0).any():
            raise ValueError(
                "step_deciles must be 11 finite, non-decreasing episode lengths >= 1 (the 0th to "
                f"100th percentiles of the matched filter's firing steps), got {list(q)}."
            )
        super().__init__(
            env, safe_demos, unsafe_demos, stream=TIMER_FILTER_STREAM, seed=seed, **options
        )
        self.p_episode, self.step_deciles = p_episode, q
        self._rng_before_reset = dict(self._rng.bit_generator.state)
        self._fire_at: int | None = None

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[Any, dict]:
        """Reset, and draw whether and at which step this episode is filtered."""
        out = super().reset(seed=seed, options=options)
        self._rng_before_reset = dict(self._rng.bit_generator.state)
        armed, u = self._rng.random(2)
        step = np.interp(u, np.linspace(0.0, 1.0, 11), self.step_deciles)
        self._fire_at = max(1, int(round(step))) if armed < self.p_episode else None
        return out

    def _decide(self, action: np.ndarray) -> tuple[bool, dict[str, float]]:
        return self._fire_at is not None and self._length + 1 == self._fire_at, {}

    def _rng_state(self) -> dict[str, Any]:
        """The generator as it was before the last reset: a checkpoint is taken between
        episodes, after the next episode's reset, and on resume that reset is made again
        (:mod:`thesis_lib.rl.resume`), so it draws again what it drew."""
        return dict(self._rng_before_reset)

    def load_state_dict(self, state: dict[str, Any]) -> None:
        super().load_state_dict(state)
        self._rng_before_reset = dict(state["rng"])

    def __repr__(self) -> str:
        return f"TimerFilter({self.env}, p_episode={self.p_episode})"


TIMER_FILTER_STREAM = 0x7173
"""The second word of :class:`TimerFilter`'s generator seed, ``[seed, TIMER_FILTER_STREAM]``."""
