"""Chapter parameters: notebook ``parameters`` cells mapped one-to-one onto dataclasses.

Papermill silently injects any ``-p name value`` it is given, even a misspelt one. Each chapter
notebook therefore calls :func:`config_from_namespace` right after its ``parameters`` cell, and
the ``thesis run`` command checks names before it starts a kernel (:func:`validate_parameters`).

Values are checked once, against the type hints of the chapter's ``Config``
(:func:`check_parameters`): by :func:`config_from_namespace` (a notebook run by papermill, a study
file) and by ``thesis run`` before papermill starts (``-p``, ``-f``, profiles). A bad value is
one line naming the parameter, the value and what is expected.
"""

from __future__ import annotations

import dataclasses
import difflib
import inspect
import types
import typing
from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import Any, Literal, TypeVar, Union

T = TypeVar("T")

# Names an IPython kernel defines by itself; never chapter parameters.
_KERNEL_NAMES = frozenset({"In", "Out", "get_ipython", "exit", "quit", "open"})


def validate_parameters(
    given: Iterable[str], valid: Iterable[str], chapter: str = "this notebook"
) -> None:
    """Raise if any name in ``given`` is not a valid parameter.

    Raises:
        ValueError: naming the first unknown parameter, a close match when there is one, and
            every valid name, e.g. ``Unknown parameter 'iteration' for notebook 04_hdt. Did you
            mean: 'iterations'? Valid: env, iterations, seed.``

    >>> validate_parameters(["seed"], ["seed", "steps"])
    >>> validate_parameters(["sed"], ["seed", "steps"], "01_background")
    Traceback (most recent call last):
    ...
    ValueError: Unknown parameter 'sed' for notebook 01_background. Did you mean: 'seed'? Valid: seed, steps.
    """
    valid = sorted(valid)
    for name in given:
        if name not in valid:
            close = difflib.get_close_matches(name, valid, n=1)
            hint = f" Did you mean: '{close[0]}'?" if close else ""
            raise ValueError(
                f"Unknown parameter '{name}' for notebook {chapter}.{hint} Valid: {', '.join(valid)}."
            )


def config_from_namespace(
    cls: type[T], namespace: Mapping[str, Any], chapter: str = "this notebook"
) -> T:
    """Build the chapter's config dataclass from the notebook's global names.

    Call it right after the ``parameters`` cell (and papermill's injected cell): every public
    global defined by then must be a field of ``cls``, so a parameter papermill injected under a
    wrong name is an error instead of being ignored. Keep imports out of the ``parameters``
    cell; modules, classes, functions and dataclass instances (an earlier ``cfg``) in
    ``namespace`` are ignored, so the cell may import what it needs and be re-run.

    Args:
        cls: a dataclass whose fields are the chapter's parameters.
        namespace: usually ``globals()`` of the notebook.
        chapter: the notebook's name, for the error message.

    Returns:
        ``cls(**values)`` with the values found in ``namespace`` (fields not found keep their
        defaults, so the dataclass is the single source of defaults).

    Raises:
        TypeError: if ``cls`` is not a dataclass.
        ValueError: for an unknown parameter (see :func:`validate_parameters`), a value that
            does not fit the field's type hint (see :func:`check_parameters`), or whatever
            ``cls.__post_init__`` rejects.
    """
    if not (dataclasses.is_dataclass(cls) and isinstance(cls, type)):
        raise TypeError(f"{cls!r} is not a dataclass")
    hints = config_hints(cls)
    names = [n for n, v in namespace.items() if _is_parameter_like(n, v)]
    validate_parameters(names, hints, chapter)
    return cls(**check_parameters(hints, {n: namespace[n] for n in names}, f"in {chapter}"))


S = TypeVar("S")


