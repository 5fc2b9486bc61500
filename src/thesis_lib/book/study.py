"""Pre-registered studies: ``params/<chapter>.study.yml`` run into ``studies/<chapter>/``.

A chapter may register later studies beside its first, each in a file of its own:
``params/<chapter>.<tag>.study.yml`` (e.g. ``04_hdt.v2.study.yml``), run into
``studies/<chapter>/<tag>/`` and named ``<chapter>:<tag>`` on the command line
(``thesis study 04_hdt:v2``). A later study names the one it replaces (``supersedes:``); the
earlier one keeps its file, its rows and its verdicts, and ``studies/claims.csv`` shows them
beside the later one (column ``history``), so a change of verdict stays visible. A study that
answers the same claims another way without replacing anything names the study it is read
beside (``beside:``; the GPU timings of C6 beside the CPU study's): its verdicts go to the
claims' ``history`` only, never to the claim's verdict.

A study file fixes, before anything runs, the chapter config (settings, seeds, sizes), the
metric, and the comparisons that test the thesis's claims (``CLAIMS.md``). ``thesis study
<chapter>`` builds the chapter's :class:`Config` from it, asks the chapter module for its
tasks (``study_tasks(cfg) -> list[Task]``) and runs them through :mod:`thesis_lib.sweep`
with the store ``studies/<chapter>/tasks/``: each finished task is written at once and is
committed with the project, so a study resumes across working sessions. ``rows.csv`` and
``run.json`` (study id, the study file's hash, commits, versions, CPU-hours, progress) are
rewritten after each run. Each task a run takes is locked (``tasks/<key>.lock``, see
:func:`task_locks`) while the run lasts, so a second ``thesis study`` of the same chapter skips
the tasks the first one is running instead of running them again. ``thesis claims`` turns
every study's rows into ``studies/claims.csv``, one verdict per claim, by
:mod:`thesis_lib.stats.claims`.

The book renders ``studies/``; it never recomputes a study.
"""

from __future__ import annotations

import contextlib
import dataclasses
import json
import os
import re
import socket
import sys
from collections.abc import Iterator, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import pandas as pd
import yaml

from thesis_lib._io import atomic_write
from thesis_lib.book.chapter import Chapter
from thesis_lib.book.params import check_value, config_from_namespace, config_hints, describe_hint
from thesis_lib.paths import project_root
from thesis_lib.provenance import git_commit, package_versions
from thesis_lib.stats import INTERVALS
from thesis_lib.stats.claims import CLAIMS, check_comparison, claim_verdicts, evaluate_comparisons
from thesis_lib.stats.gates import apply_retests, check_gate, load_review
from thesis_lib.sweep import Task, TaskStore, config_hash, fn_path, run_tasks

STUDY_KEYS = {
    "study",
    "chapter",
    "description",
    "config",
    "metric",
    "secondary",
    "columns",
    "comparisons",
    "budget_cpu_hours",
    "scale_check",
    "reuse",
    "notes",
    "gates",
    "interval",
    "supersedes",
    "beside",
}
SCALE_CHECK_KEYS = {"config", "note"}
REQUIRED_KEYS = ("study", "chapter", "config", "metric", "comparisons")
DEFAULT_COLUMNS = {"method": "method", "setting": "setting", "seed": "seed"}


@dataclass
class Study:
    """One pre-registered study, as read from its parameter file."""

    study: str
    chapter: str
    config: dict[str, Any]
    metric: str
    comparisons: list[dict[str, Any]]
    description: str = ""
    secondary: str | None = None
    columns: dict[str, str] = field(default_factory=lambda: dict(DEFAULT_COLUMNS))
    budget_cpu_hours: float | None = None
    scale_check: dict[str, Any] | None = None
    """``config``: overrides of ``config`` for a second scale on one setting, run beside the
    study and tagged ``scale: check`` (not used by the comparisons); ``note``: why."""
    reuse: list[str] = field(default_factory=list)
    """Studies (``05_decision_mamba``, ``04_hdt:v2``) whose finished tasks are copied in when a
    task is the same (same key)."""
    notes: str = ""
    path: Path | None = None
    gates: list[dict[str, Any]] = field(default_factory=list)
    """Validity gates pre-registered with the comparisons (:mod:`thesis_lib.stats.gates`)."""
    interval: str | None = None
    """The comparisons' interval (:data:`thesis_lib.stats.INTERVALS`); ``None``: the engine's
    default, :data:`DEFAULT_INTERVAL`."""
    supersedes: str | None = None
    """The id of the earlier study of the same chapter that this one replaces (its verdicts
    move to the claims' ``history`` once this one is complete)."""
    beside: str | None = None
    """The id of the study of the same chapter that this one is reported beside (the same
    claims on other hardware, say): its verdicts are listed in the claims' ``history`` and never
    decide a claim."""
    tag: str = ""
    """Which of the chapter's studies: ``""`` for ``params/<chapter>.study.yml``, ``"v2"`` for
    ``params/<chapter>.v2.study.yml`` (from the file's name; not pre-registered)."""

    @property
    def hash(self) -> str:
        """Hash of everything pre-registered (all fields but the file's path and tag;
        ``gates``, ``interval``, ``supersedes`` and ``beside`` only where a file sets them, so
        earlier study files keep their hash)."""
        d = dataclasses.asdict(self)
        d.pop("path")
        d.pop("tag")
        for key, unset in (
            ("gates", []),
            ("interval", None),
            ("supersedes", None),
            ("beside", None),
        ):
            if d[key] == unset:
                d.pop(key)
        return config_hash(d)

    @property
    def ref(self) -> str:
        """How the command line names it: ``04_hdt`` or ``04_hdt:v2``."""
        return study_ref(self.chapter, self.tag)

    @property
    def folder(self) -> Path:
        """Where its tasks and rows go: ``studies/<chapter>/`` or ``studies/<chapter>/<tag>/``."""
        return studies_dir(self.chapter, self.tag)

    @property
    def file(self) -> str:
        """Its parameter file, relative to the project: ``params/<chapter>[.<tag>].study.yml``."""
        return f"params/{study_path(self.chapter, self.tag).name}"


