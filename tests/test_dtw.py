"""thesis_lib.dtw: the thesis recursion (2.4) against hand-worked values, two independent
libraries (dtaidistance, dtw-python), invariants of the path, and the DEFENDER (4.3) variants
(batch, windows, incremental, fastdtw) against the plain pairwise DTW."""

from __future__ import annotations

import doctest
import importlib

import numpy as np
import pytest
from scipy.spatial.distance import cdist

from thesis_lib.dtw import (
    METRICS,
    IncrementalDTW,
    cost_matrix,
    dtw,
    dtw_batch,
    dtw_matrix,
    dtw_path,
    fastdtw_cost,
    initial_cost_matrix,
    local_costs,
    pack_references,
)

INF = np.inf
SCIPY_NAMES = {"l1": "cityblock", "l2": "euclidean", "sqeuclidean": "sqeuclidean"}
# (N, M, F): different lengths, 1-D and multi-D, a 1-step sequence.
SHAPES = [(7, 7, 1), (9, 13, 1), (13, 5, 3), (1, 6, 2), (20, 20, 11)]


def random_pair(n, m, f, seed=0):
    rng = np.random.default_rng(seed)
    x, y = rng.normal(size=(n, f)), rng.normal(size=(m, f))
    return (x[:, 0], y[:, 0]) if f == 1 else (x, y)


def random_references(k, f, seed=0, lengths=(3, 25)):
    rng = np.random.default_rng(seed)
    return [rng.normal(size=(int(rng.integers(*lengths)), f)) for _ in range(k)]


def brute_force_dtw(x, y, metric):
    """Plain-Python DTW: the thesis formula cell by cell (a second implementation)."""
    c = cdist(np.atleast_2d(x.T).T, np.atleast_2d(y.T).T, SCIPY_NAMES[metric])
    d = np.full((len(x) + 1, len(y) + 1), INF)
    d[0, 0] = 0.0
    for i in range(1, len(x) + 1):
        for j in range(1, len(y) + 1):
            d[i, j] = c[i - 1, j - 1] + min(d[i - 1, j], d[i - 1, j - 1], d[i, j - 1])
    return d[-1, -1]


# --- hand-worked example (x = [0, 2, 1, 3], y = [0, 1, 2, 2, 3], L1) -------------------------

X_HAND = [0.0, 2.0, 1.0, 3.0]
Y_HAND = [0.0, 1.0, 2.0, 2.0, 3.0]
LOCAL_HAND = [
    [0, 1, 2, 2, 3],
    [2, 1, 0, 0, 1],
    [1, 0, 1, 1, 2],
    [3, 2, 1, 1, 0],
]
D_HAND = [
    [0, INF, INF, INF, INF, INF],
    [INF, 0, 1, 3, 5, 8],
    [INF, 2, 1, 1, 1, 2],
    [INF, 3, 1, 2, 2, 3],
    [INF, 6, 3, 2, 3, 2],
]
PATH_HAND = [[0, 0], [0, 1], [1, 2], [2, 3], [3, 4]]  # ties resolved towards the diagonal


def test_hand_worked_example():
    np.testing.assert_array_equal(local_costs(X_HAND, Y_HAND, metric="l1"), LOCAL_HAND)
    np.testing.assert_array_equal(cost_matrix(X_HAND, Y_HAND, metric="l1"), D_HAND)
    res = dtw_path(X_HAND, Y_HAND, metric="l1")
    assert res.cost == 2.0 == dtw(X_HAND, Y_HAND, metric="l1")
    assert res.path.tolist() == PATH_HAND
    np.testing.assert_array_equal(res.matrix, D_HAND)


def test_initial_cost_matrix_matches_thesis_initialisation():
    d = initial_cost_matrix(4, 5)
    assert d.shape == (5, 6) and d[0, 0] == 0.0
    assert np.isinf(d[0, 1:]).all() and np.isinf(d[1:, 0]).all()
    assert np.isnan(d[1:, 1:]).all()
    with pytest.raises(ValueError, match="n_y must be a positive int"):
        initial_cost_matrix(3, 0)


def test_delayed_sequence_costs_zero():
    """Thesis Fig. 2.3/2.4: a delayed copy is far for one-to-one metrics but 0 for DTW."""
    x = np.sin(np.linspace(0, 2 * np.pi, 30))
    y = np.concatenate([np.full(5, x[0]), x])
    assert dtw(x, y) == 0.0
    assert np.abs(x - y[:30]).sum() > 1.0


