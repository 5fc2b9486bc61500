"""What DEFENDER's filter adds to a SAC training step (thesis 4.3.3, "% Time").

The thesis reports +19% to +3,245% wall time for its filter (Tables 4.3-4.4). Target here:
at most +10% per SAC training step with 50 + 50 demonstrations and the thesis's top state
strategies.

Two measurements, in one run:

1. **Per-step filter cost** (no agent): one ``DefenderWrapper`` decision (two group costs)
   for each of the thesis's 5 top state strategies, with ``thesis_lib.dtw`` (exact,
   incremental where possible) and with fastdtw (radius 1, L1, 20-step cap: the authors'
   setting), next to the dynamics model's gradient step.
2. **SAC training** (SB3 SAC, 256-256 nets, batch 256, one torch thread) on Hopper-v5: one
   model takes turns of ``--block`` steps on each env variant until each has run ``--steps``
   steps. Variants: plain SAC; the wrapper's **default** (exact DTW, dynamics model updated every
   4th real step) for each of the thesis's 5 top state strategies; **Algorithm 2 to the letter**
   (exact DTW, dynamics updated every real step); the DTW filter alone (dynamics never
   updated); and the **paper-faithful** ``paper_compat=True`` (fastdtw radius 1, 20-step cap,
   dynamics every step; shorter turns). Wall and CPU ms per step, the ratio to plain SAC and
   whether the +10% target is met are printed.

Demonstrations are 50 "safe" (1,000 steps) and 50 "unsafe" (20-300 steps) sequences of Hopper's
size. The unsafe group is shifted far away so the filter never fires: every step does the full
comparison work and the agent sees the same episodes as plain SAC, so the timings compare like
with like. Taking turns on one model spreads background load over all variants.

    python benchmarks/bench_defender.py --steps 1600 --block 200
    python benchmarks/bench_defender.py --steps 800 --one-strategy   # quicker
"""

from __future__ import annotations

import argparse
import os
import platform
import time

import gymnasium as gym
import numpy as np
import torch

from thesis_lib.defender import (
    DYNAMICS_TRAIN_EVERY,
    THESIS_STATE_STRATEGIES,
    DefenderWrapper,
    Demonstration,
    DynamicsModel,
)


def parse_args() -> argparse.Namespace:
    p = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    p.add_argument("--env", default="Hopper-v5")
    p.add_argument("--steps", type=int, default=1600, help="timed SAC steps per variant")
    p.add_argument(
        "--block",
        type=int,
        default=200,
        help="steps per turn; variants take turns on one SAC model",
    )
    p.add_argument("--n-demos", type=int, default=50, help="demonstrations per group")
    p.add_argument(
        "--strategy",
        default="MeanDemoW5/MeanDemoW10",
        help="strategy of the Algorithm-2, filter-only and fastdtw SAC runs",
    )
    p.add_argument(
        "--one-strategy",
        action="store_true",
        help="time the default wrapper with --strategy only, not each of the thesis's top 5",
    )
    p.add_argument(
        "--skip-fastdtw-sac", action="store_true", help="skip the (slow) SAC run with fastdtw"
    )
    p.add_argument("--seed", type=int, default=0)
    return p.parse_args()


def make_demos(
    env: gym.Env, n: int, rng: np.random.Generator
) -> tuple[list[Demonstration], list[Demonstration]]:
    obs_dim, act_dim = env.observation_space.shape[0], env.action_space.shape[0]

    def demo(length: int, offset: float, terminated: bool) -> Demonstration:
        obs = np.cumsum(rng.normal(0, 0.05, (length + 1, obs_dim)), axis=0) + offset
        return Demonstration(
            obs,
            rng.uniform(-1, 1, (length, act_dim)),
            rng.normal(1, 0.1, length),
            terminated,
            not terminated,
        )

    safe = [demo(1000, 0.0, False) for _ in range(n)]
    unsafe = [
        demo(int(rng.integers(20, 300)), 1e3, True) for _ in range(n)
    ]  # far away: never fires
    return safe, unsafe


def per_step_costs(env_id: str, safe, unsafe, rng) -> list[tuple[str, str, float]]:
    """Median µs of one filter decision (both groups) over 300 steps of a random trajectory."""
    rows = []
    obs_dim = gym.make(env_id).observation_space.shape[0]
    steps = rng.normal(0, 0.5, (300, obs_dim))
    for strategy in THESIS_STATE_STRATEGIES:
        s, u = strategy.split("/")
        for label, kw in (
            ("exact", {}),
            ("exact, 20-step cap", {"max_trajectory": 20}),
            ("fastdtw (paper_compat)", {"paper_compat": True}),
        ):
            w = DefenderWrapper(
                gym.make(env_id), safe, unsafe, safe_method=s, unsafe_method=u, **kw
            )
            n = 60 if "fastdtw" in label else 300
            w._safe.append(steps[0]), w._unsafe.append(steps[0])
            w._safe.reset(), w._unsafe.reset()
            t = time.perf_counter()
            for x in steps[:n]:
                w._safe.append(x)
                w._unsafe.append(x)
            rows.append((strategy, label, 1e6 * (time.perf_counter() - t) / n))
    dyn = DynamicsModel(obs_dim, 3)
    for _ in range(300):
        dyn.add(rng.normal(size=obs_dim), rng.normal(size=3), rng.normal(size=obs_dim))
    dyn.train_step()
    t = time.perf_counter()
    for _ in range(100):
        dyn.train_step()
    rows.append(
        (
            "dynamics model",
            "one gradient step (batch 256, 256-256)",
            1e6 * (time.perf_counter() - t) / 100,
        )
    )
    return rows