#: The interval of every study's comparisons unless its file says otherwise: Welch's t
#: interval for the mean (it covers 95% at 3-5 seeds, where the percentile bootstrap of the v1
#: rule covered about 89%; issue #35).
DEFAULT_INTERVAL = "welch"


_TAG = re.compile(r"[a-z0-9][a-z0-9_-]*")


def study_ref(chapter: str, tag: str = "") -> str:
    """``04_hdt`` (a chapter's first study) or ``04_hdt:v2`` (its study tagged ``v2``)."""
    return f"{chapter}:{tag}" if tag else chapter


def split_ref(ref: str) -> tuple[str, str]:
    """``"04_hdt:v2"`` -> ``("04_hdt", "v2")``; ``"04_hdt"`` -> ``("04_hdt", "")``.

    Raises:
        ValueError: a tag that is not lower-case letters, digits, ``-`` and ``_``.
    """
    chapter, _, tag = str(ref).partition(":")
    if tag and not _TAG.fullmatch(tag):
        raise ValueError(
            f"A study tag is lower-case letters, digits, '-' and '_' (e.g. 04_hdt:v2), got {ref!r}."
        )
    return chapter, tag


def study_path(chapter: str, tag: str = "") -> Path:
    """``params/<chapter>.study.yml`` (``tag``: ``params/<chapter>.<tag>.study.yml``)."""
    return project_root() / "params" / f"{chapter}{'.' + tag if tag else ''}.study.yml"


def studies_dir(chapter: str | None = None, tag: str = "") -> Path:
    """``<project>/studies``, ``studies/<chapter>`` or ``studies/<chapter>/<tag>`` (committed
    evidence)."""
    base = project_root() / "studies"
    if not chapter:
        return base
    return base / chapter / tag if tag else base / chapter


def study_files() -> list[Path]:
    """Every study file of the checkout, each chapter's first study before its tagged ones."""
    root = project_root() / "params"

    def order(p: Path) -> tuple[str, int, str]:
        chapter, tag = _name_parts(p)
        return chapter, bool(tag), tag

    return sorted(root.glob("*.study.yml"), key=order)


def _name_parts(p: Path) -> tuple[str, str]:
    """``(chapter, tag)`` that a study file's name says (``04_hdt.v2.study.yml``)."""
    stem = p.name.removesuffix(".study.yml")
    chapter, _, tag = stem.partition(".")
    return chapter, tag


def chapter_studies(chapter: str) -> list[Study]:
    """The studies of ``chapter``, first to last (its first study, then the tagged ones by
    tag)."""
    return [load_study(p) for p in study_files() if _name_parts(p)[0] == chapter]


def superseded_by(study: Study) -> str | None:
    """The id of the later study of ``study``'s chapter that replaces it (``supersedes:``
    names it), or None."""
    later = [s.study for s in chapter_studies(study.chapter) if s.supersedes == study.study]
    return later[0] if later else None


