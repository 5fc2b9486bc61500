"""A Sphinx directive for the book's API reference page (``book/api.md``).

``.. api-packages::`` takes one package name per line and writes, for each, a section titled
with the package's name holding ``.. automodule:: <name>`` with the page's autodoc options, so the
package's public names are documented under the package (where users import them from), however
its modules are named inside. Public names are the package's ``__all__``, or, where it has none,
the public names it imports into its namespace. A package that only holds modules (one module
per notebook: ``thesis_lib.chapters``) gets a section per module. Constants among the public
names (autodoc documents only those with a comment in the package's own source) are listed
with the doc comment of the module that defines them and their value.

Adding a package to the reference is adding one line to the directive's content.
"""

from __future__ import annotations

import importlib
import inspect
import pkgutil
import re
import sys

from docutils import nodes
from docutils.parsers.rst import Directive
from docutils.statemachine import StringList
from sphinx import addnodes
from sphinx.pycode import ModuleAnalyzer, PycodeError
from sphinx.util.nodes import nested_parse_with_titles


def _public_names(module) -> tuple[list[str], bool]:
    names = getattr(module, "__all__", None)
    if names is not None:
        return list(names), True
    return [n for n in vars(module) if not n.startswith("_") and n != "annotations"], False


def _commented_in_source(name: str) -> set[str]:
    """Names that have a doc comment or docstring in the package's own source (autodoc shows them)."""
    try:
        docs = ModuleAnalyzer.for_module(name).find_attr_docs()
    except PycodeError:
        return set()
    return {attr for (scope, attr) in docs if scope == ""}


def _is_constant(obj) -> bool:
    return not (inspect.isclass(obj) or inspect.ismodule(obj) or callable(obj))


def _short_repr(value, limit: int = 70) -> str:
    text = re.sub(r" at 0x[0-9a-f]+", "", " ".join(repr(value).split()))  # no memory addresses
    return text if len(text) <= limit else text[: limit - 4] + " ..."


def _constant_doc(package: str, const: str, value) -> list[str]:
    """The doc comment or docstring of a constant in the package's module that defines it."""
    for modname, module in sorted(sys.modules.items()):
        if not modname.startswith(package + ".") or getattr(module, const, None) is not value:
            continue
        try:
            doc = ModuleAnalyzer.for_module(modname).find_attr_docs().get(("", const))
        except PycodeError:
            continue
        if doc:
            return list(doc)
    return []


def _modules_of(name: str, package) -> list[str]:
    """A package that only holds modules: its docstring, then a section per public module."""
    lines = [name, "-" * len(name), "", f".. automodule:: {name}", ""]
    for info in sorted(pkgutil.iter_modules(package.__path__), key=lambda m: m.name):
        if info.name.startswith("_"):
            continue
        full = f"{name}.{info.name}"
        lines += [full, "~" * len(full), "", f".. automodule:: {full}", "   :members:", ""]
    return lines


class APIPackages(Directive):
    has_content = True

    def run(self) -> list[nodes.Node]:
        lines: list[str] = []
        for name in (line.strip() for line in self.content):
            if not name:
                continue
            module = importlib.import_module(name)
            public, has_all = _public_names(module)
            if not has_all and all(inspect.ismodule(getattr(module, n)) for n in public):
                lines += _modules_of(name, module)  # e.g. thesis_lib.chapters: one per notebook
                continue
            options = ["   :members:"]
            if not has_all:  # no __all__: document what the package imports into its namespace
                options += ["   :imported-members:", "   :exclude-members: annotations"]
            lines += [name, "-" * len(name), "", f".. automodule:: {name}", *options, ""]
            documented = _commented_in_source(name)
            for const in public:
                value = getattr(module, const)
                if const in documented or not _is_constant(value):
                    continue
                doc = _constant_doc(name, const, value)
                lines += [f".. py:data:: {const}", f"   :module: {name}", ""]
                lines += [f"   {line}" if line.strip() else "" for line in doc]
                lines += ["", f"   Value: ``{_short_repr(value)}``", ""]
        source, _ = self.state_machine.get_source_and_line(self.lineno)
        container = nodes.section()
        container.document = self.state.document
        nested_parse_with_titles(self.state, StringList(lines, source=source), container)
        return container.children


