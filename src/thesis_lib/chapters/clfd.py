"""The CLfD chapter's experiments (thesis 4.2.2): Table 4.1, Table 4.2, Fig 4.4 and the paper_compat check.

Each function takes the chapter config (:class:`Config`, whose fields are the notebook's
parameters) and returns tidy DataFrames; the notebook only narrates and plots.

The encoder x method grid of Table 4.1 (and the paper_compat encoders, and the encoders of
Fig 4.4) runs through :func:`thesis_lib.sweep.run_tasks`: one task per trained encoder
(:func:`train_encoder_task`), its rows stored under ``results/02_clfd/tasks`` and its weights
under ``results/02_clfd/models``, so an interrupted chapter resumes and an encoder needed by
several tables is trained once.

Used in: chapter 02_clfd.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from thesis_lib.book import compare_with_paper, results_dir
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
from thesis_lib.sweep import Task, config_hash, run_tasks

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


def trained_encoder(cfg: Config, encoder: str, method: str, paper_compat: bool = False) -> CLfD:
    """The encoder of one task, trained (or read back) through the sweep store."""
    task = encoder_task(cfg, encoder, method, paper_compat)
    path = model_path(dict(task.config))
    store = results_dir(CHAPTER) / "tasks"
    rows = run_tasks([task], store=store, desc="encoder", progress=False)
    if not path.is_file():  # a stored result whose weights were deleted: train again
        rows = run_tasks([task], store=store, desc="encoder", force=True, progress=False)
    model = build_model(cfg, encoder, method, paper_compat).load(path)
    model.history = rows[["epoch", "loss", "val_alignment_error"]].reset_index(drop=True)
    return model


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
        xtr, ytr = _features(model, data["train"], cams)
        xte, yte = _features(model, data["test"], cams)
        itr, ite = balanced_indices(ytr, rng), balanced_indices(yte, rng, per_class=100)
        mlp = train_stage_classifier(xtr[itr], ytr[itr], epochs=cfg.mlp_epochs, seed=cfg.seed)
        rows.append(
            {
                "viewpoints": name,
                "accuracy_pct": classifier_accuracy(mlp, xte[ite], yte[ite]),
                "train_accuracy_pct": classifier_accuracy(mlp, xtr[itr], ytr[itr]),
                "n_train": len(itr),
                "n_test": len(ite),
                "cameras": ", ".join(cams),
            }
        )
    return pd.DataFrame(rows)


def compare_table_4_2(table: pd.DataFrame, differs: dict[str, str]) -> pd.DataFrame:
    """Table 4.2 beside the thesis."""
    return compare_with_paper(
        "4.2", table, on=["viewpoints"], value="accuracy_pct", differs=differs
    )


def run_fig_4_4(cfg: Config) -> pd.DataFrame:
    """DDPG on the pick stage with each encoder's features and Eq 4.2 reward (Fig 4.4); one row per episode.

    The guiding demonstration is a fresh one (not in the data set), as in the thesis.
    """
    from thesis_lib.clfd.rl import train_embedding_agent

    demo_seed = cfg.seed * 100_000 + 99_999  # outside the data set's seeds
    out = []
    for m in cfg.rl_methods:
        in_table = cfg.rl_encoder in cfg.encoders and m in cfg.methods
        model = trained_encoder(
            cfg, cfg.rl_encoder, m, in_table and cfg.paper_compat and m == "clfd"
        )
        ep = train_embedding_agent(
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
        out.append(ep.assign(encoder=METHOD_LABELS[m]))
    return pd.concat(out, ignore_index=True)


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
