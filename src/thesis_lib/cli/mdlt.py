"""``thesis mdlt``: music-to-dance commands.

    thesis mdlt dance --audio my_song.wav --out angles.csv [--checkpoint ckpt.pt] \\
        [--plot angles.png] [--animation arm.gif]
    thesis mdlt train --out ckpt.pt [--variant mamba] [--iterations N] [--data-size study]

``dance`` without ``--checkpoint`` uses the small checkpoint shipped in the package, and without
``--audio`` the recording shipped in it (:func:`thesis_lib.mdlt.translate.packaged_recording`).
It checks the dance against the UR3's joint, speed and workspace limits as ``thesis ur3 check``
does and says in one line how many frames break which limit, and how many ``thesis ur3 play``
(clip mode) would clip or slow; ``--animation`` draws the arm in the pose ``thesis ur3 play``
plays (:func:`thesis_lib.ur3.dance.map_dance`).

Used in: MDLT chapter (thesis 6.5).
"""

from __future__ import annotations

import argparse
import os
import sys


def _cmd_dance(args: argparse.Namespace) -> int:
    from thesis_lib.mdlt.translate import PACKAGED_RECORDING_CREDIT, dance, packaged_recording
    from thesis_lib.ur3.dance import map_dance, prepare_dance

    audio = args.audio
    if audio is None:
        audio = packaged_recording()
        c = PACKAGED_RECORDING_CREDIT
        print(
            f"No --audio: the packaged recording, '{c['title']}' by {c['artist']} ({c['licence']})."
        )
    result = dance(
        audio,
        args.checkpoint,
        out=args.out,
        plot=args.plot,
        animation=args.animation,
        device=args.device,
        progress=not args.quiet,
        max_animation_s=args.animation_seconds,
        to_joints=map_dance,  # the arm drawn in the pose `thesis ur3 play` plays
    )
    n = len(result.angles)
    print(
        f"{n} frames ({result.times[-1]:.1f} s) of UR3 joint angles -> {args.out}"
        + (f"; plot -> {args.plot}" if args.plot else "")
        + (f"; animation -> {args.animation}" if args.animation else "")
    )
    # the check `thesis ur3 check` makes, and what `thesis ur3 play` (clip mode) would change
    playback = prepare_dance(result.angles, result.fps, mode="clip")
    print(f"UR3 limits (mapped as 'thesis ur3 play' plays it): {playback.summary()}")
    return 0


def _cmd_train(args: argparse.Namespace) -> int:
    import torch

    torch.set_num_threads(max(1, args.threads))
    if not args.quiet:
        return _train(args)
    before = os.environ.get("TQDM_DISABLE")
    os.environ["TQDM_DISABLE"] = "1"  # the data set's reader and synthesis have bars of their own
    try:
        return _train(args)
    finally:
        if before is None:
            del os.environ["TQDM_DISABLE"]
        else:
            os.environ["TQDM_DISABLE"] = before


def _train(args: argparse.Namespace) -> int:
    import dataclasses

    from thesis_lib.chapters import mdlt as ch

    values = {}
    if args.recipe != "defaults":
        from thesis_lib.book.study import load_study

        try:
            values = dict(load_study(args.recipe if args.recipe != "study" else "06_mdlt").config)
        except FileNotFoundError as err:
            print(f"{err}\nUsing the chapter's defaults (--recipe defaults).", file=sys.stderr)
    known = {f.name for f in dataclasses.fields(ch.Config)}
    cfg = ch.Config(**{k: v for k, v in values.items() if k in known})
    over = {
        "iterations": args.iterations,
        "seed": args.seed,
        "data_size": args.data_size,
        "aist_root": args.aist_root,
        "d_model": args.d_model,
        "n_layers": args.n_layers,
        "batch_size": args.batch_size,
        "progress": not args.quiet,
    }
    variant = args.variant
    if args.probe:  # the chapter's probe: MDLT-M, audio only, probe_mute muted, its batch/clip
        if variant not in ("mamba", "mamba_audio"):
            print(f"--probe trains MDLT-M (audio only); not --variant {variant}.", file=sys.stderr)
            return 2
        cfg, variant = ch.probe_config(cfg), "mamba_audio"
    cfg = dataclasses.replace(cfg, **{k: v for k, v in over.items() if v is not None})
    path, history = ch.train_translator(cfg, variant, args.out, half=not args.full_precision)
    loss = history["loss"].iloc[-20:].mean() if "loss" in history and len(history) else float("nan")
    print(
        f"{ch.VARIANT_LABELS[variant]}{' probe' if args.probe else ''}: {cfg.iterations} updates of batch {cfg.batch_size} on "
        f"the {cfg.aist_root or cfg.data_size} AIST++-layout data (final loss {loss:.4f}) -> {path} "
        f"({path.stat().st_size / 1024:.0f} KB)"
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
        "--audio",
        help="audio file (wav, flac, ogg, ...), any sample rate; default: the packaged recording "
        "(Will Savino's 'Caribbean', CC BY-SA 3.0)",
    )
    d.add_argument(
        "--checkpoint",
        help="MDLT checkpoint (.pt) carrying its feature scaler; default: the packaged one",
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
    t = sub.add_parser(
        "train",
        help="train a translator on the AIST++-layout data with the study's recipe; write a checkpoint",
    )
    t.add_argument("--out", required=True, help="checkpoint to write (.pt)")
    t.add_argument(
        "--variant",
        default="mamba",
        choices=["transformer", "mamba", "mamba_audio"],
        help="MDLT-T, MDLT-M (default) or MDLT-M without the pose input",
    )
    t.add_argument(
        "--recipe",
        default="study",
        help="'study' (params/06_mdlt.study.yml's config, default), 'defaults' (the chapter's "
        "smoke defaults) or a path to a study file",
    )
    t.add_argument(
        "--probe",
        action="store_true",
        help="the chapter's probe: MDLT-M on the audio only with the recipe's probe_mute "
        "feature groups muted (the tempogram), probe_batch_size, probe_iterations and "
        "probe_grad_clip",
    )
    t.add_argument("--iterations", type=int, help="updates (default: the recipe's)")
    t.add_argument("--batch-size", type=int, help="windows per batch (default: the recipe's)")
    t.add_argument("--d-model", type=int, help="embedding size (default: the recipe's)")
    t.add_argument("--n-layers", type=int, help="layers / Mamba blocks (default: the recipe's)")
    t.add_argument("--seed", type=int, help="seed (default: the recipe's)")
    t.add_argument(
        "--data-size",
        choices=["smoke", "full", "study"],
        help="size of the default AIST++-layout data (default: the recipe's)",
    )
    t.add_argument("--aist-root", help="a real AIST++ folder instead of the default data")
    t.add_argument("--threads", type=int, default=1, help="torch threads (default 1)")
    t.add_argument(
        "--full-precision", action="store_true", help="store float32 weights (default float16)"
    )
    t.add_argument("-q", "--quiet", action="store_true", help="no progress bar")
    t.set_defaults(func=_cmd_train)


if __name__ == "__main__":  # python -m thesis_lib.cli.mdlt dance ...
    from thesis_lib.cli import main

    sys.exit(main(["mdlt", *sys.argv[1:]]))
