"""The DEFENDER chapter's fifth and sixth studies (defender-c7c9-v5 and -v6,
params/03_defender.v5.study.yml and .v6) before they complete: their grids (the plain runs are
v4's, each control matches its seed's filter and runs last, v6 is v5 plus the timing
controls), and their comparisons and gates on hand-made rows shaped as their tasks make them,
so that the verdicts their rows will get are known to follow CLAIMS.md's rules (a control not
beaten, a floor, a filter that does not act: untestable) before 24 CPU-hours are spent."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from thesis_lib.chapters import CHAPTERS

REPO = Path(__file__).resolve().parents[1]
FILTER = "SAC+MeanDemoW5/MeanDemoW10"
CONTROL = "SAC+random:matched"
TIMER = "SAC+timer:matched"
#: Per method: crashes per 1,000 training steps, final eval score (% of the thesis's SAC), the
#: share of training episodes a filter ended, ln(training steps per CPU-second).
GOOD = {
    "SAC": (6.0, 65.0, 0.0, 4.20),
    FILTER: (2.0, 66.0, 0.60, 4.05),
    f"{FILTER} state-action": (3.5, 64.0, 0.55, 3.90),
    f"{FILTER} n=10": (3.5, 65.0, 0.50, 4.10),
    CONTROL: (4.0, 60.0, 0.60, 4.20),
    TIMER: (3.5, 60.0, 0.60, 4.20),
}


@pytest.fixture
def v5(monkeypatch):
    from thesis_lib.book import study as st

    monkeypatch.setenv("THESIS_PROJECT_ROOT", str(REPO))
    return st.load_study("03_defender:v5")


def _tasks(study) -> list:
    from thesis_lib.book import study as st

    return st.study_tasks(study, CHAPTERS["03_defender"])


def _rows(study, levels: dict[str, tuple[float, float, float, float]]) -> pd.DataFrame:
    rng = np.random.default_rng(0)
    rows = []
    for t in _tasks(study):
        c = t.config
        crashes, score, filtered, speed = levels[c["label"]]
        demos = c["strategy"] not in (
            None,
            CONTROL.removeprefix("SAC+"),
            TIMER.removeprefix("SAC+"),
        )
        rows.append(
            {
                "method": c["label"],
                "setting": "Hopper",
                "seed": c["seed"],
                "scale": c.get("scale", "study"),
                "crashes_per_1k_steps": max(0.0, crashes + rng.normal(0, 0.2)),
                "eval_score": score + rng.normal(0, 1.0),
                "best_score": score + 5.0,
                "filtered_rate": filtered,
                "log_speed": speed + rng.normal(0, 0.01),
                "demos_safe": c["n_demos"] if demos else np.nan,
                "demos_safe_expert": 0 if demos else np.nan,
            }
        )
    return pd.DataFrame(rows)


def _verdicts(study, rows: pd.DataFrame) -> tuple[pd.DataFrame, dict[str, str]]:
    from thesis_lib.book.study import evaluate_rows
    from thesis_lib.stats.claims import claim_verdicts

    res = evaluate_rows(study, rows, reps=200)
    return res, claim_verdicts(res).set_index("claim").verdict.to_dict()


def _by_label(res: pd.DataFrame, start: str) -> pd.Series:
    (row,) = [r for _, r in res.iterrows() if str(r["label"]).startswith(start)]
    return row


def test_the_grid_reuses_the_plain_runs_and_runs_each_matched_control_last(v5):
    from thesis_lib.book import study as st

    tasks = _tasks(v5)
    assert len(tasks) == 31
    v4 = {t.key for t in _tasks(st.load_study("03_defender:v4"))}
    assert {t.config["label"] for t in tasks if t.key in v4} == {"SAC"}  # the plain runs only
    assert sum(t.key in v4 for t in tasks) == 8  # 3 scale-check and 5 study seeds
    filters = {
        t.config["seed"]: t.key
        for t in tasks
        if t.config["label"] == FILTER and t.config.get("scale") != "check"
    }
    controls = [t for t in tasks if t.config["label"] == CONTROL]
    assert tasks[-5:] == controls  # after every run they match
    assert {t.config["seed"]: t.config["match"] for t in controls} == filters
    capped = [t for t in tasks if t.config["strategy"] and t.config["label"] != CONTROL]
    assert {t.config["train"]["max_trajectory"] for t in capped} == {20}


def test_a_filter_beating_its_control_decides_c7_to_c9(v5):
    """Every gate passes: C7 holds (fewer crashes than plain SAC and its matched control, the
    return kept), C8 holds (state trajectories crash less and run faster), C9 holds."""
    res, verdicts = _verdicts(v5, _rows(v5, GOOD))
    decided = res[res["counts"].astype(bool)]
    assert (decided["validity"] == "valid").all(), decided[["label", "gates"]].to_string()
    assert verdicts == {"C7": "holds", "C8": "holds", "C9": "holds"}


def test_a_filter_no_better_than_random_at_its_rate_leaves_c7s_crash_cut_untestable(v5):
    """The crash cut a random filter at the same rate makes too (an ended episode cannot
    fall) is not DEFENDER's: the control gate withholds that comparison, never 'holds'."""
    levels = {**GOOD, CONTROL: (2.0, 60.0, 0.60, 4.20)}
    res, verdicts = _verdicts(v5, _rows(v5, levels))
    crash = _by_label(res, "crashes per 1,000 training steps, SAC without vs with")
    assert crash["validity"] == "untestable" and "control:" in crash["gates"]
    # the return comparison alone still reads, but a claim with a withheld half is withheld
    assert _by_label(res, "SAC with vs without the filter")["validity"] == "valid"
    assert verdicts == {"C7": "untestable", "C8": "holds", "C9": "holds"}


