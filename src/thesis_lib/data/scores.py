"""D4RL-normalised scores: ``100 · (return − random) / (expert − random)``.

The reference returns are D4RL's (``d4rl/infos.py``), listed in
:data:`thesis_lib.data.tasks.TASKS`. HDT 5.2 and Decision Mamba 5.3 report scores this way.
"""

from __future__ import annotations

from typing import Literal, overload

import numpy as np

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
        task: task name (``hopper``, ``maze2d-umaze`` …).
        returns: undiscounted episode return(s), any shape.
        missing: what to do when the task has no D4RL reference
            (``inverted-double-pendulum``): raise or return ``None``.

    Returns:
        Score(s) of the same shape as ``returns``; ``None`` when ``missing="none"`` and
        the task has no reference.

    Raises:
        ValueError: unknown task, or no reference and ``missing="raise"``.
    """
    spec = get_task(task)
    if spec.ref_min_score is None or spec.ref_max_score is None:
        if missing == "none":
            return None
        raise ValueError(
            f"Task '{task}' has no D4RL reference returns, so no normalised score; "
            "report raw returns."
        )
    lo, hi = spec.ref_min_score, spec.ref_max_score
    out = 100.0 * (np.asarray(returns, dtype=np.float64) - lo) / (hi - lo)
    return float(out) if out.ndim == 0 else out
