"""The executors behind :func:`thesis_lib.sweep.run_tasks`: in-process, joblib, Ray.

Each executor runs the pending tasks and hands every finished task's record to ``finished``
in this process as soon as it arrives (the store writes it at once), advancing one progress
bar over the whole grid, and every failed task's :class:`~thesis_lib.sweep.TaskFailed` (with
its traceback) to ``failed``. The first task that raises stops the grid: the executor cancels
what has not started and raises the ``TaskFailed``, naming the task's config. With
``keep_going`` the executor runs every other task and returns the failures instead.
"""

from __future__ import annotations

import logging
import os
import pickle
import shutil
import tempfile
import traceback
import warnings
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

from tqdm.auto import tqdm

from ._tasks import Task, TaskFailed, execute, require_ray

Failed = Callable[["TaskFailed", str], None]
#: what the executors call on a failure: record it; ``True`` where the grid goes on
Fail = Callable[["TaskFailed", str], bool]

#: ``Task.resources`` keys that are Ray task options; any other key is a custom Ray resource.
RAY_OPTION_KEYS = ("num_cpus", "num_gpus", "memory")


def run_pending(
    todo: list[Task],
    finished: Callable[[dict[str, Any]], None],
    failed: Failed,
    *,
    keep_going: bool,
    scratch_root: Path | None = None,
    executor: str,
    n_jobs: int,
    address: str | None,
    desc: str,
    progress: bool | None,
    n_total: int,
    n_done: int,
) -> list[TaskFailed]:
    """Run ``todo`` and call ``finished(record)`` as each task ends (in this process).

    Args:
        todo: the tasks without a stored result.
        finished: called with each task's record as it arrives.
        failed: called with each failed task's ``TaskFailed`` and traceback text.
        keep_going: run every other task after a failure (and return the failures).
        scratch_root: the store's folder, under which each task finds its scratch folder
            (:func:`~thesis_lib.sweep.task_scratch`); ``None``: no scratch.
        executor: ``inprocess``, ``local`` or ``ray``.
        n_jobs: processes for ``local``; for ``ray`` without ``address``, the CPUs of the local
            Ray instance it starts (when > 1).
        address: the Ray cluster (``None``: a local instance, or the one already initialised).
        desc: the progress bar's label.
        progress: ``False`` hides the bar, ``None`` shows it unless ``TQDM_DISABLE`` is set.
        n_total: tasks in the grid; n_done: those already stored (the bar starts there).

    Returns:
        With ``keep_going``, the failures in the order they happened (else always empty).

    Raises:
        TaskFailed: without ``keep_going``, the first task that raised.
    """
    if progress is None:
        progress = os.environ.get("TQDM_DISABLE", "").lower() in ("", "0", "false")
    bar = tqdm(
        total=n_total,
        initial=n_done,
        desc=desc,
        unit="task",
        disable=not progress,
        dynamic_ncols=True,
    )
    failures: list[TaskFailed] = []

    def fail(exc: TaskFailed, traceback_text: str) -> bool:
        """Record a failure; ``True`` where the grid goes on."""
        failed(exc, traceback_text)
        if keep_going:
            failures.append(exc)
            bar.set_postfix(failed=len(failures))
        return keep_going

    try:
        if not todo:
            return failures
        if executor == "inprocess":
            _run_inprocess(todo, finished, fail, bar, scratch_root)
        elif executor == "local":
            _run_joblib(todo, finished, fail, bar, n_jobs, scratch_root)
        elif executor == "ray":
            _run_ray(todo, finished, fail, bar, n_jobs, address, scratch_root)
        else:
            raise ValueError(f"unknown executor {executor!r}")
    finally:
        bar.close()
    return failures


def _run_inprocess(
    todo: list[Task],
    finished: Callable[..., None],
    fail: Fail,
    bar: Any,
    scratch_root: Path | None = None,
) -> None:
    for t in todo:
        try:
            rec = execute(t, scratch_root)
        except Exception as e:
            exc = TaskFailed.of(t, e)
            if not fail(exc, traceback.format_exc()):
                raise exc from e
            continue
        finished(rec)
        bar.update()


