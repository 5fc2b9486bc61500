"""One evaluator for every sequence model: many episodes at once in a vectorised environment.

Each step, for every running episode, the evaluator appends the z-scored state, the time step
and the current returns-to-go to the episode's history, cuts the history to the last ``K``
steps, asks ``model.act(history)`` for the action (HDT: and the sub-goal, which it writes
into the history so the high level sees its own past sub-goals: "rolling forward"), and steps
the environment. Bookkeeping, as the DT and the authors' code:

* ``rtg_0 = target_return / rtg_scale`` and ``rtg_{t+1} = rtg_t - r_t / rtg_scale``;
* ``actions`` holds ``a_0 .. a_{t-1}`` and a zero placeholder for ``a_t`` (hidden from the
  ``s_t`` token by the causal mask); ``prev_actions`` the same shifted by one;
* ``subgoals`` holds the high level's ``g_0 .. g_{t-1}`` and a placeholder for ``g_t``,
  ``prev_subgoals`` = ``(0, g_0, .., g_{t-1})``.

Episodes end at ``terminated or truncated`` (the environment's time limit) or at
``max_steps``. Finished episodes keep their returns; the vector env autoresets them
(``NEXT_STEP``), and those steps are ignored.

Used in: HDT chapter (thesis 5.2.5; Tables 5.1-5.3); Decision Mamba chapter (5.3).
"""

from __future__ import annotations

import warnings
from collections.abc import Callable
from typing import Any, NamedTuple

import numpy as np
import torch
import torch.nn as nn
from tqdm.auto import tqdm

from thesis_lib.data import make_env, normalized_score
from thesis_lib.data.minari_sets import is_minari_id, minari_step_cap
from thesis_lib.data.robotics import forget_maze_xml
from thesis_lib.data.tasks import get_task

__all__ = ["EvalResult", "evaluate", "target_returns"]


class EvalResult(NamedTuple):
    """Per-episode results of :func:`evaluate`.

    Attributes:
        returns: ``(n_episodes,)`` undiscounted returns.
        lengths: ``(n_episodes,)`` episode lengths (steps).
        scores: ``(n_episodes,)`` D4RL-normalised scores (x100), or ``None`` when the task has
            no D4RL reference or the environment was not given by task name.
    """

    returns: np.ndarray
    lengths: np.ndarray
    scores: np.ndarray | None

    @property
    def mean_return(self) -> float:
        """Average return over the episodes."""
        return float(np.mean(self.returns))

    @property
    def mean_score(self) -> float | None:
        """Average normalised score, or ``None``."""
        return None if self.scores is None else float(np.mean(self.scores))


def target_returns(data: Any) -> dict[str, float]:
    """The DT's desired returns in the thesis (5.2.5): the data set's max return, half, 10,000.

    Used in: HDT chapter (Tables 5.1, 5.2).

    Args:
        data: An :class:`~thesis_lib.data.OfflineDataset` or a list of episodes (``.rewards``).

    Returns:
        ``{"max": R_max, "half": R_max / 2, "10k": 10000.0}``.

    Example:
        >>> from types import SimpleNamespace as E
        >>> target_returns([E(rewards=np.ones(3)), E(rewards=np.ones(5))])
        {'max': 5.0, 'half': 2.5, '10k': 10000.0}
    """
    episodes = getattr(data, "episodes", data)
    best = max(float(np.sum(e.rewards, dtype=np.float64)) for e in episodes)
    return {"max": best, "half": best / 2, "10k": 10000.0}


