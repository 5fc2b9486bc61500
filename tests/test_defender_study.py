"""The DEFENDER study (claims C7-C9): its tasks, its per-run reducer and its parameter file."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from thesis_lib.chapters import CHAPTERS
from thesis_lib.chapters import defender as ex

REPO = Path(__file__).resolve().parents[1]


def _log(rows):
    return pd.DataFrame(rows, columns=["return", "crashed", "filtered", "timestep"])


def test_training_run_numbers_on_a_hand_made_log():
    # 6 episodes over 100 steps: 2 crashed, 3 filtered, 1 reached the horizon
    ep = _log(
        [
            (10.0, True, False, 20),  # span 0 (steps 1-50)
            (-1.0, False, True, 35),  # span 0
            (30.0, True, False, 50),  # span 0 (step 50 is the span's last)
            (5.0, False, True, 70),  # span 1
            (7.0, False, True, 90),  # span 1
            (80.0, False, False, 100),  # span 1
        ]
    )
    got = ex.training_run_numbers(ep, total_steps=100, bins=2)
    assert (got["episodes"], got["crashes"], got["filtered"]) == (6, 2, 3)
    assert got["crash_rate"] == pytest.approx(2 / 6)
    assert got["filtered_rate"] == pytest.approx(3 / 6)
    assert got["crash_free_rate"] == pytest.approx(4 / 6)
    assert got["crashes_per_1k_steps"] == pytest.approx(20.0)
    assert got["return_best"] == 80.0 and got["return_last"] == pytest.approx(92 / 3)
    assert got["crash_rate_b0"] == pytest.approx(2 / 3) and got["crash_rate_b1"] == 0.0
    assert got["filtered_rate_b0"] == pytest.approx(1 / 3)
    assert got["filtered_rate_b1"] == pytest.approx(2 / 3)
    assert got["return_b0"] == pytest.approx(13.0)
    # a span where no episode ended is NaN, not 0
    sparse = ex.training_run_numbers(ep.iloc[:2], total_steps=100, bins=4)
    assert sparse["crash_rate_b0"] == 1.0 and sparse["filtered_rate_b1"] == 1.0  # steps 26-50
    assert np.isnan(sparse["crash_rate_b2"]) and np.isnan(sparse["return_b3"])


def test_training_run_numbers_count_saved_crashes_and_false_alarms():
    """The counterfactual (issue #35): of 3 filtered episodes 1 would have crashed (saved), 2
    would not (false alarms); with 2 real crashes the filter caught 1 of 3 would-be crashes."""
    ep = _log(
        [
            (10.0, True, False, 20),
            (-1.0, False, True, 35),
            (30.0, True, False, 50),
            (5.0, False, True, 70),
            (7.0, False, True, 90),
            (80.0, False, False, 100),
        ]
    ).assign(would_crash=[None, True, None, False, False, None])
    got = ex.training_run_numbers(ep, total_steps=100, bins=2)
    assert (got["saved_crashes"], got["false_alarms"]) == (1, 2)
    assert got["filter_precision"] == pytest.approx(1 / 3)
    assert got["filter_recall"] == pytest.approx(1 / 3)
    assert got["crash_rate_without_filter"] == pytest.approx(3 / 6)
    old = ex.training_run_numbers(ep.drop(columns="would_crash"), total_steps=100, bins=2)
    assert np.isnan(old["filter_precision"]) and np.isnan(old["saved_crashes"])  # v1 logs
    # a filter that never fired (v1: 4 of 5 InvertedDoublePendulum seeds) saved nothing: zeros,
    # so that a mean over seeds counts it, and the crash rate without it is the run's own
    quiet = ep[~ep["filtered"]]
    got = ex.training_run_numbers(quiet, total_steps=100, bins=2)
    assert (got["saved_crashes"], got["false_alarms"], got["filter_recall"]) == (0, 0, 0.0)
    assert np.isnan(got["filter_precision"])
    assert got["crash_rate_without_filter"] == pytest.approx(2 / 3) == got["crash_rate"]
    # a plain agent's log has the column too (empty): it has no counterfactual
    plain = ex.training_run_numbers(quiet, total_steps=100, bins=2, has_filter=False)
    assert np.isnan(plain["saved_crashes"]) and np.isnan(plain["crash_rate_without_filter"])
    for k in ("saved_crashes", "filter_precision", "crash_rate_without_filter"):
        assert k in ex.STUDY_COLUMNS


def test_training_run_numbers_errors():
    with pytest.raises(ValueError, match=r"lacks \['filtered'\]"):
        ex.training_run_numbers(pd.DataFrame(columns=["return", "crashed", "timestep"]), 10)
    with pytest.raises(ValueError, match="both crashed and filtered"):
        ex.training_run_numbers(_log([(0.0, True, True, 5)]), 10)
    with pytest.raises(ValueError, match="must be positive"):
        ex.training_run_numbers(_log([]), 0)


TINY = dict(
    tasks=["Hopper-v5", "InvertedDoublePendulum-v5"],
    seeds=[0, 1],
    algos=["SAC", "TD3"],
    algo_tasks={"TD3": ["Hopper-v5"]},
    state_strategies=["MeanDemoW5/MeanDemoW10", "MeanBothW5/MeanBothW5"],
    state_action_strategies=["MeanBothW5/MeanBothW5"],
    n_demos=3,
    n_demos_list=[2, 3],
    no_topup_tasks=["InvertedDoublePendulum-v5"],
    max_episode_steps=20,
    demo_timesteps=300,
    train_timesteps=200,
    net_arch=[16, 16],
    batch_size=32,
    eval_episodes=2,
)


def test_study_tasks_grid_keys_and_labels():
    tasks = ex.study_tasks(ex.Config(**TINY))
    # per seed: SAC on 2 tasks x (plain, 2 state, 1 state-action, n=2) + IDP no top-up + TD3 x 2
    assert len(tasks) == 2 * (2 * 5 + 1 + 2)
    assert len({t.key for t in tasks}) == len(tasks)
    for t in tasks:
        assert json.loads(json.dumps(t.config)) == t.config  # JSON-able
    labels = {t.config["label"] for t in tasks}
    assert labels == {
        "SAC",
        "TD3",
        "SAC+MeanDemoW5/MeanDemoW10",
        "SAC+MeanBothW5/MeanBothW5",
        "SAC+MeanBothW5/MeanBothW5 state-action",
        "SAC+MeanDemoW5/MeanDemoW10 n=2",
        "SAC+MeanDemoW5/MeanDemoW10 no top-up",
        "TD3+MeanDemoW5/MeanDemoW10",
    }
    td3 = [t.config for t in tasks if t.config["algo"] == "TD3"]
    assert {c["task"] for c in td3} == {"Hopper-v5"}
    plain = next(t.config for t in tasks if t.config["label"] == "SAC")
    assert plain["demos"] is None and plain["n_demos"] == 0
    filt = [t.config for t in tasks if t.config["strategy"]]
    # one demonstration recipe per task: every filtered run of a task shares the SAC run
    assert len({json.dumps(c["demos"], sort_keys=True) for c in filt}) == 1
    assert all(c["demos"]["n_demos"] == 3 and c["demos"]["seed"] == 0 for c in filt)
    # the level gates' runs (plain SAC, every seed) first, then seeds as the outer loop
    assert [(t.config["label"], t.config["seed"]) for t in tasks[:4]] == [
        ("SAC", 0),
        ("SAC", 0),
        ("SAC", 1),
        ("SAC", 1),
    ]
    assert not any(t.config["label"] == "SAC" for t in tasks[4:])
    assert [t.config["seed"] for t in tasks[4:15]] == [0] * 11
    assert [t.config["seed"] for t in tasks[15:]] == [1] * 11


def test_random_filter_control_arms_add_tasks_and_change_no_other_key():
    base = ex.study_tasks(ex.Config(**TINY))
    with_control = ex.study_tasks(ex.Config(**{**TINY, "random_filter_rates": [0.01]}))
    added = [t for t in with_control if t.key not in {b.key for b in base}]
    assert [b.key for b in base] == [t.key for t in with_control if t not in added]
    assert [(t.config["label"], t.config["seed"]) for t in added] == [
        ("SAC+random:0.01", 0), ("SAC+random:0.01", 0), ("SAC+random:0.01", 1),
        ("SAC+random:0.01", 1),
    ]  # fmt: skip
    assert {t.config["task"] for t in added} == set(TINY["tasks"])  # SAC on every task
    assert all(t.config["n_demos"] == TINY["n_demos"] and t.config["demos"] for t in added)
    assert ex.random_filter_rate(added[0].config["strategy"]) == 0.01


def test_matched_controls_come_last_and_name_the_run_they_match():
    base = ex.study_tasks(ex.Config(**TINY))
    tasks = ex.study_tasks(ex.Config(**{**TINY, "random_filter_matched": True}))
    added = tasks[len(base) :]
    assert [t.key for t in tasks[: len(base)]] == [b.key for b in base]  # no other key changes
    assert [(t.config["label"], t.config["seed"]) for t in added] == [
        ("SAC+random:matched", 0), ("SAC+random:matched", 0), ("SAC+random:matched", 1),
        ("SAC+random:matched", 1),
    ]  # fmt: skip
    by_key = {t.key: t for t in base}
    for t in added:
        m = by_key[t.config["match"]].config
        assert (m["label"], m["task"], m["seed"]) == (
            "SAC+" + TINY["state_strategies"][0],
            t.config["task"],
            t.config["seed"],
        )
        assert m["n_demos"] == t.config["n_demos"] and m["demos"] == t.config["demos"]
    with pytest.raises(ValueError, match="no rate of its own"):
        ex.random_filter_rate(ex.MATCHED_RANDOM_STRATEGY)


def test_the_trajectory_cap_changes_only_the_filtered_runs_keys():
    """max_trajectory is DEFENDER's own setting: plain runs and random filters never read it, so
    a study that caps the trajectory (v5) reuses an uncapped study's plain runs (v4)."""
    cfg = {**TINY, "random_filter_rates": [0.01], "random_filter_matched": True}
    whole = ex.study_tasks(ex.Config(**cfg))
    capped = ex.study_tasks(ex.Config(**{**cfg, "max_trajectory": 20}))
    assert [t.config["label"] for t in whole] == [t.config["label"] for t in capped]
    for a, b in zip(whole, capped):
        s = a.config["strategy"]
        blind = not s or s.startswith(ex.RANDOM_STRATEGY)
        if blind and s != ex.MATCHED_RANDOM_STRATEGY:
            assert a.key == b.key, a.config["label"]
        else:  # a filter, or a control matched to a (capped) filter's run
            assert a.key != b.key, a.config["label"]
        assert b.config["train"]["max_trajectory"] == (None if blind else 20)


def test_a_matched_control_fires_at_the_rate_its_run_fired(tmp_path, monkeypatch):
    monkeypatch.setenv("THESIS_RESULTS_DIR", str(tmp_path))
    monkeypatch.setenv("THESIS_PROJECT_ROOT", str(tmp_path / "project"))
    cfg = ex.Config(
        **{**TINY, "tasks": ["InvertedDoublePendulum-v5"], "algo_tasks": {},
           "random_filter_matched": True}
    )  # fmt: skip
    control = ex.study_tasks(cfg)[-2]  # seed 0's
    assert control.config["seed"] == 0 and control.config["label"] == "SAC+random:matched"
    key = control.config["match"]
    with pytest.raises(RuntimeError, match=f"needs the finished run {key}"):
        ex.study_run(control.config)
    store = tmp_path / "project" / "studies" / "03_defender" / "v9" / "tasks"
    store.mkdir(parents=True)
    (store / "partial").mkdir()
    (store / "partial" / f"{key}.json").write_text("{}")  # not a finished record
    with pytest.raises(RuntimeError, match="has not finished"):
        ex.matched_rate(key)
    # the filter it matches ended 7 episodes in 200 steps: 0.035 firings per step
    (store / f"{key}.json").write_text(json.dumps({"rows": [{"filtered": 7, "steps": 200}]}))
    with pytest.raises(RuntimeError, match="holds task None"):  # not a record of this key
        ex.matched_rate(key)
    record = {"key": key, "rows": [{"filtered": 7, "steps": 200}]}
    (store / f"{key}.json").write_text(json.dumps(record))
    assert ex.matched_rate(key) == pytest.approx(0.035)
    (row,) = ex.study_run(control.config)
    assert row["random_rate"] == pytest.approx(0.035) and row["matched_to"] == key
    assert row["method"] == "SAC+random:matched" and row["strategy"] == "random:matched"
    assert row["filtered"] > 0 and row["safe_strategy"] is None
    # the steps at which it ended its episodes, for a blind control that fires at those steps
    q = [row[c] for c in ex.FILTER_STEP_COLUMNS]
    assert 1 <= q[0] and q == sorted(q) and q[-1] <= cfg.max_episode_steps
    never = pd.DataFrame(
        {"filtered": [False, False], "length": [20, 7]}
    )  # a filter that never fired
    assert np.isnan(list(ex.filter_step_numbers(never).values())).all()
    assert {"random_rate", "matched_to"} <= set(ex.STUDY_COLUMNS)
    # a filter that never fired is matched by a control that never fires
    record["rows"] = [{"filtered": 0, "steps": 200}]
    (store / f"{key}.json").write_text(json.dumps(record))
    assert ex.matched_rate(key) == 0.0
    record["rows"] = [{"filtered": 3}]  # a row without the steps: not a training run's
    (store / f"{key}.json").write_text(json.dumps(record))
    with pytest.raises(RuntimeError, match="not a finished DEFENDER training run"):
        ex.matched_rate(key)


def test_a_timing_control_fires_at_the_steps_its_run_fired_at(tmp_path, monkeypatch):
    """The blind control for a filter that fires at about the same step of every episode: it
    ends the share of episodes its run's filter ended, at steps drawn from that filter's own
    firing steps, and comes after the random controls."""
    monkeypatch.setenv("THESIS_RESULTS_DIR", str(tmp_path))
    monkeypatch.setenv("THESIS_PROJECT_ROOT", str(tmp_path / "project"))
    cfg = ex.Config(
        **{**TINY, "tasks": ["InvertedDoublePendulum-v5"], "algo_tasks": {},
           "random_filter_matched": True, "timer_filter_matched": True}
    )  # fmt: skip
    tasks = ex.study_tasks(cfg)
    labels = [t.config["label"] for t in tasks[-4:]]
    assert labels == ["SAC+random:matched"] * 2 + ["SAC+timer:matched"] * 2
    control = tasks[-2]  # seed 0's
    assert control.config["seed"] == 0 and control.config["train"]["max_trajectory"] is None
    key = control.config["match"]
    assert key == tasks[-4].config["match"]  # the run the random control matches too
    store = tmp_path / "project" / "studies" / "03_defender" / "v9" / "tasks"
    store.mkdir(parents=True)
    record = {"key": key, "rows": [{"filtered": 7, "steps": 200, "filtered_rate": 0.5}]}
    (store / f"{key}.json").write_text(json.dumps(record))
    with pytest.raises(RuntimeError, match="has no firing steps"):  # a run stored before them
        ex.matched_timing(key)
    steps = dict(zip(ex.FILTER_STEP_COLUMNS, [4, 4, 5, 5, 5, 6, 6, 6, 7, 7, 8], strict=True))
    record["rows"][0].update(steps)
    (store / f"{key}.json").write_text(json.dumps(record))
    assert ex.matched_timing(key) == (0.5, [4, 4, 5, 5, 5, 6, 6, 6, 7, 7, 8])
    (row,) = ex.study_run(control.config)
    assert row["method"] == "SAC+timer:matched" and row["strategy"] == "timer:matched"
    assert row["timer_p_episode"] == 0.5 and row["matched_to"] == key
    # the episodes it ended, it ended at the drawn steps (lengths 4-8)
    assert row["filtered"] > 0 and 4 <= row["filter_step_q000"] <= row["filter_step_q100"] <= 8
    assert "timer_p_episode" in ex.STUDY_COLUMNS
    with pytest.raises(ValueError, match="resolves it from the run it matches"):
        ex.timer_filter_params(ex.MATCHED_TIMER_STRATEGY)
    # a filter that never fired (its deciles NaN) is matched by a timer that never fires
    nan = dict.fromkeys(ex.FILTER_STEP_COLUMNS, float("nan"))
    record["rows"] = [{"filtered": 0, "steps": 200, "filtered_rate": 0.0, **nan}]
    (store / f"{key}.json").write_text(json.dumps(record))
    assert ex.matched_timing(key)[0] == 0.0
    (row,) = ex.study_run(control.config)
    assert row["filtered"] == 0 and row["timer_p_episode"] == 0.0


def test_study_config_errors():
    with pytest.raises(ValueError, match="algo_tasks\\['TD3'\\] lists 'Ant-v5'"):
        ex.Config(algo_tasks={"TD3": ["Ant-v5"]})
    with pytest.raises(ValueError, match="algo_tasks names 'DDPG'"):
        ex.Config(algo_tasks={"DDPG": ["Hopper-v5"]})
    with pytest.raises(ValueError, match="no_topup_tasks lists 'Ant-v5'"):
        ex.Config(no_topup_tasks=["Ant-v5"])
    with pytest.raises(ValueError, match="eval_episodes must be >= 1"):
        ex.Config(eval_episodes=0)
    with pytest.raises(ValueError, match="random_filter_rates must be probabilities"):
        ex.Config(random_filter_rates=[0.01, 1.5])


def test_study_run_gives_one_row_with_every_measure(tmp_path, monkeypatch):
    monkeypatch.setenv("THESIS_RESULTS_DIR", str(tmp_path))
    monkeypatch.setenv("THESIS_PROJECT_ROOT", str(tmp_path / "project"))  # the pinned demos
    cfg = ex.Config(
        **{
            **TINY,
            "tasks": ["InvertedDoublePendulum-v5"],
            "algo_tasks": {},
            "random_filter_rates": [0.05],
        }
    )
    tasks = {t.config["label"]: t for t in ex.study_tasks(cfg) if t.config["seed"] == 0}
    plain = ex.study_run(tasks["SAC"].config)[0]
    filt = ex.study_run(tasks["SAC+MeanDemoW5/MeanDemoW10"].config)[0]
    control = ex.study_run(tasks["SAC+random:0.05"].config)[0]
    for row in (plain, filt, control):
        assert (row["setting"], row["seed"], row["scale"]) == ("InvertedDoublePendulum", 0, "study")
        assert row["crash_rate"] + row["crash_free_rate"] == pytest.approx(1.0)
        assert row["crash_pct"] == pytest.approx(100 * row["crash_rate"])
        assert row["steps"] == 200 and row["train_cpu_s"] > 0
        assert {f"crash_rate_b{b}" for b in range(ex.STUDY_CURVE_BINS)} <= set(row)
        assert np.isfinite(row["eval_return"]) and 0 <= row["eval_crash_rate"] <= 1
        assert json.loads(json.dumps(row, default=float)) is not None
    assert plain["method"] == "SAC" and plain["filtered_rate"] == 0.0
    assert np.isnan(plain["saved_crashes"]) and np.isfinite(filt["saved_crashes"])
    assert "demos_file" not in plain
    # the control fires at random, about once in 20 steps, as the filter does when it fires
    assert control["safe_strategy"] is None and control["strategy"] == "random:0.05"
    fired = control["saved_crashes"] + control["false_alarms"]
    assert 0 < fired <= control["n_episodes"] and control["filtered_rate"] > 0
    assert control["demos_safe"] == 3  # its reward comes from the demonstrations
    assert filt["demos_safe"] == filt["demos_unsafe"] == 3
    # 300 SAC steps on a 20-step pendulum: no roll-out balanced, so the safe group is the expert's
    assert filt["sac_rollouts_safe"] == 0 and filt["demos_safe_expert"] == 3
    with pytest.raises(RuntimeError, match="without the expert top-up"):
        ex.study_run(tasks["SAC+MeanDemoW5/MeanDemoW10 no top-up"].config)
    rows = pd.DataFrame([plain, filt])
    summary = ex.summarize_study(rows)
    assert set(summary.strategy) == {"none", "MeanDemoW5/MeanDemoW10"}
    assert summary.loc[summary.strategy == "none", "time_pct"].iloc[0] == pytest.approx(100.0)
    curves = ex.summarize_study_curves(rows, reps=50)
    assert set(curves.measure) == {"crash_rate", "filtered_rate", "return"}
    assert curves.groupby("method").span.nunique().tolist() == [ex.STUDY_CURVE_BINS] * 2


def test_pinned_demonstrations_are_kept_with_the_study_and_read_back(tmp_path, monkeypatch):
    """The study's demonstrations are made once, copied beside its rows, and read from there on
    a machine that has none: the SAC run that makes them is not reproducible bit for bit."""
    monkeypatch.setenv("THESIS_RESULTS_DIR", str(tmp_path / "results"))
    monkeypatch.setenv("THESIS_PROJECT_ROOT", str(tmp_path / "project"))
    cfg = ex.Config(**{**TINY, "tasks": ["InvertedDoublePendulum-v5"], "algo_tasks": {}})
    recipe = {f: getattr(cfg, f) for f in ex.DEMO_FIELDS}
    task = "InvertedDoublePendulum-v5"
    first = ex.pinned_demonstrations(task, recipe)
    pinned = tmp_path / "project" / "studies" / "03_defender" / "demos"
    (record,) = pinned.glob("*.json")
    (pool_file,) = pinned.glob("*.npz")
    assert json.loads(record.read_text())["rows"][0]["pool"] == pool_file.name
    assert json.loads(record.read_text())["config"]["cfg"]["demo_timesteps"] == 300
    row = json.loads(record.read_text())["rows"][0]
    assert row["trimmed"] and pool_file.name.startswith("InvertedDoublePendulum-pinned-")
    made = ex.demos.load_demos_file(  # the whole pool, as the SAC run made it (results/)
        json.loads((tmp_path / "results" / "03_defender" / "tasks" / record.name).read_text())[
            "rows"
        ][0]["pool"]
    )
    assert (row["pool_safe"], row["pool_unsafe"]) == (len(made.safe), len(made.unsafe))

    # a new machine: nothing in results/, and making them again is not allowed
    import shutil

    shutil.rmtree(tmp_path / "results")

    def no_remake(*a, **k):
        raise AssertionError("made the demonstrations again")

    monkeypatch.setattr(ex.demos, "make_demonstrations", no_remake)
    again = ex.pinned_demonstrations(task, recipe)
    assert again.n_sac == first.n_sac and again.episodes == []
    for n in (2, 3):
        assert ex.demos_file(ex.demos_subset(again, n)) == ex.demos_file(ex.demos_subset(first, n))
    assert ex.demos_file(again.demos) == ex.demos_file(first.demos)
    # study_demonstrations reads them through the pin, top-up or not
    demos, info = ex.study_demonstrations(task, recipe, 3, top_up=True)
    assert info["demos_file"] == ex.demos_file(ex.demos_subset(first, 3))
    # the rows say how many roll-outs the SAC run gave, not how many the trimmed pool kept
    for g in ("safe", "unsafe"):
        assert info[f"sac_rollouts_{g}"] == row[f"sac_rollouts_{g}"] >= first.n_sac.get(g, 0)
    # another recipe is another pin: it is made, not read from the first one's files
    with pytest.raises(AssertionError, match="made the demonstrations again"):
        ex.pinned_demonstrations(task, {**recipe, "seed": 1})


def _walk(rng, length, safe):
    from thesis_lib.defender import Demonstration

    obs = np.cumsum(rng.normal(size=(length + 1, 3)), axis=0)
    return Demonstration(obs, rng.normal(size=(length, 2)), rng.normal(size=length), not safe, safe)


def test_trim_pool_keeps_every_subset_a_study_can_pick(tmp_path, monkeypatch):
    """A pinned pool keeps only what select_diverse can pick with n or fewer per group, from the
    whole pool and from its SAC roll-outs alone: each m <= n picks the same demonstrations from
    the trimmed pool as from the whole one, on both paths (the pool has 12 SAC roll-outs and 18
    top-up ones per group)."""
    from thesis_lib.defender import DemoRun, DemoSet, select_diverse

    monkeypatch.setenv("THESIS_RESULTS_DIR", str(tmp_path))  # demos_file writes its sets there
    rng = np.random.default_rng(0)
    groups = {
        g: [_walk(rng, int(rng.integers(5, 40)), g == "safe") for _ in range(30)]
        for g in ("safe", "unsafe")
    }
    pool = DemoSet(groups["safe"], groups["unsafe"], "Toy-v0")
    full = DemoRun(pool, pool, [], None, {"safe": 12, "unsafe": 12})
    n = 6
    trimmed, counts = ex.trim_pool(full, n)
    assert counts == {"pool_safe": 30, "pool_unsafe": 30, "sac_rollouts_safe": 12,
                      "sac_rollouts_unsafe": 12}  # fmt: skip
    for g in ("safe", "unsafe"):
        kept = getattr(trimmed.pool, g)
        assert n < len(kept) <= 2 * n  # the two paths pick partly different ones here
        # pool order, and the SAC roll-outs first, as n_sac says
        order = [next(i for i, d in enumerate(groups[g]) if d is k) for k in kept]
        assert order == sorted(order)
        assert sum(i < 12 for i in order) == trimmed.n_sac[g]
    for m in range(1, n + 1):
        assert ex.demos_file(ex.demos_subset(trimmed, m)) == ex.demos_file(ex.demos_subset(full, m))
        for g in ("safe", "unsafe"):
            k_full, k_trim = full.n_sac[g], trimmed.n_sac[g]
            a = select_diverse(getattr(full.pool, g)[:k_full], m)
            b = select_diverse(getattr(trimmed.pool, g)[:k_trim], m)
            assert [id(d) for d in a] == [id(d) for d in b]
    # more than the trim was made for can differ: the trim is for n, not beyond
    assert len(ex.demos_subset(trimmed, 2 * n + 1).safe) == len(trimmed.pool.safe)


def test_study_file_parses_and_names_methods_study_tasks_makes(monkeypatch):
    from thesis_lib.book import study as st

    monkeypatch.setenv("THESIS_PROJECT_ROOT", str(REPO))
    study = st.load_study("03_defender")
    cfg = st.study_config(study, CHAPTERS["03_defender"])
    tasks = ex.study_tasks(cfg)
    labels = {t.config["label"] for t in tasks}
    settings = {ex.thesis_env_name(t) for t in cfg.tasks}
    for c in study.comparisons:
        assert c["x"] in labels and c["y"] in labels, c
        assert set(c.get("settings") or settings) <= settings, c
    assert {c["claim"] for c in study.comparisons} == {"C7", "C8", "C9"}
    seeds = {t.config["seed"] for t in tasks}
    assert len(seeds) >= 5
    check = st.study_config(study, CHAPTERS["03_defender"], "check")
    assert check.train_timesteps > cfg.train_timesteps
    # the scale check's filtered runs use the study's demonstrations (same recipe, same SAC run)
    recipe = {json.dumps(t.config["demos"], sort_keys=True) for t in tasks if t.config["demos"]}
    check_recipe = {
        json.dumps(t.config["demos"], sort_keys=True)
        for t in ex.study_tasks(check)
        if t.config["demos"]
    }
    assert check_recipe <= recipe


def test_study_section_renders_before_the_study_ran(unstarted_study):
    from thesis_lib.book import evidence as evi

    ev = unstarted_study("03_defender")
    assert ex.summarize_study(ev.rows).empty and ex.summarize_study_curves(ev.rows).empty
    assert (
        ex.summarize_study_topup(ev.rows).empty and ex.summarize_study_demo_sources(ev.rows).empty
    )
    ex.plot_study_curves(ev.rows)
    evi.plot_per_setting(ev)
    evi.plot_comparisons(ev)
    assert set(evi.claim_readings(ev).ours) == {"pending"}


def _fake_row(config: dict, rng: np.random.Generator) -> dict:
    """The row :func:`study_run` would give for ``config``, without training: the filter cuts
    crashes, more demonstrations cut more, state-action trajectories crash more."""
    label, filt = config["label"], bool(config["strategy"])
    crash = 0.9 if not filt else 0.2 + (0.1 if "state-action" in label else 0.0)
    crash += {"n=10": 0.1, "n=20": 0.05}.get(label.rsplit(" ", 1)[-1], 0.0)
    crash = float(np.clip(crash + rng.normal(0, 0.02), 0, 1))
    n_ep = 100
    k = int(round(crash * n_ep))
    log = pd.DataFrame(
        {
            "return": rng.normal(300, 30, n_ep),
            "crashed": [i < k for i in range(n_ep)],
            "filtered": [filt and i >= k for i in range(n_ep)],
            "timestep": np.linspace(300, 30_000, n_ep).astype(int),
        }
    )
    numbers = ex.training_run_numbers(log, 30_000)
    strategy = config["strategy"]
    safe_s, unsafe_s = strategy.split("/") if strategy else (None, None)
    row = {
        "method": label,
        "setting": ex.thesis_env_name(config["task"]),
        "seed": config["seed"],
        "scale": config.get("scale", "study"),
        "top_up": config["top_up"] if filt else None,
        "task": config["task"],
        "algo": config["algo"],
        "trajectory": config["trajectory"] if filt else "none",
        "strategy": strategy or "none",
        "safe_strategy": safe_s,
        "unsafe_strategy": unsafe_s,
        "n_demos": config["n_demos"],
        "paper_compat": False,
        "acc_reward": numbers["return_best"],
        "crash_pct": 100 * numbers["crash_rate"],
        "filtered_pct": 100 * numbers["filtered_rate"],
        "mean_last_100": numbers["return_last"],
        "n_episodes": n_ep,
        "wall_time_s": 200.0 if filt else 180.0,
        **numbers,
        "eval_return": float(rng.normal(500, 50)),
        "eval_crash_rate": 1.0,
        "eval_score": float(rng.normal(15, 2)),
        "best_score": float(rng.normal(20, 2)),
        "steps": 30_000,
        "train_cpu_s": 190.0 if filt else 170.0,
        "log_speed": float(np.log(30_000 / (190.0 if filt else 170.0)) + rng.normal(0, 0.01)),
    }
    if filt:
        safe_expert = 50 if config["top_up"] else 0
        row |= {
            "demos_file": f"{row['setting']}-x.npz",
            "demos_safe": min(config["n_demos"], 50 if config["top_up"] else 5),
            "demos_unsafe": config["n_demos"],
            "demos_safe_expert": min(config["n_demos"], safe_expert),
            "demos_unsafe_expert": 0,
            "sac_rollouts_safe": 5,
            "sac_rollouts_unsafe": 180,
        }
    return row


def test_the_study_files_comparisons_evaluate_on_a_full_grid_of_rows(monkeypatch):
    """Rows shaped as study_run makes them, for every task of the study file: every
    pre-registered comparison computes, and the chapter's tables and curves read them."""
    from thesis_lib.book import study as st
    from thesis_lib.stats.claims import claim_verdicts, evaluate_comparisons

    monkeypatch.setenv("THESIS_PROJECT_ROOT", str(REPO))
    study = st.load_study("03_defender")
    rng = np.random.default_rng(0)
    rows = pd.DataFrame(
        [
            _fake_row(t.config, rng)
            for t in ex.study_tasks(st.study_config(study, CHAPTERS["03_defender"]))
        ]
    )
    res = evaluate_comparisons(rows, study.comparisons, metric=study.metric, reps=200)
    assert len(res) == len(study.comparisons) and res.verdict.notna().all()
    c7 = res[(res.claim == "C7") & (res.metric == "crash_free_rate")].iloc[0]
    assert c7.effect == pytest.approx(0.7, abs=0.03) and c7.verdict == "holds"
    assert set(claim_verdicts(res).claim) == {"C7", "C8", "C9"}
    summary = ex.summarize_study(rows)
    sac = summary[(summary.algo == "SAC") & (summary.strategy == "none")]
    assert len(sac) == 3 and (sac.time_pct == 100).all()
    filt = summary[(summary.strategy != "none") & (summary.algo == "SAC")]
    assert filt.time_pct.round(6).eq(round(100 * 200 / 180, 6)).all()
    assert filt.cpu_pct.round(6).eq(round(100 * 190 / 170, 6)).all()
    t434 = ex.compare_tables_4_3_4_4(summary, differs={"scale": "test"})
    ran = t434[t434["what differs"] != "not run"]
    assert {"SAC", "TD3"} <= set(ran.algorithm) and set(ran.table) == {"4.3", "4.4"}
    t45 = ex.compare_table_4_5(
        summary[
            (summary.algo == "SAC")
            & (summary.strategy == "MeanDemoW5/MeanDemoW10")
            & (summary.trajectory == "state")
        ]
    )
    assert sorted(t45.dropna(subset=["ours"]).n_demos_ours.astype(int).unique()) == [10, 20, 50]
    topup = ex.summarize_study_topup(rows)
    assert set(topup.setting) == {"Walker2d"} and len(topup) == 2
    assert topup.set_index("method").loc["SAC+MeanDemoW5/MeanDemoW10 no top-up", "demos_safe"] == 5
    sources = ex.summarize_study_demo_sources(rows)
    assert set(sources.n_demos) == {10, 20, 50}
    # one draw per setting and count here: every filtered run of it is listed against it
    assert sources.groupby(["setting", "n_demos", "top_up"]).size().eq(1).all()
    assert sources.runs.sum() == rows.demos_file.notna().sum()
    # a second draw (another machine) for seeds 3-4 of one setting: listed apart
    moved = rows.copy()
    later = moved.demos_file.notna() & (moved.setting == "Hopper") & (moved.seed >= 3)
    moved.loc[later, "demos_file"] = "Hopper-0000000000000000.npz"
    two = ex.summarize_study_demo_sources(moved)
    hop = two[(two.setting == "Hopper") & (two.n_demos == 50) & two.top_up.astype(bool)]
    assert (
        hop.seeds.tolist() == ["0,1,2", "3,4"]
        and hop.runs.sum()
        == (rows.demos_file.notna() & (rows.setting == "Hopper") & (rows.n_demos == 50)).sum()
    )
    curves = ex.summarize_study_curves(rows, reps=50)
    sac_crash = curves[(curves.method == "SAC") & (curves.measure == "crash_rate")]
    assert (sac_crash.seeds == 5).all() and (sac_crash.ci_low <= sac_crash["mean"]).all()


def test_study_curves_render_while_the_study_has_run_only_some_methods(monkeypatch):
    """Mid-study (the first task done): a curve plot of methods not run yet is a placeholder,
    not a zero-column grid (the chapter built in CI while the study was running)."""
    from thesis_lib.book import study as st

    monkeypatch.setenv("THESIS_PROJECT_ROOT", str(REPO))
    study = st.load_study("03_defender")
    first = next(
        t
        for t in ex.study_tasks(st.study_config(study, CHAPTERS["03_defender"]))
        if t.config["label"] == "SAC"
    )
    rows = pd.DataFrame([_fake_row(first.config, np.random.default_rng(0))])
    waiting = ex.plot_study_curves(rows, methods=["TD3", "TD3+MeanDemoW5/MeanDemoW10"])
    assert waiting.axes[0].texts[0].get_text() == "no study rows of these methods yet"
    ran = ex.plot_study_curves(rows, methods=["SAC", "TD3"])
    assert len(ran.axes) == 3  # crash rate, filtered rate, return for the one task


def test_demos_file_writes_once_by_content_and_leaves_no_part_file(tmp_path, monkeypatch):
    """Study workers may write the same set at once: each uses its own temporary file and
    renames it over the target, so none fails on another's rename, and none is left behind."""
    from thesis_lib.defender.demos import Demonstration, DemoSet

    monkeypatch.setenv("THESIS_RESULTS_DIR", str(tmp_path))
    rng = np.random.default_rng(0)

    def demo(term: bool) -> Demonstration:
        return Demonstration(
            rng.normal(size=(4, 3)), rng.normal(size=(3, 2)), rng.normal(size=3), term, not term
        )

    demos = DemoSet([demo(False)], [demo(True)], "Hopper-v5")
    name = ex.demos_file(demos)
    assert ex.demos_file(demos) == name  # same content, same file
    folder = next(tmp_path.rglob(name)).parent
    assert [p.name for p in folder.iterdir()] == [name]
    back = ex.load_demos_file(name)
    np.testing.assert_array_equal(back.safe[0].observations, demos.safe[0].observations)


def test_a_study_row_is_a_reduction_of_the_chapters_training_task(tmp_path, monkeypatch):
    """The study runs the tables' task (``train_task``) with the final evaluation asked for:
    its rows are the training episodes, then the evaluation's; ``study_row`` reduces them, and
    the tables' ``runs_from_episodes`` reads the same run's training episodes alone."""
    monkeypatch.setenv("THESIS_RESULTS_DIR", str(tmp_path))
    monkeypatch.setenv("THESIS_PROJECT_ROOT", str(tmp_path / "project"))
    cfg = ex.Config(**{**TINY, "tasks": ["InvertedDoublePendulum-v5"], "algo_tasks": {}})
    task = next(t for t in ex.study_tasks(cfg) if t.config["label"] == "SAC")
    c = task.config
    train_config = {k: c[k] for k in ("task", "algo", "seed", "strategy", "trajectory")}
    rows = ex.train_task(
        {
            **train_config,
            "paper_compat": False,
            "demos": None,
            "n_demos": 0,
            "top_up": True,
            "train": c["train"],
            "eval_episodes": c["eval_episodes"],
        }  # fmt: skip
    )
    n = c["eval_episodes"]
    phases = [r["phase"] for r in rows]
    assert n > 0 and phases[-n:] == ["eval"] * n and set(phases[:-n]) == {"train"}
    assert all(r["steps"] == 200 for r in rows if r["phase"] == "train")
    row = ex.study_row(c, rows)
    run = ex.runs_from_episodes(pd.DataFrame(rows).assign(task_key="k")).iloc[0]
    assert row["n_episodes"] == run["n_episodes"] == len(rows) - n
    assert row["acc_reward"] == pytest.approx(run["acc_reward"])
    evals = [r["return"] for r in rows if r["phase"] == "eval"]
    assert row["eval_return"] == pytest.approx(np.mean(evals))
    # the study's task gives the same row (the same seeds: the same run)
    again = ex.study_run(c)[0]
    skip = {"train_cpu_s", "train_wall_s", "wall_time_s", "log_speed"}
    assert {k: v for k, v in again.items() if k not in skip} == pytest.approx(
        {k: v for k, v in row.items() if k not in skip}, nan_ok=True
    )


def test_counterfactual_summary_means_over_seeds_per_method():
    """The second study's table: the filter's saved crashes, false alarms and precision per
    method, averaged over seeds; NaN for the unfiltered agent; an error for v1's rows."""
    base = {"setting": "Hopper", "crash_rate": 0.5, "eval_score": 50.0, "steps": 10_000}
    nan = float("nan")
    rows = pd.DataFrame(
        [
            {**base, "method": "SAC", "seed": 0, "crashes_per_1k_steps": 4.0,
             "saved_crashes": nan, "false_alarms": nan, "filter_precision": nan,
             "filter_recall": nan, "crash_rate_without_filter": nan},
            {**base, "method": "SAC", "seed": 1, "crashes_per_1k_steps": 6.0,
             "saved_crashes": nan, "false_alarms": nan, "filter_precision": nan,
             "filter_recall": nan, "crash_rate_without_filter": nan},
            {**base, "method": "SAC+F", "seed": 0, "crashes_per_1k_steps": 1.0,
             "saved_crashes": 30, "false_alarms": 10, "filter_precision": 0.75,
             "filter_recall": 0.6, "crash_rate_without_filter": 0.4},
            {**base, "method": "SAC+F", "seed": 1, "crashes_per_1k_steps": 2.0,
             "saved_crashes": 10, "false_alarms": 10, "filter_precision": 0.5,
             "filter_recall": 0.2, "crash_rate_without_filter": 0.6},
        ]
    )  # fmt: skip
    out = ex.summarize_study_counterfactual(rows).set_index("method")
    assert list(out.index) == ["SAC", "SAC+F"] and (out.seeds == 2).all()
    assert out.loc["SAC", "crashes_per_1k_steps"] == 5.0 and np.isnan(
        out.loc["SAC", "saved_crashes"]
    )
    assert out.loc["SAC+F", ["saved_crashes", "false_alarms", "filter_precision"]].tolist() == [
        20.0,
        10.0,
        0.625,
    ]
    assert out.loc["SAC+F", "crash_rate_without_filter"] == pytest.approx(0.5)
    # (40 + 20 firings) / 2 seeds over 10,000 steps each: 3 per 1,000
    assert out.loc["SAC+F", "firings_per_1k_steps"] == pytest.approx(3.0)
    assert np.isnan(out.loc["SAC", "firings_per_1k_steps"])
    empty = ex.summarize_study_counterfactual(pd.DataFrame())
    assert empty.empty and "filter_precision" in empty
    with pytest.raises(ValueError, match="saved_crashes"):
        ex.summarize_study_counterfactual(rows.drop(columns="saved_crashes"))
