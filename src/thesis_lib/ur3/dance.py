"""Dance playback on the simulated UR3: MDLT's four joint angles on the arm's first four joints.

MDLT (thesis chapter 6) outputs, per audio frame, four angles in ``[-π, π]`` (two at the
shoulder, the elbow, the wrist; 6.3.3). :func:`map_dance` puts them on the UR3's shoulder pan,
shoulder lift, elbow and wrist 1 as ``q_j = offset_j + scale_j · θ_j``; wrist 2 and wrist 3
stay fixed. :func:`prepare_dance` then checks the result against the joint, speed and
workspace limits and either **clips** it (clamps to the joint limits and rate-limits to the
speed limits, the default for playback) or **rejects** it (raises
:class:`~thesis_lib.ur3.safety.UnsafeTrajectoryError`). The real robot's driver always rejects.

:func:`demo_angles` is a stand-in dance (a few periodic moves to a beat) for use until
MDLT's generated angles are at hand.

Used in: UR3 deployment chapter (chapter 6's application).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Literal

import numpy as np

from .safety import (
    SafetyLimits,
    SafetyReport,
    UnsafeTrajectoryError,
    as_angle_frames,
    check_trajectory,
    clip_trajectory,
)

__all__ = ["DanceMapping", "DancePlayback", "demo_angles", "map_dance", "prepare_dance"]


@dataclass(frozen=True)
class DanceMapping:
    """How MDLT's four angles become the UR3's six joint angles: ``q_j = offset_j + scale_j θ_j``.

    The default offsets put the arm upright (``θ = 0`` → upper arm up, forearm and wrist
    straight), scaled by one half so a full ``±π`` swing of the human arm stays above the table.
    """

    offset: tuple[float, float, float, float] = (0.0, -np.pi / 2, 0.0, -np.pi / 2)
    """Angles of joints 1-4 for ``θ = 0`` (rad)."""
    scale: tuple[float, float, float, float] = (0.5, 0.5, 0.5, 0.5)
    """Gain on each of the four angles."""
    wrist: tuple[float, float] = (-np.pi / 2, 0.0)
    """Fixed wrist 2 and wrist 3 angles (rad)."""


def _check_angles(angles: np.ndarray) -> np.ndarray:
    return as_angle_frames(angles, 4, "dance angles (MDLT's output)")


def map_dance(angles: np.ndarray, mapping: DanceMapping | None = None) -> np.ndarray:
    """``(T, 4)`` MDLT angles → ``(T, 6)`` UR3 joint angles (see :class:`DanceMapping`).

    >>> map_dance(np.zeros((1, 4)))[0].round(3).tolist()
    [0.0, -1.571, 0.0, -1.571, -1.571, 0.0]
    """
    a = _check_angles(angles)
    m = mapping or DanceMapping()
    q = np.empty((len(a), 6))
    q[:, :4] = np.asarray(m.offset) + np.asarray(m.scale) * a
    q[:, 4:] = np.asarray(m.wrist)
    return q


def demo_angles(
    seconds: float = 8.0, fps: int = 60, bpm: float = 120.0, seed: int = 0
) -> np.ndarray:
    """A stand-in dance: ``(T, 4)`` float32 angles in ``[-π, π]``, smooth moves on a beat.

    Each bar (4 beats) picks a move (sway, wave, pump, twist) with its own amplitudes; moves
    blend over half a beat. Deterministic for a given ``seed``.

    Used in: UR3 deployment chapter (until MDLT angles are used).
    """
    if seconds <= 0 or fps <= 0 or bpm <= 0:
        raise ValueError(f"Expect positive seconds, fps and bpm, got {seconds}, {fps}, {bpm}.")
    rng = np.random.default_rng(seed)
    T = int(round(seconds * fps))
    t = np.arange(T) / fps
    beat = 60.0 / bpm
    phase = 2 * np.pi * t / beat  # one cycle per beat
    moves = {
        "sway": lambda p, a: np.stack(
            [a[0] * np.sin(p / 2), 0.3 * a[1] * np.sin(p), 0.4 * a[2] * (1 - np.cos(p)), 0 * p], 1
        ),
        "wave": lambda p, a: np.stack(
            [
                0.2 * a[0] * np.sin(p / 4),
                a[1] * np.sin(p),
                -a[2] * (1 + np.sin(p)),
                a[3] * np.sin(2 * p),
            ],
            1,
        ),
        "pump": lambda p, a: np.stack(
            [
                0 * p,
                0.8 * a[1] * (1 - np.cos(p)),
                -1.2 * a[2] * (1 - np.cos(p)),
                0.5 * a[3] * np.sin(p),
            ],
            1,
        ),
        "twist": lambda p, a: np.stack(
            [
                1.2 * a[0] * np.sin(p / 2),
                0.2 * a[1] * np.sin(p),
                -0.5 * a[2] + 0 * p,
                a[3] * np.sin(p),
            ],
            1,
        ),
    }
    names = list(moves)
    bar = 4 * beat
    n_bars = int(np.ceil(seconds / bar)) + 1
    per_bar = [
        moves[names[rng.integers(len(names))]](phase, rng.uniform(0.3, 0.8, 4))
        for _ in range(n_bars)
    ]
    k = np.minimum((t // bar).astype(int), n_bars - 2)
    w = np.clip((t - k * bar - (bar - beat / 2)) / (beat / 2), 0, 1)[
        :, None
    ]  # blend into the next bar
    out = np.empty((T, 4))
    for i in range(T):
        out[i] = (1 - w[i]) * per_bar[k[i]][i] + w[i] * per_bar[k[i] + 1][i]
    return np.clip(out, -np.pi, np.pi).astype(np.float32)


@dataclass
class DancePlayback:
    """A dance ready to play: the joint trajectory and what the checks found.

    Attributes:
        q: ``(T, 6)`` joint angles to play (clipped in ``"clip"`` mode).
        fps: frames per second.
        mode: ``"clip"`` or ``"reject"``.
        before: the check of the mapped trajectory.
        after: the check of ``q``.
        changed_frames: frames where clipping moved a joint by more than 1e-9 rad.
        max_deviation: largest change clipping made (rad).
    """

    q: np.ndarray
    fps: float
    mode: str
    before: SafetyReport
    after: SafetyReport
    changed_frames: int = 0
    max_deviation: float = 0.0
    notes: list[str] = field(default_factory=list)

    @property
    def duration(self) -> float:
        """Seconds."""
        return len(self.q) / self.fps

    def summary(self) -> str:
        """One line: how many frames of the mapped dance break which limit (as ``thesis ur3
        check`` reports it) and, in ``"clip"`` mode, how many frames playing it clips or slows
        (as ``thesis ur3 play`` reports it).

        >>> pb = prepare_dance(np.array([[0.0] * 4, [1.0] * 4]), fps=60)
        >>> pb.summary()  # doctest: +NORMALIZE_WHITESPACE
        'speed limits broken in 1 of 2 frames (first at frame 1); peak speed 9.55x the allowed;
        playing it clips or slows 1 of 2 frames (largest change 0.448 rad).'
        """
        line = self.before.summary()
        if self.before.ok or self.mode != "clip":
            return line
        line = (
            f"{line[:-1]}; playing it clips or slows {self.changed_frames} of "
            f"{self.before.n_frames} frames (largest change {self.max_deviation:.3f} rad)"
        )
        return "; ".join([line, *(n.rstrip(".") for n in self.notes)]) + "."


def prepare_dance(
    angles: np.ndarray,
    fps: float = 60.0,
    mode: Literal["clip", "reject"] = "clip",
    mapping: DanceMapping | None = None,
    limits: SafetyLimits | None = None,
) -> DancePlayback:
    """Map MDLT angles to the UR3 and enforce the limits by clipping or rejecting.

    Args:
        angles: ``(T, 4)`` MDLT angles (rad) at ``fps``.
        fps: frame rate of ``angles`` (MDLT: 60).
        mode: ``"clip"`` clamps to the joint limits and rate-limits to the speed limits;
            ``"reject"`` raises if any limit is broken. A workspace violation is never
            repaired: in ``"clip"`` mode it stays in ``after`` (the driver would refuse it).
        mapping: :class:`DanceMapping`.
        limits: :class:`~thesis_lib.ur3.safety.SafetyLimits`.

    Raises:
        UnsafeTrajectoryError: ``mode="reject"`` and the mapped dance breaks a limit.

    Used in: UR3 deployment chapter.
    """
    if mode not in ("clip", "reject"):
        raise ValueError(f"Unknown mode {mode!r}. Valid: clip, reject.")
    dt = 1.0 / float(fps) if fps and fps > 0 else float("nan")
    q = map_dance(angles, mapping)
    before = check_trajectory(q, dt, limits)
    if mode == "reject":
        if not before.ok:
            raise UnsafeTrajectoryError(before)
        return DancePlayback(q, float(fps), mode, before, before)
    clipped = clip_trajectory(q, dt, limits)
    after = check_trajectory(clipped, dt, limits)
    dev = np.abs(clipped - q).max(axis=1)
    notes = [] if after.ok else [f"still unsafe after clipping: {after.summary()}"]
    return DancePlayback(
        clipped, float(fps), mode, before, after, int((dev > 1e-9).sum()), float(dev.max()), notes
    )
