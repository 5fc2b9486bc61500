"""The Decision Mamba chapter's experiments: Table 5.5's runs, the architecture sweeps, the
models' sizes, Table 5.6's timings, and the pre-registered study's grid.

* :func:`offline_task`: one run (the HDT chapter's :func:`~thesis_lib.chapters.hdt.offline_rows`,
  with this chapter's :data:`CURVE_COLUMNS`); :func:`run_table_5_5` and :func:`run_sweeps` run
  it as a resumable sweep (``results/05_decision_mamba/tasks``).
* :func:`run_parameter_counts`: the five models' sizes.
* :func:`run_table_5_6`: the timings of Table 5.6; :func:`timing_task` reduces one method's to
  the study's row (C6).
* :func:`study_tasks`: the study's grid (``thesis study 05_decision_mamba``): the runs are the
  HDT chapter's study runs (:func:`thesis_lib.chapters.hdt.study_task`), so a DT or HDT run has
  one key in both studies.

Used in: Decision Mamba chapter (Tables 5.5, 5.6; Figs 5.3-5.6; its study).
"""

from __future__ import annotations

import time
from collections.abc import Mapping
from dataclasses import asdict
from typing import Any

import gymnasium as gym
import numpy as np
import pandas as pd
import torch
from tqdm.auto import tqdm

from thesis_lib.chapters.decision_mamba.config import (
    CHAPTER,
    HIERARCHICAL,
    MAMBA_METHODS,
    RTG_METHODS,
    Arch,
    Config,
    parse_arch,
)
from thesis_lib.chapters.hdt import STUDY_COLUMNS as HDT_STUDY_COLUMNS
from thesis_lib.chapters.hdt import offline_rows, run_sweep, split_dataset, study_task
from thesis_lib.data import SequenceDataset, make_env
from thesis_lib.data.minari_sets import env_name, is_minari_id, make_minari_env, open_dataset
from thesis_lib.seq import (
    HDM,
    HDT,
    DecisionMamba,
    DecisionTransformer,
    DMConfig,
    DTConfig,
    HDMConfig,
    HDTConfig,
    resolve_scan_backend,
)
from thesis_lib.seq.evaluation import evaluate, target_returns
from thesis_lib.seq.registry import LEGACY_INIT, LEGACY_SAMPLING, build_model
from thesis_lib.seq.runner import EvalSpec
from thesis_lib.seq.subgoals import subgoal_fn
from thesis_lib.seq.trainer import TrainConfig, Trainer
from thesis_lib.sweep import Task, task_id

__all__ = [
    "CURVE_COLUMNS",
    "STUDY_COLUMNS",
    "STUDY_FILE_DEFAULTS",
    "TIMING_FIELDS",
    "load_datasets",
    "offline_task",
    "run_parameter_counts",
    "run_sweeps",
    "run_table_5_5",
    "run_table_5_6",
    "study_tasks",
    "sweep_task",
    "timing_task",
]

STUDY_FILE_DEFAULTS: dict[str, Any] = {"init": LEGACY_INIT, "sampling": LEGACY_SAMPLING}
"""What a study file that does not name these fields ran with (the v1 studies, registered
before the transformers' ``init`` existed): :func:`thesis_lib.book.study.study_config`."""

#: The columns of the curves (one row per evaluation and target).
CURVE_COLUMNS = [
    "method", "task", "tier", "seed", "arch", "n_layers", "d_model", "K", "eval_mode", "target",
    "target_return", "iteration", "return_mean", "return_std", "score_mean", "length_mean",
    "loss",
]  # fmt: skip


# ------------------------------------------------------------------------------------ the runs


