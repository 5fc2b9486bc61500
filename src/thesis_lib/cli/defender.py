"""``thesis defender lookahead``: how far ahead of a crash DEFENDER fires, for a saved policy.

    thesis defender lookahead studies/03_defender/v5/tasks/partial/<key>/step-*/model.zip \\
        [--study 03_defender:v6] [--strategy MeanDemoW5/MeanDemoW10] [--trajectory state] \\
        [--n-demos 50] [--steps 20000] [--lookahead 1,5,10,20,50,100] [--seed 0] [--out t.csv]

It prints the table of :func:`thesis_lib.chapters.defender.lookahead.filter_lookahead` (the
share of firings that would have crashed within ``k`` steps, beside a blind filter's) and,
with ``--out``, writes it as CSV with a ``.json`` beside it: the summary, the arguments, the
seed and the commit.

Used in: DEFENDER chapter (the second study's reading).
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path


def _steps_list(text: str) -> list[int]:
    try:
        ks = [int(x) for x in text.split(",") if x.strip()]
    except ValueError:
        raise argparse.ArgumentTypeError(f"expect step counts like 1,5,10; got {text!r}") from None
    if not ks or min(ks) < 1:
        raise argparse.ArgumentTypeError(f"expect positive step counts; got {text!r}")
    return ks


def _cmd_lookahead(args: argparse.Namespace) -> int:
    import pandas as pd

    from thesis_lib._io import atomic_write
    from thesis_lib.chapters.defender.lookahead import study_lookahead
    from thesis_lib.provenance import run_metadata

    out = study_lookahead(
        args.model,
        study=args.study,
        strategy=args.strategy,
        trajectory=args.trajectory,
        n_demos=args.n_demos,
        steps=args.steps,
        lookahead=args.lookahead,
        seed=args.seed,
        progress=not args.quiet,
        max_trajectory=args.max_trajectory,
        paper_compat=args.paper_compat,
    )
    s = out.summary
    if "run_label" in s:
        print(
            f"{s['run_label']}, seed {s['run_seed']} ({s['run_scale']}), at step {s['run_step']}:"
        )
    print(
        f"{int(s['firings'])} firings in {int(s['steps'])} steps ({s['firings_per_1k_steps']:.1f} "
        f"per 1,000); without the filter {s['control_crashes_per_1k_steps']:.1f} crashes per "
        f"1,000 steps in {int(s['control_episodes'])} episodes."
    )
    print(
        f"The filter fires after {s['filter_step_median']:.0f} real steps (median; 10-90%: "
        f"{s['filter_step_p10']:.0f}-{s['filter_step_p90']:.0f}), "
        f"{s['crash_in_median']:.0f} steps before the crash the policy was heading for (median "
        f"of those that would crash); without it episodes last {s['control_length_median']:.0f} "
        f"steps (median; 10-90%: {s['control_length_p10']:.0f}-{s['control_length_p90']:.0f}), "
        f"{100 * s['control_crashed_share']:.0f}% of them crash."
    )
    with pd.option_context("display.width", 120):
        print(out.table.round(3).to_string(index=False))
    if args.out:
        dest = Path(args.out)
        atomic_write(dest, lambda p: out.table.to_csv(p, index=False), keep_suffix=True)
        meta = run_metadata(
            {k: v for k, v in vars(args).items() if k != "func"}, args.seed, summary=s
        )
        atomic_write(
            dest.with_suffix(".json"),
            lambda p: p.write_text(json.dumps(meta, indent=1, default=str) + "\n"),
            keep_suffix=True,
        )
        print(f"wrote {dest} and {dest.with_suffix('.json')}")
    return 0


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add ``thesis defender ...`` to the ``thesis`` command line."""
    d = subparsers.add_parser("defender", help="DEFENDER diagnostics (thesis 4.3)")
    sub = d.add_subparsers(dest="defender_command", required=True)
    la = sub.add_parser(
        "lookahead",
        help="how far ahead of a crash the filter fires for a saved SAC policy, beside a blind "
        "filter's",
    )
    la.add_argument("model", help="a stable-baselines3 model.zip (a study checkpoint's)")
    la.add_argument(
        "--study", default="03_defender:v6", help="the study whose task and demos to use"
    )
    la.add_argument("--strategy", help="<safe>/<unsafe> methods; default the study's first")
    la.add_argument("--trajectory", choices=["state", "state_action"], default="state")
    la.add_argument("--n-demos", type=int, help="demonstrations per group; default the study's")
    la.add_argument("--steps", type=int, default=20_000, help="steps of each run (default 20000)")
    la.add_argument(
        "--lookahead",
        type=_steps_list,
        default=[1, 5, 10, 20, 50, 100],
        help="look-ahead lengths k (default 1,5,10,20,50,100)",
    )
    la.add_argument(
        "--max-trajectory",
        type=int,
        help="compare only the trajectory's last N steps (the authors' code: 20); default the "
        "study's (the thesis's text: the whole episode)",
    )
    la.add_argument(
        "--paper-compat",
        action="store_true",
        help="the authors' filter: FastDTW radius 1, the 20-step cap, fire only on > (slow)",
    )
    la.add_argument("--seed", type=int, default=0)
    la.add_argument("--out", help="CSV of the table (a .json of the run beside it)")
    la.add_argument("-q", "--quiet", action="store_true", help="no progress bars")
    la.set_defaults(func=_cmd_lookahead)
