"""One robot interface for the simulated UR3 and a real one: dry-run by default, refuses unsafe motion.

:class:`UR3Driver` checks every trajectory against :class:`~thesis_lib.ur3.safety.SafetyLimits`
(joints, speeds, workspace, and the approach from the robot's current angles) and **refuses**
one that breaks them (:class:`~thesis_lib.ur3.safety.UnsafeTrajectoryError`; nothing is sent).
In **dry-run** mode (the default) it checks and logs what it would send, and sends nothing.
:meth:`UR3Driver.emergency_stop` always goes through, also in dry-run, also while a trajectory
is streaming (from another thread or a ``KeyboardInterrupt``), and blocks further motion until
:meth:`UR3Driver.clear_stop`.

Backends (same methods, so a policy or a dance runs unchanged on either):

* :class:`SimBackend`: the MuJoCo UR3 model, kinematic; records every frame it is sent.
* :class:`URScriptBackend`: plain URScript over TCP to the controller's secondary interface
  (port 30002): ``movej`` for the approach, one ``servoj`` program for the trajectory,
  ``stopj`` to stop. Standard library only. It cannot read the robot's angles: pass
  ``current=`` to :meth:`UR3Driver.play` (from the pendant) or allow an unchecked approach.
* :class:`RTDEBackend`: ``ur_rtde`` (optional: ``pip install ur_rtde``), real-time RTDE
  ``moveJ``/``servoJ`` at the trajectory's rate, ``getActualQ`` for the current angles,
  ``servoStop``/``stopJ``/``triggerProtectiveStop`` for stopping.

A lab with a UR3: start with ``SafetyLimits(speed_scale=0.25)``, ``dry_run=True``, read the
log, then ``dry_run=False`` with a hand on the pendant's emergency stop.

Used in: UR3 deployment chapter (robot interface).
"""

from __future__ import annotations

import socket
import threading
import time
from dataclasses import dataclass, field
from typing import Any, Protocol

import numpy as np

from .model import UR3Kinematics
from .reach import HOME
from .safety import SafetyLimits, SafetyReport, UnsafeTrajectoryError, check_trajectory

__all__ = [
    "PlayResult",
    "RTDEBackend",
    "RobotBackend",
    "RobotStopped",
    "SimBackend",
    "UR3Driver",
    "URScriptBackend",
]


class RobotStopped(RuntimeError):
    """The driver is stopped (emergency stop): clear it with ``UR3Driver.clear_stop()``."""


class RobotBackend(Protocol):
    """What :class:`UR3Driver` needs from a robot (simulated or real)."""

    name: str

    def connect(self) -> None: ...
    def joint_positions(self) -> np.ndarray | None: ...
    def move_to(self, q: np.ndarray, speed: float, acceleration: float) -> None: ...
    def stream(self, q: np.ndarray, dt: float, stop: threading.Event) -> int: ...
    def stop(self) -> None: ...
    def close(self) -> None: ...


def _fmt(q: np.ndarray) -> str:
    return "[" + ", ".join(f"{x:.6f}" for x in np.asarray(q, dtype=np.float64)) + "]"


class SimBackend:
    """The simulated UR3 (kinematic MuJoCo model): takes every frame as commanded and records it.

    Args:
        q0: initial joint angles (default :data:`~thesis_lib.ur3.reach.HOME`).
        realtime: sleep ``dt`` between streamed frames (off: as fast as possible).
    """

    name = "sim"

    def __init__(self, q0: np.ndarray | None = None, realtime: bool = False) -> None:

        self.kin = UR3Kinematics()
        self.q = np.array(HOME if q0 is None else q0, dtype=np.float64)
        self.realtime = realtime
        self.history: list[np.ndarray] = []
        self.stopped = False

    def connect(self) -> None:
        return None

    def joint_positions(self) -> np.ndarray:
        return self.q.copy()

    def move_to(self, q: np.ndarray, speed: float, acceleration: float) -> None:
        del acceleration
        q = np.asarray(q, dtype=np.float64)
        n = max(
            1, int(np.ceil(np.abs(q - self.q).max() / max(speed, 1e-9) / 0.01))
        )  # 100 Hz interpolation
        for s in np.linspace(0, 1, n + 1)[1:]:
            self.history.append(self.q + s * (q - self.q))
        self.q = q.copy()
        self.kin.forward(self.q)

    def stream(self, q: np.ndarray, dt: float, stop: threading.Event) -> int:
        sent = 0
        for x in np.asarray(q, dtype=np.float64):
            if stop.is_set():
                break
            self.q = x.copy()
            self.kin.forward(self.q)
            self.history.append(self.q.copy())
            sent += 1
            if self.realtime:
                time.sleep(dt)
        return sent

    def stop(self) -> None:
        self.stopped = True

    def close(self) -> None:
        return None


