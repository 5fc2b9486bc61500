"""The Decision Mamba chapter (thesis 5.3; notebook ``05_decision_mamba``): Tables 5.5, 5.6, Figs 5.3-5.6.

* :mod:`~thesis_lib.chapters.decision_mamba.config`: :class:`Config`, the notebook's
  parameters (defaults are the smoke scale), and the sweeps' architectures (:func:`parse_arch`).
* :mod:`~thesis_lib.chapters.decision_mamba.tasks`: the experiments.
  :func:`run_parameter_counts`: the five models' sizes at the thesis's architecture;
  :func:`run_table_5_5`: every data set x seed x method at the chapter's architecture, each
  run the one offline runner (:func:`offline_task`: the HDT chapter's run, which both
  chapters' studies reduce to a row) as a resumable sweep (``results/05_decision_mamba/tasks``);
  RTG methods at the data set's max return, half of it and 10,000; :func:`run_sweeps`: the
  architectures of Figs 5.3, 5.5, 5.6 (reusing the Table 5.5 runs where the architecture is
  the same); :func:`run_table_5_6`: Table 5.6 (train ms/iteration, inference ms/step) plus the
  recurrent-step inference the thesis did not have, which :func:`timing_task` reduces to the
  study's C6 row; :func:`study_tasks`: ``thesis study 05_decision_mamba``.
* :mod:`~thesis_lib.chapters.decision_mamba.tables`: :func:`summarize_curves` (and
  :func:`summarize_study`, the study's rows): per method x data set x target x architecture x
  evaluation mode, the thesis's metric (best evaluation during training, mean +- std over
  seeds) and the final checkpoint's; :func:`summarize_eval_modes`; :func:`compare_table_5_5`,
  :func:`format_table_5_5`, :func:`compare_win_counts_5_5`: Table 5.5 beside the thesis's,
  and the "wins out of N settings" the thesis quotes (5.3.3); :func:`compare_table_5_6`,
  :func:`summarize_timing_ratios` (the ratios to DT), :func:`summarize_study_timing`.
* :mod:`~thesis_lib.chapters.decision_mamba.figures`: :func:`plot_sweep` (Figs 5.3, 5.5, 5.6)
  and :func:`plot_methods` (Fig 5.4).

Used in: Decision Mamba chapter (thesis 5.3; Tables 5.5, 5.6; Figs 5.3-5.6).
"""

from __future__ import annotations

from thesis_lib.chapters.decision_mamba.config import (
    CHAPTER,
    DM_METHODS,
    HIERARCHICAL,
    MAMBA_METHODS,
    RTG_METHODS,
    Arch,
    Config,
    parse_arch,
)
from thesis_lib.chapters.decision_mamba.figures import plot_methods, plot_sweep
from thesis_lib.chapters.decision_mamba.tables import (
    METRICS,
    TARGETS,
    THESIS_METHOD,
    WIN_COMPARISONS,
    compare_table_5_5,
    compare_table_5_6,
    compare_win_counts_5_5,
    format_table_5_5,
    summarize_curves,
    summarize_eval_modes,
    summarize_runs,
    summarize_study,
    summarize_study_timing,
    summarize_timing_ratios,
    thesis_labels_5_5,
)
from thesis_lib.chapters.decision_mamba.tasks import (
    CURVE_COLUMNS,
    STUDY_COLUMNS,
    STUDY_FILE_DEFAULTS,
    TIMING_FIELDS,
    load_datasets,
    offline_task,
    run_parameter_counts,
    run_sweeps,
    run_table_5_5,
    run_table_5_6,
    study_tasks,
    sweep_task,
    timing_task,
)

__all__ = [
    "CHAPTER",
    "CURVE_COLUMNS",
    "DM_METHODS",
    "HIERARCHICAL",
    "MAMBA_METHODS",
    "METRICS",
    "RTG_METHODS",
    "STUDY_COLUMNS",
    "STUDY_FILE_DEFAULTS",
    "TARGETS",
    "THESIS_METHOD",
    "TIMING_FIELDS",
    "WIN_COMPARISONS",
    "Arch",
    "Config",
    "compare_table_5_5",
    "compare_table_5_6",
    "compare_win_counts_5_5",
    "format_table_5_5",
    "load_datasets",
    "offline_task",
    "parse_arch",
    "plot_methods",
    "plot_sweep",
    "run_parameter_counts",
    "run_sweeps",
    "run_table_5_5",
    "run_table_5_6",
    "study_tasks",
    "summarize_curves",
    "summarize_eval_modes",
    "summarize_runs",
    "summarize_study",
    "summarize_study_timing",
    "summarize_timing_ratios",
    "sweep_task",
    "thesis_labels_5_5",
    "timing_task",
]
