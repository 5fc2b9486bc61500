"""The CLfD chapter's experiments (thesis 4.2.2) and its pre-registered study (claims C10-C12).

One function per experiment, run by the notebook's smoke run and by the study alike:

* Table 4.1 (alignment error): the encoder task :func:`~thesis_lib.chapters.clfd.encoders.train_encoder_task`
  of every encoder x method; the notebook's :func:`run_table_4_1` and the study's
  :func:`study_alignment_task` read its rows;
* Table 4.2 (stage classification from frozen features): :func:`classify_stages`, under the
  viewpoint protocols of :func:`stage_protocols`; the notebook's :func:`run_table_4_2` runs the
  thesis's three, the study's :func:`study_stage_task` all four;
* Fig 4.4 (DDPG on the pick stage): :func:`rl_episodes`, per encoder; the notebook's
  :func:`run_fig_4_4` keeps every episode, the study's :func:`study_rl_task` reduces them to
  success rates.

The study's grid is :func:`study_tasks` (``params/02_clfd.study.yml``); its task functions keep
the names their committed rows' keys were made with (``thesis_lib.chapters.clfd:<function>``).

Used in: chapter 02_clfd.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import replace
from typing import Any

import numpy as np
import pandas as pd
import torch

from thesis_lib.chapters.clfd.config import Config
from thesis_lib.chapters.clfd.data import (
    data_fingerprint,
    load_data,
    load_dataset,
    stage_labels,
)
from thesis_lib.chapters.clfd.encoders import (
    AE_COLUMNS,
    TRAIN_FIELDS,
    alignment_numbers,
    build_model,
    chapter_encoder,
    encoder_task,
    file_sha,
    model_path,
    pinned_encoder,
    train_encoders,
    trained_encoder,
    trained_encoder_rows,
)
from thesis_lib.chapters.clfd.tables import rl_final_numbers
from thesis_lib.clfd.data import MultiViewVideos
from thesis_lib.clfd.losses import nt_xent
from thesis_lib.clfd.metrics import (
    alignment_error,
    balanced_indices,
    classifier_accuracy,
    train_stage_classifier,
)
from thesis_lib.clfd.rl import GraspPointOracle, train_embedding_agent
from thesis_lib.clfd.train import ENCODER_LABELS, METHOD_LABELS, CLfD
from thesis_lib.sweep import Task, task_id

# -- the checks of the method's parts ---------------------------------------------------------------


def nt_xent_check(cfg: Config) -> tuple[float, float]:
    """NT-Xent of 4 orthogonal pairs (anchor = positive) and the same value by hand."""
    z = torch.eye(8)[:4]  # 4 pairs, anchor = positive, orthogonal across pairs
    tau = cfg.temperature
    by_hand = -np.log(np.exp(1 / tau) / (np.exp(1 / tau) + 2 * (4 - 1)))
    return float(nt_xent(z, z, tau)), float(by_hand)


def alignment_error_examples() -> dict[str, float]:
    """Alignment error of a random embedding against itself, shifted by 3 frames, and random."""
    e = np.random.default_rng(0).normal(size=(30, 32))
    return {
        "identical": alignment_error(e, e),
        "shifted by 3 frames": round(alignment_error(e, np.roll(e, 3, axis=0)), 1),
        "random": round(alignment_error(e, np.random.default_rng(1).normal(size=(30, 32))), 1),
    }


# -- Table 4.1: alignment error ---------------------------------------------------------------------


def table_4_1_tasks(cfg: Config, dataset: str) -> list[Task]:
    """The encoder tasks of Table 4.1: every encoder x method of ``cfg`` on ``dataset``."""
    return [
        encoder_task(cfg, enc, m, cfg.paper_compat and m == "clfd", dataset)
        for enc in cfg.encoders
        for m in cfg.methods
    ]


def run_table_4_1(cfg: Config, dataset: str = "PickPlace") -> pd.DataFrame:
    """Train every encoder × method and measure the alignment error (Table 4.1).

    Returns:
        One row per encoder × method (plus an untrained encoder per backbone as a floor), with
        ``alignment_error_pct`` = test-split error on pairs of seen cameras at the best
        validation checkpoint, ``val_best_pct`` = the lowest validation error (how the thesis
        reports), ``test_seen_unseen_pct`` = test error between a seen and an unseen camera.
        ``dataset`` labels the rows ("PickPlace", or "Pouring" for
        :func:`~thesis_lib.chapters.clfd.data.load_pouring`'s data, whose views are all "seen").
    """
    data = load_dataset(cfg, dataset)
    trained = train_encoders(cfg, table_4_1_tasks(cfg, dataset), desc=f"Table 4.1 ({dataset})")
    first = trained.groupby("task_key", sort=False).head(1).set_index(["encoder", "method"])
    rows = []
    for enc in cfg.encoders:
        untrained = build_model(cfg, enc, "clfd")
        label = ENCODER_LABELS[enc]
        rows.append(
            {
                "dataset": dataset,
                "encoder": label,
                "method": "untrained",
                **alignment_numbers(cfg, data, untrained),
            }
        )
        for m in cfg.methods:
            r = first.loc[(label, METHOD_LABELS[m])]
            rows.append(
                {
                    "dataset": dataset,
                    "encoder": label,
                    "method": METHOD_LABELS[m],
                    **{c: float(r[c]) for c in AE_COLUMNS},
                }
            )
    return pd.DataFrame(rows)


def run_training_histories(cfg: Config, dataset: str = "PickPlace") -> pd.DataFrame:
    """Loss and validation alignment error per epoch of every Table 4.1 encoder.

    Columns ``epoch, loss, val_alignment_error, dataset, encoder, method``.
    """
    trained = train_encoders(cfg, table_4_1_tasks(cfg, dataset), desc=f"Table 4.1 ({dataset})")
    cols = ["epoch", "loss", "val_alignment_error", "dataset", "encoder", "method"]
    return trained[cols].reset_index(drop=True)


def run_paper_compat(cfg: Config) -> pd.DataFrame:
    """CLfD trained with and without the authors' bug (anchor view never in the loss), same seed.

    Encoders already trained for Table 4.1 are read back from the sweep store.
    """
    tasks = [
        encoder_task(cfg, enc, "clfd", compat)
        for enc in cfg.compat_encoders
        for compat in (False, True)
    ]
    trained = train_encoders(cfg, tasks, desc="paper_compat")
    first = trained.groupby("task_key", sort=False).head(1)
    return first[["encoder", "paper_compat", *AE_COLUMNS]].reset_index(drop=True)


# -- Table 4.2: stage classification ----------------------------------------------------------------

#: The viewpoint sets of Table 4.2, in the thesis's order (the MLP trained and tested on them).
TABLE_4_2_VIEWPOINTS = ("Seen", "Seen + Unseen", "Unseen")
#: Stage classification protocols of the study (C11), in its order (:func:`stage_protocols`).
STAGE_PROTOCOLS = ("Seen", "Unseen", "Seen + Unseen", "Seen->Unseen")


def stage_protocols(cfg: Config) -> dict[str, tuple[list[str], list[str]]]:
    """Every stage classification protocol: name -> (cameras the MLP trains on, cameras it is
    tested on). "Seen", "Unseen" and "Seen + Unseen" train and test on the same cameras (the
    thesis's Table 4.2); "Seen->Unseen" trains on the seen cameras and tests on the unseen ones,
    the stricter test of viewpoint invariance."""
    seen, unseen = list(cfg.seen_cameras), list(cfg.unseen_cameras)
    return {
        "Seen": (seen, seen),
        "Unseen": (unseen, unseen),
        "Seen + Unseen": (seen + unseen, seen + unseen),
        "Seen->Unseen": (seen, unseen),
    }


def stage_features(
    model: CLfD, data: MultiViewVideos, cameras: list[str]
) -> tuple[np.ndarray, np.ndarray]:
    """``model``'s features of every frame of ``data`` from ``cameras`` and their stage labels."""
    idx = data.camera_index(cameras)
    feats, labels = [], []
    for v, s in zip(data.videos, stage_labels(data)):
        f = model.embed(v[:, idx])  # (T, C, D)
        feats.append(f.reshape(-1, f.shape[-1]))
        labels.append(np.repeat(s, len(idx)))
    return np.concatenate(feats), np.concatenate(labels)


def stage_accuracy(
    cfg: Config,
    model: CLfD,
    data: dict[str, MultiViewVideos],
    train_cameras: list[str],
    test_cameras: list[str],
    rng: np.random.Generator,
) -> dict[str, float]:
    """One stage classification (Table 4.2): the MLP trained on balanced frames of the training
    demonstrations from ``train_cameras``, tested on 100 frames per class of the test
    demonstrations from ``test_cameras`` (the thesis: the same cameras for both; other cameras
    test whether what was learnt on one view transfers to another).

    Returns ``accuracy_pct``, ``train_accuracy_pct``, ``n_train``, ``n_test``.

    Used in: CLfD chapter (Table 4.2) and its study (C11), through :func:`classify_stages`.
    """
    xtr, ytr = stage_features(model, data["train"], train_cameras)
    xte, yte = stage_features(model, data["test"], test_cameras)
    itr, ite = balanced_indices(ytr, rng), balanced_indices(yte, rng, per_class=100)
    mlp = train_stage_classifier(xtr[itr], ytr[itr], epochs=cfg.mlp_epochs, seed=cfg.seed)
    return {
        "accuracy_pct": classifier_accuracy(mlp, xte[ite], yte[ite]),
        "train_accuracy_pct": classifier_accuracy(mlp, xtr[itr], ytr[itr]),
        "n_train": len(itr),
        "n_test": len(ite),
    }


def classify_stages(
    cfg: Config,
    model: CLfD,
    data: dict[str, MultiViewVideos],
    protocols: Mapping[str, tuple[list[str], list[str]]],
) -> list[dict[str, Any]]:
    """Table 4.2's experiment: one stage classification (:func:`stage_accuracy`) from
    ``model``'s frozen features per protocol (name -> (train cameras, test cameras), e.g. from
    :func:`stage_protocols`), in order, all drawing their frames from one generator seeded by
    ``cfg.seed``. A protocol without cameras to train or test on is left out.

    Returns one dict per protocol: ``viewpoints`` (its name) and :func:`stage_accuracy`'s numbers.

    Used in: CLfD chapter (Table 4.2, :func:`run_table_4_2`) and its study (C11,
    :func:`study_stage_task`).
    """
    rng = np.random.default_rng(cfg.seed)
    return [
        {"viewpoints": name, **stage_accuracy(cfg, model, data, train, test, rng)}
        for name, (train, test) in protocols.items()
        if train and test
    ]


def run_table_4_2(cfg: Config) -> pd.DataFrame:
    """Stage classification from frozen features of
    :func:`~thesis_lib.chapters.clfd.encoders.chapter_encoder` (Table 4.2).

    For each viewpoint set (seen, seen + unseen, unseen) an MLP with two layers is trained on the
    features of the training demonstrations' frames from those cameras (classes balanced) and
    tested on the test demonstrations' frames from the same cameras (balanced).
    """
    data, model = load_data(cfg), chapter_encoder(cfg)
    protocols = stage_protocols(cfg)
    sets = {v: protocols[v] for v in TABLE_4_2_VIEWPOINTS}
    rows = classify_stages(cfg, model, data, sets)
    return pd.DataFrame([{**r, "cameras": ", ".join(sets[r["viewpoints"]][0])} for r in rows])


# -- Fig 4.4: RL with the encoders' features and reward ---------------------------------------------


def rl_episodes(cfg: Config, model: CLfD) -> pd.DataFrame:
    """DDPG (+HER) on the pick stage with ``model``'s features and Eq 4.2 reward, as
    ``cfg`` says (Fig 4.4); one row per training episode
    (:func:`thesis_lib.clfd.rl.train_embedding_agent`).

    The guiding demonstration is a fresh one (not in the data set of ``cfg.seed``), as in the
    thesis.

    Used in: CLfD chapter (Fig 4.4) and its study (C12).
    """
    demo_seed = cfg.seed * 100_000 + 99_999  # outside the data set's seeds
    return train_embedding_agent(
        model,
        demo_seed,
        episodes=cfg.rl_episodes,
        stage="pick",
        camera=cfg.rl_camera,
        image_size=cfg.image_size,
        max_episode_steps=cfg.rl_steps,
        her=cfg.rl_her,
        seed=cfg.seed,
        progress=cfg.progress,
    )


def run_fig_4_4(cfg: Config) -> pd.DataFrame:
    """DDPG on the pick stage with each encoder's features and Eq 4.2 reward (Fig 4.4); one row per episode.

    The guiding demonstration is a fresh one (not in the data set), as in the thesis.
    """
    out = []
    for m in cfg.rl_methods:
        in_table = cfg.rl_encoder in cfg.encoders and m in cfg.methods
        model = trained_encoder(
            cfg, cfg.rl_encoder, m, in_table and cfg.paper_compat and m == "clfd"
        )
        out.append(rl_episodes(cfg, model).assign(encoder=METHOD_LABELS[m]))
    return pd.concat(out, ignore_index=True)


# -- the pre-registered study (params/02_clfd.study.yml: claims C10-C12) -------------------------
#: Config fields a study's stage classification depends on besides :data:`TRAIN_FIELDS`.
STAGE_FIELDS = ("rl_encoder", "mlp_epochs")
#: Config fields a study's RL run depends on besides :data:`TRAIN_FIELDS`.
RL_FIELDS = (
    "rl_encoder", "rl_episodes", "rl_steps", "rl_camera", "rl_her", "rl_success_m", "rl_checkpoints",
)  # fmt: skip
#: How the study labels the untrained encoder (the controls of C11 and C12).
UNTRAINED = "untrained"
#: How the study labels C12's positive control (:class:`~thesis_lib.clfd.rl.GraspPointOracle`).
ORACLE = "oracle"


#: The columns of the study's rows (:func:`study_alignment_task`, :func:`study_stage_task`,
#: :func:`study_rl_task`); the study engine checks the study file's metrics against them. The
#: RL rows also carry the learning curve ``success_ep<k>`` (:func:`rl_success_curve`), whose
#: names follow ``rl_episodes`` and ``rl_checkpoints`` and are not listed.
STUDY_COLUMNS = [
    "claim", "method", "setting", "encoder", "seed", "scale", "n_demos", "epochs",
    # C10: alignment
    "alignment_error_pct", "neg_alignment_error", "val_best_pct", "neg_val_alignment_error",
    "test_seen_unseen_pct", "final_loss", "encoder_sha", "data_sha",
    # C11: stage classification
    "features", "stage_accuracy", "train_accuracy", "n_test",
    # C12: RL
    "episodes", "success_final", "success_mean", "success_best", "final_distance_m",
    "lifted_final", "return_final", "expert_return",
]  # fmt: skip


def _study_config(config: dict[str, Any]) -> Config:
    torch.set_num_threads(1)  # small models: one core per task
    return Config(**config["cfg"])


def _study_task(fn: Any, cfg: Config, fields: tuple[str, ...], **config: Any) -> Task:
    return Task(fn, {**config, "cfg": {f: getattr(cfg, f) for f in fields}})


def study_tasks(cfg: Config) -> list[Task]:
    """The tasks of the chapter's pre-registered study (``params/02_clfd.study.yml``), for every
    seed of ``cfg.seeds``:

    * C10 (:func:`study_alignment_task`): every encoder x method of Table 4.1;
    * C11 (:func:`study_stage_task`): stage classification from the CLfD encoder on
      ``cfg.rl_encoder``'s backbone (and from an untrained one, with ``study_controls``);
    * C12 (:func:`study_rl_task`): DDPG+HER on the pick stage with each of ``cfg.rl_methods``'
      encoders (and the untrained one; and the grasp-point oracle, with ``rl_oracle``);

    each only where ``cfg.study_claims`` names its claim.

    Encoders are trained once, through the chapter's encoder store
    (:func:`~thesis_lib.chapters.clfd.encoders.trained_encoder`), and shared by the three
    claims: the alignment tasks of ``cfg.rl_encoder``'s backbone come first (CLfD first for each
    seed), so that with two workers the stage and RL tasks find their encoders trained.

    Used in: ``thesis study 02_clfd`` (C10-C12).
    """
    seeded = [replace(cfg, seed=s) for s in cfg.seeds]
    backbones = sorted(cfg.encoders, key=lambda e: e != cfg.rl_encoder)
    methods = sorted(cfg.methods, key=lambda m: m != "clfd")  # the stage tasks' encoder first
    claims = set(cfg.study_claims)
    tasks = [
        _study_task(study_alignment_task, c, TRAIN_FIELDS, encoder=enc, method=m)
        for enc in backbones
        for c in seeded
        for m in methods
        if "C10" in claims
    ]
    tasks += [
        _study_task(study_alignment_control_task, c, TRAIN_FIELDS, encoder=enc)
        for enc in backbones
        for c in seeded
        if "C10" in claims and cfg.alignment_controls
    ]
    kinds = ["clfd"] + ([UNTRAINED] if cfg.study_controls else [])
    tasks += [
        _study_task(study_stage_task, c, TRAIN_FIELDS + STAGE_FIELDS, features=k)
        for c in seeded
        for k in kinds
        if "C11" in claims
    ]
    rl = list(cfg.rl_methods) + ([UNTRAINED] if cfg.study_controls and cfg.rl_methods else [])
    rl += [ORACLE] if cfg.rl_oracle else []
    fields = TRAIN_FIELDS + RL_FIELDS
    tasks += [
        _study_task(study_rl_task, c, fields, method=m)
        for c in seeded
        for m in rl
        if "C12" in claims
    ]
    return tasks


def _study_row(config: dict[str, Any], cfg: Config, claim: str, **row: Any) -> dict[str, Any]:
    return {
        "claim": claim,
        **row,
        "seed": cfg.seed,
        "scale": config.get("scale", "study"),
        "n_demos": cfg.n_demos,
        "epochs": cfg.epochs,
    }


@task_id("thesis_lib.chapters.clfd:study_alignment_task")
def study_alignment_task(config: dict[str, Any]) -> list[dict[str, Any]]:
    """One C10 study task: one encoder x method trained on one seed's data set (Table 4.1).

    Returns one row: ``method`` (CLfD, TCN, CMC), ``setting`` ("PickPlace <encoder>", as Table 4.1),
    ``seed``, ``scale``, ``alignment_error_pct`` (test split, pairs of seen cameras, at the best
    validation checkpoint; lower is better), ``neg_alignment_error`` = -alignment_error_pct
    (the primary metric, higher is better: x - y is how many points lower x's error is),
    ``val_best_pct`` (the lowest validation error, how the thesis reports) and its negation
    ``neg_val_alignment_error`` (the secondary metric), ``test_seen_unseen_pct`` (a seen camera
    against an unseen one) and ``final_loss``: a reduction of the rows of the encoder's task
    (:func:`~thesis_lib.chapters.clfd.encoders.train_encoder_task`, as Table 4.1's), trained
    (or read back) through the chapter's encoder store, where the stage and RL tasks of the
    same seed find it.

    Used in: ``thesis study 02_clfd`` (C10).
    """
    cfg = _study_config(config)
    enc, m = config["encoder"], config["method"]
    if enc == cfg.rl_encoder:  # the stage and RL tasks read these: kept with the study
        _, rows = pinned_encoder(cfg, enc, m)
        sha = file_sha(model_path(dict(encoder_task(cfg, enc, m).config)))
    else:
        _, rows = trained_encoder_rows(cfg, enc, m, executor="inprocess")
        sha = None
    first = rows.iloc[0]
    return [
        _study_row(
            config,
            cfg,
            "C10",
            method=METHOD_LABELS[m],
            setting=f"PickPlace {ENCODER_LABELS[enc]}",
            encoder=ENCODER_LABELS[enc],
            alignment_error_pct=float(first["alignment_error_pct"]),
            neg_alignment_error=-float(first["alignment_error_pct"]),
            val_best_pct=float(first["val_best_pct"]),
            neg_val_alignment_error=-float(first["val_best_pct"]),
            test_seen_unseen_pct=float(first["test_seen_unseen_pct"]),
            final_loss=float(rows["loss"].iloc[-1]),
            encoder_sha=sha,
            data_sha=data_fingerprint(load_data(cfg)),
        )
    ]


@task_id("thesis_lib.chapters.clfd:study_alignment_control_task")
def study_alignment_control_task(config: dict[str, Any]) -> list[dict[str, Any]]:
    """C10's control: the alignment error of an untrained encoder of one backbone on one
    seed's data set, the trivial answer a trained method must beat before its alignment says
    anything (CLAIMS.md, "Control": an untrained encoder).

    Returns one row as :func:`study_alignment_task`'s, with ``method`` ``"untrained"``: the
    test alignment error between seen cameras of the encoder as built (seeded by the seed),
    ``val_best_pct`` NaN (no training, no validation history).

    Used in: ``thesis study 02_clfd:v4`` (C10, ``alignment_controls``).
    """
    cfg = _study_config(config)
    enc = config["encoder"]
    data = load_data(cfg)
    numbers = alignment_numbers(cfg, data, build_model(cfg, enc, "clfd"))
    return [
        _study_row(
            config,
            cfg,
            "C10",
            method=UNTRAINED,
            setting=f"PickPlace {ENCODER_LABELS[enc]}",
            encoder=ENCODER_LABELS[enc],
            alignment_error_pct=float(numbers["alignment_error_pct"]),
            neg_alignment_error=-float(numbers["alignment_error_pct"]),
            val_best_pct=float("nan"),
            neg_val_alignment_error=float("nan"),
            test_seen_unseen_pct=float(numbers["test_seen_unseen_pct"]),
            data_sha=data_fingerprint(data),
        )
    ]


def _study_encoder(cfg: Config, kind: str) -> tuple[Any, str | None]:
    """The study's encoder on ``cfg.rl_encoder``'s backbone trained with method ``kind``
    (:func:`~thesis_lib.chapters.clfd.encoders.pinned_encoder`) and the hash of its weights
    file, or an untrained one (``kind == UNTRAINED``, seeded by ``cfg.seed``) and None, or
    the grasp-point oracle (``kind == ORACLE``, RL only) and None."""
    if kind == ORACLE:
        return GraspPointOracle(), None
    if kind == UNTRAINED:
        return build_model(cfg, cfg.rl_encoder, "clfd"), None
    model, _ = pinned_encoder(cfg, cfg.rl_encoder, kind)
    return model, file_sha(model_path(dict(encoder_task(cfg, cfg.rl_encoder, kind).config)))


@task_id("thesis_lib.chapters.clfd:study_stage_task")
def study_stage_task(config: dict[str, Any]) -> list[dict[str, Any]]:
    """One C11 study task: stage classification (Table 4.2, :func:`classify_stages`) from one
    seed's CLfD encoder on the ``rl_encoder`` backbone (``features: clfd``) or from an untrained
    one (the control).

    Returns one row per MLP (:data:`STAGE_PROTOCOLS`, :func:`stage_protocols`): ``method`` = the
    viewpoints ("Seen", "Unseen", "Seen + Unseen" as the thesis: the MLP trained and tested on
    those cameras; "Seen->Unseen": trained on the seen cameras, tested on the unseen ones, the
    stricter test of viewpoint invariance), ``setting`` ("stage (<features> <backbone>
    encoder)"), ``seed``, ``scale``, ``stage_accuracy`` (% of 200 balanced test frames, higher
    is better), ``train_accuracy``.

    Used in: ``thesis study 02_clfd`` (C11).
    """
    cfg = _study_config(config)
    kind = config["features"]
    (model, sha), data = _study_encoder(cfg, kind), load_data(cfg)
    data_sha = data_fingerprint(data)
    protocols = stage_protocols(cfg)
    results = classify_stages(cfg, model, data, {p: protocols[p] for p in STAGE_PROTOCOLS})
    label = "CLfD" if kind == "clfd" else UNTRAINED
    return [
        _study_row(
            config,
            cfg,
            "C11",
            method=r["viewpoints"],
            setting=f"stage ({label} {ENCODER_LABELS[cfg.rl_encoder]} encoder)",
            encoder=ENCODER_LABELS[cfg.rl_encoder],
            features=label,
            stage_accuracy=r["accuracy_pct"],
            train_accuracy=r["train_accuracy_pct"],
            n_test=r["n_test"],
            encoder_sha=sha,
            data_sha=data_sha,
        )
        for r in results
    ]


def rl_success_curve(
    episodes: pd.DataFrame, checkpoints: int, success_m: float
) -> dict[str, float]:
    """The share of successful training episodes in ``checkpoints`` equal windows of the run.

    An episode succeeds when it ends with the grasp point within ``success_m`` of the box
    centre (``final_grip_box_distance``; the pick stage's goal is the grasp). Returns
    ``success_ep<k>``: the share among the episodes of the window that ends at episode k.

    >>> ep = pd.DataFrame({"final_grip_box_distance": [0.2, 0.1, 0.02, 0.01]})
    >>> rl_success_curve(ep, 2, 0.03)
    {'success_ep2': 0.0, 'success_ep4': 1.0}
    """
    n = len(episodes)
    if n < checkpoints:
        raise ValueError(f"{n} episodes cannot fill {checkpoints} checkpoints.")
    ok = episodes["final_grip_box_distance"].to_numpy(dtype=float) < success_m
    ends = np.linspace(0, n, checkpoints + 1).round().astype(int)
    return {f"success_ep{b}": float(ok[a:b].mean()) for a, b in zip(ends[:-1], ends[1:])}


@task_id("thesis_lib.chapters.clfd:study_rl_task")
def study_rl_task(config: dict[str, Any]) -> list[dict[str, Any]]:
    """One C12 study task: DDPG+HER on the pick stage with the features and Eq 4.2 reward of
    one seed's encoder (``method``: its training method on the ``rl_encoder`` backbone, or
    ``untrained``), guided by that seed's fresh demonstration (Fig 4.4, :func:`rl_episodes`).

    Returns one row, a reduction of the run's episodes: ``method`` (CLfD, TCN, CMC, untrained),
    ``setting`` ("RL pick (<backbone> encoder)"), ``seed``, ``scale``, ``success_final`` (the
    share of the last :data:`RL_FINAL_SHARE` of the training episodes that end with the grasp
    point within ``rl_success_m`` of the box centre; higher is better), ``success_mean`` (the
    share over all episodes: the area under the learning curve), ``success_best`` (the best
    window of the curve), ``success_ep<k>`` (the curve, :func:`rl_success_curve`), and over
    the same last episodes ``final_distance_m`` (mean final gripper-box distance),
    ``lifted_final`` (share that lifted the box), ``return_final`` (mean Eq 4.2 return) and
    ``expert_return`` (the guiding demonstration's).

    Used in: ``thesis study 02_clfd`` (C12).
    """
    cfg = _study_config(config)
    m = config["method"]
    model, sha = _study_encoder(cfg, m)
    ep = rl_episodes(cfg, model)
    curve = rl_success_curve(ep, cfg.rl_checkpoints, cfg.rl_success_m)
    final = rl_final_numbers(ep, cfg.rl_success_m)
    return [
        _study_row(
            config,
            cfg,
            "C12",
            method=METHOD_LABELS.get(m, m),
            setting=f"RL pick ({ENCODER_LABELS[cfg.rl_encoder]} encoder)",
            encoder=ENCODER_LABELS[cfg.rl_encoder],
            episodes=len(ep),
            success_final=final["success_final"],
            success_mean=float((ep["final_grip_box_distance"] < cfg.rl_success_m).mean()),
            success_best=max(curve.values()),
            **curve,
            final_distance_m=final["final_distance_m"],
            lifted_final=final["lifted_final"],
            return_final=final["return_final"],
            expert_return=float(ep["expert_return"].iloc[0]),
            encoder_sha=sha,
        )
    ]
