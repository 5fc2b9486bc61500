"""Runs per CPU-hour of the sequence-model studies: float32 (the v1 code) against bfloat16 mixed
precision (``TrainConfig(precision="bf16")``), at equal config, in one process (issue #36).

A study run of the second studies (hdt-c1c3-v2, dm-c4c6-v2) is 10k training updates and five
evaluations of 10 episodes of up to 1,000 steps. This script times, per method and size, the
two parts of such a run in each precision, in turns (so that background load affects both
alike), and reports the ratio of runs per CPU-hour:

* **train**: the median CPU time of one ``Trainer.step`` (batch 64, K 20, Hopper's sizes,
  dropout 0.1 in the transformers, none in the DM/HDM as in the studies: sample, forward,
  loss, backward, clip, AdamW) over ``--repeats`` blocks of ``--updates`` steps;
* **evaluate**: one ``model.act`` on a full window for a batch of 10 episodes plus 10
  Hopper-v5 steps, times the 5 x 1,000 steps of a run's evaluations. Acting is float32 in
  both precisions (``TrainConfig.precision`` changes the training step only), so this part is
  the same on both sides and only dilutes the ratio. It is an upper bound: episodes that end
  early take fewer steps, and the DM/HDM of the study act by their recurrent step, several
  times cheaper than the window; so the ratios below are, if anything, low.

A run's fixed costs (loading the data, building the environments) are left out of both.

``run = updates x train + evaluations``; the ratio is float32's run over bfloat16's. The sizes:
``study`` is the v2 studies' (d64, 2 layers per model), ``peer`` the DT paper's and d3rlpy's
(d128, 3 layers: parity's ``dt-peer-r4``, whose bf16 twin ``dt-peer-r4-bf16`` checks that
the bf16 DT learns as d3rlpy's does).

Measured here (2026-11-28, 2-core AMD EPYC with AVX-512 BF16, beside a running two-process
study; 50 updates x 3 repeats, the DM and HDM 30 x 3):

    method   size   fp32 ms/update  bf16 ms/update  eval s/run  runs/CPU-h fp32   bf16  ratio
    DT       study            50.4            31.9          14             6.95  10.80   1.55
    HDT      study            79.2            51.9          20             4.44   6.68   1.51
    DM-noRTG study            71.9            46.7          21             4.87   7.37   1.51
    HDM      study           173.9           116.8          50             2.01   2.96   1.47
    DT       peer            202.4            96.2          50             1.74   3.56   2.05
    HDT      peer            330.1           154.9          85             1.06   2.20   2.07

Whole runs show as much or more: parity's ``dt-peer-r4-bf16`` (the DT at the peer's size, 10k
updates and a 10-episode evaluation, three seeds) took 967 to 1,000 CPU-seconds a run, its
float32 twin ``dt-peer-r4`` 2,646 to 2,960 (another day, beside other work), and scored the
same (40.9 both, at parity with d3rlpy's float32 DT).

So bf16 doubles the runs per CPU-hour at the peer's size (d128, 3 layers; the matrix
products, which bf16 speeds up, grow as d^2, so larger models should gain more), and gives
about 1.5x at the v2 studies' d64: there a step is bound by what bf16 does not speed up (the
dropout masks, about a quarter of a bf16 step; the normalisations; the Mamba's scan, which
runs in float32). The other levers of issue #36 add little on this CPU (``bench_ensemble.py``:
stacking seeds at most 8%, ``torch.compile`` slower).

    python benchmarks/bench_throughput.py                       # DT and HDT, both sizes
    python benchmarks/bench_throughput.py --methods DT --sizes peer --updates 50
"""

from __future__ import annotations

import argparse
import statistics
import time

import gymnasium as gym
import numpy as np
import torch
from bench_seq import make_data

from thesis_lib.seq import ArchSpec
from thesis_lib.seq.registry import METHODS, build_model
from thesis_lib.seq.trainer import PRECISIONS, TrainConfig, Trainer, batch_to_torch

SIZES = {"study": (64, 2), "peer": (128, 3)}
"""``name: (d_model, n_layers)``."""

