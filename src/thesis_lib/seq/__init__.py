"""Sequence-model foundations (thesis Ch. 2): attention and GPT blocks, SSMs, DT tokens.

* :mod:`thesis_lib.seq.attention` - positional encoding (Eq. 2.1-2.2), masks, attention
  (Eq. 2.3), and the pre-LN GPT :class:`Block` reused by DT, HDT and MDLT.
* :mod:`thesis_lib.seq.ssm` - S4's LTI state space model (Eq. 2.4-2.7) and Mamba's selective
  scan reference.
* :mod:`thesis_lib.seq.tokens` - returns-to-go and the DT token layout (Sec. 2.8).

Mask convention throughout: a boolean mask is ``True`` where a query may attend (torch SDPA's).

Used in: Background chapter (thesis 2.2, 2.3, 2.8); DT, HDT, MDLT, Decision Mamba chapters.
"""
from __future__ import annotations

from thesis_lib.seq.attention import (
    ACTIVATIONS,
    MLP,
    AttentionOutput,
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
from thesis_lib.seq.ssm import (
    Discretization,
    ScanStep,
    hippo_legs,
    selective_scan_reference,
    selective_scan_step,
    ssm_convolution,
    ssm_kernel,
    ssm_recurrence,
    zoh_discretize,
)
from thesis_lib.seq.tokens import (
    MODALITIES,
    deinterleave_embeddings,
    interleave_embeddings,
    interleave_tokens,
    returns_to_go,
)

__all__ = [
    "ACTIVATIONS",
    "MLP",
    "MODALITIES",
    "AttentionOutput",
    "Block",
    "CausalSelfAttention",
    "Discretization",
    "GPTBlockConfig",
    "ScanStep",
    "additive_mask",
    "attention",
    "causal_mask",
    "combine_masks",
    "deinterleave_embeddings",
    "hippo_legs",
    "interleave_embeddings",
    "interleave_tokens",
    "padding_mask",
    "returns_to_go",
    "selective_scan_reference",
    "selective_scan_step",
    "sinusoidal_positional_encoding",
    "ssm_convolution",
    "ssm_kernel",
    "ssm_recurrence",
    "zoh_discretize",
]
