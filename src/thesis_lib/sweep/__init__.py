"""Grids of independent tasks, keyed by a hash of their config, resumable, local or on Ray.

A chapter's grid (methods x settings x seeds, DEFENDER runs, CLfD encoder x loss, MDLT
folds, UR3 demonstration counts) becomes a list of :class:`Task`. Each task is a module-level
function and a JSON-able config; its key is a hash of both. :func:`run_tasks` runs the tasks
that have no result in the store yet, writes each finished task's rows to
``<store>/<key>.json`` at once (atomically), and returns all rows in task order. An
interrupted run therefore resumes where it stopped, and a finished one is never recomputed
unless ``force=True``.

Executors: ``"inprocess"`` (one after the other, in this process), ``"local"`` (joblib
processes, ``n_jobs`` of them) and ``"ray"`` (a Ray cluster at ``address`` or
``$RAY_ADDRESS``; ``pip install ".[ray]"``). The defaults come from the environment that
``thesis run`` sets for a chapter (``THESIS_EXECUTOR``, ``THESIS_JOBS``, ``RAY_ADDRESS``,
``THESIS_SWEEP_FORCE``), so a notebook needs no parameter for them. One progress bar counts
the grid's tasks (the stored ones as done) and shows an ETA.

Each stored record holds the task's config, rows, timing and host, plus the git commit and
package versions of the run (:func:`default_provenance`) and when it was stored. A task that
raises stops the grid with :class:`TaskFailed`, which names its config; what finished before
stays stored. With ``keep_going=True`` (``thesis study --keep-going``, for long unattended
runs) every other task still runs, and :class:`GridFailed` lists the failures at the end. Either
way each failure's traceback is kept in ``<store>/failed/<key>.txt`` until the task succeeds.

A long task can resume inside itself too: :func:`task_scratch` gives it a folder,
``<store>/partial/<key>/``, for a training checkpoint (the ladder's runs keep one there). A task
cut off finds it when the grid runs again; once its record is stored, the folder is removed.

Example (``train_and_evaluate`` defined at module level in a library module)::

    def train_and_evaluate(config: dict) -> list[dict]:
        ...  # train config["method"] on config["dataset"] with config["seed"]
        return [{"method": config["method"], "seed": config["seed"], "score": score}]

    tasks = [
        Task(train_and_evaluate, {"method": m, "dataset": d, "seed": s, "iterations": 100})
        for m in ("DT", "HDT") for d in ("hopper/medium",) for s in (0, 1, 2)
    ]
    rows = run_tasks(tasks, store=results_dir("04_hdt") / "tasks", desc="Table 5.3")

Used by every chapter that runs a grid (``thesis_lib.chapters``).
"""

from __future__ import annotations

import hashlib
import json
import os
import shutil
import socket
import time
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from datetime import UTC, datetime
from pathlib import Path
from typing import Any, TypeAlias

import pandas as pd

from thesis_lib._io import atomic_write
from thesis_lib.provenance import RECORDED_PACKAGES, commit_record, package_versions

from ._executors import run_pending
from ._tasks import (
    RAY_MISSING,
    GridFailed,
    Rows,
    Task,
    TaskFailed,
    canonical_json,
    config_hash,
    execute,
    fn_path,
    json_default,
    note_resumed_cpu,
    require_ray,
    resumed_cpu_s,
    scratch_file,
    scratch_of,
    task_id,
    task_scratch,
)

EXECUTORS = ("inprocess", "local", "ray")


def default_provenance() -> dict[str, Any]:
    """What every stored task record carries: the git commit (with the changed files when it
    is ``-dirty``) and the package versions, taken when the sweep starts.

    The same helpers write ``run.json`` (:mod:`thesis_lib.provenance`), so a task can be
    traced to the code that computed it. Each record also gets ``stored_utc`` when written.
    """
    versions = package_versions((*RECORDED_PACKAGES, "joblib", "ray"))
    return {**commit_record(), "versions": versions}


