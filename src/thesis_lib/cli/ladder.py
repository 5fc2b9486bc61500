"""``thesis ladder``: the scale ladder of the sequence models (issue #36), by default the
current ladder file ``params/ladder.v2.yml``; its runs and table go to ``studies/ladder.v2/``
(a file ``params/<name>.yml`` keeps its runs in ``studies/<name>/tasks``).

thesis ladder --rungs "d32 L1" -j 2     # run what is missing of one rung; run again to resume
thesis ladder --rungs "d64 L2" -j 2 --commit-every 900   # and commit the runs as they land
thesis ladder -j 2                      # every rung (d128 L3: GPU-sized, about 2 h a run on CPU)
thesis ladder --table                   # the table and the chosen size from the stored runs only
thesis ladder -f params/ladder.yml --table   # the first ladder file, read from its own runs
thesis ladder --curve hopper/medium-replay "d32 L1" DM-noRTG 0,1,2 --every 1000 --to 36000 -j 2
    # learning curves of ladder runs (their own config, evaluated every 1,000 updates): is a
    # score at a checkpoint a point or a trend? Stored in studies/<name>/curves/, resumable;
    # all stored curves are written to studies/<name>/curves.csv
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any


def write_ladder_table(ladder: Any, tasks: list[Any], store: Path) -> Any:
    """The table of ``ladder`` (a :class:`~thesis_lib.ladder.Ladder`) from the runs of its
    ``tasks`` stored in ``store``, written to ``ladder.csv`` beside the store; returns it."""
    from thesis_lib.ladder import ladder_table
    from thesis_lib.sweep import TaskStore

    st = TaskStore(store)
    rows = [r for t in tasks if st.has(t.key) for r in st.read(t.key)["rows"]]
    table = ladder_table(ladder, rows)
    out = store.parent / "ladder.csv"
    out.parent.mkdir(parents=True, exist_ok=True)
    table.to_csv(out, index=False, float_format="%.3f")
    return table


def commit_ladder(path: Path, store: Path, root: Path | None = None) -> str | None:
    """Commit the runs the ladder file ``path`` stored in ``store`` and its table (rewritten
    first), and nothing else: one commit of that folder only
    (:func:`~thesis_lib.cli.study.commit_paths`). Returns the commit message, or None when
    nothing changed.

    Raises:
        RuntimeError: ``root`` (default: the project) is not a git checkout, or git refused.
    """
    from thesis_lib.cli.study import _checkout, _stored_runs, commit_paths, count_added
    from thesis_lib.ladder import ladder_tasks, load_ladder_file
    from thesis_lib.sweep import TaskStore

    root = _checkout(root)
    ladder = load_ladder_file(path)
    every = ladder_tasks(ladder)
    folder = store.parent.resolve().relative_to(root.resolve()).as_posix()
    # a run stored while the table is rewritten is not in it: it waits for the next commit
    landed = set(_stored_runs(root, folder))
    done = sum(TaskStore(store).has(t.key) for t in every)
    write_ladder_table(ladder, every, store)
    return commit_paths(
        root,
        [folder],
        [p for p in _stored_runs(root, folder) if p not in landed],
        lambda added: (
            _landed(path.stem, count_added(added), count_added(added, "curves"))
            + f" ({done}/{len(every)})"
        ),
    )


def _landed(name: str, runs: int, curves: int) -> str:
    """A ladder commit's message: what it adds (runs, learning curves or both)."""
    parts = [f"{runs} finished run(s)"] if runs or not curves else []
    if curves:
        parts.append(f"{curves} learning curve(s)")
    return f"{name}: {' and '.join(parts)} landed"


def write_curves(store: Path) -> Any:
    """Every learning curve stored in ``store`` (``studies/<name>/curves``), as one table
    written to ``curves.csv`` beside it; returns it."""
    import pandas as pd

    from thesis_lib.ladder import CURVE_COLUMNS
    from thesis_lib.sweep import TaskStore

    st = TaskStore(store)
    rows = [r for k in st.keys() for r in st.read(k)["rows"]]
    table = pd.DataFrame(rows, columns=CURVE_COLUMNS)
    table = table.sort_values(["dataset", "rung", "method", "seed", "updates"])
    out = store.parent / "curves.csv"
    out.parent.mkdir(parents=True, exist_ok=True)
    table.to_csv(out, index=False, float_format="%.3f")
    return table


