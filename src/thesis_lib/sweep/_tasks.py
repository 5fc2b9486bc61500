"""The unit of a grid and how one runs: :class:`Task`, :func:`execute`, :class:`TaskFailed`.

Below both :mod:`thesis_lib.sweep` (which re-exports every public name here) and its
executors (:mod:`thesis_lib.sweep._executors`), so that neither imports the other back.
"""

from __future__ import annotations

import contextvars
import hashlib
import json
import socket
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, TypeAlias, TypeVar

import pandas as pd

#: result rows a task function returns: a DataFrame or a list of flat dicts.
Rows: TypeAlias = pd.DataFrame | list[dict[str, Any]]

F = TypeVar("F", bound=Callable[..., Any])


def canonical_json(obj: Any) -> str:
    """JSON with sorted keys and no spaces: the text a config hash is taken of.

    Tuples become lists and numpy scalars plain numbers, so equal configs hash equal.

    >>> canonical_json({"b": (1, 2), "a": 0.5})
    '{"a":0.5,"b":[1,2]}'
    """
    return json.dumps(obj, sort_keys=True, separators=(",", ":"), default=json_default)


def json_default(o: Any) -> Any:
    """``json.dumps``'s ``default`` for task configs and rows (NumPy scalars and arrays, paths)."""
    import numpy as np

    if isinstance(o, np.generic):
        return o.item()
    if isinstance(o, np.ndarray):
        return o.tolist()
    if isinstance(o, Path):
        return str(o)
    raise TypeError(f"config value {o!r} ({type(o).__name__}) is not JSON-able")


def config_hash(obj: Any, n: int = 16) -> str:
    """First ``n`` hex digits of the SHA-256 of :func:`canonical_json` of ``obj``.

    >>> config_hash({"a": 1, "b": [2]}) == config_hash({"b": (2,), "a": 1})
    True
    >>> config_hash({"a": 1}) == config_hash({"a": 1.0})  # 1 and 1.0 are different configs
    False
    """
    return hashlib.sha256(canonical_json(obj).encode()).hexdigest()[:n]


def fn_path(fn: Callable[..., Any]) -> str:
    """The name of a task function in its tasks' keys and records: ``module:qualname``, or the
    name :func:`task_id` gave it; a ``ValueError`` for a function that is not module-level (a
    lambda, a nested function: not picklable)."""
    mod, qual = getattr(fn, "__module__", None), getattr(fn, "__qualname__", None)
    if not mod or not qual or "<" in qual:
        raise ValueError(f"a task function must be a module-level function (picklable), got {fn!r}")
    return getattr(fn, "__task_id__", None) or f"{mod}:{qual}"


def task_id(name: str) -> Callable[[F], F]:
    """Decorator: the task function's name in its tasks' keys, in place of its
    ``module:qualname``, so that moving the function to another module keeps the keys of the
    tasks already stored (a study's committed rows). ``name`` is written ``module:qualname``,
    where ``module`` is a module that imports the function (its code fingerprint starts there).

    Example::

        @task_id("thesis_lib.chapters.hdt:study_run")  # where it was when the v1 study ran
        def study_run(config: dict) -> list[dict]: ...
    """
    mod, _, qual = name.partition(":")
    if not mod or not qual:
        raise ValueError(f"a task id is written 'module:qualname', got {name!r}")

    def mark(fn: F) -> F:
        fn.__task_id__ = name  # type: ignore[attr-defined]
        return fn

    return mark


@dataclass(frozen=True)
class Task:
    """One independent unit of a grid.

    Attributes:
        fn: a module-level function ``fn(config) -> rows`` (a DataFrame or a list of dicts).
        config: everything the task depends on, JSON-able (method, setting, seed, sizes …).
        resources: what one run of the task needs on a Ray cluster: ``num_cpus``,
            ``num_gpus`` (fractions allowed), ``memory`` (bytes) and any custom Ray resource
            (``ray.remote`` options). The in-process and local executors ignore them. Not
            part of the key.
    """

    fn: Callable[[dict[str, Any]], Rows]
    config: Mapping[str, Any]
    resources: Mapping[str, float] = field(default_factory=lambda: {"num_cpus": 1})

    @property
    def key(self) -> str:
        """Hash of the function's import path and the config."""
        return config_hash({"fn": fn_path(self.fn), "config": dict(self.config)})


