"""One trainer for every sequence model: BC, DT, HDT (thesis 5.2.5), later DM/HDM (5.3).

The authors' settings (``notes/original-code.md``): AdamW, lr 1e-4, weight decay 1e-4, a
linear warm-up over 10k steps (``lr * min((step + 1) / warmup, 1)``), gradient norms clipped
to 0.25 (HDT: each level separately, as its two optimisers did), masked MSE. The thesis trains
100k iterations with batch 64 and K 20, evaluating every 1000 iterations.

>>> trainer = Trainer(model, seq, TrainConfig(iterations=1000), eval_fn=my_eval)  # doctest: +SKIP
>>> history = trainer.train()                      # DataFrame: iteration, loss, ... # doctest: +SKIP

Randomness: batches come from the data set's own generator (``SequenceDataset(seed=...)``),
dropout from the trainer's own torch generator state (``TrainConfig.seed``); the global
torch RNG is left as it was. The model's initial weights are the caller's: the Trainer does
not re-initialise a model, so seed torch before building it (``torch.manual_seed(0)``) for a
run that gives the same numbers twice. A checkpoint holds the model, optimiser, scheduler, both
RNG states, the iteration and the history (and the CPU seconds so far and the caller's
``Trainer.extra``), so a resumed run continues with the same numbers as an uninterrupted one.

A checkpoint also records what made it (:meth:`Trainer.made_by`: the :data:`RESULT_FIELDS` of
the :class:`TrainConfig`, the model's class and config, the data set's size and content hash)
and is resumed only by a trainer made the same way; ``iterations`` may grow (the run goes on to
the new total), never shrink below what the checkpoint holds. Anything else is refused with the
fields that differ: delete the file or set ``TrainConfig(resume=False)`` to start afresh.

Used in: HDT chapter (thesis 5.2.5); Decision Mamba chapter (5.3).
"""

from __future__ import annotations

import functools
import hashlib
import json
import math
import os
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass, is_dataclass
from pathlib import Path
from typing import Any, cast

import numpy as np
import pandas as pd
import torch
import torch.nn as nn
from tqdm.auto import tqdm

from thesis_lib._io import atomic_write, hash_arrays
from thesis_lib.seq.dropout import lane_dropout
from thesis_lib.seq.models import readout_only

__all__ = [
    "KERNELS",
    "LEFT_OUT_AT",
    "PRECISIONS",
    "RESULT_FIELDS",
    "TrainConfig",
    "Trainer",
    "batch_to_torch",
    "check_kernels",
    "check_precision",
    "data_fingerprint",
]

#: The :class:`TrainConfig` fields that change a run's numbers: a checkpoint is resumed only by a
#: trainer with the same values (``iterations`` may grow; the rest only say how or where to run).
RESULT_FIELDS = ("seed", "lr", "weight_decay", "warmup_steps", "batch_size", "grad_clip")

#: :attr:`TrainConfig.precision`'s values. ``precision`` changes a run's numbers too; a checkpoint
#: records it only where it is not ``fp32`` (so the checkpoints made before the field still match).
PRECISIONS = ("fp32", "bf16")


#: :attr:`TrainConfig.kernels`' values. ``"fast"`` and ``"fast+readout"`` change a run's numbers
#: too (other dropout draws, another AdamW rounding); a checkpoint records it only where it is not
#: ``torch``.
KERNELS = ("torch", "fast", "fast+readout")

#: Options left out of a checkpoint's record and a task's key at these values, as every run
#: before the option existed ran (:meth:`Trainer.made_by`, ``TrainSpec.task_dict``, parity).
LEFT_OUT_AT = {"precision": "fp32", "kernels": "torch"}


def check_kernels(kernels: str) -> None:
    """Raise a ValueError naming the valid values if ``kernels`` is not one of :data:`KERNELS`
    (:class:`TrainConfig` and :class:`~thesis_lib.seq.runner.TrainSpec`)."""
    if kernels not in KERNELS:
        raise ValueError(f"Unknown kernels {kernels!r}. Valid: {', '.join(KERNELS)}.")


def check_precision(precision: str) -> None:
    """Raise a ValueError naming the valid values if ``precision`` is not one of
    :data:`PRECISIONS` (:class:`TrainConfig` and :class:`~thesis_lib.seq.runner.TrainSpec`)."""
    if precision not in PRECISIONS:
        raise ValueError(f"Unknown precision {precision!r}. Valid: {', '.join(PRECISIONS)}.")


