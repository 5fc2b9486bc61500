"""Every chapter runs at its smoke profile, writes its results, and the book builds with -W.

These are the slow tests (marked ``slow``): they execute notebooks through papermill exactly as
``make book`` does, into ``book/generated/``, with results redirected to a temporary folder.
"""

from __future__ import annotations

import json
import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import nbformat
import pytest

from thesis_lib.book import list_chapters, project_root, run_chapters
from thesis_lib.book.runner import GENERATED, build_book, start_order
from thesis_lib.chapters import CHAPTERS as REGISTRY

ROOT = project_root()
CHAPTERS = list_chapters(ROOT)


def test_committed_notebooks_carry_no_outputs():
    for path in sorted((ROOT / "notebooks").glob("*.ipynb")):
        nb = nbformat.read(path, as_version=4)
        for cell in nb.cells:
            if cell.cell_type == "code":
                assert not cell.outputs, f"{path.name}: strip outputs before committing"
                assert cell.execution_count is None, f"{path.name}: strip execution counts"
        tagged = [c for c in nb.cells if "parameters" in c.get("metadata", {}).get("tags", [])]
        assert len(tagged) == 1, f"{path.name} needs exactly one cell tagged 'parameters'"


def test_every_chapter_has_a_smoke_cost_and_the_longest_start_first():
    """``run_chapters`` starts the longest smoke runs first (``Chapter.smoke_s``), so that the
    book's and `make test`'s chapter runs do not end with one long chapter running alone."""
    assert set(CHAPTERS) <= set(REGISTRY)
    assert all(REGISTRY[c].smoke_s > 0 for c in CHAPTERS)
    order = start_order(CHAPTERS, REGISTRY)
    assert sorted(order) == sorted(CHAPTERS)
    costs = [REGISTRY[c].smoke_s for c in order]
    assert costs == sorted(costs, reverse=True)


@pytest.fixture(scope="session")
def executed(tmp_path_factory):
    """Run every chapter once (smoke profile, 2 processes), results into a temporary folder, with
    the system temp dir of the runs (``TMPDIR``: their kernels and the processes those start)
    pointed at an empty folder, for :func:`test_chapter_smoke_runs_leave_no_temp_files`."""
    import tempfile

    results = tmp_path_factory.mktemp("results")
    temp = tmp_path_factory.mktemp("system-temp")
    mp = pytest.MonkeyPatch()
    mp.setenv("THESIS_RESULTS_DIR", str(results))
    mp.setenv("TMPDIR", str(temp))
    mp.setattr(tempfile, "tempdir", None)  # this process reads TMPDIR again too
    try:
        runs = run_chapters(CHAPTERS, registry=REGISTRY, jobs=2, profile="smoke", root=ROOT)
    finally:
        mp.undo()
        tempfile.tempdir = None
    return {r.chapter: r for r in runs}, results, temp


#: What the temp dir may keep after a run: torch's compile cache (torch's, made on import of
#: its inductor, not our litter).
TEMP_ALLOWED = ("torchinductor_",)


@pytest.mark.slow
@pytest.mark.parametrize("chapter", CHAPTERS)
def test_chapter_smoke_run_writes_results(executed, chapter):
    runs, results, _ = executed
    run = runs[chapter]
    assert run.output == ROOT / GENERATED / f"{chapter}.ipynb"
    meta = json.loads((results / chapter / "run.json").read_text())
    assert meta["chapter"] == chapter and meta["artifacts"], "run.json lists what the chapter wrote"
    for name in meta["artifacts"]:
        assert (results / chapter / name).stat().st_size > 0
    assert meta["git_commit"] and meta["versions"]["numpy"]
    # No wall-clock assert: how long a smoke profile takes is reported by pytest's --durations
    # (pyproject addopts) and recorded in run.json, not judged by a test on a shared machine.
    assert run.wall_time_s >= 0 and meta["wall_time_s"] >= 0


