"""``thesis_lib._io``: a reader never sees half a file, a failed write changes nothing, and a
locked piece of work is done by one process at a time."""

from __future__ import annotations

import os
import threading
import time
from pathlib import Path

import numpy as np
import pytest

from thesis_lib._io import atomic_write


def test_writes_the_content_and_leaves_only_the_destination(tmp_path):
    dest = tmp_path / "sub" / "rec.json"  # the folder is made
    assert atomic_write(dest, lambda p: p.write_text('{"a": 1}')) == dest
    assert dest.read_text() == '{"a": 1}'
    assert [p.name for p in dest.parent.iterdir()] == ["rec.json"]
    umask = os.umask(0)
    os.umask(umask)
    assert dest.stat().st_mode & 0o777 == 0o666 & ~umask  # as a plain open(), not mkstemp's 0600


def test_a_failed_write_keeps_the_previous_file_and_removes_its_temporary(tmp_path):
    dest = tmp_path / "ckpt.pt"
    dest.write_bytes(b"old")

    def half_then_crash(p: Path) -> None:
        p.write_bytes(b"ne")
        raise KeyboardInterrupt  # a session killed mid-write

    with pytest.raises(KeyboardInterrupt):
        atomic_write(dest, half_then_crash)
    assert dest.read_bytes() == b"old"
    assert [p.name for p in tmp_path.iterdir()] == ["ckpt.pt"]


def test_the_temporary_file_is_invisible_to_a_suffix_listing(tmp_path):
    """The sweep store lists ``*.json``: a write in progress must not show up as a task."""
    seen: list[list[str]] = []

    def save(p: Path) -> None:
        p.write_text("{}")
        seen.append(sorted(x.name for x in tmp_path.glob("*.json")))

    atomic_write(tmp_path / "k.json", save)
    assert seen == [[]]


def test_keep_suffix_lets_numpy_write_exactly_the_temporary_path(tmp_path):
    x = np.arange(6.0).reshape(2, 3)
    atomic_write(tmp_path / "f.npy", lambda p: np.save(p, x), keep_suffix=True)
    atomic_write(tmp_path / "d.npz", lambda p: np.savez(p, x=x), keep_suffix=True)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["d.npz", "f.npy"]  # no f.tmp.npy.npy
    np.testing.assert_array_equal(np.load(tmp_path / "f.npy"), x)
    np.testing.assert_array_equal(np.load(tmp_path / "d.npz")["x"], x)


def test_concurrent_writers_of_one_file_each_rename_a_complete_copy(tmp_path):
    """Two study workers building the same demonstration set at once (the race that stopped
    the 03 study): neither fails, and the file is one writer's whole content."""
    dest = tmp_path / "set.bin"
    barrier = threading.Barrier(4)
    errors: list[BaseException] = []

    def worker(i: int) -> None:
        def save(p: Path) -> None:
            barrier.wait()  # all four hold a temporary file at the same moment
            p.write_bytes(bytes([i]) * 100_000)

        try:
            atomic_write(dest, save)
        except BaseException as e:  # pragma: no cover - the failure this test looks for
            errors.append(e)

    threads = [threading.Thread(target=worker, args=(i,)) for i in range(4)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert errors == []
    data = dest.read_bytes()
    assert len(data) == 100_000 and len(set(data)) == 1
    assert [p.name for p in tmp_path.iterdir()] == ["set.bin"]


def _hold(path, held, log):
    from thesis_lib._io import file_lock

    with file_lock(path):
        held.set()
        time.sleep(0.3)
        log.put(("released", time.monotonic()))


def test_file_lock_makes_a_second_process_wait_for_the_first(tmp_path):
    import multiprocessing as mp

    from thesis_lib._io import file_lock

    ctx = mp.get_context("fork")
    held, log = ctx.Event(), ctx.Queue()
    lock = tmp_path / "new" / ".task.lock"  # its folder is made
    p = ctx.Process(target=_hold, args=(lock, held, log))
    p.start()
    assert held.wait(10)
    with file_lock(lock):
        got = time.monotonic()
    p.join(10)
    what, released = log.get(timeout=5)
    assert what == "released" and got >= released
    with pytest.raises(ValueError), file_lock(lock):  # the lock is let go on an error too
        raise ValueError
    with file_lock(lock):
        pass
