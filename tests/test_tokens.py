"""Tests for thesis_lib.seq.tokens: returns-to-go and the DT token layout (thesis Sec. 2.8)."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest
import torch

from thesis_lib.seq import (
    MODALITIES,
    deinterleave_embeddings,
    interleave_embeddings,
    interleave_tokens,
    padding_mask,
    returns_to_go,
)


def _rtg_loop(r, gamma):
    out, acc = np.zeros(len(r)), 0.0
    for t in reversed(range(len(r))):
        acc = r[t] + gamma * acc
        out[t] = acc
    return out


def test_returns_to_go_hand_values():
    np.testing.assert_array_equal(returns_to_go([1.0, 0.0, 2.0, 3.0]), [6.0, 5.0, 5.0, 3.0])
    by_hand = [1 + 0.25 * 2 + 0.125 * 3, 0 + 0.5 * 2 + 0.25 * 3, 2 + 0.5 * 3, 3.0]
    np.testing.assert_allclose(returns_to_go([1.0, 0.0, 2.0, 3.0], gamma=0.5), by_hand)
    np.testing.assert_array_equal(returns_to_go([1, 2, 3]), [6.0, 5.0, 3.0])  # ints are fine
    assert returns_to_go([1, 2, 3]).dtype == np.float64
    np.testing.assert_array_equal(returns_to_go([5.0], gamma=0.0), [5.0])
    np.testing.assert_array_equal(
        returns_to_go([1.0, 2.0], gamma=0.0), [1.0, 2.0]
    )  # γ = 0: just r_t
    assert returns_to_go(np.array([])).shape == (0,)


def test_returns_to_go_sparse_reward_is_static():
    # Thesis Sec. 2.8: with sparse rewards the RTG does not change between steps.
    rtg = returns_to_go([0.0, 0.0, 0.0, 0.0, 1.0])
    np.testing.assert_array_equal(rtg, [1.0, 1.0, 1.0, 1.0, 1.0])


@pytest.mark.parametrize("gamma", [1.0, 0.99, 0.9, 0.3])
def test_returns_to_go_matches_loop(gamma):
    r = np.random.default_rng(0).normal(size=200)
    rtg = returns_to_go(r, gamma)
    np.testing.assert_allclose(rtg, _rtg_loop(r, gamma), rtol=1e-10, atol=1e-10)
    assert rtg[0] == pytest.approx(np.sum(r * gamma ** np.arange(200)))  # rtg_0 = discounted return
    assert rtg.flags.c_contiguous


def test_returns_to_go_does_not_modify_input():
    r = np.array([1.0, 2.0])
    out = returns_to_go(r)
    out[0] = 100.0
    assert r.tolist() == [1.0, 2.0]


@pytest.mark.parametrize(
    "rewards, gamma, match",
    [
        (np.ones((3, 2)), 1.0, r"1-D rewards \(T,\) of one episode, got shape \(3, 2\)"),
        ([1.0, np.nan, 2.0], 1.0, r"1 NaN/inf values \(first at step 1\)"),
        ([1.0, np.inf], 1.0, r"first at step 1"),
        ([1.0], 1.5, r"gamma.*\[0, 1\].*1.5"),
        ([1.0], -0.1, r"gamma.*\[0, 1\]"),
    ],
)
def test_returns_to_go_errors(rewards, gamma, match):
    with pytest.raises(ValueError, match=match):
        returns_to_go(rewards, gamma)


def test_interleave_tokens_layout():
    rewards = np.array([1.0, 2.0, 3.0])
    states = np.array([[0.0, 1.0], [0.5, 1.5], [1.0, 2.0]])
    actions = np.array([-1.0, 0.0, 1.0])
    df = interleave_tokens(returns_to_go(rewards), states, actions)
    assert isinstance(df, pd.DataFrame)
    assert list(df.columns) == ["position", "timestep", "modality", "value"]
    assert len(df) == 9
    assert df["position"].tolist() == list(range(9))
    assert df["timestep"].tolist() == [0, 0, 0, 1, 1, 1, 2, 2, 2]
    assert df["modality"].tolist() == list(MODALITIES) * 3
    assert df["modality"].cat.ordered
    assert df["value"].tolist() == [
        6.0,
        (0.0, 1.0),
        -1.0,
        5.0,
        (0.5, 1.5),
        0.0,
        3.0,
        (1.0, 2.0),
        1.0,
    ]
    # position = 3 * step + modality index
    codes = df["modality"].cat.codes.to_numpy()
    np.testing.assert_array_equal(df["position"].to_numpy(), 3 * np.arange(3).repeat(3) + codes)


def test_interleave_tokens_timesteps_and_errors():
    df = interleave_tokens(
        [2.0, 1.0], [[0.1], [0.2]], [[1.0], [2.0]], timesteps=np.array([100, 101])
    )
    assert df["timestep"].tolist() == [100, 100, 100, 101, 101, 101]
    assert df["value"].tolist() == [2.0, 0.1, 1.0, 1.0, 0.2, 2.0]  # (T, 1) columns become floats
    with pytest.raises(
        ValueError, match=r"`states` of shape \(T,\) or \(T, dim\) with T=2.*\(3,\)"
    ):
        interleave_tokens([2.0, 1.0], [0.1, 0.2, 0.3], [1.0, 2.0])
    with pytest.raises(ValueError, match=r"`actions`.*T=2"):
        interleave_tokens([2.0, 1.0], [0.1, 0.2], [1.0])
    with pytest.raises(ValueError, match=r"integer `timesteps` of shape \(T,\) = \(2,\)"):
        interleave_tokens([2.0, 1.0], [0.1, 0.2], [1.0, 2.0], timesteps=[0.5, 1.5])
    with pytest.raises(ValueError, match=r"`rtg` of shape \(T,\)"):
        interleave_tokens([[2.0, 1.0]], [0.1, 0.2], [1.0, 2.0])


def test_interleave_embeddings_matches_token_table():
    B, T, C = 2, 4, 5
    g = torch.Generator().manual_seed(0)
    r, s, a = (torch.randn(B, T, C, generator=g) for _ in range(3))
    x = interleave_embeddings(r, s, a)
    assert x.shape == (B, 3 * T, C)
    df = interleave_tokens(np.zeros(T), np.zeros(T), np.zeros(T))
    source = {"rtg": r, "state": s, "action": a}
    for pos, t, mod in df[["position", "timestep", "modality"]].itertuples(index=False):
        assert torch.equal(x[:, pos], source[mod][:, t])
    back = deinterleave_embeddings(x, 3)
    assert len(back) == 3
    for orig, got in zip((r, s, a), back):
        assert torch.equal(orig, got)


def test_interleave_padding_mask():
    kpm = padding_mask([2, 3], 3)  # (B, T) steps
    tokens = interleave_embeddings(kpm, kpm, kpm)  # (B, 3T) tokens
    assert tokens.int().tolist() == [[1, 1, 1, 1, 1, 1, 0, 0, 0], [1] * 9]


def test_interleave_errors():
    with pytest.raises(ValueError, match=r"at least one"):
        interleave_embeddings()
    with pytest.raises(ValueError, match=r"one shape.*\(1, 2, 3\), \(1, 3, 3\)"):
        interleave_embeddings(torch.zeros(1, 2, 3), torch.zeros(1, 3, 3))
    with pytest.raises(ValueError, match=r"multiple of n=3.*\(1, 7, 2\)"):
        deinterleave_embeddings(torch.zeros(1, 7, 2), 3)
