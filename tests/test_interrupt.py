"""Ctrl-C on ``thesis run`` interrupts the running cell (the kernel runs in its own session)."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import nbformat

LOOP = """
import pathlib, time
out = pathlib.Path("ticks")
out.mkdir(exist_ok=True)
for i in range(600):          # about a minute unless interrupted
    (out / f"{i:04d}").touch()
    time.sleep(0.1)
"""


def _project(root: Path) -> None:
    (root / "notebooks").mkdir()
    (root / "params").mkdir()
    (root / "_toc.yml").write_text(
        "format: jb-book\nroot: intro\nchapters:\n  - file: book/generated/demo\n"
    )
    nb = nbformat.v4.new_notebook()
    params = nbformat.v4.new_code_cell("n = 1")
    params.metadata["tags"] = ["parameters"]
    nb.cells = [params, nbformat.v4.new_code_cell(LOOP)]
    nb.metadata["kernelspec"] = {
        "name": "python3",
        "display_name": "Python 3",
        "language": "python",
    }
    nbformat.write(nb, root / "notebooks" / "demo.ipynb")
    (root / "params" / "demo.smoke.yml").write_text("n: 1\n")


def test_ctrl_c_stops_the_chapter_and_says_it_can_resume(tmp_path):
    _project(tmp_path)
    env = {**os.environ, "THESIS_PROJECT_ROOT": str(tmp_path)}
    proc = subprocess.Popen(
        [sys.executable, "-m", "thesis_lib.cli", "run", "demo", "--quiet"],
        cwd=tmp_path,
        env=env,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    ticks = tmp_path / "ticks"
    deadline = time.monotonic() + 120  # safety net only: the loop starts within seconds
    while not (ticks.is_dir() and len(list(ticks.iterdir())) >= 3):
        assert proc.poll() is None, proc.communicate()
        assert time.monotonic() < deadline, "the notebook never started"
        time.sleep(0.05)
    proc.send_signal(signal.SIGINT)  # what Ctrl-C in the terminal sends
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == 1
    assert "interrupted in cell" in err and "resumes" in err
    n = len(list(ticks.iterdir()))
    time.sleep(0.5)
    assert len(list(ticks.iterdir())) == n < 600  # the kernel stopped writing
