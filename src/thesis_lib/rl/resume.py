"""Checkpoints of an SB3 training run, taken between episodes, from which the run continues bit
for bit: the resumed run's episodes and networks are those of the run that was never stopped.

:func:`~thesis_lib.rl.train` with ``checkpoint=<folder>`` uses them. It learns in chunks
(``learn(reset_num_timesteps=False)``, which SB3 continues exactly). After each chunk it finishes
the running episode one step at a time, then saves at that episode boundary:

- the model, with SB3's ``save``: networks, optimisers, entropy coefficient, counters;
- the filled part of the replay buffer;
- every random state the rest of the run draws from: torch's, NumPy's, Python's, the action
  space's, and the environment's **as it was before its last reset**. On resume that reset is
  made again, so no simulator state needs saving;
- the episode log, and the wall and CPU seconds spent so far;
- the state of each wrapper in the env's chain, and of each extra callback, that has
  ``state_dict``/``load_state_dict``. DEFENDER's filter has them: its dynamics model and its
  episode log.

Why by hand: SB3's ``CheckpointCallback`` saves the model (and optionally the buffer) at any step.
It does not save the random states or the running episode, so a run continued from it is a
different run. We know of no library that continues an SB3 run exactly.

Limits, each refused with a clear error: one env copy, ``train_freq`` 1, plain ``Box`` replay
buffers, callbacks without ``state_dict``. Not refused: a wrapper that keeps state across episodes
without ``state_dict`` (gymnasium's ``NormalizeObservation``) starts that state again on resume.
Work done after the last checkpoint is lost when a run is killed, and its CPU time is not counted
in the resumed run's cost. Checkpoints are flushed to disk before they are named, and the one
before is kept, so a crash of the machine leaves one that loads.

Used in: DEFENDER (thesis 4.3), through its study's tasks (``thesis study 03_defender``).
"""

from __future__ import annotations

import os
import random
import shutil
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import torch
from stable_baselines3.common.base_class import BaseAlgorithm
from stable_baselines3.common.buffers import ReplayBuffer

from thesis_lib._io import atomic_write
from thesis_lib.rl.callbacks import wrapper_chain

CHECKPOINT_VERSION = 1
"""Format of the files :func:`save_checkpoint` writes; another version is refused on load."""

LATEST = "LATEST"
"""The file of a checkpoint folder that names its newest complete checkpoint."""


class ResetRecorder(gym.Wrapper):
    """Keeps what the environment's last reset drew from: the state of its random generator just
    before the reset, and the seed the reset was given (None for SB3's automatic resets).

    A checkpoint saves them. On resume the environment is put back in that state and reset again,
    which gives the same first observation and the same simulator state (for an environment
    whose reset draws only from its ``np_random``, as gymnasium's do).

    Example:
        >>> env = ResetRecorder(gym.make("Pendulum-v1"))
        >>> _ = env.reset(seed=3)
        >>> env.seed_of_reset
        3
        >>> first, _ = env.reset()
        >>> env.unwrapped.np_random.bit_generator.state = env.rng_before_reset
        >>> again, _ = env.reset()
        >>> bool((first == again).all())
        True
    """

    def __init__(self, env: gym.Env) -> None:
        super().__init__(env)
        self.rng_before_reset: dict[str, Any] | None = None
        self.seed_of_reset: int | None = None

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[Any, dict[str, Any]]:
        rng = getattr(self.env.unwrapped, "_np_random", None)
        self.rng_before_reset = None if rng is None else dict(rng.bit_generator.state)
        self.seed_of_reset = seed
        return self.env.reset(seed=seed, options=options)


def stateful_parts(objects: Sequence[Any]) -> list[Any]:
    """The objects of ``objects`` that a checkpoint saves and restores: those with
    ``state_dict`` and ``load_state_dict`` methods."""
    return [
        o
        for o in objects
        if callable(getattr(o, "state_dict", None))
        and callable(getattr(o, "load_state_dict", None))
    ]


def env_fingerprint(env: gym.Env) -> str:
    """What a checkpoint records of the env it was taken on, to refuse resuming on another:
    gymnasium's ``str`` of the wrapper chain, and the ``repr`` of each layer whose class writes
    its own (DEFENDER's filter names its strategies there). No memory addresses, so the same
    env built again matches.

    >>> env_fingerprint(gym.make("Pendulum-v1"))
    '<TimeLimit<OrderEnforcing<PassiveEnvChecker<PendulumEnv<Pendulum-v1>>>>>'
    """
    own = [
        repr(layer)
        for layer in wrapper_chain(env)
        if type(layer).__repr__ not in (object.__repr__, gym.Env.__repr__, gym.Wrapper.__repr__)
    ]
    return " ".join([str(env), *own])


