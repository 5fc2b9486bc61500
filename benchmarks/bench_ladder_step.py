"""Time one training update of the scale ladder's models at a rung, on the CPU or a GPU.

What a ladder run costs is almost all its updates (30k of them; the two evaluations are
batched over 10 episodes). This times ``Trainer.step`` (sample a batch of K-step windows,
forward, loss, backward, clip, AdamW) of DT, HDT and DM without RTG, built as the ladder builds
them (``thesis_lib.seq.registry.build_model``, ``params/ladder.v2.yml``'s arch: 1 head, K 20,
dropout 0.1; batch 64), on random hopper-sized data (11-d states, 3-d actions), after 5
warm-up updates. It prints one line: the tag and the ms per update of each model.

    python benchmarks/bench_ladder_step.py                       # d128 L3 on this machine's device
    python benchmarks/bench_ladder_step.py --rung "d64 L2" --iters 50 --device cpu

Several runs share one GPU through NVIDIA's MPS; to time N at once:

    nvidia-cuda-mps-control -d
    for i in $(seq 18); do python benchmarks/bench_ladder_step.py --iters 100 --tag "mps18-$i" & done; wait
    echo quit | nvidia-cuda-mps-control

Measured 2026-11-28 at d128 L3, one torch thread per process:

* this 2-core CPU, beside two running ladder processes: DT 201, HDT 329, DM without RTG 221 ms
  (a 30k-update run: 1.7, 2.7 and 1.8 hours);
* one NVIDIA H200 (torch 2.11, CUDA 13; the DM runs its torch-loop scan, as there is no
  mamba_ssm), 300 updates each: alone DT 11.5, HDT 22.6, DM 24.2 ms; 6 processes at once under
  MPS: DT 11.7-13.5, HDT 20.0-24.3, DM 21.8-27.5 ms each; 18 at once (the whole rung, on 16
  cores): DT 10.6-19.8, HDT 22.0-43.8, DM 27.4-47.5 ms each (medians about 14, 29 and 41).

So the GPU is about 17x one CPU core per update, and it is overhead-bound: a d128 L3 step is
a few hundred small kernels, launched from Python. Six runs at once cost each almost nothing;
18 slow the HDT and DM runs by a half to three quarters. The whole d128 L3 rung, 18 runs at
once, needs about 20 minutes of updates (DM: 30k x 41 ms), more than one 10-minute device call,
and 15 device minutes a session hold less than that plus the 3 minutes it takes to make the two
1M hopper sets there. Capturing the step in a CUDA graph (static shapes: batch 64, K 20) is the
lever that remains.
"""

from __future__ import annotations

import argparse
import time

import torch
from bench_seq import make_data  # beside this file (the script's folder is on sys.path)

from thesis_lib.ladder import Rung, parse_rung
from thesis_lib.seq.registry import ArchSpec, build_model
from thesis_lib.seq.trainer import TrainConfig, Trainer

METHODS = ("DT", "HDT", "DM-noRTG")


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    p = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    p.add_argument("--rung", default="d128 L3", help='a ladder rung, e.g. "d64 L2"')
    p.add_argument("--device", default="auto", help="cpu, cuda or auto (cuda where there is one)")
    p.add_argument("--iters", type=int, default=20, help="timed updates per model")
    p.add_argument("--methods", nargs="+", default=list(METHODS), choices=METHODS)
    p.add_argument("--tag", default="", help="printed first (to tell concurrent runs apart)")
    args = p.parse_args(argv)
    if args.device == "auto":
        args.device = "cuda" if torch.cuda.is_available() else "cpu"
    if args.iters < 1:
        p.error("--iters must be at least 1")
    return args


def time_step(method: str, rung: Rung, device: str, iters: int) -> float:
    """Milliseconds per ``Trainer.step`` of ``method`` at ``rung``, after 5 warm-up steps."""
    seq = make_data(20, sd=11, ad=3)
    arch = ArchSpec(d_model=rung.d_model, n_layers=rung.n_layers, n_heads=1, K=20, dropout=0.1)
    torch.manual_seed(0)
    trainer = Trainer(
        build_model(method, seq, arch),
        seq,
        TrainConfig(batch_size=64, progress=False, device=device),
    )

    def sync() -> None:
        if device.startswith("cuda"):
            torch.cuda.synchronize()

    for _ in range(5):
        trainer.step()
    sync()
    t = time.perf_counter()
    for _ in range(iters):
        trainer.step()
    sync()
    return 1e3 * (time.perf_counter() - t) / iters


def main(argv: list[str] | None = None) -> None:
    args = parse_args(argv)
    torch.set_num_threads(1)
    rung = parse_rung(args.rung)
    times = {m: time_step(m, rung, args.device, args.iters) for m in args.methods}
    head = f"{args.tag} " if args.tag else ""
    print(
        f"{head}{args.rung} on {args.device} (torch {torch.__version__}, {args.iters} updates): "
        + ", ".join(f"{m} {ms:.2f} ms" for m, ms in times.items())
    )


if __name__ == "__main__":
    main()
