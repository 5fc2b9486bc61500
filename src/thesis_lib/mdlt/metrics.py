"""Metrics and baselines of the MDLT chapter (thesis 6.5.1): AJE, MAE, FID, beat alignment.

* :func:`aje` - the Average Joint Error **as the authors computed it**: the root of the mean
  squared angle difference over frames and joints (an RMSE, radians). No wrapping of angles.
* :func:`mae_degrees` - the mean absolute angle difference in degrees (easier to read).
* :func:`frechet_distance` - the Fréchet distance between Gaussians fitted to the per-frame
  4-D joint angles of one generated and one true sequence (FID's formula, no Inception
  network: the "features" are the angles); :func:`evaluate_songs` averages it over songs.
  The thesis prints it as "FID (%)", but nothing converts it to a percentage: it is a plain
  distance in rad².
* :func:`beat_alignment` - Bailando's beat-align score: for each music beat,
  ``exp(-d² / (2 sigma²))`` with ``d`` the distance (frames) to the nearest kinematic beat
  (a local minimum of the joints' angular speed); the mean over music beats.
* Baselines: :func:`mean_pose_baseline`, :func:`last_pose_baseline`, :func:`random_baseline`.

Used in: MDLT chapter (thesis 6.5).
"""

from __future__ import annotations

import warnings
from collections.abc import Sequence

import numpy as np
import pandas as pd
import scipy.linalg
import scipy.signal

__all__ = [
    "BASELINES",
    "aje",
    "beat_alignment",
    "beat_alignment_null",
    "evaluate_songs",
    "frechet_distance",
    "kinematic_beats",
    "last_pose_baseline",
    "mae_degrees",
    "mean_pose_baseline",
    "random_baseline",
]


