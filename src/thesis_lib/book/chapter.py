"""What the book machinery needs of a chapter: the :class:`Chapter` contract.

A chapter is a package under :mod:`thesis_lib.chapters`, listed in its registry
(``thesis_lib.chapters.CHAPTERS``). The book's runner, its studies and its evidence pages never
import a chapter themselves (``book`` sits below ``chapters``): whoever calls them (the ``thesis``
command, a notebook, a test) passes the chapter's :class:`Chapter`, which loads the package
on first use. What the package provides:

- ``Config``: a dataclass whose defaults are the smoke scale, the one source of the notebook's
  parameters. Defined in the file ``config_file`` names, which the runner reads *without*
  importing the package (a chapter imports torch: seconds), so ``thesis run`` refuses a bad
  value at once;
- for a chapter with a pre-registered study: ``study_tasks(cfg) -> list[Task]``, and optionally
  ``STUDY_COLUMNS`` (the columns its rows have, which a study file's ``columns`` must name) and
  ``STUDY_FILE_DEFAULTS`` (fields added to ``Config`` after a study file was written, at the
  value that study ran with).

Example::

    from thesis_lib.chapters import CHAPTERS
    from thesis_lib.book import study

    hdt = CHAPTERS["04_hdt"]
    hdt.Config().seeds               # the smoke scale's seeds
    study.run_study(hdt, n_jobs=2)   # the chapter's pre-registered study
"""

from __future__ import annotations

import ast
import dataclasses
import functools
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from types import ModuleType
from typing import Any, Literal

from thesis_lib.book.params import config_hints
from thesis_lib.sweep import Task

__all__ = ["Chapter"]


@dataclass(frozen=True)
class Chapter:
    """One chapter of the book, as the book machinery sees it.

    Attributes:
        name: the notebook's name, e.g. ``04_hdt`` (``notebooks/04_hdt.ipynb``,
            ``params/04_hdt.*.yml``, ``results/04_hdt/``, ``studies/04_hdt/``).
        config_file: the source file that defines the chapter's ``Config``.
        load: imports the chapter's package and returns it (called once, on first use).
        smoke_s: about how many seconds its smoke run takes on the project's 2-core machine,
            two chapters at a time (a hint, measured, never asserted): when
            :func:`~thesis_lib.book.runner.run_chapters` runs several at once it starts the
            longest first, so that no long chapter is left to run alone at the end.
    """

    name: str
    config_file: Path
    load: Callable[[], ModuleType] = field(repr=False, compare=False)
    smoke_s: float = 0.0

    @functools.cached_property
    def package(self) -> ModuleType:
        """The chapter's package (imported on first use)."""
        return self.load()

    @property
    def _where(self) -> str:
        return getattr(self.package, "__name__", "its package")

    @property
    def Config(self) -> type:
        """The chapter's ``Config`` dataclass.

        Raises:
            ValueError: the package has no dataclass ``Config``.
        """
        cls = getattr(self.package, "Config", None)
        if not (isinstance(cls, type) and dataclasses.is_dataclass(cls)):
            raise ValueError(f"{self.name}: {self._where} has no dataclass Config")
        return cls

    @property
    def has_study(self) -> bool:
        """Whether the chapter defines ``study_tasks(cfg)``."""
        return callable(getattr(self.package, "study_tasks", None))

    def study_tasks(self, cfg: Any) -> list[Task]:
        """The chapter's study grid for ``cfg``.

        Raises:
            NotImplementedError: the chapter has no study.
        """
        if not self.has_study:
            raise NotImplementedError(f"{self._where} of {self.name} has no study_tasks(cfg) yet")
        return list(self.package.study_tasks(cfg))

    @property
    def study_columns(self) -> Sequence[str] | None:
        """The columns of the chapter's study rows, where it declares them."""
        return getattr(self.package, "STUDY_COLUMNS", None)

    @property
    def study_file_defaults(self) -> Mapping[str, Any]:
        """``Config`` fields added after a study file was written, at that study's value."""
        return getattr(self.package, "STUDY_FILE_DEFAULTS", {})

    def hints(self) -> dict[str, Any]:
        """The type hints of ``Config``'s fields, in field order, read from :attr:`config_file`
        (and the file of its base class, where it has one imported from ``thesis_lib``) without
        importing the package, where the annotations name only builtins and ``Literal``;
        otherwise from the imported ``Config``.

        Raises:
            ValueError: the file is missing or defines no class ``Config``.
        """
        if not self.config_file.is_file():
            raise ValueError(f"{self.name}: no file {self.config_file} (its Config)")
        tree = ast.parse(self.config_file.read_text())
        if _class_def(tree, "Config") is None:
            raise ValueError(f"{self.name}: {self.config_file} has no dataclass Config")
        read = _source_hints(tree, "Config")
        return read if read is not None else config_hints(self.Config)


def _class_def(tree: ast.Module, name: str) -> ast.ClassDef | None:
    return next((n for n in tree.body if isinstance(n, ast.ClassDef) and n.name == name), None)


def _source_hints(tree: ast.Module, name: str) -> dict[str, Any] | None:
    """The hints of the dataclass ``name``'s fields as its source (``tree``) writes them, its
    base's first (``dataclasses.fields``' order); ``None`` where that takes an import: a hint
    naming more than builtins and ``Literal``, more than one base, or a base not imported by
    name from a ``thesis_lib`` module."""
    import importlib.util

    node = _class_def(tree, name)
    if node is None or len(node.bases) > 1:
        return None
    hints: dict[str, Any] = {}
    for base in node.bases:
        if not isinstance(base, ast.Name):
            return None
        module = next(
            (
                imp.module
                for imp in tree.body
                if isinstance(imp, ast.ImportFrom)
                and imp.level == 0
                and any(a.name == base.id and a.asname is None for a in imp.names)
            ),
            None,
        )
        if module is None or not module.startswith("thesis_lib."):
            return None
        spec = importlib.util.find_spec(module)
        if spec is None or spec.origin is None:
            return None
        inherited = _source_hints(ast.parse(Path(spec.origin).read_text()), base.id)
        if inherited is None:
            return None
        hints.update(inherited)
    fields = [n for n in node.body if isinstance(n, ast.AnnAssign)]
    try:
        hints.update(
            {
                ast.unparse(f.target): eval(ast.unparse(f.annotation), {"Literal": Literal})
                for f in fields
            }
        )
    except NameError:
        return None
    return hints
