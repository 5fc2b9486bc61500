"""``thesis study <chapter>`` and ``thesis claims``: run pre-registered studies, judge claims.

thesis study 04_hdt                   # run or resume params/04_hdt.study.yml
thesis study 04_hdt --executor local -j 2
thesis study 04_hdt --status          # tasks done / total, CPU-hours so far and left (estimate),
                                      # the checkpoints of unfinished tasks (their newest step)
thesis study --status                 # the same for every registered study
thesis study params/04_hdt.study.yml  # the same, named by its study file
thesis study 04_hdt:v2                # a later study of the chapter: params/04_hdt.v2.study.yml
thesis study 05_decision_mamba 03_defender -j 2   # one study after the other
thesis study 03_defender 02_clfd -j 2 --keep-going   # unattended: a failed task stops nothing
thesis study 03_defender -j 2 --commit-every 600      # and commit finished tasks every 10 min
thesis claims                         # studies/claims.csv from every committed study
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import threading
from collections.abc import Callable
from pathlib import Path


def _status(ref: str) -> dict:
    """Progress of one study (``04_hdt``, ``04_hdt:v2``); refreshes its ``rows.csv`` /
    ``run.json`` once a task has run (an unstarted study gets no files)."""
    from thesis_lib.book import study as st
    from thesis_lib.chapters import get_chapter
    from thesis_lib.sweep import TaskStore

    s = st.load_study(st.study_chapter(ref))
    tasks = st.study_tasks(s, get_chapter(s.chapter))
    keys = [t.key for t in tasks]
    failed = [k for k in TaskStore(s.folder / "tasks").failures() if k in keys]
    recs = st.task_records(s, keys)  # read once: a large study has thousands of files
    if st.study_rows(s, keys, records=recs).empty:
        out = {"study": s.study, "tasks_done": 0, "tasks_total": len(keys), "cpu_hours": 0.0}
    else:
        info = st.write_study_summary(s, keys, records=recs)
        out = {k: info[k] for k in ("study", "tasks_done", "tasks_total", "cpu_hours", "commits")}
        left = info["tasks_total"] - info["tasks_done"]
        if left:  # each at the mean cost of the finished tasks most like it
            out["cpu_hours_left_estimate"] = round(st.cpu_hours_left(s, tasks, records=recs), 1)
    if failed:  # the last run of these tasks raised: tasks/failed/<key>.txt says why
        out["tasks_failed"] = failed
    done = {r["key"] for r in recs}
    checkpoints = _checkpoints(s.folder / "tasks", [t for t in tasks if t.key not in done])
    if checkpoints:
        out["checkpoints"] = checkpoints
    return out


def _checkpoints(store: Path, tasks: list) -> list[dict]:
    """The unfinished ``tasks`` that have saved a training checkpoint (``<store>/partial/<key>/``,
    where a resumable task keeps one; the task resumes from it): running now, or cut off by
    the end of an earlier run. Each with its method and seed where its config names them, the
    newest checkpoint's step (a ``step-<n>`` folder) and when the folder last changed."""
    import datetime as dt

    from thesis_lib.sweep._tasks import SCRATCH_FOLDER

    out = []
    for t in tasks:
        folder = store / SCRATCH_FOLDER / t.key
        try:  # a running task rotates its checkpoints, and removes the folder when it ends
            parts = list(folder.iterdir())
            changed = max([folder.stat().st_mtime] + [p.stat().st_mtime for p in parts])
        except (FileNotFoundError, NotADirectoryError):
            continue
        entry: dict = {"task": t.key}
        for name in ("method", "label", "seed", "scale"):
            if t.config.get(name) is not None:
                entry["method" if name == "label" else name] = t.config[name]
        steps = [
            int(p.name.removeprefix("step-"))
            for p in parts
            if p.name.startswith("step-") and p.name.removeprefix("step-").isdigit()
        ]
        if steps:
            entry["checkpoint_step"] = max(steps)
        entry["updated"] = dt.datetime.fromtimestamp(changed, dt.UTC).isoformat(timespec="seconds")
        out.append(entry)
    return out


