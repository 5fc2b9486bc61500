"""The book's chapters, one package per notebook, and their registry :data:`CHAPTERS`.

Each package holds its ``Config`` (defaults = the smoke scale), its experiments' task functions
(one per experiment, run by the notebook's smoke run and by the study alike), the tables beside
the thesis's numbers (through :func:`thesis_lib.book.compare_with_paper`) and the plots. The
notebooks, the ``thesis`` command and the tests import them; nothing below this floor does.
The book machinery (:mod:`thesis_lib.book`) receives a chapter as a
:class:`~thesis_lib.book.chapter.Chapter` from this registry.

A new chapter is one package here plus one line in :data:`CHAPTERS` (README, "Adding a
chapter, a method or a study").
"""

from __future__ import annotations

import importlib
from pathlib import Path

from thesis_lib.book.chapter import Chapter

__all__ = ["CHAPTERS", "get_chapter"]

_HERE = Path(__file__).resolve().parent


def _chapter(name: str, package: str, smoke_s: float) -> Chapter:
    folder = _HERE / package
    config = folder / "config.py"
    return Chapter(
        name=name,
        config_file=config if config.is_file() else folder / "__init__.py",
        # imported on first use: a chapter package imports torch (seconds), and `thesis run`
        # reads a Config's hints from its file first
        load=lambda: importlib.import_module(f"{__name__}.{package}"),
        smoke_s=smoke_s,
    )


#: Every chapter of the book, by its notebook's name, with how long its smoke run took
#: (seconds, ``make test``'s chapter runs on an idle 2-core machine, two at a time, 2026-12-02:
#: papermill's durations; the order in which ``thesis book -j 2`` starts them).
CHAPTERS: dict[str, Chapter] = {
    c.name: c
    for c in (
        _chapter("01_background", "background", 131),
        _chapter("survey", "survey", 6),
        _chapter("02_clfd", "clfd", 191),
        _chapter("03_defender", "defender", 392),
        _chapter("04_hdt", "hdt", 427),
        _chapter("05_decision_mamba", "decision_mamba", 143),
        _chapter("06_mdlt", "mdlt", 404),
        _chapter("07_ur3_deployment", "ur3", 94),
        _chapter("claims", "claims", 12),
    )
}


def get_chapter(name: str) -> Chapter:
    """The registered chapter ``name`` (e.g. ``04_hdt``).

    Raises:
        ValueError: no such chapter (the message lists them).
    """
    try:
        return CHAPTERS[name]
    except KeyError:
        raise ValueError(f"No chapter '{name}'. Known: {', '.join(CHAPTERS)}.") from None
