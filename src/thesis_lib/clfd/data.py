"""Multi-view demonstration data: the pick-and-place set made here, and a reader for your own videos.

:class:`MultiViewVideos` holds synchronised multi-view videos, one uint8 array (T, V, H, W, 3)
per demonstration (V cameras, the same T for every camera), with optional per-frame stage
labels and robot state. :func:`make_pick_place_dataset` renders the thesis's data set (4.2.1.1:
150 scripted demonstrations split 100/25/25, five cameras, joint angles and velocities, gripper
state) from :class:`~thesis_lib.clfd.env.MultiViewPickPlace`, and caches it on disk.
:func:`read_multiview_folder` reads the Multi-View Pouring layout (TCN's synchronised video pairs,
``<sequence>_view<k>.<ext>``) or folders of frame arrays, for users who have them.

Used in: CLfD (thesis 4.2), chapter 02_clfd.
"""

from __future__ import annotations

import json
import os
import re
import shutil
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from tqdm.auto import tqdm

from thesis_lib.clfd.env import CAMERAS, Demonstration, MultiViewPickPlace, run_demonstration
from thesis_lib.paths import data_dir

FORMAT_VERSION = 2


@dataclass
class MultiViewVideos:
    """Synchronised multi-view videos.

    Attributes:
        videos: one uint8 array (T_i, V, H, W, 3) per video; frame t of every camera shows the
            same instant.
        cameras: the V camera names, in the order of axis 1.
        names: one name per video.
        stages: optional per-frame int labels (0 = pick, 1 = place), one (T_i,) array per video.
        extras: optional per-frame arrays by name (e.g. ``joint_angles``), one list per name.

    Used in: CLfD (thesis 4.2), chapter 02_clfd.
    """

    videos: list[np.ndarray]
    cameras: tuple[str, ...]
    names: list[str] = field(default_factory=list)
    stages: list[np.ndarray] | None = None
    extras: dict[str, list[np.ndarray]] = field(default_factory=dict)

    def __post_init__(self) -> None:
        self.cameras = tuple(self.cameras)
        if not self.names:
            self.names = [f"video_{i:03d}" for i in range(len(self.videos))]
        if len(self.names) != len(self.videos):
            raise ValueError(f"{len(self.names)} names for {len(self.videos)} videos.")
        for name, v in zip(self.names, self.videos):
            if v.ndim != 5 or v.shape[-1] != 3 or v.shape[1] != len(self.cameras):
                raise ValueError(
                    f"Video {name!r} has shape {v.shape}; expected (T, {len(self.cameras)}, H, W, 3) "
                    f"for cameras {self.cameras}."
                )
            if v.dtype != np.uint8:
                raise ValueError(
                    f"Video {name!r} has dtype {v.dtype}; expected uint8 frames (0-255)."
                )
        if self.stages is not None:
            for name, v, s in zip(self.names, self.videos, self.stages):
                if len(s) != len(v):
                    raise ValueError(f"Video {name!r}: {len(s)} stage labels for {len(v)} frames.")

    def __len__(self) -> int:
        return len(self.videos)

    @property
    def image_size(self) -> int:
        return int(self.videos[0].shape[2]) if self.videos else 0

    @property
    def n_frames(self) -> int:
        return int(sum(len(v) for v in self.videos))

    def camera_index(self, cameras: Sequence[str]) -> list[int]:
        """Positions of ``cameras`` on axis 1; a clear error for an unknown name."""
        out = []
        for c in cameras:
            if c not in self.cameras:
                raise ValueError(
                    f"Unknown camera {c!r}. This data set has: {', '.join(self.cameras)}."
                )
            out.append(self.cameras.index(c))
        return out

    def subset(self, indices: Sequence[int]) -> MultiViewVideos:
        """A new data set with the videos at ``indices``."""
        idx = list(indices)
        return MultiViewVideos(
            videos=[self.videos[i] for i in idx],
            cameras=self.cameras,
            names=[self.names[i] for i in idx],
            stages=None if self.stages is None else [self.stages[i] for i in idx],
            extras={k: [v[i] for i in idx] for k, v in self.extras.items()},
        )

    def save(self, folder: str | Path) -> Path:
        """Write one ``.npz`` per video plus ``meta.json`` into ``folder``."""
        folder = Path(folder)
        folder.mkdir(parents=True, exist_ok=True)
        for i, name in enumerate(self.names):
            arrays: dict[str, Any] = {
                "frames": self.videos[i],
                **{k: v[i] for k, v in self.extras.items()},
            }
            if self.stages is not None:
                arrays["stages"] = self.stages[i]
            np.savez(folder / f"{name}.npz", **arrays)
        meta = {
            "format_version": FORMAT_VERSION,
            "cameras": list(self.cameras),
            "names": self.names,
            "extras": sorted(self.extras),
            "has_stages": self.stages is not None,
        }
        (folder / "meta.json").write_text(json.dumps(meta, indent=1))
        return folder

    @classmethod
    def load(cls, folder: str | Path) -> MultiViewVideos:
        """Read a folder written by :meth:`save`."""
        folder = Path(folder)
        meta_path = folder / "meta.json"
        if not meta_path.is_file():
            raise FileNotFoundError(
                f"No meta.json in {folder}: not a folder written by MultiViewVideos.save. For your own "
                "videos use read_multiview_folder()."
            )
        meta = json.loads(meta_path.read_text())
        videos: list[np.ndarray] = []
        stages: list[np.ndarray] = []
        extras: dict[str, list[np.ndarray]] = {k: [] for k in meta["extras"]}
        for name in meta["names"]:
            with np.load(folder / f"{name}.npz") as z:
                videos.append(z["frames"])
                if meta["has_stages"]:
                    stages.append(z["stages"])
                for k in extras:
                    extras[k].append(z[k])
        return cls(
            videos,
            tuple(meta["cameras"]),
            list(meta["names"]),
            stages if meta["has_stages"] else None,
            extras,
        )