def _buffer_state(buffer: ReplayBuffer) -> dict[str, Any]:
    n = buffer.buffer_size if buffer.full else buffer.pos
    arrays = {
        name: value[:n].copy()
        for name, value in vars(buffer).items()
        if isinstance(value, np.ndarray) and value.shape[:1] == (buffer.buffer_size,)
    }
    return {
        "class": type(buffer).__name__,
        "buffer_size": buffer.buffer_size,
        "pos": buffer.pos,
        "full": buffer.full,
        "arrays": arrays,
    }


def _load_buffer(buffer: ReplayBuffer, state: Mapping[str, Any]) -> None:
    if state["class"] != type(buffer).__name__ or state["buffer_size"] != buffer.buffer_size:
        raise ValueError(
            f"The checkpoint's replay buffer ({state['class']} of {state['buffer_size']}) does not "
            f"fit the model's ({type(buffer).__name__} of {buffer.buffer_size})."
        )
    for name, value in state["arrays"].items():
        getattr(buffer, name)[: len(value)] = value
    buffer.pos, buffer.full = int(state["pos"]), bool(state["full"])


def _replay_buffer(model: BaseAlgorithm) -> ReplayBuffer:
    buffer = getattr(model, "replay_buffer", None)
    if type(buffer) is not ReplayBuffer:
        raise ValueError(
            f"Checkpointed training saves a plain ReplayBuffer, got {type(buffer).__name__}."
        )
    return buffer


def check_resumable(model: BaseAlgorithm) -> None:
    """Raise ``ValueError`` where :func:`save_checkpoint` could not continue ``model`` exactly."""
    vec_env = model.get_env()
    n_envs = 0 if vec_env is None else vec_env.num_envs
    if n_envs != 1:
        raise ValueError(
            f"Checkpointed training needs one env copy, got {n_envs}: a checkpoint is taken "
            "between episodes, and copies end their episodes at different steps."
        )
    freq = getattr(model, "train_freq", None)
    if freq is None or freq.frequency != 1 or freq.unit.value != "step":
        raise ValueError(
            f"Checkpointed training needs train_freq 1 (one update per env step), got {freq}: "
            "otherwise the chunks it learns in would not split the run where it splits itself."
        )
    _replay_buffer(model)


def _steps_of(part: Path) -> int:
    return int(part.name.split("-", 1)[1])


def _read_state(part: Path) -> dict[str, Any] | None:
    """The state of the checkpoint ``part``, or None where it is incomplete or unreadable."""
    files = [part / f for f in ("state.pt", "model.zip", "buffer.pt")]
    if not all(f.is_file() and f.stat().st_size > 0 for f in files):
        return None
    try:
        return dict(torch.load(part / "state.pt", weights_only=False))
    except Exception:  # a file cut short by a crash of the machine: try the one before
        return None


def latest_checkpoint(folder: str | Path, run: Mapping[str, Any] | None = None) -> Path | None:
    """The newest checkpoint in ``folder`` that loads, or None where there is none: the one
    ``LATEST`` names, else (a crash cut it short) the one before it.

    Raises:
        ValueError: with ``run``, a checkpoint taken of another run: one whose ``run`` entries
            (config, env, parts) differ from ``run``'s.
    """
    folder = Path(folder)
    pointer = folder / LATEST
    named = folder / pointer.read_text().strip() if pointer.is_file() else None
    others = sorted(folder.glob("step-*"), key=_steps_of, reverse=True)
    for part in [p for p in [named] if p is not None] + [p for p in others if p != named]:
        state = _read_state(part)
        if state is None:
            continue
        if run is not None:
            differ = sorted(k for k in run if state.get(k) != run[k])
            if differ:
                raise ValueError(
                    f"{part} is a checkpoint of another run (its {', '.join(differ)} differ from "
                    "this one's); remove the folder or give another."
                )
        return part
    return None


