"""``thesis data generate | list | card | train-experts | train-expert``.

The main CLI (``thesis_lib/cli.py``) calls :func:`register` with its sub-parsers; each
sub-command's handler is set with ``set_defaults(func=...)`` and takes the parsed args.
"""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Callable
from typing import Any


def _generate(args: argparse.Namespace) -> int:
    from thesis_lib.data.recipe import generate
    from thesis_lib.data.tasks import TASKS, get_task

    if args.n_transitions is not None and args.n_transitions < 1:
        print(f"--n-transitions must be ≥ 1, got {args.n_transitions}.", file=sys.stderr)
        return 2
    tasks = list(TASKS) if args.task == "all" else [args.task]
    for task in tasks:
        spec = get_task(task)
        tiers = spec.tiers if args.tier == "all" else (args.tier,)
        for tier in tiers:
            if args.task == "all" and spec.kind == "mujoco" and not _has(task):
                print(f"skip {task}: no shipped policy", file=sys.stderr)
                continue
            did = generate(
                task,
                tier,
                n_transitions=args.n_transitions,
                size=args.size,
                seed=args.seed,
                action_noise=args.action_noise,
            )
            print(did)
    return 0


def _has(task: str) -> bool:
    from thesis_lib.data.experts import has_policies

    return has_policies(task)


def _list(args: argparse.Namespace) -> int:
    from thesis_lib.data.storage import list_datasets, search_dirs
    from thesis_lib.data.tasks import TASKS

    if args.tasks:
        for name, spec in TASKS.items():
            print(f"{name:26s} {spec.env_id:30s} {spec.kind:9s} {', '.join(spec.tiers) or '-'}")
        return 0
    print("searched: " + ", ".join(str(d) for d in search_dirs()))
    for did in list_datasets():
        print(did)
    return 0


def _card(args: argparse.Namespace) -> int:
    from thesis_lib.data.card import data_card, expert_quality, format_card

    if args.markdown:
        from thesis_lib.data.card import render_markdown

        print(render_markdown())
        return 0
    if args.experts:
        print(expert_quality().to_string(index=False))
        return 0
    if not args.dataset_id:
        print("give a data-set id, or --experts", file=sys.stderr)
        return 2
    from thesis_lib.data.storage import DamagedDatasetError

    try:
        card = data_card(args.dataset_id)
    except DamagedDatasetError as err:  # says how to rebuild it: no traceback
        print(f"thesis data card: {err}", file=sys.stderr)
        return 1
    print(json.dumps(card, default=str, indent=1) if args.json else format_card(card))
    return 0


def _train(args: argparse.Namespace) -> int:
    from dataclasses import replace

    from thesis_lib.data.experts import ARS_CONFIGS, train_experts

    tasks = [*ARS_CONFIGS, "maze2d"] if args.task == "all" else [args.task]
    for task in tasks:
        if task == "maze2d":
            from thesis_lib.data.card import record_maze_experts

            print(json.dumps(record_maze_experts(args.eval_episodes, out_dir=args.out), indent=1))
            continue
        if task not in ARS_CONFIGS:
            print(
                f"No ARS recipe for '{task}'. Valid: {', '.join(ARS_CONFIGS)}, maze2d, all.",
                file=sys.stderr,
            )
            return 2
        cfg = ARS_CONFIGS[task]
        if args.steps is not None:
            cfg = replace(cfg, total_steps=args.steps)
        if args.seed is not None:
            cfg = replace(cfg, seed=args.seed)
        rec = train_experts(
            task,
            cfg,
            out_dir=args.out,
            n_eval_episodes=args.eval_episodes,
            max_wall_s=args.max_wall_s,
            log=lambda s: print(s, flush=True),
        )
        print(
            json.dumps(
                {"task": task, "expert": rec.expert_return_mean, "medium": rec.medium_return_mean}
            )
        )
    return 0


