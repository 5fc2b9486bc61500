"""One registry of the offline sequence methods, built from one architecture spec.

The HDT, Decision Mamba and UR3 chapters train the same families of models; each method name
maps to a model class and the few switches that make it that method:

=============  ==================================================  ==========  ============
method         model                                               RTG tokens  sub-goals
=============  ==================================================  ==========  ============
``BC``         :class:`~thesis_lib.seq.models.BC` (2-layer MLP)    no          no
``DT``         :class:`~thesis_lib.seq.models.DecisionTransformer` yes         no
``DT-noRTG``   :class:`~thesis_lib.seq.models.DecisionTransformer` no          no
``HDT``        :class:`~thesis_lib.seq.models.HDT`                 no          yes
``HDT-RTG``    :class:`~thesis_lib.seq.models.HDT` (low level)     yes         yes
``DM-RTG``     :class:`~thesis_lib.seq.dm.DecisionMamba`           yes         no
``DM-noRTG``   :class:`~thesis_lib.seq.dm.DecisionMamba`           no          no
``HDM``        :class:`~thesis_lib.seq.dm.HDM`                     no          yes
=============  ==================================================  ==========  ============

:class:`ArchSpec` holds every architecture field, spelled once (``d_model``, ``n_layers``,
``n_heads``, ``K``, ...); :func:`build_model` sizes the model for a data set.

Used in: HDT chapter (Tables 5.1-5.3), Decision Mamba chapter (Tables 5.5, 5.6, Figs 5.3-5.6),
UR3 deployment chapter (Table 5.4).
"""

from __future__ import annotations

import difflib
from collections.abc import Iterable, Mapping
from dataclasses import asdict, dataclass
from typing import Any

import torch

from thesis_lib.seq.dm import HDM, DecisionMamba, DMConfig, HDMConfig
from thesis_lib.seq.models import (
    BC,
    HDT,
    BCConfig,
    DecisionTransformer,
    DTConfig,
    HDTConfig,
    resolve_init,
)

__all__ = [
    "LEGACY_SAMPLING",
    "HIERARCHICAL_METHODS",
    "MAMBA_METHODS",
    "METHODS",
    "RTG_METHODS",
    "LEGACY_INIT",
    "ArchSpec",
    "build_model",
    "check_methods",
]

METHODS: tuple[str, ...] = (
    "BC",
    "DT",
    "DT-noRTG",
    "HDT",
    "HDT-RTG",
    "DM-RTG",
    "DM-noRTG",
    "HDM",
)
"""Every method name the registry builds."""
RTG_METHODS: tuple[str, ...] = ("DT", "HDT-RTG", "DM-RTG")
"""Methods conditioned on a desired return (evaluated at several targets)."""
HIERARCHICAL_METHODS: tuple[str, ...] = ("HDT", "HDT-RTG", "HDM")
"""Methods trained on sub-goals (the data set needs the sub-goal hook)."""
MAMBA_METHODS: tuple[str, ...] = ("DM-RTG", "DM-noRTG", "HDM")
"""Methods that can act recurrently (``eval_mode``)."""


def check_methods(
    names: Iterable[str], valid: Iterable[str] = METHODS, what: str = "method"
) -> None:
    """Raise a ValueError naming the closest valid name for any unknown method.

    Example:
        >>> check_methods(["HDT", "DM"])
        Traceback (most recent call last):
        ...
        ValueError: Unknown method 'DM'. Did you mean: 'HDM'? Valid: BC, DT, DT-noRTG, HDT, HDT-RTG, DM-RTG, DM-noRTG, HDM.
    """
    valid = tuple(valid)
    if isinstance(names, str):
        raise ValueError(f"Expect a list of {what}s, got the string {names!r}.")
    for m in names:
        if m not in valid:
            close = difflib.get_close_matches(str(m), valid, n=1)
            hint = f" Did you mean: '{close[0]}'?" if close else ""
            raise ValueError(f"Unknown {what} '{m}'.{hint} Valid: {', '.join(valid)}.")