def parse_study(data: Mapping[str, Any], path: Path | None = None) -> Study:
    """Validate a study mapping (unknown or missing keys, unknown claims are errors)."""
    where = f" in {path}" if path else ""
    unknown = set(data) - STUDY_KEYS
    if unknown:
        raise ValueError(
            f"unknown study key(s) {sorted(unknown)}{where}; valid: {sorted(STUDY_KEYS)}"
        )
    missing = [k for k in REQUIRED_KEYS if k not in data]
    if missing:
        raise ValueError(f"study file{where} lacks {missing}")
    if not data["comparisons"]:
        raise ValueError(f"study file{where} pre-registers no comparison")
    for c in data["comparisons"]:
        try:
            check_comparison(c)
        except ValueError as e:
            raise ValueError(f"{e}{where}") from None
    for key, ok, expect in (
        ("metric", isinstance(data["metric"], str) and bool(data["metric"]), "a column name"),
        ("secondary", isinstance(data.get("secondary", ""), str | None), "a column name"),
        ("config", isinstance(data["config"], Mapping | None), "a mapping of Config fields"),
        ("columns", isinstance(data.get("columns") or {}, Mapping), "a mapping"),
        (
            "budget_cpu_hours",
            isinstance(data.get("budget_cpu_hours"), int | float | None)
            and not isinstance(data.get("budget_cpu_hours"), bool),
            "a number of hours",
        ),
    ):
        if not ok:
            raise ValueError(f"Expect `{key}` to be {expect}, actually: {data[key]!r}{where}")
    cols = {**DEFAULT_COLUMNS, **(data.get("columns") or {})}
    bad = {k: v for k, v in cols.items() if k not in DEFAULT_COLUMNS or not isinstance(v, str)}
    if bad:
        raise ValueError(
            f"Expect `columns` to map {sorted(DEFAULT_COLUMNS)} to column names, actually: "
            f"{bad}{where}"
        )
    check = data.get("scale_check")
    if check is not None:
        if not isinstance(check, Mapping) or set(check) - SCALE_CHECK_KEYS:
            raise ValueError(
                f"scale_check{where} must be a mapping with keys {sorted(SCALE_CHECK_KEYS)}"
            )
    reuse = data.get("reuse") or []
    if isinstance(reuse, str):
        reuse = [reuse]

    gates = data.get("gates") or []
    if not isinstance(gates, list):
        raise ValueError(f"Expect `gates` to be a list of gates, actually: {gates!r}{where}")
    for g in gates:
        try:
            check_gate(g)
        except ValueError as e:
            raise ValueError(f"{e}{where}") from None
    supersedes = data.get("supersedes")
    if supersedes is not None and not (isinstance(supersedes, str) and supersedes):
        raise ValueError(
            f"Expect `supersedes` to be the id of an earlier study, actually: {supersedes!r}{where}"
        )
    beside = data.get("beside")
    if beside is not None and not (isinstance(beside, str) and beside):
        raise ValueError(
            f"Expect `beside` to be the id of a study of the same chapter, actually: {beside!r}"
            f"{where}"
        )
    if beside is not None and supersedes is not None:
        raise ValueError(
            f"A study either replaces an earlier one (`supersedes`) or is read beside another "
            f"(`beside`), not both{where}."
        )
    interval = data.get("interval")
    if interval is not None and interval not in INTERVALS:
        raise ValueError(
            f"Expect `interval` to be one of {INTERVALS}, actually: {interval!r}{where}"
        )
    return Study(
        study=str(data["study"]),
        chapter=str(data["chapter"]),
        config=dict(data["config"] or {}),
        metric=str(data["metric"]),
        comparisons=[dict(c) for c in data["comparisons"]],
        description=str(data.get("description", "")),
        secondary=data.get("secondary"),
        columns=cols,
        budget_cpu_hours=data.get("budget_cpu_hours"),
        scale_check=dict(check) if check is not None else None,
        reuse=[str(r) for r in reuse],
        notes=str(data.get("notes", "")),
        path=path,
        gates=[dict(g) for g in gates],
        interval=interval,
        supersedes=supersedes,
        beside=beside,
    )


def load_study(ref_or_path: str | Path) -> Study:
    """Read a study file and validate it: ``"04_hdt"`` (``params/04_hdt.study.yml``),
    ``"04_hdt:v2"`` (``params/04_hdt.v2.study.yml``) or a path.

    Raises:
        FileNotFoundError: no such study file.
        ValueError: the file is invalid (:func:`parse_study`); a ``*.study.yml`` is named
            unlike its ``chapter:`` (its tasks and rows would go to another chapter's study);
            a tagged study's ``supersedes`` names no earlier study of its chapter.
    """
    p = Path(ref_or_path)
    if p.suffix not in (".yml", ".yaml"):
        p = study_path(*split_ref(str(ref_or_path)))
    if not p.is_file():
        have = [x.name for x in study_files()]
        raise FileNotFoundError(f"No study file {p}. Study files here: {have or 'none'}.")
    study = parse_study(yaml.safe_load(p.read_text()) or {}, p)
    if p.name.endswith(".study.yml"):
        chapter, tag = _name_parts(p)
        if chapter != study.chapter:
            raise ValueError(
                f"Study file {p} is named unlike its `chapter: {study.chapter}`: its results go "
                f"to studies/{study.chapter}/, so name it {study.chapter}.study.yml or "
                f"{study.chapter}.<tag>.study.yml (or fix `chapter:`)."
            )
        split_ref(study_ref(chapter, tag))  # a well-formed tag
        study.tag = tag
    if study.supersedes is not None:
        earlier = _earlier_study_ids(study)
        if study.supersedes not in earlier:
            raise ValueError(
                f"{p}: `supersedes: {study.supersedes}` names no earlier study of "
                f"{study.chapter} (earlier: {', '.join(earlier) or 'none'})."
            )
    if study.beside is not None:
        ids = {
            _file_study_id(f)
            for f in study_files()
            if _name_parts(f)[0] == study.chapter and f.resolve() != p.resolve()
        }
        if study.beside not in ids:
            raise ValueError(
                f"{p}: `beside: {study.beside}` names no other study of {study.chapter} "
                f"(its studies: {', '.join(sorted(ids)) or 'none'})."
            )
    return study


