"""``thesis study <chapter>`` and ``thesis claims``: run pre-registered studies, judge claims.

thesis study 04_hdt                   # run or resume params/04_hdt.study.yml
thesis study 04_hdt --executor local -j 2
thesis study 04_hdt --status          # tasks done / total, CPU-hours so far and left (estimate)
thesis study 05_decision_mamba 03_defender -j 2   # one study after the other
thesis study 03_defender 02_clfd -j 2 --keep-going   # unattended: a failed task stops nothing
thesis claims                         # studies/claims.csv from every committed study
"""

from __future__ import annotations

import argparse
import json
import sys


def _status(chapter: str) -> dict:
    """Progress of one study; refreshes its ``rows.csv`` / ``run.json`` once a task has run
    (an unstarted study gets no files)."""
    from thesis_lib.book import study as st
    from thesis_lib.sweep import TaskStore

    s = st.load_study(chapter)
    keys = [t.key for t in st.study_tasks(s)]
    failed = [k for k in TaskStore(st.studies_dir(chapter) / "tasks").failures() if k in keys]
    if st.study_rows(s, keys).empty:
        out = {"study": s.study, "tasks_done": 0, "tasks_total": len(keys), "cpu_hours": 0.0}
    else:
        info = st.write_study_summary(s, keys)
        out = {k: info[k] for k in ("study", "tasks_done", "tasks_total", "cpu_hours", "commits")}
        left = info["tasks_total"] - info["tasks_done"]
        if left:  # at the mean cost of the tasks done so far (tasks of a grid differ)
            out["cpu_hours_left_estimate"] = round(info["cpu_hours"] / info["tasks_done"] * left, 1)
    if failed:  # the last run of these tasks raised: tasks/failed/<key>.txt says why
        out["tasks_failed"] = failed
    return out


def _cmd_study(args: argparse.Namespace) -> int:
    from thesis_lib.book import study as st

    for chapter in args.chapter:  # every study file first: a typo fails before hours of work
        st.load_study(chapter)
    if args.status:
        for chapter in args.chapter:
            print(json.dumps(_status(chapter), indent=1))
        return 0
    from thesis_lib.sweep import GridFailed

    failed = []
    for chapter in args.chapter:  # in order; a complete study finds every task stored
        try:
            rows = st.run_study(
                chapter,
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
        print(f"{chapter}: {len(rows)} rows in {st.studies_dir(chapter)}")
    if failed:
        print(f"Failed tasks in: {', '.join(failed)}; rerun to retry them.", file=sys.stderr)
        return 1
    return 0


def _cmd_claims(args: argparse.Namespace) -> int:
    from thesis_lib.book.study import studies_dir, write_claims

    df = write_claims(reps=args.reps)
    print(df[["claim", "verdict", "effect", "ci_low", "ci_high", "chapter"]].to_string(index=False))
    print(f"-> {studies_dir() / 'claims.csv'}", file=sys.stderr)
    return 0


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add ``study`` and ``claims`` to the ``thesis`` command."""
    p = subparsers.add_parser("study", help="run or resume a chapter's pre-registered study")
    p.add_argument(
        "chapter",
        nargs="+",
        help="e.g. 04_hdt (reads params/<chapter>.study.yml); several run one after another",
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
    p.add_argument("--status", action="store_true", help="print progress; run nothing")
    p.add_argument(
        "-k",
        "--keep-going",
        action="store_true",
        help="a failed task stops nothing: run the others (and the next studies), keep its "
        "traceback in studies/<chapter>/tasks/failed/, exit 1 at the end",
    )
    p.set_defaults(func=_cmd_study)
    c = subparsers.add_parser("claims", help="write studies/claims.csv from the studies")
    c.add_argument("--reps", type=int, default=10_000, help="bootstrap replications")
    c.set_defaults(func=_cmd_claims)