def eval_step_cap(task: str, cap: int | None) -> int | None:
    """The evaluation step cap a task gets: ``cap`` for locomotion, ``None`` (the task's own time
    limit) for Maze2D.

    Maze2D's reward is sparse (1 per step near the goal) and D4RL's reference returns assume
    whole episodes (300-800 steps): cut at 100 steps every method scores at or below the random
    reference, and a table of zeros says nothing. Locomotion returns accrue every step, so a cap
    only shortens them.

    A Minari id (``D4RL/kitchen/mixed-v2``) follows
    :func:`~thesis_lib.data.minari_sets.minari_step_cap`: AntMaze and Kitchen, sparse as Maze2D,
    run whole episodes; Adroit gets ``cap``.

    Used in: HDT chapter, Decision Mamba chapter (smoke profiles).

    Example:
        >>> eval_step_cap("hopper", 100), eval_step_cap("maze2d-umaze", 100)
        (100, None)
        >>> eval_step_cap("D4RL/door/human-v2", 100), eval_step_cap("D4RL/antmaze/umaze-v1", 100)
        (100, None)
    """
    if is_minari_id(task):  # a real Minari set: AntMaze and Kitchen are sparse too
        return minari_step_cap(task, cap)
    return None if get_task(task).kind == "maze" else cap


def _env_factory(env: Any) -> tuple[Callable[[], Any] | None, Any, str | None]:
    """(factory, vector env given as is, task name) from what the user passed."""
    import gymnasium as gym

    if isinstance(env, str):
        get_task(env)  # unknown task -> ValueError listing the valid ones
        return (lambda: make_env(env)), None, env
    if isinstance(env, gym.vector.VectorEnv):
        return None, env, None
    if isinstance(env, gym.Env):
        if env.spec is None:
            raise ValueError(
                "evaluate needs several copies of the environment: pass a task name, a factory "
                "(lambda: gym.make(...)), a gymnasium VectorEnv, or an env made by gym.make (with a spec)."
            )

        spec = env.spec
        return (lambda: forget_maze_xml(gym.make(spec))), None, None
    if callable(env):
        return env, None, None
    raise TypeError(
        f"Expect a task name, an env factory, a gymnasium Env or VectorEnv; got {type(env).__name__}."
    )


def _observation(obs: Any) -> np.ndarray:
    if isinstance(obs, dict):  # PointMaze/AntMaze: the data sets store obs["observation"]
        obs = obs["observation"]
    return np.asarray(obs, dtype=np.float64).reshape(len(obs), -1)