@dataclass
class TrainConfig:
    """Training settings; defaults are the thesis's (5.2.5) and the authors' code's.

    Used in: HDT chapter (thesis 5.2.5); Decision Mamba chapter.
    """

    iterations: int = 100_000
    """Total gradient steps (a resumed run continues up to this number)."""
    batch_size: int = 64
    """Windows per batch (64 in the thesis text, 16 in the authors' repositories)."""
    lr: float = 1e-4
    """Peak AdamW learning rate."""
    weight_decay: float = 1e-4
    """AdamW weight decay (applied to every parameter, as the authors' code)."""
    warmup_steps: int = 10_000
    """Linear warm-up: ``lr * min((step + 1) / warmup_steps, 1)``."""
    grad_clip: float = 0.25
    """Max gradient norm (per HDT level); ``0`` disables clipping."""
    eval_every: int = 1000
    """Call ``eval_fn`` every this many iterations (``0``: never)."""
    checkpoint_path: str | None = None
    """Where to save checkpoints; ``None``: never save."""
    checkpoint_every: int = 1000
    """Save a checkpoint every this many iterations (and at the end) when a path is set."""
    resume: bool = True
    """Load ``checkpoint_path`` at construction when it exists."""
    seed: int = 0
    """Seed of the trainer's torch generator (dropout)."""
    device: str = "cpu"
    """``"cpu"``, ``"cuda"``, or ``"auto"`` (CUDA when available)."""
    progress: bool = True
    """Show a tqdm bar with the loss and the last evaluation return."""
    precision: str = "fp32"
    """``"fp32"``: every op in float32. ``"bf16"``: the training step's forward (and so its
    backward) under ``torch.autocast`` to bfloat16: matrix products and attention in bfloat16;
    parameters, gradients, the loss and AdamW in float32 (mixed precision). On a CPU with
    AVX-512 BF16 it trains the v2 studies' d64 DT 1.2-1.55x and the d128 3-layer DT 1.5-2x as
    fast per update, by the day's machine (``benchmarks/bench_throughput.py``); its numbers
    differ from float32's by rounding, so a run is not the float32 run, and a checkpoint is
    resumed only in its own precision. Evaluation (``eval_fn``) runs in float32 either way."""
    kernels: str = "torch"
    """``"torch"``: PyTorch's dropout and AdamW. ``"fast"``: on a CPU, dropout masks drawn as
    32-bit lanes of the generator's 64-bit integers (:mod:`thesis_lib.seq.dropout`, a quarter of
    ``bernoulli_``'s cost; the attention weights' too), and AdamW's fused kernel (one pass over
    each parameter instead of a dozen small ops; also on CUDA). Identical in distribution to
    ``"torch"`` (each element is kept with probability ``1 - p`` up to ``2^-32``; AdamW's update
    up to rounding), but other draws, so not the same run; a checkpoint is resumed only with its
    own kernels. It takes a tenth to a fifth off a transformer's bf16 step on a CPU; with
    ``precision="bf16"`` the v2 studies' d64 DT trains about 1.4-1.5x as fast as the float32
    torch step (``benchmarks/bench_throughput.py``). ``"fast+readout"``: ``"fast"``, and the
    transformers' last block run on the tokens the loss reads only
    (:func:`~thesis_lib.seq.models.readout_only`: the ``s_t`` tokens of the DT and the HDT's
    low level, the ``g_{t-1}`` tokens of its high level). Every token is still a key there, so
    the loss and its gradients are the same function of the weights as ``"fast"``'s up to
    float error, with fewer dropout draws; with ``precision="bf16"`` the d64 DT makes
    1.8-2.05x the runs per CPU-hour of the float32 torch step, by the machine's load. The
    Mambas (DM, HDM) have no readout path: for them it is ``"fast"``. Evaluation uses torch's kernels and the full trunk either way."""

    def __post_init__(self) -> None:
        for name in ("iterations", "batch_size", "warmup_steps"):
            if int(getattr(self, name)) < 1:
                raise ValueError(f"Expect `{name}` >= 1, actually: {getattr(self, name)!r}.")
        for name in ("eval_every", "checkpoint_every"):
            if int(getattr(self, name)) < 0:
                raise ValueError(
                    f"Expect `{name}` >= 0 (0 = never), actually: {getattr(self, name)!r}."
                )
        if not self.lr > 0 or self.weight_decay < 0 or self.grad_clip < 0:
            raise ValueError(
                f"Expect lr > 0, weight_decay >= 0 and grad_clip >= 0, got lr={self.lr}, "
                f"weight_decay={self.weight_decay}, grad_clip={self.grad_clip}."
            )
        if self.device not in ("cpu", "cuda", "auto") and not self.device.startswith("cuda:"):
            raise ValueError(f"Unknown device {self.device!r}. Valid: cpu, cuda, cuda:N, auto.")
        check_precision(self.precision)
        check_kernels(self.kernels)