def spec_from(config: Any, spec: type[S], /, **overrides: Any) -> S:
    """A method's spec (``ArchSpec``, ``TrainSpec``, ...) from a chapter's flat ``Config`` (a
    dataclass): each field of ``spec`` that ``config`` has as a field by the same name, then
    ``overrides``.

    A chapter's parameters are flat (one notebook cell, one line of a study file each); this is
    the one place where they become the specs the methods take, so a parameter keeps its name
    on its way from the notebook to the model.

    Example:
        >>> @dataclasses.dataclass
        ... class Train:
        ...     lr: float = 1e-3
        ...     seed: int = 0
        >>> @dataclasses.dataclass
        ... class Cfg:
        ...     lr: float = 3e-4
        ...     seeds: tuple = (0, 1)
        >>> spec_from(Cfg(), Train, seed=1)
        Train(lr=0.0003, seed=1)

    Raises:
        TypeError: an override that is no field of ``spec``.
    """
    fields = {f.name for f in dataclasses.fields(spec) if f.init}  # type: ignore[arg-type]
    unknown = sorted(set(overrides) - fields)
    if unknown:
        raise TypeError(f"{spec.__name__} has no field {', '.join(map(repr, unknown))}")
    own = {f.name for f in dataclasses.fields(config)}  # fields, not methods of the same name
    taken = {n: getattr(config, n) for n in fields & own if n not in overrides}
    return spec(**taken, **overrides)


def _is_parameter_like(name: str, value: Any) -> bool:
    if name.startswith("_") or name in _KERNEL_NAMES:
        return False
    if inspect.ismodule(value) or inspect.isclass(value) or inspect.isroutine(value):
        return False
    return not dataclasses.is_dataclass(value)


def parse_value(text: str) -> Any:
    """Read a parameter value written as text (``-p NAME VALUE``, a notebook's default).

    Python literals first (``3``, ``1e-3``, ``[0, 1]``, ``{"SAC": 4000}``, ``True``), then YAML
    scalars (``true``, ``null``), else the text itself.

    >>> [parse_value(t) for t in ["3", "1e-3", "[0, 1]", "true", "Pendulum-v1"]]
    [3, 0.001, [0, 1], True, 'Pendulum-v1']
    """
    import ast

    import yaml

    try:
        return ast.literal_eval(text)
    except (ValueError, SyntaxError):
        pass
    try:
        return yaml.safe_load(text)
    except yaml.YAMLError:
        return text


# --- Values: checked against the Config's type hints -----------------------------------------


def config_hints(cls: type) -> dict[str, Any]:
    """The type hint of each ``__init__`` field of the dataclass ``cls``, in field order.

    >>> @dataclasses.dataclass
    ... class Demo:
    ...     seed: int = 0
    ...     envs: list[str] = dataclasses.field(default_factory=list)
    >>> config_hints(Demo)
    {'seed': <class 'int'>, 'envs': list[str]}
    """
    hints = typing.get_type_hints(cls)
    return {f.name: hints.get(f.name, Any) for f in dataclasses.fields(cls) if f.init}


class _Mismatch(Exception):
    """A value does not fit a type hint (turned into a message by :func:`check_value`)."""


def check_value(name: str, value: Any, hint: Any, where: str = "") -> Any:
    """``value`` for the parameter ``name`` whose type hint is ``hint``, or a clear error.

    ``int``: a whole number (``2.0`` becomes 2; ``2.5`` and ``true`` are refused). ``float``:
    any number but a boolean. ``bool``: only true or false. ``Literal[...]``: only its values.
    ``list[X]``: a list or tuple of X; one X (say a string) becomes a one-element list, never
    a list of its characters, and a string that starts with ``[`` is read as YAML (a plain
    ``papermill -p`` passes lists as text). ``dict[K, V]``, ``X | None``, other classes:
    checked as such; a hint this check does not know passes the value on unchecked.

    >>> check_value("algos", "PPO", list[str])
    ['PPO']
    >>> check_value("iterations", 2.0, int)
    2
    >>> check_value("seed", 1.5, int, "from -p seed 1.5")
    Traceback (most recent call last):
    ...
    ValueError: Expect `seed` to be an int, actually: 1.5 (from -p seed 1.5)

    Raises:
        ValueError: naming the parameter, the value, what is expected and ``where`` (the
            value's source).
    """
    try:
        return _conform(value, hint)
    except _Mismatch:
        at = f" ({where})" if where else ""
        raise ValueError(
            f"Expect `{name}` to be {describe_hint(hint)}, actually: {value!r}{at}"
        ) from None


