"""Real Minari ids (``D4RL/door/human-v2`` …) in the HDT and Decision Mamba chapters.

The downloads are stood in for by ``tests/fixtures/minari/`` (Minari's layout, the real ids,
environment specs and spaces, a few random episodes; ``tests/fixtures/make_minari_fixtures.py``).
"""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest

from thesis_lib.data import minari_sets as ms

FIXTURES = Path(__file__).parent / "fixtures" / "minari"
DOOR, KITCHEN, ANTMAZE = "D4RL/door/human-v2", "D4RL/kitchen/complete-v2", "D4RL/antmaze/umaze-v1"


@pytest.fixture
def minari_root(tmp_path, monkeypatch):
    """``MINARI_DATASETS_PATH`` = a copy of the fixtures; results and our data in ``tmp_path``."""
    root = tmp_path / "minari"
    shutil.copytree(FIXTURES, root)
    monkeypatch.setenv("MINARI_DATASETS_PATH", str(root))
    monkeypatch.setenv("THESIS_DATA_DIR", str(tmp_path / "ours"))
    monkeypatch.setenv("THESIS_RESULTS_DIR", str(tmp_path / "results"))
    return root


# ------------------------------------------------------------------ task keys of existing sets


def _tiny_hdt(**kw):
    from thesis_lib.chapters import hdt

    return hdt.Config(
        **kw,
        datasets=["hopper/medium"],
        methods=["BC", "DT", "HDT"],
        seeds=[0],
        extra_seeds=[],
        extra_seed_datasets=[],
        compat_dataset=None,
        iterations=10,
        eval_every=5,
        eval_episodes=1,
        max_eval_steps=10,
    )


def test_task_keys_of_task_tier_sets_are_unchanged():
    """The keys of the stored study/sweep tasks of 'task/tier' sets (computed on f33c85f, before
    Minari ids were accepted): a change here would orphan the committed studies' results. Those
    ran before the transformers' ``init`` and the windows' ``sampling`` existed, with PyTorch's
    defaults (``init="torch"``) and start-drawn windows (``sampling="start"``), what a study file
    that names neither reads as; today's defaults make new keys for every method (BC's windows
    are drawn by their last step too)."""
    from thesis_lib.chapters import decision_mamba as dm
    from thesis_lib.chapters import hdt
    from thesis_lib.seq.runner import EvalSpec

    new = _tiny_hdt()
    new_keys = {
        m: hdt.study_task(new, m, "hopper/medium", 0, new.arch(False)).key for m in new.methods
    }
    assert new_keys["BC"] != "654399e8f19a64b3"  # BC: no init, but its windows are drawn anew
    assert new_keys["DT"] != "44c79d1a5285a803" and new_keys["HDT"] != "748967226e6598ff"
    torch_only = _tiny_hdt(init="torch")  # the legacy keys need both legacy values
    assert hdt.study_task(torch_only, "DT", "hopper/medium", 0, torch_only.arch(False)).key != (
        "44c79d1a5285a803"
    )
    cfg = _tiny_hdt(init="torch", sampling="start")
    keys = {m: hdt.study_task(cfg, m, "hopper/medium", 0, cfg.arch(False)).key for m in cfg.methods}
    assert keys == {"BC": "654399e8f19a64b3", "DT": "44c79d1a5285a803", "HDT": "748967226e6598ff"}
    compat = hdt.study_task(cfg, "DT", "hopper/medium", 0, cfg.arch(True), label="DT-compat")
    assert compat.key == "cf07719fda4531c6"
    assert [t.key for t in hdt.sweep_tasks(cfg, cfg.datasets, cfg.methods, False)] == [
        "a863f1ebaf01d132",
        "003bc2aca2d3ef9b",
        "6dee81c5e068bf78",
    ]
    c5 = dm.Config(
        init="torch",
        sampling="start",
        datasets=["hopper/medium"],
        methods=["DT", "DM-noRTG"],
        iterations=10,
        eval_every=5,
        eval_episodes=1,
        max_eval_steps=10,
    )
    assert [t.key for t in dm.study_tasks(c5)] == [
        "43ed29e9c764a18e",
        "0a719d2da00d1a2c",
        "7b9d3658b6f7d18f",
        "f323e13b08b3e54b",
    ]
    ev = EvalSpec(episodes=1, max_steps=10)
    assert dm.sweep_task(c5, "DM-noRTG", "hopper/medium", 0, c5.arch, ev).key == "db9c4ff3cf239c72"


