"""The CLfD chapter's data: the rendered pick-and-place set, Multi-View Pouring, their cameras.

:func:`load_dataset` gives the splits (``train``, ``val``, ``test``) of the data set a table row
names; :func:`seen_unseen_cameras` the cameras an encoder trains on and those it never sees;
:func:`data_fingerprint` the hash the study's rows record of a seed's frames.

Used in: chapter 02_clfd (through :mod:`thesis_lib.chapters.clfd.tasks`).
"""

from __future__ import annotations

import hashlib
from pathlib import Path

import numpy as np
import pandas as pd

from thesis_lib._io import hash_arrays
from thesis_lib.chapters.clfd.config import Config
from thesis_lib.clfd.data import MultiViewVideos, make_pick_place_dataset, read_multiview_folder


def load_data(cfg: Config) -> dict[str, MultiViewVideos]:
    """The pick-and-place data set of the config (rendered once, then cached)."""
    return make_pick_place_dataset(cfg.n_demos, cfg.image_size, cfg.seed, progress=cfg.progress)


def load_pouring(cfg: Config) -> dict[str, MultiViewVideos] | None:
    """Multi-View Pouring's splits from ``cfg.pouring_dir`` (None when it is not set)."""
    if not cfg.pouring_dir:
        return None
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


def seen_unseen_cameras(
    cfg: Config, data: dict[str, MultiViewVideos]
) -> tuple[list[str], list[str]]:
    """Seen and unseen cameras: the config's for the pick-and-place set, every view for other data."""
    if set(cfg.seen_cameras) <= set(data["train"].cameras):
        return cfg.seen_cameras, [c for c in cfg.unseen_cameras if c in data["train"].cameras]
    return list(data["train"].cameras), []


def stage_labels(data: MultiViewVideos) -> list[np.ndarray]:
    """The per-frame stage labels of every video (0 = pick, 1 = place).

    Raises:
        ValueError: the videos carry no stage labels.
    """
    if data.stages is None:
        raise ValueError("These videos carry no stage labels (pick/place); label them first.")
    return data.stages


def run_dataset_table(cfg: Config) -> pd.DataFrame:
    """Per split: demonstrations, frames per camera, mean length and the share of pick frames."""
    return pd.DataFrame(
        [
            {
                "split": s,
                "demonstrations": len(d),
                "frames per camera": d.n_frames,
                "mean length": np.mean([len(v) for v in d.videos]),
                "pick frames %": 100 * np.mean(np.concatenate(stage_labels(d)) == 0),
            }
            for s, d in load_data(cfg).items()
        ]
    )


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
