"""Sequence-model foundations (thesis Ch. 2): attention and GPT blocks, SSMs, DT tokens.

* :mod:`thesis_lib.seq.attention_ops` - positional encoding (Eq. 2.1-2.2), masks, attention
  (Eq. 2.3), and the pre-LN GPT :class:`Block` reused by DT, HDT and MDLT.
* :mod:`thesis_lib.seq.ssm` - S4's LTI state space model (Eq. 2.4-2.7) and Mamba's selective
  scan reference.
* :mod:`thesis_lib.seq.tokens` - returns-to-go and the DT token layout (Sec. 2.8).
* :mod:`thesis_lib.seq.models` - BC, the Decision Transformer (with and without returns-to-go)
  and the Hierarchical Decision Transformer (Sec. 5.2); :mod:`thesis_lib.seq.subgoals` - HDT's
  sub-goal selection (5.2.2).
* :mod:`thesis_lib.seq.mamba` - a Mamba-1 block with a fast CPU selective scan (numba, hand-written
  backward) and an O(1)-per-token recurrent step (Sec. 2.3, 5.3); ``mamba_ssm`` on CUDA.
* :mod:`thesis_lib.seq.dm` - the Decision Mamba and the Hierarchical Decision Mamba (Sec. 5.3),
  acting recurrently.
* :mod:`thesis_lib.seq.trainer` and :mod:`thesis_lib.seq.evaluation` - the one trainer and the
  one evaluator of every sequence model.
* :mod:`thesis_lib.seq.registry` - one registry of BC, DT, DT-noRTG, HDT, HDT-RTG, DM-RTG,
  DM-noRTG and HDM built from one :class:`ArchSpec`; :mod:`thesis_lib.seq.runner` - the one
  offline run (:func:`run_offline`: train, evaluate along the way, rows) of the HDT, Decision
  Mamba and UR3 chapters (their tables live in :mod:`thesis_lib.chapters`).

Mask convention throughout: a boolean mask is ``True`` where a query may attend (torch SDPA's).

Used in: Background chapter (thesis 2.2, 2.3, 2.8); DT, HDT, MDLT, Decision Mamba chapters.
"""

from __future__ import annotations

from thesis_lib.seq.attention_ops import (
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
from thesis_lib.seq.dm import HDM, DecisionMamba, DMConfig, HDMConfig, RecurrentPolicy, TokenMamba
from thesis_lib.seq.evaluation import EvalResult, evaluate, target_returns
from thesis_lib.seq.mamba import (
    SCAN_BACKENDS,
    GatedMLP,
    LayerState,
    Mamba,
    MambaBlock,
    MambaConfig,
    MambaMixer,
    MambaState,
    ScanOutput,
    causal_depthwise_conv1d,
    resolve_scan_backend,
    selective_scan,
)
from thesis_lib.seq.models import (
    BC,
    HDT,
    INIT_SCHEMES,
    BCConfig,
    DecisionTransformer,
    DTConfig,
    HDTConfig,
    SeqOutput,
    TokenTransformer,
    init_transformer,
    masked_mse,
)
from thesis_lib.seq.registry import METHODS, ArchSpec, build_model
from thesis_lib.seq.runner import EvalSpec, TrainSpec, run_offline
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
from thesis_lib.seq.subgoals import select_subgoal_indices, select_subgoals, subgoal_fn
from thesis_lib.seq.tokens import (
    MODALITIES,
    deinterleave_embeddings,
    interleave_embeddings,
    interleave_tokens,
    returns_to_go,
)
from thesis_lib.seq.trainer import TrainConfig, Trainer, batch_to_torch

__all__ = [
    "METHODS",
    "ArchSpec",
    "EvalSpec",
    "TrainSpec",
    "build_model",
    "run_offline",
    "DMConfig",
    "DecisionMamba",
    "HDM",
    "HDMConfig",
    "RecurrentPolicy",
    "TokenMamba",
    "ACTIVATIONS",
    "BC",
    "HDT",
    "MLP",
    "MODALITIES",
    "SCAN_BACKENDS",
    "AttentionOutput",
    "BCConfig",
    "Block",
    "CausalSelfAttention",
    "DTConfig",
    "DecisionTransformer",
    "Discretization",
    "EvalResult",
    "GPTBlockConfig",
    "GatedMLP",
    "HDTConfig",
    "INIT_SCHEMES",
    "LayerState",
    "Mamba",
    "MambaBlock",
    "MambaConfig",
    "MambaMixer",
    "MambaState",
    "ScanOutput",
    "ScanStep",
    "SeqOutput",
    "TokenTransformer",
    "TrainConfig",
    "Trainer",
    "additive_mask",
    "attention",
    "batch_to_torch",
    "causal_depthwise_conv1d",
    "causal_mask",
    "combine_masks",
    "deinterleave_embeddings",
    "evaluate",
    "hippo_legs",
    "interleave_embeddings",
    "interleave_tokens",
    "init_transformer",
    "masked_mse",
    "padding_mask",
    "resolve_scan_backend",
    "returns_to_go",
    "select_subgoal_indices",
    "select_subgoals",
    "selective_scan",
    "selective_scan_reference",
    "selective_scan_step",
    "sinusoidal_positional_encoding",
    "ssm_convolution",
    "ssm_kernel",
    "ssm_recurrence",
    "subgoal_fn",
    "target_returns",
    "zoh_discretize",
]
