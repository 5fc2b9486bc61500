"""The CLfD chapter's experiments (thesis 4.2.2): Table 4.1, Table 4.2, Fig 4.4 and the paper_compat check.

Each function takes the chapter config (:class:`Config`, whose fields are the notebook's
parameters) and returns tidy DataFrames; the notebook only narrates and plots.

The encoder x method grid of Table 4.1 (and the paper_compat encoders, and the encoders of
Fig 4.4) runs through :func:`thesis_lib.sweep.run_tasks`: one task per trained encoder
(:func:`train_encoder_task`), its rows stored under ``results/02_clfd/tasks`` and its weights
under ``results/02_clfd/models``, so an interrupted chapter resumes and an encoder needed by
several tables is trained once.

The chapter's pre-registered study (``params/02_clfd.study.yml``, claims C10-C12) is built by
:func:`study_tasks` from the same functions: :func:`study_alignment_task` (Table 4.1),
:func:`study_stage_task` (Table 4.2) and :func:`study_rl_task` (Fig 4.4), one row per run.

Used in: chapter 02_clfd.
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from thesis_lib._io import atomic_write, file_lock, hash_arrays
from thesis_lib.book import compare_with_paper, results_dir
from thesis_lib.book.study import studies_dir
from thesis_lib.clfd.data import MultiViewVideos, make_pick_place_dataset
from thesis_lib.clfd.env import CAMERAS, STAGES, MultiViewPickPlace, run_demonstration
from thesis_lib.clfd.losses import nt_xent
from thesis_lib.clfd.metrics import (
    alignment_error,
    balanced_indices,
    classifier_accuracy,
    pca_2d,
    train_stage_classifier,
)
from thesis_lib.clfd.models import ENCODERS
from thesis_lib.clfd.train import (
    ENCODER_LABELS,
    METHOD_LABELS,
    METHODS,
    CLfD,
    camera_pairs,
    mean_alignment_error,
)
from thesis_lib.sweep import Task, TaskStore, config_hash, run_tasks

CHAPTER = "02_clfd"


@dataclass
class Config:
    """Parameters of notebook 02_clfd (the smoke defaults; ``params/02_clfd.full.yml`` = the thesis's scale)."""

    seed: int = 0
    """Seeds the demonstrations, the networks, pair sampling and the RL agents."""
    n_demos: int = 18
    """Demonstrations rendered (thesis: 150), split train/val/test as 100/25/25 scaled."""
    image_size: int = 48
    """Side of the square frames in pixels."""
    encoders: list[str] = field(default_factory=lambda: ["resnet18", "tcn"])
    """Encoders of Table 4.1: "resnet18", "tcn" (the TCN-style encoder)."""
    methods: list[str] = field(default_factory=lambda: ["tcn", "cmc", "clfd"])
    """Training methods of Table 4.1: "clfd", "tcn" (triplet), "cmc"."""
    epochs: int = 16
    """Training epochs per model (thesis: 1000)."""
    batch_size: int = 32
    """Anchor-positive pairs per batch (thesis text: 32; Table 4.1's caption says 50)."""
    lr: float = 0.001
    """Adam learning rate (authors' code: 3e-4)."""
    temperature: float = 0.5
    """NT-Xent temperature τ (thesis: 0.5)."""
    resnet_width: int = 16
    """ResNet-18 channel width (64 = the real ResNet-18)."""
    tcn_width: int = 16
    """Width of the TCN-style encoder's trunk."""
    eval_every: int = 4
    """Validation alignment error every this many epochs; the best checkpoint is kept (thesis: 25)."""
    seen_cameras: list[str] = field(default_factory=lambda: ["front", "top", "overhead"])
    """Cameras the encoders train on (thesis 4.2.2.2: three "seen" viewpoints)."""
    unseen_cameras: list[str] = field(default_factory=lambda: ["gripper", "right"])
    """Cameras never shown to the encoders ("unseen")."""
    paper_compat: bool = False
    """Train CLfD with the authors' bug (anchor view never in the loss) in Tables 4.1/4.2 and Fig 4.4."""
    compat_encoders: list[str] = field(default_factory=lambda: ["tcn"])
    """Encoders on which CLfD is also trained the other way (bug on/off) to measure the difference."""
    mlp_epochs: int = 300
    """Epochs of the stage-classification MLP (thesis: 500)."""
    rl_encoder: str = "tcn"
    """Backbone of the encoders that give the RL state and reward (thesis Fig 4.4: TCN)."""
    rl_methods: list[str] = field(default_factory=lambda: ["clfd", "cmc", "tcn"])
    """Encoders (by training method) compared in Fig 4.4."""
    rl_episodes: int = 12
    """DDPG training episodes per encoder (thesis: 3000)."""
    rl_steps: int = 20
    """Steps per RL episode (the pick stage of a demonstration takes about 15)."""
    rl_camera: str = "front"
    """Camera whose image the RL agent's encoder sees."""
    rl_her: bool = True
    """Use hindsight experience replay (the thesis text's choice)."""
    pouring_dir: str | None = None
    """Folder with Multi-View Pouring's ``train``/``val``/``test`` sub-folders of ``<seq>_view<k>``
    videos (e.g. ``.../multiview-pouring/videos``); when given, Table 4.1's Pouring rows are run."""
    pouring_max_frames: int = 100
    """Frames kept per Pouring sequence (evenly subsampled)."""
    device: str = "cpu"
    """Torch device for the encoders ("cpu", "cuda" or "auto")."""
    progress: bool = False
    """Show progress bars."""
    seeds: list[int] = field(default_factory=lambda: [0])
    """Seeds of the pre-registered study (``thesis study 02_clfd``); each renders its own data set
    and guiding demonstration and trains its own encoders and agents (the chapter runs ``seed``)."""
    rl_success_m: float = 0.03
    """Study: an RL episode succeeds when it ends with the grasp point this close to the box centre (m)."""
    rl_checkpoints: int = 10
    """Study: the RL success curve cuts the training episodes into this many equal windows."""
    study_controls: bool = True
    """Study: also run an untrained encoder (same backbone) through stage classification and RL."""

    def __post_init__(self) -> None:
        for e in [*self.encoders, *self.compat_encoders, self.rl_encoder]:
            if e not in ENCODERS:
                raise ValueError(f"Unknown encoder {e!r}. Valid: {', '.join(ENCODERS)}.")
        for m in [*self.methods, *self.rl_methods]:
            if m not in METHODS:
                raise ValueError(f"Unknown method {m!r}. Valid: {', '.join(METHODS)}.")
        for c in [*self.seen_cameras, *self.unseen_cameras, self.rl_camera]:
            if c not in CAMERAS:
                raise ValueError(f"Unknown camera {c!r}. Valid: {', '.join(CAMERAS)}.")
        if len(self.seen_cameras) < 2:
            raise ValueError(
                f"seen_cameras needs at least two cameras to pair, got {self.seen_cameras}."
            )
        if set(self.seen_cameras) & set(self.unseen_cameras):
            raise ValueError(
                "A camera cannot be both seen and unseen: "
                f"{sorted(set(self.seen_cameras) & set(self.unseen_cameras))}."
            )
        if not self.seeds or len(set(self.seeds)) != len(self.seeds):
            raise ValueError(f"seeds must be distinct and not empty, got {self.seeds}.")
        if self.rl_success_m <= 0 or self.rl_checkpoints < 1:
            raise ValueError(
                f"Need rl_success_m > 0 and rl_checkpoints >= 1; got {self.rl_success_m}, "
                f"{self.rl_checkpoints}."
            )
        if self.n_demos < 3 or self.epochs < 1 or self.image_size < 16:
            raise ValueError(
                f"Need n_demos >= 3, epochs >= 1, image_size >= 16; got {self.n_demos}, "
                f"{self.epochs}, {self.image_size}."
            )


def load_data(cfg: Config) -> dict[str, MultiViewVideos]:
    """The pick-and-place data set of the config (rendered once, then cached)."""
    return make_pick_place_dataset(cfg.n_demos, cfg.image_size, cfg.seed, progress=cfg.progress)


def load_pouring(cfg: Config) -> dict[str, MultiViewVideos] | None:
    """Multi-View Pouring's splits from ``cfg.pouring_dir`` (None when it is not set)."""
    if not cfg.pouring_dir:
        return None
    from thesis_lib.clfd.data import read_multiview_folder

    root = Path(cfg.pouring_dir).expanduser()
    missing = [s for s in ("train", "val", "test") if not (root / s).is_dir()]
    if missing:
        raise FileNotFoundError(
            f"pouring_dir {root} has no {missing} sub-folder(s); point it at the folder "
            "holding Multi-View Pouring's train/val/test video folders."
        )
    return {
        s: read_multiview_folder(root / s, cfg.image_size, max_frames=cfg.pouring_max_frames)
        for s in ("train", "val", "test")
    }


def build_model(cfg: Config, encoder: str, method: str, paper_compat: bool = False) -> CLfD:
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


def _seen(cfg: Config, data: dict[str, MultiViewVideos]) -> tuple[list[str], list[str]]:
    """Seen and unseen cameras: the config's for the pick-and-place set, every view for other data."""
    if set(cfg.seen_cameras) <= set(data["train"].cameras):
        return cfg.seen_cameras, [c for c in cfg.unseen_cameras if c in data["train"].cameras]
    return list(data["train"].cameras), []


#: Config fields an encoder's training depends on (a task's config holds them).
TRAIN_FIELDS = (
    "seed", "n_demos", "image_size", "epochs", "batch_size", "lr", "temperature", "resnet_width",
    "tcn_width", "eval_every", "seen_cameras", "unseen_cameras", "pouring_dir",
    "pouring_max_frames", "device",
)  # fmt: skip


def load_dataset(cfg: Config, dataset: str = "PickPlace") -> dict[str, MultiViewVideos]:
    """``"PickPlace"`` (:func:`load_data`) or ``"Pouring"`` (:func:`load_pouring`)."""
    if dataset == "PickPlace":
        return load_data(cfg)
    if dataset == "Pouring":
        data = load_pouring(cfg)
        if data is None:
            raise ValueError("The Pouring rows need pouring_dir (Multi-View Pouring's videos).")
        return data
    raise ValueError(f"Unknown dataset {dataset!r}. Valid: PickPlace, Pouring.")


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
        cameras=_seen(cfg, data)[0],
        val=data["val"],
        eval_every=cfg.eval_every,
        progress=cfg.progress,
    )
    path = model_path(config)
    path.parent.mkdir(parents=True, exist_ok=True)
    model.save(path)
    numbers = _ae_row(cfg, data, model)
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
    return _trained_encoder_rows(cfg, encoder, method, paper_compat, executor)[0]