def check_parameters(
    hints: Mapping[str, Any], values: Mapping[str, Any], where: str | Mapping[str, str] = ""
) -> dict[str, Any]:
    """``values`` checked with :func:`check_value` against ``hints`` (names not in ``hints``
    pass unchanged: :func:`validate_parameters` checks names); ``where`` describes the source
    of all values, or of each by name.

    >>> check_parameters({"seed": int, "envs": list[str]}, {"seed": 3.0, "envs": "Hopper-v5"})
    {'seed': 3, 'envs': ['Hopper-v5']}
    """
    return {
        n: v
        if n not in hints
        else check_value(n, v, hints[n], where if isinstance(where, str) else where.get(n, ""))
        for n, v in values.items()
    }


def _conform(value: Any, hint: Any) -> Any:
    """``value`` as ``hint`` wants it (see :func:`check_value`); raises :class:`_Mismatch`."""
    origin, args = typing.get_origin(hint), typing.get_args(hint)
    if hint is Any:
        return value
    if hint is None or hint is type(None):
        if value is None:
            return None
    elif origin is Literal:
        if any(value == a and type(value) is type(a) for a in args):
            return value
    elif origin in (Union, types.UnionType):
        for arg in args:
            try:
                return _conform(value, arg)
            except _Mismatch:
                pass
    elif hint is bool:
        if isinstance(value, bool):
            return value
    elif hint is int:
        if isinstance(value, int) and not isinstance(value, bool):
            return value
        if isinstance(value, float) and value.is_integer():
            return int(value)
    elif hint is float:
        if isinstance(value, int | float) and not isinstance(value, bool):
            return value
    elif hint in (list, tuple) or origin in (list, tuple):
        if isinstance(value, str) and value.lstrip().startswith("["):
            value = parse_value(value)
        if not isinstance(value, list | tuple | dict | set):
            value = [value]  # one item, never iterated (a string is not a list of characters)
        if isinstance(value, list | tuple):
            if origin is tuple and args and args[-1] is not Ellipsis:
                if len(value) != len(args):
                    raise _Mismatch
                return type(value)(_conform(v, a) for v, a in zip(value, args))
            item = args[0] if args else Any
            return type(value)(_conform(v, item) for v in value)
    elif hint is dict or origin is dict:
        if isinstance(value, str) and value.lstrip().startswith("{"):
            value = parse_value(value)
        if isinstance(value, dict):
            key, val = args or (Any, Any)
            return {_conform(k, key): _conform(v, val) for k, v in value.items()}
    elif not isinstance(hint, type) or isinstance(value, hint):
        return value  # a hint this check does not know (the Config checks it), or a match
    raise _Mismatch


_NAMES = {
    bool: ("true or false", "true/false values"),
    int: ("an int", "ints"),
    float: ("a number", "numbers"),
    str: ("a string", "strings"),
    type(None): ("None", "None"),
}


def describe_hint(hint: Any, plural: bool = False) -> str:
    """What ``hint`` expects, in words: ``a list of strings``, ``one of 'smoke', 'full'``."""
    origin, args = typing.get_origin(hint), typing.get_args(hint)
    if hint is None or hint in _NAMES:
        return _NAMES[type(None) if hint is None else hint][plural]
    if origin is Literal:
        return "one of " + ", ".join(repr(a) for a in args)
    if origin in (Union, types.UnionType):
        return " or ".join(describe_hint(a, plural) for a in args)
    if hint in (list, tuple) or origin in (list, tuple):
        items = f" of {describe_hint(args[0], True)}" if args else ""
        return ("lists" if plural else "a list") + items
    if hint is dict or origin is dict:
        items = (
            f" of {describe_hint(args[0], True)} to {describe_hint(args[1], True)}" if args else ""
        )
        return ("mappings" if plural else "a mapping") + items
    return getattr(hint, "__name__", str(hint))


# --- One source for parameters: the chapter's Config ---------------------------------------
#
# A chapter's ``Config`` dataclass (defaults = the smoke scale) generates the notebook's
# ``parameters`` cell and ``params/<chapter>.smoke.yml``; ``params/<chapter>.full.yml`` lists
# only what differs from smoke. ``thesis params --write`` regenerates, ``--check`` compares.