# -- the pick-and-place data set -----------------------------------------------------------------
SPLITS = ("train", "val", "test")


def split_sizes(n_demos: int) -> dict[str, int]:
    """The thesis's 100/25/25 split of 150, scaled to ``n_demos`` (at least one per split).

    >>> split_sizes(150)
    {'train': 100, 'val': 25, 'test': 25}
    >>> split_sizes(12)
    {'train': 8, 'val': 2, 'test': 2}
    """
    if n_demos < 3:
        raise ValueError(f"n_demos must be >= 3 (one per split), got {n_demos}.")
    val = max(1, round(n_demos / 6))
    test = max(1, round(n_demos / 6))
    return {"train": n_demos - val - test, "val": val, "test": test}


def default_cache_dir() -> Path:
    """Where rendered data sets are cached: ``<thesis data dir>/thesis/clfd``."""
    return data_dir() / "thesis" / "clfd"


def make_pick_place_dataset(
    n_demos: int = 150,
    image_size: int = 64,
    seed: int = 0,
    cache_dir: str | Path | bool | None = None,
    progress: bool = True,
) -> dict[str, MultiViewVideos]:
    """Render the multi-view pick-and-place demonstration data set (thesis 4.2.1.1).

    Demonstration ``i`` is the scripted expert from ``reset(seed=seed * 100_000 + i)``; only
    successful demonstrations are kept (the thesis keeps no failed one), drawing further seeds
    if needed. Frames of all five cameras are recorded at every step, with the joint angles,
    joint velocities, gripper opening and stage label. The set is cached under ``cache_dir``
    (default :func:`default_cache_dir`; ``cache_dir=False`` disables caching). The
    cache is keyed by the arguments and :data:`FORMAT_VERSION` (bump it when the scene changes).

    Returns:
        ``{"train", "val", "test"}`` → :class:`MultiViewVideos`, split as :func:`split_sizes`.

    Used in: CLfD (thesis 4.2), chapter 02_clfd.
    """
    sizes = split_sizes(n_demos)
    folder = None
    if cache_dir is not False:
        base = Path(cache_dir) if isinstance(cache_dir, (str, Path)) else default_cache_dir()
        folder = base / f"pick_place_v{FORMAT_VERSION}_{n_demos}demos_{image_size}px_seed{seed}"
        if all((folder / s / "meta.json").is_file() for s in SPLITS):
            return {s: MultiViewVideos.load(folder / s) for s in SPLITS}
    env = MultiViewPickPlace(image_size=image_size)
    demos: list[Demonstration] = []
    videos: list[np.ndarray] = []
    i = 0
    bar = tqdm(total=n_demos, desc="pick-and-place demonstrations", disable=not progress)
    while len(demos) < n_demos:
        d = run_demonstration(env, seed * 100_000 + i, render=True)
        i += 1
        if d.success:
            if d.frames is None:
                raise RuntimeError("run_demonstration(render=True) returned no frames.")
            demos.append(d)
            videos.append(d.frames)
            bar.update(1)
        if i > 2 * n_demos + 20:
            raise RuntimeError(
                f"The scripted expert succeeded in only {len(demos)} of {i} episodes."
            )
    bar.close()
    env.close()
    full = MultiViewVideos(
        videos=videos,
        cameras=CAMERAS,
        names=[f"demo_{k:03d}" for k in range(n_demos)],
        stages=[d.stages for d in demos],
        extras={
            "joint_angles": [d.joint_angles.astype(np.float32) for d in demos],
            "joint_velocities": [d.joint_velocities.astype(np.float32) for d in demos],
            "gripper": [d.gripper.astype(np.float32) for d in demos],
        },
    )
    out, start = {}, 0
    for s in SPLITS:
        out[s] = full.subset(range(start, start + sizes[s]))
        start += sizes[s]
    # write aside, then rename: a concurrent reader never sees half a set (a folder swap, so
    # not thesis_lib._io.atomic_write, which writes one file)
    if folder is not None:
        tmp = folder.with_name(f"{folder.name}.tmp-{os.getpid()}")
        for s in SPLITS:
            out[s].save(tmp / s)
        try:
            tmp.rename(folder)
        except OSError:  # another process wrote it first (or an old partial copy is in the way)
            shutil.rmtree(tmp, ignore_errors=True)
    return out


