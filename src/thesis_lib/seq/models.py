"""BC, the Decision Transformer and the Hierarchical Decision Transformer (thesis 2.8, 5.2).

Read top-down, as nanoGPT's ``model.py``: the shared parts first (configs, input checks, the
masked MSE, :class:`TokenTransformer`), then the three models, one screen each.

Every model takes the same input: a dict of tensors, as ``SequenceBatch.to_torch()`` gives
(plus ``prev_subgoals`` for HDT, see :func:`thesis_lib.seq.trainer.batch_to_torch`)::

    states         (B, T, state_dim)   z-scored s_t
    actions        (B, T, act_dim)     a_t (targets; also the action tokens by default)
    prev_actions   (B, T, act_dim)     a_{t-1}, zero at the episode start (paper_compat tokens)
    returns_to_go  (B, T, 1)           rtg_t / rtg_scale
    timesteps      (B, T)              step index in the episode (int64)
    mask           (B, T)              True = real step (attend, count in the loss)
    subgoals       (B, T, state_dim)   g_t (HDT targets, low-level input)
    prev_subgoals  (B, T, state_dim)   g_{t-1}, zero at the episode start (HDT high-level input)

``model(batch, targets=batch)`` returns a :class:`SeqOutput` with the predictions and the
masked MSE; ``model.act(history)`` (``@torch.no_grad()``) returns the action (and sub-goal)
for the last step of each history, for evaluation.

``paper_compat=True`` switches (``notes/original-code.md``):

* action tokens: the authors' DT and HDT put ``a_{t-1}`` (a zero action prepended) in the
  action slot of step ``t``, after ``s_t``; the action ``a_t`` is read at ``s_t``, which then
  sees actions up to ``a_{t-2}`` only. The default puts ``a_t`` there, as the DT paper: the
  ``s_t`` token sees ``a_{t-1}`` in the previous step's slot, and ``a_t`` only after it.
* initialisation (``init="auto"`` resolves to ``"original"``): the authors' DT and HDT built
  their trunk from Hugging Face's ``GPT2Model``, which draws its weights from N(0, 0.02) (the
  residual projections from N(0, 0.02 / sqrt(2 n_layers))), and left their own embeddings,
  time-step table and heads at PyTorch's defaults. The default (``"normal"``) draws every
  Linear and Embedding from N(0, 0.02) with zero biases, as CORL's DT and the transformers
  library's ``DecisionTransformerModel``: with PyTorch's defaults everywhere (``"torch"``, the
  v1 studies) the DT learned to half of a peer DT's score on the same data (issue #33; the
  reproduction report's parity section);
* (in the data) time-steps left-padded: :class:`thesis_lib.data.SequenceDataset`;
  the last state's sub-goal is state 0: :func:`thesis_lib.seq.subgoals.subgoal_fn`.

Used in: HDT chapter (thesis 5.2, Tables 5.1-5.3, 5.6); Decision Mamba chapter (baselines).
"""

from __future__ import annotations

import contextlib
import contextvars
from collections.abc import Iterator, Mapping
from dataclasses import dataclass
from typing import Any, Literal, NamedTuple

import torch
import torch.nn as nn

from thesis_lib.seq.attention_ops import ACTIVATIONS, Block, GPTBlockConfig
from thesis_lib.seq.dropout import Dropout
from thesis_lib.seq.tokens import deinterleave_embeddings, interleave_embeddings

__all__ = [
    "BC",
    "BCConfig",
    "DTConfig",
    "DecisionTransformer",
    "HDT",
    "HDTConfig",
    "INIT_SCHEMES",
    "ModelConfig",
    "SeqOutput",
    "TwoLevel",
    "TokenTransformer",
    "action_head",
    "action_key",
    "action_output",
    "check_inputs",
    "init_transformer",
    "masked_mse",
    "readout_only",
    "readout_only_enabled",
    "rsa_tokens",
]

Tensors = Mapping[str, torch.Tensor]


class SeqOutput(NamedTuple):
    """What every model's ``forward`` returns.

    Attributes:
        actions: ``(B, T, act_dim)`` predicted actions (Tanh x ``max_action``).
        subgoals: ``(B, T, state_dim)`` predicted sub-goals (HDT), else ``None``.
        loss: Scalar training loss when targets were given (HDT: high + low), else ``None``.
        losses: Named parts of the loss as floats, e.g. ``{"action": 0.3}`` (for logs).
    """

    actions: torch.Tensor
    subgoals: torch.Tensor | None = None
    loss: torch.Tensor | None = None
    losses: dict[str, float] | None = None