class URScriptBackend:
    """URScript text over TCP (the UR controller's secondary interface, port 30002).

    Args:
        host: the controller's address.
        port: 30002 (secondary) or 30003 (real-time); both accept URScript.
        timeout: socket timeout in seconds.
        lookahead_time, gain: ``servoj`` smoothing parameters (URScript's defaults 0.1, 300).
    """

    name = "urscript"

    def __init__(
        self,
        host: str,
        port: int = 30002,
        timeout: float = 5.0,
        lookahead_time: float = 0.1,
        gain: float = 300.0,
    ) -> None:
        self.host, self.port, self.timeout = host, int(port), float(timeout)
        self.lookahead_time, self.gain = float(lookahead_time), float(gain)
        self.sock: socket.socket | None = None
        self._lock = threading.Lock()

    def connect(self) -> None:
        if self.sock is None:
            self.sock = socket.create_connection((self.host, self.port), timeout=self.timeout)

    def _send(self, text: str) -> None:
        self.connect()
        assert self.sock is not None
        with self._lock:
            self.sock.sendall(text.encode("utf-8"))

    def joint_positions(self) -> None:
        return None  # the secondary interface's binary state stream is not parsed here

    def move_to(self, q: np.ndarray, speed: float, acceleration: float) -> None:
        self._send(f"movej({_fmt(q)}, a={acceleration:.4f}, v={speed:.4f})\n")

    def program(self, q: np.ndarray, dt: float) -> str:
        """The URScript program that servos through ``q`` every ``dt`` s (what :meth:`stream` sends)."""
        lines = ["def thesis_play():"]
        lines += [
            f"  servoj({_fmt(x)}, t={dt:.6f}, lookahead_time={self.lookahead_time:.3f}, gain={self.gain:.0f})"
            for x in np.asarray(q, dtype=np.float64)
        ]
        lines += ["  stopj(2.0)", "end", "thesis_play()", ""]
        return "\n".join(lines)

    def stream(self, q: np.ndarray, dt: float, stop: threading.Event) -> int:
        if stop.is_set():
            return 0
        self._send(self.program(q, dt))
        return len(q)

    def stop(self) -> None:
        self._send("stopj(4.0)\n")

    def close(self) -> None:
        if self.sock is not None:
            self.sock.close()
            self.sock = None


