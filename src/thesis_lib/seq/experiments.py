"""The HDT chapter's experiments (thesis 5.2.5) as functions returning tidy DataFrames.

* :class:`HDTExperimentConfig`: every setting of the chapter (the notebook's parameters):
  which ``task/tier`` data sets, methods and seeds, the training and evaluation scale, and
  where to measure the ``paper_compat`` switches.
* :func:`run_method` trains one method on one data set with one seed and evaluates it every
  ``eval_every`` iterations and at the end (RTG methods at each of the thesis's targets: the
  data set's max return, half of it and 10,000, all in one batch of environments); one row
  per evaluation and target.
* :func:`run_hdt_experiments` loops over data sets x seeds x methods (one vector environment
  per data set and size, reused by every run); :func:`run_paper_compat` runs the
  ``paper_compat=True`` variants on one data set.
* :func:`summarize` gives both metrics per method x task x tier x target: the thesis's
  (``best_return``: the best evaluation average seen during training, mean +- std over seeds)
  and the honest one (``final_return_mean`` +- ``final_return_std``: the last evaluation,
  over seeds), with D4RL-normalised scores where the task has references;
  :func:`compare_paper_compat` puts the default and the authors' behaviours side by side.

Methods: ``BC``; ``DT`` (RTG, Tables 5.1, 5.3); ``DT-noRTG`` (Table 5.1); ``HDT`` (Tables
5.2, 5.3); ``HDT-RTG`` (Table 5.2).

>>> cfg = HDTExperimentConfig(datasets=["hopper/medium"], iterations=200, seeds=[0])  # doctest: +SKIP
>>> summary = summarize(run_hdt_experiments(cfg))                                      # doctest: +SKIP

Used in: HDT chapter (Tables 5.1-5.3).
"""

from __future__ import annotations

import difflib
from dataclasses import dataclass, field
from typing import Any, Literal

import numpy as np
import pandas as pd
import torch
from tqdm.auto import tqdm

from thesis_lib.seq.evaluate import eval_step_cap, evaluate, target_returns
from thesis_lib.seq.models import BC, HDT, BCConfig, DecisionTransformer, DTConfig, HDTConfig
from thesis_lib.seq.subgoals import subgoal_fn
from thesis_lib.seq.trainer import TrainConfig, Trainer

__all__ = [
    "METHODS",
    "HDTExperimentConfig",
    "build_model",
    "compare_paper_compat",
    "run_hdt_experiments",
    "run_method",
    "run_paper_compat",
    "summarize",
]

METHODS: tuple[str, ...] = ("BC", "DT", "DT-noRTG", "HDT", "HDT-RTG")
"""Method names, as the tables' columns."""

RTG_METHODS = ("DT", "HDT-RTG")
TARGET_ORDER = ("max", "half", "10k", "none")


def _check_names(names: Any, valid: tuple[str, ...], what: str) -> None:
    for m in names:
        if m not in valid:
            close = difflib.get_close_matches(m, valid, n=1)
            hint = f" Did you mean: '{close[0]}'?" if close else ""
            raise ValueError(f"Unknown {what} '{m}'.{hint} Valid: {', '.join(valid)}.")


def _split_dataset(name: str) -> tuple[str, str]:
    if not isinstance(name, str) or name.count("/") != 1:
        raise ValueError(f"Expect data sets as 'task/tier', e.g. 'hopper/medium'; got {name!r}.")
    task, tier = name.split("/")
    return task, tier


