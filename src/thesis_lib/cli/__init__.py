"""The ``thesis`` command: run chapters, build the book, make data sets, run benchmarks.

The CLI and the notebooks are the only code that imports ``thesis_lib.chapters``.

    thesis run 01_background -p rl_timesteps 20000      # one chapter, papermill underneath
    thesis run 01_background -f params/01_background.full.yml
    thesis book -j 2                                    # every chapter, then the HTML book
    thesis run 04_hdt -j 2                              # the chapter's tasks in 2 processes
    thesis run 04_hdt --profile full --executor ray     # tasks on the Ray cluster at $RAY_ADDRESS
    thesis params --check                               # parameters cells/params files vs Config
    thesis data generate --task hopper --tier medium    # see 'thesis data --help'
    thesis bench dtw                                    # benchmarks/bench_dtw.py
    thesis parity                                       # our DT/BC against d3rlpy's, see --help
    thesis ladder --rungs "d32 L1" -j 2                 # the sequence models' scale ladder

Errors in what you typed are reported in one line; THESIS_DEBUG=1 shows the traceback.
"""

from __future__ import annotations

import argparse
import importlib
import os
import subprocess
import sys
from pathlib import Path


def _sweep_env(args: argparse.Namespace) -> dict[str, str]:
    """The kernel environment from ``--executor/--address/--jobs|--task-jobs/--force``.

    Raises:
        ValueError: bad combination (see :func:`thesis_lib.book.runner.sweep_environment`).
        ImportError: ``--executor ray`` without Ray installed (says ``pip install ".[ray]"``).
    """
    from thesis_lib.book.runner import sweep_environment

    env = sweep_environment(args.executor, args.task_jobs, args.address, args.force)
    if env.get("THESIS_EXECUTOR") == "ray":
        from thesis_lib.sweep import require_ray

        require_ray()  # fail here, not in the middle of the notebook
    return env


def _cmd_run(args: argparse.Namespace) -> int:
    from thesis_lib.book import ChapterFailed, resolve_chapter, run_chapter
    from thesis_lib.book.params import parse_value
    from thesis_lib.chapters import CHAPTERS

    params = {name: parse_value(value) for name, value in (args.param or [])}
    profile: str | Path | None = args.file or args.profile
    try:
        env = _sweep_env(args)
        chapter = resolve_chapter(args.chapter)
        result = run_chapter(
            CHAPTERS.get(chapter, chapter),
            params,
            profile=profile,
            output=args.output,
            progress=not args.quiet,
            env=env,
        )
    except (ValueError, FileNotFoundError, ImportError, ChapterFailed) as err:
        print(f"thesis run: {err}", file=sys.stderr)
        return 1
    print(f"{result.chapter}: executed in {result.wall_time_s:.0f} s -> {result.output}")
    return 0


def _cmd_book(args: argparse.Namespace) -> int:
    from thesis_lib.book import ChapterFailed, run_chapters
    from thesis_lib.book.runner import build_book
    from thesis_lib.chapters import CHAPTERS

    try:
        if not args.no_run:
            env = _sweep_env(args)
            run_chapters(
                args.chapters or None,
                registry=CHAPTERS,
                jobs=args.jobs,
                profile=args.profile,
                env=env,
            )
        index = build_book(strict=not args.no_strict)
    except (ValueError, FileNotFoundError, ImportError, ChapterFailed, RuntimeError) as err:
        print(f"thesis book: {err}", file=sys.stderr)
        return 1
    print(f"The book is at {index}")
    return 0


def _cmd_list(args: argparse.Namespace) -> int:
    from thesis_lib.book import list_chapters, notebook_parameters

    for chapter in list_chapters():
        params = notebook_parameters(chapter)
        print(f"{chapter}: " + ", ".join(f"{k}={v!r}" for k, v in params.items()))
    return 0


def chapter_config(chapter: str) -> type:
    """The ``Config`` dataclass of the registered ``chapter`` (the one source of its
    parameters; see :data:`thesis_lib.chapters.CHAPTERS`).

    Raises:
        ValueError: no such chapter, or its package has no dataclass ``Config``.
    """
    from thesis_lib.chapters import get_chapter

    return get_chapter(chapter).Config


