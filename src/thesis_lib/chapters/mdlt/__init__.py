"""The MDLT chapter (thesis 6.5): its :class:`Config`, Tables 6.1-6.3 and figures.

* :func:`table_6_1` - the features used by music-to-dance methods (static, from the thesis).
* :func:`run_table_6_2` - AIST++: per genre, leave one music out (6 folds), and "All Genres"
  (fold ``i`` holds out the ``i``-th music of every genre), both variants plus the baselines.
* :func:`run_table_6_3` - PhantomDance: 10 folds by sorted index (26 of 260 songs each).
* :func:`summarize_folds` - mean and std over folds in the thesis's layout;
  :func:`compare_table_6_2` and :func:`compare_table_6_3` beside the thesis.

Each fold fits the feature scaler on its training songs only (``paper_compat=True``: on all
songs, validation included, as the authors' code did), trains each variant with
:class:`~thesis_lib.mdlt.train.MDLTTrainer`, translates every validation song autoregressively
and scores it (:mod:`thesis_lib.mdlt.metrics`). The thesis reports the best validation value
seen during training; we report the final model's (and the best over training as
``aje_best`` when ``eval_every`` > 0).

The folds run through :func:`thesis_lib.sweep.run_tasks`, one task per model x fold
(:func:`fold_task`; the baselines of a fold are one more task), stored under
``results/06_mdlt/tasks``; each task writes its checkpoint (under ``checkpoint_dir``, default
``results/06_mdlt/checkpoints``) and its predictions (``results/06_mdlt/predictions``), named by
the hash of its config, so an interrupted run resumes and no run resumes another's checkpoint.
Every fold, the C13 study's too (:func:`study_run`), runs the same task, :func:`fold_task`
(its step :func:`fold_method`).

The modules:

* :mod:`.config` - :class:`Config` (the notebook's parameters) and the shared constants;
* :mod:`.data` - the music-dance pairs, the folds, the data tables;
* :mod:`.tasks` - one method on one fold (:func:`fold_method`, :func:`fold_task`) and the
  tables' grids (``run_*``);
* :mod:`.study` - the pre-registered study (claim C13): :func:`study_tasks`, :func:`study_run`;
* :mod:`.tables` - summaries of rows (``summarize_*``) and comparisons with the thesis
  (``compare_*``);
* :mod:`.figures` - the plots and the arm animation;
* :mod:`.translator` - a translator for new music (``thesis mdlt train``) and its checks on
  recorded music.

Used in: MDLT chapter (thesis 6.5).
"""

from __future__ import annotations

from .config import (
    ALL_GENRES,
    ALL_SCOPE,
    CHAPTER,
    PER_GENRE,
    THESIS_MODEL,
    TRAIN_FIELDS,
    VARIANT_LABELS,
    Config,
    compat_config,
    probe_config,
)
from .data import (
    BEAT_COLUMN,
    THESIS_FOLDS,
    aist_folds,
    cached_sequences,
    data_args,
    data_sha,
    fingerprint_table,
    fit_scaler,
    fold_split,
    genre_label,
    load_datasets,
    load_sequences,
    phantomdance_folds,
    piece_fingerprint,
    run_dataset_table,
)
from .figures import animate_best, best_variant, plot_predictions
from .study import (
    METHOD_INDEX,
    PROBE_LABEL,
    STUDY_COLUMNS,
    TF_SUFFIX,
    gain_vs_mean_pose,
    neg_aje,
    study_label,
    study_run,
    study_songs,
    study_tasks,
)
from .tables import (
    compare_study_table_6_2,
    compare_study_table_6_3,
    compare_table_6_2,
    compare_table_6_3,
    describe_mean_pose,
    format_summary,
    scale_note,
    summarize_aje_vs_mean_pose,
    summarize_folds,
    summarize_study_mismatch,
    table_6_1,
)
from .tasks import (
    FoldResult,
    TableRun,
    checkpoint_path,
    example_checkpoint,
    fold_baselines,
    fold_method,
    fold_model,
    fold_task,
    fold_tasks,
    predictions_path,
    run_fold,
    run_mismatch,
    run_model_sizes,
    run_paper_compat,
    run_phantomdance_fps,
    run_probe,
    run_table_6_2,
    run_table_6_3,
    train_model,
)
from .translator import (
    beat_check,
    find_packaged_music,
    recorded_music_check,
    recorded_music_table,
    train_translator,
)

__all__ = [
    # config
    "ALL_GENRES",
    "ALL_SCOPE",
    "CHAPTER",
    "PER_GENRE",
    "THESIS_MODEL",
    "TRAIN_FIELDS",
    "VARIANT_LABELS",
    "Config",
    "compat_config",
    "probe_config",
    # data
    "BEAT_COLUMN",
    "THESIS_FOLDS",
    "aist_folds",
    "cached_sequences",
    "data_args",
    "data_sha",
    "fingerprint_table",
    "fit_scaler",
    "fold_split",
    "genre_label",
    "load_datasets",
    "load_sequences",
    "phantomdance_folds",
    "piece_fingerprint",
    "run_dataset_table",
    # tasks
    "FoldResult",
    "TableRun",
    "checkpoint_path",
    "example_checkpoint",
    "fold_baselines",
    "fold_method",
    "fold_model",
    "fold_task",
    "fold_tasks",
    "predictions_path",
    "run_fold",
    "run_mismatch",
    "run_model_sizes",
    "run_paper_compat",
    "run_phantomdance_fps",
    "run_probe",
    "run_table_6_2",
    "run_table_6_3",
    "train_model",
    # study
    "METHOD_INDEX",
    "PROBE_LABEL",
    "STUDY_COLUMNS",
    "TF_SUFFIX",
    "gain_vs_mean_pose",
    "neg_aje",
    "study_label",
    "study_run",
    "study_songs",
    "study_tasks",
    # tables
    "compare_study_table_6_2",
    "compare_study_table_6_3",
    "compare_table_6_2",
    "compare_table_6_3",
    "describe_mean_pose",
    "format_summary",
    "scale_note",
    "summarize_aje_vs_mean_pose",
    "summarize_folds",
    "summarize_study_mismatch",
    "table_6_1",
    # figures
    "animate_best",
    "best_variant",
    "plot_predictions",
    # translator
    "beat_check",
    "find_packaged_music",
    "recorded_music_check",
    "recorded_music_table",
    "train_translator",
]