def _pair(pred: np.ndarray, true: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    pred, true = np.asarray(pred, dtype=np.float64), np.asarray(true, dtype=np.float64)
    if pred.shape != true.shape or pred.ndim != 2 or len(pred) == 0:
        raise ValueError(
            f"Expect predicted and true angles of the same shape (T, J), T >= 1; got "
            f"{pred.shape} and {true.shape}."
        )
    if not (np.isfinite(pred).all() and np.isfinite(true).all()):
        raise ValueError("Angles contain NaN or inf.")
    return pred, true


def aje(pred: np.ndarray, true: np.ndarray) -> float:
    """Average Joint Error as the authors computed it: ``sqrt(mean((pred - true)²))`` in radians.

    Used in: MDLT chapter (thesis 6.5.1).

    Example:
        >>> aje(np.zeros((2, 2)), np.array([[1.0, 1.0], [1.0, 1.0]]))
        1.0
    """
    pred, true = _pair(pred, true)
    return float(np.sqrt(np.mean((pred - true) ** 2)))


def mae_degrees(pred: np.ndarray, true: np.ndarray) -> float:
    """Mean absolute joint-angle error in degrees.

    Example:
        >>> round(mae_degrees(np.zeros((1, 2)), np.array([[np.pi, 0.0]])), 6)
        90.0
    """
    pred, true = _pair(pred, true)
    return float(np.degrees(np.mean(np.abs(pred - true))))


def frechet_distance(x: np.ndarray, y: np.ndarray, eps: float = 1e-6) -> float:
    """Fréchet distance between Gaussians fitted to the rows of ``x (T1, J)`` and ``y (T2, J)``.

    ``|mu_x - mu_y|² + Tr(S_x + S_y - 2 (S_x S_y)^{1/2})`` with sample covariances; when the
    product is singular (e.g. a constant prediction), ``eps`` is added to the diagonals, as
    pytorch-fid does. A plain distance (rad²), not a percentage.

    Used in: MDLT chapter (thesis 6.5.1).

    Example:
        >>> a = np.array([[0.0], [2.0]])      # mean 1, variance 2
        >>> round(frechet_distance(a, a + 3.0), 6)
        9.0
    """
    x, y = np.asarray(x, dtype=np.float64), np.asarray(y, dtype=np.float64)
    if x.ndim != 2 or y.ndim != 2 or x.shape[1] != y.shape[1] or len(x) < 2 or len(y) < 2:
        raise ValueError(
            f"Expect two arrays (T, J) with the same J and T >= 2, got {x.shape} and {y.shape}."
        )
    mu_x, mu_y = x.mean(0), y.mean(0)
    s_x, s_y = np.atleast_2d(np.cov(x, rowvar=False)), np.atleast_2d(np.cov(y, rowvar=False))
    with warnings.catch_warnings():  # a singular product (constant prediction) is handled below
        warnings.simplefilter("ignore", scipy.linalg.LinAlgWarning)
        covmean = scipy.linalg.sqrtm(s_x @ s_y)
    if not np.isfinite(covmean).all():
        offset = np.eye(len(s_x)) * eps
        covmean = scipy.linalg.sqrtm((s_x + offset) @ (s_y + offset))
    covmean = np.real(covmean)
    diff = mu_x - mu_y
    return float(max(diff @ diff + np.trace(s_x) + np.trace(s_y) - 2.0 * np.trace(covmean), 0.0))


def kinematic_beats(angles: np.ndarray) -> np.ndarray:
    """Frames where the joints' angular speed has a local minimum (the dance's "beats").

    Example:
        >>> t = np.arange(100)[:, None]
        >>> kinematic_beats(np.sin(2 * np.pi * t / 20)).tolist()[:3]   # speed ~ |cos|: minima at the extremes
        [5, 15, 25]
    """
    angles = np.asarray(angles, dtype=np.float64)
    if angles.ndim != 2 or len(angles) < 3:
        return np.zeros(0, dtype=np.int64)
    speed = np.linalg.norm(np.gradient(angles, axis=0), axis=1)  # (T,), central differences
    peaks, _ = scipy.signal.find_peaks(-speed)
    return peaks


def beat_alignment(angles: np.ndarray, music_beats: np.ndarray, sigma: float = 3.0) -> float:
    """Bailando's beat-align score in [0, 1]: mean over music beats of ``exp(-d²/(2 sigma²))``.

    ``d`` = frames from a music beat to the nearest kinematic beat; ``sigma`` in frames (3 at
    60 fps in Bailando). ``music_beats``: frame indices, or a 0/1 vector of length T (the
    feature vector's beat one-hot). NaN when there are no music beats or no kinematic beats.

    Used in: MDLT chapter (thesis 6.5).
    """
    beats = np.asarray(music_beats)
    if (
        beats.ndim == 1
        and beats.dtype != np.int64
        and len(beats) == len(angles)
        and set(np.unique(beats)) <= {0, 1}
    ):
        beats = np.flatnonzero(beats > 0.5)
    beats = beats.astype(np.int64)
    kin = kinematic_beats(angles)
    if len(beats) == 0 or len(kin) == 0:
        return float("nan")
    d = np.abs(beats[:, None] - kin[None, :]).min(axis=1)
    return float(np.mean(np.exp(-(d.astype(np.float64) ** 2) / (2.0 * sigma**2))))


def beat_alignment_null(
    angles: np.ndarray,
    music_beats: np.ndarray,
    n: int = 200,
    seed: int = 0,
    sigma: float = 3.0,
    min_shift: int | None = None,
) -> dict[str, float]:
    """Does the motion follow *these* beats, more than any busy motion would? The beat-align
    score of ``angles`` against ``music_beats`` beside three nulls that keep the motion and
    break only its timing against the music:

    - **shifted motion** (``p_shift``): the motion circularly shifted by ``n`` random offsets of
      at least ``min_shift`` frames (default: one beat period): the same speed spectrum, so the
      same density of kinematic beats, but no relation to the music. ``p_shift`` is the share
      of shifts that score at least as high (with the +1 of a permutation p-value).
    - **random beats** (``random_beats_mean``): as many beats as the music's, placed uniformly
      at random. A motion with a speed minimum every few frames scores high here too: that is
      why a raw beat-align score near 0.9 says little.
    - **half-beat grid** (``half_beat``): the music's beats moved by half the median beat
      period: a motion that follows the beat scores lower there.

    ``follows_beat``: ``p_shift < 0.05`` and the score above the half-beat grid's. NaN results
    (no beats) give ``follows_beat`` False.

    A strictly periodic motion against strictly periodic beats cannot pass the shift test
    (one shift in a few lands in phase again): the test asks for timing that follows the
    music's own irregular beats, as real music and dance have.

    >>> beats = np.arange(15, 600, 30)
    >>> busy = np.random.default_rng(0).standard_normal((600, 4))       # speed minima everywhere
    >>> r = beat_alignment_null(busy, beats, n=100)
    >>> r["score"] > 0.5, r["follows_beat"]                             # high score, no following
    (True, False)
    """
    a = np.asarray(angles, dtype=np.float64)
    beats = np.asarray(music_beats)
    if beats.ndim == 1 and len(beats) == len(a) and set(np.unique(beats)) <= {0, 1}:
        beats = np.flatnonzero(beats > 0.5)
    beats = np.asarray(beats, dtype=np.int64)
    nan = float("nan")
    out: dict[str, float] = {
        "score": beat_alignment(a, beats, sigma),
        "p_shift": nan,
        "shift_mean": nan,
        "shift_q95": nan,
        "random_beats_mean": nan,
        "half_beat": nan,
        "follows_beat": False,
    }
    if len(beats) < 2 or len(a) < 3 or not np.isfinite(out["score"]):
        return out
    rng = np.random.default_rng(seed)
    period = float(np.median(np.diff(np.sort(beats))))
    lo = int(min_shift if min_shift is not None else max(1, round(period)))
    hi = len(a) - lo
    shifted = []
    if hi > lo:
        for k in rng.integers(lo, hi, size=n):
            shifted.append(beat_alignment(np.roll(a, int(k), axis=0), beats, sigma))
    sh = np.asarray(shifted, dtype=np.float64)
    rand = [
        beat_alignment(a, np.sort(rng.choice(len(a), size=len(beats), replace=False)), sigma)
        for _ in range(n)
    ]
    half = beats + int(round(period / 2))
    half = half[half < len(a)]
    out.update(
        p_shift=float((1 + np.sum(sh >= out["score"])) / (1 + len(sh))) if len(sh) else nan,
        shift_mean=float(np.nanmean(sh)) if len(sh) else nan,
        shift_q95=float(np.nanquantile(sh, 0.95)) if len(sh) else nan,
        random_beats_mean=float(np.nanmean(rand)),
        half_beat=beat_alignment(a, half, sigma) if len(half) else nan,
    )
    out["follows_beat"] = bool(
        np.isfinite(out["p_shift"]) and out["p_shift"] < 0.05 and out["score"] > out["half_beat"]
    )
    return out


def evaluate_songs(
    preds: Sequence[np.ndarray],
    trues: Sequence[np.ndarray],
    names: Sequence[str] | None = None,
    music_beats: Sequence[np.ndarray] | None = None,
) -> pd.DataFrame:
    """One row per song: ``song, aje, mae_deg, fid, beat_align``; average the rows for the table.

    Used in: MDLT chapter (thesis 6.5).
    """
    if len(preds) != len(trues) or len(preds) == 0:
        raise ValueError(
            f"Expect as many predicted as true sequences (>= 1), got {len(preds)} and {len(trues)}."
        )
    names = list(names) if names is not None else [str(i) for i in range(len(preds))]
    rows = []
    for i, (p, t) in enumerate(zip(preds, trues)):
        rows.append(
            {
                "song": names[i],
                "aje": aje(p, t),
                "mae_deg": mae_degrees(p, t),
                "fid": frechet_distance(p, t),
                "beat_align": beat_alignment(p, music_beats[i])
                if music_beats is not None
                else float("nan"),
            }
        )
    return pd.DataFrame(rows)


# ----------------------------------------------------------------------------------------------
# Baselines: each maps (training angles, song lengths, seed) to predictions per song


def mean_pose_baseline(
    train_angles: Sequence[np.ndarray], lengths: Sequence[int], seed: int = 0
) -> list[np.ndarray]:
    """Every frame = the mean training pose (the best constant under the L2 loss).

    Example:
        >>> mean_pose_baseline([np.array([[0.0, 2.0], [2.0, 4.0]])], [1])[0].tolist()
        [[1.0, 3.0]]
    """
    mean = np.concatenate([np.asarray(a) for a in train_angles]).mean(0)
    return [np.tile(mean, (n, 1)).astype(np.float32) for n in lengths]


def last_pose_baseline(
    train_angles: Sequence[np.ndarray], lengths: Sequence[int], seed: int = 0
) -> list[np.ndarray]:
    """Every frame = the last pose of the last training sequence (a robot that stops)."""
    last = np.asarray(train_angles[-1])[-1]
    return [np.tile(last, (n, 1)).astype(np.float32) for n in lengths]


def random_baseline(
    train_angles: Sequence[np.ndarray], lengths: Sequence[int], seed: int = 0
) -> list[np.ndarray]:
    """Angles drawn uniformly in [-pi, pi) each frame (the thesis's "random model", 6.5.3)."""
    rng = np.random.default_rng(seed)
    J = np.asarray(train_angles[0]).shape[1]
    return [rng.uniform(-np.pi, np.pi, size=(n, J)).astype(np.float32) for n in lengths]


BASELINES = {
    "mean_pose": mean_pose_baseline,
    "last_pose": last_pose_baseline,
    "random": random_baseline,
}
"""Name -> baseline function ``(train_angles, lengths, seed) -> predictions``."""
