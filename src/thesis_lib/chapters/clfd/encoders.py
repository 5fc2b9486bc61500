"""The CLfD chapter's encoders: one sweep task per trained encoder, stored and shared.

Every experiment of the chapter (Table 4.1, the paper_compat check, Table 4.2, Fig 4.4) and of
its study starts from encoders trained by one task function, :func:`train_encoder_task`, run
through :func:`thesis_lib.sweep.run_tasks`: its rows are stored under ``results/02_clfd/tasks``
and its weights under ``results/02_clfd/models``, so an interrupted chapter resumes and an
encoder needed by several tables is trained once. :func:`pinned_encoder` also keeps a study's
encoders beside its rows (``studies/02_clfd/encoders``).

Used in: chapter 02_clfd (through :mod:`thesis_lib.chapters.clfd.tasks`).
"""

from __future__ import annotations

import hashlib
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from thesis_lib._io import atomic_write, file_lock
from thesis_lib.book import results_dir
from thesis_lib.book.study import studies_dir
from thesis_lib.chapters.clfd.config import CHAPTER, Config
from thesis_lib.chapters.clfd.data import load_dataset, seen_unseen_cameras
from thesis_lib.clfd.data import MultiViewVideos
from thesis_lib.clfd.train import (
    ENCODER_LABELS,
    METHOD_LABELS,
    CLfD,
    camera_pairs,
    mean_alignment_error,
)
from thesis_lib.sweep import Task, TaskStore, config_hash, run_tasks, task_id

#: Config fields an encoder's training depends on (a task's config holds them).
TRAIN_FIELDS = (
    "seed", "n_demos", "image_size", "epochs", "batch_size", "lr", "temperature", "resnet_width",
    "tcn_width", "eval_every", "seen_cameras", "unseen_cameras", "pouring_dir",
    "pouring_max_frames", "device",
)  # fmt: skip

#: The Table 4.1 numbers of an encoder (:func:`alignment_numbers`).
AE_COLUMNS = ("alignment_error_pct", "val_best_pct", "test_seen_unseen_pct")


def build_model(cfg: Config, encoder: str, method: str, paper_compat: bool = False) -> CLfD:
    """An untrained encoder of backbone ``encoder`` with ``method``'s loss, as ``cfg`` says."""
    width = cfg.resnet_width if encoder == "resnet18" else cfg.tcn_width
    return CLfD(
        encoder=encoder,
        method=method,
        width=width,
        lr=cfg.lr,
        batch_size=cfg.batch_size,
        temperature=cfg.temperature,
        paper_compat=paper_compat,
        seed=cfg.seed,
        device=cfg.device,
    )


def alignment_numbers(
    cfg: Config, data: dict[str, MultiViewVideos], model: CLfD
) -> dict[str, float]:
    """Table 4.1's numbers of ``model`` (:data:`AE_COLUMNS`): the test alignment error on pairs
    of seen cameras, the lowest validation error of its history and the test error between a
    seen and an unseen camera (NaN without unseen cameras)."""
    seen_cams, unseen_cams = seen_unseen_cameras(cfg, data)
    seen = camera_pairs(seen_cams)
    unseen = [(a, b) for a in seen_cams for b in unseen_cams]
    h = model.history
    return {
        "alignment_error_pct": mean_alignment_error(model, data["test"], seen),
        "val_best_pct": float(h["val_alignment_error"].min()) if len(h) else np.nan,
        "test_seen_unseen_pct": mean_alignment_error(model, data["test"], unseen)
        if unseen
        else np.nan,
    }


def encoder_task(
    cfg: Config, encoder: str, method: str, paper_compat: bool = False, dataset: str = "PickPlace"
) -> Task:
    """The task that trains one encoder with one method (:func:`train_encoder_task`)."""
    config = {
        "dataset": dataset,
        "encoder": encoder,
        "method": method,
        "paper_compat": bool(paper_compat),
        "cfg": {f: getattr(cfg, f) for f in TRAIN_FIELDS},
    }
    return Task(train_encoder_task, config)


def model_path(config: dict[str, Any]) -> Path:
    """Where :func:`train_encoder_task` keeps the weights of the encoder of ``config``."""
    return results_dir(CHAPTER) / "models" / f"{config_hash(config)}.pt"


@task_id("thesis_lib.chapters.clfd:train_encoder_task")  # the study's pinned encoders' keys
def train_encoder_task(config: dict[str, Any]) -> list[dict[str, Any]]:
    """Sweep task: train one encoder (keeping the best validation checkpoint), save its weights.

    Returns:
        One row per epoch (``epoch``, ``loss``, ``val_alignment_error``), each with the model's
        Table 4.1 numbers (``alignment_error_pct``, ``val_best_pct``, ``test_seen_unseen_pct``).

    Used in: CLfD chapter (thesis 4.2.2), through :func:`train_encoders`.
    """
    cfg = Config(**config["cfg"])
    data = load_dataset(cfg, config["dataset"])
    model = build_model(cfg, config["encoder"], config["method"], config["paper_compat"])
    model.fit(
        data["train"],
        epochs=cfg.epochs,
        cameras=seen_unseen_cameras(cfg, data)[0],
        val=data["val"],
        eval_every=cfg.eval_every,
        progress=cfg.progress,
    )
    path = model_path(config)
    path.parent.mkdir(parents=True, exist_ok=True)
    model.save(path)
    numbers = alignment_numbers(cfg, data, model)
    return [{**row, **numbers} for row in model.history.to_dict(orient="records")]


