"""Scripted Maze2D expert: BFS over the maze grid + a PD waypoint controller.

D4RL made its ``maze2d`` data sets this way: a planner gives waypoints through the maze
cells, a PD controller tracks them, and Gaussian noise is added to the actions. Here the
maze is gymnasium-robotics' PointMaze (same point mass, same layouts), sparse reward
(1 within 0.45 of the goal).

Used by the Maze2D experiments of HDT 5.2 and Decision Mamba 5.3.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass

import numpy as np


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


@dataclass
class WaypointExpert:
    """PD controller towards the next BFS waypoint, with Gaussian action noise.

    Call :meth:`reset` with the environment at the start of each episode, then
    ``expert(obs, rng)`` each step.

    Attributes:
        p_gain: proportional gain on the position error (D4RL: 10).
        d_gain: damping on the velocity (D4RL: −1 · velocity).
        noise_std: std of the Gaussian noise added to the action before clipping.
    """

    p_gain: float = 10.0
    d_gain: float = 1.0
    noise_std: float = 0.5

    def reset(self, env: object) -> None:
        """Read the maze and the goal from ``env`` (a PointMaze, possibly wrapped)."""
        u = env.unwrapped  # type: ignore[attr-defined]
        self._maze = u.maze
        self._goal = np.asarray(u.goal[:2], dtype=np.float64).copy()
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
        a = self.p_gain * (self.target(pos) - pos) - self.d_gain * vel
        if self.noise_std > 0:
            a = a + self.noise_std * rng.standard_normal(2)
        return np.clip(a, -1.0, 1.0).astype(np.float32)
