"""Run chapter notebooks with papermill and build the book with jupyter-book.

A *chapter* is a notebook ``notebooks/<name>.ipynb`` listed in ``_toc.yml`` as
``book/generated/<name>``: the runner executes it into that place, then jupyter-book renders the
executed copies (``execute_notebooks: off`` in ``_config.yml``: papermill is the only executor).

Profiles are YAML files of parameters: ``params/<name>.smoke.yml`` (the notebook's defaults,
minutes on a laptop CPU) and ``params/<name>.full.yml`` (the thesis's scale).
"""

from __future__ import annotations

import contextlib
import os
import subprocess
import sys
import time
from collections.abc import Iterator, Mapping, Sequence
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import yaml

from thesis_lib.book.chapter import Chapter
from thesis_lib.book.params import (
    check_parameters,
    parse_value,
    validate_parameters,
)
from thesis_lib.paths import project_root
from thesis_lib.sweep import EXECUTORS

GENERATED = Path("book") / "generated"
PROFILES = ("smoke", "full")


class ChapterFailed(RuntimeError):
    """A chapter notebook raised; the message names the cell and the executed notebook to open."""


@dataclass(frozen=True)
class ChapterRun:
    """One executed chapter: where its notebook went, with which parameters, how long it took."""

    chapter: str
    output: Path
    parameters: dict[str, Any] = field(default_factory=dict)
    wall_time_s: float = 0.0


def _toc_files(node: Any) -> list[str]:
    out: list[str] = []
    if isinstance(node, dict):
        if "file" in node:
            out.append(str(node["file"]))
        for key in ("root", "parts", "chapters", "sections"):
            if key == "root" and key in node:
                out.append(str(node[key]))
            elif key in node:
                out.extend(_toc_files(node[key]))
    elif isinstance(node, list):
        for item in node:
            out.extend(_toc_files(item))
    return out


def list_chapters(root: Path | None = None) -> list[str]:
    """Names of the chapter notebooks in ``_toc.yml`` order, e.g. ``['01_background', 'survey']``."""
    root = root or project_root()
    toc = yaml.safe_load((root / "_toc.yml").read_text())
    prefix = GENERATED.as_posix() + "/"
    return [
        f[len(prefix) :].removesuffix(".ipynb") for f in _toc_files(toc) if f.startswith(prefix)
    ]


def resolve_chapter(name: str, root: Path | None = None) -> str:
    """Turn ``'01_background'``, ``'01'``, ``'background'`` or a notebook path into a chapter name.

    Raises:
        ValueError: no chapter, or several, match; the message lists the chapters.
    """
    root = root or project_root()
    chapters = list_chapters(root)
    stem = Path(name).name.removesuffix(".ipynb")
    if stem in chapters:
        return stem
    matches = [c for c in chapters if c.startswith(stem) or c.split("_", 1)[-1] == stem]
    if len(matches) == 1:
        return matches[0]
    what = "matches several chapters" if matches else "is not a chapter"
    raise ValueError(f"'{name}' {what}. Chapters: {', '.join(chapters)}.")


def notebook_path(chapter: str, root: Path | None = None) -> Path:
    root = root or project_root()
    path = root / "notebooks" / f"{chapter}.ipynb"
    if not path.is_file():
        raise FileNotFoundError(f"Chapter '{chapter}' has no notebook at {path}.")
    return path


def notebook_parameters(chapter: str, root: Path | None = None) -> dict[str, Any]:
    """The names and default values of the notebook's ``parameters`` cell."""
    import papermill as pm

    info = pm.inspect_notebook(str(notebook_path(chapter, root)))
    return {
        name: parse_value(spec["default"])
        if isinstance(spec.get("default"), str)
        else spec.get("default")
        for name, spec in info.items()
    }