@pytest.mark.slow
def test_chapter_smoke_runs_leave_no_temp_files(executed):
    """Issue #37: every chapter's smoke run leaves the system temp dir as it found it (it once left
    an ``ant_maze*.xml`` per Maze2D env made, 457 of them a ``make book``)."""
    temp = executed[2]
    left = sorted(
        str(p.relative_to(temp))
        for p in temp.rglob("*")
        if not p.relative_to(temp).parts[0].startswith(TEMP_ALLOWED)
    )
    assert left == [], f"{len(left)} files left in the temp dir: {left[:10]}"


@pytest.mark.slow
def test_book_builds_strict(executed):
    index = build_book(ROOT, strict=True)
    assert index.is_file()
    html = index.read_text()
    for chapter in CHAPTERS:
        page = ROOT / "_build" / "html" / GENERATED / f"{chapter}.html"
        assert page.is_file(), f"{chapter} missing from the built book"
        assert "<img" in page.read_text(), f"{chapter} shows no figure in the book"
    assert "book/intro.html" in html  # index.html redirects to the root page
    api = (ROOT / "_build" / "html" / "book" / "api.html").read_text()
    listed = re.findall(r"^\s+(thesis_lib\.\w+)\s*$", (ROOT / "book" / "api.md").read_text(), re.M)
    assert "thesis_lib.dtw" in listed and "thesis_lib.book" in listed
    for package in listed:  # the API reference documents each package's names by its path
        assert f'id="module-{package}"' in api, f"{package} missing from the API reference"
    assert 'id="thesis_lib.dtw.dtw"' in api and 'id="thesis_lib.seq.HDT"' in api
    intro = (ROOT / "_build" / "html" / "book" / "intro.html").read_text()
    assert "Improving the Robustness" in intro and "01_background.html" in intro


@pytest.mark.slow
def test_papermill_cli_rejects_unknown_parameter(tmp_path):
    """papermill alone injects any name; the notebook's config cell turns a typo into an error."""
    out = tmp_path / "out.ipynb"
    proc = subprocess.run(
        [
            sys.executable,
            "-m",
            "papermill",
            str(ROOT / "notebooks" / "survey.ipynb"),
            str(out),
            "-p",
            "tpo",
            "3",
            "--cwd",
            str(ROOT),
        ],
        capture_output=True,
        text=True,
    )
    assert proc.returncode != 0
    assert (
        "Unknown parameter 'tpo' for notebook survey. Did you mean: 'top'? Valid: top."
        in proc.stdout + proc.stderr
    )


def test_thesis_cli_rejects_unknown_parameter_before_running():
    proc = subprocess.run(
        [sys.executable, "-m", "thesis_lib.cli", "run", "survey", "-p", "tpo", "3"],
        capture_output=True,
        text=True,
        cwd=ROOT,
    )
    assert proc.returncode == 1
    assert "Unknown parameter 'tpo' for notebook survey. Did you mean: 'top'?" in proc.stderr


def _write_project(root: Path, source: str) -> None:
    """A minimal project: _toc.yml with one chapter 'demo', its notebook and smoke profile."""
    (root / "notebooks").mkdir()
    (root / "params").mkdir()
    (root / "_toc.yml").write_text(
        "format: jb-book\nroot: intro\nchapters:\n  - file: book/generated/demo\n"
    )
    nb = nbformat.v4.new_notebook()
    params = nbformat.v4.new_code_cell("n = 1")
    params.metadata["tags"] = ["parameters"]
    nb.cells = [params, nbformat.v4.new_code_cell(source)]
    nb.metadata["kernelspec"] = {
        "name": "python3",
        "display_name": "Python 3",
        "language": "python",
    }
    nbformat.write(nb, root / "notebooks" / "demo.ipynb")
    (root / "params" / "demo.smoke.yml").write_text("n: 1\n")


