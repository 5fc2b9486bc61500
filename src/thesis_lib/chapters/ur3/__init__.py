"""The UR3 deployment chapter (thesis 5.2.5.4 and chapter 6; notebook ``07_ur3_deployment``).

* :mod:`~thesis_lib.chapters.ur3.config`: :class:`Config`, the notebook's parameters; defaults
  are the smoke scale.
* :mod:`~thesis_lib.chapters.ur3.tasks`: the experiments. :func:`run_demonstrations`: the
  reaching demonstrations' statistics. :func:`run_table_5_4`: HDT and DT trained with 10, 20,
  ..., 80 demonstrations by the one offline runner (:func:`thesis_lib.seq.runner.run_offline`),
  each run from the 10 test starts for 200 steps, as a resumable sweep
  (``results/07_ur3_deployment/tasks``) of :func:`reach_task`; one row per test start. The
  study (:func:`study_tasks`) runs the same task, each run reduced to one row
  (:func:`study_run`). :func:`dance_angles`: MDLT's dance for the arm.
* :mod:`~thesis_lib.chapters.ur3.tables`: :func:`summarize_reach` gives the thesis's "mean ±
  std of goal positions reached" from the notebook's rows, :func:`summarize_study` from the
  study's, :func:`compare_table_5_4` puts it beside the thesis's,
  :func:`summarize_success_curves` gives the mean number of goals reached after each step,
  :func:`summarize_dance_checks` the dance's limit checks.
* :mod:`~thesis_lib.chapters.ur3.figures`: ``plot_*``: Table 5.4, success curves, goals and a
  demonstration, sub-goals, the dance.

Used in: UR3 deployment chapter (Table 5.4, dance playback, 3-D viewer).
"""

from __future__ import annotations

from thesis_lib.chapters.ur3.config import CHAPTER, METHODS, N_DEMOS, N_GOALS, RTG_SCALE, Config
from thesis_lib.chapters.ur3.figures import (
    plot_dance,
    plot_demo_subgoals,
    plot_goals,
    plot_success_curves,
    plot_table_5_4,
)
from thesis_lib.chapters.ur3.tables import (
    compare_table_5_4,
    summarize_dance_checks,
    summarize_reach,
    summarize_study,
    summarize_success_curves,
)
from thesis_lib.chapters.ur3.tasks import (
    RUN_COLUMNS,
    STUDY_COLUMNS,
    STUDY_FILE_DEFAULTS,
    dance_angles,
    reach_config,
    reach_demos,
    reach_record,
    reach_task,
    run_demonstrations,
    run_reach,
    run_row,
    run_table_5_4,
    study_run,
    study_tasks,
)

__all__ = [
    "CHAPTER",
    "METHODS",
    "N_DEMOS",
    "N_GOALS",
    "RTG_SCALE",
    "RUN_COLUMNS",
    "STUDY_COLUMNS",
    "STUDY_FILE_DEFAULTS",
    "Config",
    "compare_table_5_4",
    "dance_angles",
    "plot_dance",
    "plot_demo_subgoals",
    "plot_goals",
    "plot_success_curves",
    "plot_table_5_4",
    "reach_config",
    "reach_demos",
    "reach_record",
    "reach_task",
    "run_demonstrations",
    "run_reach",
    "run_row",
    "run_table_5_4",
    "study_run",
    "study_tasks",
    "summarize_dance_checks",
    "summarize_reach",
    "summarize_study",
    "summarize_success_curves",
]