#: what :func:`commit_studies` leaves out (git pathspec globs): failed tasks' tracebacks,
#: temporary files and the locks of running tasks (:func:`~thesis_lib.book.study.task_locks`).
NOT_COMMITTED = (
    "studies/**/tasks/failed/**",
    "studies/**/tasks/partial/**",
    "**/.*.tmp",
    "**/.*.tmp.*",
    "studies/**/tasks/*.lock",
)


def _git(root: Path, *args: str) -> subprocess.CompletedProcess:
    return subprocess.run(["git", *args], cwd=root, capture_output=True, text=True)


def _rel(folder: Path) -> str:
    """``folder`` (under the project's ``studies/``) as a path relative to the project."""
    from thesis_lib.paths import project_root

    return folder.relative_to(project_root()).as_posix()


def _checkout(root: Path | None) -> Path:
    from thesis_lib.paths import project_root

    root = Path(root) if root is not None else project_root()
    if _git(root, "rev-parse", "--is-inside-work-tree").returncode != 0:
        raise RuntimeError(f"{root} is not a git checkout: nothing to commit the studies to.")
    return root


def commit_studies(chapters: list[str], root: Path | None = None) -> str | None:
    """Commit what the studies ``chapters`` (``04_hdt``, ``04_hdt:v2``) stored, and nothing
    else.

    Refreshes each study's ``rows.csv`` / ``run.json`` (:func:`_status`) and
    ``studies/claims.csv`` (:func:`~thesis_lib.book.study.write_claims`: the verdicts of a
    study that just completed, the progress of the others), then commits
    each study's folder (``studies/<chapter>/``, ``studies/<chapter>/<tag>/``) and
    ``studies/claims.csv`` as one commit of those paths only: other
    changes in the checkout, staged or not, stay as they are. Returns the commit message, or
    None when nothing changed. Where ``claims.csv`` cannot be rebuilt (another study's file
    that this code cannot read: one written after a long run started, with a key newer than
    the run's code), the study folders are committed without it, and the message says why.

    Raises:
        RuntimeError: ``root`` (default: the project) is not a git checkout, or git refused
            (another git command holding the index lock, say); the message has git's words.
    """
    root = _checkout(root)
    # the runs stored now: a run that lands while the summaries are refreshed (seconds) is not
    # in them, so it waits for the next commit, with the rows.csv that has it
    landed = set(_stored_runs(root))
    summary = []
    for chapter in chapters:
        s = _status(chapter)
        summary.append(f"{s['study']} {s['tasks_done']}/{s['tasks_total']}")
    stale = ""
    if chapters:
        from thesis_lib.book.study import write_claims
        from thesis_lib.chapters import CHAPTERS

        try:
            write_claims(CHAPTERS)
        except Exception as e:  # another study's file this code cannot read (a newer key):
            # the runs are what must not be lost; claims.csv waits for a rebuild
            stale = f"; studies/claims.csv not rebuilt: {e}"
            print(f"claims.csv not rebuilt, the tasks are committed alone: {e}", file=sys.stderr)
    from thesis_lib.book.study import _name_parts, load_study, studies_dir, study_files, study_ref

    studies = [load_study(c) for c in chapters]
    paths = [*(_rel(s.folder) for s in studies)]
    if not stale:
        paths.append("studies/claims.csv")
    # a chapter's first study's folder holds its later studies' folders: not theirs unless named
    named = {s.ref for s in studies}
    # (from the files' names alone: a later study's file need not be readable by this code)
    others = {
        _rel(studies_dir(chapter, tag))
        for s in studies
        if not s.tag
        for chapter, tag in map(_name_parts, study_files())
        if chapter == s.chapter and tag and study_ref(chapter, tag) not in named
    }
    paths = [p for p in paths if (root / p).exists()]
    if not paths:
        return None
    others |= {p for p in _stored_runs(root) if p not in landed}
    summary_text = "; ".join(summary) + stale
    return commit_paths(
        root,
        paths,
        others,
        lambda added: f"studies: {count_added(added)} finished task(s) landed ({summary_text})",
    )


def _stored_runs(root: Path, under: str = "studies") -> list[str]:
    """The stored runs below ``root / under`` (``*/tasks/*.json`` and a ladder's
    ``*/curves/*.json``), relative to ``root``."""
    found = [*(root / under).glob("**/tasks/*.json"), *(root / under).glob("**/curves/*.json")]
    return [p.relative_to(root).as_posix() for p in found]


