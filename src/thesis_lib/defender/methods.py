"""DEFENDER's 24 comparison methods and 576 filtering strategies (thesis 4.3.2), by name.

A *method* compares the agent's trajectory with one group of demonstrations and returns one
number: a *windowing* says which part of the trajectory and of each demonstration DTW aligns,
an *aggregation* turns the K per-demonstration costs into one.

Windowings (query = the agent's trajectory, reference = one demonstration):

========  ===============================================  =======================
name      compares                                         ``dtw_batch`` arguments
========  ===============================================  =======================
Full      the whole trajectory with the whole demo         (none)
Same      the trajectory with the demo's last L steps,     ``y_window=L``
          L = the trajectory's length
DemoW     the trajectory with the demo's last W steps      ``y_window=W``
TrajW     the trajectory's last W steps with the demo      ``x_window=W``
BothW     the last W steps of both                         ``x_window=W, y_window=W``
========  ===============================================  =======================

with W in {5, 10}: 8 windowings x {Min, Max, Mean} = 24 methods, named aggregation first
(``"MeanDemoW5"``). A *strategy* is one method for the safe group and one for the unsafe group,
written ``"safe/unsafe"`` (``"MeanDemoW5/MeanDemoW10"``): 24 x 24 = 576.

Table 4.4 prints a method ``MinBoth`` (no window) that the text's list does not have; we read
it as ``MinSame`` ("an equal length window" on both sides) and accept ``Both`` as an alias of
``Same`` (:data:`ALIASES`).

Used in: DEFENDER (thesis 4.3).

>>> parse_method("MeanDemoW5")
Method(aggregation='Mean', windowing='Demo', window=5)
>>> parse_method("MeanDemoW5").name, len(METHODS), len(STRATEGIES)
('MeanDemoW5', 24, 576)
"""

from __future__ import annotations

import difflib
from collections.abc import Sequence
from typing import Literal, NamedTuple

import numpy as np
from numpy.typing import ArrayLike

from thesis_lib import dtw as _dtw

__all__ = [
    "AGGREGATIONS",
    "ALIASES",
    "METHODS",
    "STRATEGIES",
    "WINDOWINGS",
    "Method",
    "Strategy",
    "aggregate",
    "method_cost",
    "parse_method",
    "parse_strategy",
]

Aggregation = Literal["Min", "Max", "Mean"]
AGGREGATIONS: tuple[str, ...] = ("Min", "Max", "Mean")
"""How the K per-demonstration costs become one number."""

WINDOWINGS: tuple[str, ...] = (
    "Full",
    "Same",
    "DemoW5",
    "DemoW10",
    "TrajW5",
    "TrajW10",
    "BothW5",
    "BothW10",
)
"""The 8 windowings in the thesis's order (4.3.2)."""

ALIASES: dict[str, str] = {"Both": "Same"}
"""Windowing names printed in the thesis's tables but not in its list, and our reading of them."""


class Method(NamedTuple):
    """One of the 24 ways to compare a trajectory with a group of demonstrations."""

    aggregation: str
    """"Min", "Max" or "Mean" over the group's demonstrations."""
    windowing: str
    """"Full", "Same", "Demo", "Traj" or "Both"."""
    window: int | None
    """W for Demo/Traj/Both (5 or 10); None for Full and Same."""

    @property
    def name(self) -> str:
        """The thesis's name, e.g. ``"MeanDemoW5"``."""
        return f"{self.aggregation}{self.windowing}" + (f"W{self.window}" if self.window else "")

    @property
    def x_window(self) -> int | None:
        """Last steps of the trajectory to compare (None = all)."""
        return self.window if self.windowing in ("Traj", "Both") else None

    def y_window(self, query_length: int) -> int | None:
        """Last steps of each demonstration to compare, for a trajectory of ``query_length`` steps."""
        if self.windowing == "Same":
            return query_length
        return self.window if self.windowing in ("Demo", "Both") else None

    @property
    def incremental(self) -> bool:
        """True when an uncapped trajectory's cost can be updated in O(M) per step (Full, DemoW)."""
        return self.windowing in ("Full", "Demo")

    @property
    def windowing_name(self) -> str:
        """The windowing with its width, e.g. ``"DemoW5"`` (one of :data:`WINDOWINGS`)."""
        return self.windowing + (f"W{self.window}" if self.window else "")


METHODS: tuple[str, ...] = tuple(f"{agg}{win}" for agg in AGGREGATIONS for win in WINDOWINGS)
"""The 24 method names: Min*, then Max*, then Mean*, each in :data:`WINDOWINGS` order."""


def _unknown(kind: str, name: str, valid: Sequence[str]) -> ValueError:
    close = difflib.get_close_matches(str(name), valid, n=1, cutoff=0.5)
    hint = f" Did you mean: {close[0]!r}?" if close else ""
    return ValueError(f"Unknown DEFENDER {kind} {name!r}.{hint} Valid: {', '.join(valid)}.")