class RTDEBackend:
    """A real UR through ``ur_rtde`` (optional dependency; imported on :meth:`connect`)."""

    name = "rtde"

    def __init__(
        self, host: str, frequency: float = 125.0, lookahead_time: float = 0.1, gain: float = 300.0
    ) -> None:
        self.host, self.frequency = host, float(frequency)
        self.lookahead_time, self.gain = float(lookahead_time), float(gain)
        self.control: Any = None
        self.receive: Any = None

    def connect(self) -> None:
        if self.control is not None:
            return
        try:
            import rtde_control
            import rtde_receive
        except ImportError as err:
            raise ImportError(
                "RTDEBackend needs ur_rtde: pip install ur_rtde (or use URScriptBackend)."
            ) from err
        self.control = rtde_control.RTDEControlInterface(self.host)
        self.receive = rtde_receive.RTDEReceiveInterface(self.host)

    def joint_positions(self) -> np.ndarray:
        self.connect()
        return np.asarray(self.receive.getActualQ(), dtype=np.float64)

    def move_to(self, q: np.ndarray, speed: float, acceleration: float) -> None:
        self.connect()
        self.control.moveJ(list(map(float, q)), speed, acceleration)

    def stream(self, q: np.ndarray, dt: float, stop: threading.Event) -> int:
        self.connect()
        sent = 0
        for x in np.asarray(q, dtype=np.float64):
            if stop.is_set():
                break
            t0 = self.control.initPeriod()
            self.control.servoJ(list(map(float, x)), 0.0, 0.0, dt, self.lookahead_time, self.gain)
            self.control.waitPeriod(t0)
            sent += 1
        self.control.servoStop()
        return sent

    def stop(self) -> None:
        if self.control is None:
            return
        try:
            self.control.servoStop()
            self.control.stopJ(4.0)
        finally:
            self.control.triggerProtectiveStop()

    def close(self) -> None:
        if self.control is not None:
            self.control.stopScript()
            self.control.disconnect()
            self.receive.disconnect()
            self.control = self.receive = None


@dataclass
class PlayResult:
    """What :meth:`UR3Driver.play` did.

    Attributes:
        report: the safety check (approach included).
        dry_run: nothing was sent.
        frames_sent: trajectory frames handed to the backend.
        stopped: an emergency stop interrupted it.
        commands: what was (or, in dry-run, would have been) sent, one line per command.
    """

    report: SafetyReport
    dry_run: bool
    frames_sent: int = 0
    stopped: bool = False
    commands: list[str] = field(default_factory=list)


