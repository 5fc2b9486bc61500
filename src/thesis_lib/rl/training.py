"""Training, learning curves and evaluation for SB3's SAC, TD3 and DDPG.

Used in: Background (thesis 2.5-2.7), CLfD (4.2), DEFENDER (4.3).
"""

from __future__ import annotations

import copy
import json
import time
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import asdict, fields
from pathlib import Path
from typing import Any, NamedTuple, Protocol

import gymnasium as gym
import numpy as np
import pandas as pd
import torch
from stable_baselines3.common.base_class import BaseAlgorithm
from stable_baselines3.common.callbacks import BaseCallback, CallbackList
from stable_baselines3.common.env_util import make_vec_env
from stable_baselines3.common.logger import Logger
from stable_baselines3.common.noise import (
    ActionNoise,
    NormalActionNoise,
    OrnsteinUhlenbeckActionNoise,
    VectorizedActionNoise,
)
from stable_baselines3.common.utils import set_random_seed
from stable_baselines3.common.vec_env import VecEnv

from thesis_lib.rl.callbacks import (
    EPISODE_COLUMNS,
    EpisodeLogger,
    ProgressBar,
    find_horizon,
    is_crash,
    wrapper_chain,
)
from thesis_lib.rl.config import RLConfig, algo_class, did_you_mean
from thesis_lib.rl.resume import (
    ResetRecorder,
    check_resumable,
    env_fingerprint,
    latest_checkpoint,
    load_checkpoint,
    save_checkpoint,
    stateful_parts,
)

CURVE_COLUMNS: tuple[str, ...] = ("algo", "seed", *EPISODE_COLUMNS)
"""Columns of `learning_curves`, in order."""

EVAL_COLUMNS: tuple[str, ...] = (
    "episode",
    "return",
    "length",
    "terminated",
    "truncated",
    "crashed",
)
"""Columns of `evaluate`, in order."""


class TrainResult(NamedTuple):
    """What `train` returns.

    Used in: Background (thesis 2.5-2.7), CLfD (4.2), DEFENDER (4.3).
    """

    model: BaseAlgorithm
    """The trained SB3 model (`model.predict(obs, deterministic=True)` acts)."""
    episodes: pd.DataFrame
    """One row per finished training episode (`EpisodeLogger.episodes`)."""
    config: RLConfig
    """The configuration that was run."""
    wall_time_s: float
    """Seconds spent in training, checkpoints included (a resumed run: with its earlier
    parts)."""
    cpu_time_s: float = float("nan")
    """CPU seconds of this process spent in training (a resumed run: with its earlier parts)."""
    resumed_cpu_s: float = 0.0
    """Of `cpu_time_s`, the CPU seconds of the earlier parts a resumed run continued (0 where it
    ran in one go)."""


class Predictor(Protocol):
    """Anything that acts like an SB3 model: `predict(obs, state, episode_start, deterministic)`."""

    def predict(
        self,
        observation: Any,
        state: Any = None,
        episode_start: Any = None,
        deterministic: bool = False,
    ) -> tuple[Any, Any]: ...


def config_from_params(params: Mapping[str, Any]) -> RLConfig:
    """Build an `RLConfig` from a mapping (a notebook's parameters), rejecting unknown names.

    Raises:
        ValueError: a name is not an `RLConfig` field; the message suggests the closest one.

    Used in: Background (thesis 2.5-2.7), DEFENDER (4.3).

    Example:
        >>> config_from_params({"algo": "TD3", "total_timestep": 10})  # doctest: +ELLIPSIS
        Traceback (most recent call last):
        ...
        ValueError: Unknown RLConfig parameter 'total_timestep'. Did you mean: 'total_timesteps'? Valid: ...
    """
    valid = [f.name for f in fields(RLConfig) if f.init]
    for name in params:
        if name not in valid:
            raise ValueError(
                f"Unknown RLConfig parameter {name!r}.{did_you_mean(name, valid)} Valid: {', '.join(valid)}."
            )
    return RLConfig(**params)


