"""The book machinery: papermill runner, chapter parameters, results and paper comparison.

Used by every chapter notebook and by the ``thesis`` command line.
"""

from thesis_lib.book.compare import (
    DEVIATION_KINDS,
    compare_with_paper,
    load_reference,
    reference_tables,
)
from thesis_lib.book.params import config_from_namespace, validate_parameters
from thesis_lib.book.results import ChapterResults, run_metadata
from thesis_lib.book.runner import (
    ChapterFailed,
    ChapterRun,
    build_book,
    list_chapters,
    load_profile,
    notebook_parameters,
    resolve_chapter,
    run_chapter,
    run_chapters,
)
from thesis_lib.paths import project_root, results_dir

__all__ = [
    "DEVIATION_KINDS",
    "ChapterFailed",
    "ChapterResults",
    "ChapterRun",
    "build_book",
    "compare_with_paper",
    "config_from_namespace",
    "list_chapters",
    "load_profile",
    "load_reference",
    "notebook_parameters",
    "project_root",
    "reference_tables",
    "resolve_chapter",
    "results_dir",
    "run_chapter",
    "run_chapters",
    "run_metadata",
    "validate_parameters",
]
