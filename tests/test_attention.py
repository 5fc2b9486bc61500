"""Tests for thesis_lib.seq.attention_ops: Eq. 2.1-2.3, masks, and the GPT block."""

from __future__ import annotations

import math

import pytest
import torch
import torch.nn.functional as F

from thesis_lib.seq import (
    Block,
    CausalSelfAttention,
    GPTBlockConfig,
    additive_mask,
    attention,
    causal_mask,
    combine_masks,
    padding_mask,
    sinusoidal_positional_encoding,
)

# ---------------------------------------------------------------- positional encoding (Eq. 2.1-2.2)


@pytest.mark.parametrize("base", [10000.0, 1000.0])
def test_positional_encoding_hand_values(base):
    d = 8
    pe = sinusoidal_positional_encoding(5, d, base=base, dtype=torch.float64)
    assert pe.shape == (5, d)
    assert pe[1, 0].item() == pytest.approx(math.sin(1.0), abs=1e-12)
    assert pe[1, 1].item() == pytest.approx(math.cos(1.0), abs=1e-12)
    assert torch.all(pe[0, 0::2] == 0) and torch.all(pe[0, 1::2] == 1)  # position 0: sin 0, cos 0
    for p in range(5):
        for i in range(d // 2):
            angle = p / base ** (2 * i / d)
            assert pe[p, 2 * i].item() == pytest.approx(math.sin(angle), abs=1e-12)
            assert pe[p, 2 * i + 1].item() == pytest.approx(math.cos(angle), abs=1e-12)


def test_positional_encoding_base_matters():
    # The thesis's printed 1000 and the standard 10000 agree at i = 0 and differ elsewhere.
    a = sinusoidal_positional_encoding(4, 4, base=1000.0, dtype=torch.float64)
    b = sinusoidal_positional_encoding(4, 4, base=10000.0, dtype=torch.float64)
    assert torch.equal(a[:, :2], b[:, :2])
    assert a[3, 2].item() == pytest.approx(math.sin(3 / 1000**0.5))
    assert not torch.allclose(a[:, 2:], b[:, 2:])
    assert sinusoidal_positional_encoding(3, 4).dtype == torch.float32


@pytest.mark.parametrize(
    "kwargs, match",
    [
        ({"n_positions": 4, "d_model": 5}, r"positive even int.*5"),
        ({"n_positions": 4, "d_model": 0}, r"positive even int.*0"),
        ({"n_positions": 0, "d_model": 4}, r"n_positions.*positive.*0"),
        ({"n_positions": 4, "d_model": 4, "base": -1.0}, r"base.*positive"),
    ],
)
def test_positional_encoding_errors(kwargs, match):
    with pytest.raises(ValueError, match=match):
        sinusoidal_positional_encoding(**kwargs)


# ---------------------------------------------------------------- masks


def test_causal_and_padding_masks():
    assert torch.equal(
        causal_mask(3), torch.tensor([[1, 0, 0], [1, 1, 0], [1, 1, 1]], dtype=torch.bool)
    )
    pm = padding_mask(torch.tensor([2, 4, 0]), 4)
    assert pm.dtype == torch.bool and pm.shape == (3, 4)
    assert pm.int().tolist() == [[1, 1, 0, 0], [1, 1, 1, 1], [0, 0, 0, 0]]
    assert padding_mask([2], 4, side="left").int().tolist() == [[0, 0, 1, 1]]


def test_mask_errors():
    with pytest.raises(ValueError, match=r"0\.\.4.*max 5"):
        padding_mask([2, 5], 4)
    with pytest.raises(ValueError, match=r"1-D integer"):
        padding_mask(torch.tensor([[1, 2]]), 4)
    with pytest.raises(ValueError, match=r"Unknown padding side 'middle'. Valid: right, left"):
        padding_mask([1], 4, side="middle")
    with pytest.raises(ValueError, match=r"positive int, actually: 0"):
        causal_mask(0)
    with pytest.raises(ValueError, match=r"bool tensor.*float32"):
        combine_masks(causal_mask(3).float())
    with pytest.raises(ValueError, match=r"does not match"):
        combine_masks(causal_mask(3), padding_mask([1, 2], 4))
    with pytest.raises(ValueError, match=r"got neither"):
        combine_masks()


@pytest.mark.parametrize("side", ["right", "left"])
def test_combine_masks_real_queries_never_see_padding(side):
    T, lengths = 5, [5, 3, 1, 0]
    kpm = padding_mask(lengths, T, side=side)
    m = combine_masks(causal_mask(T), kpm)
    assert m.shape == (4, 1, T, T)
    m = m[:, 0]
    for b in range(4):
        for i in range(T):
            if kpm[b, i]:  # real query: causal and real keys only
                expected = [bool(j <= i and kpm[b, j]) for j in range(T)]
            else:  # padded query: itself only (no empty row)
                expected = [j == i for j in range(T)]
            assert m[b, i].tolist() == expected
    assert m.any(-1).all()  # every row has a key: softmax is finite


def test_combine_masks_shapes():
    assert combine_masks(causal_mask(3)).shape == (1, 1, 3, 3)
    assert combine_masks(causal_mask(3), keep_head_dim=False).shape == (1, 3, 3)
    full = combine_masks(None, padding_mask([2, 3], 3), keep_head_dim=False)
    assert full[0].int().tolist() == [[1, 1, 0], [1, 1, 0], [0, 0, 1]]
    assert full[1].all()


def test_additive_mask():
    M = additive_mask(causal_mask(3), dtype=torch.float64)
    assert M.dtype == torch.float64
    assert torch.all(M[causal_mask(3)] == 0) and torch.all(M[~causal_mask(3)] == float("-inf"))


# ---------------------------------------------------------------- attention (Eq. 2.3) vs SDPA


def _qkv(B=3, H=2, T=6, D=4, dtype=torch.float64, seed=0):
    g = torch.Generator().manual_seed(seed)
    return tuple(torch.randn(B, H, T, D, generator=g, dtype=dtype) for _ in range(3))


def _masks(T=6):
    kpm = padding_mask([6, 4, 2], T)
    kpm_left = padding_mask([6, 4, 2], T, side="left")
    return {
        "none": None,
        "causal": causal_mask(T),
        "padding": combine_masks(None, kpm),
        "causal+padding": combine_masks(causal_mask(T), kpm),
        "causal+left-padding": combine_masks(causal_mask(T), kpm_left),
        "causal+padding (B,T,T)": combine_masks(causal_mask(T), kpm, keep_head_dim=False),
    }


@pytest.mark.parametrize("name", list(_masks()))
@pytest.mark.parametrize("dtype, tol", [(torch.float64, 1e-12), (torch.float32, 1e-6)])
def test_attention_matches_sdpa(name, dtype, tol):
    q, k, v = _qkv(dtype=dtype)
    mask = _masks()[name]
    out, w = attention(q, k, v, mask)
    sdpa_mask = (
        mask[:, None] if mask is not None and mask.ndim == 3 else mask
    )  # SDPA broadcasts (B,T,T) like numpy
    ref = F.scaled_dot_product_attention(q, k, v, attn_mask=sdpa_mask)
    assert out.shape == (3, 2, 6, 4) and w.shape == (3, 2, 6, 6)
    torch.testing.assert_close(out, ref, atol=tol, rtol=tol)
    torch.testing.assert_close(w.sum(-1), torch.ones(3, 2, 6, dtype=dtype), atol=tol, rtol=0)
    assert torch.isfinite(out).all()


def test_attention_weights_exactly_zero_where_masked():
    q, k, v = _qkv()
    kpm = padding_mask([6, 4, 2], 6)
    mask = combine_masks(causal_mask(6), kpm)  # (B, 1, T, T)
    _, w = attention(q, k, v, mask)
    blocked = ~mask.expand_as(w)
    assert torch.all(w[blocked] == 0.0)  # exactly zero: no future, no padding
    assert torch.all(w[~blocked] > 0.0)
    future = ~causal_mask(6)
    assert torch.all(w[..., future] == 0.0)
    real_q = kpm[:, None, :, None].expand_as(w)
    padded_k = (~kpm)[:, None, None, :].expand_as(w)
    assert torch.all(w[real_q & padded_k] == 0.0)


def test_attention_equation_2_3_by_hand():
    # T = 2, D = 1: the first query sees only key 0; the second weighs both keys by softmax.
    q = torch.tensor([[[[1.0], [2.0]]]], dtype=torch.float64)
    k = torch.tensor([[[[1.0], [-1.0]]]], dtype=torch.float64)
    v = torch.tensor([[[[10.0], [20.0]]]], dtype=torch.float64)
    out, w = attention(q, k, v, causal_mask(2))
    p = math.exp(2.0) / (math.exp(2.0) + math.exp(-2.0))  # scores 2*1, 2*(-1); sqrt(D) = 1
    assert w[0, 0].tolist() == [[1.0, 0.0], [pytest.approx(p), pytest.approx(1 - p)]]
    assert out[0, 0, 1, 0].item() == pytest.approx(10 * p + 20 * (1 - p))


def test_attention_errors():
    q, k, v = _qkv()
    with pytest.raises(ValueError, match=r"no key for query row"):
        attention(q, k, v, torch.zeros(6, 6, dtype=torch.bool))
    with pytest.raises(ValueError, match=r"bool `mask`.*float32"):
        attention(q, k, v, causal_mask(6).float())
    with pytest.raises(ValueError, match=r"\(T_q, T_k\) = \(6, 6\).*\(5, 5\)"):
        attention(q, k, v, causal_mask(5))
    with pytest.raises(ValueError, match=r"same channels D: q has 4, k has 3"):
        attention(q, k[..., :3], v)
    with pytest.raises(ValueError, match=r"same length T_k: k has 6, v has 5"):
        attention(q, k, v[..., :5, :])


# ---------------------------------------------------------------- config and block


def test_config_validation():
    cfg = GPTBlockConfig(d_model=64, n_heads=4)
    assert cfg.head_dim == 16
    with pytest.raises(ValueError, match=r"d_model=10 and n_heads=4.*1, 2, 5, 10"):
        GPTBlockConfig(d_model=10, n_heads=4)
    with pytest.raises(
        ValueError, match=r"Unknown activation 'tanh'. Valid: gelu, gelu_tanh, relu, silu"
    ):
        GPTBlockConfig(activation="tanh")
    with pytest.raises(ValueError, match=r"dropout.*\[0, 1\).*1.5"):
        GPTBlockConfig(dropout=1.5)
    with pytest.raises(ValueError, match=r"n_heads.*positive int.*0"):
        GPTBlockConfig(n_heads=0)
    with pytest.raises(TypeError):
        GPTBlockConfig(head_dim=3)  # derived, not an argument


def _block(**kw):
    torch.manual_seed(0)
    cfg = GPTBlockConfig(**{"d_model": 16, "n_heads": 4, "dropout": 0.0, **kw})
    return Block(cfg).double().eval()


@pytest.mark.parametrize("activation", ["gelu", "gelu_tanh", "relu", "silu"])
def test_block_shape_and_causality(activation):
    block = _block(activation=activation)
    x = torch.randn(2, 7, 16, dtype=torch.float64)
    y = block(x)
    assert y.shape == (2, 7, 16)
    x2 = x.clone()
    x2[:, 4] = torch.randn(
        2, 16, dtype=torch.float64
    )  # change token 4 (not by a constant: LayerNorm removes it)
    y2 = block(x2)
    torch.testing.assert_close(y2[:, :4], y[:, :4], atol=1e-12, rtol=0)  # earlier outputs unchanged
    assert not torch.allclose(y2[:, 5:], y[:, 5:])  # later outputs see it through attention


@pytest.mark.parametrize("side", ["right", "left"])
def test_block_padding_does_not_leak(side):
    block = _block()
    T, lengths = 6, [6, 4, 1]
    kpm = padding_mask(lengths, T, side=side)
    x = torch.randn(3, T, 16, dtype=torch.float64)
    y = block(x, kpm)
    x2 = torch.where(kpm[..., None], x, torch.randn_like(x) * 100.0)  # change every padded token
    y2 = block(x2, kpm)
    assert torch.isfinite(y).all() and torch.isfinite(y2).all()
    torch.testing.assert_close(y2[kpm], y[kpm], atol=1e-12, rtol=0)
    # A full-length sequence with a mask of all True equals running without a mask.
    torch.testing.assert_close(y[0], block(x[:1])[0], atol=1e-12, rtol=0)
    # Right-padded sequence equals the same tokens run alone, unpadded.
    if side == "right":
        torch.testing.assert_close(y[1, :4], block(x[1:2, :4])[0], atol=1e-12, rtol=0)


def test_block_non_causal_is_encoder():
    block = _block(causal=False)
    x = torch.randn(1, 5, 16, dtype=torch.float64)
    x2 = x.clone()
    x2[:, 4] = torch.randn(1, 16, dtype=torch.float64)
    assert not torch.allclose(block(x2)[:, 0], block(x)[:, 0])  # token 0 sees the future


def test_attention_weights_match_sdpa_module():
    block = _block()
    attn: CausalSelfAttention = block.attn
    x = torch.randn(2, 5, 16, dtype=torch.float64)
    kpm = padding_mask([5, 3], 5)
    w = attn.attention_weights(x, kpm)
    assert w.shape == (2, 4, 5, 5)
    assert torch.all(w[..., ~causal_mask(5)] == 0)
    assert torch.all(w[1, :, :3, 3:] == 0)  # real queries ignore padding
    # Rebuild the module's output from the explicit weights.
    q, k, v = attn._qkv(x)
    y = (w @ v).transpose(1, 2).reshape(2, 5, 16)
    torch.testing.assert_close(attn.c_proj(y), attn(x, kpm), atol=1e-12, rtol=0)
    torch.testing.assert_close(
        block.attention_weights(x, kpm), attn.attention_weights(block.ln_1(x), kpm)
    )


def test_block_dropout_trains_and_input_errors():
    torch.manual_seed(0)
    block = Block(GPTBlockConfig(d_model=8, n_heads=2, dropout=0.5)).train()
    x = torch.randn(2, 4, 8)
    kpm = padding_mask([4, 2], 4)
    assert not torch.equal(block(x, kpm), block(x, kpm))  # dropout active in training
    block.eval()
    assert torch.equal(block(x, kpm), block(x, kpm))
    with pytest.raises(ValueError, match=r"d_model=8\), got \(2, 4, 6\)"):
        block(torch.randn(2, 4, 6))
    with pytest.raises(ValueError, match=r"\(B, T\) = \(2, 4\).*padding_mask"):
        block(x, kpm[:, :3])
    with pytest.raises(ValueError, match=r"bool tensor.*int64"):
        block(x, kpm.long())


def test_block_backward_is_finite_with_left_padding():
    torch.manual_seed(0)
    block = Block(GPTBlockConfig(d_model=8, n_heads=2, dropout=0.0))
    x = torch.randn(2, 5, 8, requires_grad=True)
    kpm = padding_mask(
        [5, 2], 5, side="left"
    )  # padded queries would have empty rows without the rule
    block(x, kpm)[kpm].sum().backward()
    assert torch.isfinite(x.grad).all()
    assert all(torch.isfinite(p.grad).all() for p in block.parameters())
    assert torch.all(x.grad[~kpm] == 0)  # padded tokens do not influence real outputs


@pytest.mark.parametrize("causal", [True, False])
@pytest.mark.parametrize("side", [None, "right", "left"])
@pytest.mark.parametrize("queries", [slice(1, None, 3), slice(0, None, 2), slice(None)])
def test_block_queries_are_the_full_blocks_rows(causal, side, queries):
    """``Block(queries=...)`` (the models' readout) gives the full block's outputs at those
    tokens, forward and backward, with and without a causal mask and padding: every token is
    still a key, and the dropped tokens' outputs feed nothing."""
    torch.manual_seed(0)
    block = _block(causal=causal)
    T = 12
    kpm = None if side is None else padding_mask([12, 7, 2], T, side=side)
    x = torch.randn(3, T, 16, dtype=torch.float64, requires_grad=True)
    full = block(x, kpm)[:, queries]
    part = block(x, kpm, queries)
    assert part.shape == full.shape
    torch.testing.assert_close(part, full, atol=1e-12, rtol=0)
    w = torch.randn_like(full)
    g_full = torch.autograd.grad((full * w).sum(), [x, *block.parameters()])
    g_part = torch.autograd.grad((part * w).sum(), [x, *block.parameters()])
    for a, b in zip(g_part, g_full, strict=True):
        torch.testing.assert_close(a, b, atol=1e-12, rtol=0)
