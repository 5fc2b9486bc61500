"""Step-by-step costs of a growing trajectory against a group of demonstrations (thesis 4.3).

:class:`WindowedCosts` gives the K per-demonstration DTW costs for one windowing after every
appended step; :class:`GroupCost` aggregates them into one method's number. The two DTW
back-ends:

- ``"exact"`` (default): :mod:`thesis_lib.dtw`. Full and DemoW on an uncapped trajectory use
  :class:`~thesis_lib.dtw.IncrementalDTW` (one new cost-matrix row per step, O(sum M_k));
  every other case (TrajW, BothW, Same, or a capped trajectory, whose oldest step drops out)
  recomputes :func:`~thesis_lib.dtw.dtw_batch` on the current window each step.
- ``"fastdtw"``: the authors' FastDTW (radius 1, L1), one Python call per demonstration per
  step, for ``paper_compat`` runs. Slow by design; it is what the thesis timed.

Used in: DEFENDER (thesis 4.3).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any, Literal

import numpy as np
from numpy.typing import ArrayLike

from thesis_lib import dtw as _dtw
from thesis_lib.defender.methods import METHODS, Method, parse_method
from thesis_lib.dtw._validation import as_sequence

__all__ = ["BACKENDS", "GroupCost", "WindowedCosts", "cost_curves"]

Backend = Literal["exact", "fastdtw"]
BACKENDS: tuple[str, ...] = ("exact", "fastdtw")


def _check_backend(backend: str) -> None:
    if backend not in BACKENDS:
        raise ValueError(f"Unknown DTW backend {backend!r}. Valid: {', '.join(BACKENDS)}.")


class WindowedCosts:
    """Per-demonstration DTW costs of a growing trajectory for one windowing.

    Args:
        references: the group's K demonstrations, packed (:func:`~thesis_lib.dtw.pack_references`).
        method: any method with the wanted windowing (the aggregation is ignored here).
        metric: DTW local cost.
        max_trajectory: compare only the trajectory's last this-many steps (the authors' code: 20);
            None = the whole trajectory.
        backend: ``"exact"`` or ``"fastdtw"``.
        radius: FastDTW's radius (``backend="fastdtw"`` only).

    After ``append`` of step t (0-based), :attr:`costs` (K,) equals
    ``dtw_batch(window(trajectory[:t+1]), references, x_window=..., y_window=...)``.
    """

    def __init__(
        self,
        references: _dtw.PackedReferences,
        method: str | Method,
        *,
        metric: _dtw.Metric = "l1",
        max_trajectory: int | None = None,
        backend: Backend = "exact",
        radius: int = 1,
    ) -> None:
        _check_backend(backend)
        if max_trajectory is not None and (
            isinstance(max_trajectory, bool) or int(max_trajectory) < 1
        ):
            raise ValueError(
                f"max_trajectory must be a positive int or None, got {max_trajectory!r}."
            )
        self.method = parse_method(method)
        self.references = references
        self.metric = metric
        self.max_trajectory = None if max_trajectory is None else int(max_trajectory)
        self.backend = backend
        self.radius = radius
        self.incremental = (
            backend == "exact" and self.method.incremental and self.max_trajectory is None
        )
        n_features = references.n_features
        if self.incremental:
            self._inc = _dtw.IncrementalDTW(
                references, metric=metric, y_window=self.method.y_window(0)
            )
        else:
            # Keep at most max_trajectory steps, in a buffer that slides only when full.
            self._buffer = np.empty((max(64, 2 * (self.max_trajectory or 0)), n_features))
            if backend == "fastdtw":
                self._demos = [
                    references.data[references.offsets[k] : references.offsets[k + 1]]
                    for k in range(references.n_sequences)
                ]
        self._costs = np.full(references.n_sequences, np.inf)
        self.reset()

    def reset(self) -> None:
        """Forget the trajectory."""
        self._n = 0  # steps appended
        self._start = 0  # buffer rows [start, end) hold the kept steps
        self._end = 0
        self._costs.fill(np.inf)
        if self.incremental:
            self._inc.reset()

    @property
    def n_steps(self) -> int:
        """Steps appended since the last reset."""
        return self._n

    @property
    def costs(self) -> np.ndarray:
        """(K,) costs after the last append (a copy); inf before the first."""
        return self._costs.copy()

    def query(self) -> np.ndarray:
        """The trajectory steps currently compared (after the ``max_trajectory`` cap), (L, F)."""
        if self.incremental:
            raise RuntimeError(
                "An incremental comparison keeps no trajectory; use backend='exact' with a cap."
            )
        return self._buffer[self._start : self._end]

    def _push(self, step: np.ndarray) -> None:
        if self._end == len(self._buffer):
            kept = self._end - self._start
            if self.max_trajectory is not None and kept >= self.max_trajectory:
                kept = self.max_trajectory - 1
                self._buffer[:kept] = self._buffer[self._end - kept : self._end]
            elif self._start > 0:
                self._buffer[:kept] = self._buffer[self._start : self._end]
            else:
                grown = np.empty((2 * len(self._buffer), self._buffer.shape[1]))
                grown[:kept] = self._buffer[:kept]
                self._buffer = grown
            self._start, self._end = 0, kept
        self._buffer[self._end] = step
        self._end += 1
        if self.max_trajectory is not None and self._end - self._start > self.max_trajectory:
            self._start = self._end - self.max_trajectory

    def append(self, step: ArrayLike) -> np.ndarray:
        """Add one trajectory step (F,) and return the (K,) costs (the internal array: do not modify)."""
        step = np.asarray(step, dtype=np.float64).reshape(-1)
        n_features = self.references.n_features
        if step.size != n_features:
            raise ValueError(
                f"trajectory step has {step.size} values but the demonstrations have {n_features} "
                "features; states and demonstrations must come from the same observation "
                "(and action) space."
            )
        self._n += 1
        if self.incremental:
            self._costs = self._inc.append(step)
            return self._costs
        self._push(step)
        x = self._buffer[self._start : self._end]
        m = self.method
        yw = m.y_window(len(x))
        if self.backend == "exact":
            self._costs = _dtw.dtw_batch(
                x, self.references, metric=self.metric, x_window=m.x_window, y_window=yw
            )
        else:
            xq = x[-m.x_window :] if m.x_window else x
            for k, demo in enumerate(self._demos):
                self._costs[k] = _dtw.fastdtw_cost(
                    xq, demo[-yw:] if yw else demo, radius=self.radius, metric=self.metric
                )
        return self._costs


class GroupCost:
    """One method's cost of a growing trajectory against one group of demonstrations.

    Args:
        references: the group's demonstrations, (M_k, F) each, or packed.
        method: a name of :data:`~thesis_lib.defender.METHODS` (e.g. ``"MeanDemoW5"``).
        metric, max_trajectory, backend, radius: as :class:`WindowedCosts`.

    Used in: DEFENDER (thesis 4.3), inside :class:`~thesis_lib.defender.DefenderWrapper`.

    >>> g = GroupCost([[[0.0], [1.0], [2.0]], [[2.0], [2.0]]], "MinDemoW5")
    >>> g.append([0.0]), g.append([1.0])
    (3.0, 1.0)
    """

    def __init__(
        self,
        references: Sequence[ArrayLike] | _dtw.PackedReferences,
        method: str | Method,
        *,
        metric: _dtw.Metric = "l1",
        max_trajectory: int | None = None,
        backend: Backend = "exact",
        radius: int = 1,
    ) -> None:
        self.method = parse_method(method)
        packed = (
            references
            if isinstance(references, _dtw.PackedReferences)
            else _dtw.pack_references(references)
        )
        self._windowed = WindowedCosts(
            packed,
            self.method,
            metric=metric,
            max_trajectory=max_trajectory,
            backend=backend,
            radius=radius,
        )
        aggs: dict[str, Callable[[np.ndarray], Any]] = {
            "Min": np.min,
            "Max": np.max,
            "Mean": np.mean,
        }
        self._agg = aggs[self.method.aggregation]

    @property
    def incremental(self) -> bool:
        """True when the cost is updated incrementally (O(M) per step)."""
        return self._windowed.incremental

    def reset(self) -> None:
        """Forget the trajectory."""
        self._windowed.reset()

    def append(self, step: ArrayLike) -> float:
        """Add one trajectory step and return the method's cost of the trajectory so far."""
        return float(self._agg(self._windowed.append(step)))

    @property
    def per_demo(self) -> np.ndarray:
        """(K,) per-demonstration costs after the last append."""
        return self._windowed.costs


