"""UR3 model, reaching task, demonstrations, dance playback and Table 5.4 at tiny scale."""

from __future__ import annotations

import numpy as np
import pytest

from thesis_lib.ur3 import dance, model, reach, safety
from thesis_lib.ur3.model import DH, UR3Kinematics, build_mjcf, dh_transform, fk_dh


# -- model ------------------------------------------------------------------------------------
def test_shipped_mjcf_is_the_generated_one():
    assert model.asset_path().read_text() == build_mjcf()


def test_mujoco_fk_equals_dh_product():
    kin = UR3Kinematics()
    rng = np.random.default_rng(0)
    for _ in range(50):
        q = rng.uniform(-2 * np.pi, 2 * np.pi, 6)
        np.testing.assert_allclose(kin.tcp_pose(q), fk_dh(q)[6], atol=1e-10)


def test_dh_closed_forms():
    # all zero: the arm stretched along -x; x = a2 + a3, y = -(d4 + d6), z = d1 - d5
    p = fk_dh(np.zeros(6))[6][:3, 3]
    np.testing.assert_allclose(
        p, [DH.a[1] + DH.a[2], -(DH.d[3] + DH.d[5]), DH.d[0] - DH.d[4]], atol=1e-12
    )
    # base rotation by 90 degrees rotates the flange position about z
    q = np.zeros(6)
    q[0] = np.pi / 2
    p90 = fk_dh(q)[6][:3, 3]
    np.testing.assert_allclose(p90, [-p[1], p[0], p[2]], atol=1e-12)
    T = dh_transform(0.3, 0.1, 0.2, np.pi / 2)
    np.testing.assert_allclose(T[:3, :3] @ T[:3, :3].T, np.eye(3), atol=1e-12)


def test_model_limits_and_speeds_in_mjcf():
    kin = UR3Kinematics()
    np.testing.assert_allclose(kin.position_limits, model.POSITION_LIMITS)
    np.testing.assert_allclose(kin.max_speed, [np.pi] * 3 + [2 * np.pi] * 3, rtol=1e-5)
    with pytest.raises(ValueError, match=r"\(\.\.\., 6\)"):
        fk_dh(np.zeros(5))


# -- reaching task ------------------------------------------------------------------------------
def test_reward_and_one_hot_bookkeeping():
    goals = np.array([[0.5] * 6, [1.0] * 6])
    env = reach.UR3ReachEnv(
        goals=goals, max_step=0.5, tolerance=0.05, start=np.zeros(6), max_steps=10
    )
    obs, _ = env.reset()
    assert obs.shape == (8,) and obs[6:].tolist() == [0, 0]
    obs, r, term, trunc, info = env.step(
        np.ones(6) * 0.5
    )  # q = 0.25: nearest open goal 0, L1 error 1.5
    assert r == pytest.approx(-1.5) and obs[6:].tolist() == [0, 0] and not term
    obs, r, term, trunc, info = env.step(np.ones(6) * 0.5)  # q = 0.5: reaches goal 0, rewarded 0
    assert r == pytest.approx(0.0) and obs[6:].tolist() == [1, 0] and info["goals_reached"] == 1
    obs, r, *_ = env.step(np.zeros(6))  # goal 0 done: the error now counts to goal 1
    assert r == pytest.approx(-3.0)
    env.step(np.ones(6))
    obs, r, term, trunc, info = env.step(np.zeros(6))
    assert term and not trunc and obs[6:].tolist() == [1, 1]
    assert env.completed[-1]["reach_steps"].tolist() == [2, 4]


def test_truncation_and_action_clipping():
    env = reach.UR3ReachEnv(start=reach.HOME, max_steps=3)
    env.reset()
    env.step(np.full(6, 5.0))  # clipped to 1 -> one max_step
    np.testing.assert_allclose(env.q, reach.HOME + env.max_step)
    env.step(np.zeros(6))
    *_, term, trunc, _ = env.step(np.zeros(6))
    assert trunc and not term and env.completed[-1]["steps"] == 3
    with pytest.raises(ValueError, match="NaN"):
        env.step(np.full(6, np.nan))