def masked_mse(pred: torch.Tensor, target: torch.Tensor, mask: torch.Tensor | None) -> torch.Tensor:
    """Mean squared error over real steps and feature dims (the authors' ``loss[mask > 0].mean()``).

    Args:
        pred: ``(B, T, D)``.
        target: ``(B, T, D)``.
        mask: ``(B, T)`` bool, ``True`` = count this step; ``None`` = all.

    Returns:
        Scalar tensor.

    Example:
        >>> p, t = torch.zeros(1, 2, 1), torch.tensor([[[1.0], [3.0]]])
        >>> masked_mse(p, t, torch.tensor([[True, False]])).item()
        1.0
    """
    if pred.shape != target.shape:
        raise ValueError(
            f"Prediction shape {tuple(pred.shape)} differs from target shape {tuple(target.shape)}."
        )
    # at least float32: under bfloat16 autocast the heads' predictions come in bf16, and the
    # targets and the loss keep their precision (as autocast's own mse_loss does)
    dtype = torch.promote_types(torch.promote_types(pred.dtype, target.dtype), torch.float32)
    err = (pred.to(dtype) - target.to(dtype)) ** 2  # (B, T, D)
    if mask is None:
        return err.mean()
    return err[mask.bool()].mean()  # (n_real, D) -> scalar


# ----------------------------------------------------------------------------------------------
# Configs


@dataclass
class ModelConfig:
    """What every sequence model's config holds: the data's sizes, the action bound and the
    context length ``K``. The base of :class:`BCConfig`, :class:`DTConfig`, :class:`HDTConfig`
    and of the Mamba configs (:mod:`thesis_lib.seq.dm`)."""

    state_dim: int
    """Size of a state (observation) vector; must match the data set."""
    act_dim: int
    """Size of an action vector."""
    max_action: float = 1.0
    """Action heads output ``tanh(.) * max_action`` (``env.action_space.high``; 1 for MuJoCo)."""
    K: int = 20
    """Context length: the number of time steps a window (and an evaluation history) holds."""

    @classmethod
    def for_data(cls, seq: Any, **kwargs: Any):
        """A config sized for a :class:`~thesis_lib.data.SequenceDataset`: its state and action sizes and K.

        Example:
            >>> from types import SimpleNamespace
            >>> seq = SimpleNamespace(states=torch.zeros(10, 11), actions=torch.zeros(10, 3), K=20)
            >>> DTConfig.for_data(seq, n_layers=2)
            DTConfig(state_dim=11, act_dim=3, max_action=1.0, K=20, d_model=128, n_layers=2, n_heads=1, dropout=0.1, activation='relu', max_timestep=4096, paper_compat=False, init='auto', use_rtg=True)
        """
        sizes: dict[str, Any] = dict(
            state_dim=int(seq.states.shape[-1]), act_dim=int(seq.actions.shape[-1]), K=int(seq.K)
        )
        return cls(**{**sizes, **kwargs})

    def __post_init__(self) -> None:
        for name in ("state_dim", "act_dim", "K"):
            value = getattr(self, name)
            if not isinstance(value, int) or isinstance(value, bool) or value <= 0:
                raise ValueError(f"Expect `{name}` to be a positive int, actually: {value!r}.")
        if not self.max_action > 0:
            raise ValueError(
                f"Expect `max_action` > 0 (the action bound), actually: {self.max_action!r}."
            )


@dataclass
class BCConfig(ModelConfig):
    """Configuration of :class:`BC` (thesis 5.2.5.3: "an MLP with two fully connected layers").

    Used in: HDT chapter (Table 5.3).
    """

    hidden_dim: int = 256
    """Width of both hidden layers."""
    dropout: float = 0.1
    """Dropout after each hidden layer."""

    def __post_init__(self) -> None:
        super().__post_init__()
        if not isinstance(self.hidden_dim, int) or self.hidden_dim <= 0:
            raise ValueError(
                f"Expect `hidden_dim` to be a positive int, actually: {self.hidden_dim!r}."
            )
        if not 0.0 <= self.dropout < 1.0:
            raise ValueError(f"Expect `dropout` in [0, 1), actually: {self.dropout!r}.")


