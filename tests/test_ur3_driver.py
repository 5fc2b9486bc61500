"""The robot driver: dry-run, refusal of unsafe motion, emergency stop, a fake UR endpoint on localhost.

Threads here synchronise on events (what was received, which frame was reached); the timeouts are
only a safety net so that a broken driver fails the test instead of hanging it.
"""

from __future__ import annotations

import socket
import threading

import numpy as np
import pytest

from thesis_lib.ur3.driver import RobotStopped, SimBackend, UR3Driver, URScriptBackend
from thesis_lib.ur3.reach import HOME
from thesis_lib.ur3.safety import SafetyLimits, UnsafeTrajectoryError


class FakeUR:
    """A TCP server on localhost that records every byte a client sends (the UR's secondary interface)."""

    def __init__(self) -> None:
        self.server = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
        self.server.bind(("127.0.0.1", 0))
        self.server.listen(1)
        self.port = self.server.getsockname()[1]
        self.received = b""
        self.connections = 0
        self._changed = threading.Condition()
        self._thread = threading.Thread(target=self._serve, daemon=True)
        self._thread.start()

    def _serve(self) -> None:
        self.server.settimeout(10)
        try:
            conn, _ = self.server.accept()
        except OSError:
            return
        with self._changed:
            self.connections += 1
            self._changed.notify_all()
        with conn:
            conn.settimeout(10)
            while True:
                try:
                    chunk = conn.recv(65536)
                except OSError:
                    return
                if not chunk:
                    return
                with self._changed:
                    self.received += chunk
                    self._changed.notify_all()

    def text(self, until: str, timeout: float = 10.0) -> str:
        """Everything received once it ends with ``until`` (the client's last command)."""
        with self._changed:
            done = self._changed.wait_for(
                lambda: self.received.decode().endswith(until), timeout=timeout
            )
        text = self.received.decode()
        assert done, f"the fake robot never received {until!r}; it got {text!r}"
        return text

    def close(self) -> None:
        self.server.close()


@pytest.fixture
def fake_ur():
    srv = FakeUR()
    yield srv
    srv.close()


def _wave(n: int = 20, amp: float = 0.2, fps: float = 50.0) -> np.ndarray:
    t = np.arange(n) / fps
    q = np.tile(HOME, (n, 1))
    q[:, 0] += amp * np.sin(2 * np.pi * t)
    return q


def test_sim_driver_is_dry_run_by_default():
    backend = SimBackend()
    drv = UR3Driver(backend)
    res = drv.play(_wave(), fps=50)
    assert res.dry_run and res.frames_sent == 0 and not backend.history
    assert drv.log[0].startswith("dry-run: movej")
    res = UR3Driver(backend, dry_run=False).play(_wave(), fps=50)
    assert res.frames_sent == 20 and len(backend.history) > 20
    np.testing.assert_allclose(backend.q, _wave()[-1])


def test_unsafe_trajectories_are_refused_and_nothing_moves():
    backend = SimBackend()
    drv = UR3Driver(backend, dry_run=False)
    fast = _wave(amp=2.0)  # 2 rad x 2 pi rad/s on the base: 4 times its limit
    with pytest.raises(UnsafeTrajectoryError, match="speed limits broken"):
        drv.play(fast, fps=50)
    beyond = _wave()
    beyond[5, 2] = 7.0
    with pytest.raises(UnsafeTrajectoryError, match="joint limits broken in 1 of 20 frames"):
        drv.play(beyond, dt=10.0)
    floor = np.tile(np.array([0.0, 0.3, 0.0, 0.0, 0.0, 0.0]), (3, 1))  # flange below the table
    with pytest.raises(UnsafeTrajectoryError, match="workspace"):
        drv.play(floor, fps=50)
    assert not backend.history and "refused" in drv.log[-1]
    # a slower speed scale refuses what full speed allows
    slow = UR3Driver(
        SimBackend(), limits=SafetyLimits(speed_scale=0.25), dry_run=False, approach_speed=0.5
    )
    with pytest.raises(UnsafeTrajectoryError):
        slow.play(_wave(amp=0.2, fps=50), fps=50)  # 1.26 rad/s > 0.785