def cost_curves(
    trajectory: ArrayLike,
    references: Sequence[ArrayLike] | _dtw.PackedReferences,
    *,
    metric: _dtw.Metric = "l1",
    max_trajectory: int | None = None,
    backend: Backend = "exact",
    methods: Sequence[str] | None = None,
) -> dict[str, np.ndarray]:
    """Every method's cost after every step of a logged trajectory (the offline replay of 4.3.2).

    Each windowing is computed once and aggregated three ways.

    Args:
        trajectory: (T, F) the logged episode's states (or state-actions).
        references: the group's demonstrations.
        methods: names to compute (default: all 24).

    Returns:
        ``{method name: (T,) costs}``, entry t = the cost after the agent's first t+1 steps.

    Used in: DEFENDER strategy ablation (thesis 4.3.2).
    """
    x = as_sequence(trajectory, "trajectory")
    packed = (
        references
        if isinstance(references, _dtw.PackedReferences)
        else _dtw.pack_references(references)
    )
    wanted = [parse_method(m) for m in (methods or METHODS)]
    by_window: dict[str, list[Method]] = {}
    for m in wanted:
        by_window.setdefault(m.windowing_name, []).append(m)
    out: dict[str, np.ndarray] = {}
    for group in by_window.values():
        wc = WindowedCosts(
            packed, group[0], metric=metric, max_trajectory=max_trajectory, backend=backend
        )
        per_demo = np.empty((len(x), packed.n_sequences))
        for t, step in enumerate(x):
            per_demo[t] = wc.append(step)
        for m in group:
            out[m.name] = {
                "Min": per_demo.min(1),
                "Max": per_demo.max(1),
                "Mean": per_demo.mean(1),
            }[m.aggregation]
    return {m.name: out[m.name] for m in wanted}