def _cmd_params(args: argparse.Namespace) -> int:
    from thesis_lib.book import list_chapters, project_root, resolve_chapter
    from thesis_lib.book.params import check_chapter, parameters_source, write_chapter
    from thesis_lib.chapters import CHAPTERS

    root = project_root()
    if args.chapters:
        chapters = [resolve_chapter(c, root) for c in args.chapters]
    else:
        chapters = [c for c in list_chapters(root) if c in CHAPTERS]
    status = 0
    for chapter in chapters:
        try:
            cls = chapter_config(chapter)
        except ValueError as err:
            print(f"thesis params: {err}", file=sys.stderr)
            status = 1
            continue
        if args.write:
            changed = write_chapter(chapter, cls, root)
            for path in changed:
                print(f"{chapter}: wrote {path.relative_to(root)}")
            if not changed:
                print(f"{chapter}: up to date")
        elif args.check:
            problems = check_chapter(chapter, cls, root)
            for problem in problems:
                print(f"{chapter}: {problem}", file=sys.stderr)
            if problems:
                status = 1
            else:
                print(f"{chapter}: parameters cell and params/ match {cls.__name__}")
        else:
            print(
                f"# {chapter}: the parameters cell generated from {CHAPTERS[chapter].config_file}"
            )
            print(parameters_source(cls))
    return status


def _cmd_bench(args: argparse.Namespace) -> int:
    from thesis_lib.book import project_root

    folder = project_root() / "benchmarks"
    script = folder / f"bench_{args.name}.py"
    if not script.is_file():
        names = sorted(p.stem.removeprefix("bench_") for p in folder.glob("bench_*.py"))
        print(
            f"thesis bench: no benchmark '{args.name}'. Available: {', '.join(names)}",
            file=sys.stderr,
        )
        return 1
    return subprocess.call([sys.executable, str(script), *args.rest])


def _add_sweep_options(cmd: argparse.ArgumentParser) -> None:
    """``--executor``, ``--address``, ``--force``: how a chapter's task grids run."""
    from thesis_lib.sweep import EXECUTORS

    cmd.add_argument(
        "--executor",
        choices=EXECUTORS,
        help="where the chapter's tasks run: in this kernel, local processes, or a Ray "
        "cluster (default: inprocess, or local with -j/--task-jobs > 1)",
    )
    cmd.add_argument(
        "--address",
        help="Ray cluster address (default $RAY_ADDRESS; none starts a local Ray); implies "
        "--executor ray",
    )
    cmd.add_argument(
        "--force",
        action="store_true",
        help="recompute tasks that already have a stored result under results/<chapter>/",
    )


