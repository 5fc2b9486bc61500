"""The HDT chapter's second study (hdt-c1c3-v2, params/04_hdt.v2.study.yml) on hand-made rows:
its grid, and what its comparisons and gates make of rows shaped as its tasks make them,
before the study itself is complete (so a gate that cannot read its rows shows now)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from thesis_lib.chapters import CHAPTERS

REPO = Path(__file__).resolve().parents[1]
HOPPER, MAZE = "hopper/medium-replay", "maze2d-umaze/expert"
#: Normalised final scores by method on hopper medium-replay, near the study's first rows.
HOPPER_LEVELS = {"BC": 12.0, "DT": 60.0, "DT-noRTG": 11.0, "HDT": 10.0, "HDT-RTG": 18.0}
MAZE_FLOOR = -17.3  # zero return on maze2d umaze


@pytest.fixture
def study(monkeypatch):
    from thesis_lib.book import study as st

    monkeypatch.setenv("THESIS_PROJECT_ROOT", str(REPO))
    return st.load_study("04_hdt:v2")


def _rows(study, hopper: dict[str, float], maze: dict[str, float]) -> pd.DataFrame:
    """One row per task of the study's grid: ``method``, ``setting``, ``seed``, ``scale`` and
    the final and best scores, at the level given per method and setting, +-1 over seeds."""
    from thesis_lib.book import study as st

    rng = np.random.default_rng(0)
    rows = []
    for t in st.study_tasks(study, CHAPTERS["04_hdt"]):
        c = t.config
        level = (hopper if c["dataset"] == HOPPER else maze)[c["method"]]
        score = level + rng.normal(0, 1)
        rows.append(
            {
                "method": c["method"],
                "setting": c["dataset"],
                "seed": c["train"]["seed"],
                "scale": c.get("scale", "study"),
                "score_final": score,
                "score_best": score + 2,
            }
        )
    return pd.DataFrame(rows)


def _verdicts(study, rows: pd.DataFrame) -> tuple[pd.DataFrame, pd.Series]:
    from thesis_lib.book.study import evaluate_rows
    from thesis_lib.stats.claims import claim_verdicts

    res = evaluate_rows(study, rows, reps=200)  # the d32 check's rows left out
    return res, claim_verdicts(res).set_index("claim").verdict


def test_the_grid_is_five_methods_five_seeds_two_sets_and_the_d32_check(study):
    from thesis_lib.book import study as st

    tasks = st.study_tasks(study, CHAPTERS["04_hdt"])
    main = [t.config for t in tasks if t.config.get("scale", "study") == "study"]
    check = [t.config for t in tasks if t.config.get("scale") == "check"]
    assert len(tasks) == 65 and len(main) == 50 and len(check) == 15
    assert {c["dataset"] for c in main} == {HOPPER, MAZE} and {c["dataset"] for c in check} == {
        HOPPER
    }
    for grid in (main, check):
        assert {(c["method"], c["train"]["seed"]) for c in grid if c["dataset"] == HOPPER} == {
            (m, s) for m in HOPPER_LEVELS for s in range(5 if grid is main else 3)
        }
    seq = [c for c in main if c["method"] != "BC"]  # BC is an MLP: no transformer size
    assert {(c["arch"]["d_model"], c["arch"]["n_layers"], c["arch"]["init"]) for c in seq} == {
        (64, 2, "normal")
    }
    assert {
        (c["arch"]["d_model"], c["arch"]["n_layers"]) for c in check if c["method"] != "BC"
    } == {(32, 1)}
    assert {c["train"]["sampling"] for c in main} == {"end"}


def test_the_gates_pass_on_rows_like_the_first_ones_and_hopper_decides(study):
    """Rows near the first seeds' (the DT far above the rest, the HDT at BC's level): every
    hopper comparison passes its gates and is decided; the maze pairs at the zero-return
    floor are withheld, and being reported apart they do not decide a claim."""
    rows = _rows(study, HOPPER_LEVELS, dict.fromkeys(HOPPER_LEVELS, MAZE_FLOOR))
    res, verdicts = _verdicts(study, rows)
    hop = res[res["label"].str.contains("hopper medium-replay")]
    maze = res[res["label"].str.contains("maze2d umaze")]
    assert len(hop) == 4 and len(maze) == 4
    assert (hop["validity"] == "valid").all(), hop[["label", "gates"]].to_string()
    assert (maze["verdict"] == "untestable").all() and not maze["counts"].astype(bool).any()
    assert "parity" in " ".join(hop["gates"])  # the DT's fidelity gate read the parity table
    assert verdicts.to_dict() == {"C1": "holds", "C2": "fails", "C3": "fails"}


def test_a_model_under_bc_minus_five_withholds_its_comparisons(study):
    """The HDT below BC - 5 on hopper: C2 and C3 cannot be judged on it (untestable); C1,
    which does not involve the HDT, still is."""
    low = {**HOPPER_LEVELS, "HDT": 3.0}
    rows = _rows(study, low, dict.fromkeys(HOPPER_LEVELS, MAZE_FLOOR))
    res, verdicts = _verdicts(study, rows)
    hdt = res[res["label"].str.contains("hopper") & res["label"].str.startswith("HDT vs")]
    assert (hdt["verdict"] == "untestable").all()
    assert verdicts["C1"] == "holds" and verdicts["C2"] == "untestable"
    # BC itself under its data's mean - 5: nothing on hopper can be judged
    rows = _rows(study, {**HOPPER_LEVELS, "BC": 5.0}, dict.fromkeys(HOPPER_LEVELS, MAZE_FLOOR))
    _, verdicts = _verdicts(study, rows)
    assert set(verdicts) == {"untestable"}


def test_a_maze_pair_off_the_floor_is_reported_not_counted(study):
    """On the maze, a pair with one method off the floor is judged, but reported apart: the
    claim's verdict stays hopper's. A pair with a method under BC - 5 is still withheld."""
    maze = {**dict.fromkeys(HOPPER_LEVELS, MAZE_FLOOR), "HDT": 20.0, "BC": 0.0}
    rows = _rows(study, HOPPER_LEVELS, maze)
    res, verdicts = _verdicts(study, rows)
    by = res.set_index("label")
    hdt_bc = by.loc["HDT vs BC on the sparse-reward maze2d umaze (reported apart)"]
    assert hdt_bc["verdict"] == "holds" and not bool(hdt_bc["counts"])
    hdt_dt = by.loc["HDT vs DT on the sparse-reward maze2d umaze (reported apart)"]
    assert hdt_dt["verdict"] == "untestable" and "FAILED level: DT" in hdt_dt["gates"]
    assert verdicts["C3"] == "fails"  # hopper's HDT vs DT decides