def count_added(added: list[str], folder: str = "tasks") -> int:
    """How many of the ``added`` paths are stored runs in a ``<folder>/`` (``*/<folder>/*.json``)."""
    return sum(f"/{folder}/" in p and p.endswith(".json") for p in added)


def commit_paths(
    root: Path,
    paths: list[str],
    others: set[str] | list[str],
    message: Callable[[list[str]], str],
) -> str | None:
    """Stage ``paths`` (less ``others`` and :data:`NOT_COMMITTED`, whatever .gitignore says)
    and commit them alone, with ``message(added)`` (``added``: the paths of the files the
    commit adds; :func:`count_added` counts the kinds); other changes in the checkout, staged
    or not, stay as they are. Returns the message, or None when nothing changed.

    Raises:
        RuntimeError: git refused (the message has git's words).
    """
    excluded = [
        *(f":(exclude,glob){g}" for g in NOT_COMMITTED),
        *(f":(exclude){o}" for o in others),
    ]
    r = _git(root, "add", "--", *paths, *excluded)
    if r.returncode != 0:
        raise RuntimeError(f"git add failed: {r.stderr.strip()}")
    only = [*paths, *(f":(exclude){o}" for o in others)]
    if _git(root, "diff", "--cached", "--quiet", "--", *only).returncode == 0:
        return None
    added = _git(root, "diff", "--cached", "--name-only", "--diff-filter=A", "--", *only).stdout
    msg = message(added.splitlines())
    r = _git(root, "commit", "-q", "-m", msg, "--", *only)
    if r.returncode != 0:
        raise RuntimeError(f"git commit failed: {r.stderr.strip() or r.stdout.strip()}")
    return msg


def start_committer(
    what: list[str] | Callable[[], str | None], every: float, root: Path | None = None
) -> _Committer:
    """``--commit-every``: a started :class:`_Committer`, after the checks that fail before
    hours of work (``SystemExit``): ``every`` positive, ``root`` (default: the project) a git
    checkout."""
    if every <= 0:
        raise SystemExit(f"--commit-every must be positive seconds, not {every}.")
    try:
        _checkout(root)
    except RuntimeError as e:
        raise SystemExit(str(e)) from e
    return _Committer(what, every).start()


class _Committer:
    """Calls :func:`commit_studies` of ``what`` (the studies' chapters), or ``what`` itself (a
    function that commits and returns its message or None; ``thesis ladder``'s), every
    ``every`` seconds in a thread, and once at :meth:`stop`; a refused commit is reported and
    retried next time."""

    def __init__(self, what: list[str] | Callable[[], str | None], every: float) -> None:
        if callable(what):
            self._commit = what
        else:
            chapters = list(what)
            self._commit = lambda: commit_studies(chapters)
        self.every = float(every)
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._loop, daemon=True)

    def start(self) -> _Committer:
        self._thread.start()
        return self

    def _loop(self) -> None:
        while not self._stop.wait(self.every):
            self.commit()

    def commit(self) -> None:
        try:
            msg = self._commit()
        except Exception as e:  # a commit refused now is retried at the next interval
            print(f"commit skipped: {e}", file=sys.stderr)
        else:
            if msg:
                print(msg, file=sys.stderr)

    def stop(self) -> None:
        self._stop.set()
        self._thread.join()
        self.commit()


