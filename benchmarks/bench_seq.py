"""Time BC, DT and HDT: one training iteration and one environment step of inference.

* train: one ``Trainer.step()`` (sample a batch from a SequenceDataset, forward, masked
  MSE, backward, grad-norm clip, AdamW step), on data of the task's sizes (HalfCheetah:
  17-d states, 6-d actions), batch 64, K 20 by default. HDT trains both levels in that step.
* inference: one environment step of ``evaluate`` in the task's environment with one
  episode (build the K-step history, ``model.act``, ``env.step``), as Table 5.6 measures it;
  "act" is ``model.act`` alone on a full K-step history of one episode.

Times are per iteration/step: the median (± the std) and the best of ``--repeats`` runs, the
models taking turns run by run so that background load affects them alike. Beside them:
Table 5.6's numbers for the task's environment (GPU, batch 16, 6 layers, d 128, K 20; mean ±
std in ms) and the ratio HDT / DT of both, the comparable quantity (absolute times depend on
the hardware). The Decision Mamba columns of Table 5.6 are the Decision Mamba chapter's.

    python benchmarks/bench_seq.py                          # batch 64, 3 layers (the authors' HDT code)
    python benchmarks/bench_seq.py --table-5-6 --task hopper  # Table 5.6's configuration, Hopper row
"""

from __future__ import annotations

import argparse
import platform
import statistics
import time

import numpy as np
import torch

from thesis_lib.data import Episode, SequenceDataset
from thesis_lib.seq.evaluation import evaluate
from thesis_lib.seq.models import BC, HDT, BCConfig, DecisionTransformer, DTConfig, HDTConfig
from thesis_lib.seq.subgoals import subgoal_fn
from thesis_lib.seq.trainer import TrainConfig, Trainer, batch_to_torch

# Table 5.6's environment names.
TABLE_5_6_ENV = {
    "halfcheetah": "HalfCheetah",
    "hopper": "Hopper",
    "walker2d": "Walker2d",
    "ant": "Ant",
    "kitchen": "Kitchen",
}


def table_5_6(task: str) -> dict[str, dict[str, tuple[float, float]]]:
    """``{method: {"train" | "inference": (mean ms, std ms)}}`` of Table 5.6's row for ``task``."""
    from thesis_lib.book import load_reference

    env = TABLE_5_6_ENV.get(task) or (
        "Maze2d" if task.startswith("maze2d") else "Antmaze" if task.startswith("antmaze") else None
    )
    if env is None:
        return {}
    ref = load_reference("5.6")
    out: dict[str, dict[str, tuple[float, float]]] = {}
    for r in ref[ref["env"] == env].itertuples():
        out.setdefault(r.method, {})[r.phase] = (float(r.time_ms_mean), float(r.time_ms_std))
    return out


def parse_args() -> argparse.Namespace:
    p = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    p.add_argument(
        "--task", default="halfcheetah", help="task whose sizes and environment are used"
    )
    p.add_argument(
        "--table-5-6", action="store_true", help="Table 5.6's configuration: batch 16, 6 layers"
    )
    p.add_argument("--batch", type=int, default=64)
    p.add_argument("--K", type=int, default=20)
    p.add_argument("--d-model", type=int, default=128)
    p.add_argument("--n-layer", type=int, default=3)
    p.add_argument("--train-iters", type=int, default=10, help="iterations per timed training run")
    p.add_argument(
        "--env-steps", type=int, default=100, help="environment steps per timed inference run"
    )
    p.add_argument("--repeats", type=int, default=5)
    p.add_argument("--threads", type=int, default=1, help="torch CPU threads")
    p.add_argument("--device", default="cpu", help="cpu or cuda")
    args = p.parse_args()
    if args.table_5_6:
        args.batch, args.n_layer, args.d_model, args.K = 16, 6, 128, 20
    return args


def task_sizes(task: str) -> tuple[int, int]:
    """(state size, action size) of ``task``'s environment."""
    from thesis_lib.data import make_env

    env = make_env(task)
    obs, _ = env.reset(seed=0)
    if isinstance(obs, dict):  # PointMaze/AntMaze: the models read obs["observation"]
        obs = obs["observation"]
    sd = int(np.asarray(obs).size)
    ad = int(np.prod(env.action_space.shape))
    env.close()
    return sd, ad