class TaskStore:
    """Finished tasks on disk: one ``<key>.json`` per task in ``root``."""

    def __init__(self, root: str | Path):
        self.root = Path(root)

    def path(self, key: str) -> Path:
        return self.root / f"{key}.json"

    def has(self, key: str) -> bool:
        return self.path(key).is_file()

    def read(self, key: str) -> dict[str, Any]:
        """The stored record of task ``key``.

        Raises:
            RuntimeError: the file cannot be read, is not JSON, or is not a task record of
                ``key`` (a ``rows`` list, the same ``key``); the message names the file and says
                to delete it.
        """
        p = self.path(key)
        try:
            rec = json.loads(p.read_text())
        except (OSError, UnicodeDecodeError, json.JSONDecodeError) as e:
            raise RuntimeError(
                f"Damaged task result {p}: {e}. Delete it and run again to recompute it."
            ) from e
        if not isinstance(rec, dict) or not isinstance(rec.get("rows"), list):
            raise RuntimeError(
                f"Damaged task result {p}: not a task record (no 'rows' list). "
                "Delete it and run again to recompute it."
            )
        if rec.get("key") != key:
            raise RuntimeError(
                f"Damaged task result {p}: it holds task {rec.get('key')!r}, not {key!r}. "
                "Delete it and run again to recompute it."
            )
        return rec

    def keys(self) -> list[str]:
        """Keys of every stored task (sorted)."""
        if not self.root.is_dir():
            return []
        return sorted(p.stem for p in self.root.glob("*.json"))

    def write(self, record: dict[str, Any], extra: Mapping[str, Any] | None = None) -> Path:
        """Store a finished task's record (and forget an earlier failure of it)."""
        self.root.mkdir(parents=True, exist_ok=True)
        rec = {**record, **(extra or {})}
        text = json.dumps(rec, indent=1, default=json_default) + "\n"
        out = atomic_write(self.path(rec["key"]), lambda tmp: tmp.write_text(text))
        self.failure_path(rec["key"]).unlink(missing_ok=True)
        return out

    def failure_path(self, key: str) -> Path:
        """Where the last failure of task ``key`` is kept: ``<root>/failed/<key>.txt``."""
        return self.root / "failed" / f"{key}.txt"

    def write_failure(self, failure: TaskFailed, traceback_text: str = "") -> Path:
        """Keep a failed task's message and traceback (with the time) until it succeeds."""
        stamp = datetime.now(UTC).isoformat(timespec="seconds")
        text = f"{stamp}\n{failure}\n"
        if traceback_text and traceback_text not in text:
            text += f"\nTraceback of the task:\n{traceback_text.rstrip()}\n"
        return atomic_write(self.failure_path(failure.key), lambda tmp: tmp.write_text(text))

    def failures(self) -> list[str]:
        """Keys of the tasks whose last run failed (sorted)."""
        folder = self.root / "failed"
        return sorted(p.stem for p in folder.glob("*.txt")) if folder.is_dir() else []


def _env_default(name: str, default: str | None) -> str | None:
    v = os.environ.get(name)
    return v if v not in (None, "") else default


def resolve_executor(executor: str | None, n_jobs: int | None) -> tuple[str, int]:
    """The executor and job count, from the arguments or ``THESIS_EXECUTOR`` / ``THESIS_JOBS``."""
    if n_jobs is None:
        text = _env_default("THESIS_JOBS", "1") or "1"
        try:
            n_jobs = int(text)
        except ValueError:
            raise ValueError(f"THESIS_JOBS must be a whole number, got {text!r}") from None
    jobs = n_jobs
    ex = executor or _env_default("THESIS_EXECUTOR", None)
    if ex is None:
        ex = "local" if jobs > 1 else "inprocess"
    if ex not in EXECUTORS:
        raise ValueError(f"unknown executor {ex!r}; choose one of {', '.join(EXECUTORS)}")
    return ex, max(1, jobs)


