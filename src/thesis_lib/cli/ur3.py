"""``thesis ur3 play | check | demos | model``: the UR3 from the command line.

``thesis ur3 play angles.csv --fps 60`` maps a dance (4 columns: MDLT's angles) or a joint
trajectory (6 columns) onto the UR3, clips it to the limits (``--mode reject`` to refuse
instead) and plays it through the driver, **dry-run unless** ``--execute`` is given;
``--gif``/``--html`` write a picture sequence or the 3-D viewer.

Used in: UR3 deployment chapter.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from thesis_lib.ur3.safety import SafetyReport


def read_angles(path: str | Path) -> np.ndarray:
    """A ``(T, 4)`` or ``(T, 6)`` array from a CSV (an optional header line) or ``.npy`` file."""
    path = Path(path)
    if not path.exists():
        raise FileNotFoundError(
            f"No angles file {path}: expected a CSV (T rows, 4 or 6 columns, radians) or .npy."
        )
    if path.suffix == ".npy":
        a = np.load(path)
    else:
        first = path.read_text().splitlines()[:1]
        header = bool(first) and not all(_is_number(c) for c in first[0].split(","))
        if header:  # e.g. `thesis mdlt dance --out`: time_s, then the four angles
            import pandas as pd

            frame = pd.read_csv(path)
            a = frame.drop(
                columns=[c for c in frame.columns if str(c).lower().startswith("time")]
            ).to_numpy()
        else:
            a = np.loadtxt(path, delimiter=",", ndmin=2)
    a = np.asarray(a, dtype=np.float64)
    if a.ndim != 2 or a.shape[1] not in (4, 6):
        raise ValueError(
            f"{path}: expected T rows of 4 (MDLT angles) or 6 (UR3 joint angles) columns, got {a.shape}."
        )
    return a


def _is_number(cell: str) -> bool:
    """Whether ``cell`` is a float literal (``8.218E-02``, ``1e3``, ``nan``, ``inf`` …), i.e. not a
    header name."""
    try:
        float(cell)
    except ValueError:
        return False
    return True


def _clip_note(before: SafetyReport, changed: int, max_change: float) -> str | None:
    """What clipping did, as ``check`` would report it, or ``None`` when nothing broke a limit."""
    if before.ok:
        return None
    return (
        f"clipped: {before.summary()[:-1]}; {changed} of {before.n_frames} frames clipped or "
        f"slowed (largest change {max_change:.3f} rad)."
    )


def _trajectory(args: argparse.Namespace):
    from thesis_lib.ur3.dance import prepare_dance
    from thesis_lib.ur3.safety import (
        SafetyLimits,
        UnsafeTrajectoryError,
        check_trajectory,
        clip_trajectory,
    )

    a = read_angles(args.angles)
    limits = SafetyLimits(speed_scale=args.speed_scale)
    if a.shape[1] == 4:
        pb = prepare_dance(a, args.fps, mode=args.mode, limits=limits)
        return pb.q, limits, _clip_note(pb.before, pb.changed_frames, pb.max_deviation)
    dt = 1.0 / args.fps
    rep = check_trajectory(a, dt, limits)
    if args.mode == "clip":
        q = clip_trajectory(a, dt, limits)
        dev = np.abs(q - a).max(axis=1)
        return q, limits, _clip_note(rep, int((dev > 1e-9).sum()), float(dev.max()))
    if not rep.ok:
        raise UnsafeTrajectoryError(rep)
    return a, limits, None


def _backend(args: argparse.Namespace):
    from thesis_lib.ur3.driver import RTDEBackend, SimBackend, URScriptBackend

    if args.backend == "sim":
        return SimBackend()
    if not args.host:
        raise ValueError(f"--backend {args.backend} needs --host (the robot controller's address).")
    return URScriptBackend(args.host) if args.backend == "urscript" else RTDEBackend(args.host)


def _play(args: argparse.Namespace) -> int:
    from thesis_lib.ur3.driver import UR3Driver
    from thesis_lib.ur3.safety import UnsafeTrajectoryError

    try:
        q, limits, note = _trajectory(args)
    except UnsafeTrajectoryError as err:
        print(f"thesis ur3 play: {err}", file=sys.stderr)
        return 2
    drv = UR3Driver(_backend(args), limits=limits, dry_run=not args.execute)
    try:
        with drv:
            res = drv.play(q, fps=args.fps, allow_unchecked_approach=args.allow_unchecked_approach)
    except UnsafeTrajectoryError as err:
        print(f"thesis ur3 play: {err}", file=sys.stderr)
        return 2
    if note:  # the file broke a limit: say so, not only that the clipped motion is safe
        print(note)
    print(res.report.summary())
    print("\n".join(drv.log))
    if args.gif:
        from thesis_lib.ur3.render import render_frames, save_gif

        step = max(1, int(round(args.fps / 15)))
        print("wrote", save_gif(render_frames(q[::step]), args.gif, fps=args.fps / step))
    if args.html:
        from thesis_lib.ur3.viewer import save_html, trajectory_html

        print("wrote", save_html(trajectory_html(q, fps=args.fps), args.html))
    return 0


def _check(args: argparse.Namespace) -> int:
    from thesis_lib.ur3.dance import map_dance
    from thesis_lib.ur3.safety import SafetyLimits, check_trajectory

    a = read_angles(args.angles)
    q = map_dance(a) if a.shape[1] == 4 else a
    rep = check_trajectory(q, 1.0 / args.fps, SafetyLimits(speed_scale=args.speed_scale))
    print(rep.summary())
    return 0 if rep.ok else 2


def _demos(args: argparse.Namespace) -> int:
    from thesis_lib.ur3.reach import get_reach_dataset

    ds = get_reach_dataset(args.n, args.seed, overwrite=True, reach_set=args.set)
    print(f"{ds.id}: {len(ds)} demonstrations, {ds.n_transitions} steps, at {ds.path}")
    return 0


def _model(args: argparse.Namespace) -> int:
    from thesis_lib.ur3.model import asset_path, build_mjcf

    if args.print:
        print(build_mjcf())
    else:
        print(asset_path())
    return 0


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add ``thesis ur3 ...`` to the main CLI."""
    p = subparsers.add_parser(
        "ur3", help="the UR3: play or check a dance, make reaching demonstrations"
    )
    sub = p.add_subparsers(dest="ur3_command", required=True)

    def common(sp: argparse.ArgumentParser) -> None:
        sp.add_argument(
            "angles", help="CSV or .npy: T x 4 MDLT angles or T x 6 UR3 joint angles (radians)"
        )
        sp.add_argument(
            "--fps", type=float, default=60.0, help="frames per second of the file (MDLT: 60)"
        )
        sp.add_argument(
            "--speed-scale",
            type=float,
            default=1.0,
            help="allowed fraction of the UR3's joint speeds",
        )

    play = sub.add_parser(
        "play", help="play a dance/trajectory through the driver (dry-run unless --execute)"
    )
    common(play)
    play.add_argument(
        "--mode", choices=("clip", "reject"), default="clip", help="clip to the limits or refuse"
    )
    play.add_argument("--backend", choices=("sim", "urscript", "rtde"), default="sim")
    play.add_argument("--host", help="robot controller address (urscript, rtde)")
    dry = play.add_mutually_exclusive_group()
    dry.add_argument(
        "--dry-run", dest="execute", action="store_false", help="check and log only (default)"
    )
    dry.add_argument(
        "--execute", dest="execute", action="store_true", help="really send the motion"
    )
    play.set_defaults(execute=False)
    play.add_argument(
        "--allow-unchecked-approach",
        action="store_true",
        help="urscript: move to the first frame without knowing the current angles",
    )
    play.add_argument("--gif", help="write rendered frames to this GIF")
    play.add_argument("--html", help="write the 3-D viewer (meshcat static HTML) here")
    play.set_defaults(func=_play)

    check = sub.add_parser(
        "check", help="check a dance/trajectory against the joint, speed and workspace limits"
    )
    common(check)
    check.set_defaults(func=_check)

    demos = sub.add_parser(
        "demos", help="(re)make the reaching demonstrations data set (thesis/ur3-reach/teleop-v0)"
    )
    demos.add_argument("-n", type=int, default=100)
    demos.add_argument("--seed", type=int, default=0)
    demos.add_argument(
        "--set",
        choices=["teleop", "any-order"],
        default="teleop",
        help="teleop: the goals in one sequence (Table 5.4's); any-order: each demonstration "
        "in an order of its own (thesis/ur3-reach/any-order-v0, harder)",
    )
    demos.set_defaults(func=_demos)

    mdl = sub.add_parser("model", help="path of the UR3 MJCF model (--print: its text)")
    mdl.add_argument("--print", action="store_true")
    mdl.set_defaults(func=_model)
