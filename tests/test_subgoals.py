"""Tests for thesis_lib.seq.subgoals: HDT's sub-goal selection (thesis 5.2.2)."""

from __future__ import annotations

import numpy as np
import pytest

from thesis_lib.data import Episode, SequenceDataset
from thesis_lib.seq.subgoals import select_subgoal_indices, select_subgoals, subgoal_fn


def _reference(rewards, n_states, paper_compat=False, keep=None):
    """The rules written straight from their definitions, with Python floats and lists."""
    keep = paper_compat if keep is None else keep
    T = len(rewards)
    out, goal = [], 0
    for i in range(T):
        if paper_compat and i == T - 1:
            goal = 0
        elif goal == i or not keep:
            cands = list(range(i + 1, n_states))
            if not cands:
                goal = i
            else:
                w = [
                    sum(float(x) for x in rewards[i:j]) / (j - i) + (1e-7 if paper_compat else 0.0)
                    for j in cands
                ]
                goal = cands[int(np.argmax(w))]  # np.argmax: first maximum
        out.append(goal)
    return np.array(out)


def test_hand_made_dense_rewards():
    # i=0: W(1)=0, W(2)=0, W(3)=5/3, W(4)=6/4, W(5)=6/5 -> 3.  i=1: W(3)=5/2 > W(4)=2 -> 3.
    # i=2: W(3)=5 -> 3.  i=3: W(4)=1, W(5)=1/2 -> 4.  i=4: only the final observation 5.
    r = [0.0, 0.0, 5.0, 1.0, 0.0]
    np.testing.assert_array_equal(select_subgoal_indices(r), [3, 3, 3, 4, 5])
    np.testing.assert_array_equal(select_subgoal_indices(r, rule="keep"), [3, 3, 3, 4, 5])


def test_the_thesis_selects_per_state_and_the_authors_code_keeps_until_reached():
    # Thesis 5.2.2: "for each state-action pair, we select the state with the highest
    # associated weight". i=0: W(2)=1, W(5)=5.1/5=1.02 -> 5; i=1: W(2)=2 beats W(5)=5.1/4 -> 2;
    # i=2..4 -> 5 (3.1 ahead); i=5 -> the final observation 6.
    r = [0.0, 2.0, 0.0, 0.0, 3.1, 0.0]
    np.testing.assert_array_equal(select_subgoal_indices(r), [5, 2, 5, 5, 5, 6])
    # The authors' code keeps state 5 from state 0 until it is reached.
    np.testing.assert_array_equal(select_subgoal_indices(r, rule="keep"), [5, 5, 5, 5, 5, 6])
    np.testing.assert_array_equal(select_subgoal_indices(r, paper_compat=True), [5, 5, 5, 5, 5, 0])
    with pytest.raises(ValueError, match="Unknown sub-goal rule"):
        select_subgoal_indices(r, rule="first")


def test_ties_go_to_the_earliest_state():
    # i=0: W(1)=0, W(2)=2/2=1, W(3)=3/3=1: a tie between 2 and 3 -> 2.
    np.testing.assert_array_equal(select_subgoal_indices([0.0, 2.0, 1.0]), [2, 2, 3])
    # Constant rewards: every weight ties -> always the next state.
    np.testing.assert_array_equal(select_subgoal_indices(np.ones(5)), [1, 2, 3, 4, 5])


def test_all_zero_rewards_give_the_next_state():
    np.testing.assert_array_equal(select_subgoal_indices(np.zeros(6)), [1, 2, 3, 4, 5, 6])


def test_sparse_reward_at_the_goal_selects_the_end():
    # Maze2D-like: 0 until the goal region, then 1 while the agent stays there.
    r = np.array([0.0] * 6 + [1.0] * 4)  # T = 10, final observation = 10
    idx = select_subgoal_indices(r)
    # Before the goal W(j) = (j - 6) / (j - i) grows with j: the final observation.
    np.testing.assert_array_equal(idx[:6], [10] * 6)
    # Inside the goal region every weight is 1: the next state (thesis rule) ...
    np.testing.assert_array_equal(idx[6:], [7, 8, 9, 10])
    # ... while the authors' code keeps the end, selected at step 0, until it is reached.
    np.testing.assert_array_equal(select_subgoal_indices(r, rule="keep"), [10] * 10)
    # Starting inside the goal region all weights are 1: the next state.
    np.testing.assert_array_equal(select_subgoal_indices(np.ones(3)), [1, 2, 3])


