"""Dynamic Time Warping (thesis 2.4), as used by DEFENDER (thesis 4.3).

Exact DTW with the thesis's recursion, compiled with numba:

- :func:`dtw` one pair's cost; :func:`dtw_path` cost, path and matrix; :func:`cost_matrix`,
  :func:`local_costs` and :func:`initial_cost_matrix` for the background figures.
- :func:`dtw_batch` one query against many references; :func:`dtw_matrix` many against many;
  :func:`pack_references` to validate references once and reuse them.
- :class:`IncrementalDTW` a growing query (the agent's trajectory) against fixed references.
- :func:`fastdtw_cost` the authors' approximate FastDTW, for ``paper_compat`` runs.

Local costs (``metric``): ``"l1"`` sum ``|x_i - y_j|`` (the DEFENDER code's choice), ``"l2"``
Euclidean norm (default), ``"sqeuclidean"`` squared Euclidean (dtaidistance accumulates this and
returns the square root of the total).

>>> from thesis_lib.dtw import dtw
>>> dtw([0.0, 1.0, 2.0], [0.0, 0.0, 1.0, 2.0], metric="l1")
0.0
"""

from __future__ import annotations

from thesis_lib.dtw._validation import METRICS, Metric
from thesis_lib.dtw.compat import fastdtw_cost
from thesis_lib.dtw.core import (
    DTWResult,
    PackedReferences,
    cost_matrix,
    dtw,
    dtw_batch,
    dtw_matrix,
    dtw_path,
    initial_cost_matrix,
    local_costs,
    pack_references,
)
from thesis_lib.dtw.incremental import IncrementalDTW

__all__ = [
    "METRICS",
    "DTWResult",
    "IncrementalDTW",
    "Metric",
    "PackedReferences",
    "cost_matrix",
    "dtw",
    "dtw_batch",
    "dtw_matrix",
    "dtw_path",
    "fastdtw_cost",
    "initial_cost_matrix",
    "local_costs",
    "pack_references",
]
