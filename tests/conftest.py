"""Shared test settings."""

from __future__ import annotations

import os

import pytest

# MuJoCo picks its OpenGL backend when it is first imported; offscreen rendering (CLfD cameras,
# UR3 frames) needs EGL on a headless machine, whichever test module imports mujoco first.
os.environ.setdefault("MUJOCO_GL", "egl")


@pytest.fixture(autouse=True, scope="session")
def _one_torch_thread():
    """Small models run faster on one thread, and a busy 2-core CI machine has no spare core."""
    try:
        import torch
    except ImportError:  # pragma: no cover - torch is in requirements.txt
        yield
        return
    n = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(n)