def test_last_state():
    r = np.array([1.0, 0.0, 0.0])
    assert select_subgoal_indices(r)[-1] == 3  # the final observation
    assert select_subgoal_indices(r, n_states=3)[-1] == 2  # no final observation: itself
    assert select_subgoal_indices(r, paper_compat=True)[-1] == 0  # the authors' bug


@pytest.mark.parametrize(("paper_compat", "rule"), [(False, None), (False, "keep"), (True, None)])
@pytest.mark.parametrize("with_final", [True, False])
def test_kernel_matches_the_definition(paper_compat, rule, with_final):
    rng = np.random.default_rng(0)
    for trial in range(200):
        T = int(rng.integers(1, 25))
        # integer rewards make exact ties common; normal ones test ordinary maxima
        r = rng.integers(0, 3, T).astype(float) if trial % 2 else rng.normal(size=T)
        n_states = T + 1 if with_final and not paper_compat else T
        got = select_subgoal_indices(
            r, n_states=None if with_final else T, paper_compat=paper_compat, rule=rule
        )
        keep = None if rule is None else rule == "keep"
        np.testing.assert_array_equal(got, _reference(r, n_states, paper_compat, keep))


def test_select_subgoals_returns_the_states():
    s = np.arange(12.0).reshape(6, 2)  # 6 states, the last final
    r = [0.0, 0.0, 5.0, 1.0, 0.0]
    g = select_subgoals(s, r)
    assert g.shape == (5, 2)
    np.testing.assert_array_equal(g, s[[3, 3, 3, 4, 5]])
    # paper_compat drops the final observation and sends the last state to state 0
    np.testing.assert_array_equal(select_subgoals(s, r, paper_compat=True), s[[3, 3, 3, 4, 0]])


def test_bad_shapes_give_clear_errors():
    with pytest.raises(ValueError, match=r"states of shape \(T \+ 1, obs_dim\) = \(4, \.\.\.\)"):
        select_subgoals(np.zeros((7, 2)), np.zeros(3))
    with pytest.raises(ValueError, match="1-D rewards"):
        select_subgoal_indices(np.zeros((3, 2)))
    with pytest.raises(ValueError, match="finite rewards"):
        select_subgoal_indices([0.0, np.nan])
    with pytest.raises(ValueError, match="n_states"):
        select_subgoal_indices(np.zeros(3), n_states=7)
    assert select_subgoal_indices(np.zeros(0)).shape == (0,)


def test_hook_plugs_into_sequence_dataset():
    rng = np.random.default_rng(1)
    T = 12
    obs = rng.normal(size=(T + 1, 3))
    rew = rng.normal(size=T)
    ep = Episode(
        0,
        obs,
        rng.normal(size=(T, 2)).astype(np.float32),
        rew,
        np.zeros(T, bool),
        np.zeros(T, bool),
    )
    seq = SequenceDataset([ep], K=4, subgoal_fn=subgoal_fn(), seed=0)
    idx = select_subgoal_indices(rew)
    expected = (obs[idx] - seq.state_mean) / seq.state_std  # z-scored with the state statistics
    np.testing.assert_allclose(seq.subgoals, expected, rtol=1e-5, atol=1e-5)


def test_hundreds_of_long_episodes():
    """A data set's worth of 1000-step episodes (how long it takes: ``--durations``)."""
    rng = np.random.default_rng(0)
    episodes = [rng.normal(size=1000) for _ in range(500)] + [np.zeros(1000) for _ in range(100)]
    steps = np.arange(1000)
    for r in episodes:
        idx = select_subgoal_indices(r)
        assert idx.shape == (1000,)
        # every sub-goal lies ahead (the last step's is the final observation)
        assert (idx > steps).all() and idx.max() <= 1000
    for r in episodes[::50]:  # the authors' rule keeps a sub-goal until it is reached
        assert (np.diff(select_subgoal_indices(r, rule="keep")) >= 0).all()
    np.testing.assert_array_equal(select_subgoal_indices(episodes[-1]), steps + 1)