RUN_UPDATES, RUN_EVAL_STEPS, EVAL_EPISODES = 10_000, 5 * 1_000, 10
"""A v2 study run: its updates, its evaluation steps (5 evaluations of up to 1,000 steps) and
the episodes acted on together."""


def parse_args() -> argparse.Namespace:
    p = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    p.add_argument("--methods", nargs="+", default=["DT", "HDT"], choices=sorted(METHODS))
    p.add_argument("--sizes", nargs="+", default=list(SIZES), choices=list(SIZES))
    p.add_argument("--updates", type=int, default=100, help="updates per timed block")
    p.add_argument("--repeats", type=int, default=3, help="timed blocks per precision")
    p.add_argument("--acts", type=int, default=100, help="timed act calls")
    return p.parse_args()


def make_trainer(method: str, size: str, precision: str) -> Trainer:
    d, n_layers = SIZES[size]
    seq = make_data(20, 11, 3)  # Hopper's state and action sizes
    torch.manual_seed(0)
    arch = ArchSpec(d_model=d, n_layers=n_layers, n_heads=1, K=20, dropout=0.1)
    model = build_model(method, seq, arch)
    cfg = TrainConfig(
        iterations=10**9, batch_size=64, warmup_steps=5000, progress=False, precision=precision
    )
    return Trainer(model, seq, cfg)


def time_steps(trainer: Trainer, n: int) -> float:
    t0 = time.process_time()
    for _ in range(n):
        trainer.step()
    return (time.process_time() - t0) / n


def time_evaluation_step(trainer: Trainer, n: int) -> float:
    """CPU seconds of one evaluation step of 10 episodes: one ``act`` on a full window of 10
    histories and 10 Hopper-v5 steps."""
    model = trainer.model
    model.eval()
    batch = batch_to_torch(trainer.dataset, trainer.dataset.sample(EVAL_EPISODES), "cpu")
    env = gym.make("Hopper-v5")
    env.reset(seed=0)
    action = np.zeros(env.action_space.shape, dtype=np.float32)
    with torch.no_grad():
        model.act(batch)  # warm-up
        t0 = time.process_time()
        for _ in range(n):
            model.act(batch)
            for _ in range(EVAL_EPISODES):
                _, _, term, trunc, _ = env.step(action)
                if term or trunc:
                    env.reset()
        out = (time.process_time() - t0) / n
    env.close()
    model.train()
    return out


def main() -> None:
    args = parse_args()
    torch.set_num_threads(1)
    print(
        f"{'method':7} {'size':6} {'fp32 ms/update':>14} {'bf16 ms/update':>14} "
        f"{'eval s/run':>10} {'runs/CPU-h fp32':>15} {'bf16':>6} {'ratio':>6}"
    )
    for size in args.sizes:
        for method in args.methods:
            trainers = {p: make_trainer(method, size, p) for p in PRECISIONS}
            for t in trainers.values():
                time_steps(t, 3)  # warm-up
            times: dict[str, list[float]] = {p: [] for p in PRECISIONS}
            for r in range(args.repeats):  # in turns, each precision first every other time
                for p in PRECISIONS[:: 1 if r % 2 == 0 else -1]:
                    times[p].append(time_steps(trainers[p], args.updates))
            step = {p: statistics.median(v) for p, v in times.items()}
            # acting is float32 on both sides: one measurement serves both
            eval_s = RUN_EVAL_STEPS * time_evaluation_step(trainers["fp32"], args.acts)
            run_s = {p: RUN_UPDATES * step[p] + eval_s for p in PRECISIONS}
            per_hour = {p: 3600.0 / s for p, s in run_s.items()}
            print(
                f"{method:7} {size:6} {1e3 * step['fp32']:14.1f} {1e3 * step['bf16']:14.1f} "
                f"{eval_s:10.0f} {per_hour['fp32']:15.2f} {per_hour['bf16']:6.2f} "
                f"{per_hour['bf16'] / per_hour['fp32']:6.2f}"
            )


if __name__ == "__main__":
    main()
