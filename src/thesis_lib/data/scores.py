"""D4RL-normalised scores: ``100 · (return − random) / (expert − random)``.

The reference returns are D4RL's (``d4rl/infos.py``), listed in
:data:`thesis_lib.data.tasks.TASKS` (our ``task/tier`` sets) and
:data:`thesis_lib.data.minari_ids.D4RL_REFERENCES` (real Minari ``D4RL/…`` ids). HDT 5.2
and Decision Mamba 5.3 report scores this way.
"""

from __future__ import annotations

from typing import Literal, overload

import numpy as np

from .minari_ids import is_minari_id, reference_returns
from .tasks import get_task


@overload
def normalized_score(task: str, returns: float, missing: Literal["raise"] = "raise") -> float: ...
@overload
def normalized_score(task: str, returns: float, missing: Literal["none"]) -> float | None: ...
@overload
def normalized_score(
    task: str, returns: float | np.ndarray, missing: Literal["raise", "none"] = "raise"
) -> float | np.ndarray | None: ...
def normalized_score(
    task: str,
    returns: float | np.ndarray,
    missing: Literal["raise", "none"] = "raise",
) -> float | np.ndarray | None:
    """D4RL-normalised score (×100) of one return or an array of returns.

    >>> round(normalized_score("hopper", 3234.3), 6)
    100.0
    >>> round(normalized_score("hopper", -20.272305), 6)
    0.0

    Args:
        task: task name (``hopper``, ``maze2d-umaze`` …) or a Minari id
            (``D4RL/door/human-v2``: :func:`thesis_lib.data.minari_ids.reference_returns`).
        returns: undiscounted episode return(s), any shape.
        missing: what to do when the task has no D4RL reference
            (``inverted-double-pendulum``): raise or return ``None``.

    Returns:
        Score(s) of the same shape as ``returns``; ``None`` when ``missing="none"`` and
        the task has no reference.

    Raises:
        ValueError: unknown task, or no reference and ``missing="raise"``.
    """
    if is_minari_id(task):  # a real Minari set: D4RL's references for its id
        ref = reference_returns(task)
        lo, hi = ref if ref is not None else (None, None)
    else:
        spec = get_task(task)
        lo, hi = spec.ref_min_score, spec.ref_max_score
    if lo is None or hi is None:
        if missing == "none":
            return None
        raise ValueError(
            f"Task '{task}' has no D4RL reference returns, so no normalised score; "
            "report raw returns."
        )
    out = 100.0 * (np.asarray(returns, dtype=np.float64) - lo) / (hi - lo)
    return float(out) if out.ndim == 0 else out
