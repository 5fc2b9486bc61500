"""Dropout whose masks cost a quarter of torch's on a CPU: the training lever of
``TrainConfig(kernels="fast")`` (issue #36's throughput).

PyTorch's CPU dropout draws its keep mask with ``bernoulli_``, about 6 ns an element on this
project's machines; at the v2 studies' size (d64, 2 layers, batch 64, 60 tokens) the masks are
a fifth of a bfloat16 training step. :func:`lane_mask` draws the same mask from the generator's
64-bit integers instead, two 32-bit lanes each: keep an element where its lane is at or above
``round(p 2^32) - 2^31``. Lanes are uniform on ``[-2^31, 2^31)``, so an element is kept with
probability ``1 - round(p 2^32) / 2^32``: ``1 - p`` up to ``2^-32``, independently of the
others, as ``bernoulli_`` keeps it. Kept elements are scaled by ``1 / (1 - p)`` as torch's are.
The draws come from torch's default generator, so ``torch.manual_seed`` (and the
:class:`~thesis_lib.seq.trainer.Trainer`'s own dropout stream) fixes them.

So a run with lane masks is identical in distribution to one with torch's, but not the same
run: the masks are other draws. The lanes are used only inside :func:`lane_dropout` (the
Trainer enters it for ``kernels="fast"`` and ``"fast+readout"`` on a CPU); everywhere else
:class:`Dropout` is ``nn.Dropout``.

Why by hand: no library offers a cheaper CPU dropout mask; ``torch.compile`` made the step
slower (``benchmarks/bench_ensemble.py``).

Used in: the sequence models' training (HDT, Decision Mamba, MDLT and UR3 chapters).
"""

from __future__ import annotations

import contextlib
import contextvars
import math
from collections.abc import Iterator

import torch
import torch.nn as nn
import torch.nn.functional as F

__all__ = ["Dropout", "dropout", "lane_dropout", "lane_dropout_enabled", "lane_mask"]

_LANES: contextvars.ContextVar[bool] = contextvars.ContextVar("lane_dropout", default=False)


@contextlib.contextmanager
def lane_dropout(enabled: bool = True) -> Iterator[None]:
    """Within this context, :func:`dropout` and :class:`Dropout` (and so every dropout of the
    sequence models, attention weights included) draw their masks with :func:`lane_mask`."""
    token = _LANES.set(bool(enabled))
    try:
        yield
    finally:
        _LANES.reset(token)


def lane_dropout_enabled() -> bool:
    """Whether the current context draws dropout masks by :func:`lane_mask`."""
    return _LANES.get()


def lane_mask(
    shape: tuple[int, ...] | torch.Size, p: float, device: torch.device | str = "cpu"
) -> torch.Tensor:
    """A bool keep mask of ``shape``: each element ``True`` with probability ``1 - p`` (up to
    ``2^-32``), independently, drawn from torch's default generator as 32-bit lanes of 64-bit
    integers.

    Args:
        shape: The mask's shape.
        p: The drop probability, in ``[0, 1)``.
        device: Where to draw it.

    Returns:
        A bool tensor of ``shape``, ``True`` = keep.

    Example:
        >>> _ = torch.manual_seed(0)
        >>> round(lane_mask((100_000,), 0.25).float().mean().item(), 2)
        0.75
    """
    if not 0.0 <= p < 1.0:
        raise ValueError(f"Expect the drop probability `p` in [0, 1), actually: {p!r}.")
    n = math.prod(shape)
    # the full signed range: random_() alone draws [0, 2^63), whose high lanes are never negative
    words = torch.empty((n + 1) // 2, dtype=torch.int64, device=device).random_(-(2**63), None)
    lanes = words.view(torch.int32)[:n]
    return lanes.ge(round(p * 2**32) - 2**31).view(shape)


def dropout(x: torch.Tensor, p: float, training: bool = True) -> torch.Tensor:
    """``F.dropout(x, p, training)``, with the mask of :func:`lane_mask` inside
    :func:`lane_dropout`."""
    if not training or p == 0.0:
        return x
    if not _LANES.get():
        return F.dropout(x, p, training)
    return x * lane_mask(x.shape, p, x.device) * (1.0 / (1.0 - p))


class Dropout(nn.Dropout):
    """``nn.Dropout`` (same parameters, state and behaviour) that draws its mask with
    :func:`lane_mask` inside :func:`lane_dropout`."""

    def forward(self, input: torch.Tensor) -> torch.Tensor:
        if self.training and self.p > 0.0 and _LANES.get():
            return dropout(input, self.p, True)
        return super().forward(input)