def test_failing_chapter_names_the_cell_and_the_notebook(tmp_path):
    from thesis_lib.book import ChapterFailed, run_chapter

    _write_project(tmp_path, "raise RuntimeError(f'boom {n}')")
    with pytest.raises(
        ChapterFailed, match=r"Chapter 'demo' failed in cell \d+ .*RuntimeError: boom 2"
    ):
        run_chapter("demo", {"n": 2}, root=tmp_path, progress=False)
    executed = nbformat.read(tmp_path / GENERATED / "demo.ipynb", as_version=4)
    assert any(
        o.get("ename") == "RuntimeError" for c in executed.cells for o in c.get("outputs", [])
    )
    with pytest.raises(ChapterFailed, match="boom 1"):
        run_chapters(["demo"], root=tmp_path)


def test_thesis_cli_reports_bad_input_in_one_line():
    proc = subprocess.run(
        [
            sys.executable,
            "-m",
            "thesis_lib.cli",
            "data",
            "generate",
            "--task",
            "hoper",
            "--tier",
            "medium",
        ],
        capture_output=True,
        text=True,
        cwd=ROOT,
    )
    assert proc.returncode == 1
    assert proc.stderr.startswith("thesis data: Unknown task 'hoper'. Did you mean: 'hopper'?")
    assert "Traceback" not in proc.stderr


def test_library_progress_bars_are_off_inside_executed_chapters(tmp_path, monkeypatch):
    """tqdm output would land in the book as lines of cursor codes; the kernel gets TQDM_DISABLE=1."""
    from thesis_lib.book import run_chapter

    monkeypatch.delenv("TQDM_DISABLE", raising=False)
    monkeypatch.setenv("MUJOCO_GL", "osmesa")  # a caller's choice is kept
    _write_project(
        tmp_path,
        "import os\nprint('TQDM_DISABLE=' + os.environ.get('TQDM_DISABLE', 'unset'), "
        "'MUJOCO_GL=' + os.environ.get('MUJOCO_GL', 'unset'))",
    )
    run_chapter("demo", root=tmp_path, progress=False)
    executed = nbformat.read(tmp_path / GENERATED / "demo.ipynb", as_version=4)
    printed = "".join(o.get("text", "") for c in executed.cells for o in c.get("outputs", []))
    assert "TQDM_DISABLE=1" in printed and "MUJOCO_GL=osmesa" in printed
    import os

    assert "TQDM_DISABLE" not in os.environ, "the runner restores the caller's environment"
    monkeypatch.delenv("MUJOCO_GL")
    run_chapter("demo", root=tmp_path, progress=False)
    executed = nbformat.read(tmp_path / GENERATED / "demo.ipynb", as_version=4)
    printed = "".join(o.get("text", "") for c in executed.cells for o in c.get("outputs", []))
    assert "MUJOCO_GL=egl" in printed and "MUJOCO_GL" not in os.environ


def test_executed_chapter_shows_its_parameters_once(tmp_path):
    """The defaults cell is hidden in the book when papermill injected the parameters that ran."""
    from thesis_lib.book import run_chapter

    _write_project(tmp_path, "print(n)")
    run_chapter("demo", {"n": 3}, root=tmp_path, progress=False)
    nb = nbformat.read(tmp_path / GENERATED / "demo.ipynb", as_version=4)
    tags = [c.metadata.get("tags", []) for c in nb.cells]
    defaults = [t for t in tags if "parameters" in t]
    injected = [i for i, t in enumerate(tags) if "injected-parameters" in t]
    assert defaults == [["parameters", "remove-cell"]]
    assert len(injected) == 1 and "n = 3" in nb.cells[injected[0]].source
    assert "remove-cell" not in tags[injected[0]]


# Ctrl-C on `thesis run` interrupts the running cell (the kernel runs in its own session).
LOOP = """
import pathlib, time
out = pathlib.Path("ticks")
out.mkdir(exist_ok=True)
for i in range(600):          # about a minute unless interrupted
    (out / f"{i:04d}").touch()
    time.sleep(0.1)
"""


def test_ctrl_c_stops_the_chapter_and_says_it_can_resume(tmp_path):
    _write_project(tmp_path, LOOP)
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