@dataclass
class _TransformerConfig(ModelConfig):
    d_model: int = 128
    """Token embedding size (128 in the authors' code)."""
    n_layers: int = 3
    """Number of GPT blocks (per level for HDT)."""
    n_heads: int = 1
    """Attention heads; must divide ``d_model``."""
    dropout: float = 0.1
    """Dropout on embeddings, attention and residual branches."""
    activation: Literal["gelu", "gelu_tanh", "relu", "silu"] = "relu"
    """MLP activation; the authors' GPT-2 config used "relu"."""
    max_timestep: int = 4096
    """Size of the learned time-step embedding table (time steps ``0 .. max_timestep-1``)."""
    paper_compat: bool = False
    """Action token ``a_{t-1}`` and the initialisation as in the authors' code (see the module
    docstring)."""
    init: Literal["auto", "normal", "original", "torch", "d3rlpy"] = "auto"
    """Weight initialisation, of :data:`INIT_SCHEMES`: ``"normal"`` (every Linear and Embedding
    N(0, 0.02), zero biases: CORL, Hugging Face), ``"original"`` (the authors' code: GPT-2's
    init in the trunk only), ``"torch"`` (PyTorch's defaults: the v1 studies), ``"d3rlpy"``
    (d3rlpy's DT, for the parity runs: ``"normal"`` in the trunk, PyTorch's defaults for the
    token embeddings and heads), ``"auto"`` (``"original"`` with ``paper_compat``, else
    ``"normal"``)."""

    def __post_init__(self) -> None:
        super().__post_init__()
        resolve_init(self.init, self.paper_compat)  # validates
        if not isinstance(self.n_layers, int) or self.n_layers <= 0:
            raise ValueError(
                f"Expect `n_layers` to be a positive int, actually: {self.n_layers!r}."
            )
        if not isinstance(self.max_timestep, int) or self.max_timestep <= 0:
            raise ValueError(
                f"Expect `max_timestep` to be a positive int, actually: {self.max_timestep!r}."
            )
        if self.activation not in ACTIVATIONS:
            raise ValueError(
                f"Unknown activation {self.activation!r}. Valid: {', '.join(ACTIVATIONS)}."
            )
        self.block_config()  # validates d_model, n_heads, dropout

    @property
    def resolved_init(self) -> str:
        """``"normal"``, ``"original"``, ``"torch"`` or ``"d3rlpy"`` (``"auto"`` resolved)."""
        return resolve_init(self.init, self.paper_compat)

    def block_config(self) -> GPTBlockConfig:
        """The :class:`GPTBlockConfig` of each block."""
        return GPTBlockConfig(
            d_model=self.d_model,
            n_heads=self.n_heads,
            dropout=self.dropout,
            activation=self.activation,
        )


@dataclass
class DTConfig(_TransformerConfig):
    """Configuration of :class:`DecisionTransformer` (thesis 2.8, 5.2.5.1).

    Used in: HDT chapter (Tables 5.1, 5.3).
    """

    use_rtg: bool = True
    """Tokens ``(rtg_t, s_t, a_t)``; ``False`` gives Table 5.1's "DT w/o desired returns" ``(s_t, a_t)``."""


@dataclass
class HDTConfig(_TransformerConfig):
    """Configuration of :class:`HDT`; ``d_model``, ``n_layers``, ``n_heads`` serve both levels.

    Used in: HDT chapter (Tables 5.2, 5.3).
    """

    low_use_rtg: bool = False
    """Add ``rtg_t`` to the low level's tokens: Table 5.2's "HDT with desired returns"."""


# ----------------------------------------------------------------------------------------------
# Input checks: fail at the door with both shapes, not deep inside a matmul.