#: Line length of the generated cell (the project's ruff ``line-length``).
LINE_LENGTH = 100

SMOKE_HEADER = (
    "# Generated from {source} by `thesis params --write`; edit the Config, not this file.\n"
)


def _plain(value: Any, where: str) -> Any:
    """``value`` as YAML/literal-able data: tuples become lists, paths strings."""
    from pathlib import PurePath

    if value is None or isinstance(value, bool | int | float | str):
        return value
    if isinstance(value, PurePath):
        return str(value)
    if isinstance(value, list | tuple):
        return [_plain(v, where) for v in value]
    if isinstance(value, dict):
        for k in value:
            if not isinstance(k, str | int) or isinstance(k, bool):
                raise TypeError(f"{where}: dict key {k!r} must be a string or an integer")
        return {k: _plain(v, where) for k, v in value.items()}
    raise TypeError(
        f"{where}: default {value!r} ({type(value).__name__}) cannot be a notebook parameter; "
        "use numbers, strings, booleans, None, lists and dicts of them"
    )


def own_fields_first(cls: type) -> list[dataclasses.Field[Any]]:
    """The ``__init__`` fields of the dataclass ``cls``: those the class itself declares, in
    their order, then each base's own (nearest base first), where ``dataclasses.fields`` puts
    the bases' first. A chapter's parameters cell opens with the chapter's own parameters
    (seed, data sets, methods) and ends with the options it shares
    (:class:`~thesis_lib.chapters.seq_config.SeqTraining`).

    >>> @dataclasses.dataclass
    ... class Shared:
    ...     device: str = "cpu"
    >>> @dataclasses.dataclass
    ... class Demo(Shared):
    ...     seed: int = 0
    >>> [f.name for f in own_fields_first(Demo)]
    ['seed', 'device']
    """
    by_name = {f.name: f for f in dataclasses.fields(cls) if f.init}  # type: ignore[arg-type]
    order: list[str] = []
    for klass in cls.__mro__:
        if not dataclasses.is_dataclass(klass):
            continue
        inherited = {
            f.name
            for base in klass.__bases__
            if dataclasses.is_dataclass(base)
            for f in dataclasses.fields(base)
        }
        order += [
            f.name
            for f in dataclasses.fields(klass)
            if f.name not in inherited and f.name in by_name and f.name not in order
        ]
    return [by_name[n] for n in order]


def config_defaults(cls: type) -> dict[str, Any]:
    """The defaults of a Config dataclass, field by field (:func:`own_fields_first`), as plain
    data (the smoke profile).

    >>> @dataclasses.dataclass
    ... class Demo:
    ...     seed: int = 0
    ...     sizes: tuple = (8, 16)
    >>> config_defaults(Demo)
    {'seed': 0, 'sizes': [8, 16]}

    Raises:
        TypeError: not a dataclass, a field without a default, or a default that is not plain
            data.
    """
    if not (dataclasses.is_dataclass(cls) and isinstance(cls, type)):
        raise TypeError(f"{cls!r} is not a dataclass")
    fields = own_fields_first(cls)
    missing = [
        f.name
        for f in fields
        if f.default is dataclasses.MISSING and f.default_factory is dataclasses.MISSING
    ]
    if missing:
        raise TypeError(
            f"{cls.__name__} must give every field a default (the smoke scale); "
            f"no default: {', '.join(missing)}"
        )
    obj = cls()
    return {f.name: _plain(getattr(obj, f.name), f"{cls.__name__}.{f.name}") for f in fields}


