"""Sub-goal selection of the Hierarchical Decision Transformer (thesis Sec. 5.2.2).

For state ``s_i`` the sub-goal is the later state ``s_j`` of the same trajectory with the
highest *average reward since* ``s_i``::

    W_i(j) = (r_i + r_{i+1} + ... + r_{j-1}) / (j - i)

in this package's indexing, where ``r_t`` is the reward of the transition ``s_t -> s_{t+1}``
(``Episode.rewards[t]``). The thesis writes ``Σ_{k=i+1..j} r_k / (j - i)`` with ``r_k`` the
reward *received on arriving at* ``s_k``: the same rewards, those earned between ``s_i`` and
``s_j``. The authors' code computes ``sum(rewards[i:j]) / (j - i)``, the same thing.

**The thesis's rule (the default).** "For each state-action pair, we select the state with
the highest associated weight to be the sub-goal" (5.2.2): every state ``i`` gets its own
``argmax_j W_i(j)``. Rewards ``[0, 2, 0, 0, 3.1, 0]`` give ``[5, 2, 5, 5, 5, 6]``: state 1
is one step from a reward of 2, a higher average than anything further.

**The authors' code** (``paper_compat=True``, or ``rule="keep"`` alone) keeps a sub-goal
until it is reached (index-wise: at step ``j`` the agent *is* at its sub-goal), then selects
a new one from there. A trajectory is cut into segments ``0 = j_0 < j_1 < ...`` with
``j_{m+1} = argmax_j W_{j_m}(j)``, and every state in ``[j_m, j_{m+1})`` gets
``s_{j_{m+1}}``: the same rewards give ``[5, 5, 5, 5, 5, 6]``. A review counted how often the
two rules differ on the first smoke data sets: 80% of hopper/medium's states, 63% of
walker2d/medium's and 82% of maze2d-umaze/expert's.

Exact rules (and where they differ from the authors' code, ``notes/original-code.md``):

* **Candidates.** ``j`` runs over ``i+1 .. T`` where ``T = len(rewards)``; ``s_T`` is the
  final observation (Minari stores ``T + 1`` observations). Given only ``T`` states (no final
  observation) the candidates stop at ``T - 1``. The authors' D4RL arrays had no final
  observation, so their candidates were ``i+1 .. T-1`` (``paper_compat=True``).
* **Ties** go to the earliest ``j`` (``np.argmax``), so the closest state wins. Weights are
  compared exactly, in float64, each sum accumulated left to right from ``r_i``.
* **The last state** (``i = T - 1``): its only candidate is the final observation ``s_T``.
  Without a final observation there is no later state; the last state is its own sub-goal.
  The authors' code gives it **state 0** (its candidate list is empty and it falls back to
  index 0): ``paper_compat=True`` reproduces that bug.
* **All-zero rewards** (sparse Maze2D/AntMaze before the goal): every weight is 0, all tie,
  and the earliest candidate wins: the sub-goal is always the **next state**, ``s_{i+1}``
  (under both rules). It then carries no information beyond "keep moving as the data did".
* **Sparse reward reached later.** If the rewards are 0 until the goal region and 1 while the
  agent stays there (D4RL Maze2D's sparse reward), a state ``i`` before the goal has
  ``W_i(j) = (number of rewarded steps in [i, j)) / (j - i)``, which grows with ``j`` after
  the first reward: the sub-goal is the **last** state of the episode, near the goal (under
  both rules). Once the agent is inside the goal region all weights are 1 and tie: the
  sub-goal is the next state again.
* ``paper_compat=True`` also adds the original's ``+ 1e-7`` to every weight. That constant
  does not change the argmax in exact arithmetic, but it rounds: two weights closer than
  about ``1e-16 * |w + 1e-7|`` become ties. The original computed the weights in the data's
  float32 (D4RL); here they are always float64, so rare near-ties can still resolve
  differently from the original's float32 run.

Cost: one pass over the candidates per selection, ``O(T)``; ``O(T^2)`` per episode for the
thesis's rule (every state selects), at most that for the authors'; compiled with numba.

Used in: HDT chapter (thesis 5.2.2); the Hierarchical Decision Mamba (5.3) reuses it.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from numba import njit

__all__ = ["select_subgoal_indices", "select_subgoals", "subgoal_fn"]


@njit(cache=True)
def _subgoal_indices(
    rewards: np.ndarray, n_states: int, paper_compat: bool, keep: bool
) -> np.ndarray:
    """Kernel: sub-goal index of each of the ``T`` states (see the module docstring).

    ``n_states`` is the number of selectable states: ``T + 1`` with a final observation,
    ``T`` without one. ``keep``: keep a sub-goal until it is reached (the authors' rule);
    else every state selects its own (the thesis's).
    """
    T = rewards.shape[0]
    out = np.empty(T, dtype=np.int64)
    last = n_states - 1  # index of the last selectable state
    sj = 0
    for si in range(T):
        if si == T - 1 and paper_compat:
            sj = 0  # the authors' bug: empty candidate list -> index 0
        elif sj == si or not keep:  # select (thesis: always; authors: once reached)
            if si + 1 > last:
                sj = si  # no later state: the last state is its own sub-goal
            else:
                acc = 0.0
                best = -np.inf
                best_j = si + 1
                for j in range(si + 1, last + 1):
                    acc += rewards[j - 1]  # Σ r[si:j], left to right as Python's sum
                    w = acc / (j - si)
                    if paper_compat:
                        w = w + 1e-7
                    if w > best:  # strict: ties keep the earliest j
                        best = w
                        best_j = j
                sj = best_j
        out[si] = sj
    return out


RULES = ("argmax", "keep")


def select_subgoal_indices(
    rewards: np.ndarray,
    n_states: int | None = None,
    paper_compat: bool = False,
    rule: str | None = None,
) -> np.ndarray:
    """Index of each state's sub-goal in its trajectory (thesis Sec. 5.2.2).

    Used in: HDT chapter (thesis 5.2.2).

    Args:
        rewards: ``(T,)`` rewards of one episode, ``rewards[t]`` for ``s_t -> s_{t+1}``; finite.
        n_states: How many states the indices may point to: ``T + 1`` when the final
            observation is available (the default), ``T`` when it is not. Ignored with
            ``paper_compat=True``, which always uses ``T`` (D4RL's arrays).
        paper_compat: Reproduce the authors' code: sub-goals kept until reached,
            candidates ``i+1 .. T-1``, the last state's sub-goal is state 0, ``+1e-7`` on
            every weight.
        rule: ``"argmax"`` (every state its own best, the thesis's text) or ``"keep"`` (kept
            until reached, the authors' code); ``None`` follows ``paper_compat``.

    Returns:
        ``(T,)`` int64 indices ``j > i`` into the episode's states (``T`` may point at the
        final observation), except the paper-compat last state (0) and, without a final
        observation, the last state (itself).

    Raises:
        ValueError: If ``rewards`` is not 1-D and finite, ``n_states`` is not ``T`` or
            ``T+1``, or ``rule`` is unknown.

    Example:
        >>> select_subgoal_indices(np.array([0.0, 2.0, 0.0, 0.0, 3.1, 0.0]))  # the thesis
        array([5, 2, 5, 5, 5, 6])
        >>> select_subgoal_indices(np.array([0.0, 2.0, 0.0, 0.0, 3.1, 0.0]), rule="keep")
        array([5, 5, 5, 5, 5, 6])
        >>> select_subgoal_indices(np.zeros(4))  # all-zero rewards: always the next state
        array([1, 2, 3, 4])
        >>> select_subgoal_indices(np.zeros(4), paper_compat=True)  # last state -> state 0
        array([1, 2, 3, 0])
    """
    if rule is None:
        rule = "keep" if paper_compat else "argmax"
    if rule not in RULES:
        raise ValueError(f"Unknown sub-goal rule {rule!r}. Valid: {', '.join(RULES)}.")
    r = np.asarray(rewards, dtype=np.float64)
    if r.ndim != 1:
        raise ValueError(
            f"select_subgoal_indices expects the 1-D rewards (T,) of one episode, got shape {r.shape}. "
            f"Call it once per episode."
        )
    if not np.all(np.isfinite(r)):
        bad = np.flatnonzero(~np.isfinite(r))
        raise ValueError(
            f"Expect finite rewards, got {bad.size} NaN/inf values (first at step {int(bad[0])})."
        )
    T = r.shape[0]
    if T == 0:
        return np.zeros(0, dtype=np.int64)
    if paper_compat:
        n_states = T
    elif n_states is None:
        n_states = T + 1
    if n_states not in (T, T + 1):
        raise ValueError(
            f"Expect n_states = T = {T} (no final observation) or T + 1 = {T + 1} (with it), "
            f"got {n_states}."
        )
    return _subgoal_indices(
        np.ascontiguousarray(r), int(n_states), bool(paper_compat), rule == "keep"
    )


def select_subgoals(
    states: np.ndarray, rewards: np.ndarray, paper_compat: bool = False, rule: str | None = None
) -> np.ndarray:
    """The sub-goal state of each step of one episode (thesis Sec. 5.2.2).

    See the module docstring for the rule, its index range, ties, the last state and sparse
    rewards.

    Used in: HDT chapter (thesis 5.2.2).

    Args:
        states: ``(T + 1, obs_dim)`` observations including the final one (Minari's
            ``Episode.observations``), or ``(T, obs_dim)`` without it.
        rewards: ``(T,)`` rewards.
        paper_compat: Reproduce the authors' code (see :func:`select_subgoal_indices`); a
            final observation, if given, is ignored, as the original never had one.
        rule: ``"argmax"`` or ``"keep"`` (see :func:`select_subgoal_indices`).

    Returns:
        ``(T, obs_dim)`` array (``states``' dtype): row ``i`` is the sub-goal of state ``i``.

    Raises:
        ValueError: If ``states`` has neither ``T`` nor ``T + 1`` rows.

    Example:
        >>> s = np.arange(6.0)[:, None]  # states 0..5, the last one final
        >>> select_subgoals(s, [0.0, 0.0, 5.0, 1.0, 0.0])[:, 0]
        array([3., 3., 3., 4., 5.])
    """
    x = np.asarray(states)
    r = np.asarray(rewards, dtype=np.float64)
    T = r.shape[0] if r.ndim == 1 else -1
    if x.ndim == 1:
        x = x[:, None]
    if x.ndim != 2 or x.shape[0] not in (T, T + 1):
        raise ValueError(
            f"select_subgoals expects states of shape (T + 1, obs_dim) = ({T + 1}, ...) with the final "
            f"observation, or (T, obs_dim) = ({T}, ...) without it, for T = {T} rewards; "
            f"got states of shape {np.asarray(states).shape}."
        )
    idx = select_subgoal_indices(r, n_states=x.shape[0], paper_compat=paper_compat, rule=rule)
    return x[idx]


def subgoal_fn(
    paper_compat: bool = False, rule: str | None = None
) -> Callable[[object], np.ndarray]:
    """The ``subgoal_fn`` hook of :class:`thesis_lib.data.SequenceDataset` for HDT.

    ``SequenceDataset(ds, K=20, subgoal_fn=subgoal_fn())`` computes every episode's sub-goals
    once, with the final observation as a candidate; ``subgoal_fn(paper_compat=True)``
    reproduces the authors' selection.

    Used in: HDT chapter (thesis 5.2.2).

    Args:
        paper_compat: See :func:`select_subgoal_indices`.
        rule: ``"argmax"`` or ``"keep"``; ``None`` follows ``paper_compat``.

    Returns:
        ``fn(episode) -> (T, obs_dim)`` float64 sub-goals (raw states; the data set z-scores them).
    """

    def fn(episode: object) -> np.ndarray:
        return select_subgoals(
            np.asarray(episode.observations, dtype=np.float64),  # type: ignore[attr-defined]
            episode.rewards,  # type: ignore[attr-defined]
            paper_compat=paper_compat,
            rule=rule,
        )

    return fn