def test_goals_are_above_the_table():
    z = model.tcp_position(reach.GOALS)[:, 2]
    assert (z > 0.1).all()


def test_scripted_demonstrations_reach_all_goals():
    eps = reach.make_demonstrations(12, seed=3)
    for e in eps:
        assert e.truncations[-1] and not e.terminations.any() and len(e) < 200
        assert e.observations[-1, 6:].tolist() == [1.0] * 5
        assert (e.observations[-4:-1, 6:] == 1).all() and (e.rewards[-3:] == 0).all()  # the hold
        e.validate()
    starts = np.array([e.observations[0, :6] for e in eps])
    assert len(np.unique(starts.round(6), axis=0)) == 12  # random starts
    assert np.abs(starts - reach.HOME).max() <= reach.START_RANGE + 1e-6


def test_dataset_roundtrip_minari_format(tmp_path, monkeypatch):
    monkeypatch.setenv("THESIS_DATA_DIR", str(tmp_path))
    ds = reach.get_reach_dataset(n_demos=22, seed=1)
    assert (tmp_path / reach.DATASET_ID / "data" / "metadata.json").exists()
    assert ds.env_id == reach.ENV_ID and len(ds) == 22
    direct = reach.make_demonstrations(22, seed=1)
    np.testing.assert_allclose(ds[5].observations, direct[5].observations)
    np.testing.assert_allclose(ds[5].rewards, direct[5].rewards)
    assert ds.metadata["thesis_info"]["n_demos"] == 22
    split = reach.split_demonstrations(ds.episodes, n_train=2, n_val=10, n_test=10)
    np.testing.assert_allclose(split.test_starts[0], ds[12].observations[0, :6])
    with pytest.raises(ValueError, match="Need 100 demonstrations"):
        reach.split_demonstrations(ds.episodes)


def _goal_order(e) -> tuple[int, ...]:
    """The order in which a demonstration reached its goals (from its one-hot entries)."""
    first = [int(np.argmax(e.observations[:, 6 + g] > 0)) for g in range(5)]
    return tuple(int(g) for g in np.argsort(first, kind="stable"))


def test_the_any_order_set_visits_the_goals_in_orders_of_its_own(tmp_path, monkeypatch):
    """``any-order``: each demonstration reaches all five goals, in an order drawn for it (the
    next goal is not a function of the goals reached); ``teleop`` goes in one sequence."""
    monkeypatch.setenv("THESIS_DATA_DIR", str(tmp_path))
    seq = reach.get_reach_dataset(n_demos=12, seed=1)
    anyo = reach.get_reach_dataset(n_demos=12, seed=1, reach_set="any-order")
    assert anyo.id == "thesis/ur3-reach/any-order-v0" and seq.id == reach.DATASET_ID
    assert {_goal_order(e) for e in seq.episodes} == {(0, 1, 2, 3, 4)}
    orders = [_goal_order(e) for e in anyo.episodes]
    assert len(set(orders)) >= 8  # 12 draws of 120 orders
    assert all(e.observations[-1, 6:].tolist() == [1.0] * 5 for e in anyo.episodes)
    assert anyo.metadata["thesis_info"]["controller"]["order"] == "random"
    with pytest.raises(ValueError, match="Unknown reach_set 'hard'. Valid: teleop, any-order"):
        reach.get_reach_dataset(n_demos=12, seed=1, reach_set="hard")


def test_the_reach_set_enters_a_task_only_where_it_is_not_teleop():
    """The v1 study's tasks (teleop) keep their keys; an any-order task has its own."""
    from thesis_lib.chapters.ur3 import Config, reach_config

    teleop = reach_config(Config(), "DT", 10, 0)
    anyo = reach_config(Config(reach_set="any-order"), "DT", 10, 0)
    assert "reach_set" not in teleop and anyo == {**teleop, "reach_set": "any-order"}
    with pytest.raises(ValueError, match="Unknown reach_set"):
        Config(reach_set="hard")


