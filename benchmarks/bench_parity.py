"""Our DT's training update against d3rlpy's at equal config (the parity harness's two sides).

Both train on the hopper/medium smoke set for ``--updates`` updates on one CPU thread, at the
study's size (d32, 1 layer) and the peer's (d128, 3 layers), batch 64, K 20. Ours is timed
in this process (:class:`~thesis_lib.seq.trainer.Trainer`); d3rlpy's in its own venv
(``thesis parity --setup``) by the peer script with no evaluation, as the CPU time of its
``fit`` (which includes building its episode buffer once). The ratio d3rlpy / ours > 1 means
ours is faster.

    python benchmarks/bench_parity.py --updates 200
"""

from __future__ import annotations

import argparse
import time

import torch

from thesis_lib.data import SequenceDataset, get_dataset
from thesis_lib.parity import peer_python, run_peer
from thesis_lib.seq import DecisionTransformer, DTConfig
from thesis_lib.seq.trainer import TrainConfig, Trainer

SIZES = {"study (d32 L1)": (32, 1), "peer (d128 L3)": (128, 3)}


def ours(ds, d_model: int, n_layers: int, updates: int) -> float:
    seq = SequenceDataset(ds, K=20, seed=0)
    torch.manual_seed(0)
    model = DecisionTransformer(DTConfig.for_data(seq, d_model=d_model, n_layers=n_layers))
    cfg = TrainConfig(iterations=updates, warmup_steps=10, eval_every=0, progress=False)
    trainer = Trainer(model, seq, cfg)
    t0 = time.process_time()
    trainer.train()
    return time.process_time() - t0


def peer(ds, d_model: int, n_layers: int, updates: int) -> float:
    config = {
        "method": "DT",
        "arch": {"d_model": d_model, "n_layers": n_layers},
        "train": {"seed": 0, "iterations": updates, "warmup_steps": 10},
        "episodes": 0,
    }
    return float(run_peer(config, ds)["train_s"])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--updates", type=int, default=200)
    args = ap.parse_args()
    torch.set_num_threads(1)
    if not peer_python().exists():
        raise SystemExit("No peer venv: run `thesis parity --setup` first.")
    ds = get_dataset("hopper", "medium")
    print(f"DT training, {args.updates} updates, batch 64, K 20, one CPU thread (CPU seconds)")
    for name, (d, n) in SIZES.items():
        a, b = ours(ds, d, n, args.updates), peer(ds, d, n, args.updates)
        print(f"  {name:16s} ours {a / args.updates * 1e3:7.1f} ms/update   d3rlpy "
              f"{b / args.updates * 1e3:7.1f} ms/update   d3rlpy / ours {b / a:5.2f}x")  # fmt: skip


if __name__ == "__main__":
    main()