def check_inputs(model: nn.Module, batch: Tensors, keys: tuple[str, ...]) -> tuple[int, int]:
    """``(B, T)`` of ``batch`` after checking it holds ``keys`` with the shapes ``model``'s
    config expects (states, actions, sub-goals, returns-to-go, time steps); a ``KeyError`` or
    ``ValueError`` naming the model and both shapes otherwise. Every model calls it first."""
    cfg: Any = model.config  # every sequence model keeps its config as ``.config``
    name = type(model).__name__
    missing = [k for k in keys if k not in batch]
    if missing:
        raise KeyError(
            f"{name} needs the inputs {', '.join(keys)}; missing: {', '.join(missing)}. "
            f"Build the batch with SequenceBatch.to_torch() (HDT: thesis_lib.seq.trainer.batch_to_torch)."
        )
    s = batch["states"]
    if s.ndim != 3 or s.shape[-1] != cfg.state_dim:
        raise ValueError(
            f"{name} expects states of shape (batch, seq_len, {cfg.state_dim}), got {tuple(s.shape)}. "
            f"The model was built with state_dim={cfg.state_dim}; load the data set it was built for, "
            f"or build a new model with state_dim={s.shape[-1] if s.ndim else '?'}."
        )
    B, T = s.shape[:2]
    if T > cfg.K:
        raise ValueError(
            f"Cannot forward a sequence of {T} steps: {name} was built with context K={cfg.K}."
        )
    dims = {
        "actions": cfg.act_dim,
        "prev_actions": cfg.act_dim,
        "subgoals": cfg.state_dim,
        "prev_subgoals": cfg.state_dim,
        "returns_to_go": 1,
    }
    for k in keys:
        if k in dims and tuple(batch[k].shape) != (B, T, dims[k]):
            raise ValueError(
                f"{name} expects {k} of shape (batch, seq_len, {dims[k]}) = {(B, T, dims[k])}, "
                f"got {tuple(batch[k].shape)}."
            )
    if "timesteps" in keys:
        ts = batch["timesteps"]
        if tuple(ts.shape) != (B, T):
            raise ValueError(
                f"{name} expects timesteps of shape (batch, seq_len) = {(B, T)}, got {tuple(ts.shape)}."
            )
        if ts.numel() and int(ts.max()) >= cfg.max_timestep:
            raise ValueError(
                f"Time step {int(ts.max())} is beyond the time-step embedding (max_timestep={cfg.max_timestep}); "
                f"build the model with max_timestep > the longest episode."
            )
    return B, T


#: the name the models here call (``benchmarks/bench_ensemble.py`` swaps it to skip the check
#: under ``vmap``, which cannot read a value)
_check_inputs = check_inputs


def action_head(d_in: int, act_dim: int) -> nn.Sequential:
    """``Linear(d_in, act_dim) + Tanh``: the action head of the DT, HDT and the Mambas (the
    model scales it by ``max_action``)."""
    return nn.Sequential(nn.Linear(d_in, act_dim), nn.Tanh())


def action_key(paper_compat: bool) -> str:
    """The batch entry in the action slot: ``a_t`` (correct), or ``a_{t-1}`` as the authors' code."""
    return "prev_actions" if paper_compat else "actions"


def rsa_tokens(model: Any, batch: Tensors) -> list[torch.Tensor]:
    """``[rtg_t,] s_t, a_t`` embeddings of a DT-style model (``embed_rtg``/``embed_state``/``embed_action``)."""
    tokens = [
        model.embed_state(batch["states"]),
        model.embed_action(batch[action_key(model.config.paper_compat)]),
    ]
    if model.embed_rtg is not None:
        tokens.insert(0, model.embed_rtg(batch["returns_to_go"]))  # (rtg_t, s_t, a_t)
    return tokens


def action_output(actions: torch.Tensor, batch: Tensors, targets: Tensors | None) -> SeqOutput:
    """``SeqOutput`` of a model that predicts actions only; with ``targets`` the masked MSE."""
    if targets is None:
        return SeqOutput(actions)
    loss = masked_mse(actions, targets["actions"], batch.get("mask"))
    return SeqOutput(actions, loss=loss, losses={"action": loss.item()})


# ----------------------------------------------------------------------------------------------
# Initialisation

INIT_SCHEMES: tuple[str, ...] = ("auto", "normal", "original", "torch", "d3rlpy")
"""Weight initialisations of the transformers (:attr:`DTConfig.init`)."""


def resolve_init(init: str, paper_compat: bool) -> str:
    """``init`` with ``"auto"`` resolved: ``"original"`` with ``paper_compat``, else ``"normal"``.

    Example:
        >>> resolve_init("auto", False), resolve_init("auto", True), resolve_init("torch", True)
        ('normal', 'original', 'torch')
    """
    if init not in INIT_SCHEMES:
        raise ValueError(f"Unknown init {init!r}. Valid: {', '.join(INIT_SCHEMES)}.")
    if init == "auto":
        return "original" if paper_compat else "normal"
    return init