def field_docs(cls: type) -> dict[str, str]:
    """Each field's documentation: the string right after it (an attribute docstring), else a
    comment at the end of its line; whitespace collapsed. Fields of base classes included."""
    import ast
    import io
    import textwrap
    import tokenize

    docs: dict[str, str] = {}
    for klass in reversed(cls.__mro__):
        if klass is object or not dataclasses.is_dataclass(klass):
            continue
        try:
            source = textwrap.dedent(inspect.getsource(klass))
        except (OSError, TypeError):
            continue
        comments = {
            tok.start[0]: tok.string.lstrip("#").strip()
            for tok in tokenize.generate_tokens(io.StringIO(source).readline)
            if tok.type == tokenize.COMMENT
        }
        body = ast.parse(source).body[0]
        if not isinstance(body, ast.ClassDef):
            continue
        stmts = body.body
        for i, node in enumerate(stmts):
            if not (isinstance(node, ast.AnnAssign) and isinstance(node.target, ast.Name)):
                continue
            nxt = stmts[i + 1] if i + 1 < len(stmts) else None
            text = ""
            if (
                isinstance(nxt, ast.Expr)
                and isinstance(nxt.value, ast.Constant)
                and isinstance(nxt.value.value, str)
            ):
                text = nxt.value.value
            else:
                end = node.end_lineno or node.lineno
                text = comments.get(end, "") or comments.get(node.lineno, "")
            if text.strip():
                docs[node.target.id] = " ".join(text.split())
    return docs


def _first_sentence(text: str) -> str:
    """The first sentence of ``text`` (up to a '.', '!' or '?' before a capital or the end)."""
    import re

    m = re.match(r"(.+?[.!?])(?=\s+[A-Z(`*]|\s*$)", text)
    return m.group(1) if m else text


def _trailing_comment(text: str) -> str:
    """A field's doc as a trailing comment that papermill still parses: papermill's parameter
    parser skips a line with two ``=``, so ``=`` becomes ':' (and ``<=``, ``>=``, ``!=``, ``==``
    their symbols)."""
    import re

    for a, b in (("<=", "≤"), (">=", "≥"), ("!=", "≠"), ("==", "≡")):
        text = text.replace(a, b)
    return re.sub(r"\s*=\s*", ": ", text)


def _py_str(s: str) -> str:
    """A string literal as ruff formats it: double quotes unless that adds escapes."""
    r = repr(s)
    if r.startswith("'") and '"' not in s:
        return '"' + r[1:-1].replace("\\'", "'") + '"'
    return r


def _py_flat(value: Any) -> str:
    """``value`` as a one-line Python literal, as ruff would write it."""
    import math

    if value is None or isinstance(value, bool):
        return repr(value)
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        if math.isnan(value):
            return 'float("nan")'
        if math.isinf(value):
            return 'float("inf")' if value > 0 else '-float("inf")'
        return repr(value)
    if isinstance(value, str):
        return _py_str(value)
    if isinstance(value, list):
        return "[" + ", ".join(_py_flat(v) for v in value) + "]"
    if isinstance(value, dict):
        items = (f"{_py_flat(k)}: {_py_flat(v)}" for k, v in value.items())
        return "{" + ", ".join(items) + "}"
    raise TypeError(f"cannot write {value!r} as a literal")


def _py_literal(value: Any, indent: int, used: int, tail: int = 0) -> str:
    """``value`` as ruff formats it when it starts at column ``used`` with ``tail`` characters
    after it on its last line: flat if it fits, else a list or dict one item per line."""
    flat = _py_flat(value)
    if used + len(flat) + tail <= LINE_LENGTH or not isinstance(value, list | dict) or not value:
        return flat
    pad = " " * (indent + 4)
    if isinstance(value, list):
        items = [pad + _py_literal(v, indent + 4, indent + 4, 1) + "," for v in value]
        return "[\n" + "\n".join(items) + "\n" + " " * indent + "]"
    lines = []
    for k, v in value.items():
        key = f"{_py_flat(k)}: "
        lines.append(pad + key + _py_literal(v, indent + 4, indent + 4 + len(key), 1) + ",")
    return "{\n" + "\n".join(lines) + "\n" + " " * indent + "}"


