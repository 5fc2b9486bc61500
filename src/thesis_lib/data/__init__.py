"""Demonstration data sets: made here by D4RL's recipe, stored in the Minari format.

>>> from thesis_lib import data
>>> ds = data.get_dataset("hopper", "medium")          # doctest: +SKIP
>>> ds = data.load("thesis/hopper/medium-v0")          # doctest: +SKIP
>>> ds = data.load("mujoco/hopper/medium-v0")          # a real Minari set  # doctest: +SKIP
>>> ds = data.open_dataset("D4RL/door/human-v2")       # either kind of name  # doctest: +SKIP
>>> seq = data.SequenceDataset(ds, K=20)               # doctest: +SKIP
>>> batch = seq.sample(64)                             # doctest: +SKIP

Used by HDT 5.2, Decision Mamba 5.3 (D4RL-recipe sets) and DEFENDER 4.3
(InvertedDoublePendulum demonstrations).
"""

from .card import (
    QUALITY_TARGETS,
    cards_table,
    check_environments,
    d4rl_comparison,
    data_card,
    expert_quality,
    format_card,
    maze_reference,
    maze_success_rate,
    plot_return_histograms,
    random_returns,
    record_maze_experts,
)
from .d4rl_reference import D4RLStats, d4rl_stats
from .deep_experts import (
    DEEP_EXPERT_CONFIGS,
    DeepExpertConfig,
    MLPPolicy,
    ship_deep_expert,
    train_deep_expert,
)
from .experts import LinearPolicy, load_policy, load_policy_record, train_experts
from .maze import FixedTarget, WaypointExpert, bfs_distances, fixed_target_maze
from .minari_sets import data_difference, dataset_key, is_minari_id, open_dataset
from .recipe import (
    DATASET_SIZES,
    action_noise_for,
    generate,
    get_dataset,
    make_env,
    make_episodes,
    rollout,
)
from .scores import normalized_score
from .sequence import SequenceBatch, SequenceDataset, returns_to_go
from .storage import (
    DamagedDatasetError,
    Episode,
    EpisodeFormatError,
    OfflineDataset,
    data_dir,
    list_datasets,
    load,
    minari_root,
    write_dataset,
)
from .tasks import TASKS, TaskSpec, gen_dataset_id, get_task, parse_dataset_id, size_namespace

__all__ = [
    "D4RLStats",
    "FixedTarget",
    "d4rl_comparison",
    "d4rl_stats",
    "fixed_target_maze",
    "size_namespace",
    "DEEP_EXPERT_CONFIGS",
    "DamagedDatasetError",
    "DeepExpertConfig",
    "Episode",
    "MLPPolicy",
    "ship_deep_expert",
    "train_deep_expert",
    "action_noise_for",
    "record_maze_experts",
    "EpisodeFormatError",
    "LinearPolicy",
    "OfflineDataset",
    "DATASET_SIZES",
    "QUALITY_TARGETS",
    "SequenceBatch",
    "SequenceDataset",
    "TASKS",
    "TaskSpec",
    "WaypointExpert",
    "bfs_distances",
    "cards_table",
    "check_environments",
    "data_card",
    "data_difference",
    "data_dir",
    "dataset_key",
    "expert_quality",
    "format_card",
    "gen_dataset_id",
    "generate",
    "get_dataset",
    "get_task",
    "is_minari_id",
    "list_datasets",
    "load",
    "load_policy",
    "load_policy_record",
    "make_env",
    "make_episodes",
    "maze_reference",
    "maze_success_rate",
    "minari_root",
    "normalized_score",
    "random_returns",
    "open_dataset",
    "parse_dataset_id",
    "returns_to_go",
    "rollout",
    "train_experts",
    "write_dataset",
]
