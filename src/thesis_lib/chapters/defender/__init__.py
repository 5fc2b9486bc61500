"""The DEFENDER chapter (thesis 4.3.2-4.3.3): its :class:`Config`, experiments, tables and figures.

``notebooks/03_defender.ipynb`` calls these in order:

1. :func:`make_demonstrations` one SAC run per task; its roll-outs become the demonstrations and
   its training episodes the ablation's log. A group the short run gives too few roll-outs of is
   topped up from the shipped expert (``demo_source="auto"``); :func:`describe_demonstrations`
   says which recipe each task used.
2. :func:`run_ablation` the 576-strategy ablation for state and state-action trajectories.
3. :func:`run_tables_4_3_4_4` SAC and TD3 with and without DEFENDER; :func:`run_table_4_5`
   SAC with MeanDemoW5/MeanDemoW10 and 10/20/50 demonstrations.
4. :func:`summarize_runs` mean ± std over seeds, % Time; :func:`compare_tables_4_3_4_4` and
   :func:`compare_table_4_5` beside the thesis.

The ablation (one task per task x trajectory kind, :func:`ablation_task`) and the training runs
(one task per task x algorithm x strategy x seed, :func:`train_task`) run through
:func:`thesis_lib.sweep.run_tasks`, stored under ``results/03_defender/tasks``: an interrupted
chapter resumes, and a run that Tables 4.3-4.4 and 4.5 share is trained once. The tasks read
their demonstrations from content-addressed files under ``results/03_defender/demos``
(:func:`demos_file`), so a task's key changes when its demonstrations do.

The pre-registered study of claims C7-C9 (``params/03_defender.study.yml``, ``thesis study
03_defender``) runs :func:`study_tasks`: one :func:`study_run` per training run, trained by the
same :func:`train_task` as the tables and reduced to one row by :func:`study_row`
and a final evaluation without the filter. Its demonstrations are made once and kept beside
its rows (:func:`pinned_demonstrations`), because a later session on a new machine made other
ones for one task. The chapter's "Evidence at study scale" reads the rows back
(:func:`summarize_study`, :func:`plot_study_curves`, :func:`summarize_study_topup`,
:func:`summarize_study_demo_sources`).

Modules:

- :mod:`~thesis_lib.chapters.defender.config` :class:`Config` (read without importing the rest);
- :mod:`~thesis_lib.chapters.defender.demos` the environments and the demonstrations;
- :mod:`~thesis_lib.chapters.defender.tasks` the ablation and the training runs (Tables 4.3-4.5);
- :mod:`~thesis_lib.chapters.defender.study` the study's grid and its per-run row;
- :mod:`~thesis_lib.chapters.defender.lookahead` how far ahead of a crash the filter fires, for
  a checkpointed policy, beside a blind filter (``thesis defender lookahead``; exploratory);
- :mod:`~thesis_lib.chapters.defender.tables` summaries and comparisons with the thesis;
- :mod:`~thesis_lib.chapters.defender.figures` the plots.

Used in: DEFENDER chapter (thesis 4.3).
"""

from __future__ import annotations

