"""DEFENDER: DTW-based episode filtering using demonstrations (thesis 4.3).

- :mod:`~thesis_lib.defender.methods` the 24 comparison methods and 576 strategies by name;
- :class:`GroupCost` / :func:`cost_curves` the trajectory's cost against a demonstration group,
  step by step (incremental exact DTW where the method allows);
- :class:`DynamicsModel` the next-state MLP that answers filtered steps;
- :class:`DefenderWrapper` the filter as a ``gymnasium.Wrapper`` (any RL library can use it);
- :func:`collect_demonstrations`, :func:`select_diverse`, :func:`save_demonstrations`,
  :func:`load_demonstrations` demonstrations as the authors made them;
- :mod:`~thesis_lib.defender.ablation` the offline strategy ablation (4.3.2);
  :data:`THESIS_STATE_STRATEGIES` / :data:`THESIS_STATE_ACTION_STRATEGIES` the thesis's top 5.

Tables 4.3-4.5 (4.3.3) are the chapter's: :mod:`thesis_lib.chapters.defender`.

Choices (each documented where it is made): exact DTW with L1 local cost over the whole episode
so far, and a tie fires the filter (Algorithm 2 steps only if Safe < Unsafe); ``paper_compat=True``
gives the authors' code (FastDTW radius 1, the last 20 steps, fire only on ">", dynamics model
updated every step). By default the dynamics model is updated every 4th real step
(:data:`DYNAMICS_TRAIN_EVERY`; ``dynamics_train_every=1`` is Algorithm 2's line 11 to the letter):
a filtered step is terminal, so SB3's agents never bootstrap from its predicted next state.
Demonstrations: SAC roll-outs as the authors made them (:func:`collect_demonstrations`), or from
the shipped experts (:func:`expert_demonstrations`) where a short run gives too few of a group;
stored as one ``.npz`` with Minari's field names (:func:`save_demonstrations`) or as Minari data
sets (:func:`save_demonstrations_minari`).

Speed (``benchmarks/bench_defender.py``, Hopper-v5, 50 + 50 demonstrations, SB3 SAC 256-256,
batch 256, one model taking turns on each env variant). One filter decision costs 17-35 µs with
the thesis's top state strategies on an idle core (Full/DemoW are incremental; BothW10 about
75 µs), against 20-100 ms with FastDTW. Per SAC training step (plain: 15 ms), lightly loaded,
wall time: the DTW filter alone +2.5%, the default wrapper (dynamics every 4th step) +6.6%,
Algorithm 2 to the letter (dynamics every step) +18%, FastDTW x5.1. Re-measured with
``make bench`` on an idle 2-core machine (load 0.4; plain SAC step 14 ms): the default wrapper
+3.9% to +5.6% for each of the 5 top state strategies, the DTW filter alone -0.5% (noise),
Algorithm 2 +17%, FastDTW x5.0. Target: at most +10%; the thesis reports +19% to +3,245%.

Used in: DEFENDER chapter (thesis 4.3), ``notebooks/03_defender.ipynb``.

>>> from thesis_lib.defender import METHODS, STRATEGIES
>>> len(METHODS), len(STRATEGIES), METHODS[:3]
(24, 576, ('MinFull', 'MinSame', 'MinDemoW5'))
"""

from __future__ import annotations

from thesis_lib.defender.compare import BACKENDS, GroupCost, WindowedCosts, cost_curves
from thesis_lib.defender.demos import (
    TRAJECTORIES,
    Demonstration,
    DemoRun,
    DemoSet,
    EpisodeRecorder,
    as_demonstration,
    collect_demonstrations,
    expert_demonstrations,
    load_demonstrations,
    load_demonstrations_minari,
    policy_demonstrations,
    rollout,
    save_demonstrations,
    save_demonstrations_minari,
    select_diverse,
    shipped_expert_label,
    trajectory_features,
)
from thesis_lib.defender.dynamics import DynamicsModel
from thesis_lib.defender.methods import (
    AGGREGATIONS,
    ALIASES,
    METHODS,
    STRATEGIES,
    THESIS_STATE_ACTION_STRATEGIES,
    THESIS_STATE_STRATEGIES,
    WINDOWINGS,
    Method,
    Strategy,
    method_cost,
    parse_method,
    parse_strategy,
)
from thesis_lib.defender.wrapper import (
    DYNAMICS_TRAIN_EVERY,
    EPISODE_LOG_COLUMNS,
    PAPER_MAX_TRAJECTORY,
    DefenderWrapper,
    RandomFilter,
    TimerFilter,
)

__all__ = [
    "AGGREGATIONS",
    "ALIASES",
    "BACKENDS",
    "DYNAMICS_TRAIN_EVERY",
    "EPISODE_LOG_COLUMNS",
    "METHODS",
    "PAPER_MAX_TRAJECTORY",
    "STRATEGIES",
    "THESIS_STATE_ACTION_STRATEGIES",
    "THESIS_STATE_STRATEGIES",
    "TRAJECTORIES",
    "WINDOWINGS",
    "DefenderWrapper",
    "RandomFilter",
    "TimerFilter",
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
    "expert_demonstrations",
    "load_demonstrations",
    "load_demonstrations_minari",
    "method_cost",
    "parse_method",
    "parse_strategy",
    "policy_demonstrations",
    "rollout",
    "save_demonstrations",
    "save_demonstrations_minari",
    "select_diverse",
    "shipped_expert_label",
    "trajectory_features",
]
