"""Adapter over the ``fastdtw`` package, for runs faithful to the authors' DEFENDER code.

The thesis (2.4) says "in practice we use FastDTW"; the DEFENDER code calls
``fastdtw(x, y, radius=1, dist=<L1>)``. Quirks of fastdtw 0.3.4 worth knowing:

- It is approximate: coarsened copies of both sequences are aligned first and the full
  resolution is searched only within ``radius`` cells of the projected path. The cost is
  the exact DP restricted to that window, so it is never below exact DTW, and equals it
  once ``radius + 2`` exceeds the length of either sequence (fastdtw then runs plain DTW).
- Coarsening averages pairs and drops the last step of an odd-length sequence at that level.
- ``dist=None`` means |a - b| for 1-D input and the L1 norm for 2-D input; an int p means
  ``np.linalg.norm(a - b, p)``; a callable is called once per cell in pure Python, which is
  why it is slow (Wu & Keogh, 2020, found it usually slower than exact DTW).
- On cost ties it prefers (i-1, j), then (i, j-1), then the diagonal, so its path can differ
  from :func:`~thesis_lib.dtw.dtw_path` at equal cost.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

from thesis_lib.dtw._validation import Metric, as_sequence, check_same_features, metric_code

__all__ = ["fastdtw_cost"]


def _sqeuclidean(a: np.ndarray, b: np.ndarray) -> float:
    d = a - b
    return float(np.dot(d, d))


def fastdtw_cost(x: ArrayLike, y: ArrayLike, *, radius: int = 1, metric: Metric = "l1") -> float:
    """Approximate DTW cost from the ``fastdtw`` package (the authors' DEFENDER setting).

    Args:
        x: (N,) or (N, F) sequence; 1-D counts as (N, 1).
        y: (M,) or (M, F) sequence with the same F.
        radius: fastdtw's search radius (the code used 1); >= min(N, M) - 1 makes it exact.
        metric: ``"l1"`` (fastdtw ``dist=1``, the paper setting), ``"l2"`` (``dist=2``) or
            ``"sqeuclidean"`` (a Python callable, slow).

    Returns:
        The fastdtw cost as a Python float, >= ``dtw(x, y, metric=metric)``.

    Raises:
        ValueError: on invalid input (as :func:`~thesis_lib.dtw.dtw`) or a negative radius.
        ImportError: if fastdtw is not installed.

    Used in: Background chapter (thesis 2.4) and DEFENDER (4.3), ``paper_compat`` runs.

    >>> fastdtw_cost([0, 1, 2], [0, 0, 1, 2])
    0.0
    """
    code = metric_code(metric)
    if isinstance(radius, bool) or not isinstance(radius, (int, np.integer)) or radius < 0:
        raise ValueError(f"radius must be a non-negative int (the authors used 1), got {radius!r}.")
    xs, ys = as_sequence(x, "x"), as_sequence(y, "y")
    check_same_features(xs, ys, "x", "y")
    try:
        from fastdtw import fastdtw
    except ImportError as err:  # pragma: no cover - depends on the environment
        raise ImportError(
            "fastdtw_cost needs the fastdtw package: pip install fastdtw==0.3.4"
        ) from err
    dist = {0: 1, 1: 2, 2: _sqeuclidean}[code]
    cost, _ = fastdtw(xs, ys, radius=int(radius), dist=dist)
    return float(cost)