def parse_method(name: str | Method) -> Method:
    """Parse a method name such as ``"MeanDemoW5"`` (case-sensitive, as the thesis prints it).

    Raises:
        ValueError: for an unknown name, with the closest valid one and all 24.

    >>> parse_method("MinBoth").name  # Table 4.4's name, read as MinSame
    'MinSame'
    >>> parse_method("MeanDemoW7")
    Traceback (most recent call last):
    ...
    ValueError: Unknown DEFENDER method 'MeanDemoW7'. Did you mean: 'MeanDemoW5'? Valid: MinFull, MinSame, MinDemoW5, MinDemoW10, MinTrajW5, MinTrajW10, MinBothW5, MinBothW10, MaxFull, MaxSame, MaxDemoW5, MaxDemoW10, MaxTrajW5, MaxTrajW10, MaxBothW5, MaxBothW10, MeanFull, MeanSame, MeanDemoW5, MeanDemoW10, MeanTrajW5, MeanTrajW10, MeanBothW5, MeanBothW10.
    """
    if isinstance(name, Method):
        return name
    if not isinstance(name, str):
        raise _unknown("method", name, METHODS)
    for agg in AGGREGATIONS:
        if name.startswith(agg):
            rest = ALIASES.get(name[len(agg) :], name[len(agg) :])
            if rest in WINDOWINGS:
                if rest in ("Full", "Same"):
                    return Method(agg, rest, None)
                kind, width = rest.split("W")
                return Method(agg, kind, int(width))
    raise _unknown("method", name, METHODS)


class Strategy(NamedTuple):
    """A filtering strategy: one method for the safe group, one for the unsafe group."""

    safe: str
    """Method name used against the safe demonstrations."""
    unsafe: str
    """Method name used against the unsafe demonstrations."""

    @property
    def name(self) -> str:
        """``"safe/unsafe"``, e.g. ``"MeanDemoW5/MeanDemoW10"``."""
        return f"{self.safe}/{self.unsafe}"


STRATEGIES: tuple[Strategy, ...] = tuple(Strategy(s, u) for s in METHODS for u in METHODS)
"""All 576 strategies, safe method major."""


def parse_strategy(name: str | Strategy | tuple[str, str]) -> Strategy:
    """Parse ``"safe/unsafe"`` (or a pair) into a :class:`Strategy` of canonical method names.

    >>> parse_strategy("MeanDemoW5/MeanDemoW10")
    Strategy(safe='MeanDemoW5', unsafe='MeanDemoW10')
    """
    if isinstance(name, str):
        parts = name.split("/")
        if len(parts) != 2:
            raise ValueError(
                f"A DEFENDER strategy is written 'safe/unsafe', e.g. 'MeanDemoW5/MeanDemoW10', got {name!r}."
            )
    else:
        parts = list(name)
    return Strategy(parse_method(parts[0]).name, parse_method(parts[1]).name)


def aggregate(costs: np.ndarray, aggregation: str) -> float:
    """Min, Max or Mean of the per-demonstration costs.

    >>> aggregate(np.array([1.0, 2.0, 6.0]), "Mean")
    3.0
    """
    if aggregation == "Min":
        return float(np.min(costs))
    if aggregation == "Max":
        return float(np.max(costs))
    if aggregation == "Mean":
        return float(np.mean(costs))
    raise _unknown("aggregation", aggregation, AGGREGATIONS)


def method_cost(
    trajectory: ArrayLike,
    demos: Sequence[ArrayLike] | _dtw.PackedReferences,
    method: str | Method,
    *,
    metric: _dtw.Metric = "l1",
    max_trajectory: int | None = None,
) -> float:
    """Cost of a whole trajectory against a group of demonstrations with one method (no state).

    The direct computation: window both sides as the method says, one exact DTW per
    demonstration, then aggregate. :class:`~thesis_lib.defender.GroupCost` gives the same
    numbers one step at a time.

    Args:
        trajectory: (L, F) the agent's trajectory so far (states or state-actions).
        demos: K demonstrations, (M_k, F) each, or packed.
        method: a name of :data:`METHODS` or a :class:`Method`.
        metric: DTW local cost ("l1" as in the authors' code).
        max_trajectory: keep only the trajectory's last this-many steps first (the authors'
            code used 20); None keeps all.

    >>> method_cost([[0.0], [1.0]], [[[0.0], [1.0]], [[5.0], [0.0], [1.0]]], "MinFull")
    0.0
    """
    m = parse_method(method)
    x = np.asarray(trajectory, dtype=np.float64)
    if max_trajectory:
        x = x[-max_trajectory:]
    costs = _dtw.dtw_batch(
        x, demos, metric=metric, x_window=m.x_window, y_window=m.y_window(len(x))
    )
    return aggregate(costs, m.aggregation)


THESIS_STATE_STRATEGIES: tuple[str, ...] = (
    "MinDemoW5/MinDemoW10", "MeanBothW5/MeanBothW5", "MeanBothW10/MeanBothW10",
    "MeanDemoW5/MeanDemoW10", "MinDemoW10/MinDemoW10",
)  # fmt: skip
"""The thesis's top 5 for state trajectories, as printed in Table 4.3 (safe/unsafe)."""

THESIS_STATE_ACTION_STRATEGIES: tuple[str, ...] = (
    "MeanBothW5/MeanBothW5", "MeanBothW10/MeanBothW10", "MinTrajW5/MinTrajW10",
    "MinBoth/MinTrajW10", "MinBoth/MinTrajW5",
)  # fmt: skip
"""The thesis's top 5 for state-action trajectories, as printed in Table 4.4."""
