"""The MDLT chapter's data: the music-dance pairs of each layout (read once per process), the
thesis's folds, the feature scaler of a fold, and the tables about the data (sizes, how much the
tempogram names its piece).

Used in: MDLT chapter (thesis 6.3, 6.5.1).
"""

from __future__ import annotations

import functools
import hashlib
import os
from collections.abc import Sequence
from typing import Any, Literal

import numpy as np
import pandas as pd

from thesis_lib._io import hash_arrays
from thesis_lib.mdlt import readers
from thesis_lib.mdlt.audio import FEATURE_SLICES, fit_feature_scaler
from thesis_lib.mdlt.synth import default_dataset, default_root

from .config import Config

BEAT_COLUMN = 53
"""Index of the beat one-hot in the raw 438-d features (MFCC 20 + delta 20 + chroma 12 + onset 1)."""
THESIS_FOLDS = 6
"""Folds of a Table 6.2 row (AIST++ has 6 pieces per genre: leave one out)."""


def genre_label(genre: str) -> str:
    """AIST++ music-genre label as Table 6.2 prints it: ``gBR``/``BR``/``mBR`` -> ``mBR``.

    Example:
        >>> genre_label("gHO"), genre_label("mHO"), genre_label("HO")
        ('mHO', 'mHO', 'mHO')
    """
    g = str(genre)
    if len(g) == 3 and g[0] in "gm":
        return "m" + g[1:]
    if len(g) == 2:
        return "m" + g
    return g


def expand_root(root: str) -> str:
    """A data set's folder with its environment variables expanded (``"$AIST_PLUSPLUS"``: a
    study file names the folder the same way on every machine; the study's rows record which
    numbers it held, ``data_sha``).

    Raises:
        ValueError: a variable it names is not set.

    >>> import os; os.environ["DEMO_ROOT"] = "/data/aist"
    >>> expand_root("$DEMO_ROOT/v1")
    '/data/aist/v1'
    """
    where = os.path.expandvars(os.path.expanduser(str(root)))
    if "$" in where:
        raise ValueError(
            f"The data folder {root!r} names an environment variable that is not set: set it to "
            "your download (e.g. AIST_PLUSPLUS=/data/aist_plusplus thesis study 06_mdlt:aist)."
        )
    return where


def load_sequences(
    layout: Literal["aist", "phantomdance"],
    root: str | None = None,
    size: str = "full",
    seed: int = 0,
    fps: int | None = None,
) -> list:
    """Music-dance pairs of ``layout``: read ``root``, or make the default data set first.

    ``fps``: feature frames per second of the PhantomDance layout (``None``: the reader's 60);
    AIST++ is always at 60. The ``study`` size exists for AIST++ only: PhantomDance gets its
    smoke set.

    Used in: MDLT chapter (thesis 6.3).
    """
    if layout == "phantomdance" and size == "study":
        size = "smoke"
    where = (
        default_dataset(layout=layout, size=size, seed=seed) if root is None else expand_root(root)
    )
    if layout == "aist":
        return readers.load_aist(where)
    return readers.load_phantomdance(where, fps=fps)


def aist_folds(sequences: Sequence, genre: str | None, n_folds: int = 6) -> list[tuple[list, list]]:
    """Thesis 6.5.1 splits: per genre, fold ``i`` validates on the genre's ``i``-th music (by id);
    ``genre=None`` ("All Genres"): fold ``i`` validates on the ``i``-th music of every genre.

    With more than :data:`THESIS_FOLDS` (6) pieces per genre (the ``study`` data size), the
    folds stay six: fold ``i`` validates on every piece ``j`` of the genre with ``j % 6 == i``.

    Used in: MDLT chapter (thesis 6.5.1).
    """
    by_genre: dict[str, list] = {}
    for s in sequences:
        by_genre.setdefault(genre_label(s.genre), []).append(s)
    for g in by_genre:
        by_genre[g].sort(key=lambda s: str(s.music_id))
    if genre is not None:
        label = genre_label(genre)
        if label not in by_genre:
            raise ValueError(
                f"No sequences of genre {genre!r}. Genres present: {', '.join(sorted(by_genre))}."
            )
        by_genre = {label: by_genre[label]}
    n_min = min(len(v) for v in by_genre.values())
    if n_min < 2:
        raise ValueError(
            f"Leave-one-music-out needs >= 2 pieces per genre; some genre has {n_min}."
        )
    groups = min(n_min, THESIS_FOLDS)
    folds = []
    for i in range(min(n_folds, groups)):
        val = [s for v in by_genre.values() for j, s in enumerate(v) if j % groups == i]
        train = [s for v in by_genre.values() for j, s in enumerate(v) if j % groups != i]
        folds.append((train, val))
    return folds


