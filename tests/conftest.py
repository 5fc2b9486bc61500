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


#: The CLfD chapter at its smallest: 3 demonstrations of 16-px frames, one TCN-style encoder
#: trained for one epoch, CLfD's DDPG+HER for a few 3-step episodes.
CLFD_TINY = dict(
    n_demos=3,
    image_size=16,
    encoders=["tcn"],
    methods=["clfd", "tcn"],
    epochs=1,
    eval_every=1,
    tcn_width=4,
    mlp_epochs=5,
    rl_methods=["clfd"],
    rl_steps=3,
)


@pytest.fixture
def clfd_tiny(tmp_path, monkeypatch):
    """:data:`CLFD_TINY`, with the data and results written under ``tmp_path``."""
    monkeypatch.setenv("THESIS_DATA_DIR", str(tmp_path))
    monkeypatch.setenv("THESIS_RESULTS_DIR", str(tmp_path / "results"))
    return dict(CLFD_TINY)


@pytest.fixture
def unstarted_study(tmp_path, monkeypatch):
    """``load(chapter)``: the chapter's :class:`~thesis_lib.book.evidence.Evidence` in a project
    that holds only its registered ``params/<chapter>.study.yml``, before any task ran (what a
    chapter's "Evidence at study scale" section renders before the study)."""
    from pathlib import Path

    import matplotlib

    matplotlib.use("Agg")
    from thesis_lib.book import evidence as evi

    repo = Path(__file__).resolve().parents[1]
    (tmp_path / "_toc.yml").write_text("root: intro\n")
    (tmp_path / "params").mkdir()
    monkeypatch.setenv("THESIS_PROJECT_ROOT", str(tmp_path))

    def load(chapter: str) -> evi.Evidence:
        name = f"{chapter}.study.yml"
        (tmp_path / "params" / name).write_text((repo / "params" / name).read_text())
        ev = evi.load_evidence(chapter, reps=100)
        assert "not run yet" in evi.status_line(ev) and ev.rows.empty
        assert set(evi.comparisons_table(ev).verdict) == {"pending"}
        return ev

    return load