def _earlier_study_ids(study: Study) -> list[str]:
    """The ids of the studies of ``study``'s chapter registered before it (by
    :func:`study_files`' order), by :func:`_file_study_id`: a file written later than the
    running code must not stop a long run's commits."""
    out = []
    for p in study_files():
        chapter, tag = _name_parts(p)
        if chapter != study.chapter:
            continue
        if tag == study.tag:
            break
        out.append(_file_study_id(p))
    return out


def _file_study_id(p: Path) -> str:
    """The ``study:`` id of the study file ``p``, read without validating the rest: a file
    written later than the running code (a key it does not know) must still be nameable."""
    return str((yaml.safe_load(p.read_text()) or {}).get("study"))


def study_chapter(ref_or_path: str | Path) -> str:
    """The reference (``04_hdt``, ``04_hdt:v2``) of a study named by it or by its study file's
    path.

    A path must be a registered study file, ``params/<chapter>[.<tag>].study.yml``: those are the
    studies that ``thesis study``, ``thesis claims`` and the book read.

    Raises:
        FileNotFoundError: no such study file.
        ValueError: the file is invalid (:func:`load_study`), or a path outside ``params/``.
    """
    p = Path(ref_or_path)
    if p.suffix not in (".yml", ".yaml"):
        split_ref(str(ref_or_path))
        return str(ref_or_path)
    study = load_study(p)
    registered = study_path(study.chapter, study.tag)
    if not registered.is_file() or p.resolve() != registered.resolve():
        raise ValueError(
            f"{p} is not a registered study of {study.chapter} ({registered}): copy it "
            f"there (or run 'thesis study {study.ref}')."
        )
    return study.ref


def _check_chapter(study: Study, chapter: Chapter) -> None:
    if chapter.name != study.chapter:
        raise ValueError(
            f"study {study.study} is of chapter {study.chapter}, not of {chapter.name}"
        )


def study_config(study: Study, chapter: Chapter, scale: str = "study") -> Any:
    """The chapter's ``Config`` with the study's overrides (an unknown field is an error);
    ``scale="check"``: with the scale check's overrides on top.

    Under the study file's values lie the chapter's ``STUDY_FILE_DEFAULTS`` (where it has
    them): fields added after the v1 studies were registered, at the value those studies ran
    with (``init: torch``), so an older file keeps its meaning and its task keys. A new study
    file names such fields itself."""
    _check_chapter(study, chapter)
    _check_study_values(study, chapter.Config)
    _check_study_columns(study, chapter.study_columns)
    # a field added after a study file was written takes the value that study ran with
    values = {**chapter.study_file_defaults, **study.config}
    if scale == "check":
        if not study.scale_check or not study.scale_check.get("config"):
            raise ValueError(f"study {study.study} has no scale_check config")
        values.update(study.scale_check["config"])
    return config_from_namespace(chapter.Config, values, f"{study.chapter} (study {study.study})")


def _check_study_values(study: Study, config_cls: type) -> None:
    """Each value of the study file's ``config`` (and ``scale_check.config``) fits the type hint
    of its ``Config`` field (:func:`~thesis_lib.book.params.check_value`, naming the file), and
    a list is written as one: ``seeds: 3`` is not the list ``[3]`` (as ``-p seeds 3`` would be),
    it is refused. Unknown fields are left to ``config_from_namespace``."""
    hints = config_hints(config_cls)
    where = f" in {study.path}" if study.path else ""
    check = (study.scale_check or {}).get("config") or {}
    for part, values in (("config", study.config), ("scale_check.config", check)):
        for name, value in values.items():
            if name not in hints:
                continue
            checked = check_value(name, value, hints[name], f"{part}{where}")
            if isinstance(checked, list | tuple) and not isinstance(value, list | tuple):
                raise ValueError(
                    f"Expect `{name}` to be {describe_hint(hints[name])}, actually: {value!r} "
                    f"({part}{where})"
                )


def _check_study_columns(study: Study, columns: Any) -> None:
    """The study's metric, secondary metric, comparison metrics and ``columns`` name columns
    of its rows, where the chapter declares them (``STUDY_COLUMNS``; else nothing to check)."""
    if columns is None:
        return
    where = f" in {study.path}" if study.path else ""
    named = [("metric", study.metric), ("secondary", study.secondary)]
    named += [(f"columns.{k}", v) for k, v in study.columns.items()]
    named += [
        (f"comparisons[{i}].metric", c["metric"])
        for i, c in enumerate(study.comparisons)
        if "metric" in c
    ]
    for key, col in named:
        if col is not None and col not in columns:
            raise ValueError(
                f"Expect `{key}` to be a column of the {study.chapter} study's rows, actually: "
                f"{col!r}{where}; its columns: {', '.join(columns)}"
            )


