"""The Claims page: the thesis's fourteen claims, the evidence for each, and its verdict.

It renders ``studies/claims.csv``, which ``thesis claims`` writes from the committed studies
(:func:`thesis_lib.book.study.write_claims`); nothing is recomputed when the book is built.

* :mod:`~thesis_lib.chapters.claims.config`: :class:`Config`, the page's parameters.
* :mod:`~thesis_lib.chapters.claims.tables`: the ledger (:func:`load_claims`,
  :func:`ledger_table`, :func:`gates_table`, :func:`verdict_counts`) and the peer parity
  (:func:`load_parity`, :func:`parity_view`, :func:`no_peer_table`) and the scale ladder
  (:func:`load_ladder`, :func:`ladder_view`, :func:`ladder_choice`,
  :func:`load_ladder_curves`).
* :mod:`~thesis_lib.chapters.claims.figures`: :func:`plot_claims`, :func:`plot_ladder_curves`.
"""

from __future__ import annotations

from thesis_lib.chapters.claims.config import Config
from thesis_lib.chapters.claims.figures import plot_claims, plot_ladder_curves
from thesis_lib.chapters.claims.tables import (
    gates_table,
    headline,
    ladder_choice,
    ladder_view,
    ledger_table,
    link_chapters,
    load_claims,
    load_ladder,
    load_ladder_curves,
    load_parity,
    no_peer_table,
    parity_view,
    studies_table,
    verdict_counts,
)
from thesis_lib.stats.claims import VERDICT_COLOURS

__all__ = [
    "VERDICT_COLOURS",
    "Config",
    "gates_table",
    "headline",
    "ladder_choice",
    "ladder_view",
    "ledger_table",
    "link_chapters",
    "load_claims",
    "load_ladder",
    "load_ladder_curves",
    "load_parity",
    "no_peer_table",
    "parity_view",
    "plot_claims",
    "plot_ladder_curves",
    "studies_table",
    "verdict_counts",
]
