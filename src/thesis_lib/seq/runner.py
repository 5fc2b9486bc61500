"""One offline run: train a registry method on a data set, evaluate it along the way, return rows.

:func:`run_offline` is the one loop behind the HDT chapter (Tables 5.1-5.3), the Decision Mamba
chapter (Table 5.5, Figs 5.3-5.6) and the UR3 chapter (Table 5.4):

1. the data set's windows (:class:`~thesis_lib.data.SequenceDataset`, sub-goals for the
   hierarchical methods), seeded with ``train.seed``;
2. the model from :func:`~thesis_lib.seq.registry.build_model` (``torch.manual_seed(seed)``
   first);
3. the one :class:`~thesis_lib.seq.trainer.Trainer`, evaluating every ``train.eval_every``
   iterations and always at the end; RTG methods at each of ``eval.targets`` (the data set's
   max return, half of it, 10,000), all targets' episodes in one batch of environments;
4. optionally the final DM/HDM evaluated in the other ``eval_mode`` too.

Specs are frozen dataclasses of plain values (:class:`TrainSpec`, :class:`EvalSpec` and
:class:`~thesis_lib.seq.registry.ArchSpec`), so a sweep task can carry them as JSON.

Used in: HDT chapter, Decision Mamba chapter, UR3 deployment chapter.
"""

from __future__ import annotations

import json
import os
from collections.abc import Callable, Mapping
from dataclasses import asdict, dataclass
from typing import Any, cast

import numpy as np
import torch

from thesis_lib.data import SequenceDataset, make_env
from thesis_lib.data.minari_sets import is_minari_id, make_minari_env
from thesis_lib.data.sequence import resolve_sampling
from thesis_lib.seq.evaluation import eval_step_cap, evaluate, target_returns
from thesis_lib.seq.registry import (
    HIERARCHICAL_METHODS,
    LEGACY_SAMPLING,
    MAMBA_METHODS,
    RTG_METHODS,
    ArchSpec,
    build_model,
    check_methods,
)
from thesis_lib.seq.subgoals import subgoal_fn
from thesis_lib.seq.trainer import (
    LEFT_OUT_AT,
    TrainConfig,
    Trainer,
    check_kernels,
    check_precision,
)
from thesis_lib.sweep import note_resumed_cpu

__all__ = ["TARGETS", "EvalSpec", "TrainSpec", "VectorEnvPool", "run_offline"]

TARGETS: tuple[str, ...] = ("max", "half", "10k")
"""The desired returns of RTG methods (thesis 5.2.5): the data set's max, half of it, 10,000."""