def evaluate(
    model: nn.Module,
    env: Any,
    n_episodes: int = 10,
    *,
    target_return: float | np.ndarray | None = None,
    seed: int = 0,
    dataset: Any = None,
    state_mean: np.ndarray | None = None,
    state_std: np.ndarray | None = None,
    rtg_scale: float | None = None,
    max_steps: int | None = None,
    n_envs: int | None = None,
    task: str | None = None,
    device: str | torch.device | None = None,
    progress: bool = False,
) -> EvalResult:
    """Run ``n_episodes`` episodes of ``model`` in ``env``, all at once in a vector env.

    Used in: HDT chapter (thesis 5.2.5); Decision Mamba chapter.

    Args:
        model: A model with ``config`` (``state_dim``, ``act_dim``, ``K``) and
            ``act(history) -> SeqOutput`` (:class:`~thesis_lib.seq.models.BC`, ``DecisionTransformer``, ``HDT``).
            A model with ``recurrent_policy(n_envs)`` (DM, HDM) acts through the policy it
            returns each round (one recurrent step per action), or windowed when it returns ``None``.
        env: A task name (``"hopper"``; scores are then D4RL-normalised), an env factory, a
            ``gym.make`` env (copied through its spec) or a ``gymnasium.vector.VectorEnv``.
        n_episodes: Episodes to run.
        target_return: Desired return (DT, HDT with RTG): the thesis uses the data set's max
            return, half of it and 10,000. Required when the model reads returns-to-go. An
            array of ``n_episodes`` values gives each episode its own target, so several
            targets run in one batch of environments (episode ``k`` gets ``target_return[k]``).
        seed: Episode ``k`` resets with seed ``seed + k``.
        dataset: A :class:`~thesis_lib.data.SequenceDataset`: its ``state_mean``,
            ``state_std`` and ``rtg_scale`` are used unless given explicitly (none of the
            statistics when it was built with ``normalize_states=False``).
        state_mean: ``(state_dim,)`` mean for z-scoring observations.
        state_std: ``(state_dim,)`` std for z-scoring observations.
        rtg_scale: Divides the returns-to-go (1000 in the authors' code).
        max_steps: Cap on episode length (default: the env's time limit, else 1000).
        n_envs: Environments run in parallel (default ``min(n_episodes, 100)``).
        task: Task name for normalised scores when ``env`` is not a task name.
        device: Where the model runs (default: where its parameters are).
        progress: Show a tqdm bar over environment steps.

    Returns:
        :class:`EvalResult` with per-episode returns, lengths and normalised scores.

    Raises:
        ValueError: If ``target_return`` is missing for a model reading returns-to-go, or the
            environment's observation/action sizes differ from the model's.
    """
    import gymnasium as gym

    cfg: Any = model.config  # every sequence model keeps its config as ``.config``
    uses_rtg = bool(getattr(cfg, "use_rtg", False) or getattr(cfg, "low_use_rtg", False))
    if uses_rtg and target_return is None:
        raise ValueError(
            f"{type(model).__name__} reads returns-to-go: pass target_return= (the thesis uses the "
            f"data set's maximum return, half of it, and 10000)."
        )
    targets = (
        np.zeros(n_episodes)
        if target_return is None
        else np.asarray(target_return, dtype=np.float64)
    )
    if targets.ndim == 0:
        targets = np.full(n_episodes, float(targets))
    if targets.shape != (n_episodes,) or not np.all(np.isfinite(targets)):
        raise ValueError(
            f"Expect target_return as one finite number or one per episode ({n_episodes},), "
            f"got shape {targets.shape}{'' if np.all(np.isfinite(targets)) else ' with NaN/inf'}."
        )
    factory, venv, task_name = _env_factory(env)  # unknown task names fail here, first
    if dataset is not None:
        raw = not getattr(dataset, "normalize_states", True)  # trained on raw states
        state_mean = (None if raw else dataset.state_mean) if state_mean is None else state_mean
        state_std = (None if raw else dataset.state_std) if state_std is None else state_std
        rtg_scale = dataset.rtg_scale if rtg_scale is None else rtg_scale
        if raw and state_mean is None:
            state_mean, state_std = np.zeros(cfg.state_dim), np.ones(cfg.state_dim)
    rtg_scale = 1000.0 if rtg_scale is None else float(rtg_scale)
    if state_mean is None:
        warnings.warn(
            "evaluate got no state statistics: observations are fed raw. Pass dataset=seq.",
            stacklevel=2,
        )
    mean = (
        np.zeros(cfg.state_dim) if state_mean is None else np.asarray(state_mean, dtype=np.float64)
    )
    std = np.ones(cfg.state_dim) if state_std is None else np.asarray(state_std, dtype=np.float64)
    if device is None:
        p = next(model.parameters(), None)
        device = p.device if p is not None else torch.device("cpu")

    task = task or task_name
    if venv is None:
        n = min(n_episodes, 100) if n_envs is None else int(n_envs)
        assert factory is not None  # _env_factory gives a factory whenever no vector env
        venv = gym.vector.SyncVectorEnv([factory] * n)
        close = True
    else:
        close = False
    single_act = venv.single_action_space
    if single_act.shape != (cfg.act_dim,):
        raise ValueError(
            f"The environment's actions have shape {single_act.shape}; {type(model).__name__} was built "
            f"with act_dim={cfg.act_dim}."
        )
    if max_steps is None:
        spec = getattr(venv, "spec", None) or getattr(
            getattr(venv, "envs", [None])[0], "spec", None
        )
        max_steps = (spec.max_episode_steps if spec is not None else None) or 1000
    max_steps = min(int(max_steps), getattr(cfg, "max_timestep", max_steps))

    was_training = model.training
    model.eval()
    returns, lengths = [], []
    try:
        done_so_far = 0
        while done_so_far < n_episodes:
            n_env = venv.num_envs
            round_targets = targets[done_so_far : done_so_far + n_env]
            round_targets = np.pad(round_targets, (0, n_env - len(round_targets)), mode="edge")
            r, ep_len = _run_round(
                model,
                venv,
                seed + done_so_far,
                max_steps,
                mean,
                std,
                round_targets,
                rtg_scale,
                device,
                progress,
            )
            take = min(len(r), n_episodes - done_so_far)
            returns.append(r[:take])
            lengths.append(ep_len[:take])
            done_so_far += take
    finally:
        model.train(was_training)
        if close:
            venv.close()
    ret, lens = np.concatenate(returns), np.concatenate(lengths)
    scores: np.ndarray | None = None
    if task is not None:
        norm = normalized_score(task, ret, missing="none")
        scores = None if norm is None else np.atleast_1d(np.asarray(norm, dtype=np.float64))
    return EvalResult(ret, lens, scores)


