"""``thesis ladder``: the scale ladder of the sequence models (issue #36), by default the
current ladder file ``params/ladder.v2.yml``; its runs and table go to ``studies/ladder.v2/``
(a file ``params/<name>.yml`` keeps its runs in ``studies/<name>/tasks``).

thesis ladder --rungs "d32 L1" -j 2     # run what is missing of one rung; run again to resume
thesis ladder -j 2                      # every rung (d128 L3: GPU-sized, about 2 h a run on CPU)
thesis ladder --table                   # the table and the chosen size from the stored runs only
thesis ladder -f params/ladder.yml --table   # the first ladder file, read from its own runs
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any


def _cmd_ladder(args: argparse.Namespace) -> int:
    from thesis_lib.ladder import (
        CURRENT_LADDER,
        choose_rung,
        ladder_table,
        ladder_tasks,
        load_ladder_file,
        parse_rung,
    )
    from thesis_lib.paths import project_root
    from thesis_lib.sweep import TaskStore, run_tasks

    root = project_root()
    path = Path(args.file or root / "params" / f"{CURRENT_LADDER}.yml")
    ladder = load_ladder_file(path)
    every = ladder_tasks(ladder)
    # only some rungs: unknown ones fail here, before any run
    todo = ladder_tasks(ladder, [parse_rung(r) for r in args.rungs]) if args.rungs else every
    store = Path(args.store or root / "studies" / path.stem / "tasks")
    st = TaskStore(store)
    if not args.table:
        run_tasks(
            [t for t in todo if not st.has(t.key)],
            store=store,
            n_jobs=args.jobs,
            desc="ladder",
            keep_going=True,
        )
    rows = [r for t in every if st.has(t.key) for r in st.read(t.key)["rows"]]
    table = ladder_table(ladder, rows)
    out = store.parent / "ladder.csv"
    out.parent.mkdir(parents=True, exist_ok=True)
    table.to_csv(out, index=False, float_format="%.3f")
    show = table[["dataset", "rung", "updates", "method", "seeds", "mean", "ci_low", "ci_high",
                  "data_mean", "bc_reference", "passes"]]  # fmt: skip
    if show.empty:
        print(f"no ladder runs stored in {store} yet")
    else:
        print(show.to_string(index=False, float_format=lambda v: f"{v:.1f}"))
    chosen, why = choose_rung(ladder, table)
    print(f"chosen: {chosen[0]} at {chosen[1]:,} updates: {why}" if chosen else f"none yet: {why}")
    print(f"written: {out}")
    return 0


def register(sub: Any) -> None:
    """Add ``thesis ladder`` to the CLI's sub-commands."""
    cmd = sub.add_parser(
        "ladder",
        help="the sequence models' scale ladder (params/ladder.v2.yml)",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    cmd.add_argument(
        "-f", "--file", type=Path, help="ladder file (default params/ladder.v2.yml, the current)"
    )
    cmd.add_argument(
        "--store",
        type=Path,
        help="where the runs are stored (default studies/<file name>/tasks; the table beside it)",
    )
    cmd.add_argument("--rungs", nargs="+", metavar="RUNG", help='only these rungs, e.g. "d32 L1"')
    cmd.add_argument("-j", "--jobs", type=int, default=1, help="runs in parallel processes")
    cmd.add_argument("--table", action="store_true", help="no runs: the table from stored runs")
    cmd.set_defaults(func=_cmd_ladder)
