"""Maze2D as D4RL defines it: a fixed evaluation target per layout, and a scripted expert.

D4RL's ``maze2d`` (``d4rl/pointmaze/maze_model.py``): each layout has one goal cell ``G``, the
evaluation target, fixed for every episode; the sparse reward is 1 within 0.5 of it. The data
were recorded by a BFS waypoint planner with a PD controller and Gaussian action noise (std
0.5), driven to *randomly drawn* goals, one after another; the rewards count the fixed target.
Here the maze is gymnasium-robotics' PointMaze (same point mass, same layouts: checked in the
tests) made with :func:`fixed_target_maze`, so evaluation and data share the target, and the
expert (:class:`WaypointExpert` with ``random_goals=True``) visits random goals as D4RL's did.
Models see the observation (position, velocity) only, as in D4RL; they need no goal input
because the target never moves.

Used by the Maze2D experiments of HDT 5.2 and Decision Mamba 5.3.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass, field
from typing import Any

import gymnasium as gym
import numpy as np

from .robotics import forget_maze_xml, register_robotics

#: D4RL's evaluation target per layout: the ``G`` cell (row, column) of its maze strings
#: (``U_MAZE``, ``MEDIUM_MAZE``, ``LARGE_MAZE``, ``OPEN`` in ``d4rl/pointmaze/maze_model.py``),
#: in gymnasium-robotics' maps of the same layouts.
D4RL_TARGET_CELLS: dict[str, tuple[int, int]] = {
    "PointMaze_UMaze-v3": (1, 1),
    "PointMaze_Medium-v3": (6, 6),
    "PointMaze_Large-v3": (7, 9),
    "PointMaze_Open-v3": (2, 3),
}
#: D4RL's sparse reward: 1 within this distance of the target (gymnasium-robotics: 0.45).
D4RL_TARGET_RADIUS = 0.5


def _free(cell: object) -> bool:
    return cell != 1 and cell != "1"


def bfs_distances(maze_map: list[list[object]], goal: tuple[int, int]) -> np.ndarray:
    """Grid distance (in cells) from every free cell to ``goal``; walls and unreachable = -1.

    >>> bfs_distances([[1, 1, 1], [1, 0, 0], [1, 1, 1]], (1, 2)).tolist()
    [[-1, -1, -1], [-1, 1, 0], [-1, -1, -1]]

    Args:
        maze_map: rows of 1 (wall) / anything else (free), as PointMaze's ``maze_map``.
        goal: ``(row, col)`` of the goal cell.

    Returns:
        ``(n_rows, n_cols)`` int array.
    """
    h, w = len(maze_map), len(maze_map[0])
    dist = -np.ones((h, w), dtype=np.int64)
    dist[goal] = 0
    q = deque([goal])
    while q:
        r, c = q.popleft()
        for dr, dc in ((1, 0), (-1, 0), (0, 1), (0, -1)):
            nr, nc = r + dr, c + dc
            if 0 <= nr < h and 0 <= nc < w and dist[nr, nc] < 0 and _free(maze_map[nr][nc]):
                dist[nr, nc] = dist[r, c] + 1
                q.append((nr, nc))
    return dist


class FixedTarget(gym.Wrapper, gym.utils.RecordConstructorArgs):
    """A PointMaze whose target is D4RL's fixed evaluation target of its layout.

    Every reset puts the target at the centre of the layout's ``G`` cell
    (:data:`D4RL_TARGET_CELLS`), exactly (gymnasium-robotics would add uniform noise), and the
    start anywhere else, as PointMaze draws it. Each step's reward is D4RL's sparse one: 1 when
    the point is within :data:`D4RL_TARGET_RADIUS` of the target, else 0; the episode never
    ends early (D4RL's maze2d is a continuing task), and ``info["success"]`` says whether the
    point is at the target. Make it with :func:`fixed_target_maze`.
    """

    def __init__(self, env: Any, cell: tuple[int, int]):
        gym.utils.RecordConstructorArgs.__init__(self, cell=tuple(cell))
        gym.Wrapper.__init__(self, env)
        self.cell = (int(cell[0]), int(cell[1]))
        maze = env.unwrapped.maze
        if maze.maze_map[self.cell[0]][self.cell[1]] in (1, "1"):
            raise ValueError(f"Target cell {self.cell} is a wall of {env.spec.id}.")
        self.target = np.asarray(maze.cell_rowcol_to_xy(np.array(self.cell)), dtype=np.float64)

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        obs, info = self.env.reset(seed=seed, options={**(options or {}), "goal_cell": self.cell})
        u: Any = self.env.unwrapped
        u.goal = self.target.copy()  # no position noise on the target
        u.update_target_site_pos()
        obs = {**obs, "desired_goal": self.target.copy()}
        return obs, info

    def step(self, action: Any):
        obs, _, _, trunc, info = self.env.step(action)
        at = float(np.linalg.norm(np.asarray(obs["achieved_goal"]) - self.target))
        success = at <= D4RL_TARGET_RADIUS
        info = {**info, "success": success}
        return {**obs, "desired_goal": self.target.copy()}, float(success), False, trunc, info


def fixed_target_maze(env_id: str, **kwargs: Any) -> Any:
    """``gymnasium.make(env_id)`` of a PointMaze as D4RL's maze2d: the fixed target of
    :class:`FixedTarget` (the goal never resets: ``continuing_task=True, reset_target=False``).

    Raises:
        ValueError: ``env_id`` has no D4RL target (:data:`D4RL_TARGET_CELLS`).
    """
    if env_id not in D4RL_TARGET_CELLS:
        raise ValueError(f"No D4RL target for '{env_id}'. Known: {', '.join(D4RL_TARGET_CELLS)}.")
    register_robotics()
    kw = {"continuing_task": True, "reset_target": False, **kwargs}
    env = forget_maze_xml(gym.make(env_id, **kw))
    return FixedTarget(env, D4RL_TARGET_CELLS[env_id])


@dataclass
class WaypointExpert:
    """PD controller towards the next BFS waypoint, with Gaussian action noise.

    Call :meth:`reset` with the environment at the start of each episode, then
    ``expert(obs, rng)`` each step.

    Attributes:
        p_gain: proportional gain on the position error (D4RL: 10).
        d_gain: damping on the velocity (D4RL: −1 · velocity).
        noise_std: std of the Gaussian noise added to the action before clipping.
        random_goals: drive to goals of its own, as D4RL's data recorder did: a free cell
            drawn at random (plus uniform noise of ±0.1, D4RL's ``set_target``), and a new one
            each time the point comes within :data:`D4RL_TARGET_RADIUS` of it; the draws come
            from ``rng`` (seeded by the roll-out). ``False``: drive to the env's own goal.
        rng: the source of the random goals.
    """

    p_gain: float = 10.0
    d_gain: float = 1.0
    noise_std: float = 0.5
    random_goals: bool = False
    rng: np.random.Generator = field(default_factory=lambda: np.random.default_rng(0))

    def reset(self, env: object) -> None:
        """Read the maze (and, unless ``random_goals``, the goal) from ``env`` (a PointMaze,
        possibly wrapped)."""
        u = env.unwrapped  # type: ignore[attr-defined]
        self._maze = u.maze
        if self.random_goals:
            self._cells = [
                (r, c)
                for r, row in enumerate(self._maze.maze_map)
                for c, cell in enumerate(row)
                if _free(cell)
            ]
            self._new_goal()
        else:
            self._set_goal(np.asarray(u.goal[:2], dtype=np.float64).copy())

    def _new_goal(self) -> None:
        cell = self._cells[int(self.rng.integers(len(self._cells)))]
        xy = np.asarray(self._maze.cell_rowcol_to_xy(np.array(cell)), dtype=np.float64)
        self._set_goal(xy + self.rng.uniform(-0.1, 0.1, size=2))

    def _set_goal(self, goal: np.ndarray) -> None:
        self._goal = goal
        row, col = self._maze.cell_xy_to_rowcol(self._goal)
        gcell = (int(row), int(col))
        self._dist = bfs_distances(self._maze.maze_map, gcell)
        self._goal_cell = gcell

    def target(self, pos: np.ndarray) -> np.ndarray:
        """Next waypoint for an agent at ``pos`` ``(2,)``: a cell centre or the goal."""
        cell = tuple(int(x) for x in self._maze.cell_xy_to_rowcol(pos))
        if cell == self._goal_cell or self._dist[cell] < 0:
            return self._goal
        best, best_d = cell, self._dist[cell]
        r, c = cell
        for dr, dc in ((1, 0), (-1, 0), (0, 1), (0, -1)):
            nr, nc = r + dr, c + dc
            d = self._dist[nr, nc]
            if d >= 0 and d < best_d:
                best, best_d = (nr, nc), d
        if best == self._goal_cell:
            return self._goal
        return np.asarray(self._maze.cell_rowcol_to_xy(np.array(best)), dtype=np.float64)

    def __call__(self, obs: dict | np.ndarray, rng: np.random.Generator) -> np.ndarray:
        """Action ``(2,)`` in ``[-1, 1]`` for observation ``obs`` (dict or ``(4,)`` array)."""
        o = obs["observation"] if isinstance(obs, dict) else obs
        pos, vel = np.asarray(o[:2], np.float64), np.asarray(o[2:4], np.float64)
        if self.random_goals and np.linalg.norm(pos - self._goal) <= D4RL_TARGET_RADIUS:
            self._new_goal()
        a = self.p_gain * (self.target(pos) - pos) - self.d_gain * vel
        if self.noise_std > 0:
            a = a + self.noise_std * rng.standard_normal(2)
        return np.clip(a, -1.0, 1.0).astype(np.float32)