# --- agreement with independent implementations ----------------------------------------------


@pytest.mark.parametrize("metric", list(METRICS))
@pytest.mark.parametrize("n,m,f", SHAPES)
def test_matches_brute_force(metric, n, m, f):
    x, y = random_pair(n, m, f, seed=n * m + f)
    assert dtw(x, y, metric=metric) == pytest.approx(brute_force_dtw(x, y, metric), rel=1e-12)


@pytest.mark.parametrize("use_c", [False, True])
@pytest.mark.parametrize("n,m,f", SHAPES)
def test_matches_dtaidistance(use_c, n, m, f):
    """dtaidistance sums squared Euclidean local costs and returns the square root of the total;
    with inner_dist='euclidean' it sums Euclidean costs with no root (our "l2")."""
    module = pytest.importorskip("dtaidistance.dtw" if f == 1 else "dtaidistance.dtw_ndim")
    x, y = random_pair(n, m, f, seed=n + m + f)
    expected_sq = module.distance(x, y, use_c=use_c)
    assert np.sqrt(dtw(x, y, metric="sqeuclidean")) == pytest.approx(expected_sq, rel=1e-12)
    expected_l2 = module.distance(x, y, use_c=use_c, inner_dist="euclidean")
    assert dtw(x, y, metric="l2") == pytest.approx(expected_l2, rel=1e-12)


@pytest.mark.parametrize("metric", list(METRICS))
@pytest.mark.parametrize("n,m,f", SHAPES)
def test_matches_dtw_python(metric, n, m, f):
    """dtw-python's default step pattern symmetric2 weights diagonal steps by 2; symmetric1 is
    the thesis recursion."""
    dtw_python = pytest.importorskip("dtw")
    x, y = random_pair(n, m, f, seed=3 * n + m + f)
    expected = dtw_python.dtw(
        x, y, dist_method=SCIPY_NAMES[metric], step_pattern="symmetric1"
    ).distance
    assert dtw(x, y, metric=metric) == pytest.approx(expected, rel=1e-12)


def test_local_costs_match_scipy_cdist():
    x, y = random_pair(6, 8, 4)
    for metric, name in SCIPY_NAMES.items():
        np.testing.assert_allclose(local_costs(x, y, metric=metric), cdist(x, y, name), rtol=1e-13)


# --- properties --------------------------------------------------------------------------------


@pytest.mark.parametrize("metric", list(METRICS))
@pytest.mark.parametrize("n,m,f", SHAPES)
def test_path_invariants(metric, n, m, f):
    x, y = random_pair(n, m, f, seed=7 * n + m)
    res = dtw_path(x, y, metric=metric)
    path = res.path
    assert path.shape[1] == 2 and path.dtype == np.int64
    assert path[0].tolist() == [0, 0] and path[-1].tolist() == [n - 1, m - 1]
    steps = {tuple(s) for s in np.diff(path, axis=0).tolist()}
    assert steps <= {(1, 0), (0, 1), (1, 1)}  # monotone and continuous
    assert max(n, m) <= len(path) <= n + m - 1
    c = local_costs(x, y, metric=metric)
    assert c[path[:, 0], path[:, 1]].sum() == pytest.approx(res.cost, rel=1e-12)
    assert res.cost == res.matrix[n, m] == dtw(x, y, metric=metric)
    assert res.matrix.shape == (n + 1, m + 1) and res.matrix[0, 0] == 0.0
    assert np.isinf(res.matrix[0, 1:]).all() and np.isinf(res.matrix[1:, 0]).all()


@pytest.mark.parametrize("metric", list(METRICS))
def test_symmetric_and_zero_on_identity(metric):
    x, y = random_pair(11, 17, 3, seed=1)
    assert dtw(x, y, metric=metric) == dtw(y, x, metric=metric)
    assert dtw(x, x, metric=metric) == 0.0


def test_1d_input_is_one_feature_and_l1_equals_l2_in_1d():
    x, y = random_pair(9, 12, 1)
    assert dtw(x, y) == dtw(x[:, None], y[:, None])
    assert dtw(x, y, metric="l1") == pytest.approx(dtw(x, y, metric="l2"), rel=1e-15)
    assert dtw([1, 2, 3], [True, False]) == dtw([1.0, 2.0, 3.0], [1.0, 0.0])


# --- windows, batch, matrix (DEFENDER's variants) ----------------------------------------------

