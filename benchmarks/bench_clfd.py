"""CLfD's cost claims (thesis 4.2.1.2) and the renderer choice of the pick-and-place task.

Two measurements:

1. **Rendering**: ms per 64x64 frame of each camera of our MJCF scene (primitive shapes) against
   gymnasium-robotics' FetchPickAndPlace (meshes), MuJoCo's software (Mesa EGL) renderer; the
   reason the task uses its own model.
2. **Training step cost**: median wall ms per training batch of CLfD (NT-Xent, two images per pair), the
   TCN baseline (triplet, three images) and CMC (two images), per encoder. The thesis argues that
   CLfD is cheaper than triplet learning because it needs two images instead of three and no
   negative sampling; the ratio TCN / CLfD is printed.

    python benchmarks/bench_clfd.py --batches 10
"""

from __future__ import annotations

import argparse
import os
import time

os.environ.setdefault("MUJOCO_GL", "egl")

import numpy as np
import torch

from thesis_lib.clfd import CAMERAS, CLfD, MultiViewPickPlace, MultiViewVideos


def time_renders(n: int, size: int) -> dict[str, float]:
    env = MultiViewPickPlace(image_size=size)
    env.reset(seed=0)
    env.render_views()
    out = {}
    for cam in CAMERAS:
        t = time.perf_counter()
        for _ in range(n):
            env.render_views([cam])
        out[cam] = (time.perf_counter() - t) / n * 1000
    env.close()
    return out


def time_fetch(n: int, size: int) -> float | None:
    try:
        import gymnasium as gym
        import gymnasium_robotics
        import mujoco
    except ImportError:
        return None
    gym.register_envs(gymnasium_robotics)
    env = gym.make("FetchPickAndPlace-v4")
    env.reset(seed=0)
    u = env.unwrapped
    r = mujoco.Renderer(u.model, size, size)
    times = []
    for cam in range(u.model.ncam):
        r.update_scene(u.data, camera=cam)
        r.render()
        t = time.perf_counter()
        for _ in range(n):
            r.update_scene(u.data, camera=cam)
            r.render()
        times.append((time.perf_counter() - t) / n * 1000)
    r.close()
    env.close()
    return float(np.mean(times))


def time_training(
    encoder: str, batches: int, size: int, batch: int, width: int
) -> dict[str, float]:
    """Median wall ms of one training batch per method; the methods take turns, batch by batch,
    so background load hits them alike."""
    rng = np.random.default_rng(0)
    n = 4 * batch
    data = MultiViewVideos(
        [rng.integers(0, 255, (n, 2, size, size, 3), dtype=np.uint8)], ("a", "b")
    )
    models = {
        m: CLfD(encoder=encoder, method=m, batch_size=batch, width=width, seed=0)
        for m in ("clfd", "tcn", "cmc")
    }
    opts = {
        m: torch.optim.Adam([*mdl.encoder.parameters(), *mdl.projection.parameters()])
        for m, mdl in models.items()
    }
    pairs = models["clfd"]._sample_epoch(data, [0, 1], rng)[:batch]
    times: dict[str, list[float]] = {m: [] for m in models}
    for i in range(batches + 1):
        for m, mdl in models.items():
            t = time.perf_counter()
            loss = mdl._loss(data, pairs)
            opts[m].zero_grad()
            loss.backward()
            opts[m].step()
            if i:  # the first round warms up
                times[m].append((time.perf_counter() - t) * 1000)
    return {m: float(np.median(v)) for m, v in times.items()}


def main() -> None:
    p = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    p.add_argument("--frames", type=int, default=50, help="renders per camera")
    p.add_argument(
        "--batches", type=int, default=10, help="timed training batches per method (median)"
    )
    p.add_argument("--size", type=int, default=48)
    p.add_argument("--batch", type=int, default=32)
    p.add_argument("--width", type=int, default=16)
    args = p.parse_args()
    torch.set_num_threads(1)
    ours = time_renders(args.frames, 64)
    fetch = time_fetch(args.frames // 2, 64)
    print("ms per 64x64 frame:", ", ".join(f"{k} {v:.2f}" for k, v in ours.items()))
    if fetch is not None:
        mean = float(np.mean(list(ours.values())))
        print(
            f"Fetch (meshes), mean over its cameras: {fetch:.2f} ms; ratio Fetch / ours = {fetch / mean:.1f}x"
        )
    for enc in ("tcn", "resnet18"):
        ms = time_training(enc, args.batches, args.size, args.batch, args.width)
        print(
            f"{enc}: ms per batch of {args.batch} pairs: "
            + ", ".join(f"{m} {v:.0f}" for m, v in ms.items())
            + f"; ratio TCN-triplet / CLfD = {ms['tcn'] / ms['clfd']:.2f}"
        )


if __name__ == "__main__":
    main()
