"""Windows of K steps for the sequence models (DT, HDT 5.2, Decision Mamba 5.3, HDM).

:class:`SequenceDataset` flattens the episodes once into contiguous arrays, then samples a
batch of windows with array indexing only (no Python loop per sample):

- a step is drawn uniformly over all the data set's steps and the window is the K steps
  *ending* at it (d3rlpy's ``DecisionTransformer``), so every step is the last one of a
  window equally often, and so the first steps of an episode, which evaluation meets with a
  short history, are trained as often as the others (issue #33). ``sampling="start"`` (the
  original DT code, CORL, and ``paper_compat``) draws an episode ∝ its length and a *start*
  uniformly inside it: an episode's first K - 1 steps then fall in fewer windows (step ``t``
  in ``(t + 1) / K`` of its share) and its last ones in windows that run past its end;
- a window shorter than K (it reached back before the episode's start, or ran past its end)
  is **right-padded**: the real steps come first, ``mask`` is ``True`` on them and ``False``
  on the padding (under the causal mask, the same as d3rlpy's left padding);
- time-steps stay with their states. The authors' code right-padded the states but
  left-padded the time-steps (``notes/original-code.md``); ``paper_compat=True`` does that.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import NamedTuple

import numpy as np
import scipy.signal

from .storage import Episode, OfflineDataset

SAMPLINGS: tuple[str, ...] = ("end", "start")
"""How :meth:`SequenceDataset.sample` draws windows (see the module docstring)."""


def resolve_sampling(sampling: str | None, paper_compat: bool = False, where: str = "") -> str:
    """``sampling`` checked against :data:`SAMPLINGS`, ``None`` resolved: ``"start"`` with
    ``paper_compat`` (the authors' code), else ``"end"``. ``where`` names the setting's owner in
    the error.

    Example:
        >>> resolve_sampling(None), resolve_sampling(None, paper_compat=True), resolve_sampling("end", True)
        ('end', 'start', 'end')
    """
    if sampling is None:
        return "start" if paper_compat else "end"
    if sampling not in SAMPLINGS:
        raise ValueError(f"Unknown sampling {sampling!r}{where}. Valid: {', '.join(SAMPLINGS)}.")
    return sampling


class SequenceBatch(NamedTuple):
    """A batch of B windows of K steps (NumPy arrays).

    Attributes:
        states: ``(B, K, obs_dim)`` float32, z-scored when the data set normalises.
        actions: ``(B, K, act_dim)`` float32, a_t.
        prev_actions: ``(B, K, act_dim)`` float32, a_{t-1} (zero at t = 0), or ``None``.
        rewards: ``(B, K, 1)`` float32.
        returns_to_go: ``(B, K, 1)`` float32, ``Σ_{t'≥t} γ^{t'-t} r_{t'} / rtg_scale``.
        timesteps: ``(B, K)`` int64, step index in the episode.
        mask: ``(B, K)`` bool, ``True`` = a real step (attend / count in the loss).
        subgoals: ``(B, K, goal_dim)`` float32 from the sub-goal hook, or ``None``.
        episode_index: ``(B,)`` int64, which episode each window came from.
        start: ``(B,)`` int64, first step of each window in its episode.
        prev_subgoals: ``(B, K, goal_dim)`` float32, g_{t-1}: the sub-goal of the step before
            (also before the window's first step), zero at an episode's first step (the HDT
            high level's start token) and on padding; ``None`` without sub-goals.
    """

    states: np.ndarray
    actions: np.ndarray
    prev_actions: np.ndarray | None
    rewards: np.ndarray
    returns_to_go: np.ndarray
    timesteps: np.ndarray
    mask: np.ndarray
    subgoals: np.ndarray | None
    episode_index: np.ndarray
    start: np.ndarray
    prev_subgoals: np.ndarray | None = None

    def to_torch(self, device: str = "cpu") -> dict:
        """The arrays as ``torch`` tensors on ``device`` (``None`` fields left out)."""
        import torch

        return {
            k: torch.from_numpy(np.ascontiguousarray(v)).to(device)
            for k, v in self._asdict().items()
            if v is not None
        }


SubgoalFn = Callable[[Episode], np.ndarray]


def returns_to_go(rewards: np.ndarray, gamma: float = 1.0) -> np.ndarray:
    """Returns-to-go of one episode: ``rtg_t = Σ_{t'=t}^{T} γ^{t'-t} r_{t'}`` (thesis Sec. 2.8).

    With the DT's ``γ = 1`` this is the reversed cumulative sum of the rewards; for ``γ < 1``
    it is the linear recurrence ``rtg_t = r_t + γ rtg_{t+1}``, run backwards by
    ``scipy.signal.lfilter`` (no Python loop). Call it once per episode: the sum stops at the
    episode's last reward, also when the episode was truncated rather than terminated. Any
    scaling of the RTG (the DT divides by a task constant) is left to the dataset code.

    Used in: Background chapter (thesis 2.8); DT, HDT, MDLT chapters; exported by
    :mod:`thesis_lib.seq` too.

    Args:
        rewards: Per-step rewards of one episode, shape ``(T,)``; finite.
        gamma: Discount in ``[0, 1]``; the DT uses ``1``.

    Returns:
        Float64 array of shape ``(T,)``; ``rtg[0]`` is the episode return.

    Raises:
        ValueError: If ``rewards`` is not 1-D or has NaN/inf, or ``gamma`` is outside ``[0, 1]``.

    Example:
        >>> returns_to_go([1.0, 2.0, 3.0])
        array([6., 5., 3.])
        >>> returns_to_go([1.0, 2.0, 3.0], gamma=0.5)  # 1 + 0.5 * (2 + 0.5 * 3)
        array([2.75, 3.5 , 3.  ])
    """
    r = np.asarray(rewards, dtype=np.float64)
    if r.ndim != 1:
        raise ValueError(
            f"returns_to_go expects the 1-D rewards (T,) of one episode, got shape {r.shape}. "
            f"Call it once per episode."
        )
    if not np.all(np.isfinite(r)):
        bad = np.flatnonzero(~np.isfinite(r))
        raise ValueError(
            f"Expect finite rewards, got {bad.size} NaN/inf values (first at step {int(bad[0])})."
        )
    if not 0.0 <= gamma <= 1.0:
        raise ValueError(f"Expect the discount `gamma` in [0, 1], actually: {gamma!r}.")
    if gamma == 1.0:
        return np.cumsum(r[::-1])[::-1].copy()
    # y[n] = x[n] + γ y[n-1] on the reversed sequence is rtg_t = r_t + γ rtg_{t+1}.
    return scipy.signal.lfilter([1.0], [1.0, -gamma], r[::-1])[::-1].copy()


class SequenceDataset:
    """Sample windows of ``K`` steps from offline episodes (DT/HDT/DM/HDM training input).

    Args:
        data: an :class:`OfflineDataset` or a list of :class:`Episode`.
        K: window length (context length; 20 in HDT 5.2 and Decision Mamba 5.3).
        rtg_scale: returns-to-go are divided by this (1000 in the DT/HDT code).
        gamma: discount of the returns-to-go (1 = undiscounted, as DT).
        normalize_states: z-score states with the data set's mean and std (+1e-6).
        prepend_zero_action: also return ``prev_actions`` (a_{t-1}, zero at t = 0): the
            authors' models see the previous action.
        subgoal_fn: HDT hook, ``fn(episode) -> (T, goal_dim)`` sub-goal per step; computed
            once here. Sub-goals of the states' size are z-scored with the state statistics.
        paper_compat: left-pad the time-steps of short windows as the authors' code did
            (states stay right-padded, so time-steps no longer line up with their states),
            and sample windows by their start (``sampling="start"``), as it did.
        sampling: how :meth:`sample` draws windows: ``"end"`` (a step uniform over all
            steps, the window ending at it) or ``"start"`` (an episode ∝ length, a start
            uniform inside it); ``None``: ``"start"`` with ``paper_compat``, else ``"end"``.
            See the module docstring.
        seed: seed of this dataset's own ``np.random.Generator``.

    Attributes:
        normalize_states: whether ``states`` (and state-sized sub-goals) are z-scored; the
            evaluator then z-scores observations the same way.
        state_mean: ``(obs_dim,)`` mean of all states.
        state_std: ``(obs_dim,)`` std of all states plus 1e-6.
        lengths: ``(n_episodes,)`` episode lengths T.
    """

    def __init__(
        self,
        data: OfflineDataset | Sequence[Episode],
        K: int = 20,
        rtg_scale: float = 1000.0,
        gamma: float = 1.0,
        normalize_states: bool = True,
        prepend_zero_action: bool = True,
        subgoal_fn: SubgoalFn | None = None,
        paper_compat: bool = False,
        sampling: str | None = None,
        seed: int = 0,
    ) -> None:
        episodes = list(data.episodes if isinstance(data, OfflineDataset) else data)
        sampling = resolve_sampling(sampling, paper_compat)
        if K < 1:
            raise ValueError(f"K must be at least 1, got {K}.")
        if rtg_scale <= 0:
            raise ValueError(f"rtg_scale must be positive, got {rtg_scale}.")
        if not episodes:
            raise ValueError("SequenceDataset needs at least one episode, got none.")
        episodes = [e for e in episodes if len(e) > 0]
        for e in episodes:
            e.validate()
        self.K = K
        self.normalize_states = bool(normalize_states)
        self.rtg_scale = float(rtg_scale)
        self.gamma = float(gamma)
        self.paper_compat = paper_compat
        self.sampling = sampling
        self.prepend_zero_action = prepend_zero_action
        self.rng = np.random.default_rng(seed)

        self.lengths = np.array([len(e) for e in episodes], dtype=np.int64)
        self.offsets = np.concatenate([[0], np.cumsum(self.lengths)[:-1]]).astype(np.int64)
        self.p_episode = self.lengths / self.lengths.sum()
        # States s_0 … s_{T-1}: the final observation has no action and no token.
        states = np.concatenate([e.observations[:-1] for e in episodes]).astype(np.float64)
        self.state_mean = states.mean(axis=0)
        self.state_std = states.std(axis=0) + 1e-6
        if normalize_states:
            states = (states - self.state_mean) / self.state_std
        self.states = states.astype(np.float32)
        self.actions = np.concatenate([e.actions for e in episodes]).astype(np.float32)
        self.actions = self.actions.reshape(len(self.actions), -1)
        prev = np.zeros_like(self.actions)
        prev[1:] = self.actions[:-1]
        prev[self.offsets] = 0.0  # a_{-1} = 0 at each episode start
        self.prev_actions = prev
        self.rewards = np.concatenate([e.rewards for e in episodes]).astype(np.float32)
        self.returns_to_go = (
            np.concatenate([returns_to_go(e.rewards, gamma) for e in episodes]) / self.rtg_scale
        ).astype(np.float32)
        self.timesteps = np.concatenate([np.arange(t) for t in self.lengths]).astype(np.int64)
        self.subgoals: np.ndarray | None = None
        self.prev_subgoals: np.ndarray | None = None
        if subgoal_fn is not None:
            g = np.concatenate([np.asarray(subgoal_fn(e), dtype=np.float64) for e in episodes])
            if len(g) != len(self.states):
                raise ValueError(
                    f"subgoal_fn must return one sub-goal per step: got {len(g)} for "
                    f"{len(self.states)} steps."
                )
            g = g.reshape(len(g), -1)
            if normalize_states and g.shape[1] == states.shape[1]:
                g = (g - self.state_mean) / self.state_std
            self.subgoals = g.astype(np.float32)
            prev_g = np.zeros_like(self.subgoals)  # g_{t-1}, zero at each episode start
            prev_g[1:] = self.subgoals[:-1]
            prev_g[self.offsets] = 0.0
            self.prev_subgoals = prev_g

    def __len__(self) -> int:
        """Number of steps (= possible window starts)."""
        return int(self.lengths.sum())

    @property
    def n_episodes(self) -> int:
        """Number of episodes."""
        return len(self.lengths)

    def normalize(self, states: np.ndarray) -> np.ndarray:
        """Z-score raw states ``(..., obs_dim)`` with this dataset's statistics (evaluation).

        Without ``normalize_states`` the states are returned as they are.
        """
        if not self.normalize_states:
            return np.asarray(states)
        return (np.asarray(states) - self.state_mean) / self.state_std

    def windows(
        self, episode_index: np.ndarray, start: np.ndarray, stop: np.ndarray | None = None
    ) -> SequenceBatch:
        """The windows starting at step ``start[b]`` of episode ``episode_index[b]``.

        Args:
            episode_index: ``(B,)`` episode indices.
            start: ``(B,)`` first step of each window, ``0 ≤ start < T``.
            stop: ``(B,)`` optional end of each window (exclusive; ``start < stop``): the
                steps from ``stop`` on are padding. Default: ``start + K`` (or the episode's end).

        Returns:
            The :class:`SequenceBatch` (right-padded, see the module docstring).
        """
        ei = np.asarray(episode_index, dtype=np.int64)
        st = np.asarray(start, dtype=np.int64)
        k = np.arange(self.K, dtype=np.int64)
        pos = st[:, None] + k[None, :]  # (B, K) step within the episode
        end = self.lengths[ei]
        if stop is not None:
            end = np.minimum(end, np.asarray(stop, dtype=np.int64))
        mask = pos < end[:, None]  # True on real steps
        flat = self.offsets[ei][:, None] + np.minimum(pos, self.lengths[ei][:, None] - 1)

        def take(a: np.ndarray) -> np.ndarray:
            out = a[flat]
            out[~mask] = 0
            return out

        timesteps = take(self.timesteps)
        if self.paper_compat:
            # Authors' code: time-steps left-padded while everything else is right-padded.
            n_pad = (~mask).sum(axis=1)
            src = k[None, :] - n_pad[:, None]  # position of the real time-step shown at k
            timesteps = np.where(src >= 0, st[:, None] + np.maximum(src, 0), 0)
        return SequenceBatch(
            states=take(self.states),
            actions=take(self.actions),
            prev_actions=take(self.prev_actions) if self.prepend_zero_action else None,
            rewards=take(self.rewards)[..., None],
            returns_to_go=take(self.returns_to_go)[..., None],
            timesteps=timesteps.astype(np.int64),
            mask=mask,
            subgoals=take(self.subgoals) if self.subgoals is not None else None,
            episode_index=ei,
            start=st,
            prev_subgoals=take(self.prev_subgoals) if self.prev_subgoals is not None else None,
        )

    def sample(self, batch_size: int) -> SequenceBatch:
        """Draw ``batch_size`` windows by ``self.sampling``: ``"end"``, a step uniform over all
        steps and the window ending at it; ``"start"``, an episode ∝ length and a start
        uniform inside it (see the module docstring).

        Returns:
            The :class:`SequenceBatch`, each array with leading dims ``(batch_size, K)``.
        """
        if self.sampling == "end":
            flat = self.rng.integers(0, len(self), size=batch_size)
            ei = np.searchsorted(self.offsets, flat, side="right") - 1
            last = flat - self.offsets[ei]  # the window's last step
            return self.windows(ei, np.maximum(last - self.K + 1, 0), stop=last + 1)
        ei = self.rng.choice(self.n_episodes, size=batch_size, p=self.p_episode)
        st = np.floor(self.rng.random(batch_size) * self.lengths[ei]).astype(np.int64)
        return self.windows(ei, st)