def _train_expert(args: argparse.Namespace) -> int:
    from dataclasses import replace

    from thesis_lib.data.deep_experts import (
        ALGORITHM_LEARNING_RATES,
        DEEP_EXPERT_CONFIGS,
        DeepExpertConfig,
        ship_deep_expert,
    )

    if args.medium:
        return _train_medium(args)
    if args.task not in DEEP_EXPERT_CONFIGS:
        print(
            f"No TQC/SAC recipe for '{args.task}'. Valid: {', '.join(DEEP_EXPERT_CONFIGS)}.",
            file=sys.stderr,
        )
        return 2
    cfg = DEEP_EXPERT_CONFIGS[args.task]
    if args.steps is not None:
        cfg = replace(cfg, total_steps=args.steps)
    if args.seed is not None:
        cfg = replace(cfg, seed=args.seed)
    try:
        if args.algorithm is not None and args.algorithm != cfg.algorithm:
            # another algorithm brings its own learning rate (CrossQ's paper: 1e-3, else
            # rl-zoo's) and critics as wide as the actor, unless told otherwise below
            default = DeepExpertConfig()
            lr = ALGORITHM_LEARNING_RATES.get(args.algorithm, default.learning_rate)
            cfg = replace(
                cfg, algorithm=args.algorithm, learning_rate=lr, critic_arch=default.critic_arch
            )
        if args.learning_rate is not None:
            cfg = replace(cfg, learning_rate=args.learning_rate)
        if args.critic_arch is not None:
            arch = tuple(int(n) for n in args.critic_arch.split(","))
            cfg = replace(cfg, critic_arch=arch)
    except ValueError as e:
        print(f"thesis data train-expert: {e}", file=sys.stderr)
        return 2
    if args.train_freq is not None:
        if args.train_freq < 1:
            print(f"--train-freq must be ≥ 1, got {args.train_freq}.", file=sys.stderr)
            return 2
        cfg = replace(cfg, train_freq=args.train_freq)

    def ship() -> dict[str, Any]:
        rec = ship_deep_expert(
            args.task,
            run_dir=args.run_dir,
            out_dir=args.out,
            n_eval_episodes=args.eval_episodes,
            log=_log,
        )
        return {
            "task": args.task,
            "expert": rec.expert_return_mean,
            "expert_normalized": rec.expert_normalized,
            "medium": rec.medium_return_mean,
        }

    return _train_then_ship(args, cfg, args.run_dir, ship)


def _log(line: str) -> None:
    print(line, flush=True)


def _train_then_ship(
    args: argparse.Namespace, cfg: Any, run_dir: Any, ship: Callable[[], dict[str, Any]]
) -> int:
    """Train (or resume) the run of ``cfg`` unless ``--ship-only``; once it is done (or with
    ``--ship``), ``ship()`` it and print what it shipped as one JSON line. The one flow of
    ``thesis data train-expert`` and ``train-expert --medium``."""
    from thesis_lib.data.deep_experts import train_deep_expert

    if not args.ship_only:
        st = train_deep_expert(
            args.task,
            cfg,
            run_dir=run_dir,
            backend=args.backend,
            max_wall_s=args.max_wall_s,
            log=_log,
        )
        if not st.done and not args.ship:
            return 0
    print(json.dumps(ship()))
    return 0