def parameters_source(cls: type) -> str:
    """The notebook's ``parameters`` cell for a Config dataclass: one ``name = value`` line per
    field, in field order, with the first sentence of the field's docstring as a trailing
    comment (as comment lines above it when the line would pass 100 characters). The text is
    stable and ruff-format clean.

    The comments come from the class's source file (:func:`field_docs`): a field followed by
    the attribute docstring "Seed of every random draw. Set it to repeat a run." gives
    ``seed = 0  # Seed of every random draw.``; ``envs: tuple = ("Hopper-v5",)  # gymnasium
    ids`` gives ``envs = ["Hopper-v5"]  # gymnasium ids``. A class without a source file (as
    here) gives the lines without comments:

    >>> @dataclasses.dataclass
    ... class Demo:
    ...     seed: int = 0
    ...     lr: float = 1e-3
    ...     envs: tuple = ("Hopper-v5",)
    >>> print(parameters_source(Demo))
    seed = 0
    lr = 0.001
    envs = ["Hopper-v5"]
    """
    import textwrap

    defaults = config_defaults(cls)
    docs = field_docs(cls)
    lines: list[str] = []
    for name, value in defaults.items():
        head = f"{name} = "
        doc = _first_sentence(docs.get(name, ""))
        comment = f"  # {_trailing_comment(doc)}" if doc else ""
        code = head + _py_literal(value, 0, len(head))
        last = code.rsplit("\n", 1)[-1]
        if comment and len(last) + len(comment) > LINE_LENGTH:
            lines.extend(
                textwrap.wrap(
                    doc,
                    LINE_LENGTH,
                    initial_indent="# ",
                    subsequent_indent="# ",
                    break_long_words=False,
                    break_on_hyphens=False,
                )
            )
            comment = ""
        lines.append(code + comment)
    return "\n".join(lines)


def smoke_yaml(cls: type, source: str | None = None) -> str:
    """``params/<chapter>.smoke.yml`` for a Config: a header naming ``source`` (default the
    class's import path), then every field's default in field order."""
    import yaml

    source = source or f"{cls.__module__}.{cls.__qualname__}"
    body = yaml.safe_dump(
        config_defaults(cls), sort_keys=False, default_flow_style=False, allow_unicode=True
    )
    return SMOKE_HEADER.format(source=source) + body


def full_overrides(defaults: Mapping[str, Any], full: Mapping[str, Any]) -> dict[str, Any]:
    """The entries of a full profile that differ from the smoke defaults.

    >>> full_overrides({"seed": 0, "steps": 10}, {"seed": 0, "steps": 1000})
    {'steps': 1000}
    """
    return {k: v for k, v in full.items() if k not in defaults or _plain(v, k) != defaults[k]}


def check_full_profile(
    cls: type, full: Mapping[str, Any], where: str = "the full profile"
) -> list[str]:
    """Problems of a full profile against its Config: unknown names, values equal to the smoke
    default (a full profile lists only what differs), values the Config rejects.

    >>> @dataclasses.dataclass
    ... class Demo:
    ...     seed: int = 0
    ...     steps: int = 10
    >>> check_full_profile(Demo, {"seed": 0, "step": 1000}, "demo.full.yml")  # doctest: +NORMALIZE_WHITESPACE
    ["demo.full.yml: 'step' is not a parameter of Demo (did you mean 'steps'?)",
     "demo.full.yml: 'seed' has the smoke value 0; list only what differs from smoke"]
    """
    defaults = config_defaults(cls)
    problems = []
    for name in full:
        if name not in defaults:
            close = difflib.get_close_matches(name, list(defaults), n=1)
            hint = f" (did you mean '{close[0]}'?)" if close else ""
            problems.append(f"{where}: '{name}' is not a parameter of {cls.__name__}{hint}")
    for name, value in full.items():
        if name in defaults and _plain(value, name) == defaults[name]:
            problems.append(
                f"{where}: '{name}' has the smoke value {value!r}; list only what differs from smoke"
            )
    known = {k: v for k, v in full.items() if k in defaults}
    try:
        cls(**check_parameters(config_hints(cls), known))
    except (TypeError, ValueError) as err:
        problems.append(f"{where}: {cls.__name__} rejects these values: {err}")
    return problems


