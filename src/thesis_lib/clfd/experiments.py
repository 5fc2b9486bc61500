"""The CLfD chapter's experiments (thesis 4.2.2): Table 4.1, Table 4.2, Fig 4.4 and the paper_compat check.

Each function takes the chapter config (:class:`ClfdChapterConfig`, whose fields are the
notebook's parameters) and returns tidy DataFrames; the notebook only narrates and plots.

Used in: chapter 02_clfd.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
import pandas as pd

from thesis_lib.book import compare_with_paper
from thesis_lib.clfd.data import MultiViewVideos, make_pick_place_dataset
from thesis_lib.clfd.env import CAMERAS, STAGES, MultiViewPickPlace, run_demonstration
from thesis_lib.clfd.metrics import (
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
    _pairs_of,
    mean_alignment_error,
)


@dataclass
class ClfdChapterConfig:
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


def load_data(cfg: ClfdChapterConfig) -> dict[str, MultiViewVideos]:
    """The pick-and-place data set of the config (rendered once, then cached)."""
    return make_pick_place_dataset(cfg.n_demos, cfg.image_size, cfg.seed, progress=cfg.progress)


def load_pouring(cfg: ClfdChapterConfig) -> dict[str, MultiViewVideos] | None:
    """Multi-View Pouring's splits from ``cfg.pouring_dir`` (None when it is not set)."""
    if not cfg.pouring_dir:
        return None
    from pathlib import Path

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


def build_model(
    cfg: ClfdChapterConfig, encoder: str, method: str, paper_compat: bool = False
) -> CLfD:
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


def _seen(cfg: ClfdChapterConfig, data: dict[str, MultiViewVideos]) -> tuple[list[str], list[str]]:
    """Seen and unseen cameras: the config's for the pick-and-place set, every view for other data."""
    if set(cfg.seen_cameras) <= set(data["train"].cameras):
        return cfg.seen_cameras, [c for c in cfg.unseen_cameras if c in data["train"].cameras]
    return list(data["train"].cameras), []


def train_model(
    cfg: ClfdChapterConfig,
    data: dict[str, MultiViewVideos],
    encoder: str,
    method: str,
    paper_compat: bool = False,
) -> CLfD:
    """Train one encoder on the seen cameras of the training split, keeping the best validation checkpoint."""
    model = build_model(cfg, encoder, method, paper_compat)
    model.fit(
        data["train"],
        epochs=cfg.epochs,
        cameras=_seen(cfg, data)[0],
        val=data["val"],
        eval_every=cfg.eval_every,
        progress=cfg.progress,
    )
    return model


def _ae_row(
    cfg: ClfdChapterConfig, data: dict[str, MultiViewVideos], model: CLfD
) -> dict[str, float]:
    seen_cams, unseen_cams = _seen(cfg, data)
    seen = _pairs_of(seen_cams)
    unseen = [(a, b) for a in seen_cams for b in unseen_cams]
    h = model.history
    return {
        "alignment_error_pct": mean_alignment_error(model, data["test"], seen),
        "val_best_pct": float(h["val_alignment_error"].min()) if len(h) else np.nan,
        "test_seen_unseen_pct": mean_alignment_error(model, data["test"], unseen)
        if unseen
        else np.nan,
    }


def run_table_4_1(
    cfg: ClfdChapterConfig, data: dict[str, MultiViewVideos], dataset: str = "PickPlace"
) -> tuple[pd.DataFrame, dict, pd.DataFrame]:
    """Train every encoder × method and measure the alignment error (Table 4.1).

    Returns:
        ``(table, models, histories)``: one table row per encoder × method (plus an untrained
        encoder per backbone as a floor), with ``alignment_error_pct`` = test-split error on
        pairs of seen cameras at the best validation checkpoint, ``val_best_pct`` = the lowest
        validation error (how the thesis reports), ``test_seen_unseen_pct`` = test error between
        a seen and an unseen camera; ``models[(encoder, method)]``; training histories.
        ``dataset`` labels the rows ("PickPlace", or "Pouring" for :func:`load_pouring`'s data,
        whose views are all "seen").
    """
    rows, models, hist = [], {}, []
    for enc in cfg.encoders:
        untrained = build_model(cfg, enc, "clfd")
        rows.append(
            {
                "dataset": dataset,
                "encoder": ENCODER_LABELS[enc],
                "method": "untrained",
                **_ae_row(cfg, data, untrained),
            }
        )
        for m in cfg.methods:
            compat = cfg.paper_compat and m == "clfd"
            model = train_model(cfg, data, enc, m, compat)
            models[(enc, m)] = model
            rows.append(
                {
                    "dataset": dataset,
                    "encoder": ENCODER_LABELS[enc],
                    "method": METHOD_LABELS[m],
                    **_ae_row(cfg, data, model),
                }
            )
            hist.append(
                model.history.assign(
                    dataset=dataset, encoder=ENCODER_LABELS[enc], method=METHOD_LABELS[m]
                )
            )
    return (
        pd.DataFrame(rows),
        models,
        pd.concat(hist, ignore_index=True) if hist else pd.DataFrame(),
    )