def study_tasks(study: Study, chapter: Chapter) -> list[Any]:
    """The study's tasks, from its chapter's ``study_tasks(cfg)``: the scale check's first
    (their configs carry ``scale: check``), then the study's own."""
    tasks = chapter.study_tasks(study_config(study, chapter))
    if study.scale_check and study.scale_check.get("config"):
        check = chapter.study_tasks(study_config(study, chapter, "check"))
        # first: CLAIMS.md asks for the scale check before the study
        tasks = [Task(t.fn, {**t.config, "scale": "check"}, t.resources) for t in check] + tasks
    return tasks


def reuse_tasks(study: Study, keys: list[str]) -> int:
    """Copy finished tasks with the same key from the studies in ``study.reuse`` into this
    study's store (each record notes where it came from); returns how many were copied.

    A record is reused only if it was written under its own study's current hash."""
    own = TaskStore(study.folder / "tasks")
    n = 0
    for ref in study.reuse:
        other = load_study(ref)
        store = TaskStore(other.folder / "tasks")
        for k in keys:
            if own.has(k) or not store.has(k):
                continue
            rec = store.read(k)
            if rec.get("study_hash") != other.hash:
                continue
            own.write(
                rec,
                {
                    "study": study.study,
                    "study_hash": study.hash,
                    "reused_from": {"study": other.study, "chapter": other.chapter},
                },
            )
            n += 1
    return n


def _try_lock(path: Path) -> int | None:
    """An exclusive ``flock`` on ``path`` (created if need be, stamped with our pid and host),
    or ``None`` when another process holds it. A lock file left by a process that died holds
    no lock (the kernel released it): it is taken over."""
    import fcntl

    while True:
        fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o644)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            os.close(fd)
            return None
        try:  # the holder may have removed the file between our open and our lock: retry
            same = os.fstat(fd).st_ino == os.stat(path).st_ino
        except FileNotFoundError:
            same = False
        if same:
            os.ftruncate(fd, 0)
            os.write(fd, f"pid {os.getpid()} on {socket.gethostname()}\n".encode())
            return fd
        os.close(fd)


@contextlib.contextmanager
def task_locks(store: str | Path, keys: list[str]) -> Iterator[list[str]]:
    """Lock the tasks ``keys`` of the task store ``store`` for the block: yields the keys this
    process took, in order; the others are held by another process (another ``thesis study``).

    One lock file per task, ``<store>/<key>.lock`` (an exclusive ``fcntl.flock``; the file
    names the holder's pid and host), removed at the end of the block, whether the tasks
    finished or failed. A lock file whose process died is taken over. POSIX only.

    Used in: :func:`run_study` (one runner per task of a study).
    """
    root = Path(store)
    root.mkdir(parents=True, exist_ok=True)
    held: dict[str, int] = {}
    try:
        for k in keys:
            fd = _try_lock(root / f"{k}.lock")
            if fd is not None:
                held[k] = fd
        yield list(held)
    finally:
        for k, fd in held.items():
            (root / f"{k}.lock").unlink(missing_ok=True)  # while still held: no one else's
            os.close(fd)


def run_study(
    chapter: Chapter,
    *,
    study: Study | str | None = None,
    executor: str | None = None,
    n_jobs: int | None = None,
    address: str | None = None,
    force: bool = False,
    progress: bool | None = None,
    keep_going: bool = False,
) -> pd.DataFrame:
    """Run (or resume) a study of ``chapter`` (its registered
    :class:`~thesis_lib.book.chapter.Chapter`: ``thesis_lib.chapters.CHAPTERS["04_hdt"]``);
    returns its rows and rewrites its files
    (``rows.csv``, ``run.json``: also when a task fails, for the tasks that finished).

    ``study``: which of the chapter's studies, a :class:`Study` or its tag (``"v2"``); default
    the chapter's first, ``params/<chapter>.study.yml``.

    ``keep_going``: a failed task does not stop the study; the others run, and
    :class:`~thesis_lib.sweep.GridFailed` lists the failures at the end (their tracebacks are in
    ``studies/<chapter>/tasks/failed/``).

    The run locks every task it is to run, from its start to its end (:func:`task_locks`); a task
    that another process holds is skipped (said on stderr), so a second run of a study never
    runs a task that the first one is running or will run. The rows returned are those of the
    tasks this run finished or found stored."""
    if not isinstance(study, Study):
        study = load_study(study_ref(chapter.name, study or ""))
    tasks = study_tasks(study, chapter)
    out = study.folder
    if study.reuse and not force:
        reuse_tasks(study, [t.key for t in tasks])
    store = TaskStore(out / "tasks")
    todo = [t.key for t in tasks if force or not store.has(t.key)]
    with task_locks(store.root, todo) as taken:
        busy = set(todo) - set(taken)
        if busy:
            first = store.root / f"{next(k for k in todo if k in busy)}.lock"
            print(
                f"study {study.study}: skipping {len(busy)} task(s) another run holds, e.g. "
                f"{first} ({_holder(first)})",
                file=sys.stderr,
            )
        mine = [t for t in tasks if t.key not in busy]
        finished = task_records(study) if taken and not force and progress is not False else []
        if finished:  # the bar's own ETA waits for a task of this run to finish
            ours = set(taken)
            left = cpu_hours_left(study, [t for t in mine if t.key in ours], records=finished)
            n = n_jobs or 1
            jobs = f", about {left / n:.1f} hours at {n} jobs" if n > 1 else ""
            print(
                f"study {study.study}: {len(taken)} task(s) to run, about {left:.1f} CPU-hours "
                f"at the cost of its finished tasks{jobs}",
                file=sys.stderr,
            )
        try:
            rows = run_tasks(
                mine,
                store.root,
                executor=executor,
                n_jobs=n_jobs,
                address=address,
                force=force,
                desc=f"study {study.study}",
                progress=progress,
                provenance={
                    "study": study.study,
                    "study_hash": study.hash,
                    "commit": git_commit(),
                },
                keep_going=keep_going,
            )
        finally:
            if task_records(study):
                write_study_summary(study, [t.key for t in tasks])
    return rows