def make_data(K: int, sd: int = 17, ad: int = 6, seed: int = 0) -> SequenceDataset:
    rng = np.random.default_rng(seed)
    eps = []
    for i in range(20):
        T = 1000
        obs = rng.normal(size=(T + 1, sd))
        eps.append(
            Episode(
                i,
                obs,
                rng.uniform(-1, 1, (T, ad)).astype(np.float32),
                rng.normal(size=T),
                np.zeros(T, bool),
                np.zeros(T, bool),
            )
        )
    return SequenceDataset(eps, K=K, subgoal_fn=subgoal_fn(), seed=seed)


def make_models(args: argparse.Namespace, sd: int = 17, ad: int = 6) -> dict[str, torch.nn.Module]:
    torch.manual_seed(0)
    tf = dict(K=args.K, d_model=args.d_model, n_layers=args.n_layer, n_heads=1)
    return {
        "BC": BC(BCConfig(sd, ad, K=args.K)),
        "DT": DecisionTransformer(DTConfig(sd, ad, **tf)),
        "HDT": HDT(HDTConfig(sd, ad, **tf)),
    }


def main() -> None:
    args = parse_args()
    torch.set_num_threads(args.threads)
    sd, ad = task_sizes(args.task)
    seq = make_data(args.K, sd, ad)
    models = make_models(args, sd, ad)
    cfg = TrainConfig(batch_size=args.batch, progress=False, device=args.device)
    trainers = {k: Trainer(m, seq, cfg) for k, m in models.items()}
    one = batch_to_torch(seq, seq.windows(np.array([0]), np.array([100])))  # one full K-step window
    history = {k: v.to(args.device) for k, v in one.items() if k != "mask"}
    times: dict[str, dict[str, list[float]]] = {
        k: {"train": [], "act": [], "step": []} for k in models
    }

    for tr in trainers.values():  # warm-up
        for _ in range(2):
            tr.step()
        m = tr.model.eval()
        m.act(history)
        evaluate(m, args.task, 1, target_return=1000.0, dataset=seq, max_steps=5)
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
            res = evaluate(
                m, args.task, 1, target_return=1000.0, dataset=seq, max_steps=args.env_steps
            )
            times[k]["step"].append((time.perf_counter() - t) / int(res.lengths.sum()))

    print(
        f"# bench_seq: torch {torch.__version__}, {platform.processor() or platform.machine()}, "
        f"{args.threads} thread(s), {args.device}; task {args.task} ({sd}-d states, {ad}-d actions); "
        f"batch {args.batch}, K {args.K}, d {args.d_model}, {args.n_layer} layers; {args.repeats} repeats"
    )
    ref = table_5_6(args.task)
    med = {k: {p: statistics.median(v) * 1e3 for p, v in d.items()} for k, d in times.items()}
    std = {k: {p: statistics.pstdev(v) * 1e3 for p, v in d.items()} for k, d in times.items()}
    print(
        f"{'model':6} {'params':>9} | {'train ms':>15} {'best':>7} {'x DT':>5} | {'act ms':>7} | "
        f"{'step ms':>15} {'best':>7} {'x DT':>5} || {'Table 5.6 train':>15} {'x DT':>5} | {'Table 5.6 infer':>15} {'x DT':>5}"
    )
    for k in models:
        n_params = sum(p.numel() for p in models[k].parameters())
        cells = []
        for phase in ("train", "inference"):
            r, r_dt = ref.get(k, {}).get(phase), ref.get("DT", {}).get(phase)
            cells.append(
                f"{f'{r[0]:.0f} ± {r[1]:.0f}' if r else '-':>15} {f'{r[0] / r_dt[0]:.2f}' if r and r_dt else '-':>5}"
            )
        print(
            f"{k:6} {n_params:9d} | {med[k]['train']:7.2f} ± {std[k]['train']:5.2f} {min(times[k]['train']) * 1e3:7.2f} "
            f"{med[k]['train'] / med['DT']['train']:5.2f} | {med[k]['act']:7.2f} | "
            f"{med[k]['step']:7.2f} ± {std[k]['step']:5.2f} {min(times[k]['step']) * 1e3:7.2f} "
            f"{med[k]['step'] / med['DT']['step']:5.2f} || {cells[0]} | {cells[1]}"
        )
    if not ref:
        print(f"(Table 5.6 has no row for {args.task}.)")


if __name__ == "__main__":
    main()
