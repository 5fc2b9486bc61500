"""Tests for thesis_lib.seq.dropout: lane dropout masks (``TrainConfig(kernels="fast")``)."""

from __future__ import annotations

import math

import pytest
import torch
import torch.nn as nn
import torch.nn.functional as F
from torch.nn.attention import SDPBackend, sdpa_kernel

from thesis_lib.seq.attention_ops import (
    CausalSelfAttention,
    GPTBlockConfig,
    _attend_lane_dropout,
    causal_mask,
    combine_masks,
    padding_mask,
)
from thesis_lib.seq.dropout import Dropout, dropout, lane_dropout, lane_dropout_enabled, lane_mask

torch.set_num_threads(1)


def _within(rate: torch.Tensor, p: float, n: int, sigmas: float = 5.0) -> bool:
    return abs(float(rate) - p) < sigmas * math.sqrt(p * (1 - p) / n)


@pytest.mark.parametrize("p", [0.1, 0.5, 0.9])
def test_each_lane_keeps_with_probability_one_minus_p(p):
    """Both 32-bit lanes of every 64-bit draw are uniform: torch's ``random_()`` alone draws
    ``[0, 2^63)``, whose high lanes would never be negative (so almost always kept)."""
    torch.manual_seed(0)
    n = 1_000_000
    keep = lane_mask((n,), p).float()
    assert keep.shape == (n,)
    for lane in (keep[0::2], keep[1::2]):  # low and high halves of the 64-bit words
        assert _within(lane.mean(), 1 - p, n // 2)
    # independent: a pair of neighbours (two lanes of one draw) are both dropped with p^2
    both = ((1 - keep[0::2]) * (1 - keep[1::2])).mean()
    assert _within(both, p * p, n // 2)


def test_a_mask_is_seeded_by_torch_and_of_any_shape():
    torch.manual_seed(3)
    a = lane_mask((4, 5, 7), 0.3)  # an odd number of elements: the last draw is half used
    torch.manual_seed(3)
    b = lane_mask((4, 5, 7), 0.3)
    assert a.dtype == torch.bool and a.shape == (4, 5, 7)
    assert torch.equal(a, b)
    assert not torch.equal(a, lane_mask((4, 5, 7), 0.3))
    assert lane_mask((1000,), 0.0).all()


def test_a_bad_p_is_a_clear_error():
    with pytest.raises(
        ValueError, match=r"Expect the drop probability `p` in \[0, 1\), actually: 1\.0"
    ):
        lane_mask((3,), 1.0)


def test_lane_dropout_zeroes_and_scales_as_torchs_does():
    torch.manual_seed(0)
    x = torch.rand(200_000) + 1.0  # no zeros of its own
    with lane_dropout():
        assert lane_dropout_enabled()
        y = dropout(x, 0.2)
    assert not lane_dropout_enabled()
    kept = y != 0
    torch.testing.assert_close(y[kept], x[kept] / 0.8)
    assert _within((~kept).float().mean(), 0.2, x.numel())
    assert float(y.mean()) == pytest.approx(float(x.mean()), rel=0.01)  # E[y] = x
    # outside the context it is F.dropout, draw for draw
    torch.manual_seed(1)
    a = dropout(x, 0.2)
    torch.manual_seed(1)
    torch.testing.assert_close(a, F.dropout(x, 0.2, True), rtol=0, atol=0)
    # and no dropout where none is asked
    with lane_dropout():
        assert dropout(x, 0.2, training=False) is x and dropout(x, 0.0) is x


def test_the_gradient_is_the_scaled_mask():
    torch.manual_seed(0)
    x = torch.randn(5000, requires_grad=True)
    with lane_dropout():
        y = dropout(x, 0.3)
    y.sum().backward()
    kept = y.detach() != 0
    torch.testing.assert_close(x.grad, kept.float() / 0.7)


def test_the_module_is_nn_dropout_outside_the_context():
    m = Dropout(0.25)
    assert isinstance(m, nn.Dropout) and repr(m) == repr(nn.Dropout(0.25))
    assert m.state_dict() == {}
    x = torch.rand(1000) + 1.0
    torch.manual_seed(2)
    a = m(x)
    torch.manual_seed(2)
    torch.testing.assert_close(a, nn.Dropout(0.25)(x), rtol=0, atol=0)
    torch.manual_seed(2)
    with lane_dropout():
        b = m(x)
        m.eval()
        assert torch.equal(m(x), x)  # eval: no dropout in either
    assert not torch.equal(a, b)  # other draws in the context
    torch.testing.assert_close(b[b != 0], x[b != 0] / 0.75)


def _qkv(B=3, H=2, T=6, D=4, seed=0):
    g = torch.Generator().manual_seed(seed)
    return [torch.randn(B, H, T, D, generator=g) for _ in range(3)]


def test_the_written_out_attention_is_sdpa_without_dropout():
    q, k, v = _qkv()
    torch.testing.assert_close(
        _attend_lane_dropout(q, k, v, causal_mask(6), 0.0),
        F.scaled_dot_product_attention(q, k, v, is_causal=True),
    )
    mask = combine_masks(causal_mask(6), padding_mask(torch.tensor([6, 4, 2]), 6))
    torch.testing.assert_close(
        _attend_lane_dropout(q, k, v, mask, 0.0),
        F.scaled_dot_product_attention(q, k, v, attn_mask=mask),
    )
    torch.testing.assert_close(
        _attend_lane_dropout(q, k, v, None, 0.0), F.scaled_dot_product_attention(q, k, v)
    )
    # bfloat16 inputs (autocast's) are attended in float32, as SDPA's CPU math path does (the
    # path SDPA takes with dropout on a CPU), to the bit
    qb, kb, vb = (t.bfloat16() for t in (q, k, v))
    out = _attend_lane_dropout(qb, kb, vb, causal_mask(6), 0.0)
    assert out.dtype == torch.bfloat16
    with sdpa_kernel(SDPBackend.MATH):
        math_path = F.scaled_dot_product_attention(qb, kb, vb, is_causal=True)
    torch.testing.assert_close(out, math_path, rtol=0, atol=0)


def test_attention_drops_its_weights_with_lane_masks_in_the_context():
    """In training, inside ``lane_dropout``: ``softmax(q k^T / sqrt(D)) * mask / (1 - p) @ v``,
    then the residual dropout, each mask the next lane draw."""
    p = 0.2
    torch.manual_seed(0)
    attn = CausalSelfAttention(GPTBlockConfig(d_model=8, n_heads=2, dropout=p)).train()
    x = torch.randn(3, 5, 8)
    torch.manual_seed(7)
    with lane_dropout():
        y = attn(x)
    torch.manual_seed(7)
    with torch.no_grad():
        q, k, v = attn._qkv(x)
        w = torch.softmax(
            (q @ k.transpose(-2, -1)) / 2.0 + torch.where(causal_mask(5), 0.0, -math.inf), -1
        )
        w = w * lane_mask(w.shape, p) / (1 - p)
        z = attn.c_proj((w @ v).transpose(1, 2).reshape(3, 5, 8))
        expected = z * lane_mask(z.shape, p) / (1 - p)
    torch.testing.assert_close(y, expected)
    # outside the context: torch's SDPA with its own dropout (other draws)
    torch.manual_seed(7)
    assert not torch.allclose(attn(x), y)
