"""The training options every chapter with sequence models shares (HDT, Decision Mamba, UR3):
:class:`SeqTraining`, a base of their ``Config`` dataclasses.

Each field is one notebook parameter of those chapters, as their own fields are; kept here so
that its choices and documentation are written once. A chapter's parameters cell and smoke
file list its own fields first and these after them (:func:`thesis_lib.book.params.config_defaults`).

Read without importing a chapter (``thesis run`` checks a parameter file against the type
hints here at once, :meth:`thesis_lib.book.chapter.Chapter.hints`), so this module imports
nothing beyond the standard library, and its annotations name only builtins and ``Literal``.

Used in: HDT, Decision Mamba and UR3 chapters (``thesis_lib.chapters.{hdt,decision_mamba,ur3}.config``).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

__all__ = ["SeqTraining"]


@dataclass
class SeqTraining:
    """How a chapter's sequence models are initialised, fed and trained; the defaults are the
    text's (and the v2 studies'), not the authors' code's unless ``paper_compat`` says so."""

    init: Literal["auto", "normal", "original", "torch", "d3rlpy"] = "auto"
    """Initialisation of the transformers (DT, HDT): ``auto`` (the authors' ``original`` with
    ``paper_compat``, else ``normal``: every Linear and Embedding N(0, 0.02), as CORL's and
    Hugging Face's DT), ``torch`` (PyTorch's defaults, the v1 studies'; a study file that
    names no ``init`` ran with it) or ``d3rlpy`` (d3rlpy 2.8.1's DT: ``normal`` in the trunk,
    PyTorch's defaults for the token embeddings and the head; the parity runs')."""
    sampling: Literal["end", "start"] | None = None
    """How the training windows are drawn (:class:`~thesis_lib.data.SequenceDataset`): ``end``
    (a step uniform over all steps, the window ending at it: d3rlpy's DT), ``start`` (the
    window's start: the original DT code's, the v1 studies'; a study file that names no
    ``sampling`` ran with it), ``None``: ``start`` with ``paper_compat``, else ``end``."""
    device: str = "cpu"
    """Training device (``cpu``, ``cuda``, ``auto``)."""
    precision: Literal["fp32", "bf16"] = "fp32"
    """Training precision (:attr:`~thesis_lib.seq.trainer.TrainConfig.precision`): ``fp32``, or
    ``bf16`` mixed precision (matrix products in bfloat16; 1.2-1.55x the updates per CPU-second
    at d64 and 1.5-2x at d128 with 3 layers on a CPU with AVX-512 BF16, by the day's machine;
    the numbers differ from float32's by rounding). Every study so far ran in ``fp32``."""
    kernels: Literal["torch", "fast", "fast+readout"] = "torch"
    """Training kernels (:attr:`~thesis_lib.seq.trainer.TrainConfig.kernels`): ``torch``,
    ``fast`` (cheaper dropout masks on a CPU and fused AdamW; identical in distribution, other
    draws) or ``fast+readout`` (those, and the transformers' last block on the tokens the loss
    reads only: the same loss up to float error; with ``bf16`` 1.8-2x the runs per CPU-hour of
    ``fp32``/``torch`` for the d64 DT). Every study so far ran with ``torch``."""