@dataclass(frozen=True)
class TrainSpec:
    """How one run trains.

    Used in: HDT, Decision Mamba and UR3 deployment chapters.
    """

    seed: int = 0
    """Seed of the run: model init, batches, dropout, evaluation episodes."""
    iterations: int = 100_000
    """Training iterations."""
    batch_size: int = 64
    """Windows per batch."""
    lr: float = 1e-4
    """Peak AdamW learning rate."""
    warmup_steps: int = 10_000
    """Linear warm-up steps."""
    eval_every: int = 1000
    """Evaluate every this many iterations and at the end; ``0``: only at the end."""
    rtg_scale: float | None = None
    """Returns-to-go divisor of the data set (``None``: the data set's default)."""
    sampling: str | None = None
    """How the windows are drawn (:class:`~thesis_lib.data.SequenceDataset`'s ``sampling``:
    ``"end"`` or ``"start"``; ``None``: ``"start"`` with ``paper_compat``, else ``"end"``)."""
    device: str = "cpu"
    """Training device (``cpu``, ``cuda``, ``auto``)."""
    progress: bool = False
    """Progress bar of the training."""
    precision: str = "fp32"
    """Training precision, :attr:`~thesis_lib.seq.trainer.TrainConfig.precision` (``"fp32"`` or
    ``"bf16"``, mixed precision)."""
    kernels: str = "torch"
    """Training kernels, :attr:`~thesis_lib.seq.trainer.TrainConfig.kernels` (``"torch"``,
    ``"fast"``: lane dropout masks and fused AdamW, or ``"fast+readout"``: those, and the
    transformers' last block on the tokens the loss reads only)."""

    def __post_init__(self) -> None:
        for name in ("iterations", "batch_size"):
            if int(getattr(self, name)) < 1:
                raise ValueError(f"Expect `{name}` >= 1, actually: {getattr(self, name)!r}.")
        if self.eval_every < 0:
            raise ValueError(f"Expect `eval_every` >= 0, actually: {self.eval_every!r}.")
        resolve_sampling(self.sampling)  # validates
        check_precision(self.precision)
        check_kernels(self.kernels)

    def task_dict(self) -> dict[str, Any]:
        """The spec as a sweep task's JSON: every field, ``sampling`` left out where it is
        ``start``, ``precision`` where it is ``fp32`` and ``kernels`` where it is ``torch``, as
        every task stored before the fields existed ran (so their keys stay valid;
        :meth:`from_task` reads them back so).

        Example:
            >>> "sampling" in TrainSpec(sampling="start").task_dict(), TrainSpec().task_dict()["sampling"]
            (False, None)
            >>> "precision" in TrainSpec().task_dict(), TrainSpec(precision="bf16").task_dict()["precision"]
            (False, 'bf16')
        """
        d = asdict(self)
        if d["sampling"] == LEGACY_SAMPLING:
            del d["sampling"]
        for k, default in LEFT_OUT_AT.items():
            if d[k] == default:
                del d[k]
        return d

    @classmethod
    def from_task(cls, d: Mapping[str, Any]) -> TrainSpec:
        """The spec of a task's ``train`` dict (:meth:`task_dict`); a missing ``sampling`` is
        ``start``, a missing ``precision`` ``fp32`` and missing ``kernels`` ``torch``, as every task
        stored before the fields existed ran.

        Example:
            >>> TrainSpec.from_task({"seed": 1}).sampling
            'start'
        """
        return cls(**{"sampling": LEGACY_SAMPLING, **d})


@dataclass(frozen=True)
class EvalSpec:
    """How one run is evaluated.

    Used in: HDT, Decision Mamba and UR3 deployment chapters.
    """

    episodes: int = 100
    """Episodes per evaluation (per target for RTG methods)."""
    max_steps: int | None = None
    """Cap on episode length (``None``: the task's time limit); Maze2D always runs whole
    episodes (:func:`~thesis_lib.seq.evaluation.eval_step_cap`)."""
    targets: tuple[str, ...] = TARGETS
    """The desired returns of RTG methods, of :data:`TARGETS`."""
    compare_eval_modes: bool = False
    """DM/HDM: also evaluate the final model in the other ``eval_mode``."""
    episode_seed: str = "per_evaluation"
    """Reset seed of the episodes: ``per_evaluation`` (``10000 (seed + 1) + iteration``, a new
    set of starts at each evaluation) or ``run`` (the run's seed; fixed test starts)."""

    def __post_init__(self) -> None:
        if self.episodes < 1:
            raise ValueError(f"Expect `episodes` >= 1, actually: {self.episodes!r}.")
        unknown = [t for t in self.targets if t not in TARGETS]
        if unknown:
            raise ValueError(f"Unknown target {unknown[0]!r}. Valid: {', '.join(TARGETS)}.")
        if self.episode_seed not in ("per_evaluation", "run"):
            raise ValueError(
                f"Unknown episode_seed {self.episode_seed!r}. Valid: per_evaluation, run."
            )


class VectorEnvPool:
    """Vector environments of one task, one per size, made once and reused by every evaluation.

    Used in: HDT, Decision Mamba and UR3 deployment chapters (through :func:`run_offline`).
    """

    def __init__(self, task: str) -> None:
        self.task = task
        self.envs: dict[int, Any] = {}

    def __call__(self, n: int) -> Any:
        """A ``SyncVectorEnv`` of ``n`` copies of the task's environment (a Minari id: the
        environment the data set records for evaluation,
        :func:`~thesis_lib.data.minari_sets.make_minari_env`)."""
        import gymnasium as gym

        make = make_minari_env if is_minari_id(self.task) else make_env
        if n not in self.envs:
            self.envs[n] = gym.vector.SyncVectorEnv([lambda: make(self.task)] * n)
        return self.envs[n]

    def close(self) -> None:
        """Close every environment made."""
        for venv in self.envs.values():
            venv.close()
        self.envs.clear()