@dataclass
class HDTExperimentConfig:
    """Every setting of the HDT chapter (thesis 5.2.5); the notebook's parameters.

    Defaults are the thesis's training scale on one data set; ``params/04_hdt.smoke.yml`` and
    ``params/04_hdt.full.yml`` hold the chapter's two profiles.

    Used in: HDT chapter (Tables 5.1-5.3).
    """

    seed: int = 0
    """Seed of the chapter's figures (episode choice); runs use ``seeds``."""
    datasets: list[str] = field(default_factory=lambda: ["hopper/medium"])
    """``task/tier`` pairs (``thesis_lib.data.TASKS``; a Maze2D task has other tiers than a
    locomotion task, so this is a list of pairs, not a task x tier product)."""
    methods: list[str] = field(default_factory=lambda: list(METHODS))
    """Subset of :data:`METHODS`."""
    seeds: list[int] = field(default_factory=lambda: [0, 1, 2])
    """Seeds run on every data set (model init, batches, dropout, evaluation episodes)."""
    extra_seeds: list[int] = field(default_factory=list)
    """More seeds, run only on ``extra_seed_datasets`` (the smoke profile: a second seed on a subset)."""
    extra_seed_datasets: list[str] = field(default_factory=list)
    """The ``task/tier`` pairs that also run ``extra_seeds``."""
    compat_dataset: str | None = None
    """``task/tier`` where ``compat_methods`` also run with ``paper_compat=True`` (the authors'
    behaviours) to measure the difference; ``None``: skip."""
    compat_methods: list[str] = field(default_factory=lambda: ["DT", "HDT"])
    """Methods of the ``paper_compat`` measurement."""
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
    bc_hidden_dim: int = 256
    """Width of BC's two hidden layers."""
    lr: float = 0.0001
    """Peak learning rate."""
    warmup_steps: int = 10_000
    """Linear warm-up steps."""
    eval_every: int = 1000
    """Evaluate every this many iterations (and at the end)."""
    eval_episodes: int = 100
    """Episodes per evaluation (per target for RTG methods)."""
    max_eval_steps: int | None = None
    """Cap on evaluation episode length (default: the task's time limit). Maze2D always runs
    whole episodes (:func:`~thesis_lib.seq.evaluate.eval_step_cap`)."""
    profile: Literal["smoke", "full"] = "smoke"
    """Data-set size profile of ``thesis_lib.data.get_dataset``."""
    n_transitions: int | None = None
    """Data-set size override (transitions)."""
    paper_compat: bool = False
    """Run everything with the authors' behaviours: a_{t-1} tokens, left-padded time-steps,
    last sub-goal = state 0 (``compat_dataset`` measures them beside the default instead)."""
    device: str = "cpu"
    """Training device (``cpu``, ``cuda``, ``auto``)."""
    progress: bool = True
    """Progress bars."""

    def __post_init__(self) -> None:
        for name in (
            "datasets",
            "methods",
            "seeds",
            "extra_seeds",
            "extra_seed_datasets",
            "compat_methods",
        ):
            value = getattr(self, name)
            if isinstance(value, str):
                raise ValueError(f"Expect `{name}` to be a list, got the string {value!r}.")
            setattr(self, name, list(value))
        if not self.datasets:
            raise ValueError("Expect at least one data set in `datasets`, e.g. ['hopper/medium'].")
        for d in (
            self.datasets
            + self.extra_seed_datasets
            + ([self.compat_dataset] if self.compat_dataset else [])
        ):
            _split_dataset(d)
        for d in self.extra_seed_datasets:
            if d not in self.datasets:
                raise ValueError(
                    f"extra_seed_datasets entry '{d}' is not in datasets ({', '.join(self.datasets)})."
                )
        _check_names(self.methods, METHODS, "method")
        _check_names(self.compat_methods, METHODS, "method")
        if (
            self.iterations < 1
            or self.eval_every < 1
            or self.eval_episodes < 1
            or self.batch_size < 1
        ):
            raise ValueError(
                f"Expect iterations, eval_every, eval_episodes and batch_size >= 1, got {self.iterations}, "
                f"{self.eval_every}, {self.eval_episodes}, {self.batch_size}."
            )

    @property
    def pairs(self) -> list[tuple[str, str]]:
        """``(task, tier)`` of each entry of ``datasets``."""
        return [_split_dataset(d) for d in self.datasets]

    def seeds_for(self, dataset: str) -> list[int]:
        """The seeds run on ``dataset`` (``task/tier``): ``seeds`` plus ``extra_seeds`` where listed."""
        extra = self.extra_seeds if dataset in self.extra_seed_datasets else []
        return list(dict.fromkeys(self.seeds + extra))

    def experiment_configs(self) -> list[HDTExperimentConfig]:
        """One config per data set (kept for callers of the former ``HDTChapterConfig``)."""
        import dataclasses

        out = []
        for d in self.datasets:
            extra = [d] if d in self.extra_seed_datasets else []
            compat = self.compat_dataset if self.compat_dataset == d else None
            out.append(
                dataclasses.replace(
                    self, datasets=[d], extra_seed_datasets=extra, compat_dataset=compat
                )
            )
        return out