def _cmd_curve(args: argparse.Namespace, ladder: Any, store: Path, committer: Any) -> int:
    from thesis_lib.ladder import curve_task, parse_rung, run_rung
    from thesis_lib.sweep import TaskStore, run_tasks

    dataset, rung, method, seeds = args.curve
    try:
        wanted = [int(x) for x in seeds.split(",")]
    except ValueError:
        raise SystemExit(
            f"Expect SEEDS as integers separated by commas (0,1,2), got {seeds!r}."
        ) from None
    to = args.to or ladder.checkpoints[-1]
    every = 1000 if args.every is None else args.every
    tasks = [curve_task(ladder, dataset, rung, method, k, every, to) for k in wanted]
    curves = store.parent / "curves"
    st = TaskStore(curves)
    try:
        run_tasks(
            [] if args.table else [t for t in tasks if not st.has(t.key)],
            store=curves,
            n_jobs=args.jobs,
            desc="curves",
            keep_going=True,
        )
    finally:
        if committer is not None:
            committer.stop()
    table = write_curves(curves)
    at = run_rung(tasks[0].config)  # a rung-free method (BC) runs at the first rung
    mine = table[
        (table["dataset"] == dataset)
        & (table["rung"] == at)
        & (table["method"] == method)
        & table["seed"].isin(wanted)
    ]
    wide = mine.pivot_table(index="updates", columns="seed", values="score")
    where = at if at == parse_rung(rung).label else f"{at} (rung-free: the same run at {rung})"
    print(f"{method} on {dataset} at {where}: D4RL-normalised score by updates and seed")
    print(wide.to_string(float_format=lambda v: f"{v:.1f}"))
    print(f"written: {curves.parent / 'curves.csv'}")
    return 0


def _cmd_ladder(args: argparse.Namespace) -> int:
    from thesis_lib.cli.study import start_committer
    from thesis_lib.ladder import (
        CURRENT_LADDER,
        choose_rung,
        ladder_tasks,
        load_ladder_file,
        parse_rung,
    )
    from thesis_lib.paths import project_root
    from thesis_lib.sweep import TaskStore, run_tasks

    if not args.curve and (args.every is not None or args.to is not None):
        raise SystemExit("--every and --to set a learning curve: use them with --curve.")
    root = project_root()
    path = Path(args.file or root / "params" / f"{CURRENT_LADDER}.yml")
    ladder = load_ladder_file(path)
    every = ladder_tasks(ladder)
    # only some rungs: unknown ones fail here, before any run
    todo = ladder_tasks(ladder, [parse_rung(r) for r in args.rungs]) if args.rungs else every
    store = Path(args.store or root / "studies" / path.stem / "tasks")
    st = TaskStore(store)
    committer = None
    if args.commit_every is not None and not args.table:
        if not store.resolve().is_relative_to(root.resolve()):
            raise SystemExit(f"{store} is not inside the project {root}: nothing to commit it to.")
        committer = start_committer(lambda: commit_ladder(path, store), args.commit_every)
    if args.curve:
        return _cmd_curve(args, ladder, store, committer)
    if not args.table:
        try:
            run_tasks(
                [t for t in todo if not st.has(t.key)],
                store=store,
                n_jobs=args.jobs,
                desc="ladder",
                keep_going=True,
            )
        finally:
            if committer is not None:
                committer.stop()  # a last commit, with the table of every run stored
    table = write_ladder_table(ladder, every, store)
    show = table[["dataset", "rung", "updates", "method", "seeds", "mean", "ci_low", "ci_high",
                  "data_mean", "bc_reference", "passes"]]  # fmt: skip
    if show.empty:
        print(f"no ladder runs stored in {store} yet")
    else:
        print(show.to_string(index=False, float_format=lambda v: f"{v:.1f}"))
    chosen, why = choose_rung(ladder, table)
    print(f"chosen: {chosen[0]} at {chosen[1]:,} updates: {why}" if chosen else f"none yet: {why}")
    print(f"written: {store.parent / 'ladder.csv'}")
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
    cmd.add_argument(
        "--commit-every",
        type=float,
        metavar="SECONDS",
        help="commit the ladder's folder (runs and table) every SECONDS and at the end, as "
        "commits of that folder only, so that a run cut off loses at most SECONDS of runs",
    )
    cmd.add_argument(
        "--curve",
        nargs=4,
        metavar=("DATASET", "RUNG", "METHOD", "SEEDS"),
        help="learning curves of ladder runs instead (SEEDS: 0,1,2): each run's own config, "
        "evaluated every --every updates to --to; stored in studies/<name>/curves/",
    )
    cmd.add_argument(
        "--every", type=int, help="--curve: updates between evaluations (default 1000)"
    )
    cmd.add_argument(
        "--to", type=int, help="--curve: updates to train to (default: the last checkpoint)"
    )
    cmd.set_defaults(func=_cmd_ladder)
