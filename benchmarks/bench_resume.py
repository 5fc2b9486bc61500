"""What checkpoints cost a DEFENDER study run (``train(..., checkpoint=folder)``).

A study run is 200,000 SAC steps on Hopper with 256-256 networks (``params/03_defender.v2.study.yml``)
and saves a checkpoint at the first episode end after every 20,000 steps: ten saves, each with the
replay buffer and DEFENDER's dynamics-model buffer as full as they will get. Two measurements, in
one run and in turns, so that background load affects both alike:

1. **Training** (SB3 SAC, 256-256, batch 256, one torch thread) on Hopper-v5 for ``--steps``
   steps, plain and checkpointed every ``--steps // 4`` steps: CPU ms per step and their ratio.
   This is the chunking's cost (a ``learn`` call per chunk and per step to the episode end).
2. **One save at the study's size**: a model whose replay buffer holds ``--buffer`` transitions,
   with a DEFENDER wrapper whose dynamics model holds as many, saved with ``save_checkpoint``:
   wall seconds per save, and ten of them as a share of a run at the step cost of (1).

Measured here (2026-11-28, 2-core CPU, beside a running study; ``--steps 2000 --repeats 1``):
12.27 ms per step plain and checkpointed, ratio 1.000; one save at 200,000 transitions 0.76 s
(89 MiB for the two kept), so ten saves are 0.3% of a 41 CPU-minute run.

    python benchmarks/bench_resume.py                      # 4,000 steps, a 200,000-transition save
    python benchmarks/bench_resume.py --steps 2000 --repeats 1
"""

from __future__ import annotations

import argparse
import statistics
import tempfile
import time
from pathlib import Path

import gymnasium as gym
import numpy as np
import torch

from thesis_lib.defender import DefenderWrapper, Demonstration
from thesis_lib.rl import config_from_params, make_model, train
from thesis_lib.rl.callbacks import EpisodeLogger
from thesis_lib.rl.resume import ResetRecorder, save_checkpoint


def parse_args() -> argparse.Namespace:
    p = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    p.add_argument("--steps", type=int, default=4000, help="SAC steps per timed run")
    p.add_argument("--repeats", type=int, default=2, help="turns of plain and checkpointed")
    p.add_argument("--buffer", type=int, default=200_000, help="transitions held at the save")
    return p.parse_args()


def _config(steps: int):
    return config_from_params(
        {
            "algo": "SAC",
            "env_id": "Hopper-v5",
            "total_timesteps": steps,
            "seed": 0,
            "net_arch": [256, 256],
            "learning_rate": 3e-4,
            "batch_size": 256,
        }
    )


def _demos(n: int, length: int, rng: np.random.Generator) -> list[Demonstration]:
    return [
        Demonstration(
            rng.normal(size=(length + 1, 11)),
            rng.uniform(-1, 1, (length, 3)),
            np.ones(length),
            False,
            True,
        )
        for _ in range(n)
    ]


def time_training(steps: int, repeats: int) -> tuple[float, float]:
    """Median CPU ms per step, plain and checkpointed."""
    plain, chunked = [], []
    for _ in range(repeats):
        c0 = time.process_time()
        train(_config(steps), progress=False)
        plain.append(1e3 * (time.process_time() - c0) / steps)
        with tempfile.TemporaryDirectory() as folder:
            c0 = time.process_time()
            train(_config(steps), progress=False, checkpoint=folder, checkpoint_every=steps // 4)
            chunked.append(1e3 * (time.process_time() - c0) / steps)
    return statistics.median(plain), statistics.median(chunked)


def time_save(n: int) -> float:
    """Wall seconds of one checkpoint whose buffers hold ``n`` transitions."""
    rng = np.random.default_rng(0)
    env = DefenderWrapper(gym.make("Hopper-v5"), _demos(50, 1000, rng), _demos(50, 100, rng))
    recorder = ResetRecorder(env)
    model = make_model(_config(n), recorder)
    buffer = model.replay_buffer  # type: ignore[attr-defined]
    for name in ("observations", "next_observations", "actions", "rewards"):
        getattr(buffer, name)[:n] = rng.normal(size=getattr(buffer, name)[:n].shape)
    buffer.pos = n
    dyn = env.dynamics
    dyn._inputs[:n] = rng.normal(size=dyn._inputs[:n].shape)
    dyn._targets[:n] = rng.normal(size=dyn._targets[:n].shape)
    dyn._size = dyn._pos = dyn._added = n
    parts = {"episode_logger": EpisodeLogger(), "wrapper0:DefenderWrapper": env}
    walls = []
    with tempfile.TemporaryDirectory() as folder:
        for _ in range(3):
            t0 = time.perf_counter()
            save_checkpoint(folder, model, recorder, parts, {})
            walls.append(time.perf_counter() - t0)
        size = sum(f.stat().st_size for f in Path(folder).rglob("*") if f.is_file())
    print(f"checkpoint folder after 3 saves (the newest two kept): {size / 2**20:.0f} MiB")
    return statistics.median(walls)


def main() -> None:
    args = parse_args()
    torch.set_num_threads(1)
    plain, chunked = time_training(args.steps, args.repeats)
    print(
        f"SAC on Hopper, {args.steps:,} steps: plain {plain:.2f} ms/step, checkpointed every "
        f"{args.steps // 4:,} {chunked:.2f} ms/step, ratio {chunked / plain:.3f}"
    )
    save_s = time_save(args.buffer)
    run_s = 200_000 * plain / 1e3
    print(
        f"one save at {args.buffer:,} transitions: {save_s:.2f} s; ten in a 200,000-step run "
        f"of {run_s / 60:.0f} CPU-minutes: {100 * 10 * save_s / run_s:.2f}% of it"
    )


if __name__ == "__main__":
    main()