def _trained_encoder_rows(
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


def _table_4_1_tasks(cfg: Config, dataset: str) -> list[Task]:
    return [
        encoder_task(cfg, enc, m, cfg.paper_compat and m == "clfd", dataset)
        for enc in cfg.encoders
        for m in cfg.methods
    ]


def _ae_row(cfg: Config, data: dict[str, MultiViewVideos], model: CLfD) -> dict[str, float]:
    seen_cams, unseen_cams = _seen(cfg, data)
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


AE_COLUMNS = ("alignment_error_pct", "val_best_pct", "test_seen_unseen_pct")


def run_table_4_1(cfg: Config, dataset: str = "PickPlace") -> pd.DataFrame:
    """Train every encoder × method and measure the alignment error (Table 4.1).

    Returns:
        One row per encoder × method (plus an untrained encoder per backbone as a floor), with
        ``alignment_error_pct`` = test-split error on pairs of seen cameras at the best
        validation checkpoint, ``val_best_pct`` = the lowest validation error (how the thesis
        reports), ``test_seen_unseen_pct`` = test error between a seen and an unseen camera.
        ``dataset`` labels the rows ("PickPlace", or "Pouring" for :func:`load_pouring`'s data,
        whose views are all "seen").
    """
    data = load_dataset(cfg, dataset)
    trained = train_encoders(cfg, _table_4_1_tasks(cfg, dataset), desc=f"Table 4.1 ({dataset})")
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
                **_ae_row(cfg, data, untrained),
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
    trained = train_encoders(cfg, _table_4_1_tasks(cfg, dataset), desc=f"Table 4.1 ({dataset})")
    cols = ["epoch", "loss", "val_alignment_error", "dataset", "encoder", "method"]
    return trained[cols].reset_index(drop=True)


def run_dataset_table(cfg: Config) -> pd.DataFrame:
    """Per split: demonstrations, frames per camera, mean length and the share of pick frames."""
    return pd.DataFrame(
        [
            {
                "split": s,
                "demonstrations": len(d),
                "frames per camera": d.n_frames,
                "mean length": np.mean([len(v) for v in d.videos]),
                "pick frames %": 100 * np.mean(np.concatenate(_stages(d)) == 0),
            }
            for s, d in load_data(cfg).items()
        ]
    )


def nt_xent_check(cfg: Config) -> tuple[float, float]:
    """NT-Xent of 4 orthogonal pairs (anchor = positive) and the same value by hand."""
    import torch

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


def compare_table_4_1(table: pd.DataFrame, differs: dict[str, str]) -> pd.DataFrame:
    """Table 4.1 beside the thesis (the Pouring rows are 'not run' unless ``pouring_dir`` was given)."""
    ours = table[table["method"] != "untrained"]
    return compare_with_paper(
        "4.1",
        ours,
        on=["dataset", "encoder", "method"],
        value="alignment_error_pct",
        differs=differs,
    )


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


def _stages(data: MultiViewVideos) -> list[np.ndarray]:
    if data.stages is None:
        raise ValueError("These videos carry no stage labels (pick/place); label them first.")
    return data.stages


def _features(
    model: CLfD, data: MultiViewVideos, cameras: list[str]
) -> tuple[np.ndarray, np.ndarray]:
    idx = data.camera_index(cameras)
    feats, labels = [], []
    for v, s in zip(data.videos, _stages(data)):
        f = model.embed(v[:, idx])  # (T, C, D)
        feats.append(f.reshape(-1, f.shape[-1]))
        labels.append(np.repeat(s, len(idx)))
    return np.concatenate(feats), np.concatenate(labels)


def run_table_4_2(cfg: Config) -> pd.DataFrame:
    """Stage classification from frozen features of :func:`chapter_encoder` (Table 4.2).

    For each viewpoint set (seen, seen + unseen, unseen) an MLP with two layers is trained on the
    features of the training demonstrations' frames from those cameras (classes balanced) and
    tested on the test demonstrations' frames from the same cameras (balanced).
    """
    data, model = load_data(cfg), chapter_encoder(cfg)
    rng = np.random.default_rng(cfg.seed)
    sets = {
        "Seen": cfg.seen_cameras,
        "Seen + Unseen": cfg.seen_cameras + cfg.unseen_cameras,
        "Unseen": cfg.unseen_cameras,
    }
    rows = []
    for name, cams in sets.items():
        if not cams:
            continue
        acc = stage_accuracy(cfg, model, data, cams, cams, rng)
        rows.append({"viewpoints": name, **acc, "cameras": ", ".join(cams)})
    return pd.DataFrame(rows)


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

    Used in: CLfD chapter (Table 4.2) and its study (C11).
    """
    xtr, ytr = _features(model, data["train"], train_cameras)
    xte, yte = _features(model, data["test"], test_cameras)
    itr, ite = balanced_indices(ytr, rng), balanced_indices(yte, rng, per_class=100)
    mlp = train_stage_classifier(xtr[itr], ytr[itr], epochs=cfg.mlp_epochs, seed=cfg.seed)
    return {
        "accuracy_pct": classifier_accuracy(mlp, xte[ite], yte[ite]),
        "train_accuracy_pct": classifier_accuracy(mlp, xtr[itr], ytr[itr]),
        "n_train": len(itr),
        "n_test": len(ite),
    }


def compare_table_4_2(table: pd.DataFrame, differs: dict[str, str]) -> pd.DataFrame:
    """Table 4.2 beside the thesis."""
    return compare_with_paper(
        "4.2", table, on=["viewpoints"], value="accuracy_pct", differs=differs
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


def rl_episodes(cfg: Config, model: CLfD) -> pd.DataFrame:
    """DDPG (+HER) on the pick stage with ``model``'s features and Eq 4.2 reward, as
    ``cfg`` says (Fig 4.4); one row per training episode
    (:func:`thesis_lib.clfd.rl.train_embedding_agent`).

    The guiding demonstration is a fresh one (not in the data set of ``cfg.seed``), as in the
    thesis.

    Used in: CLfD chapter (Fig 4.4) and its study (C12).
    """
    from thesis_lib.clfd.rl import train_embedding_agent

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


# -- figures ---------------------------------------------------------------------------------------
def plot_example_frames(seed: int = 0, image_size: int = 120, n_times: int = 3):
    """Fig 4.3: one demonstration from the five cameras at ``n_times`` instants."""
    import matplotlib.pyplot as plt

    env = MultiViewPickPlace(image_size=image_size)
    demo = run_demonstration(env, seed, render=True)
    env.close()
    if demo.frames is None:
        raise RuntimeError("the demonstration was run without rendering")
    times = np.linspace(0, len(demo.stages) - 1, n_times).round().astype(int)
    fig, axes = plt.subplots(
        n_times, len(CAMERAS), figsize=(2.2 * len(CAMERAS), 2.3 * n_times), squeeze=False
    )
    for r, t in enumerate(times):
        for c, cam in enumerate(CAMERAS):
            ax = axes[r, c]
            ax.imshow(demo.frames[t, c])
            ax.set_xticks([]), ax.set_yticks([])
            if r == 0:
                ax.set_title(cam)
            if c == 0:
                ax.set_ylabel(f"t = {t} ({STAGES[demo.stages[t]]})")
    fig.tight_layout()
    return fig


def plot_training_curves(histories: pd.DataFrame):
    """Training loss and validation alignment error per epoch, one line per encoder × method."""
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(11, 3.6))
    keys = ["dataset", "encoder", "method"] if "dataset" in histories else ["encoder", "method"]
    for key, g in histories.groupby(keys, sort=False):
        m, enc = key[-1], key[-2]
        label = f"{m} / {enc}" + (f" ({key[0]})" if len(key) == 3 and key[0] != "PickPlace" else "")
        axes[0].plot(g["epoch"], g["loss"], label=label)
        v = g.dropna(subset=["val_alignment_error"])
        axes[1].plot(v["epoch"], v["val_alignment_error"], marker="o", label=label)
    axes[0].set(xlabel="epoch", ylabel="training loss (each method its own)", title="loss")
    axes[1].set(
        xlabel="epoch",
        ylabel="alignment error [%]",
        title="validation alignment error (seen pairs)",
    )
    axes[1].axhline(100 / 3, ls=":", color="grey", label="chance (~33%)")
    axes[1].legend(fontsize=7)
    fig.tight_layout()
    return fig


def plot_rl_curves(episodes: pd.DataFrame):
    """Fig 4.4: accumulated Eq 4.2 reward per episode per encoder (dashed: the demonstration's own
    return under that encoder), and the final gripper-box distance."""
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(11, 3.6))
    for i, (enc, g) in enumerate(episodes.groupby("encoder", sort=False)):
        (line,) = axes[0].plot(g["episode"], g["return"], marker=".", label=enc)
        if "expert_return" in g:
            axes[0].axhline(
                g["expert_return"].iloc[0],
                ls="--",
                lw=1,
                color=line.get_color(),
                label=f"{enc}: the demonstration" if i == 0 else None,
            )
        axes[1].plot(g["episode"], g["final_grip_box_distance"], marker=".", label=enc)
    axes[0].set(xlabel="episode", ylabel="accumulated reward (Eq 4.2)", title="Fig 4.4: pick stage")
    axes[1].set(
        xlabel="episode", ylabel="gripper-box distance at the end [m]", title="task progress"
    )
    axes[0].legend()
    fig.tight_layout()
    return fig


def plot_embedding_pca(
    model: CLfD, video: np.ndarray, cameras: tuple[str, ...], cam_names: list[str]
):
    """PCA of one video's features from two cameras, coloured by time (same-time points should meet)."""
    import matplotlib.pyplot as plt

    idx = [cameras.index(c) for c in cam_names]
    feats = [model.embed(video[:, i]) for i in idx]
    pts = pca_2d(feats)
    t = np.arange(len(video))
    fig, ax = plt.subplots(figsize=(5.2, 4.2))
    for p, name, marker in zip(pts, cam_names, ["o", "^", "s"]):
        sc = ax.scatter(
            p[:, 0],
            p[:, 1],
            c=t,
            cmap="viridis",
            marker=marker,
            label=name,
            edgecolors="k",
            linewidths=0.3,
        )
        ax.plot(p[:, 0], p[:, 1], lw=0.5, color="grey")
    fig.colorbar(sc, ax=ax, label="time step")
    ax.set(xlabel="PC 1", ylabel="PC 2")
    ax.legend()
    fig.tight_layout()
    return fig


def run_rl_summary(cfg: Config, episodes: pd.DataFrame) -> pd.DataFrame:
    """Fig 4.4 in numbers: per encoder, the mean over the last quarter of the episodes of the
    return, the final gripper-box distance and the share of episodes that lifted the box."""
    last = episodes.groupby("encoder").tail(max(1, cfg.rl_episodes // 4))
    return (
        last.groupby("encoder", sort=False)
        .agg(
            mean_return=("return", "mean"),
            final_grip_box_distance_m=("final_grip_box_distance", "mean"),
            box_lifted_share=("box_lifted", "mean"),
        )
        .reset_index()
    )


def describe_numbers(t41: pd.DataFrame, compat: pd.DataFrame, t42: pd.DataFrame) -> list[str]:
    """The lines the chapter prints under "Reading the numbers": test alignment error per
    encoder and method, the untrained floor, the paper_compat effect and the stage accuracy."""
    lines = []
    for enc, g in t41[t41["method"] != "untrained"].groupby("encoder"):
        row = g.set_index("method")["alignment_error_pct"].round(2).to_dict()
        lines.append(f"{enc}: test alignment error (%) by method: {row}")
    floor = (
        t41[t41.method == "untrained"]
        .set_index("encoder")["alignment_error_pct"]
        .round(1)
        .to_dict()
    )
    lines.append(f"untrained floor: {floor}")
    bug = compat.set_index(["encoder", "paper_compat"])["alignment_error_pct"].round(1).to_dict()
    lines.append(f"paper_compat (bug) vs fixed: {bug}")
    acc = t42.set_index("viewpoints")["accuracy_pct"].round(1).to_dict()
    lines.append(f"stage accuracy (%): {acc}")
    return lines


# -- the pre-registered study (params/02_clfd.study.yml: claims C10-C12) -------------------------
#: Config fields a study's stage classification depends on besides :data:`TRAIN_FIELDS`.
STAGE_FIELDS = ("rl_encoder", "mlp_epochs")
#: Config fields a study's RL run depends on besides :data:`TRAIN_FIELDS`.
RL_FIELDS = (
    "rl_encoder", "rl_episodes", "rl_steps", "rl_camera", "rl_her", "rl_success_m", "rl_checkpoints",
)  # fmt: skip
#: How the study labels the untrained encoder (the controls of C11 and C12).
UNTRAINED = "untrained"
#: Stage classification protocols of the study (C11): name -> (MLP trained on, tested on).
STAGE_PROTOCOLS = ("Seen", "Unseen", "Seen + Unseen", "Seen->Unseen")
#: C12's final success rate is measured over this last share of the training episodes.
RL_FINAL_SHARE = 0.2


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
    import torch

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
      encoders (and the untrained one).

    Encoders are trained once, through the chapter's encoder store (:func:`trained_encoder`),
    and shared by the three claims: the alignment tasks of ``cfg.rl_encoder``'s backbone come
    first (CLfD first for each seed), so that with two workers the stage and RL tasks find
    their encoders trained.

    Used in: ``thesis study 02_clfd`` (C10-C12).
    """
    seeded = [replace(cfg, seed=s) for s in cfg.seeds]
    backbones = sorted(cfg.encoders, key=lambda e: e != cfg.rl_encoder)
    methods = sorted(cfg.methods, key=lambda m: m != "clfd")  # the stage tasks' encoder first
    tasks = [
        _study_task(study_alignment_task, c, TRAIN_FIELDS, encoder=enc, method=m)
        for enc in backbones
        for c in seeded
        for m in methods
    ]
    kinds = ["clfd"] + ([UNTRAINED] if cfg.study_controls else [])
    tasks += [
        _study_task(study_stage_task, c, TRAIN_FIELDS + STAGE_FIELDS, features=k)
        for c in seeded
        for k in kinds
    ]
    rl = list(cfg.rl_methods) + ([UNTRAINED] if cfg.study_controls and cfg.rl_methods else [])
    fields = TRAIN_FIELDS + RL_FIELDS
    tasks += [_study_task(study_rl_task, c, fields, method=m) for c in seeded for m in rl]
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


def data_fingerprint(data: dict[str, MultiViewVideos]) -> str:
    """A short hash of every frame, camera name and stage label of a data set's splits.

    The study's rows record it: a seed's data set is rendered anew on each machine, and this
    says whether two machines rendered the same frames.
    """
    h = hashlib.sha256()
    for split in sorted(data):
        v = data[split]
        h.update(f"{split}:{','.join(v.cameras)}".encode())
        hash_arrays(h, [*v.videos, *(v.stages or [])])
    return h.hexdigest()[:16]


def _file_sha(path: Path) -> str:
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

    Used in: CLfD chapter study, through :func:`study_alignment_task` and the stage and RL
    tasks.
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
        model, rows = _trained_encoder_rows(cfg, encoder, method, executor="inprocess")
        if not pinned.has(task.key):
            data = local.read_bytes()
            atomic_write(weights, lambda tmp: tmp.write_bytes(data))
            pinned.write(store.read(task.key))  # last: a record here means its weights are here
    return model, rows


def study_alignment_task(config: dict[str, Any]) -> list[dict[str, Any]]:
    """One C10 study task: one encoder x method trained on one seed's data set (Table 4.1).

    Returns one row: ``method`` (CLfD, TCN, CMC), ``setting`` ("PickPlace <encoder>", as Table 4.1),
    ``seed``, ``scale``, ``alignment_error_pct`` (test split, pairs of seen cameras, at the best
    validation checkpoint; lower is better), ``neg_alignment_error`` = -alignment_error_pct
    (the primary metric, higher is better: x - y is how many points lower x's error is),
    ``val_best_pct`` (the lowest validation error, how the thesis reports) and its negation
    ``neg_val_alignment_error`` (the secondary metric), ``test_seen_unseen_pct`` (a seen camera
    against an unseen one) and ``final_loss``. The encoder is trained (or read back) through the
    chapter's encoder store (:func:`trained_encoder`), where the stage and RL tasks of the same
    seed find it.

    Used in: ``thesis study 02_clfd`` (C10).
    """
    cfg = _study_config(config)
    enc, m = config["encoder"], config["method"]
    if enc == cfg.rl_encoder:  # the stage and RL tasks read these: kept with the study
        _, rows = pinned_encoder(cfg, enc, m)
        sha = _file_sha(model_path(dict(encoder_task(cfg, enc, m).config)))
    else:
        _, rows = _trained_encoder_rows(cfg, enc, m, executor="inprocess")
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


def _study_encoder(cfg: Config, kind: str) -> tuple[CLfD, str | None]:
    """The study's encoder on ``cfg.rl_encoder``'s backbone trained with method ``kind``
    (:func:`pinned_encoder`) and the hash of its weights file, or an untrained one
    (``kind == UNTRAINED``, seeded by ``cfg.seed``) and None."""
    if kind == UNTRAINED:
        return build_model(cfg, cfg.rl_encoder, "clfd"), None
    model, _ = pinned_encoder(cfg, cfg.rl_encoder, kind)
    return model, _file_sha(model_path(dict(encoder_task(cfg, cfg.rl_encoder, kind).config)))


def study_stage_task(config: dict[str, Any]) -> list[dict[str, Any]]:
    """One C11 study task: stage classification (Table 4.2) from one seed's CLfD encoder on
    the ``rl_encoder`` backbone (``features: clfd``) or from an untrained one (the control).

    Returns one row per MLP (:data:`STAGE_PROTOCOLS`): ``method`` = the viewpoints ("Seen",
    "Unseen", "Seen + Unseen" as the thesis: the MLP trained and tested on those cameras;
    "Seen->Unseen": trained on the seen cameras, tested on the unseen ones, the stricter test
    of viewpoint invariance), ``setting`` ("stage (<features> <backbone> encoder)"), ``seed``,
    ``scale``, ``stage_accuracy`` (% of 200 balanced test frames, higher is better),
    ``train_accuracy``.

    Used in: ``thesis study 02_clfd`` (C11).
    """
    cfg = _study_config(config)
    kind = config["features"]
    (model, sha), data = _study_encoder(cfg, kind), load_data(cfg)
    data_sha = data_fingerprint(data)
    rng = np.random.default_rng(cfg.seed)
    seen, unseen = cfg.seen_cameras, cfg.unseen_cameras
    cams = {
        "Seen": (seen, seen),
        "Unseen": (unseen, unseen),
        "Seen + Unseen": (seen + unseen, seen + unseen),
        "Seen->Unseen": (seen, unseen),
    }
    label = "CLfD" if kind == "clfd" else UNTRAINED
    rows = []
    for name in STAGE_PROTOCOLS:
        acc = stage_accuracy(cfg, model, data, *cams[name], rng)
        rows.append(
            _study_row(
                config,
                cfg,
                "C11",
                method=name,
                setting=f"stage ({label} {ENCODER_LABELS[cfg.rl_encoder]} encoder)",
                encoder=ENCODER_LABELS[cfg.rl_encoder],
                features=label,
                stage_accuracy=acc["accuracy_pct"],
                train_accuracy=acc["train_accuracy_pct"],
                n_test=acc["n_test"],
                encoder_sha=sha,
                data_sha=data_sha,
            )
        )
    return rows


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


def study_rl_task(config: dict[str, Any]) -> list[dict[str, Any]]:
    """One C12 study task: DDPG+HER on the pick stage with the features and Eq 4.2 reward of
    one seed's encoder (``method``: its training method on the ``rl_encoder`` backbone, or
    ``untrained``), guided by that seed's fresh demonstration (Fig 4.4).

    Returns one row: ``method`` (CLfD, TCN, CMC, untrained), ``setting`` ("RL pick (<backbone>
    encoder)"), ``seed``, ``scale``, ``success_final`` (the share of the last
    :data:`RL_FINAL_SHARE` of the training episodes that end with the grasp point within
    ``rl_success_m`` of the box centre; higher is better), ``success_mean`` (the share over all
    episodes: the area under the learning curve), ``success_best`` (the best window of the
    curve), ``success_ep<k>`` (the curve, :func:`rl_success_curve`), and over the same last episodes ``final_distance_m`` (mean final
    gripper-box distance), ``lifted_final`` (share that lifted the box), ``return_final`` (mean
    Eq 4.2 return) and ``expert_return`` (the guiding demonstration's).

    Used in: ``thesis study 02_clfd`` (C12).
    """
    cfg = _study_config(config)
    m = config["method"]
    model, sha = _study_encoder(cfg, m)
    ep = rl_episodes(cfg, model)
    curve = rl_success_curve(ep, cfg.rl_checkpoints, cfg.rl_success_m)
    last = ep.iloc[-max(1, int(np.ceil(RL_FINAL_SHARE * len(ep)))) :]
    return [
        _study_row(
            config,
            cfg,
            "C12",
            method=METHOD_LABELS.get(m, m),
            setting=f"RL pick ({ENCODER_LABELS[cfg.rl_encoder]} encoder)",
            encoder=ENCODER_LABELS[cfg.rl_encoder],
            episodes=len(ep),
            success_final=float(
                (last["final_grip_box_distance"].to_numpy(dtype=float) < cfg.rl_success_m).mean()
            ),
            success_mean=float((ep["final_grip_box_distance"] < cfg.rl_success_m).mean()),
            success_best=max(curve.values()),
            **curve,
            final_distance_m=float(last["final_grip_box_distance"].mean()),
            lifted_final=float(last["box_lifted"].astype(float).mean()),
            return_final=float(last["return"].mean()),
            expert_return=float(ep["expert_return"].iloc[0]),
            encoder_sha=sha,
        )
    ]


def _mean_ci(values: Any, reps: int = 2000) -> tuple[float, float, float]:
    from thesis_lib.stats import bootstrap_ci

    v = np.asarray(values, dtype=float)
    if len(v) < 2:
        return (float(v.mean()) if len(v) else np.nan), np.nan, np.nan
    return bootstrap_ci(lambda a: float(a.mean()), v[:, None], reps=reps, seed=0)


def study_tables_vs_thesis(
    rows: pd.DataFrame, differs: dict[str, str]
) -> tuple[pd.DataFrame, pd.DataFrame]:
    """The study's rows as Tables 4.1 and 4.2, beside the thesis's numbers.

    Table 4.1: per encoder x method, the mean test alignment error over seeds (``ours``) with
    its 95% bootstrap interval, the number of seeds and the mean of the lowest validation
    error (the thesis's way); the Pouring rows say ``not run``. Table 4.2: per viewpoint set,
    the mean stage accuracy of the CLfD encoder's MLPs, the same way (the ``Seen->Unseen``
    transfer and the untrained encoder have no thesis value).

    Used in: CLfD chapter ("Evidence at study scale").
    """
    cols41 = ["dataset", "encoder", "method", "alignment_error_pct", "ci_low", "ci_high"]
    t41 = pd.DataFrame(columns=[*cols41, "seeds", "val_best_pct"])
    t42 = pd.DataFrame(columns=["viewpoints", "accuracy_pct", "ci_low", "ci_high", "seeds"])
    if "claim" in rows:
        out = []
        c10 = rows[rows["claim"] == "C10"]  # mid-study: maybe no alignment row (nor column) yet
        for (enc, m), g in c10.groupby(["encoder", "method"], sort=False) if len(c10) else []:
            mean, lo, hi = _mean_ci(g["alignment_error_pct"])
            out.append(
                ["PickPlace", enc, m, mean, lo, hi, g["seed"].nunique(), g["val_best_pct"].mean()]
            )
        t41 = pd.DataFrame(out, columns=t41.columns) if out else t41
        c11 = rows[rows["claim"] == "C11"]
        c11 = c11[c11["features"] == "CLfD"] if "features" in c11 else c11.iloc[:0]
        out = []
        for v, g in c11.groupby("method", sort=False):
            mean, lo, hi = _mean_ci(g["stage_accuracy"])
            out.append([v, mean, lo, hi, g["seed"].nunique()])
        t42 = pd.DataFrame(out, columns=t42.columns) if out else t42
    extra41 = ["dataset", "encoder", "method", "ci_low", "ci_high", "seeds", "val_best_pct"]
    cmp41 = compare_table_4_1(t41.assign(method=t41["method"].astype(str)), differs)
    cmp41 = cmp41.merge(t41[extra41], on=["dataset", "encoder", "method"], how="left")
    cmp42 = compare_table_4_2(t42, differs).merge(
        t42[["viewpoints", "ci_low", "ci_high", "seeds"]], on="viewpoints", how="left"
    )
    return cmp41, cmp42


def study_inputs_table(rows: pd.DataFrame) -> pd.DataFrame:
    """Whether the study's tasks saw the same inputs, per seed: ``data_sets`` (distinct
    ``data_sha`` among its rows; each machine renders a seed's data set anew, so more than one
    means two machines rendered different frames) and ``encoder_matches`` ("k/n": of the stage
    and RL rows on a trained encoder, those whose ``encoder_sha`` is the one the seed's
    alignment task trained; :func:`pinned_encoder` keeps them equal). Empty before the study
    ran, and for rows made before the two hashes were recorded.

    Used in: CLfD chapter ("Evidence at study scale").
    """
    cols = ["seed", "data_sets", "encoder_matches"]
    if rows.empty or "encoder_sha" not in rows or "claim" not in rows:
        return pd.DataFrame(columns=cols)
    out = []
    for seed, g in rows.groupby("seed"):
        if "scale" in g:
            g = g[g["scale"] == "study"]
        trained = g[(g["claim"] == "C10") & g["encoder_sha"].notna()]
        sha = dict(zip(trained["method"], trained["encoder_sha"]))
        later = g[g["claim"].isin(["C11", "C12"]) & g["encoder_sha"].notna()]
        label = later["method"].where(later["claim"] == "C12", "CLfD")  # C11: CLfD's features
        match = sum(sha.get(m) == e for m, e in zip(label, later["encoder_sha"]))
        out.append([int(seed), int(g["data_sha"].nunique()), f"{match}/{len(later)}"])
    return pd.DataFrame(out, columns=cols)


def study_rl_curves(rows: pd.DataFrame) -> pd.DataFrame:
    """The C12 success curves: per method and checkpoint episode, the mean share of successful
    training episodes over seeds with its 95% bootstrap interval.

    Used in: CLfD chapter ("Evidence at study scale").
    """
    cols = ["method", "episode", "success", "ci_low", "ci_high", "seeds"]
    if "claim" not in rows:
        return pd.DataFrame(columns=cols)
    c12 = rows[rows["claim"] == "C12"]
    curve = sorted(
        (int(c.removeprefix("success_ep")), c) for c in c12.columns if c.startswith("success_ep")
    )
    out = []
    for m, g in c12.groupby("method", sort=False):
        for episode, col in curve:
            v = g[col].dropna()
            if len(v):
                out.append([m, episode, *_mean_ci(v), g.loc[v.index, "seed"].nunique()])
    return pd.DataFrame(out, columns=cols)


def plot_study_rl_curves(curves: pd.DataFrame):
    """Fig 4.4 at study scale: success rate against training episodes per encoder, the mean
    over seeds with its 95% interval shaded (:func:`study_rl_curves`).

    Used in: CLfD chapter ("Evidence at study scale").
    """
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6.5, 3.6))
    if curves.empty:
        ax.text(0.5, 0.5, "no study rows yet", ha="center", va="center")
        ax.set_axis_off()
        return fig
    for m, g in curves.groupby("method", sort=False):
        (line,) = ax.plot(g["episode"], g["success"], marker="o", label=f"{m} (n={g.seeds.max()})")
        ax.fill_between(g["episode"], g["ci_low"], g["ci_high"], color=line.get_color(), alpha=0.2)
    ax.set(
        xlabel="training episode (end of window)",
        ylabel="share of episodes ending at the box",
        title="pick stage, DDPG+HER (study)",
        ylim=(-0.03, 1.03),
    )
    ax.legend(fontsize=8)
    fig.tight_layout()
    return fig