def load_datasets(
    names: list[str], cfg: Config, data: Mapping[tuple[str, str], Any] | None = None
) -> dict[tuple[str, str], Any]:
    """``{(task, tier): OfflineDataset}`` of ``names`` (those not already in ``data``).

    A real Minari id (``D4RL/kitchen/mixed-v2``) is read from its download and keyed by its
    task and tier (``("kitchen", "mixed")``).

    Used in: Decision Mamba chapter.

    Raises:
        FileNotFoundError: a Minari id not downloaded (the message names the id and where
            Minari looks).
    """
    out = dict(data or {})
    for name in names:
        key = split_dataset(name)
        if key not in out:
            out[key] = open_dataset(name, cfg.dataset_size, cfg.n_transitions)
    return out


@task_id("thesis_lib.chapters.decision_mamba:offline_task")  # its sweep tasks' keys
def offline_task(config: dict[str, Any]) -> list[dict[str, Any]]:
    """One sweep task: train and evaluate ``config["method"]`` on ``config["dataset"]``.

    ``config`` holds ``method, dataset ("task/tier" or a Minari id), dataset_size,
    n_transitions`` and the ``arch``, ``train``, ``eval`` specs as dicts. Returns
    :data:`CURVE_COLUMNS` rows: the HDT chapter's run
    (:func:`thesis_lib.chapters.hdt.offline_rows`, the one its study reduces) with this
    chapter's columns.

    Used in: Decision Mamba chapter (through :func:`run_table_5_5`, :func:`run_sweeps`).
    """
    return offline_rows(config, CURVE_COLUMNS)


def sweep_task(
    cfg: Config, method: str, dataset: str, seed: int, arch: str | Arch, ev: EvalSpec
) -> Task:
    """The :func:`offline_task` task of one run of ``cfg`` at ``arch`` evaluated as ``ev``.

    Used in: Decision Mamba chapter (:func:`run_table_5_5`, :func:`run_sweeps`).
    """
    return Task(
        offline_task,
        {
            "method": method,
            "dataset": dataset,
            "dataset_size": cfg.dataset_size,
            "n_transitions": cfg.n_transitions,
            "arch": cfg.arch_spec(arch).task_dict(),
            "train": cfg.train_spec(seed).task_dict(),
            "eval": asdict(ev),
        },
    )


def _run(cfg: Config, tasks: list[Task], desc: str) -> pd.DataFrame:
    if not tasks:
        return pd.DataFrame(columns=CURVE_COLUMNS)
    return run_sweep(CHAPTER, tasks, desc, cfg.progress)


def run_table_5_5(cfg: Config) -> pd.DataFrame:
    """Every data set x seed x method of ``cfg`` at ``cfg.arch``: one row per evaluation and target.

    A resumable sweep (store ``results/05_decision_mamba/tasks``).

    Used in: Decision Mamba chapter (Table 5.5, Fig 5.4).
    """
    ev = EvalSpec(
        episodes=cfg.eval_episodes,
        max_steps=cfg.max_eval_steps,
        targets=("max", "half", "10k"),
        compare_eval_modes=cfg.compare_eval_modes,
    )
    tasks = [
        sweep_task(cfg, m, d, s, cfg.arch, ev)
        for d in cfg.datasets
        for s in cfg.seeds
        for m in cfg.methods
    ]
    return _run(cfg, tasks, "Table 5.5")


def run_sweeps(cfg: Config, reuse: pd.DataFrame | None = None) -> pd.DataFrame:
    """The architecture sweeps of Figs 5.3 (HDM), 5.5 (DM) and 5.6 (DM with RTG, at the max target only).

    Runs already in ``reuse`` (e.g. :func:`run_table_5_5`'s, same method, data set, seed and
    architecture) are taken from there instead of trained again.

    Used in: Decision Mamba chapter (Figs 5.3, 5.5, 5.6).
    """
    ev = EvalSpec(episodes=cfg.eval_episodes, max_steps=cfg.max_eval_steps, targets=("max",))
    frames, tasks = [], []
    for d in cfg.sweep_datasets:
        task, tier = split_dataset(d)
        for a in map(parse_arch, cfg.sweep_archs):
            for s in cfg.seeds:
                for m in cfg.sweep_methods:
                    if reuse is not None and len(reuse):
                        hit = reuse[
                            (reuse.method == m)
                            & (reuse.task == task)
                            & (reuse.tier == tier)
                            & (reuse.seed == s)
                            & (reuse.arch == a.label)
                        ]
                        if len(hit):
                            frames.append(hit)
                            continue
                    tasks.append(sweep_task(cfg, m, d, s, a, ev))
    frames.append(_run(cfg, tasks, "Figs 5.3, 5.5, 5.6"))
    return pd.concat([f for f in frames if len(f)], ignore_index=True)