class PausingSim(SimBackend):
    """The simulated UR3, which at its ``pause_at``-th streamed frame says so (``reached``) and
    holds that frame until the test lets it go on (``resume``): a robot still moving when the
    operator presses the emergency stop, with no clock in the test."""

    def __init__(self, pause_at: int) -> None:
        super().__init__()
        self.pause_at = pause_at
        self.reached = threading.Event()
        self.resume = threading.Event()
        self._streaming = False
        self._streamed = 0
        forward = self.kin.forward

        def forward_and_count(q):
            out = forward(q)
            if self._streaming:
                self._streamed += 1
                if self._streamed == self.pause_at:
                    self.reached.set()
                    self.resume.wait(timeout=10)
            return out

        self.kin.forward = forward_and_count

    def stream(self, q, dt, stop):
        self._streaming = True
        try:
            return super().stream(q, dt, stop)
        finally:
            self._streaming = False


def test_emergency_stop_halts_streaming_and_blocks_motion():
    backend = PausingSim(pause_at=10)
    drv = UR3Driver(backend, dry_run=False)
    q = _wave(n=200, amp=0.1, fps=50)

    def operator():  # another thread presses the stop while frame 10 is being played
        if backend.reached.wait(timeout=10):
            drv.emergency_stop()
        backend.resume.set()

    stopper = threading.Thread(target=operator)
    stopper.start()
    res = drv.play(q, fps=50)
    stopper.join(timeout=10)
    assert backend.reached.is_set() and not stopper.is_alive()
    # the stream halts at the next frame after the stop: exactly the 10 frames played so far
    assert res.stopped and res.frames_sent == 10 and backend.stopped
    assert len(backend.history) >= 10 and np.allclose(backend.q, q[9])
    with pytest.raises(RobotStopped):
        drv.play(q, fps=50)
    drv.clear_stop()
    assert not drv.stopped


def test_urscript_backend_against_fake_robot(fake_ur):
    backend = URScriptBackend("127.0.0.1", fake_ur.port)
    q = _wave(n=5)
    # dry-run: no connection at all
    UR3Driver(backend).play(q, fps=50)
    assert fake_ur.connections == 0
    # the current angles are unknown over URScript: the approach must be allowed explicitly
    drv = UR3Driver(backend, dry_run=False)
    with pytest.raises(ValueError, match="cannot read the robot's joint angles"):
        drv.play(q, fps=50)
    res = drv.play(q, fps=50, current=HOME)
    drv.emergency_stop()
    text = fake_ur.text(until="stopj(4.0)\n")
    lines = text.splitlines()
    assert lines[0].startswith("movej([") and "v=0.5000" in lines[0]
    assert (
        lines[1] == "def thesis_play():"
        and sum(line.strip().startswith("servoj(") for line in lines) == 5
    )
    first = [float(x) for x in lines[2].split("[")[1].split("]")[0].split(",")]
    np.testing.assert_allclose(first, q[0], atol=1e-6)
    assert "t=0.020000" in lines[2] and lines[-1] == "stopj(4.0)"
    assert res.frames_sent == 5
    drv.close()


def test_urscript_unsafe_sends_nothing(fake_ur):
    drv = UR3Driver(URScriptBackend("127.0.0.1", fake_ur.port), dry_run=False)
    with pytest.raises(UnsafeTrajectoryError):
        drv.play(_wave(amp=3.0), fps=50, current=HOME)
    assert fake_ur.connections == 0 and fake_ur.received == b""


def test_driver_argument_errors():
    with pytest.raises(ValueError, match="approach_speed"):
        UR3Driver(approach_speed=10.0)
    drv = UR3Driver()
    with pytest.raises(ValueError, match="exactly one of dt"):
        drv.play(_wave(), dt=0.1, fps=10)


def test_ur3_play_reads_the_csv_that_mdlt_dance_writes(tmp_path):
    """`thesis mdlt dance --out` writes time_s + four angles; `thesis ur3 play` takes that file as is."""
    import pandas as pd

    from thesis_lib.cli.ur3 import read_angles
    from thesis_lib.mdlt.translate import JOINT_COLUMNS

    t = np.arange(30) / 60
    angles = np.stack([0.1 * np.sin(t + k) for k in range(4)], axis=1)
    path = tmp_path / "angles.csv"
    pd.DataFrame({"time_s": t, **{c: angles[:, j] for j, c in enumerate(JOINT_COLUMNS)}}).to_csv(
        path, index=False
    )
    np.testing.assert_allclose(read_angles(path), angles)
    np.savetxt(tmp_path / "plain.csv", angles, delimiter=",")
    np.testing.assert_allclose(read_angles(tmp_path / "plain.csv"), angles)
    pd.DataFrame(angles[:, :3]).to_csv(tmp_path / "bad.csv", index=False)
    with pytest.raises(ValueError, match="4 \\(MDLT angles\\) or 6"):
        read_angles(tmp_path / "bad.csv")
