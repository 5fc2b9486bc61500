"""Pairing audio feature frames with poses by timestamp (thesis 6.3.4).

Feature frame ``i`` is centred at ``i / fps`` seconds (librosa's centred frames); each is paired
with the pose whose timestamp is nearest. The authors used ``(i + 1) / fps`` (one frame late, 17 ms
at 60 fps): ``paper_compat=True``. Thesis chapter 6.
"""

from __future__ import annotations

import numpy as np


def frame_times(n_frames: int, fps: float = 60.0, paper_compat: bool = False) -> np.ndarray:
    """Times in seconds of ``n_frames`` feature frames.

    >>> frame_times(3, fps=60).tolist()
    [0.0, 0.016666666666666666, 0.03333333333333333]
    """
    i = np.arange(n_frames, dtype=np.float64)
    return (i + 1.0 if paper_compat else i) / float(fps)


def nearest_pose_indices(frame_t: np.ndarray, pose_t: np.ndarray) -> np.ndarray:
    """Index of the pose with the nearest timestamp for each frame time (ties: the earlier pose).

    Args:
        frame_t: (T_f,) frame times, seconds.
        pose_t: (T_p,) pose timestamps, seconds; must be strictly increasing (sort them first).

    Returns:
        (T_f,) int64 indices into the poses.

    >>> nearest_pose_indices(np.array([0.0, 0.04, 0.06, 0.5]), np.array([0.0, 0.05, 0.1])).tolist()
    [0, 1, 1, 2]
    """
    frame_t = np.asarray(frame_t, dtype=np.float64)
    pose_t = np.asarray(pose_t, dtype=np.float64)
    if pose_t.ndim != 1 or pose_t.size == 0:
        raise ValueError(
            f"pose timestamps must be a non-empty 1-D array, got shape {pose_t.shape}."
        )
    if not np.all(np.isfinite(pose_t)):
        raise ValueError("pose timestamps hold NaN/inf.")
    if pose_t.size > 1 and np.any(np.diff(pose_t) <= 0):
        k = int(np.flatnonzero(np.diff(pose_t) <= 0)[0])
        raise ValueError(
            f"pose timestamps must be strictly increasing; index {k + 1} ({pose_t[k + 1]}) follows "
            f"{pose_t[k]}. Sort the poses by time and drop duplicates first."
        )
    right = np.clip(np.searchsorted(pose_t, frame_t, side="left"), 0, pose_t.size - 1)
    left = np.clip(right - 1, 0, pose_t.size - 1)
    take_left = np.abs(frame_t - pose_t[left]) <= np.abs(pose_t[right] - frame_t)
    return np.where(take_left, left, right).astype(np.int64)


def synchronize(
    features: np.ndarray,
    poses: np.ndarray,
    pose_timestamps: np.ndarray,
    fps: float = 60.0,
    timestamp_unit: float = 1e-6,
    paper_compat: bool = False,
    trim_to_poses: bool = True,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Pair every audio feature frame with the pose nearest in time.

    Args:
        features: (T_f, D) audio features at ``fps``.
        poses: (T_p, ...) poses (joint angles, joints) with one timestamp each.
        pose_timestamps: (T_p,) timestamps; AIST++ gives microseconds (``timestamp_unit=1e-6``).
        fps: feature frame rate.
        paper_compat: frame ``i`` at ``(i + 1) / fps`` as the authors' code, instead of ``i / fps``.
        trim_to_poses: drop feature frames later than the last pose plus half the median pose
            interval (music that runs on after the dance has no true pose; the authors paired it
            with the last pose). Frames before the first pose are kept (paired with it).

    Returns:
        ``(features, poses, frame_index_of_pose)``: the kept features (T, D), the paired poses
        (T, ...) and, for each kept frame, the index of its pose (T,).
    """
    features = np.asarray(features)
    poses = np.asarray(poses)
    ts = np.asarray(pose_timestamps, dtype=np.float64) * timestamp_unit
    if poses.shape[0] != ts.shape[0]:
        raise ValueError(f"{poses.shape[0]} poses but {ts.shape[0]} timestamps; they must pair up.")
    t_f = frame_times(features.shape[0], fps=fps, paper_compat=paper_compat)
    if trim_to_poses and ts.size > 1:
        half = 0.5 * float(np.median(np.diff(ts)))
        keep = t_f <= ts[-1] + half
        features, t_f = features[keep], t_f[keep]
    idx = nearest_pose_indices(t_f, ts)
    return features, poses[idx], idx