class UR3Driver:
    """The same interface for the simulated and a real UR3 (see the module docstring).

    Args:
        backend: a :class:`SimBackend` (default), :class:`URScriptBackend` or :class:`RTDEBackend`.
        limits: the limits every motion must respect.
        dry_run: check and log only, send nothing (default ``True``).
        approach_speed: joint speed (rad/s) of the ``movej`` to a trajectory's first frame.
        approach_acceleration: its acceleration (rad/s²).

    Used in: UR3 deployment chapter.
    """

    def __init__(
        self,
        backend: RobotBackend | None = None,
        limits: SafetyLimits | None = None,
        dry_run: bool = True,
        approach_speed: float = 0.5,
        approach_acceleration: float = 1.0,
    ) -> None:
        self.backend = backend if backend is not None else SimBackend()
        self.limits = limits or SafetyLimits()
        self.dry_run = bool(dry_run)
        if not 0 < approach_speed <= float(self.limits.speed.min()):
            raise ValueError(
                f"approach_speed must be in (0, {self.limits.speed.min():.3f}] rad/s, got {approach_speed}."
            )
        self.approach_speed, self.approach_acceleration = (
            float(approach_speed),
            float(approach_acceleration),
        )
        self.log: list[str] = []
        self._stop = threading.Event()

    # -- safety ---------------------------------------------------------------------------------
    @property
    def stopped(self) -> bool:
        """An emergency stop is in force."""
        return self._stop.is_set()

    def emergency_stop(self) -> None:
        """Stop now: sets the stop flag (a streaming loop halts at its next frame) and tells the backend.

        Works in dry-run too (it is always safe to stop); motion is refused until :meth:`clear_stop`.
        """
        self._stop.set()
        self.log.append("EMERGENCY STOP")
        try:
            if not self.dry_run or isinstance(self.backend, SimBackend):
                self.backend.stop()
        except OSError as err:  # the connection is gone: nothing more can be sent
            self.log.append(f"stop not delivered: {err}")

    def clear_stop(self) -> None:
        """Allow motion again after an emergency stop."""
        self._stop.clear()
        self.log.append("stop cleared")

    def current(self) -> np.ndarray | None:
        """The robot's joint angles, or ``None`` when the backend cannot tell."""
        if self.dry_run and not isinstance(self.backend, SimBackend):
            return None
        return self.backend.joint_positions()

    def check(self, q: np.ndarray, dt: float, current: np.ndarray | None = None) -> SafetyReport:
        """The safety check of a trajectory and, when the current angles are known, of its approach.

        The approach (a ``movej`` at ``approach_speed``) is checked as a straight joint-space
        path sampled every 10 ms, for the workspace; its speed is the driver's own.
        """
        q = np.atleast_2d(np.asarray(q, dtype=np.float64))
        report = check_trajectory(q, dt, self.limits)
        cur = current if current is not None else self.current()
        if cur is not None:
            cur = np.asarray(cur, dtype=np.float64).reshape(6)
            n = max(2, int(np.ceil(np.abs(q[0] - cur).max() / self.approach_speed / 0.01)) + 1)
            path = cur + np.linspace(0, 1, n)[:, None] * (q[0] - cur)
            approach = check_trajectory(path, 0.01, self.limits)
            if len(approach.workspace_frames) or len(approach.position_frames):
                report.workspace_frames = np.unique(
                    np.concatenate([[0], report.workspace_frames])
                ).astype(int)
        return report

    # -- motion ---------------------------------------------------------------------------------
    def move_to(self, q: np.ndarray, current: np.ndarray | None = None) -> PlayResult:
        """Move to one configuration at the approach speed (refused if it or the path is unsafe)."""
        return self.play(np.asarray(q, dtype=np.float64).reshape(1, 6), dt=1.0, current=current)

    def play(
        self,
        q: np.ndarray,
        dt: float | None = None,
        fps: float | None = None,
        current: np.ndarray | None = None,
        allow_unchecked_approach: bool = False,
    ) -> PlayResult:
        """Approach ``q[0]``, then stream ``q (T, 6)`` every ``dt`` s (or at ``fps``).

        Raises:
            UnsafeTrajectoryError: a joint, speed or workspace limit is broken (nothing sent).
            RobotStopped: an emergency stop is in force.
            ValueError: the current angles are unknown and ``allow_unchecked_approach`` is off.
        """
        if self.stopped:
            raise RobotStopped("Emergency stop in force: call clear_stop() before moving again.")
        if dt is not None and fps is None:
            dt = float(dt)
        elif dt is None and fps is not None:
            dt = 1.0 / float(fps)
        else:
            raise ValueError("Give exactly one of dt (seconds per frame) or fps.")
        q = np.atleast_2d(np.asarray(q, dtype=np.float64))
        cur = current if current is not None else self.current()
        if cur is None and not (self.dry_run or allow_unchecked_approach):
            raise ValueError(
                f"The {self.backend.name} backend cannot read the robot's joint angles, so the approach to the "
                "first frame cannot be checked. Pass current= (from the pendant) or allow_unchecked_approach=True."
            )
        report = self.check(q, dt, cur)
        if not report.ok:
            self.log.append(f"refused: {report.summary()}")
            raise UnsafeTrajectoryError(report)
        commands = [
            f"movej({_fmt(q[0])}, a={self.approach_acceleration:.4f}, v={self.approach_speed:.4f})"
        ]
        if len(q) > 1:
            commands.append(f"servoj x {len(q)} frames, t={dt:.6f}")
        if self.dry_run:
            self.log += [f"dry-run: {c}" for c in commands]
            return PlayResult(report, True, 0, False, commands)
        self.log += commands
        sent = 0
        try:
            self.backend.move_to(q[0], self.approach_speed, self.approach_acceleration)
            if len(q) > 1:
                sent = self.backend.stream(q, dt, self._stop)
        except BaseException:
            self.emergency_stop()
            raise
        return PlayResult(report, False, sent, self.stopped, commands)

    def close(self) -> None:
        """Close the backend's connection."""
        self.backend.close()

    def __enter__(self) -> UR3Driver:
        if not self.dry_run:
            self.backend.connect()
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        if exc_type is not None and not self.stopped:
            self.emergency_stop()
        self.close()