def build_parser(command: str | None = None) -> argparse.ArgumentParser:
    """The ``thesis`` parser; with ``command``, only that sub-package's commands are imported."""
    parser = argparse.ArgumentParser(
        prog="thesis", description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    sub = parser.add_subparsers(dest="command", required=True)

    run = sub.add_parser("run", help="execute one chapter notebook with papermill")
    run.add_argument("chapter", help="chapter name, e.g. 01_background (see 'thesis list')")
    run.add_argument(
        "-p", "--param", nargs=2, action="append", metavar=("NAME", "VALUE"), help="set a parameter"
    )
    run.add_argument(
        "-f", "--file", help="YAML file of parameters (e.g. params/01_background.full.yml)"
    )
    run.add_argument(
        "--profile", default="smoke", help="'smoke' (default) or 'full'; ignored with -f"
    )
    run.add_argument(
        "-o", "--output", help="executed notebook path (default book/generated/<chapter>.ipynb)"
    )
    run.add_argument("-q", "--quiet", action="store_true", help="no progress bar")
    run.add_argument(
        "-j",
        "--jobs",
        "--task-jobs",
        dest="task_jobs",
        type=int,
        metavar="N",
        help="tasks of the chapter's grids run in parallel (local processes unless --executor)",
    )
    _add_sweep_options(run)
    run.set_defaults(func=_cmd_run)

    book = sub.add_parser("book", help="run every chapter, then build the HTML book")
    book.add_argument("chapters", nargs="*", help="only these chapters (default: all in _toc.yml)")
    book.add_argument(
        "-j", "--jobs", type=int, default=1, help="chapters run in parallel processes"
    )
    book.add_argument("--profile", default="smoke", help="'smoke' (default) or 'full'")
    book.add_argument(
        "--no-run", action="store_true", help="only build from already executed notebooks"
    )
    book.add_argument(
        "--no-strict", action="store_true", help="do not turn Sphinx warnings into errors"
    )
    book.add_argument(
        "--task-jobs",
        dest="task_jobs",
        type=int,
        metavar="N",
        help="tasks of each chapter's grids run in parallel (-j counts chapters)",
    )
    _add_sweep_options(book)
    book.set_defaults(func=_cmd_book)

    lst = sub.add_parser("list", help="list the chapters and their parameters")
    lst.set_defaults(func=_cmd_list)

    params = sub.add_parser(
        "params",
        help="the parameters cell and params/ files from each chapter's Config",
        description="Each chapter's Config dataclass (thesis_lib.chapters.<name>.Config) is "
        "the one source of its notebook's parameters cell and params/<chapter>.smoke.yml; "
        "params/<chapter>.full.yml lists only what differs from smoke. Without --write or "
        "--check, print the generated parameters cells.",
    )
    params.add_argument("chapters", nargs="*", help="only these chapters (default: all)")
    what = params.add_mutually_exclusive_group()
    what.add_argument(
        "--write",
        action="store_true",
        help="rewrite the parameters cell and smoke.yml, and prune full.yml to what differs",
    )
    what.add_argument(
        "--check", action="store_true", help="exit 1 and list every file that disagrees"
    )
    params.set_defaults(func=_cmd_params)

    bench = sub.add_parser("bench", help="run benchmarks/bench_<name>.py")
    bench.add_argument("name")
    bench.add_argument("rest", nargs=argparse.REMAINDER, help="arguments for the benchmark script")
    bench.set_defaults(func=_cmd_bench)

    # Sub-packages contribute their own commands (e.g. 'thesis data'). Importing one imports its
    # package (torch, scipy: seconds), so only the command asked for is imported; the others get
    # a stand-in that lists them in `thesis --help` (SUBCOMMANDS: their one-line help).
    wanted = {m for n, (m, _) in SUBCOMMANDS.items() if command in (None, n)}
    for module in dict.fromkeys(m for m, _ in SUBCOMMANDS.values()):
        if module in wanted:
            importlib.import_module(module).register(sub)
    for name, (_, text) in SUBCOMMANDS.items():
        if name not in sub.choices:
            sub.add_parser(name, help=text)
    return parser


#: The commands a sub-package registers (``register(subparsers)`` in ``module``), with the help
#: line ``thesis --help`` shows without importing them. ``study`` also registers ``claims``.
SUBCOMMANDS: dict[str, tuple[str, str]] = {
    "data": ("thesis_lib.cli.data", "demonstration data sets (Minari format)"),
    "mdlt": ("thesis_lib.cli.mdlt", "music-to-dance translation (thesis chapter 6)"),
    "ur3": (
        "thesis_lib.cli.ur3",
        "the UR3: play or check a dance, make reaching demonstrations",
    ),
    "study": ("thesis_lib.cli.study", "run or resume a chapter's pre-registered study"),
    "claims": ("thesis_lib.cli.study", "write studies/claims.csv from the studies"),
    "parity": (
        "thesis_lib.cli.parity",
        "our DT and BC against d3rlpy's at equal config (params/parity.yml)",
    ),
    "ladder": ("thesis_lib.cli.ladder", "the sequence models' scale ladder (params/ladder.v2.yml)"),
    "defender": ("thesis_lib.cli.defender", "DEFENDER diagnostics (thesis 4.3)"),
}


def _command(argv: list[str]) -> str | None:
    """The sub-command named in ``argv`` (its first word that is not an option), or None."""
    return next((a for a in argv if not a.startswith("-")), None)


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else list(argv)
    args = build_parser(_command(argv)).parse_args(argv)
    try:
        return int(args.func(args) or 0)
    except (ValueError, FileNotFoundError) as err:  # bad input: say what, not a traceback
        if os.environ.get("THESIS_DEBUG"):
            raise
        print(f"thesis {args.command}: {err}", file=sys.stderr)
        return 1