class TaskFailed(RuntimeError):
    """A task of a grid raised.

    The message names the task (key, function, config) and the original error; where the task
    ran in this process the original exception is the ``__cause__``, where it ran in another
    process or on a Ray node the message carries its traceback. Tasks that finished before the
    failure are already in the store, so a rerun resumes after them. The exception is also an
    instance of the original error's type where possible (``TaskFailed[ValueError]``).
    """

    def __init__(self, task: Task, error: str, traceback_text: str = "") -> None:
        self.key = task.key
        self.fn = fn_path(task.fn)
        self.config = dict(task.config)
        self.error = error
        msg = f"Task {self.key} failed: {self.fn}({canonical_json(self.config)}) raised {error}"
        if traceback_text:
            msg += f"\n\nTraceback of the task:\n{traceback_text.rstrip()}"
        super().__init__(msg)

    def __str__(self) -> str:
        return str(self.args[0]) if self.args else ""

    def __reduce__(self) -> tuple[Any, ...]:  # picklable as a plain RuntimeError
        return (RuntimeError, (str(self),))

    @classmethod
    def of(
        cls, task: Task, error: BaseException, message: str | None = None, traceback_text: str = ""
    ) -> TaskFailed:
        """The failure of ``task`` with ``error``, also an instance of ``error``'s type where
        Python allows it, so ``except ValueError`` still catches a task's ``ValueError``."""
        kind: type[TaskFailed] = cls
        etype = type(error)
        if not issubclass(etype, cls):
            if etype not in _FAILED_TYPES:
                try:
                    _FAILED_TYPES[etype] = type(
                        f"TaskFailed[{etype.__name__}]", (cls, etype), {"__module__": __name__}
                    )
                except TypeError:  # incompatible layouts (e.g. OSError): plain TaskFailed
                    _FAILED_TYPES[etype] = cls
            kind = _FAILED_TYPES[etype]
        exc = kind(task, message or f"{etype.__name__}: {error}", traceback_text)
        exc.__cause__ = error
        return exc


_FAILED_TYPES: dict[type, type[TaskFailed]] = {}


class GridFailed(TaskFailed):
    """Tasks of a grid run with ``keep_going=True`` raised; every other task ran and is stored.

    ``failures`` holds each failed task's :class:`TaskFailed`, in the order they failed; the
    first one's ``key``, ``fn``, ``config`` and ``error`` are also this exception's.
    """

    def __init__(self, failures: Sequence[TaskFailed], n_total: int, store: Path | None = None):
        first = failures[0]
        self.failures = list(failures)
        self.key, self.fn, self.config, self.error = first.key, first.fn, first.config, first.error
        where = f"; their tracebacks are in {store / 'failed'}" if store is not None else ""
        lines = [f"{len(failures)} of {n_total} task(s) failed; the others ran{where}:"]
        lines += [f"- {f.key}: {f.fn} raised {f.error}" for f in self.failures]
        RuntimeError.__init__(self, "\n".join(lines) + f"\n\nThe first: {first}")


RAY_MISSING = (
    'The Ray executor needs Ray, an optional extra of thesis_lib: pip install ".[ray]" '
    '(from the checkout) or pip install "ray>=2.9".'
)


def require_ray() -> Any:
    """Import and return :mod:`ray`.

    Raises:
        ImportError: Ray is not installed; the message says ``pip install ".[ray]"``.
    """
    try:
        import ray
    except ImportError as e:
        raise ImportError(RAY_MISSING) from e
    return ray


def _rows_to_records(rows: Rows) -> list[dict[str, Any]]:
    recs = rows.to_dict(orient="records") if isinstance(rows, pd.DataFrame) else list(rows)
    return json.loads(json.dumps(recs, default=json_default))


