"""The Background chapter (thesis ch. 2): its :class:`Config`, tables and figures.

Each function here is one step of ``notebooks/01_background.ipynb``: the notebook narrates and
calls; the computation lives in :mod:`thesis_lib.dtw`, :mod:`thesis_lib.seq` and
:mod:`thesis_lib.rl`, and the figures are drawn here so that tests can run them too.

* :mod:`~thesis_lib.chapters.background.config`: :class:`Config`, the notebook's parameters.
* :mod:`~thesis_lib.chapters.background.tasks`: the tables :func:`run_attention_check`,
  :func:`run_ssm_check`, :func:`run_dtw_vs_fastdtw`, :func:`run_rl_curves`,
  :func:`run_dt_tokens`, and the examples the figures draw.
* :mod:`~thesis_lib.chapters.background.tables`: :func:`summarize_rl`.
* :mod:`~thesis_lib.chapters.background.figures`: the ``plot_*`` functions.

Used in: Background chapter (thesis 2.2–2.8).
"""

from __future__ import annotations

from thesis_lib.chapters.background.config import RL_ALGOS, Config
from thesis_lib.chapters.background.figures import (
    plot_attention_masks,
    plot_attention_weights,
    plot_cost_matrix,
    plot_dtw_cost_matrices,
    plot_dtw_matching,
    plot_learning_curves,
    plot_matching,
    plot_positional_encoding,
    plot_ssm,
)
from thesis_lib.chapters.background.tables import summarize_rl
from thesis_lib.chapters.background.tasks import (
    attention_check,
    delayed_example,
    naive_distance,
    peak_on_path,
    run_attention_check,
    run_dt_tokens,
    run_dtw_vs_fastdtw,
    run_rl_curves,
    run_ssm_check,
    ssm_example,
)

__all__ = [
    "RL_ALGOS",
    "Config",
    "attention_check",
    "delayed_example",
    "naive_distance",
    "peak_on_path",
    "plot_attention_masks",
    "plot_attention_weights",
    "plot_cost_matrix",
    "plot_dtw_cost_matrices",
    "plot_dtw_matching",
    "plot_learning_curves",
    "plot_matching",
    "plot_positional_encoding",
    "plot_ssm",
    "run_attention_check",
    "run_dt_tokens",
    "run_dtw_vs_fastdtw",
    "run_rl_curves",
    "run_ssm_check",
    "ssm_example",
    "summarize_rl",
]
