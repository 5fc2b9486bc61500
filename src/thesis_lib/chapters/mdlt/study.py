"""The MDLT chapter's pre-registered study (claim C13, ``params/06_mdlt.study.yml``): its grid
(:func:`study_tasks`) and its task (:func:`study_run`), whose rows are a reduction of the
chapter's fold task's rows (:func:`~thesis_lib.chapters.mdlt.tasks.fold_task`, the task every
table of the chapter runs; :func:`study_songs`) per method and genre.

Used in: ``thesis study 06_mdlt`` (C13); MDLT chapter ("Evidence at study scale").
"""

from __future__ import annotations

from typing import Any

import pandas as pd
import torch

from thesis_lib.sweep import Task, task_id

from . import data
from .config import (
    ALL_SCOPE,
    PER_GENRE,
    TRAIN_FIELDS,
    VARIANT_LABELS,
    Config,
    probe_config,
)
from .data import genre_label
from .tasks import fold_task

METHOD_INDEX = {"transformer": 0, "mamba": 1, "mamba_audio": 2}
"""A variant's place in the seed offset of its fold (``1000 * fold + index``)."""
PROBE_LABEL = "MDLT-M probe"
"""The probe (:func:`~thesis_lib.chapters.mdlt.config.probe_config`: audio-only MDLT-M,
tempogram muted, batch 64) in the study."""
TF_SUFFIX = "TF"
"""Label suffix of the study's plain teacher-forcing runs (``study_teacher_forcing``)."""

#: The columns of a study run's rows (:func:`study_run`; ``aje_windowed`` and ``mismatch_cost``
#: in MDLT-M's rows only); the study engine checks the study file's metrics against them.
STUDY_COLUMNS = [
    "method", "setting", "seed", "scope", "scale", "folds", "songs", "aje", "neg_aje",
    "aje_mean_pose", "gain_vs_mean_pose", "fid", "beat_align", "train_s", "data_sha",
    "aje_windowed", "mismatch_cost",
]  # fmt: skip


def study_label(label: str, scope: str) -> str:
    """A method's name in the study's rows: ``label`` per genre, ``"label (all genres)"`` else.

    >>> study_label("MDLT-M", "all genres"), study_label("mean pose", "per genre")
    ('MDLT-M (all genres)', 'mean pose')
    """
    return label if scope == PER_GENRE else f"{label} ({ALL_SCOPE})"


def neg_aje(aje_rad: float) -> float:
    """The study's higher-is-better metric: minus the AJE (rad); 0 is a perfect translation.

    >>> neg_aje(0.25)
    -0.25
    """
    return -float(aje_rad)


def gain_vs_mean_pose(aje_rad: float, aje_mean_pose: float) -> float:
    """``1 - AJE / AJE(mean training pose)`` on the same songs: 0 = no better than standing in
    the mean pose, 1 = perfect, < 0 = worse (higher is better).

    >>> gain_vs_mean_pose(0.3, 0.5)
    0.4
    """
    return float(1.0 - aje_rad / aje_mean_pose) if aje_mean_pose > 0 else float("nan")


def study_songs(method: str, config: dict[str, Any], genre: str | None, fold: int) -> pd.DataFrame:
    """Per validation song of one fold: the chapter's fold task
    (:func:`~thesis_lib.chapters.mdlt.tasks.fold_task`, as every table of the chapter runs it)
    for ``method`` (a variant, trained with ``windowed=True``, or ``"mean_pose"`` /
    ``"genre_mean"`` of the baselines, ``train_s`` 0), with the song's ``genre`` and the mean
    training pose's AJE on it (``aje_mean_pose``). ``config``: the study task's ``data`` and
    ``cfg`` (its :data:`TRAIN_FIELDS`, the run's seed in it)."""
    task = {
        "data": config["data"],
        "experiment": "study",
        "genre": genre,
        "fold": fold,
        "checkpoint_dir": None,
        "cfg": config["cfg"],
        "keep": False,  # no checkpoint or predictions file per study fold
    }
    base = fold_task({**task, "method": "baselines", "seed_offset": 0})
    if method in ("mean_pose", "genre_mean"):
        rows = base[base["method"] == VARIANT_LABELS[method]].assign(train_s=0.0)
    else:
        offset = 1000 * fold + METHOD_INDEX[method]
        rows = fold_task({**task, "method": method, "seed_offset": offset, "windowed": True})
    mean_pose = base[base["method"] == VARIANT_LABELS["mean_pose"]]
    rows = rows.drop(columns=["experiment", "fold"]).rename(columns={"song_genre": "genre"})
    return rows.reset_index(drop=True).assign(aje_mean_pose=mean_pose["aje"].to_numpy())