# -- dance ------------------------------------------------------------------------------------
def test_dance_mapping_and_clip():
    a = np.zeros((3, 4))
    a[:, 0] = [0.0, 0.1, 2.0]  # a jump at frame 2: 0.95 rad in 1/60 s
    q = dance.map_dance(a)
    assert q.shape == (3, 6) and q[1, 0] == pytest.approx(0.05)
    p = dance.prepare_dance(a, fps=60, mode="clip")
    assert p.before.counts()["speed"] == 1 and p.after.ok
    assert np.abs(np.diff(p.q, axis=0)).max() * 60 <= np.pi + 1e-9
    with pytest.raises(safety.UnsafeTrajectoryError, match="speed limits broken in 1 of 3 frames"):
        dance.prepare_dance(a, fps=60, mode="reject")
    with pytest.raises(ValueError, match=r"\(T, 4\)"):
        dance.map_dance(np.zeros((3, 6)))


def test_demo_dance_is_deterministic_and_in_range():
    a = dance.demo_angles(seconds=2, fps=30, seed=1)
    assert a.shape == (60, 4) and a.dtype == np.float32
    assert np.abs(a).max() <= np.pi
    np.testing.assert_array_equal(a, dance.demo_angles(seconds=2, fps=30, seed=1))


def test_safety_checks_positions_speed_workspace():
    lim = safety.SafetyLimits()
    q = np.tile(reach.HOME, (4, 1))
    assert safety.check_trajectory(q, 0.1, lim).ok
    bad = q.copy()
    bad[1, 0] = 7.0  # beyond 2 pi
    r = safety.check_trajectory(bad, 100.0, lim)
    assert r.position_frames.tolist() == [1]
    low = q.copy()
    low[2] = [0, 0, 0, 0, 0, 0]  # stretched horizontally: flange 6.7 cm above the table, elbow ok
    low[2, 1] = 0.3  # shoulder tilted down: the flange goes below the table
    r = safety.check_trajectory(low, 100.0, lim)
    assert 2 in r.workspace_frames.tolist() and r.min_tcp_z < 0
    fast = np.array([reach.HOME, reach.HOME + [0.5, 0, 0, 0, 0, 0]])
    r = safety.check_trajectory(fast, 0.1, lim)  # 5 rad/s on the base > pi
    assert r.speed_frames.tolist() == [1] and r.max_speed_ratio == pytest.approx(5 / np.pi)
    with pytest.raises(ValueError, match="NaN"):
        safety.check_trajectory(np.full((2, 6), np.nan), 0.1)


# -- Table 5.4 at tiny scale ------------------------------------------------------------------
def test_table_5_4_tiny():
    import pandas as pd

    from thesis_lib.chapters.ur3 import (
        Config,
        run_reach,
        summarize_reach,
        summarize_success_curves,
    )

    eps = reach.make_demonstrations(24, seed=0)
    demos = reach.split_demonstrations(eps, n_train=4, n_val=0, n_test=3)
    cfg = Config(
        train_demos=[4],
        seeds=[0],
        iterations=3,
        batch_size=4,
        d_model=16,
        n_layers=1,
        warmup_steps=1,
        max_eval_steps=12,
    )
    rows = pd.DataFrame(
        [
            r | {"train_demos": 4}
            for m in ("HDT", "DT")
            for r in run_reach(m, demos.train, demos.test_starts, cfg.arch(), cfg.train_spec(0), 12)
        ]
    )
    assert len(rows) == 6 and set(rows.method) == {"HDT", "DT"}
    assert rows.start.tolist() == [0, 1, 2, 0, 1, 2]
    assert rows.goals_reached.between(0, 5).all() and (rows.steps <= 12).all()
    dt = rows[rows.method == "DT"]
    assert (dt.target_return == max(e.episode_return for e in demos.train)).all()
    t = summarize_reach(rows)
    assert list(t.columns[:4]) == ["method", "train_demos", "goals_mean", "goals_std"]
    curves = summarize_success_curves(rows, horizon=12)
    last = curves[curves.step == 12].set_index("method")["goals_mean"]
    np.testing.assert_allclose(
        last.loc[["HDT", "DT"]].to_numpy(), t.set_index("method").loc[["HDT", "DT"], "goals_mean"]
    )
    with pytest.raises(ValueError, match="Did you mean: 'HDT'"):
        Config(methods=("HTD",))
    with pytest.raises(ValueError, match="train_demos must lie in 1..80"):
        Config(train_demos=[90])