def _holder(lock: Path) -> str:
    """Who holds a task lock, as its file says (``pid 123 on host``)."""
    try:
        return lock.read_text().strip() or "holder unknown"
    except OSError:
        return "holder unknown"


def task_records(study: Study, keys: list[str] | None = None) -> list[dict[str, Any]]:
    """The stored records of a study's finished tasks (those written under this study's hash),
    restricted to ``keys`` when given; read once, pass them to the functions that take
    ``records=``."""
    root = study.folder / "tasks"
    recs = []
    for p in sorted(root.glob("*.json")) if root.is_dir() else []:
        rec = json.loads(p.read_text())
        if rec.get("study_hash") == study.hash and (keys is None or rec["key"] in keys):
            recs.append(rec)
    return recs


def cpu_hours_left(
    study: Study, tasks: list[Any], records: list[dict[str, Any]] | None = None
) -> float:
    """CPU-hours the study's unfinished ``tasks`` should take, from the cost of its finished ones.

    Tasks of a grid differ (the scale check's run longer; a baseline costs next to nothing), so
    each unfinished task is priced at the mean CPU time of the finished tasks most like it: the
    same function, scale (``check`` or the study's own) and ``method`` (or ``label``, as the
    DEFENDER chapter's tasks name their method); failing that, the same
    function and scale; failing that, the same function; failing that, all of them. ``0.0``
    when nothing has finished. ``records``: the study's task records, when the caller has
    already read them (:func:`task_records`).
    """
    recs = records if records is not None else task_records(study, [t.key for t in tasks])
    if not recs:
        return 0.0
    done = {r["key"] for r in recs}

    def levels(fn: str, config: Mapping[str, Any]) -> list[tuple[Any, ...]]:
        scale = config.get("scale", "study")
        method = config.get("method", config.get("label"))
        return [(fn, scale, str(method)), (fn, scale), (fn,), ()]

    costs: dict[tuple[Any, ...], list[float]] = {}
    for r in recs:
        for level in levels(str(r.get("fn", "")), r.get("config", {})):
            costs.setdefault(level, []).append(float(r.get("cpu_s", 0.0)))
    left = 0.0
    for t in tasks:
        if t.key in done:
            continue
        level = next(lv for lv in levels(fn_path(t.fn), t.config) if lv in costs)
        left += sum(costs[level]) / len(costs[level])
    return left / 3600


def study_task_functions(study: Study) -> set[str]:
    """The task functions (``module:qualname``) that a study's stored tasks ran."""
    return {str(r["fn"]) for r in task_records(study) if r.get("fn")}


def study_rows(
    study: Study, keys: list[str] | None = None, records: list[dict[str, Any]] | None = None
) -> pd.DataFrame:
    """Tidy rows of a study's finished tasks (those written under this study's hash)."""
    frames = []
    for rec in records if records is not None else task_records(study, keys):
        df = pd.DataFrame(rec["rows"])
        df["task_key"] = rec["key"]
        frames.append(df)
    return pd.concat(frames, ignore_index=True) if frames else pd.DataFrame()


def _task_versions(records: list[dict[str, Any]]) -> dict[str, str]:
    """The package versions the study's tasks ran with: the latest stored task's (each task's
    record keeps its own), not the summarising process's, which may be another machine (the
    GPU study's tasks ran on the machine lent, its summary is rewritten here). With no task
    stored yet: this process's."""
    stamped = [r for r in records if isinstance(r.get("versions"), dict)]
    if not stamped:
        return package_versions()
    latest = max(stamped, key=lambda r: str(r.get("stored_utc") or r.get("finished_at") or ""))
    return dict(latest["versions"])


