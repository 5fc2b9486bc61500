"""Exact Dynamic Time Warping (thesis 2.4) for one pair, one-vs-many and many-vs-many.

The recursion is the thesis's: D is (N+1) x (M+1), D[0, :] = D[:, 0] = inf, D[0, 0] = 0,
D[i, j] = d(x_i, y_j) + min(D[i-1, j], D[i-1, j-1], D[i, j-1]), and the cost is D[N, M].
No step weights, no normalisation by path length, no band (dtw-python's ``symmetric1``).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import NamedTuple

import numpy as np
from numpy.typing import ArrayLike

from thesis_lib.dtw import _kernels
from thesis_lib.dtw._validation import (
    Metric,
    as_sequence,
    check_same_features,
    metric_code,
    pack,
    window_size,
)

__all__ = [
    "DTWResult",
    "PackedReferences",
    "cost_matrix",
    "dtw",
    "dtw_batch",
    "dtw_matrix",
    "dtw_path",
    "initial_cost_matrix",
    "local_costs",
    "pack_references",
]


class DTWResult(NamedTuple):
    """Result of :func:`dtw_path`."""

    cost: float
    """Alignment cost D[N, M]."""
    path: np.ndarray
    """(L, 2) int64 0-based pairs (i, j), x[i] matched to y[j], from (0, 0) to (N-1, M-1)."""
    matrix: np.ndarray
    """(N+1, M+1) accumulated cost matrix D, including the inf border row and column."""


class PackedReferences(NamedTuple):
    """Validated sequences stored end to end, built by :func:`pack_references`.

    Packing once and reusing it skips per-call validation and concatenation, which is
    most of the cost when a short query is compared with the same demonstrations every step.
    """

    data: np.ndarray
    """(sum of lengths, F) float64, C-contiguous: all sequences concatenated along time."""
    offsets: np.ndarray
    """(K+1,) int64: sequence k is ``data[offsets[k]:offsets[k+1]]``."""

    @property
    def n_sequences(self) -> int:
        return len(self.offsets) - 1

    @property
    def n_features(self) -> int:
        return self.data.shape[1]

    @property
    def lengths(self) -> np.ndarray:
        """(K,) int64 sequence lengths."""
        return np.diff(self.offsets)


References = Sequence[ArrayLike] | np.ndarray | PackedReferences
"""Many sequences: a list of (M_k, F) or (M_k,) arrays, a 3-D (K, M, F) array, or PackedReferences."""


def _last(x: np.ndarray, window: int) -> np.ndarray:
    return x[-window:] if window else x


def _packed(references: References, name: str) -> PackedReferences:
    if isinstance(references, PackedReferences):
        return references
    return PackedReferences(*pack(references, name))


def pack_references(references: Sequence[ArrayLike] | np.ndarray) -> PackedReferences:
    """Validate and pack many sequences once, for repeated :func:`dtw_batch` calls.

    Args:
        references: K sequences, a list of (M_k, F) or (M_k,) arrays (lengths may differ)
            or a 3-D (K, M, F) array.

    Returns:
        PackedReferences with ``data`` (sum M_k, F) float64 and ``offsets`` (K+1,).

    Raises:
        ValueError: if the list is empty, a sequence is empty, non-numeric, not finite,
            or the feature counts differ.

    Used in: DEFENDER (thesis 4.3), where the same demonstrations are compared every step.

    >>> packed = pack_references([[0.0, 1.0], [2.0, 3.0, 4.0]])
    >>> packed.offsets.tolist(), packed.data.shape
    ([0, 2, 5], (5, 1))
    """
    return _packed(references, "references")


def local_costs(x: ArrayLike, y: ArrayLike, metric: Metric = "l2") -> np.ndarray:
    """Pairwise local costs d(x_i, y_j), the (N, M) matrix DTW walks through.

    Args:
        x: (N,) or (N, F) sequence.
        y: (M,) or (M, F) sequence with the same F.
        metric: local cost, ``"l1"``, ``"l2"`` or ``"sqeuclidean"``.

    Returns:
        (N, M) float64 array, entry [i, j] = d(x[i], y[j]).

    Used in: Background chapter (thesis 2.4) and DEFENDER (4.3).

    >>> local_costs([0, 2], [0, 1, 3], metric="l1")
    array([[0., 1., 3.],
           [2., 1., 1.]])
    """
    code = metric_code(metric)
    xs, ys = as_sequence(x, "x"), as_sequence(y, "y")
    check_same_features(xs, ys, "x", "y")
    return _kernels.local_costs(xs, ys, code)


def initial_cost_matrix(n_x: int, n_y: int) -> np.ndarray:
    """The accumulated cost matrix before filling (thesis Fig. 2.5).

    Args:
        n_x: length N of the first sequence.
        n_y: length M of the second sequence.

    Returns:
        (N+1, M+1) float64 array: D[0, 0] = 0, rest of row 0 and column 0 inf,
        the unfilled cells NaN (so plots can leave them blank).

    Used in: Background chapter (thesis 2.4).

    >>> initial_cost_matrix(2, 3)
    array([[ 0., inf, inf, inf],
           [inf, nan, nan, nan],
           [inf, nan, nan, nan]])
    """
    for name, n in (("n_x", n_x), ("n_y", n_y)):
        if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or n < 1:
            raise ValueError(f"{name} must be a positive int (a sequence length), got {n!r}.")
    d = np.full((n_x + 1, n_y + 1), np.nan)
    d[0, :] = np.inf
    d[:, 0] = np.inf
    d[0, 0] = 0.0
    return d


def cost_matrix(x: ArrayLike, y: ArrayLike, metric: Metric = "l2") -> np.ndarray:
    """Filled accumulated cost matrix D of the thesis recursion (thesis Fig. 2.6).

    Args:
        x: (N,) or (N, F) sequence.
        y: (M,) or (M, F) sequence with the same F.
        metric: local cost, ``"l1"``, ``"l2"`` or ``"sqeuclidean"``.

    Returns:
        (N+1, M+1) float64 array with D[0, 0] = 0, the inf border, and
        D[i, j] = d(x_i, y_j) + min(D[i-1, j], D[i-1, j-1], D[i, j-1]); D[N, M] is the cost.

    Used in: Background chapter (thesis 2.4) and DEFENDER (4.3).

    >>> cost_matrix([0, 1], [0, 1, 1], metric="l1")
    array([[ 0., inf, inf, inf],
           [inf,  0.,  1.,  2.],
           [inf,  1.,  0.,  0.]])
    """
    code = metric_code(metric)
    xs, ys = as_sequence(x, "x"), as_sequence(y, "y")
    check_same_features(xs, ys, "x", "y")
    return _kernels.cost_matrix(xs, ys, code)


def dtw(
    x: ArrayLike,
    y: ArrayLike,
    *,
    metric: Metric = "l2",
    x_window: int | None = None,
    y_window: int | None = None,
) -> float:
    """Exact DTW alignment cost D[N, M] between two sequences, in O(M) memory.

    Args:
        x: (N,) or (N, F) sequence; 1-D counts as (N, 1).
        y: (M,) or (M, F) sequence with the same F.
        metric: local cost, ``"l1"`` (sum of absolute differences, what DEFENDER's code used
            through fastdtw), ``"l2"`` (Euclidean) or ``"sqeuclidean"``.
        x_window: compare only the last ``x_window`` steps of x (all of x if shorter); None = all.
        y_window: the same for y.

    Returns:
        The cost as a Python float (0.0 for sequences that warp onto each other exactly).

    Raises:
        ValueError: on empty, non-numeric, non-finite or >2-D input, differing feature counts,
            an unknown metric or a non-positive window.

    Used in: Background chapter (thesis 2.4) and DEFENDER (4.3).

    >>> dtw([0, 1, 2], [0, 0, 1, 2])  # y is x delayed by one step
    0.0
    >>> dtw([[0, 0], [1, 1]], [[0, 0], [2, 2]], metric="l1")
    2.0
    >>> dtw([5, 0, 1], [0, 1], x_window=2)
    0.0
    """
    code = metric_code(metric)
    xw, yw = window_size(x_window, "x_window"), window_size(y_window, "y_window")
    xs, ys = as_sequence(x, "x"), as_sequence(y, "y")
    check_same_features(xs, ys, "x", "y")
    return float(_kernels.dtw_cost(_last(xs, xw), _last(ys, yw), code))


def dtw_path(x: ArrayLike, y: ArrayLike, *, metric: Metric = "l2") -> DTWResult:
    """Exact DTW cost, optimal alignment path and the full cost matrix (thesis Figs. 2.6-2.7).

    The path is traced back from D[N, M] by stepping to the smallest of D[i-1, j-1],
    D[i-1, j] and D[i, j-1]. Ties prefer the diagonal, then (i-1, j), then (i, j-1), which
    favours the shorter of equal-cost paths. (fastdtw and dtw-python break ties differently:
    their paths can differ from this one at the same cost.)

    Args:
        x: (N,) or (N, F) sequence.
        y: (M,) or (M, F) sequence with the same F.
        metric: local cost, ``"l1"``, ``"l2"`` or ``"sqeuclidean"``.

    Returns:
        DTWResult(cost, path (L, 2) int64 0-based from (0, 0) to (N-1, M-1),
        matrix (N+1, M+1) with the inf border). The local costs along the path sum to cost.

    Used in: Background chapter (thesis 2.4) and DEFENDER (4.3).

    >>> res = dtw_path([0, 2, 1, 3], [0, 1, 2, 2, 3], metric="l1")
    >>> res.cost
    2.0
    >>> res.path.tolist()
    [[0, 0], [0, 1], [1, 2], [2, 3], [3, 4]]
    """
    d = cost_matrix(x, y, metric)
    return DTWResult(cost=float(d[-1, -1]), path=_kernels.backtrack(d), matrix=d)


def dtw_batch(
    x: ArrayLike,
    references: References,
    *,
    metric: Metric = "l2",
    x_window: int | None = None,
    y_window: int | None = None,
) -> np.ndarray:
    """DTW cost of one query against each of K references, in one compiled loop.

    Args:
        x: (N,) or (N, F) query (e.g. the agent's recent trajectory).
        references: K sequences (e.g. demonstrations): a list of (M_k, F) or (M_k,) arrays of any
            lengths, a 3-D (K, M, F) array, or :func:`pack_references` output (fastest when reused).
        metric: local cost, ``"l1"``, ``"l2"`` or ``"sqeuclidean"``.
        x_window: compare only the last ``x_window`` steps of the query; None = all.
        y_window: compare only the last ``y_window`` steps of every reference
            (a reference shorter than that is used whole); None = all.

    Returns:
        (K,) float64 costs, entry k equal to ``dtw(x, references[k], ...)``.

    Raises:
        ValueError: as :func:`dtw`, naming the offending reference by index.

    DEFENDER's windowings (thesis 4.3) with query = agent trajectory, references = demos:
    "Full" no windows; "Demo W" ``y_window=W``; "Traj W" ``x_window=W``; "Both W" both;
    "Same" ``y_window=len(query)`` (the demos' last L states, L = the agent's length).

    Used in: DEFENDER (thesis 4.3).

    >>> dtw_batch([0, 1, 2], [[0, 1, 2], [0, 0, 1, 1, 2], [2, 1, 0]], metric="l1")
    array([0., 0., 4.])
    """
    code = metric_code(metric)
    xw, yw = window_size(x_window, "x_window"), window_size(y_window, "y_window")
    xs = as_sequence(x, "x")
    refs = _packed(references, "references")
    if xs.shape[1] != refs.n_features:
        raise ValueError(
            f"x has shape {xs.shape} but the references have {refs.n_features} feature(s) "
            f"(reference 0 has shape {(int(refs.lengths[0]), refs.n_features)}); "
            "query and references must share the observation space."
        )
    return _kernels.dtw_batch(_last(xs, xw), refs.data, refs.offsets, yw, code)


def dtw_matrix(
    queries: References,
    references: References | None = None,
    *,
    metric: Metric = "l2",
    x_window: int | None = None,
    y_window: int | None = None,
) -> np.ndarray:
    """DTW costs of every query against every reference, in one compiled loop.

    Args:
        queries: Q sequences, in any form :func:`dtw_batch` accepts for references.
        references: K sequences; None compares the queries with each other (DTW is symmetric,
            so with equal windows only the upper triangle is computed and the diagonal is 0).
        metric: local cost, ``"l1"``, ``"l2"`` or ``"sqeuclidean"``.
        x_window: last steps of each query to compare; None = all.
        y_window: last steps of each reference to compare; None = all.

    Returns:
        (Q, K) float64 array, entry [q, k] = ``dtw(queries[q], references[k], ...)``.

    Used in: DEFENDER (thesis 4.3), picking a diverse subset of demonstrations.

    >>> dtw_matrix([[0, 1], [0, 3], [1, 1]], metric="l1")
    array([[0., 2., 1.],
           [2., 0., 3.],
           [1., 3., 0.]])
    """
    code = metric_code(metric)
    xw, yw = window_size(x_window, "x_window"), window_size(y_window, "y_window")
    qs = _packed(queries, "queries")
    if references is None:
        rs, symmetric = qs, xw == yw
    else:
        rs, symmetric = _packed(references, "references"), False
        if qs.n_features != rs.n_features:
            raise ValueError(
                f"queries have {qs.n_features} feature(s) but references have {rs.n_features}; "
                "both must share the observation space."
            )
    return _kernels.dtw_matrix(qs.data, qs.offsets, rs.data, rs.offsets, xw, yw, code, symmetric)
