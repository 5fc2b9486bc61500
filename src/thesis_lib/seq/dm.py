"""The Decision Mamba (DM) and the Hierarchical Decision Mamba (HDM) (thesis 5.3).

Both replace the transformers of the DT and the HDT (:mod:`thesis_lib.seq.models`) by stacks
of Mamba blocks (:class:`thesis_lib.seq.mamba.Mamba`). They take the same batches, train with
the same :class:`~thesis_lib.seq.trainer.Trainer` and act through the same
:func:`~thesis_lib.seq.evaluation.evaluate` as the transformers. Tokens, per time step ``t``:

* DM: ``(s_t, a_t)``, with ``use_rtg=True`` ``(rtg_t, s_t, a_t)``; ``a_t`` is read at ``s_t``
  (thesis 5.3.1, "DM without / with RTG");
* HDM high level: ``(g_{t-1}, s_t)``, the sub-goal ``g_t`` is read at ``s_t``;
  HDM low level: ``(g_t, s_t, a_t)``, ``a_t`` read at ``s_t`` (thesis 5.3.2).

There is **no positional input** (no time-step embedding, thesis 5.3.1): the recurrence orders
the tokens, so the ``timesteps`` of a batch are not read. As the authors' code, the stacked
token embeddings pass a LayerNorm before the first block; the heads are ``Linear + Tanh x
max_action`` (actions) and ``Linear`` (sub-goals, which are z-scored states).

**Acting.** ``act(history)`` re-runs the model on the last ``K`` steps, as the authors' code
did for every action (``eval_mode="window"``). A Mamba can instead keep its state:
``recurrent_policy(n_envs)`` returns a :class:`RecurrentPolicy` that feeds each environment
step's 2-3 new tokens through :meth:`~thesis_lib.seq.mamba.Mamba.step_tokens` (one compiled
call on CPU), O(1) per action instead of O(K). The evaluator uses it when the model's
``eval_mode`` resolves to ``"recurrent"`` (the default). The two modes give the same actions
while the episode is at most ``K`` steps long; after that the recurrent state has seen the
whole episode, while the window forgets everything older than ``K`` steps, so they differ
(the model was trained on ``K``-step windows that start with a zero state; the chapter
measures what that costs).

``paper_compat=True`` (``notes/original-code.md``): the action slot holds ``a_{t-1}`` (a zero
action prepended), the HDM high level's head ends in a Tanh (although its targets are
z-scored states), and evaluation re-runs the window (``eval_mode="auto"`` -> ``"window"``).

Used in: Decision Mamba chapter (thesis 5.3, Tables 5.5-5.6, Figs 5.3-5.6).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Literal

import torch
import torch.nn as nn

from thesis_lib.seq.dropout import Dropout
from thesis_lib.seq.mamba import Mamba, MambaConfig, MambaState
from thesis_lib.seq.models import (
    ModelConfig,
    SeqOutput,
    TwoLevel,
    action_head,
    action_key,
    action_output,
    check_inputs,
    rsa_tokens,
)
from thesis_lib.seq.tokens import deinterleave_embeddings, interleave_embeddings

__all__ = [
    "DMConfig",
    "DecisionMamba",
    "EVAL_MODES",
    "HDM",
    "HDMConfig",
    "RecurrentPolicy",
    "TokenMamba",
]

Tensors = Mapping[str, torch.Tensor]
EVAL_MODES: tuple[str, ...] = ("auto", "recurrent", "window")


# ----------------------------------------------------------------------------------------------
# Configs


@dataclass
class _MambaModelConfig(ModelConfig):
    d_model: int = 128
    """Token embedding size (128 in the thesis)."""
    n_layers: int = 6
    """Mamba blocks (per level for HDM; 6 in the thesis)."""
    d_state: int = 16
    """SSM state size per channel (Mamba-1's 16)."""
    d_conv: int = 4
    """Causal convolution width (Mamba-1's 4)."""
    expand: int = 2
    """Inner width = expand x d_model (Mamba-1's 2)."""
    gated_mlp: bool = True
    """A gated MLP after each mixer, as the authors' DM/HDM code from July 2024."""
    dropout: float = 0.0
    """Dropout on the token embeddings (the authors' code has none)."""
    eval_mode: Literal["auto", "recurrent", "window"] = "auto"
    """How :func:`~thesis_lib.seq.evaluation.evaluate` acts: ``"recurrent"`` (one step per
    action, conditions on the whole episode), ``"window"`` (re-run the last K steps, the
    authors' way), ``"auto"`` = window with ``paper_compat``, else recurrent."""
    paper_compat: bool = False
    """The authors' behaviours: ``a_{t-1}`` action tokens, a Tanh on the HDM's sub-goal head,
    windowed evaluation (with ``eval_mode="auto"``)."""

    def __post_init__(self) -> None:
        super().__post_init__()
        if self.eval_mode not in EVAL_MODES:
            raise ValueError(
                f"Unknown eval_mode {self.eval_mode!r}. Valid: {', '.join(EVAL_MODES)}."
            )
        if not 0.0 <= self.dropout < 1.0:
            raise ValueError(f"Expect `dropout` in [0, 1), actually: {self.dropout!r}.")
        self.mamba_config()  # validates n_layers, d_model, d_state ...

    def mamba_config(self) -> MambaConfig:
        """The :class:`MambaConfig` of each trunk."""
        return MambaConfig(
            d_model=self.d_model,
            n_layers=self.n_layers,
            d_state=self.d_state,
            d_conv=self.d_conv,
            expand=self.expand,
            gated_mlp=self.gated_mlp,
        )

    @property
    def resolved_eval_mode(self) -> str:
        """``"recurrent"`` or ``"window"`` (``"auto"`` resolved)."""
        if self.eval_mode == "auto":
            return "window" if self.paper_compat else "recurrent"
        return self.eval_mode


@dataclass
class DMConfig(_MambaModelConfig):
    """Configuration of :class:`DecisionMamba` (thesis 5.3.1).

    Used in: Decision Mamba chapter (Tables 5.5, 5.6; Figs 5.4-5.6).

    Example:
        >>> DMConfig(state_dim=11, act_dim=3, eval_mode="stepwise")
        Traceback (most recent call last):
        ...
        ValueError: Unknown eval_mode 'stepwise'. Valid: auto, recurrent, window.
    """

    use_rtg: bool = False
    """Tokens ``(rtg_t, s_t, a_t)`` ("DM w/ R"); the default ``(s_t, a_t)`` is "DM wo/ R"."""


@dataclass
class HDMConfig(_MambaModelConfig):
    """Configuration of :class:`HDM`; the Mamba sizes serve both levels (thesis 5.3.2).

    Used in: Decision Mamba chapter (Tables 5.5, 5.6; Figs 5.3, 5.4).
    """


# ----------------------------------------------------------------------------------------------
# The shared trunk


class TokenMamba(nn.Module):
    """Mamba trunk over interleaved per-step tokens: what the DM and both HDM levels share.

    ``forward([x1, x2, ...])`` interleaves the modalities' ``(B, T, d)`` embeddings
    ``(x1_0, x2_0, ..., x1_1, ...)``, applies a LayerNorm (the authors' ``embed_ln``) and
    dropout, the Mamba stack, and splits the output back per modality. No positional input.
    :meth:`step` advances a :class:`~thesis_lib.seq.mamba.MambaState` by a few tokens.

    Used in: Decision Mamba chapter (DM, HDM).
    """

    def __init__(self, config: _MambaModelConfig) -> None:
        super().__init__()
        self.embed_ln = nn.LayerNorm(config.d_model)
        self.drop = Dropout(config.dropout)
        self.mamba = Mamba(config.mamba_config())

    def forward(self, tokens: list[torch.Tensor]) -> tuple[torch.Tensor, ...]:
        """``n`` embeddings ``(B, T, d)`` -> ``n`` outputs ``(B, T, d)`` at each modality's token.

        Right-padding is harmless: the stack is causal, so padded steps after the real ones
        change no real output (the loss masks them).
        """
        x = interleave_embeddings(*tokens)  # (B, n T, d)
        # at least float32 from here, under bfloat16 autocast too (TrainConfig.precision): the
        # residual stream (Mamba.forward) starts at this LayerNorm
        x = x.to(torch.promote_types(x.dtype, torch.float32))
        y = self.mamba(self.drop(self.embed_ln(x)))
        return deinterleave_embeddings(y, len(tokens))

    def allocate_state(self, batch: int, device: torch.device | str | None = None) -> MambaState:
        """Zero state (before the first token)."""
        return self.mamba.allocate_state(batch, device=device)

    def step(self, tokens: torch.Tensor, state: MambaState) -> tuple[torch.Tensor, MambaState]:
        """Advance by ``tokens (B, n, d)`` (already embedded); returns the output at the last one ``(B, d)``."""
        y, state = self.mamba.step_tokens(self.embed_ln(tokens), state)
        return y[:, -1], state


# ----------------------------------------------------------------------------------------------
# Models


class DecisionMamba(nn.Module):
    """Decision Mamba (thesis 5.3.1): tokens ``(s_t, a_t)`` or ``(rtg_t, s_t, a_t)``, Mamba trunk.

    ``a_t`` is read at the ``s_t`` token, which has seen ``rtg_{<=t}``, ``s_{<=t}``, ``a_{<t}``.

    Used in: Decision Mamba chapter (Tables 5.5, 5.6; Figs 5.4-5.6).

    Example:
        >>> _ = torch.manual_seed(0)
        >>> dm = DecisionMamba(DMConfig(state_dim=3, act_dim=2, K=4, d_model=16, n_layers=1))
        >>> b = {"states": torch.randn(2, 4, 3), "actions": torch.zeros(2, 4, 2)}
        >>> tuple(dm(b).actions.shape)
        (2, 4, 2)
    """

    def __init__(self, config: DMConfig) -> None:
        super().__init__()
        self.config = config
        d = config.d_model
        self.embed_rtg = nn.Linear(1, d) if config.use_rtg else None
        self.embed_state = nn.Linear(config.state_dim, d)
        self.embed_action = nn.Linear(config.act_dim, d)
        self.trunk = TokenMamba(config)
        self.predict_action = action_head(d, config.act_dim)

    def input_keys(self) -> tuple[str, ...]:
        a_key = action_key(self.config.paper_compat)
        return ("states", a_key) + (("returns_to_go",) if self.config.use_rtg else ())

    def forward(self, batch: Tensors, targets: Tensors | None = None) -> SeqOutput:
        """Predict ``a_t`` at every step; with ``targets`` (``targets["actions"]``) also the masked MSE."""
        check_inputs(self, batch, self.input_keys())
        h = self.trunk(rsa_tokens(self, batch))
        actions = self.predict_action(h[-2]) * self.config.max_action  # read at s_t
        return action_output(actions, batch, targets)

    @torch.no_grad()
    def act(self, history: Tensors) -> SeqOutput:
        """Windowed acting (the authors'): re-run the history ``(B, T <= K, ...)``; ``.actions`` is ``(B, act_dim)``.

        The last step's action slot is not yet known; any value works: it comes after ``s_t``.
        """
        return SeqOutput(self.forward(history).actions[:, -1])

    def recurrent_policy(self, n_envs: int) -> RecurrentPolicy | None:
        """A :class:`RecurrentPolicy` for ``n_envs`` episodes, or ``None`` when ``eval_mode`` is ``"window"``."""
        return (
            RecurrentPolicy(self, n_envs) if self.config.resolved_eval_mode == "recurrent" else None
        )


class HDM(TwoLevel):
    """Hierarchical Decision Mamba (thesis 5.3.2): HDT's two levels with Mamba trunks.

    * high level: tokens ``(g_{t-1}, s_t)``, the sub-goal ``g_t`` read at ``s_t``;
    * low level: tokens ``(g_t, s_t, a_t)``, ``a_t`` read at ``s_t``.

    Training uses the data set's sub-goals for the low level (teacher forcing) and
    ``loss = L_high + L_low``, as :class:`~thesis_lib.seq.models.HDT`; acting, the high level's
    prediction feeds the low level and is rolled forward.

    Used in: Decision Mamba chapter (Tables 5.5, 5.6; Figs 5.3, 5.4).
    """

    def __init__(self, config: HDMConfig) -> None:
        super().__init__()
        self.config = config
        d, sd = config.d_model, config.state_dim
        self.high_embed_subgoal = nn.Linear(sd, d)
        self.high_embed_state = nn.Linear(sd, d)
        self.high = TokenMamba(config)
        # The authors' head ends in a Tanh although sub-goals are z-scored states (|z| > 1 is common).
        self.predict_subgoal = (
            nn.Sequential(nn.Linear(d, sd), nn.Tanh()) if config.paper_compat else nn.Linear(d, sd)
        )
        self.low_embed_subgoal = nn.Linear(sd, d)
        self.low_embed_state = nn.Linear(sd, d)
        self.low_embed_action = nn.Linear(config.act_dim, d)
        self.low = TokenMamba(config)
        self.predict_action = action_head(d, config.act_dim)

    def input_keys(self) -> tuple[str, ...]:
        a_key = action_key(self.config.paper_compat)
        return ("states", a_key, "subgoals", "prev_subgoals")

    def high_forward(self, batch: Tensors) -> torch.Tensor:
        """Sub-goals ``g_t`` ``(B, T, state_dim)`` from ``(g_{t-1}, s_t)`` tokens."""
        tokens = [
            self.high_embed_subgoal(batch["prev_subgoals"]),
            self.high_embed_state(batch["states"]),
        ]
        _, h_state = self.high(tokens)
        return self.predict_subgoal(h_state)

    def low_forward(self, batch: Tensors, subgoals: torch.Tensor) -> torch.Tensor:
        """Actions ``a_t`` ``(B, T, act_dim)`` from ``(g_t, s_t, a_t)`` tokens."""
        a_tok = batch[action_key(self.config.paper_compat)]
        tokens = [
            self.low_embed_subgoal(subgoals),
            self.low_embed_state(batch["states"]),
            self.low_embed_action(a_tok),
        ]
        h = self.low(tokens)
        return self.predict_action(h[1]) * self.config.max_action  # read at s_t

    def recurrent_policy(self, n_envs: int) -> RecurrentPolicy | None:
        """A :class:`RecurrentPolicy` for ``n_envs`` episodes, or ``None`` when ``eval_mode`` is ``"window"``."""
        return (
            RecurrentPolicy(self, n_envs) if self.config.resolved_eval_mode == "recurrent" else None
        )


# ----------------------------------------------------------------------------------------------
# Recurrent acting


class RecurrentPolicy:
    """Acts with a DM or HDM one environment step at a time, carrying each episode's Mamba state.

    :func:`~thesis_lib.seq.evaluation.evaluate` makes one per round of ``n_envs`` episodes
    (``model.recurrent_policy(n_envs)``) and calls ``act(history, live)`` each step with the
    same history it would give ``model.act`` and the indices of the running episodes. Only the
    history's last entries are read: at step ``t`` the policy feeds the previous step's action
    slot (for ``t > 0``), then ``[rtg_t,] s_t`` (DM) or ``g_{t-1}, s_t`` (HDM high level) and
    ``g_t, s_t`` (HDM low level), and reads the output at ``s_t``.

    Used in: Decision Mamba chapter (thesis 5.3; Table 5.6's recurrent column).

    Args:
        model: A :class:`DecisionMamba` or :class:`HDM` (in eval mode).
        n_envs: Number of episodes run side by side.
    """

    def __init__(self, model: DecisionMamba | HDM, n_envs: int) -> None:
        if not isinstance(model, (DecisionMamba, HDM)):
            raise TypeError(
                f"RecurrentPolicy drives a DecisionMamba or an HDM, got {type(model).__name__}."
            )
        self.model = model
        self.n_envs = int(n_envs)
        self.t = 0
        device = next(model.parameters()).device
        if isinstance(model, HDM):
            self.states = {
                "high": model.high.allocate_state(n_envs, device),
                "low": model.low.allocate_state(n_envs, device),
            }
        else:
            self.states = {"low": model.trunk.allocate_state(n_envs, device)}

    def _advance(
        self, level: str, trunk: TokenMamba, tokens: list[torch.Tensor], live: torch.Tensor | None
    ) -> torch.Tensor:
        state = self.states[level]
        x = torch.stack(tokens, 1)  # (n_live, n, d)
        if live is None:  # every episode runs: no gather / scatter
            y, self.states[level] = trunk.step(x, state)
            return y
        y, new = trunk.step(x, MambaState(state.conv[:, live], state.ssm[:, live]))
        state.conv[:, live] = new.conv
        state.ssm[:, live] = new.ssm
        return y  # (n_live, d) at the last token

    def _prev_action_token(self, history: Tensors) -> torch.Tensor:
        """The action slot of step ``t - 1``: ``a_{t-1}`` (or ``a_{t-2}`` with ``paper_compat``)."""
        if self.model.config.paper_compat:
            return history["prev_actions"][:, -2]  # prev_actions[t-1] = a_{t-2}
        return history["prev_actions"][:, -1]  # = actions[t-1]

    @torch.no_grad()
    def act(self, history: Tensors, live: torch.Tensor | None = None) -> SeqOutput:
        """The action (and HDM sub-goal) at step ``t`` for the running episodes ``live``.

        Args:
            history: As for ``model.act``: ``(n_live, T, ...)`` windows ending at step ``t``.
            live: ``(n_live,)`` indices of the running episodes among the ``n_envs``, in increasing
                order (as the evaluator passes them); ``None`` = all.

        Returns:
            ``SeqOutput(actions (n_live, act_dim)[, subgoals (n_live, state_dim)])``.
        """
        m, cfg = self.model, self.model.config
        s = history["states"][:, -1]  # (n_live, state_dim)
        if s.shape[-1] != cfg.state_dim:
            raise ValueError(
                f"{type(m).__name__} expects states of size {cfg.state_dim}, got {s.shape[-1]}."
            )
        if live is not None and len(live) == self.n_envs:
            live = None  # all running (the evaluator passes the indices in order)
        first = self.t == 0
        self.t += 1
        if isinstance(m, DecisionMamba):
            tokens = [] if first else [m.embed_action(self._prev_action_token(history))]
            if m.embed_rtg is not None:
                tokens.append(m.embed_rtg(history["returns_to_go"][:, -1]))
            tokens.append(m.embed_state(s))
            y = self._advance("low", m.trunk, tokens, live)
            return SeqOutput(m.predict_action(y) * cfg.max_action)
        high_tokens = [m.high_embed_subgoal(history["prev_subgoals"][:, -1]), m.high_embed_state(s)]
        y = self._advance("high", m.high, high_tokens, live)
        g = m.predict_subgoal(y)  # (n_live, state_dim)
        tokens = [] if first else [m.low_embed_action(self._prev_action_token(history))]
        tokens += [m.low_embed_subgoal(g), m.low_embed_state(s)]
        y = self._advance("low", m.low, tokens, live)
        return SeqOutput(m.predict_action(y) * cfg.max_action, g)