def make_action_noise(
    kind: str | None, sigma: float, n_actions: int, n_envs: int = 1
) -> ActionNoise | None:
    """Exploration noise for TD3/DDPG: Gaussian or Ornstein-Uhlenbeck with std `sigma` per dimension.

    Args:
        kind: "normal", "ornstein-uhlenbeck" or None (no noise).
        sigma: noise standard deviation, in units of the normalised action.
        n_actions: action dimension.
        n_envs: env copies; each gets its own noise process.

    Used in: Background (thesis 2.5-2.6), DEFENDER (4.3).
    """
    if kind is None or sigma == 0:
        return None
    mean, std = np.zeros(n_actions), sigma * np.ones(n_actions)
    noise_cls = {"normal": NormalActionNoise, "ornstein-uhlenbeck": OrnsteinUhlenbeckActionNoise}[
        kind
    ]
    noise = noise_cls(mean=mean, sigma=std)
    return VectorizedActionNoise(noise, n_envs) if n_envs > 1 else noise


def _policy_for(env: gym.Env | VecEnv) -> str:
    return "MultiInputPolicy" if isinstance(env.observation_space, gym.spaces.Dict) else "MlpPolicy"


def silent_logger() -> Logger:
    """An SB3 logger that keeps its records in memory and writes no file.

    SB3's default (`configure_logger`) creates an empty `SB3-<date-time>` folder in the system
    temp directory at every `learn()`; a model given this logger (`model.set_logger(...)`)
    leaves nothing behind. `make_model` sets it on every model it builds.

    Used in: every RL chapter, through `make_model`.
    """
    return Logger(folder=None, output_formats=[])


def make_model(config: RLConfig, env: gym.Env | VecEnv | None = None) -> BaseAlgorithm:
    """Build (seeded, untrained) the SB3 model `config` describes, on `env` or on `config.env_id`.

    The model logs to :func:`silent_logger` (no `SB3-*` folder in the temp directory).

    Used in: Background (thesis 2.5-2.7), DEFENDER (4.3).
    """
    if env is None:
        if config.env_id is None:
            raise ValueError("RLConfig.env_id is None and no env was passed: give one of them.")
        env = make_vec_env(config.env_id, n_envs=config.n_envs, seed=config.seed)
    set_random_seed(config.seed)  # before any network is built
    n_envs = env.num_envs if isinstance(env, VecEnv) else 1
    if not isinstance(env.action_space, gym.spaces.Box):
        raise ValueError(
            f"{config.algo} needs a continuous (Box) action space, got {env.action_space}."
        )
    noise = make_action_noise(
        config.action_noise_resolved,
        config.action_noise_sigma,
        int(np.prod(env.action_space.shape)),
        n_envs,
    )
    cls = algo_class(config.algo)
    model = cls(_policy_for(env), env, action_noise=noise, **config.sb3_kwargs())
    model.set_logger(silent_logger())
    return model


def train(
    config: RLConfig,
    *,
    env: gym.Env | VecEnv | None = None,
    callbacks: Iterable[BaseCallback] = (),
    progress: bool = True,
    info_keys: Sequence[str] = (),
    checkpoint: str | Path | None = None,
    checkpoint_every: int = 20_000,
) -> TrainResult:
    """Train SAC, TD3 or DDPG as `config` says and log every training episode.

    Seeds torch, NumPy, `random`, the action space and the env resets with `config.seed`, and
    runs torch on one thread, so the same config gives the same episodes on CPU.

    Args:
        config: what to run.
        env: an already built (and wrapped) gymnasium env or SB3 `VecEnv` to train on instead of
            `gymnasium.make(config.env_id)`; e.g. DEFENDER's filter wrapper. A plain env is
            wrapped by SB3 in `Monitor` and `DummyVecEnv`.
        callbacks: further SB3 callbacks, called after the episode logger.
        progress: show a tqdm bar with the step count, last return and mean of the last 10.
        info_keys: `info` entries to copy into each episode row (see `EpisodeLogger`).
        checkpoint: a folder to keep the run resumable in (`thesis_lib.rl.resume`). Where it
            holds a checkpoint of this config, training continues from there. The result is the
            same, bit for bit, as the run that was never stopped. Needs one env copy,
            `train_freq` 1, callbacks with `state_dict`/`load_state_dict` (or none), and
            the same of every wrapper that keeps state across episodes (a wrapper without
            them, such as gymnasium's `NormalizeObservation`, starts again on resume).
        checkpoint_every: a checkpoint is taken at the first episode end at or after each
            multiple of this many env steps (a multiple an episode spans is skipped).

    Returns:
        `TrainResult(model, episodes, config, wall_time_s, cpu_time_s, resumed_cpu_s)`. A
        resumed run's seconds include its earlier parts, up to the checkpoint it resumed from.

    Raises:
        ValueError: with `checkpoint`: several env copies, a `VecEnv`, `train_freq` above 1, a
            callback without `state_dict`, or a checkpoint in the folder of another run (another
            config, env or set of callbacks).

    Used in: Background (thesis 2.5-2.7), CLfD (4.2), DEFENDER (4.3).
    """
    # Small MLPs train several times faster on one thread than on two busy cores.
    torch.set_num_threads(1)
    callbacks = list(callbacks)
    if checkpoint is not None:
        return _train_resumable(
            config, env, callbacks, progress, info_keys, Path(checkpoint), checkpoint_every
        )
    model = make_model(config, env)
    logger = EpisodeLogger(info_keys=info_keys)
    chain: list[BaseCallback] = [logger]
    if progress:
        chain.append(ProgressBar(logger, desc=f"{config.algo} seed {config.seed}"))
    chain.extend(callbacks)
    start, cpu0 = time.perf_counter(), time.process_time()
    model.learn(total_timesteps=config.total_timesteps, callback=CallbackList(chain))
    wall_time_s = time.perf_counter() - start
    return TrainResult(model, logger.episodes, config, wall_time_s, time.process_time() - cpu0)


