"""The CLfD chapter's experiments (thesis 4.2.2): Table 4.1, Table 4.2, Fig 4.4 and the paper_compat check.

Each function takes the chapter config (:class:`Config`, whose fields are the notebook's
parameters) and returns tidy DataFrames; the notebook only narrates and plots.

The encoder x method grid of Table 4.1 (and the paper_compat encoders, and the encoders of
Fig 4.4) runs through :func:`thesis_lib.sweep.run_tasks`: one task per trained encoder
(:func:`train_encoder_task`), its rows stored under ``results/02_clfd/tasks`` and its weights
under ``results/02_clfd/models``, so an interrupted chapter resumes and an encoder needed by
several tables is trained once.

The chapter's pre-registered study (``params/02_clfd.study.yml``, claims C10-C12) is built by
:func:`study_tasks` from the same functions: :func:`study_alignment_task` (Table 4.1),
:func:`study_stage_task` (Table 4.2) and :func:`study_rl_task` (Fig 4.4), one row per run.

The modules:

* :mod:`~thesis_lib.chapters.clfd.config`: :class:`Config` (read without importing the chapter);
* :mod:`~thesis_lib.chapters.clfd.data`: the data sets and their cameras;
* :mod:`~thesis_lib.chapters.clfd.encoders`: the encoder task and the stores that share encoders;
* :mod:`~thesis_lib.chapters.clfd.tasks`: the experiments and the study's grid and tasks;
* :mod:`~thesis_lib.chapters.clfd.tables`: summaries and comparisons with the thesis;
* :mod:`~thesis_lib.chapters.clfd.figures`: the plots.

Used in: chapter 02_clfd.
"""

from __future__ import annotations

from thesis_lib.chapters.clfd.config import CHAPTER, Config
from thesis_lib.chapters.clfd.data import (
    data_fingerprint,
    load_data,
    load_dataset,
    load_pouring,
    run_dataset_table,
    seen_unseen_cameras,
    stage_labels,
)
from thesis_lib.chapters.clfd.encoders import (
    AE_COLUMNS,
    TRAIN_FIELDS,
    alignment_numbers,
    build_model,
    chapter_encoder,
    encoder_task,
    file_sha,
    model_path,
    pinned_encoder,
    train_encoder_task,
    train_encoders,
    trained_encoder,
    trained_encoder_rows,
)
from thesis_lib.chapters.clfd.figures import (
    plot_embedding_pca,
    plot_example_frames,
    plot_rl_curves,
    plot_study_rl_curves,
    plot_training_curves,
)
from thesis_lib.chapters.clfd.tables import (
    RL_FINAL_COLUMNS,
    RL_FINAL_SHARE,
    compare_study_tables,
    compare_table_4_1,
    compare_table_4_2,
    describe_numbers,
    rl_final_numbers,
    summarize_rl_episodes,
    summarize_study_inputs,
    summarize_study_rl_curves,
)
from thesis_lib.chapters.clfd.tasks import (
    ORACLE,
    RL_FIELDS,
    STAGE_FIELDS,
    STAGE_PROTOCOLS,
    STUDY_COLUMNS,
    TABLE_4_2_VIEWPOINTS,
    UNTRAINED,
    alignment_error_examples,
    classify_stages,
    nt_xent_check,
    rl_episodes,
    rl_success_curve,
    run_fig_4_4,
    run_paper_compat,
    run_table_4_1,
    run_table_4_2,
    run_training_histories,
    stage_accuracy,
    stage_features,
    stage_protocols,
    study_alignment_control_task,
    study_alignment_task,
    study_rl_task,
    study_stage_task,
    study_tasks,
    table_4_1_tasks,
)
from thesis_lib.clfd.train import (
    ENCODER_LABELS,
    METHOD_LABELS,
    camera_pairs,
    mean_alignment_error,
)

__all__ = [
    # config
    "CHAPTER",
    "Config",
    # data
    "data_fingerprint",
    "load_data",
    "load_dataset",
    "load_pouring",
    "run_dataset_table",
    "seen_unseen_cameras",
    "stage_labels",
    # encoders
    "AE_COLUMNS",
    "TRAIN_FIELDS",
    "alignment_numbers",
    "build_model",
    "chapter_encoder",
    "encoder_task",
    "file_sha",
    "model_path",
    "pinned_encoder",
    "train_encoder_task",
    "train_encoders",
    "trained_encoder",
    "trained_encoder_rows",
    # experiments and the study
    "ORACLE",
    "RL_FIELDS",
    "RL_FINAL_COLUMNS",
    "RL_FINAL_SHARE",
    "STAGE_FIELDS",
    "STAGE_PROTOCOLS",
    "STUDY_COLUMNS",
    "TABLE_4_2_VIEWPOINTS",
    "UNTRAINED",
    "alignment_error_examples",
    "classify_stages",
    "nt_xent_check",
    "rl_episodes",
    "rl_success_curve",
    "run_fig_4_4",
    "run_paper_compat",
    "run_table_4_1",
    "run_table_4_2",
    "run_training_histories",
    "stage_accuracy",
    "stage_features",
    "stage_protocols",
    "study_alignment_control_task",
    "study_alignment_task",
    "study_rl_task",
    "study_stage_task",
    "study_tasks",
    "table_4_1_tasks",
    # tables
    "compare_study_tables",
    "compare_table_4_1",
    "compare_table_4_2",
    "describe_numbers",
    "rl_final_numbers",
    "summarize_rl_episodes",
    "summarize_study_inputs",
    "summarize_study_rl_curves",
    # figures
    "plot_embedding_pca",
    "plot_example_frames",
    "plot_rl_curves",
    "plot_study_rl_curves",
    "plot_training_curves",
    # from thesis_lib.clfd, for the notebook and tests
    "ENCODER_LABELS",
    "METHOD_LABELS",
    "camera_pairs",
    "mean_alignment_error",
]
