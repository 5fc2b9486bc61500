"""Runs per CPU-hour of the sequence-model studies: float32 (the v1 code) against bfloat16 mixed
precision (``TrainConfig(precision="bf16")``), alone, with the fast training kernels
(``TrainConfig(kernels="fast")``: lane dropout masks and fused AdamW) and with those and the
readout-only last block (``kernels="fast+readout"``: the transformers' last block runs its
queries, attention output, residuals and MLP on the tokens the loss reads only), at equal
config, in one process (issue #36).

A study run of the second studies (hdt-c1c3-v2, dm-c4c6-v2) is 10k training updates and five
evaluations of 10 episodes of up to 1,000 steps. This script times, per method and size, the
two parts of such a run in each variant, in turns (so that background load affects all alike),
and reports the ratio of runs per CPU-hour to float32's:

* **train**: the median CPU time of one ``Trainer.step`` (batch 64, K 20, Hopper's sizes,
  dropout 0.1 in the transformers, none in the DM/HDM as in the studies: sample, forward,
  loss, backward, clip, AdamW) over ``--repeats`` blocks of ``--updates`` steps;
* **evaluate**: one ``model.act`` on a full window for a batch of 10 episodes plus 10
  Hopper-v5 steps, times the 5 x 1,000 steps of a run's evaluations. Acting is float32 with
  torch's kernels in every variant (``precision`` and ``kernels`` change the training step
  only), so this part is the same on all sides and only dilutes the ratio. It is an upper
  bound: episodes that end early take fewer steps, and the DM/HDM of the study act by their
  recurrent step, several times cheaper than the window; so the ratios below are, if
  anything, low.

A run's fixed costs (loading the data, building the environments) are left out of all.

``run = updates x train + evaluations``; the ratio is float32's run over the variant's. The
sizes: ``study`` is the v2 studies' (d64, 2 layers per model), ``peer`` the DT paper's and
d3rlpy's (d128, 3 layers: parity's ``dt-peer-r4``, whose bf16 twin ``dt-peer-r4-bf16`` checks
that the bf16 DT learns as d3rlpy's does).

Measured here on two days (2-core AMD EPYC with AVX-512 BF16), ms per update:

2026-11-28, beside a running two-process study, 50 updates x 3 repeats (DM and HDM 30 x 3),
float32 against bf16 only:

    method   size   fp32 ms/update  bf16 ms/update  eval s/run  runs/CPU-h fp32   bf16  ratio
    DT       study            50.4            31.9          14             6.95  10.80   1.55
    HDT      study            79.2            51.9          20             4.44   6.68   1.51
    DM-noRTG study            71.9            46.7          21             4.87   7.37   1.51
    HDM      study           173.9           116.8          50             2.01   2.96   1.47
    DT       peer            202.4            96.2          50             1.74   3.56   2.05
    HDT      peer            330.1           154.9          85             1.06   2.20   2.07

2026-11-29, the machine otherwise idle (the running study paused), 50 updates x 3 repeats:

    method   size   fp32  bf16  bf16+fast  eval s/run   x bf16  x bf16+fast
    DT       study  71.3  59.1       47.8          21     1.20         1.47
    HDT      study 110.4  83.7       73.9          30     1.31         1.48
    DM-noRTG study  90.8  72.2       69.8          37     1.25         1.29
    HDM      study 226.1 170.6      170.1          75     1.31         1.32
    DT       peer  264.5 169.9      152.9          64     1.54         1.70
    HDT      peer  430.1 275.8      261.3         103     1.54         1.62

and again for the DT, 50 x 5: study 70.0, 53.8, 48.7 ms (x 1.29 and 1.42), peer 258.5,
165.9, 150.0 (x 1.54 and 1.69).

So the gain depends on the day's machine: float32 steps took 1.3-1.4x longer on the second
day and bfloat16 steps 1.5-1.8x longer, which no code change explains (the same venv and
code; a float32 [3840, 64] x [64, 256] product takes 2.0 ms, bfloat16 0.6 ms). bf16 doubled the
runs per CPU-hour at the peer's size on the first day and gave 1.5x on the second; at the v2
studies' d64 it gives 1.2-1.55x, since there a step is bound by what bfloat16 does not speed
up (dropout masks, the casts autocast adds, normalisations, the Mamba's scan in float32). The
fast kernels take a tenth to a fifth off a transformer's bf16 step (its dropout masks, a fifth
of the step, cost a quarter as much; AdamW's dozen small ops per parameter become one) and
nothing measurable off the DM/HDM, which have no dropout. Issue #36's 2x at equal config is
met only at the peer's size, and only on the first day; with both levers the v2 studies' d64
reaches 1.4-1.5x. The other levers of issue #36 add little on this CPU
(``bench_ensemble.py``: stacking seeds at most 8%, ``torch.compile`` slower).

2026-12-01, beside a running two-process study, DT at d64, 30 updates x 4 repeats in turns,
an experiment not kept in the code: the fast kernels' attention with its two matrix products
in bfloat16 (softmax in float32) instead of float32 took 56.7 against 57.9 ms (fp32 83.9: x1.48
against x1.45). A bfloat16 step's profile there: casts 18%, the matrix products 27%, dropout
masks 9%, LayerNorm 6%; the attention's float32 products are not what holds the ratio down.

2026-12-02, the same set-up, 30 updates x 4 repeats in turns, another experiment not kept: the
whole DT in bfloat16 (parameters, activations, LayerNorm and fused AdamW, no autocast and so
no casts) took 52.8 ms a step against 54.7 for bf16+fast (float32 84.5): x1.04, so the casts
are not the lever either. torch's profiler on the bf16+fast step: ``copy_`` 17% (about 200
calls a step on [64, 60, 64]-sized tensors), matrix products 24%, lane masks 7%, and the
ReLU and its backward on [64, 60, 256] 7% (about 1.2 ms each: elementwise bfloat16 is slow on
this CPU); no single op is left that could give the missing 1.35x.

2026-12-02 (a later session), the same set-up, DT at d64, 20 updates x 4 repeats in turns after
a warm-up, an experiment not kept: ``torch.compile`` (inductor, ``dynamic=False``) on top of
bf16, where the fusion of the elementwise ops could have paid. The whole model's forward:
124.6 ms a step against 60.3 for bf16+fast (float32 97.1; the input checks and the masked loss
break the graph, and the masked loss recompiles for each count of valid steps); the GPT trunk
alone (``model.transformer``): 120.3 against 60.7 (float32 90.2). Compiled code is twice as
slow on this CPU, with bf16 as with float32 (``bench_ensemble.py``).

2026-12-02 (the sixteenth session), beside a running two-process study, 30 updates x 4 repeats
in turns, the readout-only last block added (``kernels="fast+readout"``, kept in the code). Its
loss and gradients are ``"fast"``'s up to float error (``tests/test_trainer.py``,
``tests/test_attention.py``), so the parity of ``dt-peer-r4-bf16-fast`` carries over; what it
saves is the last block's work at the tokens no loss reads (two of the DT's three, one of the
HDT high level's two), about a fifth to a quarter of a bf16 step at d64:

    method   size   fp32  bf16  bf16+fast  +readout  eval s/run  x bf16  x bf16+fast  x +readout
    DT       study  85.8  63.1       53.1      40.6          27    1.35         1.59        2.05
    HDT      study 110.3  87.0       73.6      57.5          31    1.26         1.48        1.87
    DT       peer  274.4 170.2      161.2     131.5          68    1.59         1.67        2.03
    HDT      peer  559.9 343.8      318.0     281.0         118    1.61         1.73        1.95

and again the same day with the study paused (the machine otherwise idle), 30 x 4:

    method   size   fp32  bf16  bf16+fast  +readout  eval s/run  x bf16  x bf16+fast  x +readout
    DT       study  76.1  57.5       48.8      41.1          27    1.31         1.53        1.80
    HDT      study 119.6  91.9       79.7      66.0          40    1.29         1.48        1.77
    DT       peer  269.4 183.3      172.1     142.5          73    1.45         1.54        1.85
    HDT      peer  443.8 274.2      262.3     221.5         106    1.60         1.66        1.96

So with bf16 and ``fast+readout`` the DT makes 2.03-2.05x the runs per CPU-hour of the v1
code beside a running study and 1.80-1.85x on an idle machine, the HDT 1.87-1.95x and
1.77-1.96x: issue #36's 2x is reached for the DT under load only. The Mambas have no readout
path (their scan runs over every token; a
DM/HDM step is bound by the scan and the float32 elementwise ops around it) and stay at
1.3x: in the same run, with the causal convolution's bfloat16 input cast to float32 once
rather than in each of its four mixed-dtype products (``causal_depthwise_conv1d``; about a
tenth off a bf16 DM step in a direct comparison, 106 against 95 ms), DM-noRTG at 125.4,
97.3, 99.6 and 93.5 ms (x 1.28, 1.25, 1.32) and the HDM at 303.6, 225.0, 215.4 and 219.4 ms
(x 1.33, 1.39, 1.37), where ``fast+readout`` is ``fast`` for them.

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
from thesis_lib.seq.trainer import TrainConfig, Trainer, batch_to_torch

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


VARIANTS = {
    "fp32": ("fp32", "torch"),
    "bf16": ("bf16", "torch"),
    "bf16+fast": ("bf16", "fast"),
    "bf16+fast+readout": ("bf16", "fast+readout"),
}
"""``name: (precision, kernels)``; ``fp32`` is the v1 code's training step."""