def profile_path(chapter: str, profile: str | Path = "smoke", root: Path | None = None) -> Path:
    """The file of a profile: ``params/<chapter>.<profile>.yml`` or the YAML file given.

    Raises:
        ValueError: unknown profile name. FileNotFoundError: the file does not exist.
    """
    root = root or project_root()
    if str(profile) in PROFILES:
        path = root / "params" / f"{chapter}.{profile}.yml"
    else:
        path = Path(profile)
        if path.suffix not in (".yml", ".yaml"):
            raise ValueError(
                f"Unknown profile '{profile}'. Use one of {', '.join(PROFILES)} or a .yml file."
            )
    if not path.is_file():
        raise FileNotFoundError(f"No parameter file {path} for chapter '{chapter}'.")
    return path


def load_profile(
    chapter: str, profile: str | Path = "smoke", root: Path | None = None
) -> dict[str, Any]:
    """Parameters of a profile: ``'smoke'``, ``'full'`` or the path of a YAML file.

    Raises:
        ValueError: unknown profile name; the file is not YAML (one line: the file, the line
            and the problem) or not a mapping. FileNotFoundError: the file does not exist.
    """
    path = profile_path(chapter, profile, root)
    try:
        data = yaml.safe_load(path.read_text()) or {}
    except yaml.YAMLError as err:
        raise ValueError(f"{path}{_yaml_problem(err)}") from None
    if not isinstance(data, dict):
        raise ValueError(
            f"{path} must hold a mapping of parameter names to values, got {type(data).__name__}."
        )
    return data


def _yaml_problem(err: yaml.YAMLError) -> str:
    """A YAML error in one line: ``, line 3: invalid YAML (while parsing a flow sequence:
    expected ',' or ']', but got ':')``."""
    mark = getattr(err, "problem_mark", None)
    line = f", line {mark.line + 1}" if mark is not None else ""
    what = [getattr(err, "context", None), getattr(err, "problem", None)]
    text = ": ".join(str(w) for w in what if w) or str(err).splitlines()[0]
    return f"{line}: invalid YAML ({text})"


def _as_typed(name: str, value: Any) -> str:
    """``-p NAME VALUE`` as typed (near enough): ``-p seed 1.5``, ``-p flag true``."""
    import json

    text = value if isinstance(value, str) else json.dumps(value, default=repr)
    return f"-p {name} {text}"