# -- viewer and command line --------------------------------------------------------------------
def test_viewer_is_self_contained_html():
    import re

    from thesis_lib.ur3.viewer import iframe, trajectory_html

    q = np.tile(reach.HOME, (5, 1))
    q[:, 0] = np.linspace(0, 0.5, 5)
    page = trajectory_html(q, fps=10, title="test")
    assert page.lstrip().lower().startswith("<!doctype html") or "<html" in page[:200].lower()
    assert not re.findall(r'(?:src|href)="https?://', page), "the page must not fetch anything"
    assert "test" in page and len(page) > 100_000  # three.js inlined
    assert "srcdoc=" in iframe(page).data
    with pytest.raises(ValueError, match=r"\(T, 6\)"):
        trajectory_html(np.zeros((3, 4)))


def test_cli_check_and_dry_run(tmp_path, capsys):
    from thesis_lib.cli import main

    ok = tmp_path / "ok.csv"
    np.savetxt(ok, np.zeros((30, 4)), delimiter=",", header="a1,a2,a3,a4", comments="")
    assert main(["ur3", "check", str(ok), "--fps", "60"]) == 0
    assert main(["ur3", "play", str(ok)]) == 0
    out = capsys.readouterr().out
    assert "dry-run: movej" in out and "servoj x 30 frames" in out
    jump = tmp_path / "jump.csv"
    a = np.zeros((30, 4))
    a[15:, 0] = 2.0
    np.savetxt(jump, a, delimiter=",")
    assert main(["ur3", "check", str(jump)]) == 2
    assert main(["ur3", "play", str(jump), "--mode", "reject"]) == 2
    assert "speed limits broken in 1 of 30 frames" in capsys.readouterr().err
    assert main(["ur3", "play", str(tmp_path / "missing.csv")]) == 1


@pytest.mark.parametrize("first", ["8.218E-02", "1e3", "nan", "inf", "-INF", "1E+00"])
def test_a_headerless_csv_keeps_its_first_row_whatever_the_float_spelling(tmp_path, first):
    from thesis_lib.cli.ur3 import read_angles

    a = np.full((10, 4), 0.1)
    path = tmp_path / "angles.csv"
    rows = [",".join([first, "0.1", "0.1", "0.1"])] + [",".join(["0.1"] * 4)] * 9
    path.write_text("\n".join(rows) + "\n")
    got = read_angles(path)
    assert got.shape == (10, 4)  # the first row is data, not a header
    a[0, 0] = float(first)
    np.testing.assert_array_equal(got, a)
    path.write_text("shoulder_pan,lift,elbow,wrist\n" + "\n".join(rows[1:]) + "\n")
    assert read_angles(path).shape == (9, 4)  # a real header is still skipped


@pytest.mark.parametrize("cols", [4, 6])
def test_play_in_clip_mode_reports_the_frames_it_clipped(tmp_path, capsys, cols):
    """`check` says 9 of 10 frames break the speed limits; `play` must not claim all is well."""
    from thesis_lib.cli import main

    if cols == 6:
        q = np.tile(reach.HOME, (10, 1))
        q[:, 0] += 0.2 * np.arange(10)
    else:
        q = np.zeros((10, 4))
        q[:, 0] = 0.3 * np.arange(10)
    path = tmp_path / "fast.csv"
    np.savetxt(path, q, delimiter=",")
    assert main(["ur3", "check", str(path)]) == 2
    assert "speed limits broken in 9 of 10 frames" in capsys.readouterr().out
    assert main(["ur3", "play", str(path)]) == 0
    out = capsys.readouterr().out
    assert "speed limits broken in 9 of 10 frames" in out
    assert "9 of 10 frames clipped or slowed" in out
    ok = tmp_path / "still.csv"
    np.savetxt(
        ok, np.zeros((10, cols)) if cols == 4 else np.tile(reach.HOME, (10, 1)), delimiter=","
    )
    assert main(["ur3", "play", str(ok)]) == 0
    assert "clipped" not in capsys.readouterr().out  # nothing to report when nothing changed


