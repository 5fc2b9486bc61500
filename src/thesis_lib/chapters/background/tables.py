"""The Background chapter's summaries of rows: :func:`summarize_rl`, the learning curves'
first, last and best returns.

Used in: Background chapter (thesis 2.5–2.7).
"""

from __future__ import annotations

import pandas as pd

__all__ = ["summarize_rl"]


def summarize_rl(episodes: pd.DataFrame, last: int = 5) -> pd.DataFrame:
    """First and last-``last``-episode mean returns per algorithm (mean over seeds)."""
    rows = []
    for (algo, seed), g in episodes.groupby(["algo", "seed"], sort=False):
        g = g.sort_values("episode")
        rows.append(
            {
                "algo": algo,
                "seed": seed,
                "episodes": len(g),
                "first_return": g["return"].iloc[0],
                f"mean_return_last_{last}": g["return"].tail(last).mean(),
                "best_return": g["return"].max(),
            }
        )
    per_seed = pd.DataFrame(rows)
    return (
        per_seed.groupby("algo", sort=False)
        .mean(numeric_only=True)
        .drop(columns="seed")
        .reset_index()
    )
