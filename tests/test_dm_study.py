"""The Decision Mamba chapter's second study (dm-c4c6-v2, params/05_decision_mamba.v2.study.yml)
before it runs: its DT and HDT tasks are hdt-c1c3-v2's (copied, not trained again), and its
comparisons and gates on hand-made rows shaped as its tasks make them."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import pytest
import torch

from thesis_lib.chapters import CHAPTERS

REPO = Path(__file__).resolve().parents[1]
#: Normalised final scores on hopper medium-replay, near the ladder's and hdt-c1c3-v2's.
LEVELS = {"DT": 60.0, "HDT": 10.0, "DM-RTG": 11.0, "DM-noRTG": 10.5, "HDM": 12.0}
#: Actions per second re-running the window, and in each method's own way (DM, HDM: recurrent).
WINDOW = {"DT": 300.0, "HDT": 150.0, "DM-RTG": 170.0, "DM-noRTG": 170.0, "HDM": 70.0}
OWN = {**WINDOW, "DM-RTG": 750.0, "DM-noRTG": 750.0, "HDM": 350.0}


@pytest.fixture
def studies(monkeypatch):
    from thesis_lib.book import study as st

    monkeypatch.setenv("THESIS_PROJECT_ROOT", str(REPO))
    return st.load_study("05_decision_mamba:v2"), st.load_study("04_hdt:v2")


def _tasks(study, chapter: str) -> list:
    from thesis_lib.book import study as st

    return st.study_tasks(study, CHAPTERS[chapter])


def _rows(study, levels: dict[str, float]) -> pd.DataFrame:
    rng = np.random.default_rng(0)
    rows = []
    for t in _tasks(study, "05_decision_mamba"):
        c, m = t.config, t.config["method"]
        if t.fn.__name__ == "timing_task":
            rows.append(
                {
                    "method": m,
                    "setting": f"{c['dataset']} (timing)",
                    "seed": c["seed"],
                    "scale": "study",
                    "act_per_s_window": WINDOW[m] * rng.normal(1, 0.02),
                    "act_per_s": OWN[m] * rng.normal(1, 0.02),
                    "train_per_s": (40.0 if m == "DT" else 20.0) * rng.normal(1, 0.02),
                }
            )
        else:
            score = levels[m] + rng.normal(0, 1)
            rows.append(
                {
                    "method": m,
                    "setting": c["dataset"],
                    "seed": c["train"]["seed"],
                    "scale": "study",
                    "score_final": score,
                    "score_best": score + 2,
                }
            )
    return pd.DataFrame(rows)


def _verdicts(study, rows: pd.DataFrame) -> tuple[pd.DataFrame, dict[str, str]]:
    from thesis_lib.book.study import evaluate_rows
    from thesis_lib.stats.claims import claim_verdicts

    res = evaluate_rows(study, rows, reps=200)
    return res, claim_verdicts(res).set_index("claim").verdict.to_dict()


def test_the_dt_and_hdt_runs_are_the_hdt_studys_and_the_rest_is_new(studies):
    dm, hdt = studies
    tasks = _tasks(dm, "05_decision_mamba")
    hdt_keys = {t.key for t in _tasks(hdt, "04_hdt")}
    runs = [t for t in tasks if t.fn.__name__ != "timing_task"]
    timing = [t for t in tasks if t.fn.__name__ == "timing_task"]
    shared = {t.config["method"] for t in runs if t.key in hdt_keys}
    assert shared == {"DT", "HDT"} and sum(t.key in hdt_keys for t in runs) == 10
    assert {t.config["method"] for t in runs if t.key not in hdt_keys} == {
        "DM-RTG",
        "DM-noRTG",
        "HDM",
    }
    assert len(runs) == 25 and len(timing) == 50
    assert {t.config["dataset"] for t in timing} == {"hopper/medium", "maze2d-umaze/expert"}


def test_rows_like_the_ladders_decide_c4_c5_and_c6(studies):
    """The DM variants at BC's level, the DT far above: C4 holds (no RTG, no loss), C5 fails
    (the DM under the DT), C6 fails on the window timing (a DM action slower than a DT's)."""
    res, verdicts = _verdicts(studies[0], _rows(studies[0], LEVELS))
    decided = res[res["counts"].astype(bool)]
    assert (decided["validity"] == "valid").all(), decided[["label", "gates"]].to_string()
    assert verdicts == {"C4": "holds", "C5": "fails", "C6": "fails"}
    by = res.set_index("label")
    rec = by.loc[
        "actions per second, DM acting by its O(1) recurrent step vs DT's window (reported apart)"
    ]
    assert rec["verdict"] == "holds" and not bool(rec["counts"])


def test_a_dm_under_bc_minus_five_withholds_c4_and_its_c5_comparison(studies):
    """The DM without RTG under BC - 5 (7.1): C4 and DM-vs-DT are untestable, HDM-vs-HDT is
    still judged."""
    res, verdicts = _verdicts(studies[0], _rows(studies[0], {**LEVELS, "DM-noRTG": 2.0}))
    by = res.set_index("label")
    assert verdicts["C4"] == "untestable"
    assert by.loc["DM (without RTG) vs DT, hopper medium-replay", "verdict"] == "untestable"
    assert by.loc["HDM vs HDT, hopper medium-replay", "validity"] == "valid"


# ------------------------------------------------------------------ the GPU timing study (C6)


@pytest.fixture
def gpu_study(monkeypatch):
    from thesis_lib.book import study as st

    monkeypatch.setenv("THESIS_PROJECT_ROOT", str(REPO))
    return st.load_study("05_decision_mamba:gpu")


def test_the_gpu_study_times_v2s_c6_tasks_on_cuda_and_trains_nothing(gpu_study, studies):
    """dm-c6-gpu-v1: v2's timing tasks (same fields but the device, repeats and data size),
    each carrying ``device: cuda`` in its config (so its key), and no training run; v2's own
    timing tasks carry no device (their keys are those of the rows already stored)."""
    gpu = _tasks(gpu_study, "05_decision_mamba")
    assert len(gpu) == 30 and {t.fn.__name__ for t in gpu} == {"timing_task"}
    assert {t.config["device"] for t in gpu} == {"cuda"}
    assert {t.config["dataset"] for t in gpu} == {"hopper/medium", "maze2d-umaze/expert"}
    v2 = [t for t in _tasks(studies[0], "05_decision_mamba") if t.fn.__name__ == "timing_task"]
    assert not any("device" in t.config for t in v2)
    same = {"method", "dataset", "timing_arch", "timing_batch_size", "timing_train_iters"}
    assert {tuple(t.config[k] for k in sorted(same)) for t in gpu} <= {
        tuple(t.config[k] for k in sorted(same)) for t in v2
    }
    assert {t.key for t in gpu}.isdisjoint({t.key for t in v2})


def test_the_gpu_studys_rows_decide_c6_as_v2s(gpu_study):
    """Rows shaped as a GPU run makes them (plus the GPU's name and the scan) go through the
    same comparisons: a DM action slower than a DT's on the window fails C6."""
    rows = _rows(gpu_study, LEVELS).assign(device="NVIDIA H200", scan_backend="torch")
    res, verdicts = _verdicts(gpu_study, rows)
    assert verdicts == {"C6": "fails"}
    assert set(res["seeds"]) == {3}


@pytest.mark.skipif(torch.cuda.is_available(), reason="checks the error on a machine without GPU")
def test_a_gpu_timing_task_without_a_gpu_says_so():
    from thesis_lib.chapters.decision_mamba.tasks import timing_task

    with pytest.raises(RuntimeError, match="no CUDA GPU"):
        timing_task(
            {
                "method": "DT",
                "dataset": "hopper/medium",
                "seed": 0,
                "timing_arch": "1/16/5",
                "timing_batch_size": 4,
                "timing_train_iters": 1,
                "timing_infer_steps": 5,
                "timing_infer_episodes": 1,
                "dataset_size": "smoke",
                "n_transitions": None,
                "device": "cuda",
            }
        )
