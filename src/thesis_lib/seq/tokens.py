"""Decision Transformer tokens (thesis Sec. 2.8): returns-to-go and the interleaved layout.

The DT reads a trajectory as the token sequence ``(rtg_1, s_1, a_1, ..., rtg_T, s_T, a_T)``:
three tokens per time step, in that order, each embedded by its own linear layer, plus a
learned embedding of the time step (not of the token position) shared by the step's three
tokens. The action ``a_t`` is predicted from the output at the ``s_t`` token, which under a
causal mask has seen ``rtg_1..rtg_t``, ``s_1..s_t`` and ``a_1..a_{t-1}`` (Eq. 2.18).

* :func:`returns_to_go` computes ``rtg_t = Σ_{t' >= t} γ^{t'-t} r_{t'}`` for one episode.
* :func:`interleave_tokens` lays out a short trajectory as a table, for worked examples.
* :func:`interleave_embeddings` / :func:`deinterleave_embeddings` do the same layout for
  ``(B, T, C)`` embedding tensors inside the models.

Time steps are 0-based here, as the index fed to the time-step embedding; the thesis writes
``rtg_1, s_1, a_1`` with 1-based subscripts, so thesis step ``t`` is ``timestep = t - 1``.

Used in: Background chapter (thesis 2.8); DT, HDT, MDLT chapters.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import pandas as pd
import torch

from thesis_lib.data.sequence import returns_to_go as returns_to_go  # one implementation, in data

MODALITIES: tuple[str, ...] = ("rtg", "state", "action")
"""Token order within one DT time step."""


def _per_step(name: str, x: object, T: int) -> list[float | tuple[float, ...]]:
    arr = np.asarray(x, dtype=np.float64)
    if arr.ndim not in (1, 2) or arr.shape[0] != T:
        raise ValueError(
            f"Expect `{name}` of shape (T,) or (T, dim) with T={T} (the length of `rtg`), got shape {arr.shape}."
        )
    if arr.ndim == 1 or arr.shape[1] == 1:
        return [float(v) for v in arr.reshape(T)]
    return [tuple(float(v) for v in row) for row in arr]


def interleave_tokens(
    rtg: np.ndarray,
    states: np.ndarray,
    actions: np.ndarray,
    timesteps: np.ndarray | None = None,
) -> pd.DataFrame:
    """The DT token layout ``(rtg_1, s_1, a_1, ..., rtg_T, s_T, a_T)`` as a tidy table.

    One row per token: the token at ``position = 3 * k + m`` is modality ``m`` (rtg, state,
    action) of the ``k``-th step of the window. For a worked example in the book; the models
    use :func:`interleave_embeddings`.

    Used in: Background chapter (thesis 2.8).

    Args:
        rtg: Returns-to-go ``(T,)``.
        states: States ``(T,)`` or ``(T, state_dim)``.
        actions: Actions ``(T,)`` or ``(T, act_dim)``.
        timesteps: Optional 0-based episode time step of each window entry ``(T,)``, e.g.
            ``range(100, 100 + T)`` for a window starting at step 100; default ``0 .. T-1``.

    Returns:
        DataFrame with ``3 T`` rows and columns ``position`` (int), ``timestep`` (int),
        ``modality`` (ordered categorical: rtg < state < action) and ``value`` (a float for
        scalar tokens, a tuple of floats for vector tokens).

    Raises:
        ValueError: If the inputs do not share the length ``T``.

    Example:
        >>> df = interleave_tokens(returns_to_go([1.0, 2.0]), [0.1, 0.2], [-1.0, 1.0])
        >>> df[["position", "timestep", "modality"]].values.tolist()[:4]
        [[0, 0, 'rtg'], [1, 0, 'state'], [2, 0, 'action'], [3, 1, 'rtg']]
        >>> df["value"].tolist()
        [3.0, 0.1, -1.0, 2.0, 0.2, 1.0]
    """
    rtg_arr = np.asarray(rtg, dtype=np.float64)
    if rtg_arr.ndim != 1:
        raise ValueError(f"Expect `rtg` of shape (T,), got shape {rtg_arr.shape}.")
    T = rtg_arr.shape[0]
    per_modality: list[list[Any]] = [
        [float(v) for v in rtg_arr],
        _per_step("states", states, T),
        _per_step("actions", actions, T),
    ]
    if timesteps is None:
        ts = np.arange(T)
    else:
        ts = np.asarray(timesteps)
        if ts.shape != (T,) or not np.issubdtype(ts.dtype, np.integer):
            raise ValueError(
                f"Expect integer `timesteps` of shape (T,) = ({T},), got shape {ts.shape} and dtype {ts.dtype}."
            )
    n = len(MODALITIES)
    return pd.DataFrame(
        {
            "position": np.arange(n * T),
            "timestep": np.repeat(ts, n).astype(np.int64),
            "modality": pd.Categorical(
                list(MODALITIES) * T, categories=list(MODALITIES), ordered=True
            ),
            "value": [per_modality[m][k] for k in range(T) for m in range(n)],
        }
    )


def interleave_embeddings(*embeddings: torch.Tensor) -> torch.Tensor:
    """Interleave per-modality embeddings step by step: ``(x1_0, x2_0, ..., x1_1, x2_1, ...)``.

    For the DT, ``interleave_embeddings(rtg_emb, state_emb, action_emb)`` gives the token
    sequence of :func:`interleave_tokens`: token ``n * k + m`` is modality ``m`` of step ``k``.
    Works for masks too: ``interleave_embeddings(mask, mask, mask)`` on ``(B, T)`` bool masks
    gives the ``(B, n T)`` key-padding mask of the tokens.

    Used in: Background chapter (thesis 2.8); DT, HDT, MDLT chapters.

    Args:
        *embeddings: ``n >= 1`` tensors of the same shape ``(B, T, ...)``, e.g. ``(B, T, C)``.

    Returns:
        ``(B, n T, ...)``.

    Raises:
        ValueError: If no tensor is given or the shapes differ.

    Example:
        >>> r, s, a = torch.tensor([[1, 2]]), torch.tensor([[10, 20]]), torch.tensor([[-1, -2]])
        >>> interleave_embeddings(r, s, a).tolist()
        [[1, 10, -1, 2, 20, -2]]
    """
    if not embeddings:
        raise ValueError("interleave_embeddings needs at least one tensor.")
    shape = embeddings[0].shape
    if len(shape) < 2 or any(e.shape != shape for e in embeddings):
        raise ValueError(
            f"Expect tensors of one shape (B, T, ...), got {[tuple(e.shape) for e in embeddings]}."
        )
    B, T, *rest = shape
    stacked = torch.stack(embeddings, dim=2)  # (B, T, n, ...)
    return stacked.reshape(B, T * len(embeddings), *rest)  # (B, n T, ...)


def deinterleave_embeddings(x: torch.Tensor, n_modalities: int) -> tuple[torch.Tensor, ...]:
    """Inverse of :func:`interleave_embeddings`: split ``(B, n T, ...)`` into ``n`` tensors ``(B, T, ...)``.

    For the DT, ``_, h_state, _ = deinterleave_embeddings(out, 3)`` picks the outputs at the
    state tokens, from which the actions are predicted.

    Used in: DT, HDT, MDLT chapters.

    Args:
        x: Interleaved tokens ``(B, n T, ...)``.
        n_modalities: ``n``, the number of tokens per step.

    Returns:
        Tuple of ``n`` tensors ``(B, T, ...)`` (views of ``x`` when it is contiguous).

    Raises:
        ValueError: If the token axis is not a multiple of ``n_modalities``.

    Example:
        >>> r, s, a = deinterleave_embeddings(torch.tensor([[1, 10, -1, 2, 20, -2]]), 3)
        >>> s.tolist()
        [[10, 20]]
    """
    if not isinstance(n_modalities, int) or n_modalities <= 0:
        raise ValueError(f"Expect `n_modalities` to be a positive int, actually: {n_modalities!r}.")
    if x.ndim < 2 or x.shape[1] % n_modalities != 0:
        raise ValueError(
            f"Expect tokens of shape (B, n T, ...) with the token axis a multiple of n={n_modalities}, "
            f"got {tuple(x.shape)}."
        )
    B, nT, *rest = x.shape
    x = x.reshape(B, nT // n_modalities, n_modalities, *rest)  # (B, T, n, ...)
    return tuple(x[:, :, m] for m in range(n_modalities))
