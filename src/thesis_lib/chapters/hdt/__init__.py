"""The HDT chapter (thesis 5.2; notebook ``04_hdt``): Tables 5.1-5.3 and the sub-goal figures.

* :mod:`~thesis_lib.chapters.hdt.config`: :class:`Config`, every setting of the chapter, the
  notebook's parameters; defaults are the smoke scale (``params/04_hdt.smoke.yml``).
* :mod:`~thesis_lib.chapters.hdt.tasks`: the experiments. :func:`run_datasets`: the data sets
  and their statistics (``data.cards_table``); :func:`run_subgoal_stats`,
  :func:`run_maze_subgoal_stats`: what the sub-goal rule picks; :func:`offline_task`: one run
  (:func:`thesis_lib.seq.runner.run_offline`), which :func:`run_curves` (every data set x seed x
  method) and :func:`run_paper_compat` (the ``paper_compat=True`` variants) run as a resumable
  sweep (``results/04_hdt/tasks``), and :func:`study_run` reduces to the study's one row per
  run (:func:`study_tasks`: ``thesis study 04_hdt``).
* :mod:`~thesis_lib.chapters.hdt.tables`: :func:`summarize_curves` (and
  :func:`summarize_study`, the study's rows): both metrics per method x task x tier x target:
  the thesis's (``best_return``: the best evaluation average during training, mean +- std over
  seeds) and the honest one (``final_return_mean`` +- ``final_return_std``, the last
  evaluation); :func:`summarize_paper_compat`, :func:`summarize_seed_spread`;
  :func:`compare_table_5_1`, :func:`compare_table_5_2`, :func:`compare_table_5_3`,
  :func:`compare_win_counts_5_3`: our numbers beside the thesis's.
* :mod:`~thesis_lib.chapters.hdt.figures`: :func:`plot_subgoal_index`,
  :func:`plot_subgoal_weights`, :func:`plot_maze_subgoals`, :func:`plot_training_curves`.

Methods: ``BC``; ``DT`` (RTG, Tables 5.1, 5.3); ``DT-noRTG`` (Table 5.1); ``HDT`` (Tables
5.2, 5.3); ``HDT-RTG`` (Table 5.2).

Used in: HDT chapter (Tables 5.1-5.3, Figures of 5.2.2).
"""

from __future__ import annotations

from thesis_lib.chapters.hdt.config import CHAPTER, METHODS, Config, split_dataset
from thesis_lib.chapters.hdt.figures import (
    plot_maze_subgoals,
    plot_subgoal_index,
    plot_subgoal_weights,
    plot_training_curves,
)
from thesis_lib.chapters.hdt.tables import (
    METRIC_STD,
    METRICS,
    TARGET_ORDER,
    compare_table_5_1,
    compare_table_5_2,
    compare_table_5_3,
    compare_win_counts_5_3,
    summarize_curves,
    summarize_paper_compat,
    summarize_runs,
    summarize_seed_spread,
    summarize_study,
    thesis_labels,
)
from thesis_lib.chapters.hdt.tasks import (
    ARCH_FIELDS,
    CURVE_COLUMNS,
    STUDY_COLUMNS,
    STUDY_FILE_DEFAULTS,
    arch_fields,
    load_datasets,
    offline_rows,
    offline_task,
    run_curves,
    run_datasets,
    run_maze_subgoal_stats,
    run_paper_compat,
    run_subgoal_stats,
    run_sweep,
    study_run,
    study_task,
    study_tasks,
    sweep_tasks,
)

__all__ = [
    "ARCH_FIELDS",
    "CHAPTER",
    "CURVE_COLUMNS",
    "METHODS",
    "METRICS",
    "METRIC_STD",
    "STUDY_COLUMNS",
    "STUDY_FILE_DEFAULTS",
    "TARGET_ORDER",
    "Config",
    "arch_fields",
    "compare_table_5_1",
    "compare_table_5_2",
    "compare_table_5_3",
    "compare_win_counts_5_3",
    "load_datasets",
    "offline_rows",
    "offline_task",
    "plot_maze_subgoals",
    "plot_subgoal_index",
    "plot_subgoal_weights",
    "plot_training_curves",
    "run_curves",
    "run_datasets",
    "run_maze_subgoal_stats",
    "run_paper_compat",
    "run_subgoal_stats",
    "run_sweep",
    "split_dataset",
    "study_run",
    "study_task",
    "study_tasks",
    "summarize_curves",
    "summarize_paper_compat",
    "summarize_runs",
    "summarize_seed_spread",
    "summarize_study",
    "sweep_tasks",
    "thesis_labels",
]