def make_trainer(method: str, size: str, precision: str, kernels: str = "torch") -> Trainer:
    d, n_layers = SIZES[size]
    seq = make_data(20, 11, 3)  # Hopper's state and action sizes
    torch.manual_seed(0)
    arch = ArchSpec(d_model=d, n_layers=n_layers, n_heads=1, K=20, dropout=0.1)
    model = build_model(method, seq, arch)
    cfg = TrainConfig(
        iterations=10**9,
        batch_size=64,
        warmup_steps=5000,
        progress=False,
        precision=precision,
        kernels=kernels,
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
    names = list(VARIANTS)
    print(
        f"{'method':8} {'size':5} "
        + " ".join(f"{n + ' ms':>20}" for n in names)
        + f" {'eval s/run':>10} "
        + " ".join(f"{'runs/h ' + n:>24}" for n in names)
        + " "
        + " ".join(f"{'x ' + n:>19}" for n in names[1:])
    )
    for size in args.sizes:
        for method in args.methods:
            trainers = {n: make_trainer(method, size, *VARIANTS[n]) for n in names}
            for t in trainers.values():
                time_steps(t, 3)  # warm-up
            times: dict[str, list[float]] = {n: [] for n in names}
            for r in range(args.repeats):  # in turns, the order reversed every other time
                for n in names[:: 1 if r % 2 == 0 else -1]:
                    times[n].append(time_steps(trainers[n], args.updates))
            step = {n: statistics.median(v) for n, v in times.items()}
            # acting is float32 with torch's kernels on every side: one measurement serves all
            eval_s = RUN_EVAL_STEPS * time_evaluation_step(trainers["fp32"], args.acts)
            per_hour = {n: 3600.0 / (RUN_UPDATES * step[n] + eval_s) for n in names}
            print(
                f"{method:8} {size:5} "
                + " ".join(f"{1e3 * step[n]:20.1f}" for n in names)
                + f" {eval_s:10.0f} "
                + " ".join(f"{per_hour[n]:24.2f}" for n in names)
                + " "
                + " ".join(f"{per_hour[n] / per_hour['fp32']:19.2f}" for n in names[1:])
            )


if __name__ == "__main__":
    main()