def _train_medium(args: argparse.Namespace) -> int:
    """``thesis data train-expert --medium``: train (or resume) the task's medium run, then ship
    the snapshot whose sampled return is nearest D4RL's medium level (``<task>-medium``)."""
    from dataclasses import replace

    from thesis_lib.data.deep_experts import (
        MEDIUM_RUN_CONFIGS,
        runs_dir,
        ship_medium_run,
    )

    if args.task not in MEDIUM_RUN_CONFIGS:
        print(
            f"No medium-run recipe for '{args.task}'. Valid: {', '.join(MEDIUM_RUN_CONFIGS)}.",
            file=sys.stderr,
        )
        return 2
    cfg = MEDIUM_RUN_CONFIGS[args.task]
    if args.steps is not None:
        cfg = replace(cfg, total_steps=args.steps)
    run_dir = args.run_dir or runs_dir() / f"{args.task}-medium"

    def ship() -> dict[str, Any]:
        rec = ship_medium_run(
            args.task, run_dir, out_dir=args.out, n_eval_episodes=args.eval_episodes, log=_log
        )
        return {
            "task": args.task,
            "medium_step": rec.expert_step,
            "medium_normalized": rec.medium_normalized,
            "medium_sampled_normalized": rec.medium_sampled_normalized,
        }

    return _train_then_ship(args, cfg, run_dir, ship)


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add the ``data`` sub-command (``generate``, ``list``, ``card``, ``train-experts``,
    ``train-expert``)."""
    from thesis_lib.data.deep_experts import ALGORITHMS  # loaded with thesis_lib.data already

    p = subparsers.add_parser("data", help="demonstration data sets (Minari format)")
    sub = p.add_subparsers(dest="data_command", required=True)

    g = sub.add_parser(
        "generate",
        help="make thesis[-<size>]/<task>/<tier>-v0 by the D4RL recipe (smoke: thesis/, "
        "full: thesis-1m/)",
    )
    g.add_argument("--task", required=True, help="task name, or 'all' (see 'data list --tasks')")
    g.add_argument(
        "--tier", default="all", help="expert|medium|medium-replay|medium-expert|random|all"
    )
    g.add_argument(
        "--size",
        choices=["smoke", "full"],
        default="smoke",
        help="smoke: 20k transitions; full: D4RL's 1M",
    )
    g.add_argument("--n-transitions", type=int, default=None, help="overrides --size")
    g.add_argument("--seed", type=int, default=0)
    g.add_argument("--action-noise", type=float, default=None, help="std; default per task kind")
    g.set_defaults(func=_generate)

    lst = sub.add_parser("list", help="data sets found on disk (or --tasks)")
    lst.add_argument("--tasks", action="store_true", help="list tasks and their tiers instead")
    lst.set_defaults(func=_list)

    c = sub.add_parser("card", help="statistics of a data set (or --experts)")
    c.add_argument("dataset_id", nargs="?", help="e.g. thesis/hopper/medium-v0")
    c.add_argument("--json", action="store_true")
    c.add_argument("--experts", action="store_true", help="shipped experts vs quality targets")
    c.add_argument("--markdown", action="store_true", help="the whole data card as Markdown")
    c.set_defaults(func=_card)

    t = sub.add_parser("train-experts", help="re-train the shipped ARS expert/medium policies")
    t.add_argument(
        "--task",
        default="all",
        help="an ARS task, 'maze2d' (measure the scripted expert and random actions) or 'all'",
    )
    t.add_argument("--steps", type=int, default=None, help="override the recipe's step count")
    t.add_argument("--seed", type=int, default=None)
    t.add_argument(
        "--max-wall-s",
        type=float,
        default=None,
        help="stop at the first checkpoint past this time (record says where)",
    )
    t.add_argument("--eval-episodes", type=int, default=100)
    t.add_argument("--out", default=None, help="output dir (default: the package's policies/)")
    t.set_defaults(func=_train)

    te = sub.add_parser(
        "train-expert",
        help="train (or resume) a D4RL-grade expert (TQC; Ant: CrossQ) for walker2d, halfcheetah "
        "or ant, then ship it (policies/<task>.npz)",
    )
    te.add_argument("--task", required=True, help="walker2d, halfcheetah or ant")
    te.add_argument(
        "--backend",
        default="auto",
        choices=["auto", "sbx", "sb3"],
        help="sbx (JAX, faster; pip install '.[experts]') or sb3 (PyTorch)",
    )
    te.add_argument(
        "--steps",
        type=int,
        default=None,
        help="override the recipe's step cap; a larger cap continues a finished run",
    )
    te.add_argument("--seed", type=int, default=None)
    te.add_argument(
        "--algorithm",
        default=None,
        choices=ALGORITHMS,
        help="override the recipe's algorithm (with that algorithm's own learning rate)",
    )
    te.add_argument("--learning-rate", type=float, default=None)
    te.add_argument(
        "--critic-arch",
        default=None,
        help="the critics' hidden layers, comma-separated (e.g. 1024,1024; default: the actor's)",
    )
    te.add_argument(
        "--train-freq",
        type=int,
        default=None,
        help="collect N steps, then take N gradient steps in one compiled loop (same "
        "update-to-data ratio; the recipe's 1 suits a CPU, 32 a GPU with sbx)",
    )
    te.add_argument(
        "--max-wall-s",
        type=float,
        default=None,
        help="checkpoint and stop this call after that long (run again to resume)",
    )
    te.add_argument(
        "--run-dir",
        default=None,
        help="the run's folder (default: $THESIS_CACHE_DIR/expert_runs/<task>)",
    )
    te.add_argument(
        "--ship",
        action="store_true",
        help="ship the run's best snapshot even if the run is not finished",
    )
    te.add_argument("--ship-only", action="store_true", help="ship without training")
    te.add_argument(
        "--medium",
        action="store_true",
        help="the task's medium run instead (hopper, walker2d, halfcheetah): trained to D4RL's "
        "published medium level and shipped as policies/<task>-medium (run dir "
        "$THESIS_CACHE_DIR/expert_runs/<task>-medium)",
    )
    te.add_argument("--eval-episodes", type=int, default=100)
    te.add_argument("--out", default=None, help="output dir (default: the package's policies/)")
    te.set_defaults(func=_train_expert)


def main(argv: list[str] | None = None) -> int:
    """Stand-alone entry: ``python -m thesis_lib.cli.data data …``."""
    parser = argparse.ArgumentParser(prog="thesis")
    sub = parser.add_subparsers(dest="command", required=True)
    register(sub)
    args = parser.parse_args(argv)
    return int(args.func(args) or 0)


if __name__ == "__main__":
    raise SystemExit(main())
