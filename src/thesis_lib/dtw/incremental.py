"""DTW of a growing query against fixed references, one step at a time (DEFENDER, thesis 4.3)."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numpy.typing import ArrayLike

from thesis_lib.dtw import _kernels
from thesis_lib.dtw._validation import Metric, as_sequence, metric_code, window_size
from thesis_lib.dtw.core import PackedReferences, pack_references

__all__ = ["IncrementalDTW"]


class IncrementalDTW:
    """Costs of a growing query against K fixed references, updated in O(sum M_k) per step.

    Appending query step i+1 only adds row i+1 of each reference's cost matrix D, which
    depends on row i alone; so the object keeps one row per reference (O(sum M_k) memory)
    and never revisits earlier steps. After t appends, :attr:`costs` equals
    ``dtw_batch(query[:t], references, metric=metric, y_window=y_window)`` exactly
    (bit for bit: the kernels share one cell expression).

    Windows: ``y_window`` (the last W steps of every reference, DEFENDER's "Demo W") is fixed,
    so it is supported. A window on the query side (DEFENDER's "Traj W", the agent's last W
    steps) cannot be updated incrementally: dropping the oldest query step changes D[1, :],
    and with it every later row. The same holds for "Same" (``y_window`` = the query's length,
    so the reference window moves as the query grows). Use ``dtw_batch`` each step for those;
    with a query of about 20 steps it costs O(20 sum M_k).

    Args:
        references: K sequences, a list of (M_k, F) or (M_k,) arrays, a 3-D (K, M, F) array or
            :func:`~thesis_lib.dtw.pack_references` output.
        metric: local cost, ``"l1"``, ``"l2"`` or ``"sqeuclidean"``.
        y_window: compare only the last ``y_window`` steps of every reference; None = all.

    Used in: DEFENDER (thesis 4.3), comparing the agent's trajectory with the demonstrations
    at every environment step.

    >>> inc = IncrementalDTW([[0.0, 1.0, 2.0], [2.0, 1.0]], metric="l1")
    >>> inc.append(0.0)
    array([3., 3.])
    >>> inc.append(1.0)
    array([1., 2.])
    >>> inc.append(2.0)
    array([0., 3.])
    >>> inc.n_steps
    3
    """

    def __init__(
        self,
        references: Sequence[ArrayLike] | np.ndarray | PackedReferences,
        *,
        metric: Metric = "l2",
        y_window: int | None = None,
    ) -> None:
        self.metric: Metric = metric
        self._code = metric_code(metric)
        self.y_window = y_window
        self._y_window = window_size(y_window, "y_window")
        self.references = pack_references(references)
        self._rows = np.empty(self.references.data.shape[0])  # D[i, 1:] of every reference
        self._costs = np.empty(self.references.n_sequences)
        self._obs = np.empty((1, self.references.n_features))
        self.reset()

    @property
    def n_steps(self) -> int:
        """Number of query steps appended since construction or :meth:`reset`."""
        return self._n_steps

    @property
    def n_references(self) -> int:
        return self.references.n_sequences

    @property
    def costs(self) -> np.ndarray:
        """(K,) current costs, a copy; all inf before the first append (D[0, M] = inf)."""
        return self._costs.copy()

    def reset(self) -> None:
        """Forget the query: back to row 0 of every cost matrix."""
        self._rows.fill(np.inf)
        self._costs.fill(np.inf)
        self._n_steps = 0

    def append(self, observation: ArrayLike) -> np.ndarray:
        """Add one query step and return the updated costs.

        Args:
            observation: the new query step, (F,) (or a scalar / (1, F) when convenient).

        Returns:
            (K,) float64 costs of the query so far against every reference (a new array).

        Raises:
            ValueError: if the observation does not have F finite values.
        """
        obs = np.asarray(observation, dtype=np.float64)
        n_features = self.references.n_features
        if obs.size != n_features:
            raise ValueError(
                f"observation has shape {obs.shape} ({obs.size} values) but the references have "
                f"{n_features} feature(s); append one step of shape ({n_features},)."
            )
        self._obs[0] = obs.reshape(n_features)
        if not np.isfinite(self._obs).all():
            raise ValueError(
                f"observation {obs.tolist()} contains NaN or inf; DTW needs finite values. "
                "Nothing was appended."
            )
        _kernels.incremental_step(
            self._obs,
            self.references.data,
            self.references.offsets,
            self._rows,
            self._n_steps == 0,
            self._y_window,
            self._code,
            self._costs,
        )
        self._n_steps += 1
        return self._costs.copy()

    def extend(self, observations: ArrayLike) -> np.ndarray:
        """Append several steps, (T,) or (T, F), and return the costs after the last one.

        Raises:
            ValueError: as :meth:`append`, or if ``observations`` is empty.
        """
        steps = as_sequence(observations, "observations")
        n_features = self.references.n_features
        if steps.shape[1] != n_features:
            raise ValueError(
                f"observations has shape {steps.shape} but the references have {n_features} feature(s); "
                f"pass (T, {n_features}) steps."
            )
        costs = self.costs
        for step in steps:
            costs = self.append(step)
        return costs

    def __repr__(self) -> str:
        return (
            f"IncrementalDTW(n_references={self.n_references}, n_features={self.references.n_features}, "
            f"metric={self.metric!r}, y_window={self.y_window}, n_steps={self.n_steps})"
        )
