"""Imports in ``src/thesis_lib`` point one way: chapters -> methods -> (data, dtw, rl).

The layers (``thesis_lib.<top>``, the first name after ``thesis_lib``):

- **foundation** ``data``, ``dtw``, ``rl``: what every method builds on;
- **methods** the foundation plus ``seq``, ``defender``, ``clfd``, ``mdlt``, ``ur3``, and
  ``parity`` (the harness that trains ``seq``'s methods beside a peer library's);
- **services** ``book``, ``sweep``, ``stats``, ``_io``: shared machinery (paths, results, paper
  tables, the task engine, the evidence rules, atomic file writes) that any layer may use;
- **chapters** ``chapters`` (one module per notebook; the legacy ``background`` module counts as
  chapter code until it moves there);
- **entry points** ``thesis_lib.cli`` and every package's ``cli`` module (the ``thesis data``,
  ``thesis mdlt``, ``thesis ur3`` sub-commands): a command line may call any layer.

The rules, one test each (parametrised, so a failure names the rule):

1. ``methods-import-only-foundation``: a method package imports, from ``thesis_lib``, only itself,
   the foundation and the services; never another method package, a chapter or the CLI. (Lazy
   imports inside functions count too: direction is about dependency, not import time.) One
   edge between methods is allowed, listed in ``METHOD_EDGES`` with its reason: ``mdlt`` builds
   MDLT-T/MDLT-M from ``seq``'s blocks and trains them with ``seq``'s one trainer.
2. ``data-imports-no-seq``: ``thesis_lib.data`` imports nothing from ``thesis_lib.seq``.
3. ``only-cli-imports-chapters``: nothing in ``src`` imports ``thesis_lib.chapters`` (or the
   chapter module ``thesis_lib.background``) except the entry points, the chapters themselves,
   and ``thesis_lib.book`` *inside a function* (the runner and ``thesis params`` map a chapter
   name to its ``Config``; a lazy import keeps ``import thesis_lib.book`` free of every method).
   Notebooks import chapters too; they are not under ``src``.
4. ``services-import-no-methods-at-module-level``: ``book``, ``sweep``, ``stats`` and ``_io`` import no
   method package, chapter or the CLI at module level (inside a function is allowed: e.g. a
   service that renders a method's output on demand).

An import is ``import thesis_lib.x``, ``from thesis_lib.x import ...``, a relative import
resolved against the importing module, or ``importlib.import_module("thesis_lib.x...")`` with a
literal name. ``import`` statements under ``if TYPE_CHECKING:`` count as lazy; those under
``if __name__ == "__main__":`` (a module run as a script, e.g. ``python -m thesis_lib.cli.mdlt``
handing over to the top CLI) are entry points, not dependencies, and are skipped. The package root
``thesis_lib/__init__.py`` (which loads sub-packages on first attribute access) is exempt.
The rules hold for whatever modules exist: before ``chapters/`` exists rule 3 checks that nothing
imports it, after it exists the same code checks its importers.
"""

from __future__ import annotations

import ast
from dataclasses import dataclass
from pathlib import Path

import pytest

SRC = Path(__file__).resolve().parents[1] / "src"
PKG = "thesis_lib"

FOUNDATION = {"data", "dtw", "rl"}
METHODS = FOUNDATION | {"seq", "defender", "clfd", "mdlt", "ur3", "parity"}
SERVICES = {"book", "sweep", "stats", "_io", "paths", "provenance"}
CHAPTERS = {"chapters", "background"}
ENTRY = {"cli"}
# (importer, imported): edges between method packages that the design wants
METHOD_EDGES = {
    ("mdlt", "seq"),  # MDLT-T/MDLT-M are built from seq's blocks, trained by seq's one trainer
    ("parity", "seq"),  # the peer-parity harness trains seq's DT/BC against a peer library's
}


@dataclass(frozen=True)
class Import:
    source: str  # importing module, e.g. thesis_lib.seq.models
    target: str  # imported module or name, e.g. thesis_lib.data.sequence
    file: Path
    line: int
    lazy: bool  # inside a function or under `if TYPE_CHECKING:`

    @property
    def where(self) -> str:
        return f"{self.file.relative_to(SRC.parent)}:{self.line}"


def _module_name(path: Path, src: Path) -> tuple[str, bool]:
    parts = list(path.relative_to(src).with_suffix("").parts)
    is_pkg = parts[-1] == "__init__"
    if is_pkg:
        parts = parts[:-1]
    return ".".join(parts), is_pkg


def _resolve(module: str, is_pkg: bool, level: int, name: str | None) -> str:
    base = module.split(".")
    if not is_pkg:
        base = base[:-1]
    if level > 1:
        base = base[: len(base) - (level - 1)]
    return ".".join(base + ([name] if name else []))


def _is_main_guard(node: ast.If) -> bool:
    test = node.test
    return (
        isinstance(test, ast.Compare)
        and isinstance(test.left, ast.Name)
        and test.left.id == "__name__"
        and any(isinstance(c, ast.Constant) and c.value == "__main__" for c in test.comparators)
    )


def _is_type_checking(node: ast.If) -> bool:
    test = node.test
    return (isinstance(test, ast.Name) and test.id == "TYPE_CHECKING") or (
        isinstance(test, ast.Attribute) and test.attr == "TYPE_CHECKING"
    )


