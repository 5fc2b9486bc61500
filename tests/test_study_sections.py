"""Every chapter's "Evidence at study scale" section renders at any point of its study.

A session stops wherever its study is, and CI then runs every chapter against the rows
committed so far: a part of the grid, in the order the queue happened to finish it. Twice a
section failed on such a part (chapter 03 asked matplotlib for a grid of zero columns while no
TD3 row existed; chapter 02's tables raised ``KeyError: 'encoder'`` before any alignment row),
and only a CI run on a clean checkout found it. Here each chapter's own notebook cells, from
``evi.load_evidence`` to ``results.finish()``, run against fake rows of the real study grid:
one task, a random third, all tasks but one, and (the step to "complete") all of them. The rows have the shape each chapter's task
function gives (faked, no training); the grid, the study file and the notebook are the real ones.
"""

from __future__ import annotations

import json
import os
from pathlib import Path

import nbformat
import numpy as np
import pytest

from thesis_lib.book import study as st
from thesis_lib.chapters import CHAPTERS

REPO = Path(__file__).resolve().parents[1]


def _rows_03(tasks: list, rng: np.random.Generator) -> list[list[dict]]:
    from test_defender_study import _fake_row

    return [[_fake_row(t.config, rng)] for t in tasks]


def _rows_02(tasks: list, rng: np.random.Generator) -> list[list[dict]]:
    from test_clfd_study import _fake_rows

    return [_fake_rows([t], rng).to_dict("records") for t in tasks]


def _rows_06(tasks: list, rng: np.random.Generator) -> list[list[dict]]:
    """The rows :func:`thesis_lib.chapters.mdlt.study_run` gives (its labels, one row per
    genre of the held-out songs, ``aje_windowed`` for MDLT-M), without training."""
    from thesis_lib.chapters import mdlt as ex

    genres = [ex.genre_label(g) for g in st.load_study("06_mdlt").config["genres"]]
    out = []
    for t in tasks:
        c = t.config
        m, scope = c["method"], c["scope"]
        if m == "probe":
            labels = [ex.PROBE_LABEL]
        elif c.get("recipe") == "teacher forcing":
            labels = [f"{ex.VARIANT_LABELS[m]} {ex.TF_SUFFIX}"]
        elif m == "baselines":
            labels = ["mean pose", "genre mean"][: 2 if scope == ex.ALL_SCOPE else 1]
        else:
            labels = [ex.VARIANT_LABELS[m]]
        rows = []
        for label in labels:
            for g in genres if scope == ex.ALL_SCOPE else [ex.genre_label(c["genre"])]:
                mp = 0.5 + rng.normal(0, 0.01)
                a = mp if label == "mean pose" else 0.45 + rng.normal(0, 0.02)
                row = {"method": ex.study_label(label, scope), "setting": g, "seed": c["seed"],
                       "scope": scope, "scale": c.get("scale", "study"), "folds": len(c["folds"]),
                       "songs": 2, "aje": a, "neg_aje": -a, "aje_mean_pose": mp,
                       "gain_vs_mean_pose": 1 - a / mp, "fid": 1.0, "beat_align": 0.3,
                       "train_s": 30.0}  # fmt: skip
                if m == "mamba":
                    row |= {"aje_windowed": a - 0.01, "mismatch_cost": 0.01}
                rows.append(row)
        out.append(rows)
    return out


FAKES = {"03_defender": _rows_03, "02_clfd": _rows_02, "06_mdlt": _rows_06}


def _cells(chapter: str) -> list[str]:
    """The notebook's parameters and set-up cells, then its evidence section up to (not
    including) ``results.finish()``."""
    nb = nbformat.read(REPO / "notebooks" / f"{chapter}.ipynb", as_version=4)
    code = [c.source for c in nb.cells if c.cell_type == "code"]
    start = next(i for i, s in enumerate(code) if "evi.load_evidence(" in s)
    stop = next(i for i, s in enumerate(code) if "results.finish()" in s)
    assert start < stop
    return [*code[:2], *code[start:stop]]


def _share(n: int, which: str, rng: np.random.Generator) -> list[int]:
    if which == "one":
        return [int(rng.integers(n))]
    if which == "third":
        return sorted(rng.choice(n, size=max(2, n // 3), replace=False).tolist())
    if which == "all-but-one":
        return sorted(rng.choice(n, size=n - 1, replace=False).tolist())
    return list(range(n))


WHICH = ["one", "third", "all-but-one", "all"]


@pytest.mark.parametrize("which", WHICH)
@pytest.mark.parametrize("chapter", sorted(FAKES))
def test_evidence_section_renders_on_part_of_the_grid(chapter, which, tmp_path, monkeypatch):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    (tmp_path / "_toc.yml").write_text("root: intro\n")
    (tmp_path / "params").mkdir()
    for f in (REPO / "params").glob(f"{chapter}.*study.yml"):  # later studies: "not run yet"
        (tmp_path / "params" / f.name).write_text(f.read_text())
    monkeypatch.setenv("THESIS_PROJECT_ROOT", str(tmp_path))
    monkeypatch.setenv("THESIS_RESULTS_DIR", str(tmp_path / "results"))
    monkeypatch.setitem(os.environ, "MUJOCO_GL", os.environ.get("MUJOCO_GL", "egl"))

    study = st.load_study(chapter)
    tasks = st.study_tasks(
        study, CHAPTERS[study.chapter]
    )  # the grid and its scale check, as `thesis study` runs it
    rng = np.random.default_rng(WHICH.index(which))
    done = _share(len(tasks), which, rng)
    store = tmp_path / "studies" / chapter / "tasks"
    store.mkdir(parents=True)
    for i, rows in zip(done, FAKES[chapter]([tasks[i] for i in done], rng)):
        rec = {"key": tasks[i].key, "rows": rows, "study_hash": study.hash, "cpu_s": 60.0,
               "wall_s": 60.0, "commit": "0" * 40}  # fmt: skip
        (store / f"{tasks[i].key}.json").write_text(json.dumps(rec, default=float))
    info = st.write_study_summary(study, [t.key for t in tasks])
    assert info["tasks_done"] == len(done) and info["complete"] == (which == "all")

    ns: dict = {}
    for i, src in enumerate(_cells(chapter)):
        try:
            exec(compile(src, f"<{chapter} cell {i}>", "exec"), ns)
        except Exception as e:
            raise AssertionError(f"{chapter}, {len(done)}/{len(tasks)} tasks: cell\n{src}") from e
    plt.close("all")
    ev = ns["ev"]
    assert ev.complete == (which == "all") and len(ev.rows) + len(ev.check) >= 1
    verdicts = set(ns["readings"]["ours"])
    if which == "all":  # the fake rows decide every claim of the chapter
        assert verdicts <= {"holds", "fails", "inconclusive", "untestable"}, verdicts
    else:
        assert verdicts == {"pending"}  # no verdict from a partial grid