@torch.no_grad()
def _normal_(module: nn.Module, std: float = 0.02) -> None:
    """Every Linear and Embedding of ``module``: weights N(0, std), biases zero; LayerNorms (1, 0)."""
    for m in module.modules():
        if isinstance(m, (nn.Linear, nn.Embedding)):
            m.weight.normal_(0.0, std)
        if isinstance(m, nn.Linear) and m.bias is not None:
            m.bias.zero_()
        if isinstance(m, nn.LayerNorm):
            if m.weight is not None:
                m.weight.fill_(1.0)
            if m.bias is not None:
                m.bias.zero_()


@torch.no_grad()
def init_transformer(model: nn.Module, scheme: str, n_layers: int) -> nn.Module:
    """Initialise a DT-style ``model`` in place by ``scheme`` (resolved: not ``"auto"``).

    * ``"normal"``: every Linear and Embedding N(0, 0.02), zero biases, LayerNorms (1, 0), in
      module order: CORL's ``DecisionTransformer._init_weights`` and Hugging Face's
      ``DecisionTransformerModel``.
    * ``"original"``: only the GPT blocks of every :class:`TokenTransformer`, as Hugging Face's
      ``GPT2Model`` initialises itself: N(0, 0.02), the residual projections (``c_proj``)
      N(0, 0.02 / sqrt(2 n_layers)), zero biases; the time-step table, the token embeddings,
      ``embed_ln`` and the heads keep PyTorch's defaults, as in the authors' code, which made
      them outside the GPT-2 model.
    * ``"torch"``: nothing (PyTorch's defaults: Linear Kaiming-uniform, Embedding N(0, 1)).
    * ``"d3rlpy"``: d3rlpy 2.8.1's ``ContinuousDecisionTransformer``, for the parity runs: every
      :class:`TokenTransformer` (the time-step table, ``embed_ln``, the GPT blocks, ``ln_f``) as
      ``"normal"`` (no residual scaling), the token embeddings and the heads at PyTorch's
      defaults (d3rlpy attaches them after its ``apply(_init_weights)``).

    Returns:
        ``model``.

    Example:
        >>> m = DecisionTransformer(DTConfig(state_dim=3, act_dim=2, d_model=16, n_layers=1))
        >>> round(m.transformer.embed_timestep.weight.std().item(), 2)  # "auto" = "normal"
        0.02
    """
    if scheme == "normal":
        _normal_(model)
    elif scheme == "original":
        resid_std = 0.02 / (2 * n_layers) ** 0.5
        for trunk in (m for m in model.modules() if isinstance(m, TokenTransformer)):
            for name, p in trunk.blocks.named_parameters():
                if name.endswith("c_proj.weight"):
                    p.normal_(0.0, resid_std)
                elif p.ndim >= 2:
                    p.normal_(0.0, 0.02)
                elif name.endswith("bias"):
                    p.zero_()
                else:  # LayerNorm weights
                    p.fill_(1.0)
    elif scheme == "d3rlpy":
        for trunk in (m for m in model.modules() if isinstance(m, TokenTransformer)):
            _normal_(trunk)
    elif scheme != "torch":
        raise ValueError(
            f"Unknown init {scheme!r}. Valid: normal, original, torch, d3rlpy (or auto, resolved "
            "first)."
        )
    return model


# ----------------------------------------------------------------------------------------------
# The shared transformer trunk


_READOUT: contextvars.ContextVar[bool] = contextvars.ContextVar("readout_only", default=False)


@contextlib.contextmanager
def readout_only(enabled: bool = True) -> Iterator[None]:
    """Within this context, a :class:`TokenTransformer` asked for one modality's output
    (``read=``) runs its last block on that modality's tokens only (``Block(queries=...)``).

    The outputs it returns are the same as outside the context up to float error (and the
    dropout draws of the last block, which are fewer): every token is still a key of the last
    block, and no token's output there feeds another's. So a training step's loss and
    gradients are the same function of the weights, at about two thirds of the trunk's cost
    for a 2-layer DT. The :class:`~thesis_lib.seq.trainer.Trainer` enters it for
    ``TrainConfig(kernels="fast+readout")`` (issue #36's throughput), for the training step
    only; ``act`` and evaluation run the full trunk.

    Example:
        >>> with readout_only():
        ...     readout_only_enabled()
        True
        >>> readout_only_enabled()
        False
    """
    token = _READOUT.set(bool(enabled))
    try:
        yield
    finally:
        _READOUT.reset(token)