def _cmd_study(args: argparse.Namespace) -> int:
    from thesis_lib.book.runner import KERNEL_ENV_DEFAULTS

    # MuJoCo picks its OpenGL back end once, at its first import. One process runs the studies
    # one after another (and its in-process tasks), so a study that renders (02's CLfD frames)
    # after one that only simulates (03's locomotion) must find the headless back end already
    # chosen, as a chapter's kernel does.
    os.environ.setdefault("MUJOCO_GL", KERNEL_ENV_DEFAULTS["MUJOCO_GL"])
    from thesis_lib.book import study as st
    from thesis_lib.chapters import get_chapter

    if not args.chapter:
        if not args.status:
            raise SystemExit(
                "Name the studies to run (e.g. thesis study 04_hdt); without one, only --status "
                "(every study) is allowed."
            )
        args.chapter = [st.load_study(p).ref for p in st.study_files()]
    # every study file first (names, values, metrics): a typo fails before hours of work
    args.chapter = [st.study_chapter(c) for c in args.chapter]
    for ref in args.chapter:
        s = st.load_study(ref)
        st.study_config(s, get_chapter(s.chapter))
    if args.status:
        for chapter in args.chapter:
            print(json.dumps(_status(chapter), indent=1))
        return 0
    committer = None
    if args.commit_every is not None:
        committer = start_committer(args.chapter, args.commit_every)
    try:
        failed = _run_studies(args)
    finally:
        if committer is not None:
            committer.stop()  # a last commit: a study that just completed lands with its verdicts
    if failed:
        print(f"Failed tasks in: {', '.join(failed)}; rerun to retry them.", file=sys.stderr)
        return 1
    return 0


def _run_studies(args: argparse.Namespace) -> list[str]:
    from thesis_lib.book import study as st
    from thesis_lib.chapters import get_chapter
    from thesis_lib.sweep import GridFailed

    failed = []
    for chapter in args.chapter:  # in order; a complete study finds every task stored
        study = st.load_study(chapter)
        try:
            rows = st.run_study(
                get_chapter(study.chapter),
                study=study,
                executor=args.executor,
                n_jobs=args.jobs,
                address=args.address,
                force=args.force,
                keep_going=args.keep_going,
            )
        except GridFailed as e:  # --keep-going: the next study still runs
            print(f"{chapter}: {e}", file=sys.stderr)
            failed.append(f"{chapter} ({len(e.failures)} task(s))")
            continue
        print(f"{chapter}: {len(rows)} rows in {study.folder}")
    return failed


def _cmd_claims(args: argparse.Namespace) -> int:
    from thesis_lib.book.study import studies_dir, write_claims
    from thesis_lib.chapters import CHAPTERS

    df = write_claims(CHAPTERS, reps=args.reps)
    print(df[["claim", "verdict", "effect", "ci_low", "ci_high", "chapter"]].to_string(index=False))
    print(f"-> {studies_dir() / 'claims.csv'}", file=sys.stderr)
    return 0


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add ``study`` and ``claims`` to the ``thesis`` command."""
    p = subparsers.add_parser("study", help="run or resume a chapter's pre-registered study")
    p.add_argument(
        "chapter",
        nargs="*",
        help="e.g. 04_hdt or params/04_hdt.study.yml (reads params/<chapter>.study.yml), "
        "04_hdt:v2 (a later study, params/04_hdt.v2.study.yml); several run one after another; "
        "none, with --status: every study",
    )
    p.add_argument(
        "--executor",
        choices=["inprocess", "local", "ray"],
        default=None,
        help="where tasks run (default: in this process; local with -j > 1)",
    )
    p.add_argument("-j", "--jobs", type=int, default=None, help="parallel tasks (local)")
    p.add_argument("--address", default=None, help="Ray cluster address (or $RAY_ADDRESS)")
    p.add_argument("--force", action="store_true", help="recompute finished tasks")
    p.add_argument(
        "--status",
        action="store_true",
        help="print progress (tasks done, CPU-hours so far and left, the newest checkpoint of each unfinished task); run nothing",
    )
    p.add_argument(
        "-k",
        "--keep-going",
        action="store_true",
        help="a failed task stops nothing: run the others (and the next studies), keep its "
        "traceback in studies/<chapter>/tasks/failed/, exit 1 at the end",
    )
    p.add_argument(
        "--commit-every",
        type=float,
        default=None,
        metavar="SECONDS",
        help="commit studies/<chapter>/ (and studies/claims.csv) every SECONDS and at the end, "
        "as commits of those paths only, so that a run cut off loses at most SECONDS of tasks",
    )
    p.set_defaults(func=_cmd_study)
    c = subparsers.add_parser("claims", help="write studies/claims.csv from the studies")
    c.add_argument("--reps", type=int, default=10_000, help="bootstrap replications")
    c.set_defaults(func=_cmd_claims)