def phantomdance_folds(
    sequences: Sequence, n_folds: int = 10, run: int | None = None
) -> list[tuple[list, list]]:
    """Thesis 6.5.3: songs sorted by name, fold ``i`` validates on the ``i``-th tenth.

    ``run``: only the first ``run`` folds (default all).
    """
    seqs = sorted(sequences, key=lambda s: str(s.name))
    if len(seqs) < n_folds:
        raise ValueError(f"{n_folds} folds need >= {n_folds} sequences, got {len(seqs)}.")
    bounds = np.linspace(0, len(seqs), n_folds + 1).round().astype(int)
    folds = []
    for i in range(n_folds if run is None else min(run, n_folds)):
        val = seqs[bounds[i] : bounds[i + 1]]
        train = seqs[: bounds[i]] + seqs[bounds[i + 1] :]
        folds.append((train, val))
    return folds


def fold_split(data: dict[str, Any], genre: str | None, fold: int) -> tuple[list, list]:
    """``(train, val)`` of fold ``fold`` of the data set ``data`` (``layout, root, size, seed``
    and, for PhantomDance, ``fps``: a task config's ``data``); ``genre``: an AIST++ per-genre
    row (``None``: all genres)."""
    seqs = cached_sequences(
        data["layout"], data["root"], data["size"], data["seed"], data.get("fps")
    )
    if data["layout"] == "phantomdance":
        return phantomdance_folds(seqs, 10, run=fold + 1)[fold]
    return aist_folds(seqs, genre, fold + 1)[fold]


def fit_scaler(train: Sequence, val: Sequence, paper_compat: bool, mute: Sequence[str] = ()):
    """The feature scaler of a fold: fitted on ``train`` (``paper_compat``: on ``val`` too)."""
    return fit_feature_scaler(
        [s.features for s in train],
        [s.features for s in val],
        paper_compat=paper_compat,
        mute=tuple(mute),
    )


@functools.lru_cache(maxsize=4)
def cached_sequences(
    layout: str, root: str | None, size: str, seed: int, fps: int | None = None
) -> tuple:
    """:func:`load_sequences`, once per process (the last four data sets are kept)."""
    return tuple(load_sequences(layout, root, size, seed, fps))  # type: ignore[arg-type]


@functools.lru_cache(maxsize=4)
def data_sha(layout: str, root: str | None, size: str, seed: int, fps: int | None = None) -> str:
    """A short hash of every piece's name, features and angles (:func:`cached_sequences`).

    The study's rows record it: each machine synthesises and featurises the data set anew, and
    this says whether two machines made the same numbers.
    """
    h = hashlib.sha256()
    for s in cached_sequences(layout, root, size, seed, fps):
        h.update(str(s.name).encode())
        hash_arrays(h, (s.features, s.angles))
    return h.hexdigest()[:16]


def data_args(cfg: Config) -> tuple[str | None, str, int]:
    """``(root, size, seed)`` of the AIST++-layout data of ``cfg`` (for :func:`load_sequences`)."""
    return cfg.aist_root, cfg.data_size, cfg.data_seed


def load_datasets(cfg: Config) -> tuple[list, list]:
    """The AIST++-layout and PhantomDance-layout music-dance pairs of ``cfg`` (read once per
    process; the default data sets are made on first use)."""
    aist = cached_sequences("aist", cfg.aist_root, cfg.data_size, cfg.data_seed)
    phantom = cached_sequences(
        "phantomdance", cfg.phantomdance_root, cfg.data_size, cfg.data_seed, cfg.phantom_fps()
    )
    return list(aist), list(phantom)


def run_dataset_table(cfg: Config) -> pd.DataFrame:
    """Per data set: music-dance pairs, genres, mean length (s) and frames."""
    aist, phantom = load_datasets(cfg)
    return pd.DataFrame(
        [
            {
                "data set": name,
                "pairs": len(seqs),
                "genres": len({genre_label(s.genre) for s in seqs}),
                "seconds (mean)": np.mean([len(s.angles) / s.fps for s in seqs]),
                "frames": sum(len(s.angles) for s in seqs),
            }
            for name, seqs in (("AIST++ layout", aist), ("PhantomDance layout", phantom))
        ]
    )