def run_parameter_counts(
    state_dim: int = 11, act_dim: int = 3, K: int = 20, d_model: int = 128, n_layers: int = 6
) -> pd.DataFrame:
    """Trainable parameters of DT, HDT, DM (with and without the gated MLP) and HDM at one size.

    Used in: Decision Mamba chapter (the models' sizes at the thesis's 6/128/20).
    """
    size: dict[str, Any] = dict(
        state_dim=state_dim, act_dim=act_dim, K=K, d_model=d_model, n_layers=n_layers
    )

    def n_params(model: torch.nn.Module) -> int:
        return sum(p.numel() for p in model.parameters())

    models = {
        f"DT ({n_layers} GPT blocks)": lambda: DecisionTransformer(DTConfig(**size)),
        f"HDT (2 x {n_layers} GPT blocks)": lambda: HDT(HDTConfig(**size)),
        "DM, gated MLP (authors' later code)": lambda: DecisionMamba(DMConfig(**size)),
        "DM, plain Mamba blocks": lambda: DecisionMamba(DMConfig(**size, gated_mlp=False)),
        "HDM, gated MLP": lambda: HDM(HDMConfig(**size)),
    }
    return pd.DataFrame([{"model": k, "parameters": n_params(f())} for k, f in models.items()])


# ------------------------------------------------------------------------------- Table 5.6: time


def _timing_env(task: str) -> Any:
    """One environment of ``task`` (a Minari id: its recorded evaluation environment)."""
    make = make_minari_env if is_minari_id(task) else make_env
    return gym.vector.SyncVectorEnv([lambda: make(task)])


def _sync(device: torch.device) -> None:
    """Wait for ``device``'s queued kernels (CUDA runs them after the call returns), so a
    timer read next counts them; nothing on the CPU."""
    if device.type == "cuda":
        torch.cuda.synchronize(device)