def time_variants(
    variants: dict, steps: int, block: int, seed: int
) -> dict[str, tuple[float, float]]:
    """(wall ms, CPU ms) per SAC training step for each env variant, measured on one SAC model.

    The model switches env every ``block`` steps (``set_env`` forces a reset), cycling through
    the variants until each has run ``steps`` timed steps, so slow drifts in background load hit
    every variant alike. CPU time is this process's (one torch thread).
    """
    from stable_baselines3 import SAC

    envs = {name: make() for name, make in variants.items()}
    model = SAC(
        "MlpPolicy",
        envs["plain SAC"],
        learning_rate=3e-4,
        batch_size=256,
        learning_starts=100,
        policy_kwargs={"net_arch": [256, 256]},
        seed=seed,
        device="cpu",
    )
    model.learn(300)  # random warm-up and the first gradient steps, untimed
    wall = dict.fromkeys(envs, 0.0)
    cpu = dict.fromkeys(envs, 0.0)
    timed = dict.fromkeys(envs, 0)  # steps actually timed
    for env in envs.values():  # one untimed turn each: JIT, first resets, dynamics warm-up
        model.set_env(env)
        model.learn(20, reset_num_timesteps=False)
    # fastdtw is ~10x slower per step: it gets turns of block // 8 steps and as many turns.
    size = {name: max(10, block // 8) if "fastdtw" in name else block for name in envs}
    n_turns = -(-steps // block)
    for _ in range(n_turns):
        for name, env in envs.items():
            model.set_env(env)
            t, c = time.perf_counter(), time.process_time()
            model.learn(size[name], reset_num_timesteps=False)
            wall[name] += time.perf_counter() - t
            cpu[name] += time.process_time() - c
            timed[name] += size[name]
    out = {name: (1e3 * wall[name] / timed[name], 1e3 * cpu[name] / timed[name]) for name in envs}
    return out


def main() -> None:
    args = parse_args()
    torch.set_num_threads(1)
    rng = np.random.default_rng(args.seed)
    safe, unsafe = make_demos(gym.make(args.env), args.n_demos, rng)
    print(
        f"# DEFENDER overhead: {args.env}, {args.n_demos} + {args.n_demos} demonstrations, "
        f"{platform.processor() or platform.machine()}, {os.cpu_count()} cores, torch threads 1, "
        f"load average {os.getloadavg()[0]:.1f}"
    )

    print("\n## Per-step filter cost (one decision: both groups), µs")
    decision_us = {}
    for strategy, label, us in per_step_costs(args.env, safe, unsafe, rng):
        print(f"{strategy:26s} {label:40s} {us:10.1f}")
        if label == "exact":
            decision_us[strategy] = us

    def wrapped(strategy: str, **kw):
        s, u = strategy.split("/")
        return lambda: DefenderWrapper(
            gym.make(args.env), safe, unsafe, safe_method=s, unsafe_method=u, **kw
        )

    variants = {"plain SAC": lambda: gym.make(args.env)}
    for strategy in [args.strategy] if args.one_strategy else THESIS_STATE_STRATEGIES:
        variants[f"default: {strategy}"] = wrapped(strategy)  # exact DTW, dynamics every 4th step
    variants[f"Algorithm 2 (dynamics every step): {args.strategy}"] = wrapped(
        args.strategy, dynamics_train_every=1
    )
    variants[f"DTW filter only (no dynamics update): {args.strategy}"] = wrapped(
        args.strategy, dynamics_train_every=10**9
    )
    if not args.skip_fastdtw_sac:
        variants[f"paper-faithful fastdtw (paper_compat): {args.strategy}"] = wrapped(
            args.strategy, paper_compat=True
        )
    times = time_variants(variants, args.steps, args.block, args.seed)
    wall0, cpu0 = times["plain SAC"]
    print(
        f"\n## SAC training step (256-256, batch 256, {args.steps} steps per variant in blocks of "
        f"{args.block}, one model; default = exact DTW, dynamics model updated every "
        f"{DYNAMICS_TRAIN_EVERY}th real step)"
    )
    print(
        f"{'variant':62s} {'wall ms':>8s} {'ratio':>7s} {'CPU ms':>8s} {'ratio':>7s}  target <= 1.10 (wall, CPU)"
    )

    def verdict(ratio: float) -> str:
        return "met" if ratio <= 1.10 else "NOT met"

    for name, (wall, cpu) in times.items():
        v = "" if name == "plain SAC" else f"{verdict(wall / wall0)}, {verdict(cpu / cpu0)}"
        print(f"{name:62s} {wall:8.2f} {wall / wall0:7.3f} {cpu:8.2f} {cpu / cpu0:7.3f}  {v}")
    load = os.getloadavg()[0]
    if load > (os.cpu_count() or 1):
        print(
            f"\nNote: load average {load:.1f} on {os.cpu_count()} cores during the run: other processes took "
            "turns on the CPU, so wall ratios are unreliable; the CPU ratios (this process's own time) are "
            "the better measure."
        )
    main_ratio = times[f"default: {args.strategy}"][0] / wall0
    others = [st for st in THESIS_STATE_STRATEGIES if f"default: {st}" not in times]
    if others and args.strategy in decision_us:
        print(
            f"\n## Estimated wall ratio of the default wrapper for the other top-5 state strategies\n"
            f"(measured ratio of {args.strategy} + the difference in decision cost / plain step)"
        )
        for st in others:
            est = main_ratio + (decision_us[st] - decision_us[args.strategy]) / (1e3 * wall0)
            print(f"{'default: ' + st:62s} {'':8s} {est:7.3f}  {verdict(est)} (estimate)")


if __name__ == "__main__":
    main()