def _guarded(task: Task, scratch_root: Path | None = None) -> dict[str, Any]:
    """Run ``task`` in a worker; return ``{"record": …}`` or ``{"error": …, "traceback": …}``.

    A worker returns its failure instead of raising it, so the parent knows which task failed.
    """
    try:
        return {"key": task.key, "record": execute(task, scratch_root)}
    except Exception as e:
        err: BaseException = e
        try:
            pickle.dumps(e)
        except Exception:
            err = RuntimeError(f"{type(e).__name__}: {e}")
        return {
            "key": task.key,
            "error": err,
            "message": f"{type(e).__name__}: {e}",
            "traceback": traceback.format_exc(),
        }


#: Thread-pool variables limited in each local worker (``cpu_count // n_jobs`` threads), as
#: joblib does, unless set in the caller's environment.
THREAD_VARS = (
    "OMP_NUM_THREADS",
    "OPENBLAS_NUM_THREADS",
    "MKL_NUM_THREADS",
    "BLIS_NUM_THREADS",
    "VECLIB_MAXIMUM_THREADS",
    "NUMEXPR_NUM_THREADS",
)


def _run_joblib(
    todo: list[Task],
    finished: Callable[..., None],
    fail: Fail,
    bar: Any,
    n_jobs: int,
    scratch_root: Path | None = None,
) -> None:
    """``n_jobs`` local processes (joblib's loky executor, reused across grids).

    Each worker holds one task at a time (the next is sent when one finishes). After a
    failure no new task starts (unless the grid keeps going); the running ones finish and are
    stored, then :class:`TaskFailed` is raised. Ctrl-C stops the workers at once.
    """
    from concurrent.futures import FIRST_COMPLETED, wait
    from concurrent.futures.process import BrokenProcessPool

    from joblib import cpu_count
    from joblib.executor import get_memmapping_executor

    threads = str(max(cpu_count() // n_jobs, 1))
    env = {var: os.environ.get(var, threads) for var in THREAD_VARS}

    def get_reusable_executor() -> Any:
        # joblib's own factory, not loky's: loky's reusable executor lacks the temp-folder
        # manager joblib.Parallel expects when it reuses that executor later in the process
        # (AttributeError '_temp_folder_manager' in the next Parallel(n_jobs>1) call).
        return get_memmapping_executor(n_jobs, env=env)

    executor = get_reusable_executor()
    queue = iter(todo)
    pending: dict[Any, Task] = {}

    def submit_next() -> None:
        nonlocal executor
        task = next(queue, None)
        if task is None:
            return
        try:
            fut = executor.submit(_guarded, task, scratch_root)
        except BrokenProcessPool:  # a worker died (killed, out of memory): a fresh pool
            executor = get_reusable_executor()
            fut = executor.submit(_guarded, task, scratch_root)
        pending[fut] = task

    for _ in range(n_jobs):
        submit_next()
    failure: TaskFailed | None = None
    try:
        while pending:
            done, _ = wait(pending, return_when=FIRST_COMPLETED)
            for fut in done:
                task = pending.pop(fut)
                try:
                    out = fut.result()
                except Exception as e:  # the worker died (killed, out of memory …)
                    out = {"error": e, "message": f"{type(e).__name__}: {e}", "traceback": ""}
                if "error" in out:
                    exc = TaskFailed.of(task, out["error"], out["message"], out["traceback"])
                    if fail(exc, out["traceback"]):
                        submit_next()
                    elif failure is None:
                        failure = exc
                    continue
                finished(out["record"])
                bar.update()
                if failure is None:
                    submit_next()
    except BaseException:  # Ctrl-C, or an error while storing: stop the workers now
        executor.shutdown(wait=False, kill_workers=True)
        raise
    if failure is not None:
        raise failure


def _ray_options(resources: Mapping[str, float]) -> dict[str, Any]:
    """``Task.resources`` as ``ray.remote`` options: ``num_cpus``/``num_gpus``/``memory`` as
    they are, any other key as a custom resource.

    >>> _ray_options({"num_cpus": 2, "num_gpus": 0.5, "TPU": 1})
    {'num_cpus': 2, 'num_gpus': 0.5, 'resources': {'TPU': 1}}
    """
    opts: dict[str, Any] = {k: resources[k] for k in RAY_OPTION_KEYS if k in resources}
    custom = {k: v for k, v in resources.items() if k not in RAY_OPTION_KEYS}
    if custom:
        opts["resources"] = custom
    return opts


#: ``ray.remote`` option names and the cluster resource each one counts.
_RAY_RESOURCE_NAMES = {"num_cpus": "CPU", "num_gpus": "GPU", "memory": "memory"}


def _infeasible(resources: Mapping[str, float], cluster: Mapping[str, float]) -> list[str]:
    """What a task asks for beyond the whole cluster's ``cluster`` resources (Ray would wait
    for it forever unless the cluster grows).

    >>> _infeasible({"num_cpus": 1, "num_gpus": 1}, {"CPU": 2.0})
    ['num_gpus=1 (the cluster has 0 GPU)']
    """
    out = []
    for key, amount in resources.items():
        name = _RAY_RESOURCE_NAMES.get(key, key)
        have = cluster.get(name, 0)
        if amount > have:
            out.append(f"{key}={amount} (the cluster has {have:g} {name})")
    return out


def _ray_execute(task: Task, scratch_root: Path | None = None) -> dict[str, Any]:
    return _guarded(task, scratch_root)


def _run_ray(
    todo: list[Task],
    finished: Callable[..., None],
    fail: Fail,
    bar: Any,
    n_jobs: int,
    address: str | None,
    scratch_root: Path | None = None,
) -> None:
    """Tasks as Ray remote calls with their resources; records gathered with ``ray.wait`` as
    they finish. Uses the Ray this process is connected to; otherwise connects to ``address``
    or starts a local instance (``n_jobs`` CPUs when > 1, else all), and disconnects (stops the
    local instance and removes its session folder) when the grid ends."""
    ray = require_ray()
    started, session_dir = False, None
    if not ray.is_initialized():
        if address:
            ray.init(address=address, logging_level=logging.WARNING)
        else:
            # a short folder: Ray's socket paths must stay under 108 characters
            session_dir = tempfile.mkdtemp(
                prefix="ray-", dir="/tmp" if os.name == "posix" else None
            )
            ray.init(
                num_cpus=n_jobs if n_jobs > 1 else None,
                include_dashboard=False,
                logging_level=logging.WARNING,
                _temp_dir=session_dir,
            )
        started = True
    by_ref: dict[Any, Task] = {}
    try:
        cluster = ray.cluster_resources()
        asks = {tuple(sorted(t.resources.items())): t for t in todo}
        for t in asks.values():
            too_much = _infeasible(t.resources, cluster)
            if too_much:
                warnings.warn(
                    f"Task {t.key} asks for {', '.join(too_much)}: it waits until the Ray "
                    "cluster has that much (add nodes, or lower Task.resources).",
                    stacklevel=4,
                )
        remote = ray.remote(_ray_execute)
        for t in todo:
            by_ref[remote.options(**_ray_options(t.resources)).remote(t, scratch_root)] = t
        while by_ref:
            ready, _ = ray.wait(list(by_ref), num_returns=1)
            for ref in ready:
                t = by_ref.pop(ref)
                try:
                    out = ray.get(ref)
                except ray.exceptions.RayError as e:  # the worker died, was cancelled …
                    exc = TaskFailed.of(t, e)
                    if not fail(exc, ""):
                        raise exc from e
                    continue
                if "error" in out:
                    err = out["error"]
                    exc = TaskFailed.of(t, err, out["message"], out["traceback"])
                    if not fail(exc, out["traceback"]):
                        raise exc from err
                    continue
                finished(out["record"])
                bar.update()
    finally:
        for ref in by_ref:  # after a failure or Ctrl-C: stop what is still queued or running
            try:
                ray.cancel(ref, force=True)
            except Exception:
                pass
        if started:
            ray.shutdown()
        if session_dir is not None:
            shutil.rmtree(session_dir, ignore_errors=True)
