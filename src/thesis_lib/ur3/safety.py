"""Joint, speed and workspace limits of the UR3, and checking (or clipping) a trajectory against them.

A trajectory is ``(T, 6)`` joint angles in radians sampled every ``dt`` seconds. Three checks:

* **position**: every angle inside :data:`~thesis_lib.ur3.model.POSITION_LIMITS`;
* **speed**: ``|q[t+1] - q[t]| / dt`` at most ``speed_scale x`` :data:`~thesis_lib.ur3.model.MAX_SPEED`
  (and, when the robot's current angles are given, the first step from them too);
* **workspace**: the tool flange inside a sphere of ``reach`` metres around the shoulder and at
  least ``tcp_z_min`` above the table, every joint origin above ``link_z_min`` (forward
  kinematics of :mod:`thesis_lib.ur3.model`).

:func:`check_trajectory` reports; :func:`clip_trajectory` clamps positions and rate-limits
speeds (it cannot repair a workspace violation, which it leaves in the report). The dance
playback clips; the driver refuses (:class:`thesis_lib.ur3.driver.UR3Driver`).

Used in: UR3 deployment chapter (dance playback, robot driver).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .model import MAX_SPEED, POSITION_LIMITS, UR3Kinematics

__all__ = [
    "SafetyLimits",
    "SafetyReport",
    "UnsafeTrajectoryError",
    "check_trajectory",
    "clip_trajectory",
]


class UnsafeTrajectoryError(ValueError):
    """A trajectory breaks a joint, speed or workspace limit; ``.report`` says which and where."""

    def __init__(self, report: SafetyReport) -> None:
        super().__init__(f"Refused: {report.summary()}")
        self.report = report


@dataclass(frozen=True)
class SafetyLimits:
    """What a trajectory must respect (defaults: the UR3 data sheet, full speed, a table at z = 0).

    Used in: UR3 deployment chapter.
    """

    position: np.ndarray = field(default_factory=lambda: POSITION_LIMITS.copy())
    """``(6, 2)`` joint position limits (rad)."""
    max_speed: np.ndarray = field(default_factory=lambda: MAX_SPEED.copy())
    """``(6,)`` maximum joint speeds (rad/s)."""
    speed_scale: float = 1.0
    """Allowed fraction of ``max_speed`` (a lab would start lower, e.g. 0.25)."""
    reach: float = 0.65
    """Tool flange at most this far from the shoulder (frame 1, 0.1519 m above the base), in m.
    The arm's own reach is about 0.62 m; set less to fence the arm in."""
    tcp_z_min: float = 0.03
    """Tool flange at least this high above the table (m)."""
    link_z_min: float = 0.0
    """Every joint origin at least this high (m)."""

    def __post_init__(self) -> None:
        pos = np.asarray(self.position, dtype=np.float64)
        spd = np.asarray(self.max_speed, dtype=np.float64)
        if pos.shape != (6, 2) or np.any(pos[:, 0] >= pos[:, 1]):
            raise ValueError(
                f"Expect position limits of shape (6, 2) with low < high, got {pos.tolist()}."
            )
        if spd.shape != (6,) or np.any(spd <= 0):
            raise ValueError(f"Expect 6 positive maximum speeds, got {spd.tolist()}.")
        if not 0 < self.speed_scale <= 1:
            raise ValueError(f"Expect 0 < speed_scale <= 1, got {self.speed_scale}.")
        object.__setattr__(self, "position", pos)
        object.__setattr__(self, "max_speed", spd)

    @property
    def speed(self) -> np.ndarray:
        """``(6,)`` allowed speeds: ``speed_scale * max_speed``."""
        return self.speed_scale * self.max_speed


@dataclass
class SafetyReport:
    """Where a trajectory breaks the limits.

    Attributes:
        n_frames: frames checked.
        position_frames: frame indices with an angle outside the limits.
        speed_frames: frame indices ``t`` whose move from ``t - 1`` (or from the current angles
            at ``t = 0``) is too fast.
        workspace_frames: frame indices whose arm leaves the workspace.
        max_speed_ratio: the largest ``speed / allowed speed`` over joints and frames.
        min_tcp_z: the lowest tool-flange height (m).
    """

    n_frames: int
    position_frames: np.ndarray
    speed_frames: np.ndarray
    workspace_frames: np.ndarray
    max_speed_ratio: float
    min_tcp_z: float

    @property
    def ok(self) -> bool:
        """No violation of any kind."""
        return not (
            len(self.position_frames) or len(self.speed_frames) or len(self.workspace_frames)
        )

    def counts(self) -> dict[str, int]:
        """Frames violating each limit."""
        return {
            "position": len(self.position_frames),
            "speed": len(self.speed_frames),
            "workspace": len(self.workspace_frames),
        }

    def summary(self) -> str:
        """One line: what is violated, how often, where first."""
        if self.ok:
            return f"{self.n_frames} frames within the joint, speed and workspace limits."
        parts = []
        for name, frames in (
            ("joint limits", self.position_frames),
            ("speed limits", self.speed_frames),
            ("workspace", self.workspace_frames),
        ):
            if len(frames):
                parts.append(
                    f"{name} broken in {len(frames)} of {self.n_frames} frames (first at frame {int(frames[0])})"
                )
        extra = (
            f"; peak speed {self.max_speed_ratio:.2f}x the allowed"
            if len(self.speed_frames)
            else ""
        )
        return "; ".join(parts) + extra + "."


