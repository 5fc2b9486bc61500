"""The HDT chapter's experiments (thesis 5.2.5) as functions returning tidy DataFrames.

* :func:`run_method` trains one method on one data set with one seed and evaluates it every
  ``eval_every`` iterations (RTG methods at each of the thesis's targets: the data set's max
  return, half of it and 10,000); one row per evaluation.
* :func:`run_hdt_experiments` loops over tasks x tiers x seeds x methods.
* :func:`summarize` gives both metrics per method x task x tier x target: the thesis's
  (``best_return``: the best evaluation average seen during training, averaged over seeds)
  and the honest one (``final_return_mean`` +- ``final_return_std``: the last evaluation,
  over seeds), with D4RL-normalised scores where the task has references.

Methods: ``BC``; ``DT`` (RTG, Tables 5.1, 5.3); ``DT-noRTG`` (Table 5.1); ``HDT`` (Tables
5.2, 5.3); ``HDT-RTG`` (Table 5.2).

Used in: HDT chapter (Tables 5.1-5.3).
"""
from __future__ import annotations

import difflib
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np
import pandas as pd
import torch

from thesis_lib.seq.evaluate import evaluate, target_returns
from thesis_lib.seq.models import BC, HDT, BCConfig, DecisionTransformer, DTConfig, HDTConfig
from thesis_lib.seq.subgoals import subgoal_fn
from thesis_lib.seq.trainer import TrainConfig, Trainer

__all__ = ["METHODS", "HDTExperimentConfig", "build_model", "run_hdt_experiments", "run_method", "summarize"]

METHODS: tuple[str, ...] = ("BC", "DT", "DT-noRTG", "HDT", "HDT-RTG")
"""Method names, as the tables' columns."""

RTG_METHODS = ("DT", "HDT-RTG")


@dataclass
class HDTExperimentConfig:
    """Settings of the HDT chapter's runs; defaults are the thesis's full scale (5.2.5).

    Used in: HDT chapter (Tables 5.1-5.3).
    """

    tasks: tuple[str, ...] = ("hopper",)
    """Task names (``thesis_lib.data.TASKS``)."""
    tiers: tuple[str, ...] = ("medium",)
    """Data-set tiers (``medium``, ``expert``, ``medium-replay`` ...)."""
    methods: tuple[str, ...] = METHODS
    """Subset of :data:`METHODS`."""
    seeds: tuple[int, ...] = (0, 1, 2)
    """One run per seed (model init, batches, dropout, evaluation episodes)."""
    iterations: int = 100_000
    """Training iterations (100k in the thesis)."""
    batch_size: int = 64
    """Batch size (64 in the thesis text)."""
    K: int = 20
    """Context length."""
    d_model: int = 128
    """Embedding size of the transformers."""
    n_layer: int = 3
    """GPT blocks per transformer (per HDT level)."""
    n_head: int = 1
    """Attention heads."""
    dropout: float = 0.1
    """Dropout."""
    lr: float = 1e-4
    """Peak learning rate."""
    warmup_steps: int = 10_000
    """Linear warm-up steps."""
    eval_every: int = 1000
    """Evaluate every this many iterations (and at the end)."""
    eval_episodes: int = 100
    """Episodes per evaluation."""
    max_eval_steps: int | None = None
    """Cap on evaluation episode length (default: the task's time limit)."""
    profile: Literal["smoke", "full"] = "smoke"
    """Data-set size profile of ``thesis_lib.data.get_dataset``."""
    n_transitions: int | None = None
    """Data-set size override (transitions)."""
    paper_compat: bool = False
    """The authors' behaviours: a_{t-1} tokens, left-padded time-steps, last sub-goal = state 0."""
    device: str = "cpu"
    """Training device (``cpu``, ``cuda``, ``auto``)."""
    progress: bool = True
    """Progress bars."""

    def __post_init__(self) -> None:
        self.tasks, self.tiers = tuple(self.tasks), tuple(self.tiers)
        self.methods, self.seeds = tuple(self.methods), tuple(self.seeds)
        for m in self.methods:
            if m not in METHODS:
                close = difflib.get_close_matches(m, METHODS, n=1)
                hint = f" Did you mean: '{close[0]}'?" if close else ""
                raise ValueError(f"Unknown method '{m}'.{hint} Valid: {', '.join(METHODS)}.")
        if self.iterations < 1 or self.eval_every < 1 or self.eval_episodes < 1:
            raise ValueError(
                f"Expect iterations, eval_every and eval_episodes >= 1, got {self.iterations}, "
                f"{self.eval_every}, {self.eval_episodes}."
            )


def build_model(method: str, seq: Any, cfg: HDTExperimentConfig, max_action: float = 1.0) -> torch.nn.Module:
    """The model of ``method`` sized for the data set ``seq``.

    Used in: HDT chapter (Tables 5.1-5.3).
    """
    tf = dict(d_model=cfg.d_model, n_layer=cfg.n_layer, n_head=cfg.n_head, dropout=cfg.dropout,
              paper_compat=cfg.paper_compat, max_action=max_action)
    if method == "BC":
        return BC(BCConfig.for_data(seq, max_action=max_action, dropout=cfg.dropout))
    if method in ("DT", "DT-noRTG"):
        return DecisionTransformer(DTConfig.for_data(seq, use_rtg=method == "DT", **tf))
    if method in ("HDT", "HDT-RTG"):
        return HDT(HDTConfig.for_data(seq, low_use_rtg=method == "HDT-RTG", **tf))
    raise ValueError(f"Unknown method '{method}'. Valid: {', '.join(METHODS)}.")


