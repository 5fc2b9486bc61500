"""Exploratory: how many deterministic roll-outs of the plain SAC runs' checkpoints reach the
1,000-step horizon (20 per checkpoint, resets seeded 2000-2019)? It sizes a demonstration run
whose safe and unsafe groups both come from SAC (the thesis's recipe). Output: demo_yield.txt.

    THESIS_PROJECT_ROOT=. python studies/03_defender/diagnostics/same_source/demo_yield.py \\
        'studies/03_defender/v3/tasks/partial/*/step-*/model.zip'

Checkpoints are not committed (the study keeps the newest two per run); the run that wrote
demo_yield.txt read copies kept during the session. Keys: c99f7485 = plain SAC seed 0,
33172a5b = plain SAC seed 1, bc7ce061 = SAC + MeanDemoW5/MeanDemoW10 seed 2 (scale check).
"""

from __future__ import annotations

import glob
import sys

import gymnasium as gym
import numpy as np
import torch

from thesis_lib.chapters.defender.lookahead import sb3_policy


def main(pattern: str) -> None:
    torch.set_num_threads(1)
    env = gym.make("Hopper-v5")
    for m in sorted(glob.glob(pattern)):
        act = sb3_policy(m, deterministic=True)
        safe, lengths = 0, []
        for ep in range(20):
            o, _ = env.reset(seed=2000 + ep)
            n = 0
            while True:
                o, _, term, trunc, _ = env.step(act(o))
                n += 1
                if term or trunc:
                    break
            safe += int(trunc and not term)
            lengths.append(n)
        run, step = m.split("/")[-3][:8], m.split("/")[-2]
        print(f"{run} {step}: {safe}/20 reach the horizon, median length {np.median(lengths):.0f}")


if __name__ == "__main__":
    main(sys.argv[1])