def _fsync(path: Path) -> None:
    fd = os.open(path, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def save_checkpoint(
    folder: str | Path,
    model: BaseAlgorithm,
    recorder: ResetRecorder,
    parts: Mapping[str, Any],
    extra: Mapping[str, Any],
) -> Path:
    """Save ``model``'s run at an episode boundary into ``folder``; return the checkpoint's path.

    ``parts``: named objects with ``state_dict`` (the episode logger, stateful wrappers and
    callbacks). ``extra``: anything else to keep (what run it is, seconds spent). The checkpoint
    is written under a temporary name, flushed to disk, renamed, and only then named in
    ``LATEST``. The checkpoint before it is kept; older ones are removed. A run killed while
    saving keeps its previous checkpoint.
    """
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    name = f"step-{int(model.num_timesteps):010d}"
    tmp = folder / f".{name}.tmp"
    shutil.rmtree(tmp, ignore_errors=True)
    tmp.mkdir()
    model.save(tmp / "model.zip")
    torch.save(_buffer_state(_replay_buffer(model)), tmp / "buffer.pt")
    cuda = torch.cuda.is_available() and torch.cuda.is_initialized()
    state = {
        "version": CHECKPOINT_VERSION,
        "num_timesteps": int(model.num_timesteps),
        "rng": {
            "torch": torch.get_rng_state(),
            "cuda": torch.cuda.get_rng_state_all() if cuda else None,
            "numpy": np.random.get_state(),  # noqa: NPY002 (SB3 seeds the legacy global RNG)
            "python": random.getstate(),
            "action_space": dict(model.action_space.np_random.bit_generator.state),
            "env_before_reset": recorder.rng_before_reset,
            "env_reset_seed": recorder.seed_of_reset,
        },
        "parts": {key: part.state_dict() for key, part in parts.items()},
        **extra,
    }
    torch.save(state, tmp / "state.pt")
    for f in ("model.zip", "buffer.pt", "state.pt"):
        _fsync(tmp / f)
    _fsync(tmp)
    final = folder / name
    shutil.rmtree(final, ignore_errors=True)
    os.replace(tmp, final)
    _fsync(folder)

    def write_pointer(path: Path) -> None:
        path.write_text(name)
        _fsync(path)

    atomic_write(folder / LATEST, write_pointer)
    _fsync(folder)
    for old in sorted(folder.glob("step-*"), key=_steps_of)[:-2]:
        shutil.rmtree(old, ignore_errors=True)
    for stale in folder.glob(".step-*.tmp"):  # a save a kill cut short
        shutil.rmtree(stale, ignore_errors=True)
    return final


def load_checkpoint(
    path: str | Path,
    algo_cls: type[BaseAlgorithm],
    env: ResetRecorder,
    parts: Mapping[str, Any],
    device: str | torch.device = "auto",
) -> tuple[BaseAlgorithm, dict[str, Any]]:
    """The model of the checkpoint at ``path`` on ``env`` (a fresh env of the same run), with its
    replay buffer and random states restored and ``parts`` loaded; and the checkpoint's whole
    state (with the ``extra`` entries it was saved with). The next ``learn`` call resets ``env``
    as the saved run did.

    Raises:
        ValueError: a checkpoint of another format version, or ``parts`` other than its own.
    """
    path = Path(path)
    state = torch.load(path / "state.pt", weights_only=False)
    if state.get("version") != CHECKPOINT_VERSION:
        raise ValueError(
            f"{path} is a checkpoint of format {state.get('version')}, this code reads "
            f"{CHECKPOINT_VERSION}; remove the folder to start the run again."
        )
    if set(parts) != set(state["parts"]):
        raise ValueError(
            f"{path} holds the state of {', '.join(sorted(state['parts']))}, this run has "
            f"{', '.join(sorted(parts))}."
        )
    model = algo_cls.load(path / "model.zip", env=env, device=device)
    _load_buffer(_replay_buffer(model), torch.load(path / "buffer.pt", weights_only=False))
    for key, part in parts.items():
        part.load_state_dict(state["parts"][key])
    # `load` re-seeds everything with the run's seed: put back where the run was instead.
    rng = state["rng"]
    torch.set_rng_state(rng["torch"])
    if rng.get("cuda") is not None and torch.cuda.is_available():
        torch.cuda.set_rng_state_all(rng["cuda"])
    np.random.set_state(rng["numpy"])  # noqa: NPY002 (SB3 seeds the legacy global RNG)
    random.setstate(rng["python"])
    model.action_space.np_random.bit_generator.state = rng["action_space"]
    vec_env = model.get_env()
    assert vec_env is not None
    vec_env._reset_seeds()  # the seed `load` set would otherwise drive the next reset
    if rng["env_reset_seed"] is not None:
        vec_env.seed(int(rng["env_reset_seed"]))
    elif rng["env_before_reset"] is not None:
        env.unwrapped.np_random.bit_generator.state = rng["env_before_reset"]
    return model, state
