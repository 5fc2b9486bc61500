"""Time BC, DT and HDT: one training iteration and one environment step of inference.

* train: one ``Trainer.step()`` (sample a batch from a SequenceDataset, forward, masked
  MSE, backward, grad-norm clip, AdamW step), on HalfCheetah-sized data (17-d states,
  6-d actions), batch 64, K 20 by default. HDT trains both levels in that step.
* inference: one environment step of ``evaluate`` in HalfCheetah-v5 with one episode
  (build the K-step history, ``model.act``, ``env.step``), as Table 5.6 measures it;
  "act only" is ``model.act`` on a full K-step history of one episode.

Times are per iteration/step: the median and the best of ``--repeats`` runs, the models taking
turns run by run so that background load affects them alike. Table 5.6's numbers (GPU, batch
16, 6 layers, d 128, K 20, HalfCheetah) are printed beside ours for scale, not for equality.

    python benchmarks/bench_seq.py                      # batch 64, 3 layers (the authors' HDT code)
    python benchmarks/bench_seq.py --batch 16 --n-layer 6   # Table 5.6's configuration
"""
from __future__ import annotations

import argparse
import platform
import statistics
import time

import numpy as np
import torch

from thesis_lib.data import Episode, SequenceDataset
from thesis_lib.seq.evaluate import evaluate
from thesis_lib.seq.models import BC, HDT, BCConfig, DecisionTransformer, DTConfig, HDTConfig
from thesis_lib.seq.subgoals import subgoal_fn
from thesis_lib.seq.trainer import TrainConfig, Trainer, batch_to_torch

# Table 5.6, HalfCheetah row (ms, mean): GPU, batch 16, 6 layers.
TABLE_5_6 = {"DT": (14, 5), "HDT": (19, 7)}


def parse_args() -> argparse.Namespace:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--batch", type=int, default=64)
    p.add_argument("--K", type=int, default=20)
    p.add_argument("--d-model", type=int, default=128)
    p.add_argument("--n-layer", type=int, default=3)
    p.add_argument("--train-iters", type=int, default=10, help="iterations per timed training run")
    p.add_argument("--env-steps", type=int, default=100, help="environment steps per timed inference run")
    p.add_argument("--repeats", type=int, default=5)
    p.add_argument("--threads", type=int, default=1, help="torch CPU threads")
    p.add_argument("--device", default="cpu", help="cpu or cuda")
    return p.parse_args()


def make_data(K: int, seed: int = 0) -> SequenceDataset:
    rng = np.random.default_rng(seed)
    eps = []
    for i in range(20):
        T = 1000
        obs = rng.normal(size=(T + 1, 17))
        eps.append(Episode(i, obs, rng.uniform(-1, 1, (T, 6)).astype(np.float32), rng.normal(size=T),
                           np.zeros(T, bool), np.zeros(T, bool)))
    return SequenceDataset(eps, K=K, subgoal_fn=subgoal_fn(), seed=seed)


def make_models(args: argparse.Namespace) -> dict[str, torch.nn.Module]:
    torch.manual_seed(0)
    tf = dict(K=args.K, d_model=args.d_model, n_layer=args.n_layer, n_head=1)
    return {
        "BC": BC(BCConfig(17, 6, K=args.K)),
        "DT": DecisionTransformer(DTConfig(17, 6, **tf)),
        "HDT": HDT(HDTConfig(17, 6, **tf)),
    }


def main() -> None:
    args = parse_args()
    torch.set_num_threads(args.threads)
    seq = make_data(args.K)
    models = make_models(args)
    cfg = TrainConfig(batch_size=args.batch, progress=False, device=args.device)
    trainers = {k: Trainer(m, seq, cfg) for k, m in models.items()}
    one = batch_to_torch(seq, seq.windows(np.array([0]), np.array([100])))  # one full K-step window
    history = {k: v.to(args.device) for k, v in one.items() if k != "mask"}
    times: dict[str, dict[str, list[float]]] = {k: {"train": [], "act": [], "step": []} for k in models}

    for k, tr in trainers.items():  # warm-up
        for _ in range(2):
            tr.step()
        m = tr.model.eval()
        m.act(history)
        evaluate(m, "halfcheetah", 1, target_return=1000.0, dataset=seq, max_steps=5)
    for _ in range(args.repeats):
        for k, tr in trainers.items():
            t = time.perf_counter()
            for _ in range(args.train_iters):
                tr.step()
            if args.device != "cpu":
                torch.cuda.synchronize()
            times[k]["train"].append((time.perf_counter() - t) / args.train_iters)
            m = tr.model.eval()
            t = time.perf_counter()
            for _ in range(20):
                m.act(history)
            if args.device != "cpu":
                torch.cuda.synchronize()
            times[k]["act"].append((time.perf_counter() - t) / 20)
            t = time.perf_counter()
            res = evaluate(m, "halfcheetah", 1, target_return=1000.0, dataset=seq, max_steps=args.env_steps)
            times[k]["step"].append((time.perf_counter() - t) / int(res.lengths.sum()))

    print(f"# bench_seq: torch {torch.__version__}, {platform.processor() or platform.machine()}, "
          f"{args.threads} thread(s), {args.device}; batch {args.batch}, K {args.K}, d {args.d_model}, {args.n_layer} layers")
    print(f"{'model':6} {'params':>9} {'train ms (best)':>18} {'x DT':>6} {'act ms':>8} {'step ms (best)':>16} "
          f"{'x DT':>6} {'Table 5.6 train/step ms (GPU)':>30}")
    med = {k: {p: statistics.median(v) * 1e3 for p, v in d.items()} for k, d in times.items()}
    for k in models:
        best_train, best_step = min(times[k]["train"]) * 1e3, min(times[k]["step"]) * 1e3
        n_params = sum(p.numel() for p in models[k].parameters())
        ref = TABLE_5_6.get(k)
        ref_s = f"{ref[0]} / {ref[1]}" if ref else "-"
        print(f"{k:6} {n_params:9d} {med[k]['train']:8.2f} ({best_train:6.2f}) {med[k]['train'] / med['DT']['train']:6.2f} "
              f"{med[k]['act']:8.2f} {med[k]['step']:7.2f} ({best_step:6.2f}) {med[k]['step'] / med['DT']['step']:6.2f} "
              f"{ref_s:>30}")


if __name__ == "__main__":
    main()