def run_chapter(
    chapter: str | Chapter,
    parameters: Mapping[str, Any] | None = None,
    *,
    profile: str | Path | None = "smoke",
    output: str | Path | None = None,
    kernel: str = "python3",
    progress: bool = True,
    root: Path | None = None,
    env: Mapping[str, str] | None = None,
    hints: Mapping[str, Any] | None = None,
) -> ChapterRun:
    """Execute one chapter notebook with papermill.

    Every parameter is checked before papermill starts: its name against the notebook's
    ``parameters`` cell, its value against the type hints of the chapter's ``Config``
    (:func:`~thesis_lib.book.params.check_parameters`, as the notebook will check it).

    Args:
        chapter: a chapter name (see :func:`resolve_chapter`), or its registered
            :class:`~thesis_lib.book.chapter.Chapter` (``thesis_lib.chapters.CHAPTERS``), whose
            ``Config`` checks the values before papermill starts (given a name, the notebook
            checks them when it builds its ``Config``).
        hints: the ``Config``'s type hints where ``chapter`` is a name (a worker process
            receives them instead of the :class:`Chapter`, whose loader does not pickle).
        parameters: overrides on top of the profile (``thesis run -p``).
        profile: ``'smoke'``, ``'full'``, a YAML path, or ``None`` for the notebook's defaults.
        output: where the executed notebook goes (default ``book/generated/<chapter>.ipynb``).
        kernel: Jupyter kernel name.
        progress: show papermill's cell progress bar.
        env: environment variables for the notebook's kernel, over the caller's (e.g.
            :func:`sweep_environment`: how the chapter's task grids run).

    Raises:
        ValueError: an unknown parameter name (listing the valid ones), a value of the wrong
            type (naming the parameter, the value and where it came from), a profile that is
            not valid YAML.
        ChapterFailed: a cell raised; names the cell and the executed notebook.
    """
    import papermill as pm

    root = root or project_root()
    spec = chapter if isinstance(chapter, Chapter) else None
    chapter = resolve_chapter(spec.name if spec else str(chapter), root)
    params: dict[str, Any] = {}
    where: dict[str, str] = {}
    if profile is not None:
        path = profile_path(chapter, profile, root)
        params = load_profile(chapter, path, root)
        shown = path.relative_to(root) if path.is_relative_to(root) else path
        where = dict.fromkeys(params, f"in {shown}")
    for name, value in (parameters or {}).items():
        params[name], where[name] = value, f"from {_as_typed(name, value)}"
    validate_parameters(params, notebook_parameters(chapter, root), chapter)
    if spec is not None or hints is not None:
        params = check_parameters(dict(spec.hints() if spec else hints or {}), params, where)
    out = Path(output) if output else root / GENERATED / f"{chapter}.ipynb"
    out.parent.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    try:
        with _kernel_environment(env), _interrupt_forwarded_to_kernel():
            pm.execute_notebook(
                str(notebook_path(chapter, root)),
                str(out),
                parameters=params,
                kernel_name=kernel,
                cwd=str(root),
                progress_bar=progress,
                log_output=False,
            )
    except pm.PapermillExecutionError as err:
        if err.ename == "KeyboardInterrupt":
            raise ChapterFailed(
                f"Chapter '{chapter}' interrupted in cell {err.cell_index}; the tasks it had "
                f"finished are stored, so running it again resumes there ({out})."
            ) from None
        raise ChapterFailed(
            f"Chapter '{chapter}' failed in cell {err.cell_index} (execution count {err.exec_count}): "
            f"{err.ename}: {err.evalue}\nOpen {out} — papermill marked the failing cell at its top."
        ) from None
    _show_parameters_once(out)
    return ChapterRun(chapter, out, params, round(time.perf_counter() - t0, 2))


@contextlib.contextmanager
def _interrupt_forwarded_to_kernel() -> Iterator[None]:
    """Ctrl-C interrupts the running cell, as in Jupyter.

    Jupyter starts the kernel in its own session, so the terminal's SIGINT reaches only this
    process, and papermill keeps waiting for the kernel. While a chapter runs, the first SIGINT
    is passed on to the kernel and its children (a task grid's workers): the cell raises
    ``KeyboardInterrupt``, the tasks finished so far are already stored, and the chapter stops.
    A second Ctrl-C stops this process at once.
    """
    import signal
    import threading

    if threading.current_thread() is not threading.main_thread():
        yield  # signal handlers can only be set in the main thread (e.g. a worker process pool)
        return
    import psutil

    previous = signal.getsignal(signal.SIGINT)

    def forward(signum: int, frame: Any) -> None:
        for child in psutil.Process().children(recursive=True):
            with contextlib.suppress(psutil.Error):
                child.send_signal(signal.SIGINT)
        signal.signal(signal.SIGINT, signal.default_int_handler)

    signal.signal(signal.SIGINT, forward)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous)


def _show_parameters_once(path: Path) -> None:
    """The book shows the parameters a chapter ran with once: papermill's injected cell (what ran),
    not also the notebook's defaults cell above it (tagged ``remove-cell`` for jupyter-book)."""
    import nbformat

    nb = nbformat.read(path, as_version=4)
    tags = [c.get("metadata", {}).get("tags", []) for c in nb.cells]
    if not any("injected-parameters" in t for t in tags):
        return
    for cell, t in zip(nb.cells, tags):
        if "parameters" in t and "remove-cell" not in t:
            cell.metadata["tags"] = [*t, "remove-cell"]
    nbformat.write(nb, path)


KERNEL_ENV_DEFAULTS = {"TQDM_DISABLE": "1", "MUJOCO_GL": "egl"}
"""What an executed chapter's kernel gets unless the caller set it. ``TQDM_DISABLE``: tqdm bars
inside a chapter would be printed into the book as hundreds of lines of cursor codes (papermill's
own bar over the cells still shows progress). ``MUJOCO_GL=egl``: MuJoCo renders off-screen
(the UR3 and CLfD frames); where EGL is missing the UR3 renderer falls back to matplotlib."""