def thesis_table_4_1(table: pd.DataFrame, differs: dict[str, str]) -> pd.DataFrame:
    """Table 4.1 beside the thesis (the Pouring rows are 'not run' unless ``pouring_dir`` was given)."""
    ours = table[table["method"] != "untrained"]
    return compare_with_paper(
        "4.1",
        ours,
        on=["dataset", "encoder", "method"],
        value="alignment_error_pct",
        differs=differs,
    )


def run_paper_compat(
    cfg: ClfdChapterConfig, data: dict[str, MultiViewVideos], models: dict
) -> pd.DataFrame:
    """CLfD trained with and without the authors' bug (anchor view never in the loss), same seed.

    Models already trained for Table 4.1 are reused.
    """
    rows = []
    for enc in cfg.compat_encoders:
        for compat in (False, True):
            model = models.get((enc, "clfd")) if compat == cfg.paper_compat else None
            model = model or train_model(cfg, data, enc, "clfd", compat)
            rows.append(
                {
                    "encoder": ENCODER_LABELS[enc],
                    "paper_compat": compat,
                    **_ae_row(cfg, data, model),
                }
            )
    return pd.DataFrame(rows)


def _features(
    model: CLfD, data: MultiViewVideos, cameras: list[str]
) -> tuple[np.ndarray, np.ndarray]:
    idx = data.camera_index(cameras)
    feats, labels = [], []
    for v, s in zip(data.videos, data.stages):
        f = model.embed(v[:, idx])  # (T, C, D)
        feats.append(f.reshape(-1, f.shape[-1]))
        labels.append(np.repeat(s, len(idx)))
    return np.concatenate(feats), np.concatenate(labels)


def run_table_4_2(
    cfg: ClfdChapterConfig, data: dict[str, MultiViewVideos], model: CLfD
) -> pd.DataFrame:
    """Stage classification from frozen features (Table 4.2).

    For each viewpoint set (seen, seen + unseen, unseen) an MLP with two layers is trained on the
    features of the training demonstrations' frames from those cameras (classes balanced) and
    tested on the test demonstrations' frames from the same cameras (balanced).
    """
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


def thesis_table_4_2(table: pd.DataFrame, differs: dict[str, str]) -> pd.DataFrame:
    return compare_with_paper(
        "4.2", table, on=["viewpoints"], value="accuracy_pct", differs=differs
    )


def run_fig_4_4(
    cfg: ClfdChapterConfig, data: dict[str, MultiViewVideos], models: dict
) -> pd.DataFrame:
    """DDPG on the pick stage with each encoder's features and Eq 4.2 reward (Fig 4.4); one row per episode.

    The guiding demonstration is a fresh one (not in the data set), as in the thesis.
    """
    from thesis_lib.clfd.rl import train_embedding_agent

    demo_seed = cfg.seed * 100_000 + 99_999  # outside the data set's seeds
    out = []
    for m in cfg.rl_methods:
        model = models.get((cfg.rl_encoder, m)) or train_model(cfg, data, cfg.rl_encoder, m)
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


def summary_numbers(t41: pd.DataFrame) -> dict[str, Any]:
    """Small facts the chapter prints: best method per encoder, CLfD vs baselines."""
    out = {}
    for enc, g in t41[t41["method"] != "untrained"].groupby("encoder"):
        out[enc] = g.set_index("method")["alignment_error_pct"].round(2).to_dict()
    return out
