"""Two quirks of gymnasium-robotics (Maze2D/PointMaze, AntMaze, Adroit, Kitchen), handled once.

- :func:`register_robotics`: its environments are registered on first use; the notice its
  import prints (the Adroit-v1 reward change) is kept (:func:`robotics_notice`) instead of
  appearing in every chapter that makes a maze.
- :func:`forget_maze_xml`: each maze env writes its MuJoCo model to a temporary file and never
  removes it; this removes it.

The bottom of :mod:`thesis_lib.data`'s environment code: :mod:`~thesis_lib.data.maze` and
:mod:`~thesis_lib.data.envs` build on it.
"""

from __future__ import annotations

import contextlib
import io
import os
import warnings
from typing import Any

__all__ = ["forget_maze_xml", "register_robotics", "robotics_notice"]

_ROBOTICS_NOTICE = ""


def forget_maze_xml(env: Any) -> Any:
    """Delete the model file a gymnasium-robotics maze (PointMaze, AntMaze) wrote; return ``env``.

    Each maze env writes its MuJoCo model to ``<temp dir>/ant_maze<time>.xml`` and never
    removes it (hundreds per book build). The model is loaded once the env is made, so the
    file is removed here; other envs are returned untouched.
    """
    xml = getattr(getattr(env, "unwrapped", env), "tmp_xml_file_path", None)
    if isinstance(xml, str) and os.path.basename(xml).startswith("ant_maze"):
        with contextlib.suppress(FileNotFoundError):
            os.remove(xml)
    return env


def register_robotics() -> None:
    """Register gymnasium-robotics' environments once.

    Its import prints a notice about the Adroit-v1 reward change to stderr; it would appear in
    every chapter that makes a maze, so it is kept (:func:`robotics_notice`) and raised as a
    warning for Adroit tasks only (:func:`thesis_lib.data.make_env`).
    """
    global _ROBOTICS_NOTICE
    import gymnasium as gym

    buf = io.StringIO()
    with warnings.catch_warnings(), contextlib.redirect_stderr(buf):
        warnings.simplefilter("ignore")
        import gymnasium_robotics  # lazy: gymnasium_robotics

        gym.register_envs(gymnasium_robotics)
    _ROBOTICS_NOTICE = _ROBOTICS_NOTICE or buf.getvalue().strip()


def robotics_notice() -> str:
    """What gymnasium-robotics printed on import ("" before :func:`register_robotics`)."""
    return _ROBOTICS_NOTICE