def readout_only_enabled() -> bool:
    """Whether the current context runs the last block on the read tokens only (:func:`readout_only`)."""
    return _READOUT.get()


class TokenTransformer(nn.Module):
    """GPT trunk over interleaved per-step tokens: the part DT and both HDT levels share.

    ``forward([x1, x2, ...], timesteps, mask)`` adds the learned time-step embedding to every
    modality's ``(B, T, d)`` embedding, interleaves them ``(x1_0, x2_0, ..., x1_1, ...)``,
    applies LayerNorm to the stacked tokens (as the DT's ``embed_ln``), dropout, the causal
    GPT blocks with the step mask repeated per token, a final LayerNorm (GPT-2's ``ln_f``),
    and splits the output back per modality.

    Used in: HDT chapter (DT, HDT), Decision Mamba chapter (DT baseline).
    """

    def __init__(self, config: _TransformerConfig) -> None:
        super().__init__()
        self.embed_timestep = nn.Embedding(config.max_timestep, config.d_model)
        self.embed_ln = nn.LayerNorm(config.d_model)
        self.drop = Dropout(config.dropout)
        self.blocks = nn.ModuleList([Block(config.block_config()) for _ in range(config.n_layers)])
        self.ln_f = nn.LayerNorm(config.d_model)

    def forward(
        self,
        tokens: list[torch.Tensor],
        timesteps: torch.Tensor,
        mask: torch.Tensor | None = None,
        read: int | None = None,
    ) -> Any:
        """Run the trunk.

        Args:
            tokens: ``n`` embeddings ``(B, T, d)``, in token order within a step.
            timesteps: ``(B, T)`` int64 time steps.
            mask: ``(B, T)`` bool, ``True`` = real step; ``None`` = all real.
            read: ``None``: return every modality's output. An index into ``tokens`` (negative
                counts from the end): return that modality's output only; inside
                :func:`readout_only` the last block then runs on its tokens only.

        Returns:
            ``n`` outputs ``(B, T, d)``: the output at each modality's token; with ``read``,
            the one output ``(B, T, d)``.
        """
        n = len(tokens)
        if read is not None and not -n <= read < n:
            raise ValueError(f"Expect `read` in [{-n}, {n}) for {n} token(s), actually: {read!r}.")
        time = self.embed_timestep(timesteps)  # (B, T, d), shared by the step's tokens
        x = interleave_embeddings(*(tok + time for tok in tokens))  # (B, n T, d)
        x = self.drop(self.embed_ln(x))
        key_padding = None
        if mask is not None and not bool(mask.all()):  # all real: the fused causal kernel, no mask
            key_padding = interleave_embeddings(*([mask.bool()] * n))  # (B, n T)
        # inside readout_only, the last block's queries: the read modality's tokens only
        readout = slice(read % n, None, n) if read is not None and readout_only_enabled() else None
        last = len(self.blocks) - 1
        for i, block in enumerate(self.blocks):
            x = block(x, key_padding, readout if i == last else None)
        if readout is not None:
            return self.ln_f(x)  # (B, T, d): the read modality's tokens
        out = deinterleave_embeddings(self.ln_f(x), n)
        return out if read is None else out[read]


# ----------------------------------------------------------------------------------------------
# Models


class BC(nn.Module):
    """Behaviour cloning: ``a_t = tanh(MLP(s_t)) * max_action``, two hidden layers (thesis 5.2.5.3).

    Applied step by step to a window, so it trains on the same batches as DT and HDT and its
    loss is the same masked MSE.

    Used in: HDT chapter (Table 5.3).
    """

    def __init__(self, config: BCConfig) -> None:
        super().__init__()
        self.config = config
        h = config.hidden_dim
        self.net = nn.Sequential(
            nn.Linear(config.state_dim, h), nn.ReLU(), Dropout(config.dropout),
            nn.Linear(h, h), nn.ReLU(), Dropout(config.dropout),
            nn.Linear(h, config.act_dim), nn.Tanh(),
        )  # fmt: skip

    def forward(self, batch: Tensors, targets: Tensors | None = None) -> SeqOutput:
        """Predict ``a_t`` from ``s_t``; with ``targets`` (``targets["actions"]``) also the loss."""
        _check_inputs(self, batch, ("states",))
        actions = self.net(batch["states"]) * self.config.max_action  # (B, T, act_dim)
        return action_output(actions, batch, targets)

    @torch.no_grad()
    def act(self, history: Tensors) -> SeqOutput:
        """Action for the last state of each history: ``SeqOutput.actions`` is ``(B, act_dim)``."""
        out = self.forward({"states": history["states"][:, -1:]})
        return SeqOutput(out.actions[:, -1])