from thesis_lib.chapters.defender.config import CHAPTER, DEMO_SOURCES, Config
from thesis_lib.chapters.defender.demos import (
    DEMO_FIELDS,
    collect_task_demonstrations,
    demonstrations_task,
    demos_file,
    demos_subset,
    episode_limit,
    load_demos_file,
    make_demonstrations,
    make_env,
    pinned_demonstrations,
    rl_overrides,
    save_demonstration_files,
    study_demonstrations,
    thesis_env_name,
    trim_pool,
)
from thesis_lib.chapters.defender.figures import (
    crash_curves,
    plot_ablation_heatmap,
    plot_curves,
    plot_curves_table_4_5,
    plot_study_curves,
)
from thesis_lib.chapters.defender.lookahead import (
    LOOKAHEAD_DIR,
    LOOKAHEAD_STEPS,
    filter_lookahead,
    lookahead_results,
    study_lookahead,
    summarize_lookahead,
)
from thesis_lib.chapters.defender.study import (
    CRASH_DEFINITION,
    DEMO_INFO,
    FILTER_STEP_COLUMNS,
    STUDY_COLUMNS,
    STUDY_CURVE_BINS,
    THESIS_SAC_RETURN,
    filter_step_numbers,
    matched_rate,
    matched_timing,
    study_label,
    study_row,
    study_run,
    study_task,
    study_tasks,
    training_run_numbers,
)
from thesis_lib.chapters.defender.tables import (
    STUDY_DATA_NOTE,
    STUDY_V2_DATA_NOTE,
    STUDY_V4_DATA_NOTE,
    STUDY_V5_DATA_NOTE,
    compare_table_4_5,
    compare_tables_4_3_4_4,
    compare_thesis_strategies,
    compare_top_strategies,
    describe_demonstrations,
    describe_effects,
    methods_table,
    scale_note,
    summarize_demonstrations,
    summarize_paper_compat_effect,
    summarize_runs,
    summarize_study,
    summarize_study_counterfactual,
    summarize_study_curves,
    summarize_study_demo_sources,
    summarize_study_topup,
    summarize_top_strategies,
)
from thesis_lib.chapters.defender.tasks import (
    EVAL_SEED,
    MATCHED_RANDOM_STRATEGY,
    MATCHED_TIMER_STRATEGY,
    RANDOM_STRATEGY,
    RUN_COLUMNS,
    TRAIN_FIELDS,
    TableRuns,
    TrainedRun,
    ablation_task,
    random_filter_rate,
    random_strategy,
    run_ablation,
    run_table_4_5,
    run_tables_4_3_4_4,
    runs_from_episodes,
    timer_filter_params,
    timer_strategy,
    train_run,
    train_task,
)
from thesis_lib.defender import THESIS_STATE_ACTION_STRATEGIES, THESIS_STATE_STRATEGIES

__all__ = [
    "CHAPTER",
    "CRASH_DEFINITION",
    "LOOKAHEAD_DIR",
    "LOOKAHEAD_STEPS",
    "DEMO_FIELDS",
    "DEMO_SOURCES",
    "DEMO_INFO",
    "EVAL_SEED",
    "MATCHED_RANDOM_STRATEGY",
    "MATCHED_TIMER_STRATEGY",
    "RANDOM_STRATEGY",
    "RUN_COLUMNS",
    "FILTER_STEP_COLUMNS",
    "STUDY_COLUMNS",
    "STUDY_CURVE_BINS",
    "STUDY_DATA_NOTE",
    "STUDY_V2_DATA_NOTE",
    "STUDY_V4_DATA_NOTE",
    "STUDY_V5_DATA_NOTE",
    "THESIS_SAC_RETURN",
    "THESIS_STATE_ACTION_STRATEGIES",
    "THESIS_STATE_STRATEGIES",
    "TRAIN_FIELDS",
    "Config",
    "TableRuns",
    "TrainedRun",
    "ablation_task",
    "collect_task_demonstrations",
    "compare_table_4_5",
    "compare_tables_4_3_4_4",
    "compare_thesis_strategies",
    "compare_top_strategies",
    "crash_curves",
    "demonstrations_task",
    "demos_file",
    "demos_subset",
    "describe_demonstrations",
    "describe_effects",
    "episode_limit",
    "filter_lookahead",
    "load_demos_file",
    "lookahead_results",
    "make_demonstrations",
    "make_env",
    "methods_table",
    "pinned_demonstrations",
    "trim_pool",
    "plot_ablation_heatmap",
    "plot_curves",
    "plot_curves_table_4_5",
    "plot_study_curves",
    "rl_overrides",
    "random_filter_rate",
    "random_strategy",
    "timer_filter_params",
    "timer_strategy",
    "run_ablation",
    "run_table_4_5",
    "run_tables_4_3_4_4",
    "runs_from_episodes",
    "save_demonstration_files",
    "scale_note",
    "study_demonstrations",
    "matched_rate",
    "matched_timing",
    "study_label",
    "study_lookahead",
    "study_row",
    "study_run",
    "study_task",
    "study_tasks",
    "summarize_demonstrations",
    "summarize_lookahead",
    "summarize_paper_compat_effect",
    "summarize_runs",
    "summarize_study",
    "summarize_study_counterfactual",
    "summarize_study_curves",
    "summarize_study_demo_sources",
    "summarize_study_topup",
    "summarize_top_strategies",
    "thesis_env_name",
    "train_run",
    "train_task",
    "filter_step_numbers",
    "training_run_numbers",
]
