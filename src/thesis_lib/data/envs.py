"""The environment of a task: :func:`make_env` (``gymnasium.make`` as the data sets were made).

Below :mod:`~thesis_lib.data.storage` (a stored set recovers its environment with it) and
:mod:`~thesis_lib.data.recipe` (which re-exports it); above :mod:`~thesis_lib.data.maze`.
"""

from __future__ import annotations

import warnings

import gymnasium as gym

from .maze import fixed_target_maze
from .robotics import forget_maze_xml, register_robotics, robotics_notice
from .tasks import get_task

__all__ = ["make_env"]


def make_env(task: str, **kwargs: object):  # -> gym.Env
    """``gymnasium.make`` for ``task``, with its episode limit (and robotics envs registered);
    a Maze2D task as D4RL's maze2d, with its layout's fixed target
    (:func:`thesis_lib.data.maze.fixed_target_maze`)."""
    spec = get_task(task)
    if spec.kind in ("maze", "robotics"):
        register_robotics()
        if spec.env_id.startswith("AdroitHand") and robotics_notice():
            warnings.warn(robotics_notice(), stacklevel=2)
    kw = {**spec.env_kwargs, **kwargs}
    if spec.kind == "maze":  # D4RL's maze2d: one fixed target per layout (data and evaluation)
        return fixed_target_maze(spec.env_id, max_episode_steps=spec.max_episode_steps, **kw)
    return forget_maze_xml(gym.make(spec.env_id, max_episode_steps=spec.max_episode_steps, **kw))
