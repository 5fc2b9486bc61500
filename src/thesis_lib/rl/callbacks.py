"""SB3 callbacks: a per-episode log (return, length, crash) and a progress bar.

Both read `rewards`, `dones` and `infos` from `self.locals`, the interface SB3 documents for
callbacks (STYLE.md Sec. 9 dislikes it; it is the only way to see every step without
wrapping the env, and it is confined to this module).

Used in: Background (thesis 2.5-2.7), DEFENDER (4.3).
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from typing import Any

import gymnasium as gym
import numpy as np
import pandas as pd
from stable_baselines3.common.callbacks import BaseCallback
from stable_baselines3.common.vec_env import VecEnv

EPISODE_COLUMNS: tuple[str, ...] = (
    "episode", "env_index", "timestep", "return", "length",
    "terminated", "truncated", "crashed", "wall_time_s",
)  # fmt: skip
"""Columns of `EpisodeLogger.episodes`, in order (then any `info_keys`)."""


def find_horizon(env: gym.Env | VecEnv) -> int | None:
    """Episode horizon of `env`: the `max_episode_steps` of its `TimeLimit`, or None if it has none.

    Looks for a `gymnasium.wrappers.TimeLimit` in the wrapper chain first, then at
    `env.spec.max_episode_steps`. For a `VecEnv`, reads the first sub-environment.

    Used in: Background (thesis 2.5-2.7), DEFENDER (4.3).

    Example:
        >>> find_horizon(gym.make("Pendulum-v1"))
        200
        >>> find_horizon(gym.make("Pendulum-v1", max_episode_steps=50))
        50
    """
    if isinstance(env, VecEnv):
        try:  # DummyVecEnv/SubprocVecEnv look the name up through the whole wrapper chain
            return env.get_attr("_max_episode_steps", indices=[0])[0]
        except AttributeError:
            spec = env.get_attr("spec", indices=[0])[0]
            return None if spec is None else spec.max_episode_steps
    for layer in wrapper_chain(env):
        if isinstance(layer, gym.wrappers.TimeLimit):
            return layer._max_episode_steps
    spec = getattr(env, "spec", None)
    return None if spec is None else spec.max_episode_steps


def wrapper_chain(env: gym.Env) -> list[gym.Env]:
    """``env`` and every env it wraps, outermost first.

    >>> [type(e).__name__ for e in wrapper_chain(gym.make("Pendulum-v1"))][-1]
    'PendulumEnv'
    """
    chain: list[gym.Env] = []
    inner: Any = env
    while isinstance(inner, gym.Env):
        chain.append(inner)
        inner = getattr(inner, "env", None)
    return chain


def is_crash(terminated: bool, length: int, horizon: int | None) -> bool:
    """A crash is an episode that terminated before the horizon (thesis 4.3.3).

    Without a horizon (no `TimeLimit`) every termination counts as a crash; an episode that
    was truncated, or that terminated exactly at the horizon, is not one.

    Example:
        >>> is_crash(True, 37, 1000), is_crash(True, 1000, 1000), is_crash(False, 12, 1000)
        (True, False, False)
    """
    return bool(terminated) and (horizon is None or length < horizon)


class EpisodeLogger(BaseCallback):
    """Records one row per finished training episode; read them with `.episodes`.

    Works with any number of env copies. For each copy it sums the raw rewards (before any
    `VecNormalize`) and counts steps; when the copy reports `done` it writes a row:

    - `episode`: 0-based index in order of completion, over all copies;
    - `env_index`: which copy; `timestep`: `model.num_timesteps` at the episode's last step;
    - `return`, `length`: undiscounted sum of rewards and number of steps;
    - `terminated`, `truncated`: Gymnasium's flags, recovered from SB3's `done` and its
      `info["TimeLimit.truncated"]` (SB3 sets that key to `truncated and not terminated`, so an
      episode that ends both ways at once is logged as terminated);
    - `crashed`: terminated before the horizon (`is_crash`);
    - `wall_time_s`: seconds since training started;
    - one column per name in `info_keys`, copied from the episode's last `info` (None if absent),
      e.g. a flag a DEFENDER wrapper sets when its filter ends an episode.

    Episodes still running when training stops are not logged.

    Args:
        horizon: episode horizon for `crashed`; None reads it from the training env's
            `TimeLimit` at training start (`find_horizon`).
        info_keys: names of `info` entries to copy into each row.

    Used in: Background (thesis 2.5-2.7), DEFENDER (4.3).
    """

    def __init__(self, horizon: int | None = None, info_keys: Sequence[str] = ()) -> None:
        super().__init__()
        if horizon is not None and horizon <= 0:
            raise ValueError(f"EpisodeLogger expects a positive horizon or None, got {horizon}.")
        self.horizon = horizon
        self.info_keys = tuple(info_keys)
        self._rows: list[dict[str, Any]] = []
        self._returns = np.zeros(0)
        self._lengths = np.zeros(0, dtype=np.int64)
        self._start = 0.0
        self._earlier_s = 0.0  # wall seconds of a resumed run's earlier parts

    def _on_training_start(self) -> None:
        n_envs = self.training_env.num_envs
        if self.horizon is None:
            self.horizon = find_horizon(self.training_env)
        # `learn(reset_num_timesteps=False)` keeps the env's running episodes; otherwise SB3 resets it.
        if self.locals.get("reset_num_timesteps", True) or len(self._returns) != n_envs:
            self._returns = np.zeros(n_envs)
            self._lengths = np.zeros(n_envs, dtype=np.int64)
            self._start = time.perf_counter() - self._earlier_s

    @property
    def between_episodes(self) -> bool:
        """True when no env copy is inside an episode (before the first step, or right after
        every copy's episode ended): where a checkpoint can be taken (`thesis_lib.rl.resume`)."""
        return not self._lengths.any()

    def state_dict(self) -> dict[str, Any]:
        """The log so far and its clock, taken between episodes (`between_episodes`)."""
        if not self.between_episodes:
            raise RuntimeError("EpisodeLogger.state_dict is taken between episodes only.")
        return {
            "rows": [dict(r) for r in self._rows],
            "elapsed_s": time.perf_counter() - self._start if len(self._returns) else 0.0,
        }

    def load_state_dict(self, state: dict[str, Any]) -> None:
        """Continue the log of `state`: its rows, and its clock for `wall_time_s`."""
        self._rows = [dict(r) for r in state["rows"]]
        self._earlier_s = float(state["elapsed_s"])
        self._returns = np.zeros(0)  # the next training start sizes them
        self._lengths = np.zeros(0, dtype=np.int64)

    def _on_step(self) -> bool:
        rewards = self.locals["rewards"]
        vec_normalize = self.model.get_vec_normalize_env()
        if vec_normalize is not None:
            rewards = vec_normalize.get_original_reward()
        dones, infos = self.locals["dones"], self.locals["infos"]
        self._returns += rewards
        self._lengths += 1
        for i in np.flatnonzero(dones):
            info = infos[i]
            truncated = bool(info.get("TimeLimit.truncated", False))
            terminated = not truncated
            length = int(self._lengths[i])
            row = {
                "episode": len(self._rows),
                "env_index": int(i),
                "timestep": int(self.num_timesteps),
                "return": float(self._returns[i]),
                "length": length,
                "terminated": terminated,
                "truncated": truncated,
                "crashed": is_crash(terminated, length, self.horizon),
                "wall_time_s": time.perf_counter() - self._start,
            }
            row.update({key: info.get(key) for key in self.info_keys})
            self._rows.append(row)
            self._returns[i] = 0.0
            self._lengths[i] = 0
        return True

    @property
    def episodes(self) -> pd.DataFrame:
        """Finished episodes so far, one row each (columns: `EPISODE_COLUMNS` + `info_keys`)."""
        return pd.DataFrame(self._rows, columns=[*EPISODE_COLUMNS, *self.info_keys])

    @property
    def n_episodes(self) -> int:
        """Number of finished episodes so far."""
        return len(self._rows)

    def last_returns(self, n: int) -> list[float]:
        """Returns of the last `n` finished episodes (fewer if fewer have finished)."""
        return [row["return"] for row in self._rows[-n:]]


class ProgressBar(BaseCallback):
    """A tqdm bar over env steps that shows the last episode return and the mean of the last 10.

    SB3's own `progress_bar=True` shows only the step count (and needs `rich`). This bar reads
    the returns from an `EpisodeLogger`, which must be in the same callback list.

    Args:
        logger: the episode logger to read returns from.
        window: how many recent episodes the running mean covers.
        desc: label shown left of the bar (e.g. "TD3 seed 0").
        total: the run's env steps, for a run learnt in several `learn` calls: one bar from the
            model's step count to `total`, closed when it is reached. None: a bar per call.

    Used in: Background (thesis 2.5-2.7), DEFENDER (4.3).
    """

    def __init__(
        self,
        logger: EpisodeLogger,
        window: int = 10,
        desc: str | None = None,
        total: int | None = None,
    ) -> None:
        super().__init__()
        self.episode_logger = logger
        self.window = window
        self.desc = desc
        self.total = total
        self._n_logged = 0
        self._pbar: Any = None

    def _on_training_start(self) -> None:
        from tqdm.auto import tqdm

        if self.total is None:
            total = self.locals["total_timesteps"] - self.model.num_timesteps
            self._pbar = tqdm(total=total, desc=self.desc, unit="step", dynamic_ncols=True)
        elif self._pbar is None:  # a run learnt in chunks: one bar over all, from where it is
            self._pbar = tqdm(
                total=self.total,
                initial=self.model.num_timesteps,
                desc=self.desc,
                unit="step",
                dynamic_ncols=True,
            )

    def _on_step(self) -> bool:
        self._pbar.update(self.training_env.num_envs)
        n_logged = self.episode_logger.n_episodes
        if n_logged != self._n_logged:
            self._n_logged = n_logged
            recent = self.episode_logger.last_returns(self.window)
            postfix = {
                "return": f"{recent[-1]:.1f}",
                f"mean{self.window}": f"{np.mean(recent):.1f}",
                "episodes": n_logged,
            }
            self._pbar.set_postfix(
                postfix, refresh=False
            )  # a dict keeps this order; kwargs get sorted
        return True

    def _on_training_end(self) -> None:
        if self._pbar is None:
            return
        self._pbar.refresh()
        if self.total is None or self.model.num_timesteps >= self.total:
            self.close()

    def close(self) -> None:
        """Close the bar (a run learnt in chunks that stops early or raises)."""
        if self._pbar is not None:
            self._pbar.close()
            self._pbar = None
