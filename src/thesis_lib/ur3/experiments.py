"""Table 5.4: HDT and DT on the UR3 reaching task, trained with 10, 20, ..., 80 demonstrations.

:func:`run_reach_method` trains one model on the first ``n_train`` training demonstrations
with one seed and runs it from each of the 10 test starts for 200 steps with the project's one
evaluator (:func:`thesis_lib.seq.evaluate`), reading the goals reached from the environments.
:func:`run_table_5_4` loops over methods x demonstration counts x seeds; :func:`table_5_4`
aggregates to the thesis's "mean ± std of goal positions reached" and :func:`success_curves`
gives the mean number of goals reached after each step.

Used in: UR3 deployment chapter (Table 5.4).
"""

from __future__ import annotations

import difflib
from dataclasses import dataclass
from functools import partial
from typing import Any

import numpy as np
import pandas as pd

from .reach import UR3ReachEnv, get_reach_dataset, split_demonstrations

__all__ = [
    "REACH_METHODS",
    "ReachConfig",
    "run_reach_method",
    "run_table_5_4",
    "success_curves",
    "table_5_4",
]

REACH_METHODS = ("HDT", "DT")
"""The two methods of Table 5.4."""


@dataclass
class ReachConfig:
    """Settings of the Table 5.4 runs; defaults are the thesis's full scale.

    Used in: UR3 deployment chapter (Table 5.4).
    """

    train_demos: tuple[int, ...] = (10, 20, 30, 40, 50, 60, 70, 80)
    """Numbers of training demonstrations (the first n of the 80 training ones)."""
    methods: tuple[str, ...] = REACH_METHODS
    """Subset of :data:`REACH_METHODS`."""
    seeds: tuple[int, ...] = (0, 1, 2)
    """One run per seed (model init, batches, dropout)."""
    n_demos: int = 100
    """Demonstrations made: 80 train, 10 validation, 10 test starts (the thesis's split)."""
    data_seed: int = 0
    """Seed of the demonstrations (random starts, the operator's wobble)."""
    iterations: int = 10_000
    """Training iterations per run."""
    batch_size: int = 64
    """Windows per batch."""
    K: int = 20
    """Context length."""
    d_model: int = 128
    """Embedding size."""
    n_layer: int = 3
    """GPT blocks (per HDT level)."""
    n_head: int = 1
    """Attention heads."""
    dropout: float = 0.1
    """Dropout."""
    lr: float = 1e-4
    """Peak learning rate."""
    warmup_steps: int = 1000
    """Linear warm-up steps."""
    max_eval_steps: int = 200
    """Steps per test episode (200 in the thesis)."""
    rtg_scale: float = 10.0
    """Returns-to-go divisor (returns are about -30 to -60 here, not thousands)."""
    paper_compat: bool = False
    """The authors' behaviours (a_{t-1} tokens, left-padded time-steps, last sub-goal = state 0)."""
    device: str = "cpu"
    """Training device."""
    progress: bool = False
    """Progress bars."""

    def __post_init__(self) -> None:
        self.train_demos, self.methods, self.seeds = (
            tuple(self.train_demos),
            tuple(self.methods),
            tuple(self.seeds),
        )
        for m in self.methods:
            if m not in REACH_METHODS:
                close = difflib.get_close_matches(m, REACH_METHODS, n=1)
                hint = f" Did you mean: '{close[0]}'?" if close else ""
                raise ValueError(f"Unknown method '{m}'.{hint} Valid: {', '.join(REACH_METHODS)}.")
        n_train = self.n_demos - 20
        bad = [n for n in self.train_demos if not 1 <= n <= n_train]
        if bad:
            raise ValueError(
                f"train_demos must lie in 1..{n_train} (n_demos - 10 validation - 10 test), got {bad}."
            )


def _model(method: str, seq: Any, cfg: ReachConfig) -> Any:
    from thesis_lib.seq import HDT, DecisionTransformer, DTConfig, HDTConfig

    kw = dict(
        d_model=cfg.d_model,
        n_layer=cfg.n_layer,
        n_head=cfg.n_head,
        dropout=cfg.dropout,
        paper_compat=cfg.paper_compat,
        max_action=1.0,
        max_timestep=max(256, cfg.max_eval_steps + 1),
    )
    if method == "HDT":
        return HDT(HDTConfig.for_data(seq, **kw))
    return DecisionTransformer(DTConfig.for_data(seq, **kw))