def run_table_5_6(cfg: Config, data: Mapping[tuple[str, str], Any] | None = None) -> pd.DataFrame:
    """Table 5.6: ms per training iteration and per inference step of each method, at ``cfg.timing_arch``.

    * train: one gradient step of the :class:`~thesis_lib.seq.trainer.Trainer` (sampling the
      batch of ``timing_batch_size`` windows included; HDT/HDM: both levels), timed
      ``timing_train_iters`` times after one untimed step;
    * inference: an episode of at most ``timing_infer_steps`` steps in one environment through
      :func:`~thesis_lib.seq.evaluation.evaluate` (building the history, the action, the
      environment's transition), as ms per step, ``timing_infer_episodes`` episodes after one
      untimed. DT/HDT re-run the window (``window``); DM/HDM are timed re-running the window, as
      the authors' code, and with the recurrent step (``recurrent``, not in the thesis).

    The models are untrained (time does not depend on the weights, only on episode lengths).
    They run on ``cfg.device``; on a GPU each timed training step ends with a synchronisation,
    and acting synchronises at every step (the action goes back to the environment).

    Used in: Decision Mamba chapter (Table 5.6).

    Returns:
        One row per data set x method x phase x mode: ``task, tier, method, phase, mode,
        time_ms_mean, time_ms_std, n``.
    """
    arch = cfg.arch_spec(cfg.timing_arch)
    data = load_datasets(cfg.timing_datasets, cfg, data)
    rows = []
    for name in cfg.timing_datasets:
        task, tier = split_dataset(name)
        for method in tqdm(cfg.methods, desc=f"timing {name}", disable=not cfg.progress):
            sg = subgoal_fn(cfg.paper_compat) if method in HIERARCHICAL else None
            seq = SequenceDataset(
                data[(task, tier)],
                K=arch.K,
                subgoal_fn=sg,
                paper_compat=cfg.paper_compat,
                seed=cfg.seed,
            )
            venv = _timing_env(env_name(name))
            torch.manual_seed(cfg.seed)
            model: Any = build_model(
                method, seq, arch, float(np.max(venv.single_action_space.high))
            )
            trainer = Trainer(
                model,
                seq,
                TrainConfig(
                    iterations=10**9,
                    batch_size=cfg.timing_batch_size,
                    lr=cfg.lr,
                    warmup_steps=cfg.warmup_steps,
                    progress=False,
                    device=cfg.device,
                    precision=cfg.precision,
                    kernels=cfg.kernels,
                ),
            )
            times = []
            for i in range(cfg.timing_train_iters + 1):
                t0 = time.perf_counter()
                trainer.step()
                _sync(trainer.device)  # a GPU's kernels run after the call returns
                if i:
                    times.append((time.perf_counter() - t0) * 1e3)
            rows.append(
                {
                    "task": task,
                    "tier": tier,
                    "method": method,
                    "phase": "train",
                    "mode": "",
                    "time_ms_mean": float(np.mean(times)),
                    "time_ms_std": float(np.std(times)),
                    "n": len(times),
                }
            )
            target = target_returns(data[(task, tier)])["max"] if method in RTG_METHODS else None
            modes = ("window", "recurrent") if method in MAMBA_METHODS else ("window",)
            try:
                for mode in modes:
                    if method in MAMBA_METHODS:
                        model.config.eval_mode = mode
                    per_step = []
                    for i in range(cfg.timing_infer_episodes + 1):
                        t0 = time.perf_counter()
                        res = evaluate(
                            model,
                            venv,
                            1,
                            target_return=target,
                            dataset=seq,
                            seed=cfg.seed + i,
                            max_steps=cfg.timing_infer_steps,
                        )
                        if i:
                            per_step.append(
                                (time.perf_counter() - t0) * 1e3 / max(int(res.lengths[0]), 1)
                            )
                    rows.append(
                        {
                            "task": task,
                            "tier": tier,
                            "method": method,
                            "phase": "inference",
                            "mode": mode,
                            "time_ms_mean": float(np.mean(per_step)),
                            "time_ms_std": float(np.std(per_step)),
                            "n": len(per_step),
                        }
                    )
            finally:
                venv.close()
    return pd.DataFrame(rows)


# ------------------------------------------------------------------------------------ the study

#: The columns of the study's rows: a run's (:func:`thesis_lib.chapters.hdt.study_run`, the
#: HDT chapter's ``STUDY_COLUMNS``) and a C6 timing's (:func:`timing_task`); the study engine
#: checks the study file's metrics against them.
STUDY_COLUMNS = [
    *HDT_STUDY_COLUMNS,
    "arch", "train_ms", "act_ms_window", "act_ms_recurrent", "train_per_s", "act_per_s_window",
    "act_per_s_recurrent", "act_per_s",
]  # fmt: skip

#: The Config fields a C6 timing task carries (its config, so its key).
TIMING_FIELDS = (
    "timing_arch",
    "timing_batch_size",
    "timing_train_iters",
    "timing_infer_steps",
    "timing_infer_episodes",
    "dataset_size",
    "n_transitions",
)