# ------------------------------------------------------------------ names, references, caps


def test_names_of_both_kinds():
    assert ms.dataset_key("hopper/medium") == ("hopper", "medium")
    assert ms.dataset_key(DOOR) == ("door", "human")
    assert ms.dataset_key("D4RL/antmaze/large-diverse-v1") == ("antmaze", "large-diverse")
    assert ms.env_name("maze2d-umaze/expert") == "maze2d-umaze"
    assert ms.env_name(KITCHEN) == KITCHEN
    for bad in ("hopper-medium", "D4RL/door/human", "a/b/c/d"):
        with pytest.raises(ValueError, match="Minari id"):
            ms.dataset_key(bad)


def test_d4rl_reference_returns_and_scores():
    from thesis_lib.data import normalized_score
    from thesis_lib.seq.evaluation import eval_step_cap

    # d4rl/infos.py: door-human-v1 = door-human-v0's references.
    assert ms.reference_returns(DOOR) == (-56.512833, 2880.5693087298737)
    assert ms.reference_returns("D4RL/pen/expert-v2") == (96.262799, 3076.8331017826877)
    assert ms.reference_returns("D4RL/kitchen/mixed-v2") == (0.0, 4.0)
    assert ms.reference_returns("D4RL/antmaze/medium-diverse-v1") == (0.0, 1.0)
    assert len(ms.D4RL_REFERENCES) == 12 + 3 + 6
    assert normalized_score(KITCHEN, 3.0) == pytest.approx(75.0)
    assert normalized_score(DOOR, 2880.5693087298737) == pytest.approx(100.0)
    assert normalized_score("hopper", 3234.3) == pytest.approx(100.0)  # unchanged
    assert eval_step_cap(DOOR, 100) == 100
    assert eval_step_cap(KITCHEN, 100) is None and eval_step_cap(ANTMAZE, 100) is None
    assert eval_step_cap("hopper", 100) == 100 and eval_step_cap("maze2d-umaze", 100) is None


def test_missing_download_names_the_id_and_where_minari_looks(tmp_path, monkeypatch):
    from thesis_lib.chapters import hdt

    monkeypatch.setenv("MINARI_DATASETS_PATH", str(tmp_path / "empty"))
    monkeypatch.setenv("THESIS_DATA_DIR", str(tmp_path / "ours"))
    cfg = hdt.Config(datasets=["D4RL/door/cloned-v2"], extra_seed_datasets=[], compat_dataset=None)
    msg = rf"'D4RL/door/cloned-v2'.*{tmp_path / 'empty'}.*minari download D4RL/door/cloned-v2"
    with pytest.raises(FileNotFoundError, match=msg):
        hdt.load_datasets(cfg)


# ------------------------------------------------------------------ the fixtures load and evaluate


@pytest.mark.parametrize(
    "dataset_id, obs_dim, act_dim, steps",
    [(DOOR, 39, 28, 200), (KITCHEN, 59, 9, 280), (ANTMAZE, 27, 8, 700)],
)
def test_fixture_loads_with_its_own_environment(minari_root, dataset_id, obs_dim, act_dim, steps):
    ds = ms.open_dataset(dataset_id)
    assert len(ds) == 3 and ds.n_transitions == 24
    assert ds.episodes[0].observations.shape == (9, obs_dim)
    assert ds.episodes[0].actions.shape == (8, act_dim)
    assert ds.episodes[-1].truncations[-1]
    assert (ds.ref_min_score, ds.ref_max_score) == ms.reference_returns(dataset_id)
    assert len(ms.open_dataset(dataset_id, n_transitions=16)) == 2
    env = ms.make_minari_env(dataset_id)
    try:
        assert env.spec.max_episode_steps == steps
        assert env.action_space.shape == (act_dim,)
        obs, _ = env.reset(seed=0)
        flat = obs["observation"] if isinstance(obs, dict) else obs
        assert np.asarray(flat).shape == (obs_dim,)
        if dataset_id == ANTMAZE:  # D4RL's scoring: the episode ends at the goal
            assert env.spec.kwargs["continuing_task"] is False
            assert env.spec.kwargs["maze_map"][3][1] == "g"
        if dataset_id == KITCHEN:
            assert env.spec.kwargs["tasks_to_complete"][0] == "microwave"
    finally:
        env.close()


# ------------------------------------------------------------------ the chapters, tiny scale


