"""The survey of demonstration learning (thesis ch. 3, Table 3.4) as data.

Table 3.4 categorises 111 papers by technique, data, learned goal, inference, evaluation and
benchmark. Several cells hold more than one value (``"Policy Learning, IRL"``); the counting
helpers split them, so a paper counts once under each value it names. Tables
(:mod:`~thesis_lib.chapters.survey.tables`): :func:`load_survey` (the table itself),
:func:`summarize_counts` (papers per value of a column), :func:`duplicate_citations`; figure
(:mod:`~thesis_lib.chapters.survey.figures`): :func:`plot_survey`.

Used in: the Survey page of the book (thesis ch. 3).
"""

from __future__ import annotations

from thesis_lib.chapters.survey.config import Config
from thesis_lib.chapters.survey.figures import plot_survey
from thesis_lib.chapters.survey.tables import (
    COUNTED_COLUMNS,
    MULTI_VALUED,
    count_values,
    duplicate_citations,
    load_survey,
    split_values,
    summarize_counts,
)

__all__ = [
    "COUNTED_COLUMNS",
    "MULTI_VALUED",
    "Config",
    "count_values",
    "duplicate_citations",
    "load_survey",
    "plot_survey",
    "split_values",
    "summarize_counts",
]