#: The running task's scratch folder (:func:`task_scratch`), set by :func:`execute`.
_SCRATCH: contextvars.ContextVar[Path | None] = contextvars.ContextVar("scratch", default=None)

#: The folder of a store that holds its unfinished tasks' scratch folders, one per task key.
SCRATCH_FOLDER = "partial"


def task_scratch() -> Path | None:
    """Where the running task may keep what lets it resume after an interruption (a training
    checkpoint), or ``None`` where it has none (no store, or not inside a task).

    The folder is ``<store>/partial/<key>/``, made on first call. A task killed before it
    ends (the session's end, Ctrl-C, a lost worker) finds it again when the grid is run again;
    once the task's record is stored, the folder is removed. Only the task of that key uses it
    (a running grid locks its tasks), so a file name inside needs no more than what it is.

    Example:
        >>> task_scratch() is None  # outside a task
        True
    """
    path = _SCRATCH.get()
    if path is not None:
        path.mkdir(parents=True, exist_ok=True)
    return path


#: CPU seconds of the running task's earlier, cut-off parts (:func:`note_resumed_cpu`).
_RESUMED_CPU: contextvars.ContextVar[list[float] | None] = contextvars.ContextVar(
    "resumed_cpu", default=None
)


def note_resumed_cpu(seconds: float) -> None:
    """Tell the running task that it resumed work whose earlier parts, cut off before, spent
    ``seconds`` CPU seconds (as the checkpoint it resumed from records). :func:`execute` adds
    them to the task's ``cpu_s``, so that a resumed task costs what the whole task cost;
    :func:`resumed_cpu_s` gives them to the task's own rows. Outside a task it does nothing.

    Example:
        >>> note_resumed_cpu(12.5)  # outside a task: nothing to tell
        >>> resumed_cpu_s()
        0.0
    """
    noted = _RESUMED_CPU.get()
    if noted is not None:
        noted.append(float(seconds))


def resumed_cpu_s() -> float:
    """The CPU seconds of the running task's earlier parts (:func:`note_resumed_cpu`); 0 where
    it started fresh or outside a task."""
    return float(sum(_RESUMED_CPU.get() or ()))


def scratch_file(name: str) -> Path | None:
    """``name`` in the running task's scratch folder (:func:`task_scratch`), or ``None`` where
    the task has none: what a task passes as its checkpoint file.

    Example:
        >>> scratch_file("train.pt") is None  # outside a task
        True
    """
    scratch = task_scratch()
    return None if scratch is None else scratch / name


def scratch_of(store: str | Path, key: str) -> Path:
    """The scratch folder of task ``key`` in the store ``store`` (:func:`task_scratch`)."""
    return Path(store) / SCRATCH_FOLDER / key


def execute(task: Task, scratch_root: str | Path | None = None) -> dict[str, Any]:
    """Run one task and return its record (rows, config, timing). Used by every executor.

    With ``scratch_root`` (a store's folder), the task's :func:`task_scratch` is
    ``<scratch_root>/partial/<key>``; the executor's caller removes it once the record is stored.
    """
    t0, c0 = time.time(), time.process_time()
    token = _SCRATCH.set(None if scratch_root is None else scratch_of(scratch_root, task.key))
    resumed: list[float] = []
    token_cpu = _RESUMED_CPU.set(resumed)
    try:
        rows = task.fn(dict(task.config))
    finally:
        _SCRATCH.reset(token)
        _RESUMED_CPU.reset(token_cpu)
    record = {
        "key": task.key,
        "fn": fn_path(task.fn),
        "config": json.loads(canonical_json(dict(task.config))),
        "rows": _rows_to_records(rows),
        "wall_s": round(time.time() - t0, 3),
        # a resumed task: this call's CPU seconds and those of its earlier parts
        "cpu_s": round(time.process_time() - c0 + sum(resumed), 3),
        "finished_at": time.strftime("%Y-%m-%dT%H:%M:%S%z"),
        "host": socket.gethostname(),
    }
    if resumed:
        record["resumed_cpu_s"] = round(sum(resumed), 3)
    return record