def test_plain_sac_under_half_the_thesiss_return_withholds_every_claim(v5):
    levels = {**GOOD, "SAC": (6.0, 30.0, 0.0, 4.20)}
    res, verdicts = _verdicts(v5, _rows(v5, levels))
    assert verdicts == {"C7": "untestable", "C8": "untestable", "C9": "untestable"}


def test_filters_that_barely_act_withhold_the_crash_comparisons_of_c8_and_c9(v5):
    """Both filters of a pair ending under 10% of the episodes: C8's and C9's crash
    comparisons are untestable (the firing gate, `require: either`); one filter acting is
    enough to read them."""
    quiet = {
        m: (v[0], v[1], 0.05 if m not in ("SAC", CONTROL) else v[2], v[3]) for m, v in GOOD.items()
    }
    res, _ = _verdicts(v5, _rows(v5, quiet))
    for start in (
        "crashes per 1,000 training steps, state-action",
        "crashes per 1,000 training steps, 10 vs 50",
    ):
        row = _by_label(res, start)
        assert row["validity"] == "untestable" and "level (both)" in row["gates"], start
    one = {**quiet, FILTER: GOOD[FILTER]}
    res, _ = _verdicts(v5, _rows(v5, one))
    assert _by_label(res, "crashes per 1,000 training steps, 10 vs 50")["validity"] == "valid"


@pytest.fixture
def v6(monkeypatch):
    from thesis_lib.book import study as st

    monkeypatch.setenv("THESIS_PROJECT_ROOT", str(REPO))
    return st.load_study("03_defender:v6")


def test_v6_is_v5_and_a_timing_control_per_seed_run_last(v5, v6):
    tasks5, tasks6 = _tasks(v5), _tasks(v6)
    assert [t.key for t in tasks6[:31]] == [t.key for t in tasks5]  # every v5 task, reused
    timers = tasks6[31:]
    assert [t.config["label"] for t in timers] == [TIMER] * 5
    random = {t.config["seed"]: t.config["match"] for t in tasks5 if t.config["label"] == CONTROL}
    assert {t.config["seed"]: t.config["match"] for t in timers} == random  # the same runs
    assert v6.supersedes == v5.study and "03_defender:v5" in v6.reuse


def test_v6_decides_c7_where_the_filter_beats_both_controls(v6):
    res, verdicts = _verdicts(v6, _rows(v6, GOOD))
    decided = res[res["counts"].astype(bool)]
    assert (decided["validity"] == "valid").all(), decided[["label", "gates"]].to_string()
    assert verdicts == {"C7": "holds", "C8": "holds", "C9": "holds"}


def test_v6_withholds_c7_where_a_blind_filter_at_its_steps_does_as_well(v6):
    """Beating the random control is not enough: a filter whose crash cut a timer firing at
    its own steps matches has shown its timing, not its knowledge of the fall."""
    levels = {**GOOD, TIMER: (2.0, 60.0, 0.60, 4.20)}
    res, verdicts = _verdicts(v6, _rows(v6, levels))
    crash = _by_label(res, "crashes per 1,000 training steps, SAC without vs with")
    assert crash["validity"] == "untestable"
    assert "FAILED control: SAC+timer:matched" in crash["gates"]
    assert "passed control: SAC+random:matched" in crash["gates"]
    assert verdicts == {"C7": "untestable", "C8": "holds", "C9": "holds"}