#: Kernel environment variables that say how a chapter's task grids run (read by
#: :func:`thesis_lib.sweep.run_tasks`): executor, parallel tasks, Ray address, recompute.
SWEEP_ENV = ("THESIS_EXECUTOR", "THESIS_JOBS", "RAY_ADDRESS", "THESIS_SWEEP_FORCE")


def sweep_environment(
    executor: str | None = None,
    jobs: int | None = None,
    address: str | None = None,
    force: bool = False,
) -> dict[str, str]:
    """The kernel environment for ``thesis run --executor/--jobs/--address/--force``.

    Only what is given is set, so a variable the caller exported stays in effect otherwise.
    An ``address`` without an executor means ``ray``.

    >>> sweep_environment("local", 4)
    {'THESIS_EXECUTOR': 'local', 'THESIS_JOBS': '4'}
    >>> sweep_environment(address="ray://head:10001", force=True)
    {'THESIS_EXECUTOR': 'ray', 'RAY_ADDRESS': 'ray://head:10001', 'THESIS_SWEEP_FORCE': '1'}

    Raises:
        ValueError: an unknown executor, ``jobs < 1``, or an address with a non-Ray executor.
    """
    if address and executor is None:
        executor = "ray"
    env: dict[str, str] = {}
    if executor is not None:
        if executor not in EXECUTORS:
            raise ValueError(f"Unknown executor '{executor}'. Use one of {', '.join(EXECUTORS)}.")
        env["THESIS_EXECUTOR"] = executor
    if jobs is not None:
        if jobs < 1:
            raise ValueError(f"The number of parallel tasks must be at least 1, got {jobs}.")
        env["THESIS_JOBS"] = str(jobs)
    if address:
        if executor != "ray":
            raise ValueError(f"A Ray address needs the Ray executor, not '{executor}'.")
        env["RAY_ADDRESS"] = address
    if force:
        env["THESIS_SWEEP_FORCE"] = "1"
    return env


@contextlib.contextmanager
def _kernel_environment(env: Mapping[str, str] | None = None) -> Iterator[None]:
    """For the duration: set ``env`` (over the caller's values) and the
    :data:`KERNEL_ENV_DEFAULTS` that neither sets; then restore the environment."""
    wanted = {k: v for k, v in KERNEL_ENV_DEFAULTS.items() if k not in os.environ}
    wanted.update(env or {})
    saved = {k: os.environ.get(k) for k in wanted}
    os.environ.update(wanted)
    try:
        yield
    finally:
        for k, old in saved.items():
            if old is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = old


def _run_one(args: tuple) -> ChapterRun:
    # a name and its Config's hints, not the Chapter: its loader does not pickle
    chapter, hints, parameters, profile, root, env = args
    return run_chapter(
        chapter, parameters, profile=profile, root=root, progress=False, env=env, hints=hints
    )


def start_order(chapters: Sequence[str], registry: Mapping[str, Chapter]) -> list[str]:
    """``chapters`` longest smoke run first (:attr:`Chapter.smoke_s
    <thesis_lib.book.chapter.Chapter.smoke_s>`), the order in which :func:`run_chapters`
    starts them when it runs several at once; chapters of equal or no hint keep their order.

    >>> from pathlib import Path
    >>> reg = {"a": Chapter("a", Path("a.py"), load=lambda: None, smoke_s=10),
    ...        "b": Chapter("b", Path("b.py"), load=lambda: None, smoke_s=400)}
    >>> start_order(["a", "unknown", "b"], reg)
    ['b', 'a', 'unknown']
    """
    return sorted(chapters, key=lambda c: -(registry[c].smoke_s if c in registry else 0.0))