def test_mujoco_frames_show_the_arm_and_follow_the_pose():
    """Offscreen MuJoCo frames (EGL, set in conftest) are not blank and change with the pose."""
    from thesis_lib.ur3 import reach
    from thesis_lib.ur3.render import render_frames

    q = np.array([reach.HOME, reach.GOALS[0]])
    frames = render_frames(q, 160, 120, backend="mujoco")
    assert frames.shape == (2, 120, 160, 3) and frames.dtype == np.uint8
    assert frames[0].std() > 10, "a blank frame: cameras/lights not computed before rendering"
    assert np.abs(frames[0].astype(int) - frames[1].astype(int)).mean() > 0.5


def test_study_tasks_cover_the_grid_and_table_5_4_pools_the_runs():
    import pandas as pd

    from thesis_lib.chapters import ur3 as ch

    cfg = ch.Config(seeds=[0, 1], train_demos=[10, 80], iterations=5)
    tasks = ch.study_tasks(cfg)
    grid = {(t.config["method"], t.config["train_demos"], t.config["train"]["seed"]) for t in tasks}
    assert len(tasks) == len(grid) == 2 * 2 * 2
    assert len({t.key for t in tasks}) == len(tasks)
    # two runs of 10 test starts: means 4 and 5, each with std 1 -> pooled mean 4.5, std
    # sqrt(mean(1 + 16, 1 + 25) - 4.5**2) = sqrt(1.25)
    runs = pd.DataFrame(
        [
            {"method": "HDT", "train_demos": 10, "seed": s, "goals_mean": m, "goals_std": 1.0,
             "all_five": a}
            for s, m, a in [(0, 4.0, 0.2), (1, 5.0, 0.6)]
        ]
    )  # fmt: skip
    t = ch.summarize_study(runs).iloc[0]
    assert t.goals_mean == pytest.approx(4.5) and t.goals_std == pytest.approx(1.25**0.5)
    assert t.all_five == pytest.approx(0.4) and t.n_seeds == 2


def test_table_5_4_is_pooled_from_the_runs_as_the_study_rows_are():
    import pandas as pd

    from thesis_lib.chapters import ur3 as ch
    from thesis_lib.sweep import fn_path

    rng = np.random.default_rng(0)
    rows = pd.DataFrame(
        [
            {"method": m, "train_demos": n, "seed": s, "start": k,
             "goals_reached": int(rng.integers(0, 6))}
            for n in (10, 80) for m in ("HDT", "DT") for s in (0, 1, 2) for k in range(10)
        ]
    )  # fmt: skip
    t = ch.summarize_reach(rows)
    g = rows.groupby(["method", "train_demos"], sort=False)["goals_reached"]
    np.testing.assert_allclose(t.goals_mean, g.mean(), rtol=0, atol=1e-12)
    np.testing.assert_allclose(t.goals_std, g.std(ddof=0), rtol=0, atol=1e-12)
    np.testing.assert_allclose(t.all_five, g.apply(lambda x: np.mean(x >= 5)), rtol=0, atol=1e-12)
    assert t.n_episodes.tolist() == [30] * 4
    assert list(t.columns) == [
        "method", "train_demos", "goals_mean", "goals_std", "all_five", "n_episodes"
    ]  # fmt: skip
    # the study's tasks keep the name their committed keys were made with
    assert fn_path(ch.study_run) == "thesis_lib.chapters.ur3:study_run"
    assert fn_path(ch.reach_task) == "thesis_lib.chapters.ur3:reach_task"