@task_id("thesis_lib.chapters.mdlt:study_run")  # the v1 study's name (the chapter as one module)
def study_run(config: dict[str, Any]) -> list[dict[str, Any]]:
    """One C13 study task: one method, one scope (and genre), one seed, over every fold.

    Config keys: ``data`` (as :func:`~thesis_lib.chapters.mdlt.tasks.fold_task`'s), ``scope``
    (:data:`PER_GENRE` or :data:`ALL_SCOPE`), ``genre`` (the genre of a per-genre task;
    ``None`` for all genres), ``method`` (a variant, ``"probe"``, or ``"baselines"``: the mean
    pose and, for all genres, the genre-mean pose), ``folds`` (fold indices), ``seed``, ``cfg`` (the
    :data:`TRAIN_FIELDS` of the chapter's :class:`Config`; ``seed`` is overridden),
    ``scale`` (``study`` or ``check``) and, for the plain teacher-forcing runs, ``recipe``
    (``"teacher forcing"``: the method's label gains :data:`TF_SUFFIX`).

    Each fold trains the method on the fold's training pieces (held-out music: the fold's
    validation pieces are never trained on) and translates every validation piece from its
    first frame to its last, by the task every fold of the chapter's tables runs
    (:func:`~thesis_lib.chapters.mdlt.tasks.fold_task`); the per-song rows
    (:func:`study_songs`) are averaged per genre of the song over all folds (every song weighs
    the same).

    Returns:
        One row per method and genre (a per-genre task: one; all genres: one per genre):
        ``method`` (:func:`study_label`), ``setting`` (the genre), ``seed``, ``scope``,
        ``scale``, ``folds``, ``songs``, ``aje`` (rad, lower is better), ``neg_aje``
        (:func:`neg_aje`, the primary, higher-is-better metric), ``aje_mean_pose`` (the mean
        training pose on the same songs), ``gain_vs_mean_pose`` (:func:`gain_vs_mean_pose`,
        secondary, higher is better), ``fid``, ``beat_align``, ``train_s``, and for MDLT-M
        ``aje_windowed`` and ``mismatch_cost`` (``aje - aje_windowed``: what the whole-song
        recurrence costs against restarting every ``K_mamba`` frames; > 0 = it costs), and
        ``data_sha`` (:func:`~thesis_lib.chapters.mdlt.data.data_sha`: which numbers the data
        set held on this machine).

    Used in: ``thesis study 06_mdlt`` (C13).
    """
    torch.set_num_threads(1)  # small models: one core per run
    seed = int(config["seed"])
    cfg = Config(**{**config["cfg"], "seed": seed})
    run = {"data": config["data"], "cfg": {f: getattr(cfg, f) for f in TRAIN_FIELDS}}
    method, scope = config["method"], config["scope"]
    if method == "probe":  # the task's cfg is already probe_config's
        variants, labels = ["mamba_audio"], [PROBE_LABEL]
    elif config.get("recipe") == "teacher forcing":  # the task's cfg has pose_noise 0
        variants, labels = [method], [f"{VARIANT_LABELS[method]} {TF_SUFFIX}"]
    elif method == "baselines":
        variants = ["mean_pose"] + (["genre_mean"] if scope == ALL_SCOPE else [])
        labels = [VARIANT_LABELS["mean_pose"], "genre mean"][: len(variants)]
    else:
        variants, labels = [method], [VARIANT_LABELS[method]]
    genre = config["genre"] if scope == PER_GENRE else None
    d = config["data"]
    data_sha = data.data_sha(d["layout"], d["root"], d["size"], d["seed"], d.get("fps"))
    out: list[dict[str, Any]] = []
    for variant, label in zip(variants, labels):
        songs = pd.concat(
            [study_songs(variant, run, genre, int(fold)) for fold in config["folds"]],
            ignore_index=True,
        )
        for g, grp in songs.groupby("genre", sort=True):
            a, mp = float(grp["aje"].mean()), float(grp["aje_mean_pose"].mean())
            row = {
                "method": study_label(label, scope),
                "setting": str(g),
                "seed": seed,
                "scope": scope,
                "scale": config.get("scale", "study"),
                "folds": len(config["folds"]),
                "songs": len(grp),
                "aje": a,
                "neg_aje": neg_aje(a),
                "aje_mean_pose": mp,
                "gain_vs_mean_pose": gain_vs_mean_pose(a, mp),
                "fid": float(grp["fid"].mean()),
                "beat_align": float(grp["beat_align"].mean()),
                "train_s": float(grp["train_s"].drop_duplicates().sum()),
                "data_sha": data_sha,
            }
            if "aje_windowed" in grp and grp["aje_windowed"].notna().all():
                w = float(grp["aje_windowed"].mean())
                row.update(aje_windowed=w, mismatch_cost=a - w)
            out.append(row)
    return out