def _warmup(step: int, warmup_steps: int) -> float:
    return min((step + 1) / warmup_steps, 1.0)


def batch_to_torch(
    dataset: Any, batch: Any, device: str | torch.device = "cpu"
) -> dict[str, torch.Tensor]:
    """A :class:`~thesis_lib.data.SequenceBatch` as model inputs (tensors on ``device``).

    The batch carries everything the models read, HDT's ``prev_subgoals`` included
    (``g_{t-1}``: the previous step's sub-goal, also across the window's start, zero at an
    episode's first step and on padding; see :class:`~thesis_lib.data.SequenceBatch`), so this
    is ``batch.to_torch(device)``; ``dataset`` is kept for callers of the earlier signature.

    Used in: HDT chapter (thesis 5.2); Decision Mamba chapter.

    Args:
        dataset: The :class:`~thesis_lib.data.SequenceDataset` the batch came from (unused).
        batch: A batch from ``dataset.sample`` / ``dataset.windows``.
        device: Device of the tensors.

    Returns:
        ``{name: tensor}`` for every field of the batch that is not ``None``.
    """
    return batch.to_torch(device)


def data_fingerprint(dataset: Any) -> dict[str, Any]:
    """The size and content hash of a data set: what a checkpoint records of its training data.

    The hash covers every array attribute of ``dataset`` (states, actions, returns-to-go,
    sub-goals, ...: dtype, shape and bytes, by name) and its scalar settings (``K``,
    ``rtg_scale``, ``paper_compat``, ...), not its random generator: the same data sampled with
    another seed is the same data set (a resumed run restores the generator's state).

    Used in: :class:`Trainer` checkpoints (HDT, Decision Mamba and MDLT chapters).

    Example:
        >>> from thesis_lib.data import Episode, SequenceDataset
        >>> ep = Episode(0, np.arange(8.0).reshape(4, 2), np.zeros((3, 1)), np.ones(3),
        ...              np.zeros(3, bool), np.zeros(3, bool))
        >>> a, b = (data_fingerprint(SequenceDataset([ep], K=2, seed=s)) for s in (0, 1))
        >>> a == b, a["size"], a == data_fingerprint(SequenceDataset([ep], K=3))
        (True, 3, False)
    """
    attrs = sorted(getattr(dataset, "__dict__", {}).items())
    settings = {k: v for k, v in attrs if isinstance(v, (bool, int, float, str))}
    h = hashlib.sha256(json.dumps(settings, sort_keys=True).encode())
    for name, value in attrs:
        if isinstance(value, np.ndarray):
            h.update(name.encode())
            hash_arrays(h, [value])
    return {"size": len(dataset), "sha256": h.hexdigest()[:16]}


def _mean_return(result: Any) -> float:
    if hasattr(result, "returns"):
        return float(np.mean(result.returns))
    return float(result)