WINDOWS = [(None, None), (5, None), (None, 4), (5, 4), (1, 1), (100, 100)]


@pytest.mark.parametrize("x_window,y_window", WINDOWS)
def test_windowed_equals_dtw_on_sliced_arrays(x_window, y_window):
    x, y = random_pair(12, 15, 3, seed=2)
    xs = x if x_window is None else x[-x_window:]
    ys = y if y_window is None else y[-y_window:]
    assert dtw(x, y, metric="l1", x_window=x_window, y_window=y_window) == dtw(xs, ys, metric="l1")


@pytest.mark.parametrize("metric", list(METRICS))
@pytest.mark.parametrize("x_window,y_window", WINDOWS)
def test_batch_equals_loop_of_single_calls(metric, x_window, y_window):
    refs = random_references(12, 3, seed=4)
    x = np.random.default_rng(5).normal(size=(10, 3))
    expected = [dtw(x, r, metric=metric, x_window=x_window, y_window=y_window) for r in refs]
    kwargs = dict(metric=metric, x_window=x_window, y_window=y_window)
    np.testing.assert_array_equal(dtw_batch(x, refs, **kwargs), expected)
    np.testing.assert_array_equal(dtw_batch(x, pack_references(refs), **kwargs), expected)


def test_batch_accepts_3d_array_and_1d_references():
    refs3 = np.random.default_rng(6).normal(size=(5, 8, 2))
    x = np.random.default_rng(7).normal(size=(6, 2))
    np.testing.assert_array_equal(dtw_batch(x, refs3), [dtw(x, r) for r in refs3])
    refs1 = [np.arange(4.0), np.arange(7.0)[::-1]]
    np.testing.assert_array_equal(
        dtw_batch(np.arange(5.0), refs1), [dtw(np.arange(5.0), r) for r in refs1]
    )


@pytest.mark.parametrize("x_window,y_window", [(None, None), (4, 4), (3, 6)])
def test_dtw_matrix_equals_loops(x_window, y_window):
    qs, rs = random_references(4, 2, seed=8), random_references(6, 2, seed=9)
    kw = dict(metric="l1", x_window=x_window, y_window=y_window)
    expected = [[dtw(q, r, **kw) for r in rs] for q in qs]
    np.testing.assert_array_equal(dtw_matrix(qs, rs, **kw), expected)
    expected_self = [[dtw(q, r, **kw) for r in qs] for q in qs]
    np.testing.assert_array_equal(dtw_matrix(qs, **kw), expected_self)


# --- incremental ---------------------------------------------------------------------------------


@pytest.mark.parametrize("metric", list(METRICS))
@pytest.mark.parametrize("y_window", [None, 6])
def test_incremental_equals_full_recomputation_at_every_step(metric, y_window):
    refs = random_references(9, 4, seed=10)
    query = np.random.default_rng(11).normal(size=(30, 4))
    inc = IncrementalDTW(refs, metric=metric, y_window=y_window)
    assert np.isinf(inc.costs).all()
    for t in range(1, len(query) + 1):
        costs = inc.append(query[t - 1])
        full = dtw_batch(query[:t], refs, metric=metric, y_window=y_window)
        np.testing.assert_allclose(costs, full, rtol=0, atol=1e-12)
        np.testing.assert_array_equal(costs, full)  # same cell expression: bit-identical
    assert inc.n_steps == len(query)
    inc.reset()
    assert inc.n_steps == 0 and np.isinf(inc.costs).all()
    np.testing.assert_array_equal(
        inc.extend(query[:5]), dtw_batch(query[:5], refs, metric=metric, y_window=y_window)
    )


def test_incremental_returns_copies():
    inc = IncrementalDTW([[0.0, 1.0]], metric="l1")
    first = inc.append(0.0)
    inc.append(5.0)
    assert first.tolist() == [1.0]


# --- fastdtw adapter -----------------------------------------------------------------------------


@pytest.mark.parametrize("n,m,f", [(9, 13, 1), (13, 5, 3), (20, 20, 11)])
def test_fastdtw_with_large_radius_equals_exact_l1(n, m, f):
    pytest.importorskip("fastdtw")
    x, y = random_pair(n, m, f, seed=12)
    assert fastdtw_cost(x, y, radius=max(n, m), metric="l1") == pytest.approx(
        dtw(x, y, metric="l1"), rel=1e-12
    )
    assert fastdtw_cost(x, y, radius=max(n, m), metric="l2") == pytest.approx(
        dtw(x, y, metric="l2"), rel=1e-12
    )