def build_model(
    method: str,
    seq: Any,
    cfg: HDTExperimentConfig,
    max_action: float = 1.0,
    paper_compat: bool | None = None,
) -> torch.nn.Module:
    """The model of ``method`` sized for the data set ``seq``.

    Used in: HDT chapter (Tables 5.1-5.3).
    """
    compat = cfg.paper_compat if paper_compat is None else paper_compat
    tf = dict(
        d_model=cfg.d_model,
        n_layer=cfg.n_layer,
        n_head=cfg.n_head,
        dropout=cfg.dropout,
        paper_compat=compat,
        max_action=max_action,
    )
    if method == "BC":
        return BC(
            BCConfig.for_data(
                seq, max_action=max_action, dropout=cfg.dropout, hidden_dim=cfg.bc_hidden_dim
            )
        )
    if method in ("DT", "DT-noRTG"):
        return DecisionTransformer(DTConfig.for_data(seq, use_rtg=method == "DT", **tf))
    if method in ("HDT", "HDT-RTG"):
        return HDT(HDTConfig.for_data(seq, low_use_rtg=method == "HDT-RTG", **tf))
    raise ValueError(f"Unknown method '{method}'. Valid: {', '.join(METHODS)}.")


class _EnvPool:
    """Vector environments of one task, one per size, made once and reused by every run."""

    def __init__(self, task: str) -> None:
        self.task, self.envs = task, {}

    def get(self, n: int) -> Any:
        import gymnasium as gym

        from thesis_lib.data import make_env

        if n not in self.envs:
            self.envs[n] = gym.vector.SyncVectorEnv([lambda: make_env(self.task)] * n)
        return self.envs[n]

    def close(self) -> None:
        for venv in self.envs.values():
            venv.close()
        self.envs.clear()