def prune_full_yaml(text: str, defaults: Mapping[str, Any]) -> str:
    """A full profile's text with only what differs from ``defaults``; its leading comment
    block (why these values) is kept.

    >>> print(prune_full_yaml("# thesis scale\\nseed: 0\\nsteps: 1000\\n", {"seed": 0, "steps": 10}), end="")
    # thesis scale
    steps: 1000
    """
    import yaml

    lines = text.splitlines()
    n = 0
    while n < len(lines) and (lines[n].startswith("#") or not lines[n].strip()):
        n += 1
    header = "\n".join(lines[:n]).rstrip()
    data = yaml.safe_load(text) or {}
    if not isinstance(data, dict):
        raise ValueError(f"a profile must be a mapping, got {type(data).__name__}")
    over = full_overrides(defaults, data)
    body = yaml.safe_dump(over, sort_keys=False, allow_unicode=True) if over else ""
    return (header + "\n" if header else "") + body


def notebook_parameters_cell(path: str | Path) -> str:
    """The source of the notebook's cell tagged ``parameters``.

    Raises:
        ValueError: no such cell, or more than one.
    """
    import nbformat

    nb = nbformat.read(str(path), as_version=4)
    return _parameters_cell(nb, path).source


def _parameters_cell(nb: Any, path: Any) -> Any:
    cells = [c for c in nb.cells if "parameters" in c.get("metadata", {}).get("tags", [])]
    if len(cells) != 1:
        raise ValueError(f"{path} must have exactly one cell tagged 'parameters', has {len(cells)}")
    return cells[0]


def write_parameters_cell(path: str | Path, source: str) -> bool:
    """Replace the source of the notebook's ``parameters`` cell; return whether it changed.

    The rest of the notebook is written back as nbformat writes it (outputs untouched).
    """
    import nbformat

    nb = nbformat.read(str(path), as_version=4)
    cell = _parameters_cell(nb, path)
    if cell.source == source:
        return False
    cell.source = source
    nbformat.write(nb, str(path))
    return True


def check_chapter(chapter: str, cls: type, root: str | Path) -> list[str]:
    """Where ``chapter``'s files disagree with its Config (empty when they agree): the
    notebook's ``parameters`` cell and ``params/<chapter>.smoke.yml`` against the generated
    text, ``params/<chapter>.full.yml`` against :func:`check_full_profile`."""
    import yaml

    root = Path(root)
    problems = []
    nb = root / "notebooks" / f"{chapter}.ipynb"
    want = parameters_source(cls)
    try:
        if notebook_parameters_cell(nb) != want:
            problems.append(
                f"{nb.relative_to(root)}: the parameters cell differs from "
                f"{cls.__name__} (run 'thesis params --write {chapter}')"
            )
    except (OSError, ValueError) as err:
        problems.append(str(err))
    smoke = root / "params" / f"{chapter}.smoke.yml"
    if not smoke.is_file() or smoke.read_text() != smoke_yaml(cls):
        problems.append(
            f"params/{chapter}.smoke.yml differs from {cls.__name__} "
            f"(run 'thesis params --write {chapter}')"
        )
    full = root / "params" / f"{chapter}.full.yml"
    if full.is_file():
        data = yaml.safe_load(full.read_text()) or {}
        if not isinstance(data, dict):
            problems.append(f"params/{chapter}.full.yml must hold a mapping")
        else:
            problems += check_full_profile(cls, data, f"params/{chapter}.full.yml")
    return problems


def write_chapter(chapter: str, cls: type, root: str | Path) -> list[Path]:
    """Regenerate ``chapter``'s parameters cell and smoke profile from its Config, and prune its
    full profile to what differs from smoke; return the files that changed."""
    root = Path(root)
    changed = []
    nb = root / "notebooks" / f"{chapter}.ipynb"
    if write_parameters_cell(nb, parameters_source(cls)):
        changed.append(nb)
    smoke = root / "params" / f"{chapter}.smoke.yml"
    text = smoke_yaml(cls)
    if not smoke.is_file() or smoke.read_text() != text:
        smoke.write_text(text)
        changed.append(smoke)
    full = root / "params" / f"{chapter}.full.yml"
    if full.is_file():
        pruned = prune_full_yaml(full.read_text(), config_defaults(cls))
        if pruned != full.read_text():
            full.write_text(pruned)
            changed.append(full)
    return changed
