"""Shared test settings."""
from __future__ import annotations

import pytest


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