# -- reader for the Multi-View Pouring layout and for your own videos -----------------------------
_VIEW_RE = re.compile(r"^(?P<seq>.+?)[_-]view(?P<view>\d+)$", re.IGNORECASE)
_ARRAY_EXT = {".npy", ".npz"}
_IMAGE_EXT = {".png", ".jpg", ".jpeg"}


def _read_frames(path: Path) -> np.ndarray:
    """(T, H, W, 3) uint8 from a .npy/.npz array, a folder of images, or a video file."""
    if path.is_dir():
        files = sorted(p for p in path.iterdir() if p.suffix.lower() in _IMAGE_EXT)
        if not files:
            raise ValueError(f"Folder {path} holds no frames (.png/.jpg).")
        import imageio.v3 as iio

        arr = np.stack([iio.imread(p) for p in files])
    elif path.suffix.lower() == ".npy":
        arr = np.load(path)
    elif path.suffix.lower() == ".npz":
        with np.load(path) as z:
            key = "frames" if "frames" in z.files else z.files[0]
            arr = z[key]
    else:
        import imageio.v3 as iio

        try:
            arr = iio.imread(path)  # a video: needs an imageio plugin (pyav or imageio-ffmpeg)
        except Exception as exc:
            raise ValueError(
                f"Cannot read video {path} ({exc}). Install a video plugin (`pip install av`) or convert "
                "the videos to frame arrays (.npy, shape (T, H, W, 3))."
            ) from exc
    arr = np.asarray(arr)
    if arr.ndim == 4 and arr.shape[-1] == 4:
        arr = arr[..., :3]
    if arr.ndim != 4 or arr.shape[-1] != 3:
        raise ValueError(f"{path}: expected frames of shape (T, H, W, 3), got {arr.shape}.")
    if arr.dtype != np.uint8:
        if np.issubdtype(arr.dtype, np.floating) and np.nanmax(arr) <= 1.0:
            arr = arr * 255.0
        if not np.all(np.isfinite(arr)):
            raise ValueError(f"{path}: frames contain NaN or infinite values.")
        arr = np.clip(arr, 0, 255).astype(np.uint8)
    return arr