def write_study_summary(
    study: Study, keys: list[str], records: list[dict[str, Any]] | None = None
) -> dict[str, Any]:
    """Rewrite the study's ``rows.csv`` and ``run.json`` (in :attr:`Study.folder`) from the
    stored tasks (``records``, when the caller has read them already). ``run.json``'s
    ``versions`` are those of the latest task's run (:func:`_task_versions`)."""
    out = study.folder
    out.mkdir(parents=True, exist_ok=True)
    recs = records if records is not None else task_records(study, keys)
    rows = study_rows(study, keys, records=recs)
    atomic_write(out / "rows.csv", lambda tmp: rows.to_csv(tmp, index=False))
    info = {
        "study": study.study,
        "chapter": study.chapter,
        "study_file": study.file,
        "study_hash": study.hash,
        "tasks_total": len(keys),
        "tasks_done": len(recs),
        "complete": len(recs) == len(keys),
        "commits": sorted({r.get("commit", "unknown") for r in recs}),
        "cpu_hours": round(sum(float(r.get("cpu_s", 0.0)) for r in recs) / 3600, 3),
        "wall_hours": round(sum(float(r.get("wall_s", 0.0)) for r in recs) / 3600, 3),
        "versions": _task_versions(recs),
        "budget_cpu_hours": study.budget_cpu_hours,
    }
    if study.supersedes:
        info["supersedes"] = study.supersedes
    if study.beside:
        info["beside"] = study.beside
    atomic_write(out / "run.json", lambda tmp: tmp.write_text(json.dumps(info, indent=1) + "\n"))
    return info


def gates_path(chapter: str, tag: str = "") -> Path:
    """``params/<chapter>[.<tag>].gates.yml``: the post-hoc validity review of a study whose
    file predates gates (the v1 studies); its gates are applied beside the file's own."""
    return project_root() / "params" / f"{chapter}{'.' + tag if tag else ''}.gates.yml"


def study_gates(study: Study) -> list[dict[str, Any]]:
    """The study file's gates, then those of its review file (:func:`gates_path`)."""
    p = gates_path(study.chapter, study.tag)
    review = load_review(p)[0] if p.is_file() else []
    return [*study.gates, *review]


def study_comparisons(study: Study) -> list[dict[str, Any]]:
    """The study's comparisons, with its review file's ``retest`` entries applied
    (:func:`thesis_lib.stats.gates.apply_retests`: e.g. an equivalence claim retested by TOST)."""
    p = gates_path(study.chapter, study.tag)
    retests = load_review(p)[1] if p.is_file() else []
    return apply_retests(study.comparisons, retests)


def _parity_table() -> pd.DataFrame | None:
    """``studies/parity/parity.csv`` (the fidelity gates' evidence), or ``None``."""
    p = project_root() / "studies" / "parity" / "parity.csv"
    return pd.read_csv(p) if p.is_file() else None


def read_run_info(study: Study) -> dict[str, Any]:
    """The study's ``run.json`` (``{}`` before it ran)."""
    p = study.folder / "run.json"
    return json.loads(p.read_text()) if p.exists() else {}


def is_complete(study: Study, info: Mapping[str, Any] | None = None) -> bool:
    """Every task of ``study`` has run under its current file (``info``: its ``run.json``)."""
    info = read_run_info(study) if info is None else info
    return bool(info.get("complete")) and info.get("study_hash") == study.hash


def evaluate_study(study: Study | str, reps: int = 10_000) -> pd.DataFrame:
    """The pre-registered comparisons of a finished study (a :class:`Study`, or its reference:
    ``04_hdt``, ``04_hdt:v2``); raises if it is incomplete, or if a row the comparisons read is
    wrong (the error names its task file and what is wrong)."""
    if not isinstance(study, Study):
        study = load_study(study)
    info = read_run_info(study)
    if not is_complete(study, info):
        raise RuntimeError(
            f"study {study.study} of {study.chapter} is not complete "
            f"({info.get('tasks_done', 0)}/{info.get('tasks_total', '?')} tasks); "
            f"run 'thesis study {study.ref}' first"
        )
    rows = study_rows(study)
    if "task_key" in rows:  # a bad row is named by its task file (thesis_lib.stats.score_matrix)
        where = study.folder.relative_to(project_root()).as_posix()
        rows = rows.assign(task_file=f"{where}/tasks/" + rows["task_key"] + ".json")
    res = evaluate_rows(study, rows, reps)
    res.insert(0, "study", study.study)
    res.insert(1, "chapter", study.chapter)
    return res


def evaluate_rows(study: Study, rows: pd.DataFrame, reps: int = 10_000) -> pd.DataFrame:
    """``study``'s pre-registered comparisons, gates and parity evidence applied to ``rows``
    (its scale-check rows left out), complete or not: what :func:`evaluate_study` computes
    for a finished study, e.g. for rows made by hand to test a study file before it runs."""
    if "scale" in rows:
        rows = rows[rows["scale"].fillna("study") == "study"]
    c = study.columns
    return evaluate_comparisons(
        rows,
        study_comparisons(study),
        metric=study.metric,
        method_col=c["method"],
        setting_col=c["setting"],
        seed_col=c["seed"],
        reps=reps,
        interval=study.interval or DEFAULT_INTERVAL,
        gates=study_gates(study),
        parity=_parity_table(),
    )