def piece_fingerprint(
    sequences: Sequence, group: str = "tempogram", frames_per_piece: int = 200, seed: int = 0
) -> dict[str, Any]:
    """How much a feature group names the piece it comes from: the memorisation risk of C13.

    The features are min-max scaled over all ``sequences`` (as
    :class:`~thesis_lib.mdlt.audio.FeatureScaler` does) and restricted to ``group``
    (:data:`~thesis_lib.mdlt.audio.FEATURE_SLICES`). Then:

    * ``between_share``: the share of the group's total variance (summed over its dimensions)
      that lies between the pieces' means; 1 = constant within a piece, 0 = the same mean in
      every piece;
    * ``id_accuracy``: for ``frames_per_piece`` random frames of each piece, how often the
      nearest piece mean (Euclidean) is the frame's own piece; ``chance`` = 1 / pieces.

    A group with a high share and accuracy lets a model recognise each training piece and
    memorise its dance instead of learning what the music asks for.

    Used in: MDLT chapter (the data; the C13 study's data size).

    Example:
        >>> from types import SimpleNamespace as NS
        >>> x = np.zeros((4, 438), np.float32)
        >>> a, b = NS(features=x), NS(features=x + np.eye(1, 438, 100, dtype=np.float32))
        >>> piece_fingerprint([a, b])["between_share"]
        1.0
    """
    if group not in FEATURE_SLICES:
        raise ValueError(f"Unknown feature group {group!r}. Valid: {', '.join(FEATURE_SLICES)}.")
    if len(sequences) < 2:
        raise ValueError(f"Expect >= 2 pieces, got {len(sequences)}.")
    sl = FEATURE_SLICES[group]
    feats = [np.asarray(s.features, np.float64)[:, sl] for s in sequences]
    lo = np.min([f.min(0) for f in feats], axis=0)
    hi = np.max([f.max(0) for f in feats], axis=0)
    span = np.where(hi > lo, hi - lo, 1.0)
    feats = [(f - lo) / span for f in feats]
    n = np.array([len(f) for f in feats], dtype=np.float64)
    means = np.stack([f.mean(0) for f in feats])
    grand = (means * n[:, None]).sum(0) / n.sum()
    between = float((n * ((means - grand) ** 2).sum(1)).sum())
    total = float(sum(((f - grand) ** 2).sum() for f in feats))
    rng = np.random.default_rng(seed)
    hits, tried = 0, 0
    for i, f in enumerate(feats):
        idx = rng.choice(len(f), size=min(frames_per_piece, len(f)), replace=False)
        d = ((f[idx, None, :] - means[None]) ** 2).sum(-1)  # (frames, pieces)
        hits += int((d.argmin(1) == i).sum())
        tried += len(idx)
    return {
        "group": group,
        "pieces": len(feats),
        "seconds_per_piece": float(
            np.mean([len(s.features) / getattr(s, "fps", 60) for s in sequences])
        ),
        "between_share": between / total if total > 0 else float("nan"),
        "id_accuracy": hits / tried,
        "chance": 1.0 / len(feats),
    }


def fingerprint_table(
    cfg: Config, sizes: Sequence[str] = ("smoke", "study"), make: bool = False
) -> pd.DataFrame:
    """:func:`piece_fingerprint` of the tempogram (and, for contrast, the MFCC deltas) on the
    default AIST++-layout set at each of ``sizes`` (``cfg.data_seed``); with ``cfg.aist_root``,
    that folder instead. One row per size x group.

    ``make``: make a default set that does not exist yet (the study size costs about 5
    CPU-minutes); ``False``: report it as not made (``thesis study 06_mdlt`` makes it) unless it
    is the run's own ``data_size``.

    Used in: MDLT chapter (the data) and its study section.
    """
    out: list[dict[str, Any]] = []
    for size in [cfg.data_size] if cfg.aist_root else sizes:
        made = (default_root("aist", size, cfg.data_seed) / ".complete.json").is_file()
        if not (cfg.aist_root or made or make or size == cfg.data_size):
            out.append({"data size": size, "group": "not made yet (thesis study 06_mdlt makes it)"})
            continue
        seqs = cached_sequences("aist", cfg.aist_root, size, cfg.data_seed)
        for group in ("tempogram", "mfcc_delta"):
            out.append({"data size": size, **piece_fingerprint(seqs, group)})
    return pd.DataFrame(out)