class _ChunkGuard(BaseCallback):
    """First in a chunk's callbacks: undoes what each `learn` call's set-up changes, so that
    learning in chunks trains the model as one call would. SB3 sets the run's length to the
    chunk's (the learning-rate schedule reads it) and resets the action noise's process. (The
    callbacks themselves see a training start and end per chunk.)"""

    def __init__(self, total_timesteps: int) -> None:
        super().__init__()
        self.total_timesteps = int(total_timesteps)
        self.noise: ActionNoise | None = None

    def _on_training_start(self) -> None:
        self.model._total_timesteps = self.total_timesteps
        if self.noise is not None:
            self.model.action_noise = self.noise

    def _on_step(self) -> bool:
        return True


class _Chain(CallbackList):
    """`CallbackList` that remembers whether a callback asked to stop. SB3 counts the step before
    it asks the callbacks, so the step count cannot tell."""

    stopped = False

    def _on_step(self) -> bool:
        ok = super()._on_step()
        self.stopped = self.stopped or not ok
        return ok


def _train_resumable(
    config: RLConfig,
    env: gym.Env | VecEnv | None,
    callbacks: list[BaseCallback],
    progress: bool,
    info_keys: Sequence[str],
    folder: Path,
    every: int,
) -> TrainResult:
    """`train` with checkpoints in `folder` (`thesis_lib.rl.resume`)."""
    if every < 1:
        raise ValueError(f"checkpoint_every must be a positive number of steps, got {every}.")
    if isinstance(env, VecEnv):
        raise ValueError(
            "Checkpointed training takes a gymnasium env (or none), not a VecEnv: it wraps the "
            "env to record its resets."
        )
    lacking = [type(cb).__name__ for cb in callbacks if not stateful_parts([cb])]
    if lacking:
        raise ValueError(
            f"Checkpointed training cannot restore the callbacks {', '.join(lacking)}: give "
            "them state_dict/load_state_dict, or train without checkpoint."
        )
    if config.n_envs != 1:
        raise ValueError(f"Checkpointed training needs n_envs 1, got {config.n_envs}.")
    if env is None:
        if config.env_id is None:
            raise ValueError("RLConfig.env_id is None and no env was passed: give one of them.")
        env = gym.make(config.env_id)
    recorder = ResetRecorder(env)
    logger = EpisodeLogger(info_keys=info_keys)
    wrappers = stateful_parts(wrapper_chain(env))
    parts: dict[str, Any] = {
        "episode_logger": logger,
        **{f"wrapper{i}:{type(w).__name__}": w for i, w in enumerate(wrappers)},
        **{f"callback{i}:{type(cb).__name__}": cb for i, cb in enumerate(callbacks)},
    }
    run = {  # what a checkpoint must have been taken of
        "config": json.loads(json.dumps(config_dict(config), default=str)),
        "env": env_fingerprint(env),
        "part_names": sorted(parts),
    }
    earlier_wall = earlier_cpu = 0.0
    found = latest_checkpoint(folder, run)
    if found is None:
        model = make_model(config, recorder)
    else:
        model, state = load_checkpoint(
            found, algo_class(config.algo), recorder, parts, device=config.device
        )
        model.set_logger(silent_logger())
        earlier_wall, earlier_cpu = float(state["wall_s"]), float(state["cpu_s"])
    check_resumable(model)
    guard = _ChunkGuard(config.total_timesteps)
    bar = (
        ProgressBar(logger, desc=f"{config.algo} seed {config.seed}", total=config.total_timesteps)
        if progress
        else None
    )
    chain: list[BaseCallback] = [guard, logger, *([bar] if bar else []), *callbacks]
    start, cpu0 = time.perf_counter(), time.process_time()

    def learn(steps: int) -> bool:
        """Learn `steps` more env steps; False where a callback stopped training."""
        guard.noise = copy.deepcopy(model.action_noise)
        calls = _Chain(chain)
        model.learn(steps, callback=calls, reset_num_timesteps=False)
        return not calls.stopped

    total = config.total_timesteps
    try:
        while model.num_timesteps < total:
            next_save = (model.num_timesteps // every + 1) * every
            if not learn(min(total, next_save) - model.num_timesteps):
                break
            stopped = False
            while model.num_timesteps < total and not logger.between_episodes:
                if not learn(1):
                    stopped = True
                    break
            if stopped or model.num_timesteps >= total:
                break
            save_checkpoint(
                folder,
                model,
                recorder,
                parts,
                {
                    **run,
                    "wall_s": earlier_wall + time.perf_counter() - start,
                    "cpu_s": earlier_cpu + time.process_time() - cpu0,
                },
            )
    finally:
        if bar is not None:
            bar.close()
    wall_time_s = earlier_wall + time.perf_counter() - start
    cpu_time_s = earlier_cpu + time.process_time() - cpu0
    return TrainResult(model, logger.episodes, config, wall_time_s, cpu_time_s, earlier_cpu)


def _curve_task(config: RLConfig, progress: bool, cache_dir: str | None = None) -> pd.DataFrame:
    cached = _cache_paths(config, cache_dir)
    if cached and cached[0].is_file() and cached[1].is_file():
        if json.loads(cached[1].read_text()) == config_dict(config):
            return pd.read_csv(cached[0])
    episodes = train(config, progress=progress).episodes
    episodes.insert(0, "seed", config.seed)
    episodes.insert(0, "algo", config.algo)
    if cached:
        cached[0].parent.mkdir(parents=True, exist_ok=True)
        episodes.to_csv(cached[0], index=False)
        cached[1].write_text(json.dumps(config_dict(config), indent=1))
    return episodes


def _cache_paths(config: RLConfig, cache_dir: str | None) -> tuple[Path, Path] | None:
    if cache_dir is None:
        return None
    stem = Path(cache_dir) / f"{config.env_id}-{config.algo}-seed{config.seed}"
    return stem.with_suffix(".csv"), stem.with_suffix(".json")


def learning_curves(
    algos: Sequence[str],
    env_id: str,
    total_timesteps: int | Mapping[str, int],
    seeds: Sequence[int],
    n_jobs: int = 1,
    progress: bool = True,
    cache_dir: str | Path | None = None,
    **overrides: Any,
) -> pd.DataFrame:
    """Train each algorithm with each seed and return every training episode as a tidy table.

    Each (algo, seed) pair is a joblib task: `n_jobs=1` runs them in this process, one after the
    other; `n_jobs>1` (or -1 for all cores) runs them in worker processes. The same rows come
    back either way.

    Args:
        algos: names of `RLConfig.algo`, e.g. ["DDPG", "TD3", "SAC"].
        env_id: gymnasium id, e.g. "Pendulum-v1".
        total_timesteps: steps per run, one number or one per algorithm ({"SAC": 5000, ...}).
        seeds: seeds to run each algorithm with.
        n_jobs: joblib worker processes.
        progress: show a bar over finished runs (and, with `n_jobs=1`, one per run).
        cache_dir: if given, each finished (algo, seed) run is saved there (episodes CSV and
            its config as JSON) and reused when called again with the same config, so a long
            sweep that stops part-way resumes from the runs it had finished.
        **overrides: further `RLConfig` fields for every run (e.g. `net_arch=[64, 64]`).

    Returns:
        One row per (algo, seed, episode), columns `CURVE_COLUMNS`: algo, seed, episode,
        env_index, timestep, return, length, terminated, truncated, crashed, wall_time_s.

    Used in: Background (thesis 2.5-2.7, Fig. "DDPG/TD3/SAC learning curves").
    """
    from joblib import Parallel, delayed
    from tqdm.auto import tqdm

    steps = (
        total_timesteps
        if isinstance(total_timesteps, Mapping)
        else dict.fromkeys(algos, total_timesteps)
    )
    missing = [algo for algo in algos if algo not in steps]
    if missing:
        raise ValueError(f"total_timesteps has no entry for {missing}; it has {sorted(steps)}.")
    configs = [
        config_from_params(
            {
                **overrides,
                "algo": algo,
                "env_id": env_id,
                "seed": int(seed),
                "total_timesteps": steps[algo],
            }
        )
        for algo in algos
        for seed in seeds
    ]
    # In-process runs also show a bar per run; worker processes' bars would interleave.
    per_run_bars = progress and n_jobs == 1
    run_all = Parallel(n_jobs=n_jobs, return_as="generator")
    cache = str(cache_dir) if cache_dir is not None else None
    tasks = run_all(delayed(_curve_task)(config, per_run_bars, cache) for config in configs)
    frames = list(tqdm(tasks, total=len(configs), desc=f"{env_id} runs", disable=not progress))
    return pd.concat(frames, ignore_index=True)[list(CURVE_COLUMNS)]


def evaluate(
    model: Predictor,
    env: str | gym.Env,
    n_episodes: int = 10,
    seed: int = 0,
    deterministic: bool = True,
) -> pd.DataFrame:
    """Run `model` for `n_episodes` episodes without learning and log each one.

    Duck-typed like SB3's `evaluate_policy`: `model` is anything with
    `predict(obs, state=, episode_start=, deterministic=) -> (action, state)`. The env is reset
    with `seed` once, before the first episode (Gymnasium's convention), so the same seed gives
    the same episodes.

    Args:
        model: the policy.
        env: a gymnasium id (made with `gymnasium.make`) or a gymnasium env (not a `VecEnv`).
        n_episodes: episodes to run.
        seed: seed of the first reset and of the action space.
        deterministic: act with the policy's mean/greedy action.

    Returns:
        One row per episode, columns `EVAL_COLUMNS`: episode, return, length, terminated,
        truncated, crashed.

    Used in: Background (thesis 2.5-2.7), DEFENDER (4.3).
    """
    if n_episodes <= 0:
        raise ValueError(f"evaluate expects n_episodes > 0, got {n_episodes}.")
    if isinstance(env, VecEnv):
        raise TypeError(
            "evaluate expects a gymnasium id or gymnasium.Env, got a VecEnv; pass its inner env."
        )
    env = gym.make(env) if isinstance(env, str) else env
    horizon = find_horizon(env)
    env.action_space.seed(seed)
    rows = []
    obs, _ = env.reset(seed=seed)
    for episode in range(n_episodes):
        if episode > 0:
            obs, _ = env.reset()
        state, episode_start = None, np.ones((1,), dtype=bool)
        total, length, terminated, truncated = 0.0, 0, False, False
        while not (terminated or truncated):
            action, state = model.predict(
                obs, state=state, episode_start=episode_start, deterministic=deterministic
            )
            episode_start = np.zeros((1,), dtype=bool)
            obs, reward, terminated, truncated, _ = env.step(action)
            total += float(reward)
            length += 1
        rows.append(
            {
                "episode": episode,
                "return": total,
                "length": length,
                "terminated": bool(terminated),
                "truncated": bool(truncated),
                "crashed": is_crash(bool(terminated), length, horizon),
            }
        )
    return pd.DataFrame(rows, columns=list(EVAL_COLUMNS))


def config_dict(config: RLConfig) -> dict[str, Any]:
    """`config` as a JSON-ready dict of its init fields (for `run.json` beside a results CSV)."""
    return {k: v for k, v in asdict(config).items() if k != "action_noise_resolved"}