def _no_inline_attribute_type(app, what, name, obj, options, lines) -> None:
    """Napoleon reads an attribute's docstring ``"X: Y"`` as type ``X``, description ``Y``.

    The library writes attribute and field docstrings as plain sentences ("Which SB3 algorithm:
    ..."), so an empty comment line first gives napoleon nothing to take for a type (napoleon
    skips blank lines, not comments). Runs before napoleon (priority 400 < 500).
    """
    if what in ("attribute", "data", "property") and lines:
        lines[:0] = ["..", ""]


_MISSING = object()


def _lookup(dotted: str):
    """The object a dotted ``thesis_lib`` name points to, or ``_MISSING`` (imports only thesis_lib)."""
    parts = dotted.split(".")
    if parts[0] != "thesis_lib":
        return _MISSING
    for i in range(len(parts), 0, -1):
        try:
            obj = importlib.import_module(".".join(parts[:i]))
        except ImportError:
            continue
        try:
            for attr in parts[i:]:
                obj = getattr(obj, attr)
        except AttributeError:
            return _MISSING
        return obj
    return _MISSING


def _undocumented_but_real(app, env, node, contnode):
    """A link to a real ``thesis_lib`` name that this page does not document renders as code.

    The reference documents packages, so a docstring's link to a name of its own module
    (``:func:`default_cache_dir``` in ``thesis_lib.clfd.data``), to a submodule or to a name by its
    submodule path has no target here. Such a link is resolved to plain code when the name
    exists in Python: looked up from the module that defines the documented object, then from
    each enclosing package. A name that exists nowhere still fails the -n build (a typo, or a
    name left behind by a rename).
    """
    if node.get("refdomain") != "py":
        return None
    target = node.get("reftarget", "")
    if target.startswith("thesis_lib."):
        candidates = [target]
    else:
        owners = []
        match = re.search(r"docstring of ([\w.]+)", node.source or "")
        if match:
            owners.append(match.group(1))
        module, cls = node.get("py:module"), node.get("py:class")
        if module and cls:
            owners.append(f"{module}.{cls}")
        parent = node.parent
        while parent is not None and not isinstance(parent, addnodes.desc):
            parent = parent.parent
        if parent is not None:  # a signature or the "Bases:" line: the object being described
            for sig in parent.findall(addnodes.desc_signature):
                if sig.get("module") and sig.get("fullname"):
                    owners.append(f"{sig['module']}.{sig['fullname']}")
                break
        if module:
            owners.append(module)
        scopes: list[str] = []
        for owner in owners:
            parts = owner.split(".")
            for i in range(len(parts), 0, -1):
                scope = ".".join(parts[:i])
                scopes.append(scope)
                defining = getattr(_lookup(scope), "__module__", None)
                if isinstance(defining, str):
                    scopes.append(defining)
        candidates = [f"{scope}.{target}" for scope in dict.fromkeys(scopes)]
    for candidate in candidates:
        if _lookup(candidate) is not _MISSING:
            return contnode
    return None


def _no_object_base(app, name, obj, options, bases) -> None:
    """``Bases: object`` says nothing: show a class's bases only when it has real ones."""
    if object in bases:
        bases.remove(object)


def setup(app):
    app.add_directive("api-packages", APIPackages)
    app.connect("autodoc-process-bases", _no_object_base)
    app.connect("autodoc-process-docstring", _no_inline_attribute_type, priority=400)
    app.connect("missing-reference", _undocumented_but_real)
    return {"parallel_read_safe": True, "parallel_write_safe": True}