def run_offline(
    method: str,
    dataset: Any,
    arch: ArchSpec,
    train: TrainSpec,
    eval: EvalSpec,
    *,
    task: str | None = None,
    envs: Callable[[int], Any] | None = None,
    episode_info: Callable[[Any], dict[str, Any]] | None = None,
    checkpoint: str | os.PathLike | None = None,
    checkpoint_every: int = 1000,
) -> list[dict[str, Any]]:
    """Train ``method`` on ``dataset`` and evaluate it; one row per evaluation and target.

    Used in: HDT chapter (Tables 5.1-5.3), Decision Mamba chapter (Table 5.5, Figs 5.3-5.6),
    UR3 deployment chapter (Table 5.4).

    Args:
        method: One of :data:`~thesis_lib.seq.registry.METHODS`.
        dataset: The episodes: an ``OfflineDataset`` or a list of ``Episode``.
        arch: :class:`~thesis_lib.seq.registry.ArchSpec`.
        train: :class:`TrainSpec` (its ``seed`` seeds the whole run).
        eval: :class:`EvalSpec`.
        task: The task whose environment evaluates (needed unless ``envs`` is given; also
            names the D4RL score and the Maze2D step cap), or a real Minari id
            (``D4RL/door/human-v2``: the data set's own evaluation environment, D4RL's
            references for that id; :mod:`thesis_lib.data.minari_sets`).
        envs: ``envs(n) -> gymnasium VectorEnv`` of ``n`` environments (default: a
            :class:`VectorEnvPool` of ``task``, closed at the end).
        episode_info: ``fn(env) -> dict`` read from each environment of the vector env after the
            final evaluation; given, the final evaluation gives one row per episode (the dict's
            keys added) instead of one per target.
        checkpoint: a file to save the run to every ``checkpoint_every`` updates (training
            state and the evaluation rows so far) and to resume from where it exists: a run
            cut off and called again gives the rows of an uninterrupted one. A checkpoint of
            another run (method, architecture, training, evaluation, task or data) is refused
            with what differs. ``None``: no checkpoint.
        checkpoint_every: updates between saves of ``checkpoint``.

    Returns:
        Rows with ``method, seed, arch, n_layers, d_model, K, paper_compat, eval_mode, target,
        target_return, iteration, return_mean, return_std, score_mean, length_mean, loss``
        (``episode`` and the ``episode_info`` keys with ``episode_info``).

    Raises:
        ValueError: ``checkpoint`` holds another run's state.
    """
    check_methods([method])
    if envs is None and task is None:
        raise ValueError("run_offline needs the task's name (task=...) or an envs factory.")
    seed = train.seed
    sg = subgoal_fn(arch.paper_compat) if method in HIERARCHICAL_METHODS else None
    extra: dict[str, Any] = {} if train.rtg_scale is None else {"rtg_scale": train.rtg_scale}
    seq = SequenceDataset(
        dataset,
        K=arch.K,
        subgoal_fn=sg,
        paper_compat=arch.paper_compat,
        sampling=train.sampling,
        seed=seed,
        **extra,
    )
    own_envs = envs is None
    pool: Any = VectorEnvPool(cast(str, task)) if envs is None else envs
    targets: dict[str, float | None]
    if method in RTG_METHODS:
        targets = {k: v for k, v in target_returns(dataset).items() if k in eval.targets}
    else:
        targets = {"none": None}
    n = eval.episodes
    rows: list[dict[str, Any]] = []
    try:
        venv = pool(n * len(targets))  # every target's episodes in one batch of environments
        max_action = float(np.max(venv.single_action_space.high))
        torch.manual_seed(seed)
        model: Any = build_model(method, seq, arch, max_action)
        base_mode = model.config.resolved_eval_mode if method in MAMBA_METHODS else "window"
        per_episode = None if method not in RTG_METHODS else np.repeat(list(targets.values()), n)
        max_steps = eval.max_steps if task is None else eval_step_cap(task, eval.max_steps)

        def run_eval(m: torch.nn.Module, mode: str, final: bool = False) -> None:
            it = trainer.iteration
            ep_seed = seed if eval.episode_seed == "run" else 10_000 * (seed + 1) + it
            res = evaluate(
                m,
                venv,
                n * len(targets),
                target_return=per_episode,
                dataset=seq,
                task=task,
                seed=ep_seed,
                max_steps=max_steps,
            )
            base = {
                "method": method, "seed": seed, "arch": arch.label, "n_layers": arch.n_layers,
                "d_model": arch.d_model, "K": arch.K, "paper_compat": arch.paper_compat,
                "eval_mode": mode, "iteration": it,
                "loss": trainer.history[-1]["loss"] if trainer.history else np.nan,
            }  # fmt: skip
            for k, (name, target) in enumerate(targets.items()):
                part = slice(k * n, (k + 1) * n)
                row = base | {
                    "target": name,
                    "target_return": np.nan if target is None else target,
                    "return_mean": float(np.mean(res.returns[part])),
                    "return_std": float(np.std(res.returns[part])),
                    "score_mean": np.nan
                    if res.scores is None
                    else float(np.mean(res.scores[part])),
                    "length_mean": float(np.mean(res.lengths[part])),
                }
                if final and episode_info is not None:
                    for i, env in enumerate(venv.envs[part]):
                        rows.append(row | {"episode": i} | episode_info(env))
                else:
                    rows.append(row)

        def eval_fn(m: torch.nn.Module) -> float:
            run_eval(m, base_mode)
            return rows[-len(targets)]["return_mean"]  # the first target's, for the progress bar

        train_cfg = TrainConfig(
            iterations=train.iterations,
            batch_size=train.batch_size,
            lr=train.lr,
            warmup_steps=train.warmup_steps,
            eval_every=train.eval_every if episode_info is None else 0,
            seed=seed,
            device=train.device,
            progress=train.progress,
            precision=train.precision,
            kernels=train.kernels,
            checkpoint_path=None if checkpoint is None else os.fspath(checkpoint),
            checkpoint_every=checkpoint_every,
        )
        trainer = Trainer(model, seq, train_cfg, eval_fn=eval_fn)
        if checkpoint is not None:
            _resume_rows(trainer, rows, checkpoint, method, arch, train, eval, task)
            if trainer.resumed_cpu_s:  # a stored grid's task counts its cut-off parts too
                note_resumed_cpu(trainer.resumed_cpu_s)
        trainer.train()
        if episode_info is not None:
            model.eval()
            run_eval(model, base_mode, final=True)
        elif train.eval_every == 0 or train.iterations % train.eval_every:
            trainer.evaluate()  # always evaluate the final model
        if eval.compare_eval_modes and method in MAMBA_METHODS:
            other = "window" if base_mode == "recurrent" else "recurrent"
            model.config.eval_mode = other
            model.eval()
            try:
                run_eval(model, other)
            finally:
                model.config.eval_mode = arch.eval_mode
    finally:
        if own_envs:
            pool.close()
    return rows