def run_reach_method(
    method: str, n_train: int, seed: int, cfg: ReachConfig, demos: Any = None
) -> pd.DataFrame:
    """Train ``method`` on ``n_train`` demonstrations with ``seed``; test from every test start.

    Args:
        method: ``"HDT"`` or ``"DT"`` (evaluated at the training demonstrations' best return).
        n_train: number of training demonstrations.
        seed: seed of the run.
        cfg: :class:`ReachConfig`.
        demos: a :class:`~thesis_lib.ur3.reach.ReachDemos`; default from :func:`get_reach_dataset`.

    Returns:
        One row per test start: ``method, train_demos, seed, start, goals_reached, steps,
        reach_steps`` (the step each goal was reached, -1 if never; a string for CSV), ``loss``.

    Used in: UR3 deployment chapter (Table 5.4).
    """
    import gymnasium as gym
    import torch

    from thesis_lib.data import SequenceDataset
    from thesis_lib.seq import TrainConfig, Trainer, evaluate, subgoal_fn

    if demos is None:
        demos = split_demonstrations(get_reach_dataset(cfg.n_demos, cfg.data_seed).episodes)
    train = demos.train[:n_train]
    seq = SequenceDataset(
        train,
        K=cfg.K,
        rtg_scale=cfg.rtg_scale,
        subgoal_fn=subgoal_fn(cfg.paper_compat),
        paper_compat=cfg.paper_compat,
        seed=seed,
    )
    torch.manual_seed(seed)
    model = _model(method, seq, cfg)
    tc = TrainConfig(
        iterations=cfg.iterations,
        batch_size=cfg.batch_size,
        lr=cfg.lr,
        warmup_steps=cfg.warmup_steps,
        eval_every=0,
        seed=seed,
        device=cfg.device,
        progress=cfg.progress,
    )
    trainer = Trainer(model, seq, tc)
    trainer.train()
    loss = float(trainer.history[-1]["loss"]) if trainer.history else float("nan")

    envs = [partial(UR3ReachEnv, start=s, max_steps=cfg.max_eval_steps) for s in demos.test_starts]
    venv = gym.vector.SyncVectorEnv(envs)
    try:
        target = max(e.episode_return for e in train) if method == "DT" else None
        evaluate(
            model,
            venv,
            n_episodes=len(envs),
            target_return=target,
            dataset=seq,
            seed=seed,
            max_steps=cfg.max_eval_steps,
        )
        rows = []
        for i, env in enumerate(venv.envs):
            done = env.unwrapped.completed
            rec = (
                done[0]
                if done
                else {
                    "goals_reached": int(env.unwrapped.reached.sum()),
                    "reach_steps": env.unwrapped.reach_steps,
                    "steps": env.unwrapped.t,
                }
            )
            rows.append(
                {
                    "method": method,
                    "train_demos": n_train,
                    "seed": seed,
                    "start": i,
                    "goals_reached": rec["goals_reached"],
                    "steps": rec["steps"],
                    "reach_steps": " ".join(str(int(s)) for s in rec["reach_steps"]),
                    "loss": loss,
                }
            )
    finally:
        venv.close()
    return pd.DataFrame(rows)


def run_table_5_4(cfg: ReachConfig) -> pd.DataFrame:
    """Every method x demonstration count x seed of ``cfg``: the concatenated per-start rows.

    Used in: UR3 deployment chapter (Table 5.4).
    """
    from tqdm.auto import tqdm

    demos = split_demonstrations(get_reach_dataset(cfg.n_demos, cfg.data_seed).episodes)
    runs = [(m, n, s) for n in cfg.train_demos for m in cfg.methods for s in cfg.seeds]
    frames = [
        run_reach_method(m, n, s, cfg, demos)
        for m, n, s in tqdm(runs, desc="Table 5.4", disable=not cfg.progress)
    ]
    return pd.concat(frames, ignore_index=True)


def table_5_4(rows: pd.DataFrame) -> pd.DataFrame:
    """Mean and std (over test starts and seeds) of the goals reached per method and count.

    Returns:
        Columns ``method, train_demos, goals_mean, goals_std, all_five`` (share of test
        episodes that reached all goals), ``n_episodes``, as the reference ``table_5_4.csv``.
    """
    g = rows.groupby(["method", "train_demos"], sort=False)["goals_reached"]
    n_goals = 5
    out = pd.DataFrame({
        "goals_mean": g.mean(),
        "goals_std": g.std(ddof=0),
        "all_five": g.apply(lambda x: float(np.mean(x >= n_goals))),
        "n_episodes": g.size(),
    }).reset_index()  # fmt: skip
    return out


def success_curves(rows: pd.DataFrame, horizon: int = 200) -> pd.DataFrame:
    """Mean number of goals reached by each step ``0..horizon``, per method and count.

    Returns:
        Long table ``method, train_demos, step, goals_mean``.
    """
    out = []
    steps = np.arange(horizon + 1)
    for (m, n), g in rows.groupby(["method", "train_demos"], sort=False):
        reach = np.array(
            [[int(x) for x in s.split()] for s in g["reach_steps"]]
        )  # (episodes, goals)
        hit = (reach[:, :, None] >= 0) & (reach[:, :, None] <= steps[None, None, :])
        mean = hit.sum(axis=1).mean(axis=0)
        out.append(pd.DataFrame({"method": m, "train_demos": n, "step": steps, "goals_mean": mean}))
    return pd.concat(out, ignore_index=True)