class Trainer:
    """Train a sequence model on a :class:`~thesis_lib.data.SequenceDataset` (thesis Algorithm 3).

    Used in: HDT chapter (thesis 5.2.5); Decision Mamba chapter.

    Args:
        model: :class:`~thesis_lib.seq.models.BC`, ``DecisionTransformer``, ``HDT`` or any
            module with ``forward(batch, targets) -> SeqOutput`` and a ``config`` holding
            ``state_dim``, ``act_dim`` and ``K``. Trained from its weights as they are (the
            Trainer does not re-initialise it): seed torch before building it
            (``torch.manual_seed(0)``) for the same numbers on every run.
        dataset: Where batches come from.
        config: :class:`TrainConfig`.
        eval_fn: Called as ``eval_fn(model)`` (model in eval mode) every
            ``config.eval_every`` iterations; returns a float or an object with ``returns``
            (e.g. :class:`~thesis_lib.seq.evaluation.EvalResult`); its mean is logged.

    Raises:
        ValueError: If the data set and the model disagree on dimensions, or an HDT gets a
            data set without sub-goals; or if ``config.checkpoint_path`` holds a checkpoint
            (and ``config.resume``) made by another run (:meth:`load`) or with more iterations
            than ``config.iterations``.
    """

    def __init__(
        self,
        model: nn.Module,
        dataset: Any,
        config: TrainConfig | None = None,
        eval_fn: Callable[[nn.Module], Any] | None = None,
    ) -> None:
        self.config = config = config or TrainConfig()
        self.model, self.dataset, self.eval_fn = model, dataset, eval_fn
        _check_compatible(model, dataset)
        if config.device == "auto":
            self.device = torch.device("cuda" if torch.cuda.is_available() else "cpu")
        else:
            self.device = torch.device(config.device)
        self.model.to(self.device)
        self.optimizer = torch.optim.AdamW(
            model.parameters(),
            lr=config.lr,
            weight_decay=config.weight_decay,
            fused=True if config.kernels != "torch" else None,
        )
        self.scheduler = torch.optim.lr_scheduler.LambdaLR(
            self.optimizer, functools.partial(_warmup, warmup_steps=config.warmup_steps)
        )
        self.iteration = 0
        self.history: list[dict[str, float]] = []
        self.last_eval: float = math.nan
        # what the caller keeps in the checkpoint beside the training state (JSON-able; e.g.
        # run_offline's evaluation rows); restored by load()
        self.extra: dict[str, Any] = {}
        self._cpu_before, self._cpu_t0 = 0.0, time.process_time()
        self._rng_state = torch.Generator().manual_seed(config.seed).get_state()
        self._data_fingerprint: dict[str, Any] | None = None
        if config.resume and config.checkpoint_path and Path(config.checkpoint_path).exists():
            self.load(config.checkpoint_path)
            if self.iteration > config.iterations:
                raise ValueError(
                    f"Checkpoint '{config.checkpoint_path}' holds {self.iteration} iterations, "
                    f"more than iterations={config.iterations}: ask for at least "
                    f"{self.iteration}, or start fresh (delete the file or set resume=False)."
                )

    # -- one step ---------------------------------------------------------------------------

    def step(self) -> dict[str, float]:
        """One gradient step on a fresh batch; returns ``{"loss": ..., "loss_<part>": ...}``."""
        batch = batch_to_torch(
            self.dataset, self.dataset.sample(self.config.batch_size), self.device
        )
        self.model.train()
        with torch.random.fork_rng(devices=[]):  # our own dropout stream; global RNG untouched
            torch.set_rng_state(self._rng_state)
            with (
                torch.autocast(
                    self.device.type,
                    dtype=torch.bfloat16,
                    enabled=self.config.precision == "bf16",
                ),
                lane_dropout(self.config.kernels != "torch" and self.device.type == "cpu"),
                readout_only(self.config.kernels == "fast+readout"),
            ):
                out = self.model(batch, targets=batch)
            self.optimizer.zero_grad(set_to_none=True)
            out.loss.backward()
            self._rng_state = torch.get_rng_state()
        if self.config.grad_clip > 0:
            groups = (
                cast(Any, self.model).clip_groups()
                if hasattr(self.model, "clip_groups")
                else [list(self.model.parameters())]
            )
            for params in groups:
                torch.nn.utils.clip_grad_norm_(params, self.config.grad_clip)
        self.optimizer.step()
        self.scheduler.step()
        self.iteration += 1
        row = {"iteration": self.iteration, "loss": out.loss.item()}
        row.update({f"loss_{k}": v for k, v in (out.losses or {}).items()})
        return row

    def evaluate(self) -> Any:
        """Run ``eval_fn`` on the model in eval mode; record and return its result."""
        if self.eval_fn is None:
            raise ValueError(
                "This Trainer has no eval_fn; pass eval_fn=lambda m: evaluate(m, task, ...)."
            )
        self.model.eval()
        try:
            result = self.eval_fn(self.model)
        finally:
            self.model.train()
        self.last_eval = _mean_return(result)
        return result

    # -- the loop ---------------------------------------------------------------------------

    def train(self, iterations: int | None = None) -> pd.DataFrame:
        """Train until ``iterations`` (default ``config.iterations``) steps in total.

        Returns:
            The history, one row per iteration: ``iteration``, ``loss``, ``loss_<part>``,
            ``lr``, ``eval_return`` (NaN where no evaluation ran).
        """
        cfg = self.config
        total = cfg.iterations if iterations is None else int(iterations)
        if total < self.iteration:
            raise ValueError(
                f"Expect `iterations` >= {self.iteration} (this trainer's iterations so far), "
                f"actually: {total}."
            )
        bar = tqdm(
            total=total,
            initial=self.iteration,
            disable=not cfg.progress,
            desc=type(self.model).__name__,
        )
        try:
            while self.iteration < total:
                row = self.step()
                row["lr"] = float(self.scheduler.get_last_lr()[0])
                row["eval_return"] = math.nan
                if (
                    self.eval_fn is not None
                    and cfg.eval_every
                    and self.iteration % cfg.eval_every == 0
                ):
                    self.evaluate()
                    row["eval_return"] = self.last_eval
                self.history.append(row)
                if (
                    cfg.checkpoint_path
                    and cfg.checkpoint_every
                    and self.iteration % cfg.checkpoint_every == 0
                ):
                    self.save(cfg.checkpoint_path)
                bar.update(1)
                if self.iteration % 10 == 0 or self.iteration == total:
                    bar.set_postfix(
                        loss=f"{row['loss']:.4f}", eval=f"{self.last_eval:.1f}", refresh=False
                    )
        finally:
            bar.close()
        if cfg.checkpoint_path:
            self.save(cfg.checkpoint_path)
        return self.history_frame()

    @property
    def resumed_cpu_s(self) -> float:
        """The CPU seconds recorded in the checkpoint this trainer resumed (the runs cut off
        before it, up to their last save); 0 for a fresh start."""
        return self._cpu_before

    @property
    def cpu_s(self) -> float:
        """Process CPU seconds since this trainer was made, plus those recorded in the
        checkpoint it resumed (the work of the runs cut off before it, up to their last save)."""
        return self._cpu_before + time.process_time() - self._cpu_t0

    def history_frame(self) -> pd.DataFrame:
        """The history as a DataFrame (one row per iteration)."""
        return pd.DataFrame(self.history)

    # -- checkpoints ------------------------------------------------------------------------

    def made_by(self) -> dict[str, Any]:
        """What this trainer's numbers depend on, as a checkpoint records it (flat, JSON-like).

        The :data:`RESULT_FIELDS` of the config, ``precision`` where it is not ``fp32`` and
        ``kernels`` where it is not ``torch``;
        ``model_class`` and ``model.<field>`` for each
        field of the model's ``config`` dataclass; ``data.size`` and ``data.sha256`` of the
        data set (:func:`data_fingerprint`, computed once per trainer).
        """
        made: dict[str, Any] = {k: getattr(self.config, k) for k in RESULT_FIELDS}
        for k, default in LEFT_OUT_AT.items():
            if getattr(self.config, k) != default:
                made[k] = getattr(self.config, k)
        made["model_class"] = type(self.model).__name__
        model_cfg = getattr(self.model, "config", None)
        if model_cfg is not None and is_dataclass(model_cfg) and not isinstance(model_cfg, type):
            made.update({f"model.{k}": v for k, v in asdict(model_cfg).items()})
        if self._data_fingerprint is None:
            self._data_fingerprint = data_fingerprint(self.dataset)
        made.update({f"data.{k}": v for k, v in self._data_fingerprint.items()})
        # as it reads back: tuples as lists, anything not JSON as its repr
        return json.loads(json.dumps(made, default=repr))

    def state_dict(self) -> dict[str, Any]:
        """Everything a resumed run needs, and what made it (:meth:`made_by`)."""
        return {
            "made_by": self.made_by(),
            "model_class": type(self.model).__name__,
            "model_config": asdict(cast(Any, self.model).config)
            if hasattr(self.model, "config")
            else None,
            "model": self.model.state_dict(),
            "optimizer": self.optimizer.state_dict(),
            "scheduler": self.scheduler.state_dict(),
            "torch_rng": self._rng_state,
            "dataset_rng": self.dataset.rng.bit_generator.state,
            "iteration": self.iteration,
            "history": self.history,
            "last_eval": self.last_eval,
            "train_config": asdict(self.config),
            "cpu_s": self.cpu_s,
            "extra_json": json.dumps(self.extra, default=_json_scalar),
        }

    def save(self, path: str | os.PathLike) -> None:
        """Write a checkpoint (atomically: a crash mid-write keeps the previous one)."""
        state = self.state_dict()
        atomic_write(path, lambda tmp: torch.save(state, tmp))

    def load(self, path: str | os.PathLike) -> None:
        """Restore a checkpoint written by :meth:`save` into this trainer (model included).

        Raises:
            FileNotFoundError: If there is no checkpoint at ``path``.
            ValueError: If it was written for another model class, or made by another run: it
                records another :meth:`made_by` (the message names each field that differs,
                old -> new), or none (a checkpoint of the code before the record).
        """
        path = Path(path)
        if not path.exists():
            raise FileNotFoundError(
                f"No checkpoint at '{path}'. Train with TrainConfig(checkpoint_path=...) first."
            )
        ckpt = torch.load(path, map_location=self.device, weights_only=True)
        fresh = "delete it or set resume=False to start fresh"
        if ckpt["model_class"] != type(self.model).__name__:
            raise ValueError(
                f"Checkpoint '{path}' holds a {ckpt['model_class']}, not a {type(self.model).__name__}; "
                f"build the matching model (config: {ckpt['model_config']}), or {fresh}."
            )
        if not isinstance(ckpt.get("made_by"), dict):
            raise ValueError(
                f"Checkpoint '{path}' does not record what made it (written before checkpoints "
                f"were keyed by their run), so it cannot be matched to this run: {fresh}."
            )
        old, new = ckpt["made_by"], self.made_by()

        def show(made: dict[str, Any], k: str) -> str:
            return repr(made[k]) if k in made else "(absent)"

        differ = [
            f"{k}: {show(old, k)} -> {show(new, k)}"
            for k in [*new, *(k for k in old if k not in new)]
            if show(old, k) != show(new, k)
        ]
        if differ:
            raise ValueError(
                f"Checkpoint '{path}' was made by another run ({'; '.join(differ)}): {fresh}."
            )
        self.model.load_state_dict(ckpt["model"])
        self.optimizer.load_state_dict(ckpt["optimizer"])
        self.scheduler.load_state_dict(ckpt["scheduler"])
        self._rng_state = ckpt["torch_rng"].cpu()
        self.dataset.rng.bit_generator.state = ckpt["dataset_rng"]
        self.iteration = int(ckpt["iteration"])
        self.history = list(ckpt["history"])
        self.last_eval = float(ckpt["last_eval"])
        self.extra = json.loads(ckpt.get("extra_json", "{}"))
        self._cpu_before, self._cpu_t0 = float(ckpt.get("cpu_s", 0.0)), time.process_time()