def _imports_of(path: Path, src: Path = SRC) -> list[Import]:
    module, is_pkg = _module_name(path, src)
    tree = ast.parse(path.read_text(), filename=str(path))
    found: list[Import] = []

    def visit(node: ast.AST, lazy: bool) -> None:
        for child in ast.iter_child_nodes(node):
            child_lazy = lazy or isinstance(
                child, ast.FunctionDef | ast.AsyncFunctionDef | ast.Lambda
            )
            if isinstance(child, ast.If) and _is_type_checking(child):
                child_lazy = True
            if isinstance(child, ast.If) and _is_main_guard(child):
                continue
            targets: list[str] = []
            if isinstance(child, ast.Import):
                targets = [a.name for a in child.names]
            elif isinstance(child, ast.ImportFrom):
                if child.level:
                    base = _resolve(module, is_pkg, child.level, child.module)
                else:
                    base = child.module or ""
                if base == PKG or child.module is None:
                    # `from thesis_lib import seq`, `from . import models`: the sub-modules
                    targets = [f"{base}.{a.name}" for a in child.names]
                else:
                    targets = [base]
            elif (
                isinstance(child, ast.Call)
                and isinstance(child.func, ast.Attribute | ast.Name)
                and getattr(child.func, "attr", getattr(child.func, "id", "")) == "import_module"
                and child.args
                and isinstance(child.args[0], ast.Constant)
                and isinstance(child.args[0].value, str)
            ):
                targets = [child.args[0].value]
            for target in targets:
                if target == PKG or target.startswith(PKG + "."):
                    found.append(Import(module, target, path, child.lineno, lazy))
            visit(child, child_lazy)

    visit(tree, False)
    return found


def _layer(name: str) -> str | None:
    """``thesis_lib.<top>...`` -> ``<top>``; any ``...cli`` module -> ``cli`` (an entry point)."""
    parts = name.split(".")
    if len(parts) < 2 or parts[0] != PKG:
        return None
    return "cli" if parts[-1] == "cli" else parts[1]


ALL_IMPORTS = [
    imp
    for path in sorted((SRC / PKG).rglob("*.py"))
    if path != SRC / PKG / "__init__.py"
    for imp in _imports_of(path)
]


def _violations(rule: str) -> list[str]:
    bad = []
    for imp in ALL_IMPORTS:
        src, dst = _layer(imp.source), _layer(imp.target)
        if dst is None or src == dst:
            continue
        if rule == "methods-import-only-foundation":
            broken = src in METHODS and dst not in FOUNDATION | SERVICES
            broken = broken and (src, dst) not in METHOD_EDGES
        elif rule == "data-imports-no-seq":
            broken = src == "data" and dst == "seq"
        elif rule == "only-cli-imports-chapters":
            broken = (
                dst in CHAPTERS and src not in ENTRY | CHAPTERS and not (src == "book" and imp.lazy)
            )
        elif rule == "services-import-no-methods-at-module-level":
            broken = src in SERVICES and not imp.lazy and dst in METHODS | CHAPTERS | ENTRY
        else:  # pragma: no cover
            raise ValueError(rule)
        if broken:
            bad.append(f"{imp.where}: {imp.source} imports {imp.target}")
    return bad


RULES = [
    "methods-import-only-foundation",
    "data-imports-no-seq",
    "only-cli-imports-chapters",
    "services-import-no-methods-at-module-level",
]


@pytest.mark.parametrize("rule", RULES)
def test_imports_point_down(rule):
    bad = _violations(rule)
    assert not bad, f"{rule}: {len(bad)} import(s) against the layering:\n" + "\n".join(bad)


def test_the_scanner_sees_every_kind_of_import(tmp_path):
    """The parser behind the rules: absolute, relative, `from pkg import sub`, lazy, importlib."""
    pkg = tmp_path / PKG / "seq"
    pkg.mkdir(parents=True)
    (tmp_path / PKG / "__init__.py").write_text("")
    (pkg / "__init__.py").write_text("from . import models\nfrom ..data import load\n")
    code = (
        "import importlib\n"
        "from typing import TYPE_CHECKING\n"
        "import thesis_lib.dtw.core\n"
        "from thesis_lib import ur3\n"
        "from .tokens import x\n"
        "if TYPE_CHECKING:\n"
        "    from thesis_lib.book import paths\n"
        "def f():\n"
        "    from thesis_lib.chapters import hdt\n"
        "    return importlib.import_module('thesis_lib.chapters.mdlt')\n"
        "if __name__ == '__main__':\n"
        "    from thesis_lib.cli import main\n"
    )
    (pkg / "models.py").write_text(code)
    got = {(i.source, i.target, i.line, i.lazy) for i in _imports_of(pkg / "models.py", tmp_path)}
    assert got == {
        ("thesis_lib.seq.models", "thesis_lib.dtw.core", 3, False),
        ("thesis_lib.seq.models", "thesis_lib.ur3", 4, False),
        ("thesis_lib.seq.models", "thesis_lib.seq.tokens", 5, False),
        ("thesis_lib.seq.models", "thesis_lib.book", 7, True),
        ("thesis_lib.seq.models", "thesis_lib.chapters", 9, True),
        ("thesis_lib.seq.models", "thesis_lib.chapters.mdlt", 10, True),
    }
    init = {(i.target, i.lazy) for i in _imports_of(pkg / "__init__.py", tmp_path)}
    assert init == {("thesis_lib.seq.models", False), ("thesis_lib.data", False)}