def _resume_rows(
    trainer: Trainer,
    rows: list[dict[str, Any]],
    checkpoint: str | os.PathLike,
    method: str,
    arch: ArchSpec,
    train: TrainSpec,
    eval: EvalSpec,
    task: str | None,
) -> None:
    """Put the rows of a resumed run's evaluations before its own, and keep ``rows`` in the
    trainer's checkpoint from now on. The trainer checks the training (:meth:`Trainer.load`);
    this checks what it does not see: the method, architecture, evaluation and task."""
    run = json.loads(
        json.dumps(
            {
                "method": method,
                "arch": arch.task_dict(),
                # the total may grow (the trainer goes on to it), and a run may move device
                "train": {
                    k: v
                    for k, v in train.task_dict().items()
                    if k not in ("progress", "iterations", "device")
                },
                "eval": asdict(eval),
                "task": task,
            },
            default=str,
        )
    )
    before = trainer.extra.get("run")
    if before is not None and before != run:
        differ = [
            f"{k}: {before.get(k)!r} -> {run.get(k)!r}"
            for k in sorted({*run, *before})
            if before.get(k) != run.get(k)
        ]
        raise ValueError(
            f"Checkpoint '{os.fspath(checkpoint)}' was made by another run "
            f"({'; '.join(differ)}): delete it to start fresh."
        )
    rows.extend(trainer.extra.get("rows", []))
    trainer.extra.update(run=run, rows=rows)  # the same list: each save holds the rows so far