def _resize(frames: np.ndarray, size: int) -> np.ndarray:
    """Resize (..., H, W, 3) uint8 frames to (..., size, size, 3) (bilinear)."""
    import torch
    import torch.nn.functional as F

    lead = frames.shape[:-3]
    x = torch.from_numpy(frames.reshape(-1, *frames.shape[-3:])).permute(0, 3, 1, 2).float()
    x = F.interpolate(x, size=(size, size), mode="bilinear", align_corners=False, antialias=True)
    out = x.round().clamp(0, 255).byte().permute(0, 2, 3, 1).numpy()
    return out.reshape(*lead, size, size, 3)


def read_multiview_folder(
    folder: str | Path,
    image_size: int | None = 64,
    views: Sequence[int] | None = None,
    max_frames: int | None = None,
) -> MultiViewVideos:
    """Read synchronised multi-view videos from a folder (e.g. Multi-View Pouring's ``videos/train``).

    Files are grouped by sequence: ``<sequence>_view<k>.<ext>`` (TCN's Multi-View Pouring names),
    where each file is a video (.mov/.mp4, needs ``pip install av``), a frame array
    (.npy/.npz, (T, H, W, 3)), or a folder of .png/.jpg frames. Every sequence must have the same
    views, and all views of a sequence the same number of frames: the frames must be
    synchronised, or the anchor-positive pairs of CLfD would show different instants.

    Args:
        folder: the folder to read.
        image_size: frames are resized to this square size (None keeps them, then all must match).
        views: which view numbers to keep (default: all that every sequence has).
        max_frames: keep at most this many frames per sequence (evenly subsampled).

    Raises:
        FileNotFoundError: no such folder, or no ``*_view<k>`` entry in it.
        ValueError: unsynchronised views (different frame counts), a sequence missing a view, or
            unreadable frames, naming the sequence and what was expected.

    Used in: CLfD (thesis 4.2), chapter 02_clfd.
    """
    folder = Path(folder)
    if not folder.is_dir():
        raise FileNotFoundError(
            f"No folder {folder}. Point read_multiview_folder at a folder of "
            "'<sequence>_view<k>' videos or frame arrays."
        )
    groups: dict[str, dict[int, Path]] = {}
    for p in sorted(folder.iterdir()):
        stem = p.name if p.is_dir() else p.stem
        m = _VIEW_RE.match(stem)
        if m:
            groups.setdefault(m["seq"], {})[int(m["view"])] = p
    if not groups:
        raise FileNotFoundError(
            f"No '<sequence>_view<k>' files or folders in {folder} (e.g. 'pour_01_view0.mov', "
            "'pour_01_view1.npy')."
        )
    all_views = sorted(set.intersection(*(set(g) for g in groups.values())))
    wanted = list(views) if views is not None else all_views
    videos, names = [], []
    for seq, g in sorted(groups.items()):
        missing = [v for v in wanted if v not in g]
        if missing:
            raise ValueError(
                f"Sequence {seq!r} has views {sorted(g)} but not {missing}; every sequence needs "
                f"views {wanted}."
            )
        frames = [_read_frames(g[v]) for v in wanted]
        lengths = [len(f) for f in frames]
        if len(set(lengths)) != 1:
            detail = ", ".join(f"view{v}: {n}" for v, n in zip(wanted, lengths))
            raise ValueError(
                f"Sequence {seq!r} is not synchronised: its views have different numbers of frames "
                f"({detail}). CLfD pairs frame t of one view with frame t of another, so every view must "
                "have the same frames; trim or resample them to a common clock first."
            )
        if image_size is not None:
            frames = [_resize(f, image_size) for f in frames]
        shapes = {f.shape[1:] for f in frames}
        if len(shapes) != 1:
            raise ValueError(
                f"Sequence {seq!r}: views have different frame sizes {sorted(shapes)}; pass image_size."
            )
        video = np.stack(frames, axis=1)  # (T, V, H, W, 3)
        if max_frames is not None and len(video) > max_frames:
            video = video[np.linspace(0, len(video) - 1, max_frames).round().astype(int)]
        videos.append(video)
        names.append(seq)
    sizes = {v.shape[2:] for v in videos}
    if len(sizes) != 1:
        raise ValueError(f"Sequences have different frame sizes {sorted(sizes)}; pass image_size.")
    return MultiViewVideos(videos, tuple(f"view{v}" for v in wanted), names)
