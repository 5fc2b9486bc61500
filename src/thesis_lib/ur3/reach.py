"""The UR3 reaching task of thesis 5.2.5.4, its scripted demonstrations and their data set.

Five goal joint configurations must be reached, in any order, within 200 steps.

* **State** (11-D): the six joint angles (rad) and a one-hot vector of the goals reached so far
  (the thesis's "one-hot-encoded vector representing the goal positions reached": one entry
  per goal, 1 once that goal has been reached).
* **Action** (6-D): joint-angle increments, in units of ``max_step`` rad (``Box(-1, 1)``): the
  arm moves by ``action * max_step`` per step, clipped to the joint limits. The default 0.1 rad
  per 0.1 s control step is 1 rad/s, under the UR3's 180°/s.
* **Reward**: ``-Σ_j |q_j - g_j|``, the absolute joint error to the *nearest unreached* goal
  ``g`` (nearest in that same L1 error), measured after the move, against the goals that were
  unreached before it (so the step that reaches a goal is rewarded for closing in on it).
* A goal is **reached** when every joint is within ``tolerance`` (0.1 rad) of it. The episode
  terminates when all five are reached and is truncated after ``max_steps`` (200).

The thesis's robot moved physically; here the arm is kinematic (a position-controlled UR
tracks small increments closely), and :mod:`thesis_lib.ur3.model`'s MuJoCo model gives the
forward kinematics and pictures.

Demonstrations (:func:`make_demonstrations`): the thesis teleoperated the robot from random
starts "through the sequence of goal positions". :class:`TeleopController` imitates that: it
heads for the next goal of the sequence (or, optionally, the nearest unreached one) with a
saturated proportional command, plus an Ornstein-Uhlenbeck wobble of
the operator's hand that fades near the goal. :func:`get_reach_dataset` stores 100 of them as
the Minari data set ``thesis/ur3-reach/teleop-v0`` (80 train, 10 validation, 10 test starts).

Used in: UR3 deployment chapter (Table 5.4).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import gymnasium as gym
import numpy as np

from thesis_lib.data import Episode, load, write_dataset
from thesis_lib.data.storage import OfflineDataset, find_dataset

from .model import POSITION_LIMITS
from .render import render_frames

__all__ = [
    "DATASET_ID",
    "ENV_ID",
    "REACH_SETS",
    "GOALS",
    "HOME",
    "ReachDemos",
    "TeleopController",
    "UR3ReachEnv",
    "get_reach_dataset",
    "make_demonstrations",
    "nearest_unreached",
    "split_demonstrations",
]

ENV_ID = "thesis/UR3Reach-v0"
"""Gymnasium id of :class:`UR3ReachEnv` (registered on import of ``thesis_lib.ur3``)."""
DATASET_ID = "thesis/ur3-reach/teleop-v0"
"""Minari id of the demonstrations (the ``teleop`` set of :data:`REACH_SETS`)."""

REACH_SETS: dict[str, dict[str, Any]] = {
    "teleop": {
        "id": DATASET_ID,
        "order": "sequence",
        "about": "the thesis's: every demonstration goes through the goals in one sequence",
    },
    "any-order": {
        "id": "thesis/ur3-reach/any-order-v0",
        "order": "random",
        "about": "each demonstration visits the goals in an order of its own (operators who "
        "each choose their way): the next goal is not a function of the goals reached, so a "
        "policy must infer it from the history or be given a sub-goal",
    },
}
"""The reaching data sets: ``teleop`` (Table 5.4's) and ``any-order``, harder (issue #35: at
``teleop`` both methods reach 4.7 of 5 goals from 20 demonstrations up, a ceiling; on
``any-order`` a 1-layer DT reached 0.4-1.6 goals from 10 demonstrations and 3.7 from 80)."""

HOME = np.array([0.0, -np.pi / 2, np.pi / 2, -np.pi / 2, -np.pi / 2, 0.0])
"""A common UR "home": upper arm up, forearm forward, tool down."""

GOALS = np.array([
    [0.0, -1.2, 1.2, -1.57, -1.57, 0.0],
    [0.8, -1.0, 0.9, -1.4, -1.57, 0.3],
    [-0.8, -1.4, 1.5, -1.7, -1.57, -0.3],
    [0.4, -1.8, 1.9, -1.6, -1.2, 0.6],
    [-0.4, -0.9, 0.7, -1.2, -1.9, -0.6],
])  # fmt: skip
"""``(5, 6)`` goal joint configurations (rad); each keeps the tool above the table."""

START_RANGE = 0.6
"""Random starts: ``HOME`` plus a uniform offset in ``[-START_RANGE, START_RANGE]`` rad per joint."""


def nearest_unreached(q: np.ndarray, goals: np.ndarray, reached: np.ndarray) -> tuple[int, float]:
    """Index of the nearest goal not yet reached and its L1 joint error (``(-1, 0.0)`` if none).

    >>> nearest_unreached(np.zeros(2), np.array([[1.0, 1.0], [0.5, 0.0]]), np.array([False, True]))
    (0, 2.0)
    """
    open_ = np.flatnonzero(~np.asarray(reached, dtype=bool))
    if open_.size == 0:
        return -1, 0.0
    err = np.abs(goals[open_] - q).sum(axis=1)
    k = int(np.argmin(err))
    return int(open_[k]), float(err[k])


class UR3ReachEnv(gym.Env):
    """Reach five goal joint configurations in any order (thesis 5.2.5.4); see the module docstring.

    Args:
        goals: ``(n_goals, 6)`` goal configurations (default :data:`GOALS`).
        max_steps: truncation (200 in the thesis's test).
        max_step: joint increment in rad for an action of 1.
        tolerance: a goal is reached when every joint is within this many rad.
        start: a fixed start configuration ``(6,)`` (the thesis's 10 test starts); default random.
        start_range: half-width of the random starts around :data:`HOME`.
        terminate_on_success: end the episode when every goal is reached (off for recording
            demonstrations, which hold the last goal a few steps before the operator stops).

    Attributes:
        completed: for every finished episode (terminated or truncated), a dict with
            ``goals_reached`` and ``reach_steps`` (the step at which each goal was reached, or -1).
            The vector evaluator resets finished episodes, so the outcome is kept here.

    Used in: UR3 deployment chapter (Table 5.4).
    """

    metadata = {"render_modes": ["rgb_array"], "render_fps": 10}

    def __init__(
        self,
        goals: np.ndarray | None = None,
        max_steps: int = 200,
        max_step: float = 0.1,
        tolerance: float = 0.1,
        start: np.ndarray | None = None,
        start_range: float = START_RANGE,
        terminate_on_success: bool = True,
        render_mode: str | None = None,
    ) -> None:

        self.goals = np.array(GOALS if goals is None else goals, dtype=np.float64)
        if self.goals.ndim != 2 or self.goals.shape[1] != 6:
            raise ValueError(f"Expect goals of shape (n_goals, 6), got {self.goals.shape}.")
        if max_steps < 1 or max_step <= 0 or tolerance <= 0:
            raise ValueError(
                f"Expect max_steps >= 1, max_step > 0 and tolerance > 0; got {max_steps}, {max_step}, {tolerance}."
            )
        self.n_goals = len(self.goals)
        self.max_steps, self.max_step, self.tolerance = (
            int(max_steps),
            float(max_step),
            float(tolerance),
        )
        self.fixed_start = None if start is None else np.asarray(start, dtype=np.float64).reshape(6)
        self.start_range = float(start_range)
        self.terminate_on_success = bool(terminate_on_success)
        self.limits = POSITION_LIMITS
        high = np.concatenate([self.limits[:, 1], np.ones(self.n_goals)]).astype(np.float32)
        low = np.concatenate([self.limits[:, 0], np.zeros(self.n_goals)]).astype(np.float32)
        self.observation_space = gym.spaces.Box(low, high, dtype=np.float32)
        self.action_space = gym.spaces.Box(-1.0, 1.0, (6,), dtype=np.float32)
        self.render_mode = render_mode
        self.completed: list[dict[str, Any]] = []
        self.q = HOME.copy()
        self.reached = np.zeros(self.n_goals, dtype=bool)
        self.reach_steps = np.full(self.n_goals, -1)
        self.t = 0

    def _obs(self) -> np.ndarray:
        return np.concatenate([self.q, self.reached.astype(np.float64)]).astype(np.float32)

    def _info(self) -> dict[str, Any]:
        return {
            "goals_reached": int(self.reached.sum()),
            "reached": self.reached.copy(),
            "q": self.q.copy(),
        }

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        """Start at ``options["start"]``, the fixed start, or ``HOME`` + a random offset."""
        super().reset(seed=seed)
        options = options or {}
        if "start" in options:
            self.q = np.asarray(options["start"], dtype=np.float64).reshape(6).copy()
        elif self.fixed_start is not None:
            self.q = self.fixed_start.copy()
        else:
            self.q = HOME + self.np_random.uniform(-self.start_range, self.start_range, 6)
        self.q = np.clip(self.q, self.limits[:, 0], self.limits[:, 1])
        self.reached = np.zeros(self.n_goals, dtype=bool)
        self.reach_steps = np.full(self.n_goals, -1)
        self.t = 0
        return self._obs(), self._info()

    def step(self, action: np.ndarray):
        a = np.asarray(action, dtype=np.float64).reshape(6)
        if not np.all(np.isfinite(a)):
            raise ValueError(f"Action contains NaN or inf: {a}.")
        a = np.clip(a, -1.0, 1.0)
        self.q = np.clip(self.q + a * self.max_step, self.limits[:, 0], self.limits[:, 1])
        self.t += 1
        _, err = nearest_unreached(self.q, self.goals, self.reached)  # goals open before this move
        reward = -err
        hit = (~self.reached) & (np.abs(self.goals - self.q).max(axis=1) < self.tolerance)
        self.reach_steps[hit] = self.t
        self.reached |= hit
        terminated = bool(self.reached.all()) and self.terminate_on_success
        truncated = (not terminated) and self.t >= self.max_steps
        if terminated or truncated:
            self.completed.append(
                {
                    "goals_reached": int(self.reached.sum()),
                    "reach_steps": self.reach_steps.copy(),
                    "steps": self.t,
                }
            )
        return self._obs(), float(reward), terminated, truncated, self._info()

    def render(self):
        if self.render_mode != "rgb_array":
            return None

        return render_frames(self.q[None])[0]


if ENV_ID not in gym.registry:
    gym.register(ENV_ID, entry_point="thesis_lib.ur3.reach:UR3ReachEnv")


@dataclass
class TeleopController:
    """A scripted stand-in for the thesis's teleoperation: through the goals in sequence.

    ``action = clip(gain * (g - q) / max_step + wobble, -1, 1)``, where the wobble is an
    Ornstein-Uhlenbeck process (the operator's hand) scaled down near the goal.

    Used in: UR3 deployment chapter (Table 5.4 demonstrations).
    """

    gain: float = 0.6
    """Proportional gain: the fraction of the remaining error closed per step (before saturation)."""
    noise: float = 0.15
    """Scale of the wobble (in action units)."""
    theta: float = 0.3
    """OU mean reversion per step."""
    order: str = "sequence"
    """``"sequence"``: the goals in their listed order, as the thesis's operator went "through the
    sequence of goal positions"; ``"nearest"``: the nearest unreached goal first; ``"random"``:
    a new random order for each demonstration (operators who each choose their own way)."""
    seed: int = 0
    """Seed of the controller's own generator."""

    def __post_init__(self) -> None:
        if self.order not in ("sequence", "nearest", "random"):
            raise ValueError(f"Unknown order {self.order!r}. Valid: sequence, nearest, random.")
        self.rng = np.random.default_rng(self.seed)
        self.ou = np.zeros(6)
        self.route: np.ndarray | None = None

    def reset(self) -> None:
        """Clear the wobble and, for ``order="random"``, draw the episode's order of the goals
        (call at each episode start)."""
        self.ou = np.zeros(6)
        self.route = None

    def __call__(self, env: UR3ReachEnv) -> np.ndarray:
        if self.order == "nearest":
            k, _ = nearest_unreached(env.q, env.goals, env.reached)
        elif self.order == "random":
            if self.route is None or len(self.route) != env.n_goals:
                self.route = self.rng.permutation(env.n_goals)
            left = [g for g in self.route if not env.reached[g]]
            k = int(left[0]) if left else -1
        else:
            open_ = np.flatnonzero(~env.reached)
            k = int(open_[0]) if open_.size else -1
        if k < 0:
            return np.zeros(6, dtype=np.float32)
        e = env.goals[k] - env.q
        self.ou += -self.theta * self.ou + self.rng.normal(0.0, 1.0, 6) * self.noise
        fade = min(1.0, float(np.abs(e).max()) / 0.5)  # steady hand close to the goal
        a = self.gain * e / env.max_step + fade * self.ou
        return np.clip(a, -1.0, 1.0).astype(np.float32)


def make_demonstrations(
    n: int = 100,
    seed: int = 0,
    env_kwargs: dict | None = None,
    controller: TeleopController | None = None,
    hold_steps: int = 3,
) -> list:
    """``n`` scripted demonstrations from random starts, as :class:`thesis_lib.data.Episode` s.

    Episode ``i`` starts from ``reset(seed=seed + i)``. Each runs until all goals are reached,
    then holds still for ``hold_steps`` more steps and ends (``truncations[-1]``), as an
    operator who stops recording. The hold matters: without it no demonstration *state* has
    the last goal's one-hot entry set (only the final observation does), its standard
    deviation is 0, and the z-scored HDT sub-goal that is the final observation explodes.

    Used in: UR3 deployment chapter (Table 5.4).
    """
    if n < 1:
        raise ValueError(f"Expect n >= 1 demonstrations, got {n}.")
    env = UR3ReachEnv(**{"terminate_on_success": False, **(env_kwargs or {})})
    ctrl = controller or TeleopController(seed=seed)
    episodes = []
    for i in range(n):
        obs, _ = env.reset(seed=seed + i)
        ctrl.reset()
        obs_l, A, R, term, trunc = [obs], [], [], [], []
        done, hold = False, 0
        while not done:
            a = ctrl(env)
            obs, r, te, tr, _ = env.step(a)
            hold += bool(env.reached.all())
            tr = tr or hold > hold_steps  # the operator stops recording
            obs_l.append(obs)
            A.append(a)
            R.append(r)
            term.append(te)
            trunc.append(tr)
            done = te or tr
        episodes.append(
            Episode(
                id=i,
                observations=np.array(obs_l, dtype=np.float32),
                actions=np.array(A, dtype=np.float32),
                rewards=np.array(R, dtype=np.float64),
                terminations=np.array(term, dtype=bool),
                truncations=np.array(trunc, dtype=bool),
            )
        )
    return episodes


def get_reach_dataset(
    n_demos: int = 100,
    seed: int = 0,
    overwrite: bool = False,
    root: Any = None,
    reach_set: str = "teleop",
):
    """The demonstrations as a Minari data set (made on first use): ``reach_set`` of
    :data:`REACH_SETS`, ``thesis/ur3-reach/teleop-v0`` by default.

    Made again when the stored set was made with other settings (size, seed, controller, goals).

    Returns:
        The :class:`thesis_lib.data.OfflineDataset`.

    Used in: UR3 deployment chapter (Table 5.4).
    """
    if reach_set not in REACH_SETS:
        raise ValueError(f"Unknown reach_set {reach_set!r}. Valid: {', '.join(REACH_SETS)}.")
    spec = REACH_SETS[reach_set]
    dataset_id = spec["id"]
    ctrl = TeleopController(seed=seed, order=spec["order"])
    info = {
        "algorithm": "thesis_lib.ur3.reach.TeleopController",
        "n_demos": int(n_demos),
        "seed": int(seed),
        "controller": {k: getattr(ctrl, k) for k in ("gain", "noise", "theta", "order")},
        "goals": GOALS.tolist(),
        "hold_steps": 3,
        "version": 4,
    }
    if not overwrite and root is None and find_dataset(dataset_id) is not None:
        ds = load(dataset_id)
        if ds.metadata.get("thesis_info", {}) == info:
            return ds
    episodes = make_demonstrations(n_demos, seed, controller=ctrl)
    path = write_dataset(
        dataset_id,
        episodes,
        ENV_ID,
        description="UR3 reaching (thesis 5.2.5.4): scripted "
        f"teleoperation-like demonstrations through five goal joint configurations; {spec['about']}.",
        info=info,
        root=root,
    )
    if root is not None:
        return OfflineDataset(
            id=dataset_id,
            episodes=episodes,
            env_id=ENV_ID,
            ref_min_score=None,
            ref_max_score=None,
            metadata={"thesis_info": info},
            path=path,
        )
    return load(dataset_id)


@dataclass
class ReachDemos:
    """The thesis's split of the 100 demonstrations: 80 train, 10 validation, 10 test starts."""

    train: list
    validation: list
    test_starts: np.ndarray
    """``(n_test, 6)`` initial joint angles of the test demonstrations."""


def split_demonstrations(
    episodes: list, n_train: int = 80, n_val: int = 10, n_test: int = 10
) -> ReachDemos:
    """Split in order: the first ``n_train`` train, the next ``n_val`` validate, the next ``n_test`` give starts."""
    need = n_train + n_val + n_test
    if len(episodes) < need:
        raise ValueError(
            f"Need {need} demonstrations ({n_train} train + {n_val} validation + {n_test} test), "
            f"got {len(episodes)}."
        )
    eps = list(episodes)
    starts = np.array(
        [np.asarray(e.observations[0][:6], dtype=np.float64) for e in eps[n_train + n_val : need]]
    )
    return ReachDemos(eps[:n_train], eps[n_train : n_train + n_val], starts)