def run_tasks(
    tasks: Sequence[Task] | Iterable[Task],
    store: str | Path | None = None,
    *,
    executor: str | None = None,
    n_jobs: int | None = None,
    address: str | None = None,
    force: bool | None = None,
    desc: str = "tasks",
    progress: bool | None = None,
    provenance: Mapping[str, Any] | None = None,
    keep_going: bool | None = None,
) -> pd.DataFrame:
    """Run the tasks that have no stored result and return every task's rows, in task order.

    Args:
        tasks: the grid.
        store: folder of finished tasks; ``None`` keeps nothing (no resume).
        executor: ``inprocess``, ``local`` or ``ray`` (default: ``$THESIS_EXECUTOR``, else
            ``local`` when ``n_jobs > 1``, else ``inprocess``).
        n_jobs: parallel tasks for ``local`` (default ``$THESIS_JOBS`` or 1).
        address: Ray cluster address (default ``$RAY_ADDRESS``; none starts a local Ray).
        force: recompute finished tasks too, from the start (their scratch folders cleared;
            default ``$THESIS_SWEEP_FORCE``).
        desc: the progress bar's label.
        progress: show a progress bar with an ETA (default: unless ``TQDM_DISABLE`` is set).
        provenance: extra fields written into each stored record, on top of the git commit,
            the package versions (:func:`default_provenance`) and ``stored_utc``.
        keep_going: after a task fails, run every other task, then raise :class:`GridFailed`
            (default ``$THESIS_SWEEP_KEEP_GOING``, else ``False``: the first failure stops
            the grid). A failed task's traceback is kept in ``<store>/failed/<key>.txt``.

    Returns:
        The rows of all tasks, concatenated, with a ``task_key`` column.

    Raises:
        ValueError: two tasks with the same key, or an unknown executor.
        TaskFailed: a task raised (its config is in the message); the tasks that finished
            before it are stored.
        GridFailed: with ``keep_going``, one or more tasks raised; all the others are stored.
        RuntimeError: a stored result is damaged (the message names the file).
        ImportError: ``executor="ray"`` without Ray installed.
    """
    tasks = list(tasks)
    keys = [t.key for t in tasks]
    if len(set(keys)) != len(keys):
        from collections import Counter

        dup = [k for k, n in Counter(keys).items() if n > 1]
        first = tasks[keys.index(dup[0])]
        raise ValueError(
            f"{len(dup)} task(s) appear twice in the grid, e.g. "
            f"{fn_path(first.fn)}({canonical_json(dict(first.config))}) (key {dup[0]})"
        )
    if force is None:
        force = _env_default("THESIS_SWEEP_FORCE", "0") not in ("0", "false", "False")
    if keep_going is None:
        keep_going = _env_default("THESIS_SWEEP_KEEP_GOING", "0") not in ("0", "false", "False")
    ex, jobs = resolve_executor(executor, n_jobs)
    st = TaskStore(store) if store is not None else None
    done: dict[str, dict[str, Any]] = {}
    if st is not None and not force:
        done = {k: st.read(k) for k in keys if st.has(k)}
    todo = [t for t in tasks if t.key not in done]
    if st is not None and force:  # recomputed from the start: no resume from a scratch folder
        for t in todo:
            shutil.rmtree(scratch_of(st.root, t.key), ignore_errors=True)
    extra: dict[str, Any] = {}
    if st is not None and todo:
        extra = {**default_provenance(), **(provenance or {})}
    elif provenance:
        extra = dict(provenance)

    def finished(rec: dict[str, Any]) -> None:
        if st is not None:
            stamp = datetime.now(UTC).isoformat(timespec="seconds")
            st.write(rec, {**extra, "stored_utc": stamp})
            shutil.rmtree(scratch_of(st.root, rec["key"]), ignore_errors=True)  # stored: done
        done[rec["key"]] = rec

    def failed(exc: TaskFailed, traceback_text: str) -> None:
        if st is not None:
            st.write_failure(exc, traceback_text)

    failures = run_pending(
        todo,
        finished,
        failed,
        keep_going=keep_going,
        scratch_root=None if st is None else st.root,
        executor=ex,
        n_jobs=jobs,
        address=address or _env_default("RAY_ADDRESS", None),
        desc=desc,
        progress=progress,
        n_total=len(tasks),
        n_done=len(tasks) - len(todo),
    )
    if failures:
        raise GridFailed(failures, len(tasks), st.root if st is not None else None)
    frames = []
    for k in keys:
        df = pd.DataFrame(done[k]["rows"])
        df["task_key"] = k
        frames.append(df)
    return pd.concat(frames, ignore_index=True) if frames else pd.DataFrame()


def probe(config: dict[str, Any]) -> list[dict[str, Any]]:
    """A task that reports where it ran: host, process, CPUs and GPUs it sees.

    Check a cluster before a long run: ``run_tasks([Task(probe, {"i": i}) for i in
    range(8)], executor="ray")`` lists the nodes that took tasks.

    >>> sorted(probe({"i": 3})[0])
    ['cpus', 'cuda_visible_devices', 'host', 'i', 'pid']
    """
    return [
        {
            "i": config.get("i"),
            "host": socket.gethostname(),
            "pid": os.getpid(),
            "cpus": os.cpu_count(),
            "cuda_visible_devices": os.environ.get("CUDA_VISIBLE_DEVICES", ""),
        }
    ]


_fn_path = fn_path  # the old name, imported by thesis_lib.book.study

__all__ = [
    "EXECUTORS",
    "GridFailed",
    "RAY_MISSING",
    "Task",
    "TaskFailed",
    "TaskStore",
    "canonical_json",
    "config_hash",
    "default_provenance",
    "execute",
    "note_resumed_cpu",
    "probe",
    "require_ray",
    "resolve_executor",
    "resumed_cpu_s",
    "run_tasks",
    "scratch_file",
    "scratch_of",
    "task_id",
    "task_scratch",
]
