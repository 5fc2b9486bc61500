"""``thesis mdlt``: music-to-dance commands.

    thesis mdlt dance --audio my_song.wav --checkpoint ckpt.pt --out angles.csv \\
        [--plot angles.png] [--animation arm.gif]

Used in: MDLT chapter (thesis 6.5).
"""

from __future__ import annotations

import argparse
import sys


def _cmd_dance(args: argparse.Namespace) -> int:
    from thesis_lib.mdlt.translate import dance

    result = dance(
        args.audio,
        args.checkpoint,
        out=args.out,
        plot=args.plot,
        animation=args.animation,
        device=args.device,
        progress=not args.quiet,
        max_animation_s=args.animation_seconds,
    )
    n = len(result.angles)
    print(
        f"{n} frames ({result.times[-1]:.1f} s) of UR3 joint angles -> {args.out}"
        + (f"; plot -> {args.plot}" if args.plot else "")
        + (f"; animation -> {args.animation}" if args.animation else "")
    )
    return 0


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add ``thesis mdlt ...`` to the ``thesis`` command line."""
    mdlt = subparsers.add_parser("mdlt", help="music-to-dance translation (thesis chapter 6)")
    sub = mdlt.add_subparsers(dest="mdlt_command", required=True)
    d = sub.add_parser(
        "dance", help="translate a music file into UR3 joint angles with a trained MDLT checkpoint"
    )
    d.add_argument(
        "--audio", required=True, help="audio file (wav, flac, ogg, ...), any sample rate"
    )
    d.add_argument(
        "--checkpoint", required=True, help="MDLT checkpoint (.pt) carrying its feature scaler"
    )
    d.add_argument("--out", required=True, help="CSV to write: time_s and four joint angles (rad)")
    d.add_argument("--plot", help="PNG of the angle curves")
    d.add_argument("--animation", help="animation of the arm: .gif or .html")
    d.add_argument(
        "--animation-seconds",
        type=float,
        default=30.0,
        help="animate at most this many seconds (default 30)",
    )
    d.add_argument("--device", default="cpu", help="cpu or cuda")
    d.add_argument("-q", "--quiet", action="store_true", help="no progress bar")
    d.set_defaults(func=_cmd_dance)


if __name__ == "__main__":  # python -m thesis_lib.mdlt.cli dance ...
    from thesis_lib.cli import main

    sys.exit(main(["mdlt", *sys.argv[1:]]))