CLAIMS_COLUMNS = [
    "claim",
    "statement",
    "verdict",
    "effect",
    "ci_low",
    "ci_high",
    "prob_improvement",
    "kind",
    "margin",
    "seeds",
    "settings",
    "decided_by",
    "validity",
    "chapter",
    "study",
    "study_commit",
    "comparisons",
    "history",
]


def history_entries(history: Any) -> list[tuple[str, str]]:
    """``(study, status)`` of each study in a ``history`` cell of ``claims.csv`` (what
    :func:`write_claims` writes), first to last; the status is a verdict or the progress of a
    study still running. An empty cell (no study) gives ``[]``.

    >>> history_entries("ur3-c14-v1: untestable; ur3-c14-v2: pending, 0/52 tasks")
    [('ur3-c14-v1', 'untestable'), ('ur3-c14-v2', 'pending, 0/52 tasks')]
    """
    if not isinstance(history, str) or not history.strip():
        return []
    entries = []
    for part in history.split("; "):
        study, _, status = part.partition(": ")
        entries.append((study.strip(), status.strip()))
    return entries


def write_claims(chapters: Mapping[str, Chapter], reps: int = 10_000) -> pd.DataFrame:
    """``studies/claims.csv``: one row per claim of CLAIMS.md, ``pending`` where no study
    (or no complete one) answers it yet. ``chapters``: the registry
    (``thesis_lib.chapters.CHAPTERS``), which counts a pending study's tasks.

    Where several studies of a chapter pre-register a claim (a later study that supersedes an
    earlier one), the verdict is the last complete one's, and ``history`` lists every study of
    the claim, first to last, with its verdict or its progress (``hdt-c1c3-v1: untestable;
    hdt-c1c3-v2: pending, 12/450 tasks``); a study replaced before it completed, with where it
    stopped (``defender-c7c9-v2: superseded by defender-c7c9-v3 at 5/26 tasks``). A study read
    ``beside`` another is listed in ``history`` (``dm-c6-gpu-v1: fails, beside dm-c4c6-v2``) and
    decides nothing."""
    rows: dict[str, dict[str, Any]] = {}
    history: dict[str, list[str]] = {}
    studies = [load_study(p) for p in study_files()]
    replaced_by = {s.supersedes: s.study for s in studies if s.supersedes}
    for study in studies:
        info = read_run_info(study)
        claims = dict.fromkeys(c["claim"] for c in study.comparisons)
        aside = f", beside {study.beside}" if study.beside else ""
        if not is_complete(study, info):
            done = info.get("tasks_done", 0) if info.get("study_hash") == study.hash else 0
            total = len(study_tasks(study, chapters[study.chapter]))
            later = replaced_by.get(study.study)
            for cl in claims:
                history.setdefault(cl, []).append(
                    f"{study.study}: superseded by {later} at {done}/{total} tasks"
                    if later
                    else f"{study.study}: pending, {done}/{total} tasks{aside}"
                )
                if later or study.beside:
                    continue  # the study that replaces it, or the one it is read beside, answers
                if rows.get(cl, {}).get("verdict", "pending") != "pending":
                    continue  # an earlier complete study answers it until this one completes
                rows[cl] = {
                    "claim": cl,
                    "verdict": "pending",
                    "chapter": study.chapter,
                    "study": study.study,
                    "comparisons": f"{done}/{total} tasks done",
                }
            continue
        verdicts = claim_verdicts(evaluate_study(study, reps=reps))
        for r in verdicts.to_dict("records"):
            history.setdefault(r["claim"], []).append(f"{study.study}: {r['verdict']}{aside}")
            if study.beside:
                continue  # read beside another study: listed, never the claim's verdict
            rows[r["claim"]] = {
                **r,
                "chapter": study.chapter,
                "study": study.study,
                "study_commit": ",".join(info.get("commits", [])),
            }
    table = []
    for cid, (_sec, statement) in CLAIMS.items():
        r = rows.get(cid, {"claim": cid, "verdict": "pending", "comparisons": "no study yet"})
        r = {**r, "history": "; ".join(history.get(cid, []))}
        table.append({**{k: None for k in CLAIMS_COLUMNS}, **r, "statement": statement})
    df = pd.DataFrame(table, columns=CLAIMS_COLUMNS)
    out = studies_dir()
    out.mkdir(parents=True, exist_ok=True)
    # two study processes may rewrite this at once: a reader never sees half of it
    atomic_write(out / "claims.csv", lambda tmp: df.to_csv(tmp, index=False))
    return df


__all__ = [
    "Study",
    "chapter_studies",
    "superseded_by",
    "evaluate_rows",
    "evaluate_study",
    "history_entries",
    "is_complete",
    "read_run_info",
    "split_ref",
    "study_files",
    "study_ref",
    "load_study",
    "parse_study",
    "run_study",
    "studies_dir",
    "study_config",
    "study_path",
    "study_rows",
    "task_records",
    "study_task_functions",
    "reuse_tasks",
    "study_tasks",
    "cpu_hours_left",
    "write_claims",
    "write_study_summary",
]
