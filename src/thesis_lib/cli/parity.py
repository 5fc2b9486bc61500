"""``thesis parity``: our methods against a peer library's at equal config (``params/parity.yml``).

thesis parity --setup                  # make the peer venv (d3rlpy 2.8.1) once
thesis parity                          # run what is missing, write studies/parity/parity.csv
thesis parity --only dt-study bc-study -j 2
thesis parity --table                  # print the table from the stored runs only
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any


def _cmd_parity(args: argparse.Namespace) -> int:
    from thesis_lib.data.recipe import GENERATOR_VERSION
    from thesis_lib.parity import (
        can_redo,
        load_parity_file,
        parity_table,
        parity_tasks,
        setup_peer,
        unique_tasks,
    )
    from thesis_lib.paths import project_root
    from thesis_lib.sweep import TaskStore, run_tasks

    root = project_root()
    comparisons = load_parity_file(args.file or root / "params" / "parity.yml")
    if args.setup:
        print(f"peer environment: {setup_peer()}")
        return 0
    tasks = parity_tasks(comparisons)
    if args.only:
        unknown = [n for n in args.only if n not in tasks]
        if unknown:
            raise ValueError(f"Unknown comparison(s) {unknown}. Valid: {', '.join(tasks)}.")
    store = args.store or root / "studies" / "parity" / "tasks"
    st = TaskStore(store)
    if not args.table:
        chosen = {k: v for k, v in tasks.items() if not args.only or k in args.only}
        todo = [t for t in unique_tasks(chosen) if not st.has(t.key)]
        stale = [t for t in todo if not can_redo(t.config)]
        if stale:  # made on data this checkout no longer makes: their rows stay a record
            names = sorted({n for n, sides in chosen.items() for ts in sides.values()
                            for t in ts if t in stale})  # fmt: skip
            print(
                f"skipping {len(stale)} run(s) of {', '.join(names)}: their data recipe is not "
                f"this checkout's ({GENERATOR_VERSION}), so they cannot be redone",
                file=sys.stderr,
            )
        run_tasks(
            [t for t in todo if t not in stale],
            store=store,
            n_jobs=args.jobs,
            desc="parity",
            keep_going=True,
        )
    rows = {
        name: {side: [r for t in ts if st.has(t.key) for r in st.read(t.key)["rows"]]
               for side, ts in sides.items()}
        for name, sides in tasks.items()
    }  # fmt: skip
    table = parity_table(comparisons, rows)
    out = store.parent / "parity.csv"
    out.parent.mkdir(parents=True, exist_ok=True)
    table.to_csv(out, index=False, float_format="%.3f")
    show = table[["comparison", "init", "arch", "updates", "seeds", "ours", "peer", "data_mean",
                  "difference", "ci_low", "ci_high", "parity"]]  # fmt: skip
    print(show.to_string(index=False, float_format=lambda v: f"{v:.1f}"))
    print(f"written: {out}")
    return 0


def register(sub: Any) -> None:
    """Add ``thesis parity`` to the CLI's sub-commands."""
    cmd = sub.add_parser(
        "parity",
        help="our DT and BC against d3rlpy's at equal config (params/parity.yml)",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    cmd.add_argument("-f", "--file", type=Path, help="parity file (default params/parity.yml)")
    cmd.add_argument(
        "--store",
        type=Path,
        help="where the runs are stored (default studies/parity/tasks; the table beside it)",
    )
    cmd.add_argument("--only", nargs="+", metavar="NAME", help="only these comparisons")
    cmd.add_argument("-j", "--jobs", type=int, default=1, help="runs in parallel processes")
    cmd.add_argument("--setup", action="store_true", help="make the peer venv, then stop")
    cmd.add_argument("--table", action="store_true", help="no runs: the table from stored runs")
    cmd.set_defaults(func=_cmd_parity)