def test_hdt_table_5_3_rows_from_minari_ids(minari_root):
    from thesis_lib.chapters import hdt

    cfg = hdt.Config(
        datasets=[DOOR, KITCHEN],
        methods=["BC", "DT", "HDT"],
        extra_seed_datasets=[],
        compat_dataset=None,
        iterations=2,
        eval_every=2,
        batch_size=4,
        K=4,
        d_model=8,
        bc_hidden_dim=8,
        warmup_steps=1,
        eval_episodes=1,
        max_eval_steps=5,
    )
    data = hdt.load_datasets(cfg)
    assert set(data) == {("door", "human"), ("kitchen", "complete")}
    curves = hdt.run_curves(cfg)
    assert set(zip(curves.task, curves.tier)) == set(data)
    door = curves[curves.task == "door"]
    assert (door.length_mean <= 5).all()  # Adroit: the smoke cap applies
    kitchen = curves[curves.task == "kitchen"]
    assert (kitchen.length_mean > 5).all()  # Kitchen: whole episodes, as Maze2D
    for _, r in curves.iterrows():  # D4RL-normalised with D4RL's references of the id
        lo, hi = ms.reference_returns(DOOR if r.task == "door" else KITCHEN)
        assert r.score_mean == pytest.approx(100 * (r.return_mean - lo) / (hi - lo))
    summary = hdt.summarize_curves(curves)
    data_avg = {k: float(np.mean(ds.returns)) for k, ds in data.items()}
    t53 = hdt.compare_table_5_3(summary, data_avg)
    ran = t53[t53.metric == "best during training (thesis)"].dropna(subset=["ours"])
    got = {(r.task, r.dataset, r.method): r.paper for _, r in ran.iterrows()}
    assert got[("Door", "human", "bc")] == 363
    assert got[("Door", "human", "hdt")] == 338
    assert got[("Door", "human", "data_avg")] == 796
    assert got[("Kitchen", "complete", "dt")] == 2.5
    assert len(got) == 8  # 2 settings x (bc, dt, hdt, data_avg)


def test_decision_mamba_table_5_5_rows_from_minari_ids(minari_root):
    from thesis_lib.chapters import decision_mamba as dm

    cfg = dm.Config(
        datasets=[ANTMAZE],
        methods=["DT", "DM-noRTG"],
        iterations=2,
        eval_every=2,
        batch_size=4,
        arch="1/8/4",
        warmup_steps=1,
        eval_episodes=1,
        max_eval_steps=5,
        compare_eval_modes=False,
        sweep_datasets=[ANTMAZE],
        timing_datasets=[ANTMAZE],
    )
    data = dm.load_datasets(cfg.datasets, cfg)
    assert set(data) == {("antmaze", "umaze")}
    curves = dm.run_table_5_5(cfg)
    assert (curves.length_mean > 5).all()  # AntMaze: whole episodes (to the goal or 700 steps)
    assert curves.score_mean.notna().all()
    assert (curves.score_mean == 100 * curves.return_mean).all()  # references 0 and 1
    t55 = dm.compare_table_5_5(dm.summarize_curves(curves), cfg.eval_mode)
    ran = t55[t55.metric == t55.metric.iloc[0]].dropna(subset=["ours"])
    got = {(r.task, r.dataset, r.method, r.desired_return): r.paper for _, r in ran.iterrows()}
    assert got[("Antmaze", "umaze", "DT", "max")] == 0.92
    assert got[("Antmaze", "umaze", "DM_without_R", "none")] == 0.95


def test_the_default_extra_seed_and_compat_sets_follow_datasets():
    from thesis_lib.chapters import hdt

    # `thesis run 04_hdt -p datasets '["D4RL/door/human-v2"]'` alone: the defaults step aside
    cfg = hdt.Config(datasets=["D4RL/door/human-v2"])
    assert cfg.extra_seed_datasets == [] and cfg.compat_dataset is None
    cfg = hdt.Config(datasets=["maze2d-umaze/expert", "hopper/expert"])
    assert cfg.extra_seed_datasets == ["maze2d-umaze/expert"] and cfg.compat_dataset is None
    assert hdt.Config().compat_dataset == "hopper/medium"  # the smoke defaults are unchanged
    # what a user names must be in `datasets`
    with pytest.raises(ValueError, match="extra_seed_datasets entry 'hopper/medium'"):
        hdt.Config(datasets=["hopper/expert"], extra_seed_datasets=["hopper/medium"])
    with pytest.raises(ValueError, match="compat_dataset 'walker2d/medium' is not in datasets"):
        hdt.Config(datasets=["hopper/medium"], compat_dataset="walker2d/medium")