def train_encoders(cfg: Config, tasks: list[Task], desc: str) -> pd.DataFrame:
    """Run (or read back) encoder tasks: their rows, with ``dataset``, ``encoder``, ``method``
    (the tables' labels) and ``paper_compat`` columns."""
    unique = list({t.key: t for t in tasks}.values())
    rows = run_tasks(unique, store=results_dir(CHAPTER) / "tasks", desc=desc)
    keys = pd.DataFrame(
        [
            {
                "task_key": t.key,
                "dataset": t.config["dataset"],
                "encoder": ENCODER_LABELS[t.config["encoder"]],
                "method": METHOD_LABELS[t.config["method"]],
                "paper_compat": t.config["paper_compat"],
            }
            for t in unique
        ]
    )
    return rows.merge(keys, on="task_key", how="left")


def trained_encoder(
    cfg: Config,
    encoder: str,
    method: str,
    paper_compat: bool = False,
    executor: str | None = None,
) -> CLfD:
    """The encoder of one task, trained (or read back) through the sweep store."""
    return trained_encoder_rows(cfg, encoder, method, paper_compat, executor)[0]


def trained_encoder_rows(
    cfg: Config,
    encoder: str,
    method: str,
    paper_compat: bool = False,
    executor: str | None = None,
) -> tuple[CLfD, pd.DataFrame]:
    """:func:`trained_encoder` and the rows of its task (:func:`train_encoder_task`)."""
    task = encoder_task(cfg, encoder, method, paper_compat)
    path = model_path(dict(task.config))
    store = results_dir(CHAPTER) / "tasks"
    kw: dict[str, Any] = {"desc": "encoder", "progress": False, "executor": executor}
    rows = run_tasks([task], store=store, **kw)
    if not path.is_file():  # a stored result whose weights were deleted: train again
        rows = run_tasks([task], store=store, force=True, **kw)
    model = build_model(cfg, encoder, method, paper_compat).load(path)
    model.history = rows[["epoch", "loss", "val_alignment_error"]].reset_index(drop=True)
    return model, rows


def chapter_encoder(cfg: Config) -> CLfD:
    """The encoder of Table 4.2 and the embedding figure: CLfD on ``cfg.rl_encoder``'s backbone
    (the first Table 4.1 encoder when that one is not in the grid)."""
    if cfg.rl_encoder in cfg.encoders and "clfd" in cfg.methods:
        return trained_encoder(cfg, cfg.rl_encoder, "clfd", cfg.paper_compat)
    enc, m = cfg.encoders[0], cfg.methods[0]
    return trained_encoder(cfg, enc, m, cfg.paper_compat and m == "clfd")


def file_sha(path: Path) -> str:
    """The first 16 hex digits of the SHA-256 of a file (an encoder's weights)."""
    return hashlib.sha256(path.read_bytes()).hexdigest()[:16]


def pinned_encoder(
    cfg: Config, encoder: str, method: str, folder: str | Path | None = None
) -> tuple[CLfD, pd.DataFrame]:
    """A study encoder that later tasks read: trained once and kept beside the study's rows.

    The stage (C11) and RL (C12) tasks use the encoders the alignment (C10) tasks trained. A
    study runs across sessions, and a later session may run on a new machine whose encoder
    store (``results/02_clfd``) is empty. So the first call trains the encoder through the
    store (:func:`trained_encoder`) and copies its weights and sweep record into ``folder``
    (default ``studies/02_clfd/encoders/``, committed with the rows: about 130 kB per
    TCN-style encoder); every later call, on any machine, puts them back into the store and
    reads them from there instead of training again. Two workers asking for the same encoder
    at once: the second waits for the first (a file lock), then reads its result.

    Returns:
        ``(model, rows)`` as :func:`trained_encoder` and its task's rows.

    Used in: CLfD chapter study, through
    :func:`~thesis_lib.chapters.clfd.tasks.study_alignment_task` and the stage and RL tasks.
    """
    task = encoder_task(cfg, encoder, method)
    pinned = TaskStore(Path(folder) if folder is not None else studies_dir(CHAPTER) / "encoders")
    weights = pinned.root / f"{task.key}.pt"
    store = TaskStore(results_dir(CHAPTER) / "tasks")
    local = model_path(dict(task.config))
    with file_lock(results_dir(CHAPTER) / "models" / f".{task.key}.lock"):
        if pinned.has(task.key) and weights.is_file():
            data = weights.read_bytes()
            if not local.is_file() or local.read_bytes() != data:
                atomic_write(local, lambda tmp: tmp.write_bytes(data))
            store.write(pinned.read(task.key))
        model, rows = trained_encoder_rows(cfg, encoder, method, executor="inprocess")
        if not pinned.has(task.key):
            data = local.read_bytes()
            atomic_write(weights, lambda tmp: tmp.write_bytes(data))
            pinned.write(store.read(task.key))  # last: a record here means its weights are here
    return model, rows
