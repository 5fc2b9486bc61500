"""The executors behind :func:`thesis_lib.sweep.run_tasks`: in-process, joblib, Ray."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from tqdm.auto import tqdm


def run_pending(
    todo: list[Any],
    finished: Callable[[dict[str, Any]], None],
    *,
    executor: str,
    n_jobs: int,
    address: str | None,
    desc: str,
    progress: bool | None,
    n_total: int,
    n_done: int,
) -> None:
    """Run ``todo`` and call ``finished(record)`` as each task ends (in this process)."""
    from . import execute

    bar = tqdm(total=n_total, initial=n_done, desc=desc, unit="task", disable=progress is False)
    try:
        if executor == "inprocess" or not todo:
            for t in todo:
                finished(execute(t))
                bar.update()
        elif executor == "local":
            from joblib import Parallel, delayed

            par = Parallel(n_jobs=n_jobs, return_as="generator_unordered")
            for rec in par(delayed(execute)(t) for t in todo):
                finished(rec)
                bar.update()
        else:
            raise NotImplementedError(f"executor {executor!r}")
    finally:
        bar.close()