def run_method(
    method: str,
    task: str,
    tier: str,
    seed: int,
    cfg: HDTExperimentConfig,
    data: Any = None,
    envs: _EnvPool | None = None,
    paper_compat: bool | None = None,
    seq: Any = None,
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
        envs: Vector environments to reuse (internal; made and closed here when ``None``).
        paper_compat: Override of ``cfg.paper_compat`` for this run.
        seq: The :class:`~thesis_lib.data.SequenceDataset` of ``data`` built with this run's
            ``K`` and ``paper_compat`` (reused across runs: its generator is re-seeded here).

    Returns:
        One row per evaluation (and target): ``method, task, tier, seed, paper_compat, target,
        target_return, iteration, return_mean, return_std, score_mean, length_mean, loss``.
    """
    from thesis_lib.data import SequenceDataset, get_dataset

    compat = cfg.paper_compat if paper_compat is None else bool(paper_compat)
    if data is None:
        data = get_dataset(task, tier, cfg.profile, n_transitions=cfg.n_transitions)
    if seq is None:
        seq = SequenceDataset(
            data, K=cfg.K, subgoal_fn=subgoal_fn(compat), paper_compat=compat, seed=seed
        )
    elif seq.K != cfg.K or seq.paper_compat != compat or seq.subgoals is None:
        raise ValueError(
            f"The given SequenceDataset has K={seq.K}, paper_compat={seq.paper_compat}, "
            f"sub-goals {seq.subgoals is not None}; this run needs K={cfg.K}, paper_compat={compat}."
        )
    else:
        seq.rng = np.random.default_rng(seed)  # the same batches as a freshly built data set
    own_envs = envs is None
    envs = _EnvPool(task) if own_envs else envs
    targets = target_returns(data) if method in RTG_METHODS else {"none": None}
    n = cfg.eval_episodes
    venv = envs.get(n * len(targets))  # every target's episodes in one batch of environments
    max_action = float(np.max(venv.single_action_space.high))
    torch.manual_seed(seed)
    model = build_model(method, seq, cfg, max_action, paper_compat=compat)
    per_episode = None if method not in RTG_METHODS else np.repeat([targets[k] for k in targets], n)
    rows: list[dict[str, Any]] = []

    def eval_fn(m: torch.nn.Module) -> float:
        res = evaluate(
            m,
            venv,
            n * len(targets),
            target_return=per_episode,
            dataset=seq,
            task=task,
            seed=10_000 * (seed + 1) + trainer.iteration,
            max_steps=eval_step_cap(task, cfg.max_eval_steps),
        )
        for k, (name, target) in enumerate(targets.items()):
            part = slice(k * n, (k + 1) * n)
            rows.append({
                "method": method, "task": task, "tier": tier, "seed": seed, "paper_compat": compat,
                "target": name, "target_return": np.nan if target is None else target,
                "iteration": trainer.iteration, "return_mean": float(np.mean(res.returns[part])),
                "return_std": float(np.std(res.returns[part])),
                "score_mean": np.nan if res.scores is None else float(np.mean(res.scores[part])),
                "length_mean": float(np.mean(res.lengths[part])),
                "loss": trainer.history[-1]["loss"] if trainer.history else np.nan,
            })  # fmt: skip
        return rows[-len(targets)]["return_mean"]  # the first target's (max) for the progress bar

    train_cfg = TrainConfig(
        iterations=cfg.iterations,
        batch_size=cfg.batch_size,
        lr=cfg.lr,
        warmup_steps=cfg.warmup_steps,
        eval_every=cfg.eval_every,
        seed=seed,
        device=cfg.device,
        progress=cfg.progress,
    )
    trainer = Trainer(model, seq, train_cfg, eval_fn=eval_fn)
    try:
        trainer.train()
        if cfg.iterations % cfg.eval_every:  # always evaluate the final model
            trainer.evaluate()
    finally:
        if own_envs:
            envs.close()
    return pd.DataFrame(rows)


def run_hdt_experiments(
    cfg: HDTExperimentConfig,
    paper_compat: bool | None = None,
    datasets: list[str] | None = None,
    methods: list[str] | None = None,
) -> pd.DataFrame:
    """Every data set x seed x method of ``cfg``: the concatenated :func:`run_method` rows.

    Used in: HDT chapter (Tables 5.1-5.3).

    Args:
        cfg: :class:`HDTExperimentConfig`.
        paper_compat: Override of ``cfg.paper_compat``.
        datasets: Subset of ``cfg.datasets`` (default: all).
        methods: Subset of ``cfg.methods`` (default: all).
    """
    from thesis_lib.data import SequenceDataset, get_dataset

    compat = cfg.paper_compat if paper_compat is None else bool(paper_compat)
    datasets = cfg.datasets if datasets is None else list(datasets)
    methods = cfg.methods if methods is None else list(methods)
    _check_names(methods, METHODS, "method")
    runs = [(d, s, m) for d in datasets for s in cfg.seeds_for(d) for m in methods]
    frames = []
    bar = tqdm(total=len(runs), disable=not cfg.progress, desc="runs")
    try:
        for d in datasets:
            task, tier = _split_dataset(d)
            data = get_dataset(task, tier, cfg.profile, n_transitions=cfg.n_transitions)
            envs = _EnvPool(task)
            seq = SequenceDataset(data, K=cfg.K, subgoal_fn=subgoal_fn(compat), paper_compat=compat)
            try:
                for seed in cfg.seeds_for(d):
                    for method in methods:
                        bar.set_postfix_str(f"{d} {method} seed {seed}", refresh=False)
                        frames.append(
                            run_method(
                                method,
                                task,
                                tier,
                                seed,
                                cfg,
                                data=data,
                                envs=envs,
                                paper_compat=compat,
                                seq=seq,
                            )
                        )
                        bar.update(1)
            finally:
                envs.close()
    finally:
        bar.close()
    return pd.concat(frames, ignore_index=True)


def run_paper_compat(cfg: HDTExperimentConfig) -> pd.DataFrame:
    """``cfg.compat_methods`` on ``cfg.compat_dataset`` with ``paper_compat=True`` (its seeds).

    Used in: HDT chapter (the authors' behaviours measured, see :func:`compare_paper_compat`).

    Raises:
        ValueError: If ``cfg.compat_dataset`` is not set.
    """
    if not cfg.compat_dataset:
        raise ValueError("Set compat_dataset='task/tier' to measure the paper_compat behaviours.")
    return run_hdt_experiments(
        cfg, paper_compat=True, datasets=[cfg.compat_dataset], methods=cfg.compat_methods
    )


def summarize(curves: pd.DataFrame) -> pd.DataFrame:
    """Both metrics per ``method, task, tier, target`` from :func:`run_method` rows.

    * ``best_return`` (+- ``best_return_std``): the thesis's metric, the highest evaluation
      average seen during training (mean and std over seeds of each run's best);
      ``best_score`` likewise.
    * ``final_return_mean``, ``final_return_std``: the last evaluation, mean and std over
      seeds (``final_score_*`` likewise); ``n_seeds``.

    Rows with and without ``paper_compat`` (when the column is there) are kept apart.

    Used in: HDT chapter (Tables 5.1-5.3).
    """
    keys = ["method", "task", "tier", "target"] + (
        ["paper_compat"] if "paper_compat" in curves else []
    )
    per_run = curves.sort_values("iteration", kind="stable").groupby(keys + ["seed"], sort=False)
    runs = pd.DataFrame({
        "best_return": per_run["return_mean"].max(),
        "best_score": per_run["score_mean"].max(),
        "final_return": per_run["return_mean"].last(),
        "final_score": per_run["score_mean"].last(),
    }).reset_index()  # fmt: skip
    g = runs.groupby(keys, sort=False)
    out = pd.DataFrame({
        "best_return": g["best_return"].mean(),
        "best_return_std": g["best_return"].std(ddof=0),
        "best_score": g["best_score"].mean(),
        "final_return_mean": g["final_return"].mean(),
        "final_return_std": g["final_return"].std(ddof=0),
        "final_score_mean": g["final_score"].mean(),
        "final_score_std": g["final_score"].std(ddof=0),
        "n_seeds": g["seed"].nunique(),
    }).reset_index()  # fmt: skip
    order = {m: i for i, m in enumerate(METHODS)} | {t: i for i, t in enumerate(TARGET_ORDER)}
    out = out.sort_values(
        ["task", "tier", "method", "target"],
        kind="stable",
        key=lambda c: c.map(order) if c.name in ("method", "target") else c,
    )
    return out.reset_index(drop=True)


def compare_paper_compat(curves: pd.DataFrame, compat_curves: pd.DataFrame) -> pd.DataFrame:
    """The default behaviour beside ``paper_compat=True``, per method and target, both metrics.

    Used in: HDT chapter (the authors' behaviours measured).

    Args:
        curves: :func:`run_hdt_experiments` rows (default behaviour); only the data set and
            methods of ``compat_curves`` are used.
        compat_curves: :func:`run_paper_compat` rows.

    Returns:
        One row per ``metric, method, task, tier, target``: ``correct``, ``correct_std``,
        ``paper_compat``, ``paper_compat_std``, ``difference`` (paper_compat - correct),
        ``n_seeds``.
    """
    keys = ["method", "task", "tier", "target"]
    a = summarize(curves.assign(paper_compat=False))
    b = summarize(compat_curves.assign(paper_compat=True))
    a = a.merge(b[keys], on=keys)  # the settings measured both ways
    frames = []
    for metric, (col, std) in {
        "best during training (thesis)": ("best_return", "best_return_std"),
        "final checkpoint": ("final_return_mean", "final_return_std"),
    }.items():
        m = a[keys + [col, std, "n_seeds"]].merge(
            b[keys + [col, std]], on=keys, suffixes=("", "_compat")
        )
        frames.append(pd.DataFrame({
            "metric": metric, **{k: m[k] for k in keys},
            "correct": m[col], "correct_std": m[std],
            "paper_compat": m[f"{col}_compat"], "paper_compat_std": m[f"{std}_compat"],
            "difference": m[f"{col}_compat"] - m[col], "n_seeds": m["n_seeds"],
        }))  # fmt: skip
    return pd.concat(frames, ignore_index=True)
