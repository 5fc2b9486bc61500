"""Benchmark thesis_lib.data: roll-out throughput, full-size data-set time, window sampling.

    python benchmarks/bench_data.py                 # all tasks, 5,000 transitions each
    python benchmarks/bench_data.py --tasks hopper maze2d-umaze --n 20000

Prints, per task, roll-out throughput (transitions/s, policy + environment), the store +
load time, and the extrapolated time to make each D4RL-size data set (1M transitions; 2M
for medium-expert). Then the time of ``SequenceDataset.sample(64)`` with K = 20, against a
per-sample Python loop (the way CORL's DT ``SequenceDataset`` samples), as a ratio.
"""

from __future__ import annotations

import argparse
import os
import tempfile
import time
import warnings

import numpy as np

warnings.filterwarnings("ignore")


def bench_rollouts(tasks: list[str], n: int) -> list[dict]:
    from thesis_lib.data import (
        gen_dataset_id,
        get_task,
        load,
        make_env,
        make_episodes,
        write_dataset,
    )
    from thesis_lib.data.experts import has_policies

    rows = []
    for task in tasks:
        spec = get_task(task)
        tier = "expert" if (spec.kind == "maze" or has_policies(task)) else "random"
        if spec.kind == "robotics":
            tier = "random"
        t0 = time.perf_counter()
        eps, _ = make_episodes(task, tier, n, seed=0)
        roll = time.perf_counter() - t0
        did = gen_dataset_id(task, tier)
        env = make_env(task)
        t0 = time.perf_counter()
        write_dataset(did, eps, env.spec, spec.ref_min_score, spec.ref_max_score)
        store = time.perf_counter() - t0
        env.close()
        t0 = time.perf_counter()
        load(did)
        ld = time.perf_counter() - t0
        gen = roll + store
        tps = n / roll
        rows.append(
            {
                "task": task,
                "tier": tier,
                "transitions/s": tps,
                "store_s": store,
                "load_s": ld,
                "full_1M_min": (1e6 / n) * gen / 60,
                "full_medium_expert_2M_min": (2e6 / n) * gen / 60,
            }
        )
        print(
            f"{task:26s} {tier:8s} {tps:9.0f} tr/s  store {store:6.2f}s  load {ld:6.2f}s"
            f"  -> 1M: {rows[-1]['full_1M_min']:6.1f} min, 2M: "
            f"{rows[-1]['full_medium_expert_2M_min']:6.1f} min",
            flush=True,
        )
    return rows


def _loop_sample(episodes, K: int, batch: int, rng: np.random.Generator, scale: float):
    """Reference: one Python iteration per window (CORL-style), right padding."""
    lens = np.array([len(e) for e in episodes])
    p = lens / lens.sum()
    out_s, out_a, out_r, out_t, out_m = [], [], [], [], []
    for _ in range(batch):
        e = episodes[rng.choice(len(episodes), p=p)]
        si = rng.integers(len(e))
        s = e.observations[si : si + K]
        a = e.actions[si : si + K]
        rtg = np.cumsum(e.rewards[si:][::-1])[::-1][:K] / scale
        L = len(s) if si + K <= len(e) else len(e) - si
        s, a, rtg = s[:L], a[:L], rtg[:L]
        pad = K - L
        out_s.append(np.pad(s, ((0, pad), (0, 0))))
        out_a.append(np.pad(a, ((0, pad), (0, 0))))
        out_r.append(np.pad(rtg, (0, pad)))
        out_t.append(np.pad(np.arange(si, si + L), (0, pad)))
        out_m.append(np.r_[np.ones(L), np.zeros(pad)])
    return [np.stack(x) for x in (out_s, out_a, out_r, out_t, out_m)]


def bench_sequence(n_steps: int = 200_000, K: int = 20, batch: int = 64, reps: int = 200) -> dict:
    from thesis_lib.data import Episode, SequenceDataset

    rng = np.random.default_rng(0)
    eps, total, i = [], 0, 0
    while total < n_steps:
        T = int(rng.integers(50, 1001))
        eps.append(
            Episode(
                i,
                rng.standard_normal((T + 1, 17)),
                rng.standard_normal((T, 6)),
                rng.standard_normal(T),
                np.zeros(T, bool),
                np.zeros(T, bool),
            )
        )
        total += T
        i += 1
    ds = SequenceDataset(eps, K=K)
    ds.sample(batch)
    t0 = time.perf_counter()
    for _ in range(reps):
        ds.sample(batch)
    ours = (time.perf_counter() - t0) / reps
    t0 = time.perf_counter()
    r = np.random.default_rng(1)
    for _ in range(max(5, reps // 10)):
        _loop_sample(eps, K, batch, r, 1000.0)
    loop = (time.perf_counter() - t0) / max(5, reps // 10)
    print(
        f"SequenceDataset.sample(batch={batch}, K={K}) on {total} steps / {len(eps)} episodes: "
        f"{ours * 1e3:.3f} ms; per-sample loop {loop * 1e3:.3f} ms; speed-up x{loop / ours:.1f}"
    )
    return {"ours_ms": ours * 1e3, "loop_ms": loop * 1e3, "ratio": loop / ours}


def main() -> None:
    from thesis_lib.data import TASKS

    ap = argparse.ArgumentParser(description=__doc__)
    default = [t for t, s in TASKS.items() if s.kind != "robotics" or s.tiers]
    ap.add_argument("--tasks", nargs="*", default=default)
    ap.add_argument("--n", type=int, default=5000, help="transitions rolled out per task")
    ap.add_argument(
        "--keep", action="store_true", help="write into THESIS_DATA_DIR, not a temp dir"
    )
    a = ap.parse_args()
    if not a.keep:
        os.environ["THESIS_DATA_DIR"] = tempfile.mkdtemp(prefix="bench_data_")
    bench_rollouts(a.tasks, a.n)
    bench_sequence()


if __name__ == "__main__":
    main()