class DecisionTransformer(nn.Module):
    """Decision Transformer (Chen et al. 2021; thesis 2.8): tokens ``(rtg_t, s_t, a_t)``.

    ``a_t`` is read at the ``s_t`` token, which sees ``rtg_{<=t}``, ``s_{<=t}``, ``a_{<t}``.
    ``use_rtg=False`` drops the RTG token (Table 5.1's "DT w/o desired returns");
    ``paper_compat=True`` puts ``a_{t-1}`` in the action slot as the authors' code.

    Used in: HDT chapter (Tables 5.1, 5.3); Decision Mamba chapter.
    """

    def __init__(self, config: DTConfig) -> None:
        super().__init__()
        self.config = config
        d = config.d_model
        self.embed_rtg = nn.Linear(1, d) if config.use_rtg else None
        self.embed_state = nn.Linear(config.state_dim, d)
        self.embed_action = nn.Linear(config.act_dim, d)
        self.transformer = TokenTransformer(config)
        self.predict_action = action_head(d, config.act_dim)
        init_transformer(self, config.resolved_init, config.n_layers)

    def input_keys(self) -> tuple[str, ...]:
        a_key = action_key(self.config.paper_compat)
        return ("states", a_key, "timesteps") + (("returns_to_go",) if self.config.use_rtg else ())

    def forward(self, batch: Tensors, targets: Tensors | None = None) -> SeqOutput:
        """Predict ``a_t`` at every step; with ``targets`` (``targets["actions"]``) also the loss."""
        _check_inputs(self, batch, self.input_keys())
        tokens = rsa_tokens(self, batch)
        h_state = self.transformer(tokens, batch["timesteps"], batch.get("mask"), read=-2)  # at s_t
        actions = self.predict_action(h_state) * self.config.max_action
        return action_output(actions, batch, targets)

    @torch.no_grad()
    def act(self, history: Tensors) -> SeqOutput:
        """Action at the last step of each history ``(B, T <= K, ...)``; ``.actions`` is ``(B, act_dim)``.

        The last step's ``actions`` entry is not yet known; any value works (zeros): the
        causal mask hides it from the ``s_t`` token.
        """
        return SeqOutput(self.forward(history).actions[:, -1])


class TwoLevel(nn.Module):
    """What HDT and HDM share: per-level gradient clipping, teacher-forced training on
    ``L_high + L_low``, and windowed acting. A subclass builds its two levels in
    ``__init__`` and gives :meth:`input_keys`, :meth:`high_forward` and :meth:`low_forward`; this
    class holds no parameters, so it does not change a model's initialisation.
    """

    def input_keys(self) -> tuple[str, ...]:
        """The batch entries :meth:`forward` reads (checked by :func:`check_inputs`)."""
        raise NotImplementedError

    def high_forward(self, batch: Tensors) -> torch.Tensor:
        """Sub-goals ``g_t`` ``(B, T, state_dim)``."""
        raise NotImplementedError

    def low_forward(self, batch: Tensors, subgoals: torch.Tensor) -> torch.Tensor:
        """Actions ``a_t`` ``(B, T, act_dim)`` given the sub-goals."""
        raise NotImplementedError

    def clip_groups(self) -> list[list[nn.Parameter]]:
        """Parameters of each level: the trainer clips their gradient norms separately, as the authors."""
        high = [p for n, p in self.named_parameters() if n.startswith(("high", "predict_subgoal"))]
        ids = {id(p) for p in high}
        return [high, [p for p in self.parameters() if id(p) not in ids]]

    def forward(self, batch: Tensors, targets: Tensors | None = None) -> SeqOutput:
        """Predict ``g_t`` (high) and ``a_t`` (low, on ``batch["subgoals"]``); with targets, ``L_high + L_low``."""
        _check_inputs(self, batch, self.input_keys())
        subgoals = self.high_forward(batch)  # (B, T, state_dim)
        actions = self.low_forward(batch, batch["subgoals"])  # teacher forcing
        if targets is None:
            return SeqOutput(actions, subgoals)
        mask = batch.get("mask")
        l_high = masked_mse(subgoals, targets["subgoals"], mask)
        l_low = masked_mse(actions, targets["actions"], mask)
        loss = l_high + l_low
        return SeqOutput(
            actions, subgoals, loss, {"subgoal": l_high.item(), "action": l_low.item()}
        )

    @torch.no_grad()
    def act(self, history: Tensors) -> SeqOutput:
        """Sub-goal and action at the last step of each history (windowed acting).

        ``history["prev_subgoals"]`` holds the sub-goals the high level predicted before
        (zero at the episode start); ``history["subgoals"][:, -1]`` is overwritten with the
        new prediction. Returns ``SeqOutput(actions (B, act_dim), subgoals (B, state_dim))``.
        """
        _check_inputs(self, history, self.input_keys())
        g = self.high_forward(history)[:, -1]  # (B, state_dim)
        subgoals = history["subgoals"].clone()
        subgoals[:, -1] = g
        actions = self.low_forward(history, subgoals)[:, -1]  # (B, act_dim)
        return SeqOutput(actions, g)


