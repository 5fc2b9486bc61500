"""DEFENDER: DTW-based episode filtering using demonstrations (thesis 4.3).

- :mod:`~thesis_lib.defender.methods` the 24 comparison methods and 576 strategies by name;
- :class:`GroupCost` / :func:`cost_curves` the trajectory's cost against a demonstration group,
  step by step (incremental exact DTW where the method allows);
- :class:`DynamicsModel` the next-state MLP that answers filtered steps;
- :class:`DefenderWrapper` the filter as a ``gymnasium.Wrapper`` (any RL library can use it);
- :func:`collect_demonstrations`, :func:`select_diverse`, :func:`save_demonstrations`,
  :func:`load_demonstrations` demonstrations as the authors made them;
- :mod:`~thesis_lib.defender.ablation` the offline strategy ablation (4.3.2);
- :mod:`~thesis_lib.defender.experiments` Tables 4.3-4.5 (4.3.3) for the chapter notebook.

Choices (each documented where it is made): exact DTW with L1 local cost over the whole episode
so far, and a tie fires the filter (Algorithm 2 steps only if Safe < Unsafe); ``paper_compat=True``
gives the authors' code (FastDTW radius 1, the last 20 steps, fire only on ">"). The dynamics
model is trained on every real step (Algorithm 2, line 11). Demonstrations are stored as one
``.npz`` with Minari's field names (:func:`save_demonstrations`).

Speed (``benchmarks/bench_defender.py``, Hopper-v5, 50 + 50 demonstrations, 2-core CPU): one
filter decision costs 17-35 µs with the thesis's top state strategies (Full/DemoW are incremental;
BothW10 about 75 µs), against 20-100 ms with FastDTW. Per SB3 SAC training step (256-256,
batch 256, one SAC model taking turns on each env, 1,600 steps each; plain SAC 15 ms) the DTW
filter alone added 2.5%, the whole wrapper 18% with the dynamics model trained every real step
(one more 256-256 network, 2.5 ms a step) and 6.6% with ``dynamics_kwargs={"train_every": 4}``;
FastDTW made a step 5.1 times as long. The thesis reports +19% to +3,245%.

Used in: DEFENDER chapter (thesis 4.3), ``notebooks/03_defender.ipynb``.

>>> from thesis_lib.defender import METHODS, STRATEGIES
>>> len(METHODS), len(STRATEGIES), METHODS[:3]
(24, 576, ('MinFull', 'MinSame', 'MinDemoW5'))
"""
from __future__ import annotations

from thesis_lib.defender.compare import BACKENDS, GroupCost, WindowedCosts, cost_curves
from thesis_lib.defender.demos import (
    TRAJECTORIES,
    DemoRun,
    EpisodeRecorder,
    DemoSet,
    Demonstration,
    as_demonstration,
    collect_demonstrations,
    load_demonstrations,
    rollout,
    save_demonstrations,
    select_diverse,
    trajectory_features,
)
from thesis_lib.defender.dynamics import DynamicsModel
from thesis_lib.defender.methods import (
    AGGREGATIONS,
    ALIASES,
    METHODS,
    STRATEGIES,
    WINDOWINGS,
    Method,
    Strategy,
    method_cost,
    parse_method,
    parse_strategy,
)
from thesis_lib.defender.wrapper import EPISODE_LOG_COLUMNS, PAPER_MAX_TRAJECTORY, DefenderWrapper

__all__ = [
    "AGGREGATIONS",
    "ALIASES",
    "BACKENDS",
    "EPISODE_LOG_COLUMNS",
    "METHODS",
    "PAPER_MAX_TRAJECTORY",
    "STRATEGIES",
    "TRAJECTORIES",
    "WINDOWINGS",
    "DefenderWrapper",
    "DemoRun",
    "EpisodeRecorder",
    "DemoSet",
    "Demonstration",
    "DynamicsModel",
    "GroupCost",
    "Method",
    "Strategy",
    "WindowedCosts",
    "as_demonstration",
    "collect_demonstrations",
    "cost_curves",
    "load_demonstrations",
    "method_cost",
    "parse_method",
    "parse_strategy",
    "rollout",
    "save_demonstrations",
    "select_diverse",
    "trajectory_features",
]
