"""The Survey page's figure: :func:`plot_survey`, four bar charts of Table 3.4.

Used in: the Survey page of the book (thesis ch. 3).
"""

from __future__ import annotations

import pandas as pd

from thesis_lib.chapters.survey.tables import count_values

__all__ = ["plot_survey"]


def plot_survey(df: pd.DataFrame, *, top: int = 12):
    """Four bar charts: papers per year, per technique, per learned goal, per benchmark."""
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(2, 2, figsize=(12, 9))
    specs = [
        ("year", "Papers per year"),
        ("technique", "Per technique"),
        ("learned_goal", "Per learned goal"),
        ("benchmark", f"Per benchmark (top {top})"),
    ]
    for ax, (column, title) in zip(axes.flat, specs):
        counts = count_values(df, column, top=None if column == "year" else top)
        if column == "year":
            ax.bar(counts.index.astype(int), counts.values, color="tab:blue")
            ax.set_xlabel("year")
        else:
            counts.iloc[::-1].plot.barh(ax=ax, color="tab:blue")
            ax.set_ylabel("")
        ax.set_title(title)
        ax.set_xlabel("papers" if column != "year" else "year")
    fig.tight_layout()
    return fig
