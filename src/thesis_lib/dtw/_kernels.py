"""Numba kernels for exact DTW (thesis 2.4). Private: call the wrappers in ``core``.

All kernels take C-contiguous float64 arrays of shape (N, F) and a metric code
(``L1``, ``L2``, ``SQEUCLIDEAN``). A reference set is "packed": one (sum M, F)
array plus an int64 ``offsets`` array of length K+1, reference k being
``data[offsets[k]:offsets[k+1]]``. ``window`` arguments are ints, 0 meaning
"the whole sequence", W > 0 meaning "the last min(W, length) steps".

The helpers are inlined at numba IR level (``inline="always"``): left as calls, the 1-D
1000 x 1000 case was 6x slower. Every kernel computes a cell with the same expression,
``local_cost + min(up, diag, left)``, so the full matrix, the two-row and the
incremental kernels give bit-identical costs.
"""

from __future__ import annotations

import numpy as np
from numba import njit

L1 = 0
L2 = 1
SQEUCLIDEAN = 2


@njit(cache=True, inline="always")
def _pair_cost(a, ia, b, ib, metric):
    """Local cost d(a[ia], b[ib]) between two feature vectors, summed over features in order.

    (Splitting the sum into several accumulators was slower: the local costs do not depend
    on the DP chain, so the CPU already overlaps them across cells.)
    """
    s = 0.0
    if metric == L1:
        for f in range(a.shape[1]):
            s += abs(a[ia, f] - b[ib, f])
        return s
    for f in range(a.shape[1]):
        d = a[ia, f] - b[ib, f]
        s += d * d
    if metric == L2:
        return np.sqrt(s)
    return s


@njit(cache=True, inline="always")
def _min3(up, diag, left):
    m = up
    if diag < m:
        m = diag
    if left < m:
        m = left
    return m


@njit(cache=True, inline="always")
def _window_start(start, stop, window):
    """First index of the last ``window`` steps of [start, stop); window 0 = all."""
    if window > 0 and stop - start > window:
        return stop - window
    return start


@njit(cache=True)
def local_costs(x, y, metric):
    """(N, M) matrix of d(x_i, y_j)."""
    n, m = x.shape[0], y.shape[0]
    out = np.empty((n, m))
    for i in range(n):
        for j in range(m):
            out[i, j] = _pair_cost(x, i, y, j, metric)
    return out


@njit(cache=True)
def cost_matrix(x, y, metric):
    """(N+1, M+1) accumulated cost matrix D with the inf border and D[0, 0] = 0."""
    n, m = x.shape[0], y.shape[0]
    d = np.empty((n + 1, m + 1))
    d[0, 0] = 0.0
    for j in range(1, m + 1):
        d[0, j] = np.inf
    for i in range(1, n + 1):
        d[i, 0] = np.inf
        for j in range(1, m + 1):
            d[i, j] = _pair_cost(x, i - 1, y, j - 1, metric) + _min3(
                d[i - 1, j], d[i - 1, j - 1], d[i, j - 1]
            )
    return d


@njit(cache=True)
def backtrack(d):
    """Optimal path through a filled D, as (L, 2) 0-based (i, j) pairs.

    From (N, M) step to the smallest of D[i-1, j-1], D[i-1, j], D[i, j-1];
    ties go to the diagonal, then to (i-1, j), then to (i, j-1).
    """
    i, j = d.shape[0] - 1, d.shape[1] - 1
    path = np.empty((i + j - 1, 2), dtype=np.int64)
    k = 0
    while True:
        path[k, 0] = i - 1
        path[k, 1] = j - 1
        k += 1
        if i == 1 and j == 1:
            break
        diag = d[i - 1, j - 1]
        up = d[i - 1, j]
        left = d[i, j - 1]
        if diag <= up and diag <= left:
            i -= 1
            j -= 1
        elif up <= left:
            i -= 1
        else:
            j -= 1
    return path[:k][::-1].copy()


@njit(cache=True)
def _dtw_rows(x, y, y_start, y_stop, metric, row):
    """D[N, M] of x against y[y_start:y_stop] in O(M) memory (``row`` has >= M+1 cells)."""
    m = y_stop - y_start
    row[0] = 0.0  # D[0, 0]
    for j in range(1, m + 1):
        row[j] = np.inf  # D[0, j]
    for i in range(x.shape[0]):
        diag = row[0]  # D[i-1, 0]: 0 on the first row, inf afterwards
        left = np.inf  # D[i, 0]
        row[0] = np.inf
        for j in range(1, m + 1):
            up = row[j]
            c = _pair_cost(x, i, y, y_start + j - 1, metric) + _min3(up, diag, left)
            row[j] = c
            diag = up
            left = c
    return row[m]


@njit(cache=True)
def dtw_cost(x, y, metric):
    """DTW cost of one pair, O(M) memory."""
    row = np.empty(y.shape[0] + 1)
    return _dtw_rows(x, y, 0, y.shape[0], metric, row)


@njit(cache=True)
def dtw_batch(x, data, offsets, y_window, metric):
    """Costs of one query x against every packed reference, shape (K,)."""
    k = offsets.shape[0] - 1
    max_m = 0
    for r in range(k):
        max_m = max(max_m, offsets[r + 1] - offsets[r])
    row = np.empty(max_m + 1)
    out = np.empty(k)
    for r in range(k):
        stop = offsets[r + 1]
        start = _window_start(offsets[r], stop, y_window)
        out[r] = _dtw_rows(x, data, start, stop, metric, row)
    return out


@njit(cache=True)
def dtw_matrix(q_data, q_offsets, r_data, r_offsets, x_window, y_window, metric, symmetric):
    """(Q, K) costs of packed queries against packed references.

    With ``symmetric`` the references are the queries and only i < j is computed.
    """
    nq = q_offsets.shape[0] - 1
    nr = r_offsets.shape[0] - 1
    max_m = 0
    for r in range(nr):
        max_m = max(max_m, r_offsets[r + 1] - r_offsets[r])
    row = np.empty(max_m + 1)
    out = np.zeros((nq, nr))
    for q in range(nq):
        q_stop = q_offsets[q + 1]
        x = q_data[_window_start(q_offsets[q], q_stop, x_window) : q_stop]
        for r in range(q + 1 if symmetric else 0, nr):
            stop = r_offsets[r + 1]
            start = _window_start(r_offsets[r], stop, y_window)
            out[q, r] = _dtw_rows(x, r_data, start, stop, metric, row)
            if symmetric:
                out[r, q] = out[q, r]
    return out


@njit(cache=True)
def incremental_step(obs, data, offsets, rows, first, y_window, metric, out):
    """Advance every reference's last cost-matrix row by one query step, in place.

    ``obs`` is (1, F); ``rows[offsets[k]:offsets[k+1]]`` holds D[i, 1:M+1] of reference k
    (D[i, 0] is implicit: 0 before the first step, inf afterwards). Writes D[i+1, M] to ``out``.
    """
    for r in range(offsets.shape[0] - 1):
        stop = offsets[r + 1]
        start = _window_start(offsets[r], stop, y_window)
        diag = 0.0 if first else np.inf
        left = np.inf
        for j in range(start, stop):
            up = rows[j]
            c = _pair_cost(obs, 0, data, j, metric) + _min3(up, diag, left)
            rows[j] = c
            diag = up
            left = c
        out[r] = rows[stop - 1]