def run_method(
    method: str, task: str, tier: str, seed: int, cfg: HDTExperimentConfig, data: Any = None
) -> pd.DataFrame:
    """Train ``method`` on ``thesis/<task>/<tier>`` with ``seed``; evaluate along the way.

    Used in: HDT chapter (Tables 5.1-5.3).

    Args:
        method: One of :data:`METHODS`.
        task: Task name; evaluation runs in its environment.
        tier: Data-set tier.
        seed: Seed of this run.
        cfg: :class:`HDTExperimentConfig`.
        data: The episodes to train on (an ``OfflineDataset`` or a list of ``Episode``);
            default ``thesis_lib.data.get_dataset(task, tier, cfg.profile, n_transitions=...)``.

    Returns:
        One row per evaluation (and target): ``method, task, tier, seed, target,
        target_return, iteration, return_mean, return_std, score_mean, length_mean, loss``.
    """
    from thesis_lib.data import SequenceDataset, get_dataset, make_env

    if data is None:
        data = get_dataset(task, tier, cfg.profile, n_transitions=cfg.n_transitions)
    seq = SequenceDataset(data, K=cfg.K, subgoal_fn=subgoal_fn(cfg.paper_compat),
                          paper_compat=cfg.paper_compat, seed=seed)
    env = make_env(task)
    max_action = float(np.max(env.action_space.high))
    env.close()
    torch.manual_seed(seed)
    model = build_model(method, seq, cfg, max_action)
    targets = target_returns(data) if method in RTG_METHODS else {"none": None}
    rows: list[dict[str, Any]] = []

    def eval_fn(m: torch.nn.Module) -> float:
        for name, target in targets.items():
            res = evaluate(m, task, cfg.eval_episodes, target_return=target, dataset=seq,
                           seed=10_000 * (seed + 1) + trainer.iteration, max_steps=cfg.max_eval_steps)
            rows.append({
                "method": method, "task": task, "tier": tier, "seed": seed, "target": name,
                "target_return": np.nan if target is None else target, "iteration": trainer.iteration,
                "return_mean": res.mean_return, "return_std": float(np.std(res.returns)),
                "score_mean": np.nan if res.scores is None else res.mean_score,
                "length_mean": float(np.mean(res.lengths)),
                "loss": trainer.history[-1]["loss"] if trainer.history else np.nan,
            })  # fmt: skip
        return rows[-len(targets)]["return_mean"]  # the first target's (max) for the progress bar

    train_cfg = TrainConfig(iterations=cfg.iterations, batch_size=cfg.batch_size, lr=cfg.lr,
                            warmup_steps=cfg.warmup_steps, eval_every=cfg.eval_every, seed=seed,
                            device=cfg.device, progress=cfg.progress)
    trainer = Trainer(model, seq, train_cfg, eval_fn=eval_fn)
    trainer.train()
    if cfg.iterations % cfg.eval_every:  # always evaluate the final model
        trainer.evaluate()
    return pd.DataFrame(rows)


def run_hdt_experiments(cfg: HDTExperimentConfig) -> pd.DataFrame:
    """Every task x tier x seed x method of ``cfg``: the concatenated :func:`run_method` rows.

    Used in: HDT chapter (Tables 5.1-5.3).
    """
    from thesis_lib.data import get_dataset

    frames = []
    for task in cfg.tasks:
        for tier in cfg.tiers:
            data = get_dataset(task, tier, cfg.profile, n_transitions=cfg.n_transitions)
            for seed in cfg.seeds:
                for method in cfg.methods:
                    frames.append(run_method(method, task, tier, seed, cfg, data=data))
    return pd.concat(frames, ignore_index=True)


def summarize(curves: pd.DataFrame) -> pd.DataFrame:
    """Both metrics per ``method, task, tier, target`` from :func:`run_method` rows.

    * ``best_return``: the thesis's metric, the highest evaluation average seen during
      training (mean over seeds of each run's best); ``best_score`` likewise.
    * ``final_return_mean``, ``final_return_std``: the last evaluation, mean and std over
      seeds (``final_score_*`` likewise); ``n_seeds``.

    Used in: HDT chapter (Tables 5.1-5.3).
    """
    keys = ["method", "task", "tier", "target"]
    per_run = curves.sort_values("iteration").groupby(keys + ["seed"], sort=False)
    runs = pd.DataFrame({
        "best_return": per_run["return_mean"].max(),
        "best_score": per_run["score_mean"].max(),
        "final_return": per_run["return_mean"].last(),
        "final_score": per_run["score_mean"].last(),
    }).reset_index()  # fmt: skip
    g = runs.groupby(keys, sort=False)
    out = pd.DataFrame({
        "best_return": g["best_return"].mean(),
        "best_score": g["best_score"].mean(),
        "final_return_mean": g["final_return"].mean(),
        "final_return_std": g["final_return"].std(ddof=0),
        "final_score_mean": g["final_score"].mean(),
        "final_score_std": g["final_score"].std(ddof=0),
        "n_seeds": g["seed"].nunique(),
    }).reset_index()  # fmt: skip
    order = {m: i for i, m in enumerate(METHODS)} | {t: i for i, t in enumerate(("max", "half", "10k", "none"))}
    out = out.sort_values(["task", "tier", "method", "target"], key=lambda c: c.map(order) if c.name in ("method", "target") else c)
    return out.reset_index(drop=True)