def run_chapters(
    chapters: Sequence[str] | None = None,
    *,
    registry: Mapping[str, Chapter] | None = None,
    jobs: int = 1,
    profile: str | Path | None = "smoke",
    parameters: Mapping[str, Mapping[str, Any]] | None = None,
    root: Path | None = None,
    env: Mapping[str, str] | None = None,
) -> list[ChapterRun]:
    """Run several chapters, ``jobs`` at a time in separate processes; every chapter is tried.

    ``jobs`` counts chapters; how each chapter's own task grids run (executor, parallel
    tasks) is set by ``env`` (see :func:`sweep_environment`), given to every chapter's kernel.
    ``registry`` (``thesis_lib.chapters.CHAPTERS``): each chapter found there has its values
    checked against its ``Config``'s type hints before papermill starts it, and with
    ``jobs > 1`` the chapters start longest first (:attr:`Chapter.smoke_s
    <thesis_lib.book.chapter.Chapter.smoke_s>`; the rest in the order given), so that the
    last to finish is a short one. The runs come back in the order given.

    Raises:
        ChapterFailed: after all chapters ran, if any failed (every failure in the message).
    """
    root = root or project_root()
    chapters = [resolve_chapter(c, root) for c in (chapters or list_chapters(root))]
    registry = registry or {}
    tasks = [
        (
            c,
            registry[c].hints() if c in registry else None,
            dict((parameters or {}).get(c, {})),
            profile,
            root,
            dict(env or {}),
        )
        for c in chapters
    ]
    if jobs > 1:
        start = {c: i for i, c in enumerate(start_order(chapters, registry))}
        tasks.sort(key=lambda t: start[t[0]])
    done: list[ChapterRun] = []
    failures: list[str] = []

    def _report(result: ChapterRun) -> None:
        done.append(result)
        print(
            f"[thesis] {result.chapter}: done in {result.wall_time_s:.0f} s -> {result.output}",
            flush=True,
        )

    if jobs <= 1:
        for task in tasks:
            print(f"[thesis] running {task[0]} ...", flush=True)
            try:
                _report(_run_one(task))
            except ChapterFailed as err:
                failures.append(str(err))
    else:
        with ProcessPoolExecutor(max_workers=jobs) as pool:
            futures = {pool.submit(_run_one, t): t[0] for t in tasks}
            print(
                f"[thesis] running {', '.join(futures.values())} with {jobs} processes ...",
                flush=True,
            )
            for fut in as_completed(futures):
                try:
                    _report(fut.result())
                except ChapterFailed as err:
                    failures.append(str(err))
    if failures:
        raise ChapterFailed("\n\n".join(failures))
    order = {c: i for i, c in enumerate(chapters)}
    return sorted(done, key=lambda r: order[r.chapter])


def build_book(root: Path | None = None, *, strict: bool = True) -> Path:
    """Build the HTML book with jupyter-book 1.x from the executed notebooks; return index.html.

    Raises:
        FileNotFoundError: a chapter in ``_toc.yml`` has not been executed yet.
        RuntimeError: jupyter-book failed (its output is in the message).
    """
    root = root or project_root()
    missing = [c for c in list_chapters(root) if not (root / GENERATED / f"{c}.ipynb").is_file()]
    if missing:
        raise FileNotFoundError(
            f"Chapters not executed yet: {', '.join(missing)}. Run 'thesis run <chapter>' or 'thesis book'."
        )
    exe = Path(sys.executable).with_name("jupyter-book")
    cmd = [
        str(exe) if exe.exists() else "jupyter-book",
        "build",
        str(root),
        "--path-output",
        str(root),
    ]
    if strict:
        cmd += ["-W", "-n", "--keep-going"]
    env = {**os.environ, "PYDEVD_DISABLE_FILE_VALIDATION": "1"}
    proc = subprocess.run(cmd, cwd=root, capture_output=True, text=True, env=env)
    if proc.returncode != 0:
        raise RuntimeError(
            f"jupyter-book build failed ({proc.returncode}):\n{proc.stdout[-6000:]}\n{proc.stderr[-6000:]}"
        )
    return root / "_build" / "html" / "index.html"