def as_angle_frames(q: np.ndarray, n_joints: int = 6, what: str = "a trajectory") -> np.ndarray:
    """``q`` as a float ``(T, n_joints)`` array of radians with ``T >= 1`` and no NaN/inf, or a
    ``ValueError`` that names ``what`` and the first bad frame. The one input check of the UR3
    code (trajectories, dance angles)."""
    q = np.asarray(q, dtype=np.float64)
    if q.ndim != 2 or q.shape[1] != n_joints:
        raise ValueError(f"Expect {what} of shape (T, {n_joints}) in radians, got {q.shape}.")
    if len(q) == 0:
        raise ValueError(f"Expect {what} with at least one frame, got 0.")
    if not np.all(np.isfinite(q)):
        bad = int(np.flatnonzero(~np.isfinite(q).all(axis=1))[0])
        raise ValueError(f"Found NaN or inf in {what}, first at frame {bad}.")
    return q


def _as_traj(q: np.ndarray) -> np.ndarray:
    return as_angle_frames(q, 6, "a trajectory")


def _check_dt(dt: float) -> float:
    if not (np.isfinite(dt) and dt > 0):
        raise ValueError(f"Expect a positive time step dt in seconds, got {dt}.")
    return float(dt)


def check_trajectory(
    q: np.ndarray, dt: float, limits: SafetyLimits | None = None, current: np.ndarray | None = None
) -> SafetyReport:
    """Check a ``(T, 6)`` trajectory sampled every ``dt`` s against ``limits``.

    Args:
        q: joint angles (rad).
        dt: seconds between frames (``1 / fps``).
        limits: default :class:`SafetyLimits`.
        current: the robot's angles now ``(6,)``; the move to ``q[0]`` is then checked too.

    Returns:
        The :class:`SafetyReport`.

    Used in: UR3 deployment chapter.
    """
    q, dt, lim = _as_traj(q), _check_dt(dt), limits or SafetyLimits()
    pos_bad = np.flatnonzero(((q < lim.position[:, 0]) | (q > lim.position[:, 1])).any(axis=1))
    prev = np.vstack(
        [q[:1] if current is None else np.asarray(current, dtype=np.float64).reshape(1, 6), q[:-1]]
    )
    ratio = np.abs(q - prev) / dt / lim.speed  # (T, 6)
    spd_bad = np.flatnonzero((ratio > 1.0 + 1e-9).any(axis=1))
    kin = UR3Kinematics()
    pts = kin.points_trajectory(q)  # (T, 8, 3): base, joint origins, flange
    tcp = pts[:, -1]
    shoulder = pts[:, 2]
    ws = (
        (np.linalg.norm(tcp - shoulder, axis=1) > lim.reach)
        | (tcp[:, 2] < lim.tcp_z_min)
        | (pts[:, 2:-1, 2] < lim.link_z_min).any(axis=1)
    )
    return SafetyReport(
        len(q), pos_bad, spd_bad, np.flatnonzero(ws), float(ratio.max()), float(tcp[:, 2].min())
    )


def clip_trajectory(
    q: np.ndarray, dt: float, limits: SafetyLimits | None = None, current: np.ndarray | None = None
) -> np.ndarray:
    """Clamp ``q`` into the joint limits, then rate-limit it to the allowed speeds.

    The rate limiter follows the clamped trajectory as closely as the speed allows
    (``x[t] = x[t-1] + clip(q[t] - x[t-1], ±speed·dt)``), so a fast move lags and catches up.
    Workspace violations are not repaired: check the result with :func:`check_trajectory`.

    Returns:
        ``(T, 6)`` the clipped trajectory.

    >>> clip_trajectory(np.array([[0.0] * 6, [1.0] * 6]), dt=0.1)[1].round(3).tolist()
    [0.314, 0.314, 0.314, 0.628, 0.628, 0.628]
    """
    q, dt, lim = _as_traj(q), _check_dt(dt), limits or SafetyLimits()
    q = np.clip(q, lim.position[:, 0], lim.position[:, 1])
    step = lim.speed * dt * (1 - 1e-9)
    out = np.empty_like(q)
    x = q[0] if current is None else np.asarray(current, dtype=np.float64).reshape(6)
    for t in range(len(q)):
        x = x + np.clip(q[t] - x, -step, step)
        out[t] = x
    return out
