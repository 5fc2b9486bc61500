"""The import graph of ``src/thesis_lib`` has floors, and imports only go down (issue #38).

The floors, top to bottom (a module's floor is its top-level package under ``thesis_lib``):

====  =========================================================================
5     ``cli``: ``thesis_lib.cli`` and its sub-commands (``thesis data``, ``thesis mdlt``, ...)
4     ``chapters``: one module per notebook
3     ``book`` (running notebooks, studies, params), ``parity`` (our DT/BC beside a peer's)
      and ``ladder`` (the sequence models' scale ladder)
2     the methods: ``seq``, ``defender``, ``clfd``, ``mdlt``, ``ur3``
1     the base: ``data``, ``sweep``, ``stats``, ``rl``, ``dtw``
0     the ground: ``_io``, ``paths``, ``provenance`` and the root ``thesis_lib/__init__.py``
====  =========================================================================

The rules, one test each:

(a) every import goes to the same or a lower floor;
(b) no cycle among the top-level packages;
(c) no cycle among the modules. A package's ``__init__`` importing its own sub-modules (to
    re-export their names) is not a cycle, so those edges are left out -- unless one of the
    package's own sub-modules imports a *name* from that ``__init__`` while the ``__init__``
    (directly or not) imports the sub-module: that is a real cycle through a re-export and is
    reported. ``from . import sibling`` is an edge to the sibling module, not to ``__init__``;
    only a name that is not a module makes an edge to the package itself;
(d) in the packages cleaned for #38 (``CLEANED``) no module imports another ``thesis_lib``
    module inside a function, unless the import carries a reason as a trailing comment
    (``# lazy: torch``, ``# cycle: ...``): imports belong at the top, where they show the
    module's dependencies. ``cli`` is the exception, for one reason said once
    (``LAZY_PACKAGES``): a command loads only what it runs.

An import is any ``import`` / ``from ... import`` statement anywhere in a file (module level,
class bodies, functions), or ``importlib.import_module("thesis_lib....")`` with a literal name.
Relative imports are resolved against the importing module, and ``from pkg import name`` is an
edge to ``pkg.name`` when that is a module or package, else to ``pkg``. Imports under
``if TYPE_CHECKING:`` are skipped (they never run), and so are those under
``if __name__ == "__main__":`` (a module run as a script hands over to its entry point; that is
not a dependency of the module).
"""

from __future__ import annotations

import ast
import re
from collections import defaultdict
from dataclasses import dataclass
from pathlib import Path

SRC = Path(__file__).resolve().parents[1] / "src"
PKG = "thesis_lib"

FLOORS: dict[str, int] = {
    "cli": 5,
    "chapters": 4,
    "book": 3,
    "parity": 3,
    "ladder": 3,
    "seq": 2,
    "defender": 2,
    "clfd": 2,
    "mdlt": 2,
    "ur3": 2,
    "data": 1,
    "sweep": 1,
    "stats": 1,
    "rl": 1,
    "dtw": 1,
    "_io": 0,
    "paths": 0,
    "provenance": 0,
    "": 0,  # the root thesis_lib/__init__.py
}

# (importer, imported) module edges that go up a floor today. #38: being removed.
# Only chapters, book and cli modules may be listed; the test fails when a listed edge is gone,
# so this set only shrinks.
KNOWN_UPWARD: set[tuple[str, str]] = set()

# Top-level packages whose function-level imports of thesis_lib modules were moved to the top
# (#38); a lazy one that stays carries its reason as a trailing comment. The ``cli`` package is
# not one of them.
CLEANED = {
    "seq",
    "data",
    "defender",
    "clfd",
    "mdlt",
    "ur3",
    "rl",
    "dtw",
    "sweep",
    "stats",
    "parity",
    "ladder",
    "_io",
    "paths",
    "provenance",
    "book",
    "chapters",
}
#: Packages whose function-level imports all share one reason, said here once.
LAZY_PACKAGES = {
    # a command imports only what it runs: `thesis run` with a bad value fails in under a second
    # (issue #37), before torch, MuJoCo or a chapter's package loads
    "cli": "start-up",
}
REASON = re.compile(r"#\s*[A-Za-z][\w-]*:\s*\S")  # `# lazy: torch`, `# cycle: data.recipe`


# --- the graph ------------------------------------------------------------------------------


