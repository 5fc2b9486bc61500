"""Chapter parameters: notebook ``parameters`` cells mapped one-to-one onto dataclasses.

Papermill silently injects any ``-p name value`` it is given, even a misspelt one. Each chapter
notebook therefore calls :func:`config_from_namespace` right after its ``parameters`` cell, and
the ``thesis run`` command checks names before it starts a kernel (:func:`validate_parameters`).
"""

from __future__ import annotations

import dataclasses
import difflib
import inspect
from collections.abc import Iterable, Mapping
from typing import Any, TypeVar

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
        ValueError: for an unknown parameter (see :func:`validate_parameters`), or whatever
            ``cls.__post_init__`` rejects.
    """
    if not dataclasses.is_dataclass(cls):
        raise TypeError(f"{cls!r} is not a dataclass")
    fields = {f.name for f in dataclasses.fields(cls) if f.init}
    names = [n for n, v in namespace.items() if _is_parameter_like(n, v)]
    validate_parameters(names, fields, chapter)
    return cls(**{n: namespace[n] for n in names})


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