class HDT(TwoLevel):
    """Hierarchical Decision Transformer (thesis 5.2): a high level proposes sub-goals, a low level acts.

    * high level: tokens ``(s_t, g_{t-1})``; ``g_t`` is read at the ``g_{t-1}`` token
      (linear head, z-scored state space, no Tanh);
    * low level: tokens ``(g_t, s_t, a_t)`` (``(rtg_t, g_t, s_t, a_t)`` with ``low_use_rtg``);
      ``a_t`` is read at the ``s_t`` token (Tanh x ``max_action``).

    In training the low level sees the data set's sub-goals (teacher forcing) and both levels
    learn at once (Algorithm 3): ``loss = L_high + L_low``; they share no parameters, so the
    sum gives each level its own gradient. At evaluation :meth:`act` runs the high level,
    then the low level on the predicted sub-goal.

    Used in: HDT chapter (Tables 5.2, 5.3).
    """

    def __init__(self, config: HDTConfig) -> None:
        super().__init__()
        self.config = config
        d, sd = config.d_model, config.state_dim
        # high level
        self.high_embed_state = nn.Linear(sd, d)
        self.high_embed_subgoal = nn.Linear(sd, d)
        self.high = TokenTransformer(config)
        self.predict_subgoal = nn.Linear(d, sd)
        # low level
        self.low_embed_rtg = nn.Linear(1, d) if config.low_use_rtg else None
        self.low_embed_subgoal = nn.Linear(sd, d)
        self.low_embed_state = nn.Linear(sd, d)
        self.low_embed_action = nn.Linear(config.act_dim, d)
        self.low = TokenTransformer(config)
        self.predict_action = action_head(d, config.act_dim)
        init_transformer(self, config.resolved_init, config.n_layers)

    def high_forward(self, batch: Tensors) -> torch.Tensor:
        """Sub-goal predictions ``g_t`` ``(B, T, state_dim)`` from ``(s_t, g_{t-1})`` tokens."""
        tokens = [
            self.high_embed_state(batch["states"]),
            self.high_embed_subgoal(batch["prev_subgoals"]),
        ]
        h_goal = self.high(tokens, batch["timesteps"], batch.get("mask"), read=1)  # at g_{t-1}
        return self.predict_subgoal(h_goal)

    def low_forward(self, batch: Tensors, subgoals: torch.Tensor) -> torch.Tensor:
        """Actions ``a_t`` ``(B, T, act_dim)`` from ``([rtg_t,] g_t, s_t, a_t)`` tokens."""
        a_tok = batch[action_key(self.config.paper_compat)]
        tokens = [
            self.low_embed_subgoal(subgoals),
            self.low_embed_state(batch["states"]),
            self.low_embed_action(a_tok),
        ]
        if self.low_embed_rtg is not None:
            tokens.insert(0, self.low_embed_rtg(batch["returns_to_go"]))
        h_state = self.low(tokens, batch["timesteps"], batch.get("mask"), read=-2)  # at s_t
        return self.predict_action(h_state) * self.config.max_action

    def input_keys(self) -> tuple[str, ...]:
        a_key = action_key(self.config.paper_compat)
        keys = ("states", a_key, "timesteps", "subgoals", "prev_subgoals")
        return keys + (("returns_to_go",) if self.config.low_use_rtg else ())
