"""Table 3.4 as data: the table itself (:func:`load_survey`), the papers per value of a column
(:func:`count_values`, :func:`summarize_counts`) and the citation numbers shared by two papers
(:func:`duplicate_citations`).

Used in: the Survey page of the book (thesis ch. 3).
"""

from __future__ import annotations

import pandas as pd

from thesis_lib.book import load_reference

__all__ = [
    "COUNTED_COLUMNS",
    "MULTI_VALUED",
    "count_values",
    "duplicate_citations",
    "load_survey",
    "split_values",
    "summarize_counts",
]

#: Columns of Table 3.4 whose cells may list several comma-separated values.
MULTI_VALUED = ("technique", "data", "learned_goal", "inference", "evaluation", "benchmark")

#: Columns whose value counts the Survey page saves as tables (``counts_<column>``).
COUNTED_COLUMNS = ("technique", "learned_goal", "inference", "evaluation")


def load_survey() -> pd.DataFrame:
    """Table 3.4 as printed (111 rows; spelling kept, see the reference README)."""
    return load_reference("3.4")


def split_values(cell: object) -> list[str]:
    """Split one multi-valued cell: ``'Policy Learning, IRL'`` → ``['Policy Learning', 'IRL']``.

    Empty parts (the trailing comma of one cell) are dropped; a missing cell gives ``[]``.

    >>> split_values("Regression Error, Succ. Rate,")
    ['Regression Error', 'Succ. Rate']
    """
    if not isinstance(cell, str):
        return []
    return [part.strip() for part in cell.split(",") if part.strip()]


def count_values(
    df: pd.DataFrame, column: str, *, top: int | None = None, case_insensitive: bool = True
) -> pd.Series:
    """How many papers name each value of ``column`` (multi-valued cells split).

    Args:
        df: Table 3.4 (:func:`load_survey`).
        column: one of the table's columns; ``"year"`` counts papers per year.
        top: keep the ``top`` most frequent values.
        case_insensitive: merge spellings that differ only in case (``Sensor data`` /
            ``Sensor Data``), keeping the most frequent spelling as the label.

    Raises:
        ValueError: unknown column (listing the valid ones).
    """
    if column not in df.columns:
        raise ValueError(f"Table 3.4 has no column '{column}'. Valid: {', '.join(df.columns)}.")
    if column == "year":
        return df["year"].value_counts().sort_index().rename("papers")
    values = df[column].map(split_values).explode().dropna()
    if case_insensitive:
        spelling = values.groupby(values.str.lower()).agg(lambda s: s.value_counts().index[0])
        values = values.str.lower().map(spelling)
    counts = values.value_counts().rename("papers")
    counts.index.name = column
    return counts.head(top) if top else counts


def duplicate_citations(df: pd.DataFrame) -> pd.DataFrame:
    """Rows whose citation number is shared with a different paper (an error in the printed table)."""
    dup = df[df.duplicated("ref", keep=False)]
    return dup.sort_values(["ref", "year"])[["ref", "name", "year"]].reset_index(drop=True)


def summarize_counts(survey: pd.DataFrame, column: str) -> pd.DataFrame:
    """Papers per value of ``column`` as a two-column table (``column``, ``papers``).

    Used in: the Survey page (thesis ch. 3), one table per :data:`COUNTED_COLUMNS`.
    """
    return count_values(survey, column).reset_index()