@dataclass(frozen=True)
class Edge:
    source: str  # importing module, e.g. thesis_lib.seq.runner
    target: str  # imported module (a file under src), e.g. thesis_lib.data.sequence
    line: int
    lazy: bool  # inside a function
    names_module: bool  # `from pkg import sub` / `import pkg.sub`: the target is named as a module
    reason: str | None  # the trailing `# why: ...` comment on the import, if any

    @property
    def where(self) -> str:
        return f"{module_file(self.source).relative_to(SRC.parent)}:{self.line}"


def module_name(path: Path, src: Path = SRC) -> str:
    parts = list(path.relative_to(src).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts = parts[:-1]
    return ".".join(parts)


def all_modules(src: Path = SRC) -> dict[str, Path]:
    return {module_name(p, src): p for p in sorted((src / PKG).rglob("*.py"))}


MODULES = all_modules()


def module_file(name: str) -> Path:
    return MODULES[name]


def _is_pkg(path: Path) -> bool:
    return path.name == "__init__.py"


def _existing(name: str, modules: dict[str, Path]) -> str:
    """The longest prefix of ``name`` that is a module (``a.b.Name`` -> ``a.b``)."""
    parts = name.split(".")
    while parts and ".".join(parts) not in modules:
        parts.pop()
    return ".".join(parts)


def _if_kind(node: ast.If) -> str | None:
    test = node.test
    if (isinstance(test, ast.Name) and test.id == "TYPE_CHECKING") or (
        isinstance(test, ast.Attribute) and test.attr == "TYPE_CHECKING"
    ):
        return "type_checking"
    if (
        isinstance(test, ast.Compare)
        and isinstance(test.left, ast.Name)
        and test.left.id == "__name__"
        and any(isinstance(c, ast.Constant) and c.value == "__main__" for c in test.comparators)
    ):
        return "main"
    return None


def edges_of(path: Path, modules: dict[str, Path], src: Path = SRC) -> list[Edge]:
    """Every import of a ``thesis_lib`` module in ``path``, resolved to a module of ``modules``."""
    source = module_name(path, src)
    text = path.read_text()
    lines = text.splitlines()
    tree = ast.parse(text, filename=str(path))
    package = source if _is_pkg(path) else source.rpartition(".")[0]
    found: list[Edge] = []

    def reason(node: ast.stmt | ast.expr) -> str | None:
        span = lines[node.lineno - 1 : (node.end_lineno or node.lineno)]
        for line in span:
            m = REASON.search(line)
            if m:
                return line[m.start() :].lstrip("# ").strip()
        return None

    def add(target: str, node: ast.AST, lazy: bool, names_module: bool) -> None:
        if target != PKG and not target.startswith(PKG + "."):
            return
        resolved = _existing(target, modules)
        if not resolved:
            return
        found.append(
            Edge(
                source,
                resolved,
                node.lineno,  # type: ignore[attr-defined]
                lazy,
                names_module and resolved == target,
                reason(node),  # type: ignore[arg-type]
            )
        )

    def visit(node: ast.AST, lazy: bool) -> None:
        for child in ast.iter_child_nodes(node):
            if isinstance(child, ast.If) and _if_kind(child):
                # skip the guarded body; its `else:` (if any) runs
                for stmt in child.orelse:
                    visit(ast.Module(body=[stmt], type_ignores=[]), lazy)
                continue
            child_lazy = lazy or isinstance(
                child, ast.FunctionDef | ast.AsyncFunctionDef | ast.Lambda
            )
            if isinstance(child, ast.Import):
                for alias in child.names:
                    add(alias.name, child, lazy, True)
            elif isinstance(child, ast.ImportFrom):
                if child.level:
                    base = package.split(".")
                    base = base[: len(base) - (child.level - 1)]
                    base_name = ".".join(base + ([child.module] if child.module else []))
                else:
                    base_name = child.module or ""
                for alias in child.names:
                    sub = f"{base_name}.{alias.name}"
                    if sub in modules:
                        add(sub, child, lazy, True)
                    else:
                        add(base_name, child, lazy, False)
            elif (
                isinstance(child, ast.Call)
                and getattr(child.func, "attr", getattr(child.func, "id", None)) == "import_module"
                and child.args
                and isinstance(child.args[0], ast.Constant)
                and isinstance(child.args[0].value, str)
            ):
                add(child.args[0].value, child, lazy, True)
            visit(child, child_lazy)

    visit(tree, False)
    return list(dict.fromkeys(found))  # one edge per (statement, target)


def build_graph(src: Path = SRC) -> list[Edge]:
    modules = all_modules(src)
    return [e for path in modules.values() for e in edges_of(path, modules, src)]


EDGES = build_graph()


def top(module: str) -> str:
    """``thesis_lib.data.experts`` -> ``data``; the root ``thesis_lib`` -> ``""``."""
    parts = module.split(".")
    return parts[1] if len(parts) > 1 else ""


def floor(module: str) -> int:
    return FLOORS[top(module)]


def is_within(module: str, package: str) -> bool:
    return module.startswith(package + ".")


def _cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components of more than one node (Tarjan), each sorted."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    out: list[list[str]] = []
    counter = 0

    def strong(v: str) -> None:
        nonlocal counter
        index[v] = low[v] = counter
        counter += 1
        stack.append(v)
        on_stack.add(v)
        for w in sorted(graph.get(v, ())):
            if w not in index:
                strong(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                out.append(sorted(comp))

    for v in sorted(graph):
        if v not in index:
            strong(v)
    return out


def _reaches(graph: dict[str, set[str]], start: str, goal: str) -> list[str] | None:
    """A path start -> ... -> goal in ``graph`` (breadth first), or None."""
    parent: dict[str, str | None] = {start: None}
    queue = [start]
    while queue:
        v = queue.pop(0)
        if v == goal:
            path = [v]
            while parent[path[-1]] is not None:
                path.append(parent[path[-1]])  # type: ignore[arg-type]
            return path[::-1]
        for w in sorted(graph.get(v, ())):
            if w not in parent:
                parent[w] = v
                queue.append(w)
    return None


def module_graph(edges: list[Edge], *, drop_reexports: bool) -> dict[str, set[str]]:
    graph: dict[str, set[str]] = defaultdict(set)
    for e in edges:
        if e.source == e.target:
            continue
        if drop_reexports and is_within(e.target, e.source):
            continue  # a package's __init__ importing its own sub-module
        graph[e.source].add(e.target)
    return graph


def upward(edges: list[Edge]) -> dict[tuple[str, str], list[Edge]]:
    bad: dict[tuple[str, str], list[Edge]] = defaultdict(list)
    for e in edges:
        if floor(e.target) > floor(e.source):
            bad[(e.source, e.target)].append(e)
    return bad


def function_level_imports(edges: list[Edge]) -> dict[str, list[Edge]]:
    """Per file, its imports of thesis_lib modules made inside a function."""
    per_file: dict[str, list[Edge]] = defaultdict(list)
    for e in edges:
        if e.lazy:
            per_file[e.source].append(e)
    return per_file


# --- the tests ------------------------------------------------------------------------------


def test_the_graph_sees_known_edges():
    """A few edges that exist in the code, to check the scanner on the real tree."""
    got = {(e.source, e.target) for e in EDGES}
    assert any(s == "thesis_lib.seq.runner" and is_within(t, "thesis_lib.data") for s, t in got)
    # `from thesis_lib import dtw` style and relative imports resolve to the sub-module
    assert ("thesis_lib.data", "thesis_lib.data.storage") in got
    assert ("thesis_lib.seq.dm", "thesis_lib.seq.models") in got
    assert all(t in MODULES for _, t in got)
    assert set(FLOORS) == {top(m) for m in MODULES}, "every top-level package has a floor"


def test_the_scanner_resolves_every_kind_of_import(tmp_path):
    pkg = tmp_path / PKG / "seq"
    pkg.mkdir(parents=True)
    (tmp_path / PKG / "dtw").mkdir()
    (tmp_path / PKG / "__init__.py").write_text("")
    (tmp_path / PKG / "dtw" / "__init__.py").write_text("")
    (tmp_path / PKG / "dtw" / "core.py").write_text("")
    (tmp_path / PKG / "book.py").write_text("")
    (tmp_path / PKG / "chapters.py").write_text("")
    (pkg / "__init__.py").write_text("from . import models\nfrom .tokens import Tok\n")
    (pkg / "tokens.py").write_text("")
    code = (
        "import importlib\n"
        "from typing import TYPE_CHECKING\n"
        "import thesis_lib.dtw.core\n"
        "from thesis_lib import dtw, __version__\n"
        "from .tokens import x\n"
        "from . import tokens, helper\n"
        "from ..dtw.core import dtw as d\n"
        "if TYPE_CHECKING:\n"
        "    from thesis_lib.book import paths\n"
        "def f():\n"
        "    from thesis_lib.chapters import hdt  # lazy: heavy\n"
        "    return importlib.import_module('thesis_lib.dtw.core')\n"
        "if __name__ == '__main__':\n"
        "    from thesis_lib.cli import main\n"
    )
    (pkg / "models.py").write_text(code)
    modules = all_modules(tmp_path)
    got = {
        (e.target, e.line, e.lazy, e.reason) for e in edges_of(pkg / "models.py", modules, tmp_path)
    }
    assert got == {
        ("thesis_lib.dtw.core", 3, False, None),
        ("thesis_lib.dtw", 4, False, None),
        ("thesis_lib", 4, False, None),
        ("thesis_lib.seq.tokens", 5, False, None),
        ("thesis_lib.seq.tokens", 6, False, None),
        ("thesis_lib.seq", 6, False, None),  # `helper` is no module: a name from __init__
        ("thesis_lib.dtw.core", 7, False, None),
        ("thesis_lib.chapters", 11, True, "lazy: heavy"),
        ("thesis_lib.dtw.core", 12, True, None),
    }
    init = {(e.source, e.target) for e in edges_of(pkg / "__init__.py", modules, tmp_path)}
    assert init == {
        ("thesis_lib.seq", "thesis_lib.seq.models"),
        ("thesis_lib.seq", "thesis_lib.seq.tokens"),
    }


def test_imports_go_down_the_floors():
    bad = upward(EDGES)
    new = {k: v for k, v in bad.items() if k not in KNOWN_UPWARD}
    gone = sorted(KNOWN_UPWARD - set(bad))
    assert not new, f"{len(new)} import(s) go up a floor:\n" + "\n".join(
        f"  {a} -> {b} (floor {floor(a)} -> floor {floor(b)}) at {', '.join(e.where for e in es)}"
        for (a, b), es in sorted(new.items())
    )
    assert not gone, (
        "these KNOWN_UPWARD imports no longer exist; remove them from the list:\n"
        + "\n".join(f"  {a} -> {b}" for a, b in gone)
    )
    assert all(top(a) in {"chapters", "book", "cli"} for a, _ in KNOWN_UPWARD)


def test_no_cycles_between_top_level_packages():
    graph: dict[str, set[str]] = defaultdict(set)
    for e in EDGES:
        a, b = top(e.source), top(e.target)
        if a != b:
            graph[a].add(b)
    cycles = _cycles(graph)
    assert not cycles, "import cycles between top-level packages:\n" + "\n".join(
        "  " + " <-> ".join(c or "thesis_lib" for c in comp) for comp in cycles
    )


def test_no_cycles_between_modules():
    graph = module_graph(EDGES, drop_reexports=True)
    problems = ["  " + " <-> ".join(comp) for comp in _cycles(graph)]
    # a sub-module importing a name from its own package's __init__, which imports it back
    full = module_graph(EDGES, drop_reexports=False)
    for e in EDGES:
        if is_within(e.source, e.target) and not e.names_module:
            back = _reaches(full, e.target, e.source)
            if back:
                problems.append(
                    f"  {e.source} imports a name from {e.target} ({e.where}), which imports it: "
                    + " -> ".join(back)
                )
    assert not problems, "import cycles between modules:\n" + "\n".join(problems)


def test_no_function_level_imports_of_our_own_modules_without_a_reason():
    lazy = function_level_imports(EDGES)
    bad = [
        f"  {e.where}: {e.source} imports {e.target} inside a function"
        for module, es in sorted(lazy.items())
        if top(module) in CLEANED and top(module) not in LAZY_PACKAGES
        for e in es
        if e.reason is None
    ]
    assert not bad, (
        "move these imports to the top of the module, or give the reason as a trailing comment "
        "(`# lazy: torch`, `# cycle: ...`):\n" + "\n".join(bad)
    )


#: (importer, imported) method packages that build on another method, with the reason; any
#: other import between two packages of the methods' floor is refused: each method stands on
#: the base alone, so it can be read, tested and replaced on its own.
METHOD_EDGES = {
    ("mdlt", "seq"),  # MDLT-T/MDLT-M are built from seq's blocks, trained by seq's one trainer
}


def test_methods_build_on_the_base_not_on_each_other():
    methods = {p for p, f in FLOORS.items() if f == 2}
    bad = sorted(
        f"  {e.source} -> {e.target} at {e.where}"
        for e in EDGES
        if top(e.source) in methods
        and top(e.target) in methods
        and top(e.source) != top(e.target)
        and (top(e.source), top(e.target)) not in METHOD_EDGES
    )
    assert not bad, "a method imports another method (add to METHOD_EDGES with a reason?):\n" + (
        "\n".join(bad)
    )
    used = {(top(e.source), top(e.target)) for e in EDGES}
    assert METHOD_EDGES <= used, f"listed but unused: {sorted(METHOD_EDGES - used)}"
