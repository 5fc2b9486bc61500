"""Shared test settings."""

from __future__ import annotations

import os

import pytest

from thesis_lib.chapters import CHAPTERS

# MuJoCo picks its OpenGL backend when it is first imported; offscreen rendering (CLfD cameras,
# UR3 frames) needs EGL on a headless machine, whichever test module imports mujoco first.
os.environ.setdefault("MUJOCO_GL", "egl")


# --- the system temp dir is left as it was found (issue #37) ------------------------------------
# The whole run (this process, the kernels and workers it starts: they inherit TMPDIR) writes its
# temporary files into one private folder. At the end, anything left there but pytest's own
# tmp_path folders and torch's compile cache fails the run, with the names; otherwise the folder
# is removed, so `make test` leaves nothing behind in the system temp dir.
_TEMP_ALLOWED = ("pytest-of-", "torchinductor_")


def pytest_configure(config):
    import tempfile

    if os.environ.get("THESIS_TEST_TMPDIR"):  # a nested pytest (a test that runs pytest)
        return
    private = tempfile.mkdtemp(prefix="thesis-tests-")
    os.environ["TMPDIR"] = os.environ["THESIS_TEST_TMPDIR"] = private
    tempfile.tempdir = None  # gettempdir() reads TMPDIR again
    config.stash[_TEMP_KEY] = private


_TEMP_KEY = pytest.StashKey[str]()


def pytest_sessionfinish(session, exitstatus):
    import shutil
    from pathlib import Path

    private = session.config.stash.get(_TEMP_KEY, None)
    if private is None:
        return
    left = sorted(
        str(p.relative_to(private))
        for p in Path(private).iterdir()
        if not p.name.startswith(_TEMP_ALLOWED)
    )
    if left:
        print(f"\nThe tests left {len(left)} entries in their temp dir {private}: {left[:20]}")
        session.exitstatus = pytest.ExitCode.TESTS_FAILED
    elif exitstatus == 0:
        shutil.rmtree(private, ignore_errors=True)


def pytest_collection_modifyitems(session, config, items):
    """The chapters' smoke runs (``test_chapters.py``, about half of `make test`'s CPU, run two at a
    time by one worker) come first, so that they start at once rather than after the worker's
    earlier files; with ``--dist loadfile --no-loadscope-reorder`` (the Makefile's), xdist hands
    out the files in this order. The rest keep pytest's order."""
    items.sort(key=lambda item: 0 if item.nodeid.startswith("tests/test_chapters.py") else 1)


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
        ev = evi.load_evidence(CHAPTERS[chapter], reps=100)
        assert "not run yet" in evi.status_line(ev) and ev.rows.empty
        assert set(evi.comparisons_table(ev).verdict) == {"pending"}
        return ev

    return load
