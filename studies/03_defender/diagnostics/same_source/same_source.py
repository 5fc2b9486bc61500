"""Exploratory (not a registered study): where do DEFENDER's firings come from?

DEFENDER (MeanDemoW5/MeanDemoW10, state trajectories) on a plain SAC policy of
defender-c7c9-v3, once with the study's demonstrations (its 50 safe ones all from the shipped
expert, its 50 unsafe ones all from its 30,000-step SAC run) and once with the safe group
replaced by roll-outs of that same SAC policy that reached the horizon (the unsafe group kept).
Nothing learns. Output: same_source.txt beside this file.

    THESIS_PROJECT_ROOT=. python studies/03_defender/diagnostics/same_source/same_source.py \\
        studies/03_defender/v3/tasks/partial/c99f7485a1306c22/step-0000140239/model.zip

The checkpoint is a study run's (plain SAC, seed 0, at 140,239 steps); checkpoints are not
committed, so the run that wrote same_source.txt used a copy kept during the session.
"""

from __future__ import annotations

import sys

import gymnasium as gym
import numpy as np
import torch

from thesis_lib.book import study as st
from thesis_lib.chapters import get_chapter
from thesis_lib.chapters.defender.demos import make_env, study_demonstrations
from thesis_lib.chapters.defender.lookahead import filter_lookahead, sb3_policy
from thesis_lib.chapters.defender.study import study_task
from thesis_lib.defender import Demonstration, DemoSet, select_diverse


def main(model: str, rollouts: int = 40, steps: int = 5000) -> None:
    torch.set_num_threads(1)
    s = st.load_study("03_defender:v3")
    cfg = st.study_config(s, get_chapter(s.chapter))
    recipe = study_task(cfg, "Hopper-v5", "SAC", 0, "MeanDemoW5/MeanDemoW10").config["demos"]
    demos, _ = study_demonstrations("Hopper-v5", recipe, 50)
    act = sb3_policy(model, deterministic=True)
    env = gym.make("Hopper-v5")
    safe = []
    for ep in range(rollouts):
        o, _ = env.reset(seed=1000 + ep)
        obs, acts, rews = [o], [], []
        while True:
            a = act(o)
            o, r, term, trunc, _ = env.step(a)
            acts.append(a)
            rews.append(r)
            obs.append(o)
            if term or trunc:
                break
        if trunc and not term:
            safe.append(
                Demonstration(np.array(obs[:-1]), np.array(acts), np.array(rews), False, True)
            )
    print(f"roll-outs of the policy that reached the horizon: {len(safe)} of {rollouts}")
    own = DemoSet(select_diverse(safe, min(50, len(safe))), demos.unsafe, "Hopper-v5")
    policy = sb3_policy(model, seed=0)
    for name, d in (("the study's demonstrations (safe: expert)", demos), ("safe: own", own)):
        out = filter_lookahead(
            policy, lambda: make_env("Hopper-v5", None), d, steps=steps, lookahead=(10, 50, 100)
        )
        f = out.firings.filter_step
        print(
            f"{name}: {out.summary['firings_per_1k_steps']:.1f} firings per 1,000 steps; fires "
            f"at step (10/50/90%) {f.quantile([0.1, 0.5, 0.9]).round(0).tolist() if len(f) else '-'}"
            f"; episodes without the filter last {out.summary['control_length_median']:.0f} "
            f"steps (median), {100 * out.summary['control_crashed_share']:.0f}% crash"
        )
        print(out.table.round(3).to_string(index=False))


if __name__ == "__main__":
    main(sys.argv[1])