def _json_scalar(o: Any) -> Any:
    """``json.dumps``'s ``default`` for :attr:`Trainer.extra`: NumPy scalars as numbers."""
    if isinstance(o, np.generic):
        return o.item()
    raise TypeError(f"Trainer.extra holds a {type(o).__name__}, which a checkpoint cannot keep.")


def _check_compatible(model: nn.Module, dataset: Any) -> None:
    cfg = getattr(model, "config", None)
    if cfg is None:
        return
    name = type(model).__name__
    state_dim, act_dim = dataset.states.shape[-1], dataset.actions.shape[-1]
    if state_dim != cfg.state_dim:
        raise ValueError(
            f"{name} expects states of size state_dim={cfg.state_dim}, but the data set's states have "
            f"size {state_dim} (shape {dataset.states.shape}). Build the model with state_dim={state_dim}."
        )
    if act_dim != cfg.act_dim:
        raise ValueError(
            f"{name} expects actions of size act_dim={cfg.act_dim}, but the data set's actions have "
            f"size {act_dim}. Build the model with act_dim={act_dim}."
        )
    if dataset.K > cfg.K:
        raise ValueError(
            f"The data set's windows have K={dataset.K} steps; {name} was built with K={cfg.K}."
        )
    if getattr(cfg, "paper_compat", False) and not dataset.prepend_zero_action:
        raise ValueError(
            f"{name}(paper_compat=True) reads a_(t-1) tokens: build the SequenceDataset with prepend_zero_action=True."
        )
    if name == "HDT":
        if dataset.subgoals is None:
            raise ValueError(
                "HDT needs sub-goals: build the data set with "
                "SequenceDataset(data, K, subgoal_fn=thesis_lib.seq.subgoals.subgoal_fn())."
            )
        if dataset.subgoals.shape[-1] != cfg.state_dim:
            raise ValueError(
                f"HDT predicts sub-goals of size state_dim={cfg.state_dim}, the data set's have "
                f"size {dataset.subgoals.shape[-1]}."
            )
