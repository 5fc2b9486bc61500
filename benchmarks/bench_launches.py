"""Count the ATen ops of one action and one training step of each method: on a GPU, the launches.

At the thesis's size (6 layers, d_model 128, K 20; batch 16 for training) a step on a GPU is
bound by kernel launches, not arithmetic: dm-c6-gpu-v1 timed the models on an NVIDIA H200, and
the DM acted 2-3x slower than the DT there. This script counts, with PyTorch's profiler on the
CPU, the top-level ATen ops (each one kernel launch or more on a GPU) that one action and one
training step run, for each method, on the code path a GPU takes:

* ``--path gpu`` (default): the selective scan's torch backend (a loop over the window's
  tokens, :func:`thesis_lib.seq.mamba.resolve_scan_backend` on CUDA without ``mamba_ssm``)
  and the recurrent step's unfused torch ops (the fused step is a CPU kernel);
* ``--path cpu``: what runs here (the numba scan, one op; the fused numba step, one op).

Acting goes through :func:`thesis_lib.seq.evaluation.evaluate` (building the history, the
model, the environment's step), averaged over an episode of ``--steps`` steps after one
untimed episode; training is one :class:`~thesis_lib.seq.trainer.Trainer` step (sampling
included) after one untimed step.

    python benchmarks/bench_launches.py                     # maze2d-umaze/expert, 20k set
    python benchmarks/bench_launches.py --path cpu

Counted 2026-11-28 (``--path gpu``, maze2d-umaze; ops per action, window / recurrent, and per
training step): DT 183 / 1,710; HDT 331 / 3,363; DM without RTG 1,153 / 633 / 4,509; DM with
RTG 1,483 / 933 / 5,503; HDM 2,606 / 1,540 / 9,993. The DM without RTG runs 3.5-6.3x the DT's
ops per action and 2.6x per training step; on the H200 it acted 2.0-2.9x slower and trained
2.2-2.3x slower (dm-c6-gpu-v1). On the CPU path the fused recurrent step is 68 ops.
"""

from __future__ import annotations

import argparse
from typing import Any

import numpy as np
import pandas as pd
import torch
from torch.profiler import ProfilerActivity, profile

from thesis_lib.chapters.decision_mamba import tasks as dm_tasks
from thesis_lib.chapters.decision_mamba.config import HIERARCHICAL, MAMBA_METHODS, Config
from thesis_lib.data import SequenceDataset
from thesis_lib.seq import mamba as mamba_mod
from thesis_lib.seq.evaluation import evaluate, target_returns
from thesis_lib.seq.registry import build_model
from thesis_lib.seq.subgoals import subgoal_fn
from thesis_lib.seq.trainer import TrainConfig, Trainer


def top_level_ops(prof: Any) -> int:
    """ATen ops not called from another ATen op (what a GPU launches one kernel or more for)."""
    ops = [e for e in prof.events() if e.name.startswith("aten::")]
    return sum(1 for e in ops if e.cpu_parent is None or not e.cpu_parent.name.startswith("aten::"))


def gpu_path(model: torch.nn.Module) -> None:
    """Make ``model``'s Mamba layers take a GPU's code path on the CPU."""
    for m in model.modules():
        if isinstance(m, mamba_mod.MambaMixer):
            m.scan_backend = "torch"
        if isinstance(m, mamba_mod.Mamba):
            step = m.step_tokens
            m.step_tokens = lambda x, state, fused=None, _s=step: _s(x, state, fused=False)  # type: ignore[method-assign]


def count(method: str, dataset: str, path: str, steps: int) -> dict[str, Any]:
    cfg = Config(timing_datasets=[dataset], dataset_size="smoke")
    arch = cfg.arch_spec("6/128/20")
    task, tier = dm_tasks.split_dataset(dataset)
    data = dm_tasks.load_datasets([dataset], cfg, None)[(task, tier)]
    seq = SequenceDataset(
        data, K=arch.K, subgoal_fn=subgoal_fn(False) if method in HIERARCHICAL else None, seed=0
    )
    venv = dm_tasks._timing_env(dm_tasks.env_name(dataset))
    torch.manual_seed(0)
    model: Any = build_model(method, seq, arch, float(np.max(venv.single_action_space.high)))
    if path == "gpu":
        gpu_path(model)
    row: dict[str, Any] = {"method": method}
    trainer = Trainer(model, seq, TrainConfig(iterations=10, batch_size=16, progress=False))
    trainer.step()
    with profile(activities=[ProfilerActivity.CPU]) as prof:
        trainer.step()
    row["train step"] = top_level_ops(prof)
    target = target_returns(data)["max"] if method in ("DT", "DM-RTG") else None
    for mode in ("window", "recurrent") if method in MAMBA_METHODS else ("window",):
        if method in MAMBA_METHODS:
            model.config.eval_mode = mode
        kw = dict(target_return=target, dataset=seq, max_steps=steps)
        evaluate(model, venv, 1, seed=0, **kw)
        with profile(activities=[ProfilerActivity.CPU]) as prof:
            res = evaluate(model, venv, 1, seed=1, **kw)
        row[f"act ({mode})"] = round(top_level_ops(prof) / max(int(res.lengths[0]), 1))
    venv.close()
    return row


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--dataset", default="maze2d-umaze/expert")
    p.add_argument("--path", choices=["gpu", "cpu"], default="gpu")
    p.add_argument("--steps", type=int, default=30)
    args = p.parse_args()
    torch.set_num_threads(1)
    rows = [count(m, args.dataset, args.path, args.steps) for m in Config().methods]
    print(f"ATen ops per action / training step, {args.path} path, {args.dataset}")
    print(pd.DataFrame(rows).set_index("method").to_string())


if __name__ == "__main__":
    main()