@dataclass(frozen=True)
class ArchSpec:
    """The architecture of every registry method (fields a method does not use are ignored).

    Used in: HDT, Decision Mamba and UR3 deployment chapters.
    """

    d_model: int = 128
    """Token embedding size (transformers and Mamba)."""
    n_layers: int = 3
    """GPT or Mamba blocks (per level for HDT/HDM)."""
    n_heads: int = 1
    """Attention heads (DT/HDT)."""
    K: int = 20
    """Context length."""
    dropout: float = 0.1
    """Dropout of BC and the transformers (DM/HDM have none, as the authors' code)."""
    bc_hidden_dim: int = 256
    """Width of BC's two hidden layers."""
    gated_mlp: bool = True
    """Gated MLP in each Mamba block (the authors' later DM/HDM code)."""
    eval_mode: str = "recurrent"
    """How DM/HDM act: ``recurrent`` (one O(1) step per action), ``window`` (the authors') or
    ``auto`` (window with ``paper_compat``)."""
    max_timestep: int = 4096
    """Size of the transformers' time-step embedding."""
    paper_compat: bool = False
    """The authors' behaviours (a_{t-1} tokens, left-padded time-steps, last sub-goal = state 0,
    HDM Tanh sub-goal head, GPT-2's initialisation in the transformers' trunks only)."""
    init: str = "auto"
    """Initialisation of the transformers (DT, HDT), of
    :data:`~thesis_lib.seq.models.INIT_SCHEMES`: ``auto`` = ``original`` with ``paper_compat``,
    else ``normal`` (every Linear and Embedding N(0, 0.02), as CORL's and Hugging Face's DT);
    ``torch`` = PyTorch's defaults, what the v1 studies ran with; ``d3rlpy`` = d3rlpy's DT's
    mix, for the parity runs."""

    def __post_init__(self) -> None:
        resolve_init(self.init, self.paper_compat)  # validates

    @property
    def label(self) -> str:
        """``"L6 D128 K20"``, as the thesis's figure legends."""
        return f"L{self.n_layers} D{self.d_model} K{self.K}"

    @property
    def resolved_init(self) -> str:
        """``normal``, ``original``, ``torch`` or ``d3rlpy`` (``auto`` resolved)."""
        return resolve_init(self.init, self.paper_compat)

    def task_dict(self) -> dict[str, Any]:
        """The spec as a sweep task's JSON: every field, ``init`` resolved, and left out where
        it is ``torch``, the scheme of every task stored before the field existed (so their
        keys stay valid; :meth:`from_task` reads a missing ``init`` as ``torch``).

        Example:
            >>> ArchSpec().task_dict()["init"], "init" in ArchSpec(init="torch").task_dict()
            ('normal', False)
        """
        d = asdict(self)
        d["init"] = self.resolved_init
        if d["init"] == LEGACY_INIT:
            del d["init"]
        return d

    @classmethod
    def from_task(cls, d: Mapping[str, Any]) -> ArchSpec:
        """The spec of a task's ``arch`` dict (:meth:`task_dict`, or any subset of the fields);
        a missing ``init`` is ``torch``, as every task stored before the field existed ran.

        Example:
            >>> ArchSpec.from_task({"d_model": 32}).init
            'torch'
        """
        return cls(**{"init": LEGACY_INIT, **d})


LEGACY_INIT = "torch"
"""The initialisation of every stored task and study file that names none (the v1 studies)."""

LEGACY_SAMPLING = "start"
"""The window sampling of every stored task and study file that names none (the v1 studies):
:class:`~thesis_lib.data.SequenceDataset` drew a window's start before ``sampling`` existed."""


def build_model(method: str, seq: Any, arch: ArchSpec, max_action: float = 1.0) -> torch.nn.Module:
    """The model of ``method`` with architecture ``arch``, sized for the data set ``seq``.

    Args:
        method: One of :data:`METHODS`.
        seq: A :class:`~thesis_lib.data.SequenceDataset` (state/action sizes; ``K`` from ``arch``).
        arch: :class:`ArchSpec`.
        max_action: Action bound of the environment.

    Used in: HDT, Decision Mamba and UR3 deployment chapters.
    """
    check_methods([method])
    sizes: dict[str, Any] = dict(
        state_dim=int(seq.states.shape[-1]),
        act_dim=int(seq.actions.shape[-1]),
        K=arch.K,
        max_action=max_action,
    )
    if method == "BC":
        return BC(BCConfig(**sizes, dropout=arch.dropout, hidden_dim=arch.bc_hidden_dim))
    common: dict[str, Any] = dict(
        d_model=arch.d_model, n_layers=arch.n_layers, paper_compat=arch.paper_compat
    )
    if method in ("DT", "DT-noRTG", "HDT", "HDT-RTG"):
        tf: dict[str, Any] = dict(
            n_heads=arch.n_heads,
            dropout=arch.dropout,
            max_timestep=arch.max_timestep,
            init=arch.init,
            **common,
        )
        if method.startswith("DT"):
            return DecisionTransformer(DTConfig(**sizes, use_rtg=method == "DT", **tf))
        return HDT(HDTConfig(**sizes, low_use_rtg=method == "HDT-RTG", **tf))
    mb: dict[str, Any] = dict(gated_mlp=arch.gated_mlp, eval_mode=arch.eval_mode, **common)
    if method == "HDM":
        return HDM(HDMConfig(**sizes, **mb))
    return DecisionMamba(DMConfig(**sizes, use_rtg=method == "DM-RTG", **mb))