def _run_round(model, venv, seed, H, mean, std, target_return, rtg_scale, device, progress):
    """One batch of ``venv.num_envs`` episodes. Returns (returns, lengths)."""
    cfg: Any = model.config  # every sequence model keeps its config as ``.config``
    N, K, sd, ad = venv.num_envs, cfg.K, cfg.state_dim, cfg.act_dim
    obs, _ = venv.reset(seed=seed)
    obs = _observation(obs)
    # Models that can act recurrently (DM, HDM) give a per-round policy carrying each episode's
    # state; None (or no such method) = windowed acting with model.act(history).
    make_policy = getattr(model, "recurrent_policy", None)
    policy = make_policy(N) if callable(make_policy) else None
    if obs.shape[1] != sd:
        raise ValueError(
            f"{type(model).__name__} expects states of size state_dim={sd}, the environment gives "
            f"observations of size {obs.shape[1]}. Use the environment of the model's data set."
        )
    f32 = dict(dtype=torch.float32, device=device)
    states = torch.zeros(N, H, sd, **f32)  # z-scored s_t
    rtgs = torch.zeros(N, H, 1, **f32)  # rtg_t / scale
    actions = torch.zeros(
        N, H + 1, ad, **f32
    )  # actions[:, t + 1] = a_t; actions[:, 0] = a_{-1} = 0
    subgoals = torch.zeros(
        N, H + 1, sd, **f32
    )  # subgoals[:, t + 1] = g_t; subgoals[:, 0] = g_{-1} = 0
    timesteps = torch.arange(H, device=device)[None, :].expand(N, H)  # (N, H)
    rtg = np.asarray(target_return, dtype=np.float64) / rtg_scale  # (N,) one target per env
    ret, length = np.zeros(N), np.zeros(N, dtype=np.int64)
    done = np.zeros(N, dtype=bool)
    for t in tqdm(range(H), disable=not progress, desc="evaluate", leave=False):
        states[:, t] = torch.as_tensor((obs - mean) / std, **f32)
        rtgs[:, t, 0] = torch.as_tensor(rtg, **f32)
        lo = max(0, t - K + 1)  # history cut to the last K steps
        live = torch.as_tensor(np.flatnonzero(~done), device=device)
        history = {
            "states": states[live, lo : t + 1],
            "actions": actions[live, lo + 1 : t + 2],
            "prev_actions": actions[live, lo : t + 1],
            "returns_to_go": rtgs[live, lo : t + 1],
            "timesteps": timesteps[live, lo : t + 1],
            "subgoals": subgoals[live, lo + 1 : t + 2],
            "prev_subgoals": subgoals[live, lo : t + 1],
        }
        out = model.act(history) if policy is None else policy.act(history, live)
        actions[live, t + 1] = out.actions.to(**f32)
        if out.subgoals is not None:
            subgoals[live, t + 1] = out.subgoals.to(**f32)  # roll the sub-goals forward
        step_actions = actions[:, t + 1].cpu().numpy()
        obs, reward, terminated, truncated, _ = venv.step(step_actions)
        obs = _observation(obs)
        reward = np.asarray(reward, dtype=np.float64)
        ret[~done] += reward[~done]
        length[~done] += 1
        rtg = rtg - reward / rtg_scale
        done |= np.asarray(terminated) | np.asarray(truncated)
        if done.all():
            break
    return ret, length
