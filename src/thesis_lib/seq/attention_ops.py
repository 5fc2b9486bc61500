"""Attention, masks and a pre-LN GPT block: the Transformer pieces of thesis Sec. 2.2.

Read top-down, as nanoGPT's ``model.py``:

1. :func:`sinusoidal_positional_encoding` (Eq. 2.1-2.2),
2. boolean masks (:func:`causal_mask`, :func:`padding_mask`, :func:`combine_masks`) and the
   additive mask ``M`` of Eq. 2.3 (:func:`additive_mask`),
3. :func:`attention`, Eq. 2.3 written out to teach and to plot attention weights,
4. the modules the Decision Transformer family reuses: :class:`CausalSelfAttention` (on
   ``F.scaled_dot_product_attention``), :class:`MLP`, :class:`Block`, and their config
   :class:`GPTBlockConfig`.

Mask convention, everywhere in this package: a boolean mask is ``True`` where a query **may
attend** to a key, the same convention as the boolean ``attn_mask`` of
``torch.nn.functional.scaled_dot_product_attention``. (``nn.MultiheadAttention``'s
``key_padding_mask`` uses the opposite one; do not pass our masks there.)

Used in: Background chapter (thesis 2.2, 2.8); Decision Transformer, HDT and MDLT chapters.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Literal, NamedTuple, get_args

import torch
import torch.nn as nn
import torch.nn.functional as F

from thesis_lib.seq.dropout import Dropout, dropout, lane_dropout_enabled

# ----------------------------------------------------------------------------------------------
# Positional encoding (Eq. 2.1-2.2)


def sinusoidal_positional_encoding(
    n_positions: int, d_model: int, base: float = 10000.0, dtype: torch.dtype = torch.float32
) -> torch.Tensor:
    """Sinusoidal positional encoding of Eq. 2.1-2.2 (Vaswani et al., 2017).

    ``PE[p, 2i] = sin(p / base**(2i/d))`` and ``PE[p, 2i+1] = cos(p / base**(2i/d))``, so even
    dimensions hold sines and odd dimensions cosines of the same frequency.

    The thesis prints ``1000`` in Eq. 2.1-2.2 where the standard formula of Vaswani et al. has
    ``10000``. The default ``base=10000.0`` is the standard one; ``base=1000.0`` reproduces the
    printed formula. Neither is what the thesis's models use: DT, HDT and MDLT embed the time
    step index with a learned ``nn.Embedding`` (thesis Sec. 2.8) and add it to every token of
    that step.

    Used in: Background chapter (thesis 2.2).

    Args:
        n_positions: Number of positions ``P`` (token indices ``0 .. P-1``); positive.
        d_model: Embedding size ``d``; positive and even (one sin/cos pair per frequency).
        base: The constant raised to ``2i/d``; positive. 10000 standard, 1000 as printed.
        dtype: Floating dtype of the result (computed in float64, then cast).

    Returns:
        Tensor of shape ``(n_positions, d_model)``, heatmap-ready (positions on rows).

    Raises:
        ValueError: If ``n_positions`` is not positive, ``d_model`` is not positive and even,
            or ``base`` is not positive.

    Example:
        >>> pe = sinusoidal_positional_encoding(4, 6)
        >>> tuple(pe.shape)
        (4, 6)
        >>> round(pe[1, 0].item(), 4), round(pe[1, 1].item(), 4)  # sin(1), cos(1)
        (0.8415, 0.5403)
    """
    if not isinstance(n_positions, int) or n_positions <= 0:
        raise ValueError(f"Expect `n_positions` to be a positive int, actually: {n_positions!r}.")
    if not isinstance(d_model, int) or d_model <= 0 or d_model % 2 != 0:
        raise ValueError(
            f"Expect `d_model` to be a positive even int (one sin/cos pair per frequency), "
            f"actually: {d_model!r}."
        )
    if not base > 0:
        raise ValueError(
            f"Expect `base` to be positive (10000 standard, 1000 as printed), actually: {base!r}."
        )
    position = torch.arange(n_positions, dtype=torch.float64)[:, None]  # (P, 1)
    two_i = torch.arange(0, d_model, 2, dtype=torch.float64)  # (d/2,) = 0, 2, 4, ...
    angle = position / float(base) ** (two_i / d_model)  # (P, d/2)
    pe = torch.empty(n_positions, d_model, dtype=torch.float64)
    pe[:, 0::2] = torch.sin(angle)  # Eq. 2.1
    pe[:, 1::2] = torch.cos(angle)  # Eq. 2.2
    return pe.to(dtype)


# ----------------------------------------------------------------------------------------------
# Masks. True = may attend (torch SDPA's boolean attn_mask convention).


def causal_mask(T: int, device: torch.device | str | None = None) -> torch.Tensor:
    """Causal (look-ahead) mask: query ``i`` may attend to keys ``j <= i``.

    ``True`` means *may attend* (torch SDPA's boolean ``attn_mask`` convention), so this is the
    lower triangle including the diagonal. The thesis's "upper triangular look-ahead mask" is
    the complement: the entries that are hidden.

    Used in: Background chapter (thesis 2.2, 2.8); DT, HDT, MDLT chapters.

    Args:
        T: Sequence length; positive.
        device: Device of the result.

    Returns:
        Bool tensor of shape ``(T, T)``, ``[query, key]``; heatmap-ready.

    Raises:
        ValueError: If ``T`` is not a positive int.

    Example:
        >>> causal_mask(3).int().tolist()
        [[1, 0, 0], [1, 1, 0], [1, 1, 1]]
    """
    if not isinstance(T, int) or T <= 0:
        raise ValueError(f"Expect the sequence length `T` to be a positive int, actually: {T!r}.")
    return torch.ones(T, T, dtype=torch.bool, device=device).tril()


def padding_mask(
    lengths: torch.Tensor | list[int], T: int, side: Literal["right", "left"] = "right"
) -> torch.Tensor:
    """Key-padding mask from sequence lengths: ``True`` at real tokens, ``False`` at padding.

    With ``side="right"`` (the default) sequence ``b`` occupies positions ``0 .. lengths[b]-1``
    and padding follows it. With ``side="left"`` the padding comes first and the real tokens
    occupy the last ``lengths[b]`` positions, as in the original Decision Transformer code,
    which left-pads short context windows.

    Thesis Sec. 2.8 describes the DT's mask as "a binary vector with as many elements as the
    length of the sequence"; in the DT code that vector is this key-padding mask, and the
    causal part is applied inside GPT-2 (here: :func:`combine_masks` with :func:`causal_mask`).

    Used in: Background chapter (thesis 2.2); DT, HDT, MDLT chapters.

    Args:
        lengths: Number of real tokens per sequence, shape ``(B,)``, each in ``0 .. T``.
        T: Padded sequence length; positive.
        side: Where the padding is: ``"right"`` or ``"left"``.

    Returns:
        Bool tensor of shape ``(B, T)``, ``True`` = real token (may be attended to).

    Raises:
        ValueError: If ``lengths`` is not 1-D, has a value outside ``0 .. T``, or ``side`` is
            unknown.

    Example:
        >>> padding_mask([3, 1], 4).int().tolist()
        [[1, 1, 1, 0], [1, 0, 0, 0]]
        >>> padding_mask([3, 1], 4, side="left").int().tolist()
        [[0, 1, 1, 1], [0, 0, 0, 1]]
    """
    if not isinstance(T, int) or T <= 0:
        raise ValueError(f"Expect the padded length `T` to be a positive int, actually: {T!r}.")
    if side not in ("right", "left"):
        raise ValueError(f"Unknown padding side {side!r}. Valid: right, left.")
    lengths = torch.as_tensor(lengths)
    if lengths.ndim != 1 or lengths.is_floating_point() or lengths.is_complex():
        raise ValueError(
            f"Expect `lengths` to be a 1-D integer tensor of shape (B,), "
            f"got shape {tuple(lengths.shape)} and dtype {lengths.dtype}."
        )
    if lengths.numel() and (lengths.min() < 0 or lengths.max() > T):
        raise ValueError(
            f"Expect every length in 0..{T} (the padded length T), "
            f"got min {int(lengths.min())} and max {int(lengths.max())}."
        )
    pos = torch.arange(T, device=lengths.device)[None, :]  # (1, T)
    if side == "right":
        return pos < lengths[:, None]  # (B, T)
    return pos >= T - lengths[:, None]  # (B, T)


def combine_masks(
    attn_mask: torch.Tensor | None = None,
    key_padding_mask: torch.Tensor | None = None,
    *,
    keep_head_dim: bool = True,
) -> torch.Tensor:
    """Combine a ``(T, T)`` attention mask and a ``(B, T)`` key-padding mask into one mask.

    Convention: ``True`` = may attend (torch SDPA's boolean ``attn_mask`` convention), for the
    inputs and for the result. Query ``i`` of sequence ``b`` may attend to key ``j`` when
    ``attn_mask[i, j]`` and ``key_padding_mask[b, j]`` are both ``True``: real queries never
    see padding, wherever it is (right padding, left padding or holes).

    Padded queries are the NaN hazard: with left padding and a causal mask, the first padded
    query has no key left, and a softmax over a row of ``-inf`` is ``NaN``, which then spreads
    through the next layers and the gradients. We define the behaviour instead: a padded query
    (``key_padding_mask[b, i]`` is ``False``) attends to itself and only to itself, whatever
    ``attn_mask`` says. Its output is then a function of its own token, finite, and no real
    token depends on it; the loss must ignore it, as it ignores every padded position.

    Used in: Background chapter (thesis 2.2, 2.8); DT, HDT, MDLT chapters.

    Args:
        attn_mask: Bool ``(T, T)`` or ``(B, T, T)``, ``[query, key]``, e.g. :func:`causal_mask`.
            ``None`` means full attention.
        key_padding_mask: Bool ``(B, T)``, ``True`` at real tokens, e.g. :func:`padding_mask`.
            ``None`` means no padding.
        keep_head_dim: Return ``(B, 1, T, T)``, which broadcasts over the heads of
            ``(B, H, T, D)`` queries, if ``True``; ``(B, T, T)`` if ``False``.

    Returns:
        Bool tensor ``(B, 1, T, T)`` (or ``(B, T, T)``); ``B = 1`` when only ``attn_mask`` is
        given as ``(T, T)``. Every query row has at least one ``True`` when every row of
        ``attn_mask`` has one (e.g. causal masks), so it is safe for softmax.

    Raises:
        ValueError: If both are ``None``, a mask is not boolean, or the shapes disagree.

    Example:
        >>> m = combine_masks(causal_mask(3), padding_mask([2], 3), keep_head_dim=False)
        >>> m[0].int().tolist()  # query 2 is padding: it attends to itself only
        [[1, 0, 0], [1, 1, 0], [0, 0, 1]]
    """
    if attn_mask is None and key_padding_mask is None:
        raise ValueError(
            "combine_masks needs `attn_mask`, `key_padding_mask` or both; got neither."
        )
    for name, m in (("attn_mask", attn_mask), ("key_padding_mask", key_padding_mask)):
        if m is not None and m.dtype != torch.bool:
            raise ValueError(
                f"Expect `{name}` to be a bool tensor (True = may attend), got dtype {m.dtype}. "
                f"Convert a 0/1 mask with `.bool()`."
            )
    if attn_mask is not None and (
        attn_mask.ndim not in (2, 3) or attn_mask.shape[-1] != attn_mask.shape[-2]
    ):
        raise ValueError(
            f"Expect `attn_mask` of shape (T, T) or (B, T, T), got {tuple(attn_mask.shape)}."
        )
    if key_padding_mask is not None and key_padding_mask.ndim != 2:
        raise ValueError(
            f"Expect `key_padding_mask` of shape (B, T), got {tuple(key_padding_mask.shape)}."
        )

    if key_padding_mask is None:
        assert attn_mask is not None  # checked above: at least one mask is given
        allowed = attn_mask if attn_mask.ndim == 3 else attn_mask[None]  # (B, T, T)
    else:
        B, T = key_padding_mask.shape
        if attn_mask is None:
            attn_mask = torch.ones(T, T, dtype=torch.bool, device=key_padding_mask.device)
        if attn_mask.shape[-1] != T or (attn_mask.ndim == 3 and attn_mask.shape[0] != B):
            raise ValueError(
                f"`attn_mask` of shape {tuple(attn_mask.shape)} does not match `key_padding_mask` of "
                f"shape {(B, T)}: expect (T, T) = {(T, T)} or (B, T, T) = {(B, T, T)}."
            )
        allowed = attn_mask & key_padding_mask[:, None, :]  # (B, T, T): real keys only
        # Padded queries attend to themselves only: no all-False row, so no NaN (see docstring).
        eye = torch.eye(T, dtype=torch.bool, device=key_padding_mask.device)  # (T, T)
        padded_query = ~key_padding_mask[:, :, None]  # (B, T, 1)
        allowed = torch.where(padded_query, eye, allowed)  # (B, T, T)
    return allowed[:, None] if keep_head_dim else allowed


def additive_mask(mask: torch.Tensor, dtype: torch.dtype = torch.float32) -> torch.Tensor:
    """The additive mask ``M`` of Eq. 2.3 from a boolean mask: ``0`` where allowed, ``-inf`` else.

    Used in: Background chapter (thesis 2.2).

    Args:
        mask: Bool tensor of any shape, ``True`` = may attend.
        dtype: Floating dtype of ``M``.

    Returns:
        Tensor of ``mask``'s shape with ``0.0`` where ``mask`` is ``True`` and ``-inf`` elsewhere.

    Example:
        >>> additive_mask(causal_mask(2)).tolist()
        [[0.0, -inf], [0.0, 0.0]]
    """
    if mask.dtype != torch.bool:
        raise ValueError(f"Expect a bool mask (True = may attend), got dtype {mask.dtype}.")
    zero = torch.zeros((), dtype=dtype, device=mask.device)
    return torch.where(mask, zero, torch.tensor(float("-inf"), dtype=dtype, device=mask.device))


# ----------------------------------------------------------------------------------------------
# Eq. 2.3, written out


class AttentionOutput(NamedTuple):
    """What :func:`attention` returns."""

    out: torch.Tensor
    """Attended values, ``(B, H, T_q, D_v)``."""
    weights: torch.Tensor
    """Attention weights (rows sum to 1, exactly 0 where masked), ``(B, H, T_q, T_k)``."""


def attention(
    q: torch.Tensor, k: torch.Tensor, v: torch.Tensor, mask: torch.Tensor | None = None
) -> AttentionOutput:
    """Scaled dot-product attention, Eq. 2.3, written out: ``softmax((QK^T + M) / sqrt(D)) V``.

    ``M`` is :func:`additive_mask` of ``mask``: ``0`` where a query may attend, ``-inf`` where it
    may not. The thesis adds ``M`` before dividing by ``sqrt(D)``; for a 0/-inf mask that is the
    same as adding it after (``-inf / sqrt(D) = -inf``), which is what
    ``F.scaled_dot_product_attention`` does. ``D`` is the channels per head (``head_dim``).

    This explicit version is for teaching and for plotting the weights;
    :class:`CausalSelfAttention` uses the fused ``F.scaled_dot_product_attention``, which
    computes the same ``out``.

    Used in: Background chapter (thesis 2.2); attention plots in the DT, HDT, MDLT chapters.

    Args:
        q: Queries ``(B, H, T_q, D)`` (any leading dims work, e.g. ``(B, T_q, D)``).
        k: Keys ``(B, H, T_k, D)``.
        v: Values ``(B, H, T_k, D_v)``.
        mask: Optional bool mask, ``True`` = may attend (torch SDPA convention): ``(T_q, T_k)``,
            ``(B, T_q, T_k)`` (a head axis is inserted for 4-D queries) or ``(B, 1|H, T_q, T_k)``.
            Build it with :func:`causal_mask` / :func:`combine_masks`.

    Returns:
        :class:`AttentionOutput` ``(out (B, H, T_q, D_v), weights (B, H, T_q, T_k))``;
        ``weights[b, h]`` is heatmap-ready (query rows, key columns).

    Raises:
        ValueError: On mismatched shapes, a non-bool mask, or a mask with a query row where no
            key is allowed (softmax of an all ``-inf`` row is ``NaN``).

    Example:
        >>> q = k = v = torch.eye(2)[None, None]  # (B=1, H=1, T=2, D=2)
        >>> out, w = attention(q, k, v, causal_mask(2))
        >>> w[0, 0, 0].tolist()  # the first query sees only itself
        [1.0, 0.0]
    """
    if q.ndim < 2 or k.ndim < 2 or v.ndim < 2:
        raise ValueError(
            f"Expect q, k, v of shape (B, H, T, D), got q {tuple(q.shape)}, k {tuple(k.shape)}, v {tuple(v.shape)}."
        )
    if q.shape[-1] != k.shape[-1]:
        raise ValueError(
            f"Queries and keys need the same channels D: q has {q.shape[-1]}, k has {k.shape[-1]} "
            f"(shapes {tuple(q.shape)} and {tuple(k.shape)})."
        )
    if k.shape[-2] != v.shape[-2]:
        raise ValueError(
            f"Keys and values need the same length T_k: k has {k.shape[-2]}, v has {v.shape[-2]} "
            f"(shapes {tuple(k.shape)} and {tuple(v.shape)})."
        )
    D = q.shape[-1]
    scores = q @ k.transpose(-2, -1)  # (B, H, T_q, T_k) = Q K^T
    if mask is not None:
        if mask.dtype != torch.bool:
            raise ValueError(
                f"Expect a bool `mask` (True = may attend, torch SDPA convention), got dtype {mask.dtype}."
            )
        if mask.ndim == 3 and q.ndim == 4:
            mask = mask[:, None]  # (B, 1, T_q, T_k): broadcast over heads, not over the batch
        if mask.shape[-2:] != scores.shape[-2:]:
            raise ValueError(
                f"Expect the mask's last two dims (T_q, T_k) = {tuple(scores.shape[-2:])}, "
                f"got mask of shape {tuple(mask.shape)}."
            )
        empty = ~mask.any(dim=-1)  # (..., T_q): query rows with no allowed key
        if empty.any():
            where = tuple(int(i) for i in empty.nonzero()[0])
            raise ValueError(
                f"The mask allows no key for query row at index {where} (of mask shape {tuple(mask.shape)}); "
                f"softmax over an all -inf row is NaN. Build padded masks with combine_masks(), "
                f"which lets padded queries attend to themselves."
            )
        scores = scores + additive_mask(mask, dtype=scores.dtype)  # Q K^T + M
    weights = torch.softmax(scores / math.sqrt(D), dim=-1)  # (B, H, T_q, T_k)
    out = weights @ v  # (B, H, T_q, D_v)
    return AttentionOutput(out, weights)


# ----------------------------------------------------------------------------------------------
# Modules: nanoGPT-style pre-LN GPT-2 block, reused by DT / HDT / MDLT.

Activation = Literal["gelu", "gelu_tanh", "relu", "silu"]
ACTIVATIONS: tuple[str, ...] = get_args(Activation)


def _make_activation(name: str) -> nn.Module:
    return {
        "gelu": nn.GELU(),
        "gelu_tanh": nn.GELU(approximate="tanh"),  # GPT-2's "gelu_new"
        "relu": nn.ReLU(),
        "silu": nn.SiLU(),
    }[name]


def _check_key_padding_mask(key_padding_mask: torch.Tensor, B: int, T: int) -> None:
    if key_padding_mask.dtype != torch.bool or tuple(key_padding_mask.shape) != (B, T):
        raise ValueError(
            f"Expect `key_padding_mask` to be a bool tensor of shape (B, T) = {(B, T)} with True at real "
            f"tokens, got dtype {key_padding_mask.dtype} and shape {tuple(key_padding_mask.shape)}. "
            f"Build it with padding_mask(lengths, T)."
        )


def _attend_lane_dropout(
    q: torch.Tensor, k: torch.Tensor, v: torch.Tensor, mask: torch.Tensor | None, p: float
) -> torch.Tensor:
    """``F.scaled_dot_product_attention(q, k, v, attn_mask=mask, dropout_p=p)`` written out, so
    that the attention weights' dropout is :func:`~thesis_lib.seq.dropout.dropout`'s (lane
    masks inside :func:`~thesis_lib.seq.dropout.lane_dropout`). On a CPU with dropout, SDPA
    runs this same math path (no fused kernel), so it costs no more. ``mask``: bool, ``True`` =
    may attend, every query row with at least one key (:func:`combine_masks`).

    In float32 throughout, as SDPA's CPU math path computes bfloat16 inputs (under
    ``TrainConfig(precision="bf16")``'s autocast too); the result has ``q``'s dtype."""
    dtype = q.dtype
    with torch.autocast(q.device.type, enabled=False):
        q, k, v = q.float(), k.float(), v.float()
        scores = (q @ k.transpose(-2, -1)) * (1.0 / math.sqrt(q.shape[-1]))
        if mask is not None:
            scores = scores.masked_fill(~mask, float("-inf"))
        return (dropout(torch.softmax(scores, dim=-1), p) @ v).to(dtype)


class CausalSelfAttention(nn.Module):
    """Multi-head self-attention (Eq. 2.3 per head) on ``F.scaled_dot_product_attention``.

    Causal unless ``config.causal`` is ``False``. An optional key-padding mask hides padded
    tokens from every query; padded queries attend to themselves (see :func:`combine_masks`).

    Used in: Background chapter (thesis 2.2); DT, HDT, MDLT chapters.
    """

    def __init__(self, config: GPTBlockConfig) -> None:
        super().__init__()
        self.config = config
        self.c_attn = nn.Linear(
            config.d_model, 3 * config.d_model, bias=config.bias
        )  # q, k, v for all heads
        self.c_proj = nn.Linear(config.d_model, config.d_model, bias=config.bias)
        self.resid_dropout = Dropout(config.dropout)

    def _qkv(
        self, x: torch.Tensor, queries: slice | None = None
    ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        if x.ndim != 3 or x.shape[-1] != self.config.d_model:
            raise ValueError(
                f"Expect input of shape (B, T, d_model={self.config.d_model}), got {tuple(x.shape)}."
            )
        B, T, C = x.shape
        nh, hs = self.config.n_heads, self.config.head_dim
        if queries is None:
            q, k, v = self.c_attn(x).split(C, dim=2)  # 3 x (B, T, C)
        else:  # the query rows of c_attn on the query tokens only; keys and values on all
            w, b = self.c_attn.weight, self.c_attn.bias
            q = F.linear(x[:, queries], w[:C], None if b is None else b[:C])  # (B, Tq, C)
            k, v = F.linear(x, w[C:], None if b is None else b[C:]).split(C, dim=2)
        q = q.view(B, q.shape[1], nh, hs).transpose(1, 2)  # (B, nh, Tq, hs)
        k = k.view(B, T, nh, hs).transpose(1, 2)  # (B, nh, T, hs)
        v = v.view(B, T, nh, hs).transpose(1, 2)  # (B, nh, T, hs)
        return q, k, v

    def _mask(self, x: torch.Tensor, key_padding_mask: torch.Tensor | None) -> torch.Tensor | None:
        B, T, _ = x.shape
        if key_padding_mask is None:
            return causal_mask(T, device=x.device) if self.config.causal else None  # (T, T)
        _check_key_padding_mask(key_padding_mask, B, T)
        causal = causal_mask(T, device=x.device) if self.config.causal else None
        return combine_masks(causal, key_padding_mask)  # (B, 1, T, T)

    def forward(
        self,
        x: torch.Tensor,
        key_padding_mask: torch.Tensor | None = None,
        queries: slice | None = None,
    ) -> torch.Tensor:
        """Attend.

        Args:
            x: Token embeddings ``(B, T, d_model)``.
            key_padding_mask: Optional bool ``(B, T)``, ``True`` at real tokens.
            queries: ``None``: every token queries. A slice of the token axis: only those
                tokens query (over all keys, with their rows of the same masks), and only
                their outputs are returned: the same numbers as ``forward(x)[:, queries]``
                up to float error and the dropout draws, at a fraction of the cost
                (:class:`Block`).

        Returns:
            ``(B, T, d_model)``, or ``(B, Tq, d_model)`` at the ``queries``.
        """
        q, k, v = self._qkv(x, queries)  # (B, nh, Tq, hs), (B, nh, T, hs) x 2; checks x
        B, Tq, C = x.shape[0], q.shape[2], x.shape[2]
        dropout_p = self.config.dropout if self.training else 0.0
        if queries is not None:  # the queries' rows of the full mask
            mask = self._mask(x, key_padding_mask)  # (T, T), (B, 1, T, T) or None
            if mask is not None:
                mask = mask[queries] if mask.ndim == 2 else mask[:, :, queries]
            if dropout_p > 0.0 and lane_dropout_enabled():
                y = _attend_lane_dropout(q, k, v, mask, dropout_p)
            else:
                y = F.scaled_dot_product_attention(q, k, v, attn_mask=mask, dropout_p=dropout_p)
        elif dropout_p > 0.0 and lane_dropout_enabled():  # TrainConfig(kernels="fast"...)
            y = _attend_lane_dropout(q, k, v, self._mask(x, key_padding_mask), dropout_p)
        elif key_padding_mask is None:
            # The fused kernel builds the causal mask itself.
            y = F.scaled_dot_product_attention(
                q, k, v, dropout_p=dropout_p, is_causal=self.config.causal
            )
        else:
            y = F.scaled_dot_product_attention(
                q, k, v, attn_mask=self._mask(x, key_padding_mask), dropout_p=dropout_p
            )
        y = y.transpose(1, 2).contiguous().view(B, Tq, C)  # (B, Tq, nh * hs): heads side by side
        return self.resid_dropout(self.c_proj(y))

    @torch.no_grad()
    def attention_weights(
        self, x: torch.Tensor, key_padding_mask: torch.Tensor | None = None
    ) -> torch.Tensor:
        """Per-head attention weights for ``x``, through the explicit :func:`attention`.

        Args:
            x: Token embeddings ``(B, T, d_model)`` (the block's input after ``ln_1``).
            key_padding_mask: Optional bool ``(B, T)``, ``True`` at real tokens.

        Returns:
            Weights ``(B, n_heads, T, T)`` without dropout; ``[b, h]`` is heatmap-ready.
        """
        q, k, v = self._qkv(x)
        return attention(q, k, v, self._mask(x, key_padding_mask)).weights


class MLP(nn.Module):
    """Position-wise feed-forward network: ``Linear(d, r d) -> activation -> Linear(r d, d) -> dropout``.

    Used in: Background chapter (thesis 2.2); DT, HDT, MDLT chapters.
    """

    def __init__(self, config: GPTBlockConfig) -> None:
        super().__init__()
        hidden = config.mlp_ratio * config.d_model
        self.c_fc = nn.Linear(config.d_model, hidden, bias=config.bias)
        self.act = _make_activation(config.activation)
        self.c_proj = nn.Linear(hidden, config.d_model, bias=config.bias)
        self.dropout = Dropout(config.dropout)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """``(B, T, d_model) -> (B, T, d_model)``."""
        return self.dropout(self.c_proj(self.act(self.c_fc(x))))


class Block(nn.Module):
    """Pre-LN GPT-2 Transformer block: ``x + attn(ln_1(x))``, then ``x + mlp(ln_2(x))``.

    GPT-2 (and so the DT, which is built on GPT-2) normalises *before* each sub-layer; the
    original Transformer of thesis Fig. 2.1 normalises after the residual sum ("post-LN").

    Used in: Background chapter (thesis 2.2); DT, HDT, MDLT chapters.

    Example:
        >>> _ = torch.manual_seed(0)
        >>> block = Block(GPTBlockConfig(d_model=8, n_heads=2, dropout=0.0))
        >>> tuple(block(torch.randn(3, 5, 8)).shape)
        (3, 5, 8)
    """

    def __init__(self, config: GPTBlockConfig) -> None:
        super().__init__()
        self.ln_1 = nn.LayerNorm(config.d_model, bias=config.bias)
        self.attn = CausalSelfAttention(config)
        self.ln_2 = nn.LayerNorm(config.d_model, bias=config.bias)
        self.mlp = MLP(config)

    def forward(
        self,
        x: torch.Tensor,
        key_padding_mask: torch.Tensor | None = None,
        queries: slice | None = None,
    ) -> torch.Tensor:
        """Apply the block.

        Args:
            x: Token embeddings ``(B, T, d_model)``.
            key_padding_mask: Optional bool ``(B, T)``, ``True`` at real tokens; padded tokens
                are hidden from every real query (outputs at padded positions are meaningless).
            queries: ``None``: every token's output. A slice of the token axis: only those
                tokens' outputs, ``block(x)[:, queries]`` up to float error and the dropout
                draws. Every token is still a key, but the queries, the attention's output
                projection, the residuals and the MLP run on the sliced tokens only: the last
                block of a model that reads one token in ``n`` costs about ``(2 + 10/n) / 12``
                of a full one in matrix products (the models' readout, ``kernels="fast+readout"``).

        Returns:
            ``(B, T, d_model)``, or ``(B, Tq, d_model)`` at the ``queries``.

        Example:
            >>> _ = torch.manual_seed(0)
            >>> block = Block(GPTBlockConfig(d_model=8, n_heads=2, dropout=0.0)).eval()
            >>> x = torch.randn(3, 6, 8)
            >>> torch.allclose(block(x, queries=slice(1, None, 2)), block(x)[:, 1::2], atol=1e-6)
            True
        """
        if x.ndim != 3 or x.shape[-1] != self.ln_1.normalized_shape[0]:
            raise ValueError(
                f"Expect input of shape (B, T, d_model={self.ln_1.normalized_shape[0]}), got {tuple(x.shape)}."
            )
        if queries is None:
            x = x + self.attn(self.ln_1(x), key_padding_mask)
        else:
            x = x[:, queries] + self.attn(self.ln_1(x), key_padding_mask, queries)
        x = x + self.mlp(self.ln_2(x))
        return x

    @torch.no_grad()
    def attention_weights(
        self, x: torch.Tensor, key_padding_mask: torch.Tensor | None = None
    ) -> torch.Tensor:
        """The attention weights this block uses on input ``x`` (for plots).

        Args:
            x: The block's input ``(B, T, d_model)`` (``ln_1`` is applied here).
            key_padding_mask: Optional bool ``(B, T)``, ``True`` at real tokens.

        Returns:
            ``(B, n_heads, T, T)``, rows = queries, columns = keys; ``[b, h]`` is heatmap-ready.
        """
        return self.attn.attention_weights(self.ln_1(x), key_padding_mask)


@dataclass
class GPTBlockConfig:
    """Configuration of one :class:`Block` (and of its attention and MLP).

    Defaults follow the Decision Transformer's gym setup (embedding 128, one head, dropout
    0.1), except the activation: GELU as in GPT-2; the original DT code uses ``"relu"``.

    Used in: Background chapter (thesis 2.2); DT, HDT, MDLT chapters.

    Example:
        >>> GPTBlockConfig(d_model=128, n_heads=4).head_dim
        32
        >>> GPTBlockConfig(d_model=100, n_heads=3)
        Traceback (most recent call last):
        ...
        ValueError: d_model must be divisible by n_heads, got d_model=100 and n_heads=3 (100 % 3 = 1). Choose n_heads among the divisors of 100: 1, 2, 4, 5, 10, 20, 25, 50, 100.
    """

    d_model: int = 128
    """Embedding size ``C`` of every token; split evenly across heads."""
    n_heads: int = 1
    """Number of attention heads; must divide ``d_model``."""
    dropout: float = 0.1
    """Dropout on attention weights and on both residual branches, in ``[0, 1)``."""
    bias: bool = True
    """Biases in the linear layers and LayerNorms (GPT-2 has them)."""
    activation: Activation = "gelu"
    """MLP activation: "gelu", "gelu_tanh" (GPT-2's ``gelu_new``), "relu" (original DT), "silu"."""
    mlp_ratio: int = 4
    """MLP hidden width as a multiple of ``d_model`` (4 in GPT-2 and DT)."""
    causal: bool = True
    """Causal self-attention (decoder, as in GPT-2/DT); ``False`` gives full attention (encoder)."""
    head_dim: int = field(init=False)
    """Derived: channels per head, ``d_model // n_heads`` (the ``D`` of Eq. 2.3)."""

    def __post_init__(self) -> None:
        for name in ("d_model", "n_heads", "mlp_ratio"):
            value = getattr(self, name)
            if not isinstance(value, int) or isinstance(value, bool) or value <= 0:
                raise ValueError(f"Expect `{name}` to be a positive int, actually: {value!r}.")
        if self.d_model % self.n_heads != 0:
            divisors = ", ".join(
                str(n) for n in range(1, self.d_model + 1) if self.d_model % n == 0
            )
            raise ValueError(
                f"d_model must be divisible by n_heads, got d_model={self.d_model} and n_heads={self.n_heads} "
                f"({self.d_model} % {self.n_heads} = {self.d_model % self.n_heads}). "
                f"Choose n_heads among the divisors of {self.d_model}: {divisors}."
            )
        if not 0.0 <= self.dropout < 1.0:
            raise ValueError(f"Expect `dropout` in [0, 1), actually: {self.dropout!r}.")
        if self.activation not in ACTIVATIONS:
            raise ValueError(
                f"Unknown activation {self.activation!r}. Valid: {', '.join(ACTIVATIONS)}."
            )
        self.head_dim = self.d_model // self.n_heads