def study_tasks(cfg: Config) -> list[Task]:
    """The tasks of the chapter's pre-registered study (``params/05_decision_mamba.study.yml``).

    Every data set x seed x method of ``cfg`` at ``cfg.arch``, each reduced to one row by
    :func:`thesis_lib.chapters.hdt.study_run`, and the timings of C6 (:func:`timing_task`)
    on every ``timing_datasets`` x seed x method. A DT or HDT run here has the same task key as
    the HDT chapter's study run of the same settings, so the study file's ``reuse: [04_hdt]``
    copies it instead of training it again.

    Used in: ``thesis study 05_decision_mamba``.
    """
    arch = cfg.arch_spec()
    tasks = [
        study_task(cfg, m, d, s, arch) for d in cfg.datasets for s in cfg.seeds for m in cfg.methods
    ]
    timing = {k: getattr(cfg, k) for k in TIMING_FIELDS}
    if cfg.device != "cpu":  # the CPU studies' task keys hold no device
        timing["device"] = cfg.device
    tasks += [
        Task(timing_task, {"method": m, "dataset": d, "seed": s, **timing})
        for d in cfg.timing_datasets
        for s in cfg.seeds
        for m in cfg.methods
    ]
    return tasks


@task_id("thesis_lib.chapters.decision_mamba:timing_task")  # the committed study's keys
def timing_task(config: dict[str, Any]) -> list[dict[str, Any]]:
    """One C6 study task: Table 5.6's timings of one method on one environment, one repeat.

    ``config`` holds ``method, dataset, seed`` (the repeat: model init and episode starts),
    the ``timing_*``, ``dataset_size`` and ``n_transitions`` fields of :class:`Config`, and
    ``device`` where it is not the CPU (a GPU study: ``cuda``; its rows also name the GPU,
    ``device``, and the DM/HDM's scan, ``scan_backend``). Returns
    one row: ``method, setting ("<task/tier> (timing)"), seed, scale``, the ms per training
    iteration (``train_ms``) and per action (``act_ms_window``; DM/HDM also
    ``act_ms_recurrent``), and the speeds ``train_per_s``, ``act_per_s_window``,
    ``act_per_s_recurrent`` and ``act_per_s`` (each method's own way: DM/HDM recurrent,
    DT/HDT window); higher is better, as the study's comparisons read them.

    Used in: ``thesis study 05_decision_mamba`` (C6).
    """
    device = str(config.get("device", "cpu"))
    if device != "cpu" and not torch.cuda.is_available():
        raise RuntimeError(
            f"This study task times the models on device {device!r}, but torch sees no CUDA GPU "
            f"here (torch {torch.__version__}). Run the study on a machine with one."
        )
    cfg = Config(
        methods=[config["method"]],
        seed=int(config["seed"]),
        timing_datasets=[config["dataset"]],
        device=device,
        **{k: config[k] for k in TIMING_FIELDS},
    )
    t = run_table_5_6(cfg)
    ms = {
        ("train" if p == "train" else f"act_{m}"): float(v)
        for p, m, v in zip(t.phase, t["mode"], t.time_ms_mean)
    }
    row: dict[str, Any] = {
        "method": config["method"],
        "setting": f"{config['dataset']} (timing)",
        "seed": int(config["seed"]),
        "scale": config.get("scale", "study"),
        "arch": config["timing_arch"],
        "train_ms": ms["train"],
        "act_ms_window": ms["act_window"],
        "act_ms_recurrent": ms.get("act_recurrent", np.nan),
    }
    row["train_per_s"] = 1e3 / row["train_ms"]
    row["act_per_s_window"] = 1e3 / row["act_ms_window"]
    row["act_per_s_recurrent"] = 1e3 / row["act_ms_recurrent"]
    own = "act_ms_recurrent" if config["method"] in MAMBA_METHODS else "act_ms_window"
    row["act_per_s"] = 1e3 / row[own]  # each method acting its own way (DM/HDM: recurrent)
    if device != "cpu":  # which GPU, and which selective scan the DM/HDM ran there
        dev = torch.device("cuda" if device == "auto" else device)
        row["device"] = torch.cuda.get_device_name(dev)
        row["scan_backend"] = resolve_scan_backend(dev) if config["method"] in MAMBA_METHODS else ""
    return [row]