def study_tasks(cfg: Config) -> list[Task]:
    """The tasks of the chapter's pre-registered study (``params/06_mdlt.study.yml``, C13):
    per genre (each of ``cfg.genres``, all when ``None``) and, with ``cfg.all_genres``, all
    genres; each of ``cfg.variants`` and the baselines (and, with ``cfg.study_probe``, the
    probe on all genres; with ``cfg.study_teacher_forcing``, each variant trained with plain
    teacher forcing on all genres), each of ``cfg.study_seeds``, every one of the first ``cfg.n_folds``
    folds inside one task (:func:`study_run`).

    Used in: ``thesis study 06_mdlt`` (C13).
    """
    spec = {"layout": "aist", "root": cfg.aist_root, "size": cfg.data_size, "seed": cfg.data_seed}
    if cfg.genres is None:
        seqs = data.cached_sequences("aist", *data.data_args(cfg))
        present = sorted({genre_label(s.genre) for s in seqs})
    else:
        present = [genre_label(g) for g in cfg.genres]
    train = {f: getattr(cfg, f) for f in TRAIN_FIELDS}
    probe = {f: getattr(probe_config(cfg), f) for f in TRAIN_FIELDS}
    folds = list(range(cfg.n_folds))
    scopes: list[tuple[str, str | None]] = [(PER_GENRE, g) for g in present]
    if cfg.all_genres:
        scopes.append((ALL_SCOPE, None))
    tasks = []
    for seed in cfg.study_seeds:
        for scope, genre in scopes:
            base = {"data": spec, "scope": scope, "genre": genre, "folds": folds, "seed": int(seed)}
            methods = ["baselines", *cfg.variants]
            if cfg.study_probe and scope == ALL_SCOPE:
                methods.append("probe")
            for m in methods:
                run = {**base, "method": m, "cfg": probe if m == "probe" else train}
                tasks.append(Task(study_run, run))
            if cfg.study_teacher_forcing and scope == ALL_SCOPE:
                tf = {"cfg": {**train, "pose_noise": 0.0}, "recipe": "teacher forcing"}
                for m in cfg.variants:
                    tasks.append(Task(study_run, {**base, "method": m, **tf}))
    return tasks