def test_fastdtw_radius_1_is_an_upper_bound_and_matches_the_package():
    fastdtw = pytest.importorskip("fastdtw")
    rng = np.random.default_rng(13)
    for _ in range(10):
        x, y = rng.normal(size=(40, 3)), rng.normal(size=(33, 3))
        approx = fastdtw_cost(x, y, radius=1)
        assert approx >= dtw(x, y, metric="l1") - 1e-12
        assert approx == fastdtw.fastdtw(x, y, radius=1, dist=1)[0]


# --- errors users can act on ---------------------------------------------------------------------


@pytest.mark.parametrize(
    "call,match",
    [
        (lambda: dtw([], [1.0]), r"x is empty \(shape \(0, 1\)\)"),
        (lambda: dtw(np.zeros((3, 0)), np.zeros((3, 0))), "x is empty"),
        (
            lambda: dtw([1.0, np.nan], [1.0]),
            "x at time step 1, feature 0 is nan; DTW needs finite values",
        ),
        (lambda: dtw([1.0], [[0.0, np.inf]]), "y at time step 0, feature 1 is inf"),
        (lambda: dtw(np.zeros((4, 3)), np.zeros((5, 2))), r"x shape \(4, 3\) and y shape \(5, 2\)"),
        (
            lambda: dtw([1.0], [1.0], metric="L1"),
            r"Unknown metric 'L1'\. Did you mean 'l1'\? Valid: 'l1', 'l2', 'sqeuclidean'",
        ),
        (
            lambda: dtw([1.0], [1.0], metric="euclidean"),
            r"Unknown metric 'euclidean'\. Did you mean 'l2'\?",
        ),
        (
            lambda: dtw([1.0], [1.0], metric="cosine"),
            r"Unknown metric 'cosine'\. Valid: 'l1', 'l2', 'sqeuclidean'",
        ),
        (lambda: dtw(["a", "b"], [1.0]), "x must be numeric .* got dtype <U1"),
        (lambda: dtw([1 + 1j], [1.0]), "x must be numeric"),
        (
            lambda: dtw(np.zeros((2, 3, 4)), [1.0]),
            r"x must be 1-D \(N,\) or 2-D \(N, F\) .* got 3-D shape \(2, 3, 4\)",
        ),
        (lambda: dtw(1.0, [1.0]), "x must be 1-D .* got 0-D"),
        (lambda: dtw([[1.0], [1.0, 2.0]], [1.0]), "x could not be read as a numeric array"),
        (lambda: dtw([1.0], [1.0], x_window=0), "x_window must be a positive int .* got 0"),
        (lambda: dtw([1.0], [1.0], y_window=2.5), "y_window must be a positive int"),
        (lambda: dtw_batch([1.0], []), "references is empty"),
        (lambda: dtw_batch([1.0], np.zeros((3, 4))), "A 2-D array is ambiguous"),
        (
            lambda: dtw_batch([1.0], [[1.0], [np.nan, 1.0]]),
            r"references\[1\] at time step 0, feature 0 is nan",
        ),
        (
            lambda: dtw_batch(np.zeros((3, 2)), [np.zeros((4, 2)), np.zeros((4, 3))]),
            r"references\[1\] has shape \(4, 3\) but references\[0\] has shape \(4, 2\)",
        ),
        (
            lambda: dtw_batch(np.zeros((3, 2)), [np.zeros((4, 3))]),
            r"x has shape \(3, 2\) but the references have 3 feature",
        ),
        (
            lambda: IncrementalDTW([np.zeros((4, 3))]).append([1.0, 2.0]),
            r"observation has shape \(2,\) .* 3 feature",
        ),
        (lambda: IncrementalDTW([np.zeros((4, 1))]).append(np.nan), "contains NaN or inf"),
        (lambda: fastdtw_cost([1.0], [1.0], radius=-1), "radius must be a non-negative int"),
    ],
)
def test_errors_name_the_problem(call, match):
    with pytest.raises(ValueError, match=match):
        call()


@pytest.mark.parametrize("module", ["core", "incremental", "compat", "_validation", "__init__"])
def test_docstring_examples(module):
    name = "thesis_lib.dtw" if module == "__init__" else f"thesis_lib.dtw.{module}"
    result = doctest.testmod(importlib.import_module(name), optionflags=doctest.ELLIPSIS)
    assert result.failed == 0
