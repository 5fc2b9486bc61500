"""DEFENDER (thesis 4.3): methods against a direct computation, the wrapper's contract, errors."""

from __future__ import annotations

import json

import gymnasium as gym
import numpy as np
import pandas as pd
import pytest
import torch

from thesis_lib.defender import (
    DYNAMICS_TRAIN_EVERY,
    EPISODE_LOG_COLUMNS,
    METHODS,
    STRATEGIES,
    DefenderWrapper,
    Demonstration,
    DemoSet,
    DynamicsModel,
    GroupCost,
    cost_curves,
    expert_demonstrations,
    load_demonstrations,
    method_cost,
    parse_method,
    parse_strategy,
    save_demonstrations,
    select_diverse,
)
from thesis_lib.defender.ablation import first_fire_steps, rank_strategies, strategy_ablation
from thesis_lib.dtw import pack_references


# --------------------------------------------------------------------------- a direct computation
def naive_dtw(x: np.ndarray, y: np.ndarray) -> float:
    """The thesis's recursion with L1 local cost, written out in pure Python."""
    n, m = len(x), len(y)
    d = [[float("inf")] * (m + 1) for _ in range(n + 1)]
    d[0][0] = 0.0
    for i in range(1, n + 1):
        for j in range(1, m + 1):
            cost = float(np.abs(x[i - 1] - y[j - 1]).sum())
            d[i][j] = cost + min(d[i - 1][j], d[i - 1][j - 1], d[i][j - 1])
    return d[n][m]


def direct_cost(traj: np.ndarray, demos: list[np.ndarray], name: str) -> float:
    """A method's cost spelled out from its definition in thesis 4.3.2 (no library windowing)."""
    agg = {"Min": min, "Max": max, "Mean": lambda v: sum(v) / len(v)}[
        name[: 4 if name.startswith("Mean") else 3]
    ]
    rest = name[4:] if name.startswith("Mean") else name[3:]
    costs = []
    for demo in demos:
        if rest == "Full":
            x, y = traj, demo
        elif rest == "Same":  # the demo's last L steps, L = the trajectory's length
            x, y = traj, demo[-len(traj) :]
        else:
            kind, w = rest.split("W")
            w = int(w)
            x = traj[-w:] if kind in ("Traj", "Both") else traj
            y = demo[-w:] if kind in ("Demo", "Both") else demo
        costs.append(naive_dtw(x, y))
    return agg(costs)


@pytest.fixture(scope="module")
def small_groups():
    rng = np.random.default_rng(3)
    demos = [rng.integers(-3, 4, size=(n, 2)).astype(float) for n in (4, 13, 8)]
    traj = rng.integers(-3, 4, size=(12, 2)).astype(float)
    return traj, demos


def test_there_are_24_methods_and_576_strategies():
    assert len(METHODS) == 24 == len(set(METHODS))
    assert len(STRATEGIES) == 576 == len({s.name for s in STRATEGIES})
    assert {parse_method(m).name for m in METHODS} == set(METHODS)
    assert parse_strategy("MinBoth/MinTrajW10").name == "MinSame/MinTrajW10"  # Table 4.4's name


@pytest.mark.parametrize("name", METHODS)
def test_each_method_matches_direct_computation(small_groups, name):
    traj, demos = small_groups
    # one-shot and streaming (every prefix) both equal the definition
    assert method_cost(traj, demos, name) == pytest.approx(direct_cost(traj, demos, name))
    g = GroupCost(demos, name)
    for t in range(len(traj)):
        assert g.append(traj[t]) == pytest.approx(direct_cost(traj[: t + 1], demos, name)), (
            name,
            t,
        )


@pytest.mark.parametrize("name", ["MeanFull", "MinSame", "MaxDemoW5", "MeanTrajW10", "MinBothW5"])
def test_capped_trajectory_uses_last_steps(small_groups, name):
    traj, demos = small_groups
    g = GroupCost(demos, name, max_trajectory=5)
    for t in range(len(traj)):
        got = g.append(traj[t])
        assert got == pytest.approx(direct_cost(traj[max(0, t - 4) : t + 1], demos, name)), (
            name,
            t,
        )
    assert not g.incremental


def test_incremental_used_where_possible(small_groups):
    _, demos = small_groups
    assert GroupCost(demos, "MeanDemoW5").incremental and GroupCost(demos, "MinFull").incremental
    assert (
        not GroupCost(demos, "MeanTrajW5").incremental
        and not GroupCost(demos, "MeanSame").incremental
    )


def test_fastdtw_backend_never_undercuts_exact(small_groups):
    traj, demos = small_groups
    a = GroupCost(demos, "MeanBothW5", backend="fastdtw", max_trajectory=20)
    b = GroupCost(demos, "MeanBothW5", max_trajectory=20)
    for step in traj:
        assert a.append(step) >= b.append(step) - 1e-12  # fastdtw never undercuts exact DTW


def test_cost_curves_match_group_cost(small_groups):
    traj, demos = small_groups
    curves = cost_curves(traj, demos)
    for name in METHODS:
        g = GroupCost(demos, name)
        np.testing.assert_allclose(curves[name], [g.append(s) for s in traj])


def test_first_fire_steps_agrees_with_the_rule(small_groups):
    traj, demos = small_groups
    safe, unsafe = pack_references(demos[:2]), pack_references(demos[2:])
    fires = first_fire_steps(traj, safe, unsafe)
    for i, j in [(0, 0), (5, 17), (18, 3), (23, 23)]:
        gs, gu = GroupCost(safe, METHODS[i]), GroupCost(unsafe, METHODS[j])
        first = next((t for t, s in enumerate(traj) if not gs.append(s) < gu.append(s)), len(traj))
        assert fires[i, j] == first


# --------------------------------------------------------------------------- errors
def test_unknown_method_lists_valid_and_close_match():
    with pytest.raises(
        ValueError,
        match=r"Unknown DEFENDER method 'MeanDemoW7'\. Did you mean: 'MeanDemoW5'\? Valid: MinFull",
    ):
        parse_method("MeanDemoW7")
    with pytest.raises(ValueError, match="written 'safe/unsafe'"):
        parse_strategy("MeanDemoW5")


class CountingEnv(gym.Env):
    """1-D walk: the state moves by the action; terminates when |x| > 3. Counts real steps."""

    observation_space = gym.spaces.Box(-np.inf, np.inf, (2,), np.float32)
    action_space = gym.spaces.Box(-1, 1, (1,), np.float32)

    def __init__(self) -> None:
        self.n_steps = 0
        self.x = 0.0

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        self.x = 0.0
        return np.array([self.x, 0.0], np.float32), {}

    def step(self, action):
        self.n_steps += 1
        self.x += float(np.asarray(action).reshape(-1)[0])
        return np.array([self.x, 1.0], np.float32), 1.0, abs(self.x) > 3, False, {}


def _demo(xs, terminated):
    obs = np.stack([np.asarray(xs, float), np.ones(len(xs))], 1)
    acts = np.diff(obs[:, :1], axis=0)
    return Demonstration(
        obs, acts, np.full(len(acts), 1.0 if not terminated else -5.0), terminated, not terminated
    )


@pytest.fixture()
def walk_demos():
    safe = [_demo(np.zeros(12), False), _demo(0.1 * np.sin(np.arange(12)), False)]
    unsafe = [_demo(np.arange(6) * 1.0, True), _demo(-np.arange(6) * 1.0, True)]
    return safe, unsafe


def make_walk(walk_demos, **kw):
    safe, unsafe = walk_demos
    return DefenderWrapper(
        gym.wrappers.TimeLimit(CountingEnv(), 12),
        safe,
        unsafe,
        safe_method=kw.pop("safe_method", "MinDemoW5"),
        unsafe_method=kw.pop("unsafe_method", "MinDemoW5"),
        **kw,
    )


def test_wrapper_errors_are_clear(walk_demos):
    safe, unsafe = walk_demos
    env = gym.wrappers.TimeLimit(CountingEnv(), 12)
    with pytest.raises(ValueError, match="at least one unsafe demonstration"):
        DefenderWrapper(env, safe, [])
    bad = Demonstration(np.zeros((4, 3)), np.zeros((3, 1)), np.zeros(3), True, False)
    with pytest.raises(
        ValueError, match=r"unsafe demonstration 2 has states of size 3 .* observations of size 2"
    ):
        DefenderWrapper(env, safe, [*unsafe, bad])
    with pytest.raises(ValueError, match="Did you mean: 'MeanDemoW10'"):
        DefenderWrapper(env, safe, unsafe, unsafe_method="MeanDemoW01")
    with pytest.raises(ValueError, match="Unknown trajectory"):
        DefenderWrapper(env, safe, unsafe, trajectory="actions")


def test_wrapper_never_steps_real_env_when_it_filters(walk_demos):
    env = make_walk(walk_demos)
    inner = env.unwrapped
    env.reset(seed=0)
    n_real = 0
    for _ in range(12):
        before = inner.n_steps
        obs, reward, terminated, truncated, info = env.step(np.array([1.0], np.float32))
        if info["filtered"]:
            assert inner.n_steps == before, "a filtered step must not touch the real env"
            assert terminated and not truncated
            assert reward == pytest.approx(-5.0)  # the lowest single-step reward in the demos
            assert info["filter_step"] == n_real
            break
        n_real += 1
        assert inner.n_steps == before + 1
    else:
        pytest.fail("walking straight into the unsafe region should be filtered")
    log = env.episodes
    assert log.filtered.tolist() == [True] and log.crashed.tolist() == [False]
    assert inner.x <= 3, "the filter stopped the walk before the crash"
    with pytest.raises(RuntimeError, match="call reset"):
        env.step(np.array([0.0], np.float32))
    env.reset()  # reset clears the trajectory: standing still is safe again
    _, _, term, trunc, info = env.step(np.array([0.0], np.float32))
    assert not info["filtered"] and not term


def test_crash_labelling(walk_demos):
    safe, unsafe = walk_demos
    # a filter that never fires (unsafe cost always higher): real crashes are crashes
    env = DefenderWrapper(
        gym.wrappers.TimeLimit(CountingEnv(), 12),
        safe,
        unsafe,
        filter_reward=-1.0,
        safe_method="MinFull",
        unsafe_method="MinFull",
    )
    env._unsafe.append = lambda step: np.inf
    env.reset(seed=0)
    for _ in range(5):
        *_, term, trunc, info = env.step(np.array([1.0], np.float32))
        if term:
            break
    env.reset()
    for _ in range(12):
        *_, term, trunc, info = env.step(np.array([0.0], np.float32))
        if term or trunc:
            break
    log = env.episodes
    assert log.crashed.tolist() == [True, False]
    assert log.truncated.tolist() == [False, True] and log.filtered.tolist() == [False, False]


def test_wrapper_with_random_action_loop(walk_demos):
    env = make_walk(
        walk_demos, trajectory="state_action", safe_method="MeanBothW5", unsafe_method="MeanBothW5"
    )
    env.action_space.seed(0)
    env.reset(seed=0)
    for _ in range(300):
        _, _, term, trunc, _ = env.step(env.action_space.sample())
        if term or trunc:
            env.reset()
    log = env.episodes
    assert len(log) > 10
    assert env.n_real_steps + env.n_filtered_steps == 300
    assert env.unwrapped.n_steps == env.n_real_steps
    assert not (log.crashed & log.filtered).any()


@pytest.mark.parametrize("algo", ["SAC", "TD3"])
def test_wrapper_trains_with_sb3(walk_demos, algo):
    from thesis_lib.rl import RLConfig, train

    env = make_walk(walk_demos)
    cfg = RLConfig(
        algo=algo,
        env_id=None,
        total_timesteps=300,
        learning_starts=50,
        net_arch=[16, 16],
        batch_size=32,
    )
    res = train(cfg, env=env, progress=False, info_keys=["filtered", "filter_step"])
    assert len(res.episodes) > 0 and "filtered" in res.episodes.columns
    assert env.n_real_steps == env.unwrapped.n_steps
    assert (
        env.dynamics.n_updates == env.n_real_steps // DYNAMICS_TRAIN_EVERY
    )  # real transitions only


@pytest.mark.parametrize("algo", ["SAC", "TD3"])
def test_wrapper_with_sb3_directly_and_its_episode_log(walk_demos, algo, tmp_path, monkeypatch):
    """The issue's usage: ``SAC("MlpPolicy", DefenderWrapper(...)).learn(...)``, then read the log."""
    import tempfile

    import stable_baselines3 as sb3

    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path))  # SB3's own logger makes a folder there

    env = make_walk(walk_demos, safe_method="MeanDemoW5", unsafe_method="MeanDemoW10")
    model = getattr(sb3, algo)(
        "MlpPolicy",
        env,
        learning_starts=50,
        batch_size=32,
        seed=0,
        policy_kwargs={"net_arch": [16, 16]},
        device="cpu",
    )
    model.learn(300)
    log = env.episodes
    assert list(log.columns) == list(EPISODE_LOG_COLUMNS) and len(log) > 0
    steps = env.n_real_steps + env.n_filtered_steps
    assert (
        steps == 300 and 0 <= steps - log.length.sum() < 12
    )  # all but the unfinished last episode
    assert env.unwrapped.n_steps == env.n_real_steps
    assert log.filtered.sum() == env.n_filtered_steps  # a filtered step ends its episode
    fired = log[log.filtered]
    assert (fired.filter_step == fired.length - 1).all() and log[
        ~log.filtered
    ].filter_step.isna().all()
    assert not (log.crashed & log.filtered).any()
    assert (log.crashed == (log.terminated & ~log.filtered & (log.length < 12))).all()


def test_dynamics_update_rate_default_and_paper_compat(walk_demos):
    assert make_walk(walk_demos).dynamics.train_every == DYNAMICS_TRAIN_EVERY == 4
    assert (
        make_walk(walk_demos, paper_compat=True).dynamics.train_every == 1
    )  # Algorithm 2: every step
    assert make_walk(walk_demos, dynamics_train_every=1).dynamics.train_every == 1
    with pytest.raises(ValueError, match="once"):
        make_walk(walk_demos, dynamics_train_every=2, dynamics_kwargs={"train_every": 3})


def test_paper_compat_settings(walk_demos):
    env = make_walk(walk_demos, paper_compat=True)
    assert env.max_trajectory == 20 and env.metric == "l1"
    env.reset(seed=0)
    env.step(np.array([0.5], np.float32))


# --------------------------------------------------------------------------- dynamics model
def test_dynamics_model_learns_a_linear_system():
    torch.manual_seed(0)
    rng = np.random.default_rng(0)
    a_mat, b_mat = np.array([[0.9, 0.1], [-0.2, 0.8]]), np.array([[0.5], [1.0]])
    model = DynamicsModel(2, 1, hidden=(64, 64), learning_rate=3e-3, batch_size=64, seed=0)
    for _ in range(2000):
        s, a = rng.uniform(-1, 1, 2), rng.uniform(-1, 1, 1)
        model.observe(s, a, a_mat @ s + b_mat @ a)
    model.fit(500)
    s, a = rng.uniform(-1, 1, (50, 2)), rng.uniform(-1, 1, (50, 1))
    pred = np.stack([model.predict(si, ai) for si, ai in zip(s, a)])
    true = s @ a_mat.T + a @ b_mat.T
    assert np.abs(pred - true).mean() < 0.03
    assert model.n_updates == 2500


def test_dynamics_model_predicts_identity_before_training():
    model = DynamicsModel(3, 1)
    np.testing.assert_allclose(model.predict([1, 2, 3], [0.5]), [1, 2, 3])


# --------------------------------------------------------------------------- demonstrations, ablation
def test_demonstrations_round_trip_and_diverse_subset(tmp_path, walk_demos):
    safe, unsafe = walk_demos
    ds = DemoSet(list(safe), list(unsafe), "CountingEnv")
    back = load_demonstrations(save_demonstrations(ds, tmp_path / "d.npz"))
    assert back.env_id == "CountingEnv" and len(back.safe) == 2 and len(back.unsafe) == 2
    for a, b in zip(ds.safe + ds.unsafe, back.safe + back.unsafe):
        np.testing.assert_array_equal(a.observations, b.observations)
        assert (a.terminated, a.truncated) == (b.terminated, b.truncated)
    with pytest.raises(FileNotFoundError, match="collect_demonstrations"):
        load_demonstrations(tmp_path / "missing.npz")
    # farthest-point: from the longest, the next pick is the one farthest from it
    pts = [_demo(np.full(4, v), False) for v in (0.0, 0.1, 5.0, 5.1)]
    picked = select_diverse(pts, 2)
    assert sorted(float(d.observations[0, 0]) for d in picked) == [0.0, 5.1]


def test_expert_demonstrations_make_both_groups(tmp_path):
    from thesis_lib.defender import load_demonstrations_minari, save_demonstrations_minari

    demos = expert_demonstrations(
        "InvertedDoublePendulum-v5", n_safe=2, n_unsafe=2, max_episode_steps=30
    )
    ids = save_demonstrations_minari(demos, root=tmp_path)  # the data-set issue's Minari storage
    assert ids["unsafe"] == "thesis/defender-inverteddoublependulum/unsafe-v0"
    back = load_demonstrations_minari("InvertedDoublePendulum-v5", root=tmp_path)
    for a, b in zip(demos.safe + demos.unsafe, back.safe + back.unsafe):
        np.testing.assert_allclose(a.observations, b.observations)
        assert (a.terminated, a.truncated, a.length) == (b.terminated, b.truncated, b.length)
    assert [(d.length, d.truncated, d.terminated) for d in demos.safe] == [(30, True, False)] * 2
    assert all(d.terminated and d.length < 30 for d in demos.unsafe)
    assert demos.safe[0].observations.shape == (31, 9) and demos.safe[0].actions.shape == (30, 1)
    assert not np.array_equal(demos.safe[0].observations, demos.safe[1].observations)
    with pytest.raises(
        ValueError,
        match="No shipped expert policy for 'Pendulum-v1'; experts ship for: .*Hopper-v5",
    ):
        expert_demonstrations("Pendulum-v1", n_safe=1, n_unsafe=1)


def test_shipped_expert_label_names_the_kind_of_the_shipped_policy():
    """The demonstrations table says which expert topped a group up: TQC where one has
    shipped (Walker2d, HalfCheetah), linear ARS elsewhere; read from the training records."""
    from thesis_lib.data.experts import load_policy_record
    from thesis_lib.defender import shipped_expert_label

    assert shipped_expert_label("InvertedDoublePendulum-v5") == "ARS expert"
    for env_id, task in (("Walker2d-v5", "walker2d"), ("Hopper-v5", "hopper")):
        kind = load_policy_record(task).algorithm_name
        assert kind in ("ARS", "TQC") and shipped_expert_label(env_id) == f"{kind} expert"
    assert shipped_expert_label("Walker2d-v5") == "TQC expert"  # shipped with #15's recipe
    with pytest.raises(ValueError, match="No shipped expert policy for 'Pendulum-v1'"):
        shipped_expert_label("Pendulum-v1")


def test_make_demonstrations_tops_up_a_missing_group(tmp_path, monkeypatch):
    """200 SAC steps on InvertedDoublePendulum: no roll-out balances 20 steps, so "auto" takes the safe
    group from the expert and the thesis's recipe alone ("sac") fails with a clear message."""
    from thesis_lib.chapters import defender as ex

    monkeypatch.setenv("THESIS_RESULTS_DIR", str(tmp_path))

    kw = dict(
        tasks=["InvertedDoublePendulum-v5"],
        max_episode_steps=20,
        demo_timesteps=200,
        n_demos=3,
        n_demos_list=[2, 3],
        net_arch=[16, 16],
        batch_size=32,
    )
    runs = ex.make_demonstrations(ex.Config(**kw))
    run = runs["InvertedDoublePendulum-v5"]
    assert run.n_sac["safe"] == 0 and run.n_sac["unsafe"] > 3
    assert run.sources() == {"safe": (0, 3), "unsafe": (3, 0)}
    table = ex.summarize_demonstrations(runs, ex.Config(**kw))
    assert table.recipe.tolist() == ["ARS expert + noise", "SAC roll-outs (thesis)"]
    assert (
        "came from the shipped ARS expert" in ex.describe_demonstrations(runs, ex.Config(**kw))[0]
    )
    assert len(run.episodes) > 0 and all(
        len(d.actions) <= 20 for d in run.episodes
    )  # the ablation's log
    with pytest.raises(RuntimeError, match="0 safe .* expert_demonstrations"):
        ex.make_demonstrations(ex.Config(**kw, demo_source="sac"))


def test_strategy_ablation_scores(walk_demos):
    safe, unsafe = walk_demos
    demos = DemoSet(safe, unsafe, "walk")
    episodes = [
        _demo(np.arange(6) * 1.0, True),
        _demo(np.zeros(12), False),
        _demo(np.linspace(0, -4, 9), True),
    ]
    scores = strategy_ablation(episodes, demos, horizon=11)
    assert len(scores) == 576 and scores.n_crashed.iloc[0] == 2
    assert scores.score.between(0, 1).all()
    row = scores.set_index("strategy").loc["MinDemoW5/MinDemoW5"]
    assert row.crashes_stopped == 1.0 and row.safe_episodes_cut == 0.0
    ranked = rank_strategies(scores.assign(trajectory="state", task="walk"), top=5)
    assert ranked["rank"].tolist() == [1, 2, 3, 4, 5]
    assert ranked.score.is_monotonic_decreasing


@pytest.mark.parametrize(
    ("name", "cap"), [("MeanTrajW5", None), ("MinSame", None), ("MeanFull", 7), ("MaxDemoW10", 30)]
)
def test_long_trajectories_past_the_buffer(name, cap):
    """The trajectory buffer grows (uncapped) or slides (capped) past its first 64 rows correctly."""
    rng = np.random.default_rng(5)
    demos = [rng.normal(size=(n, 3)) for n in (15, 40)]
    traj = rng.normal(size=(150, 3))
    g = GroupCost(demos, name, max_trajectory=cap)
    for t in range(len(traj)):
        got = g.append(traj[t])
        if t % 13 == 0 or t == len(traj) - 1:
            assert got == pytest.approx(
                method_cost(traj[: t + 1], demos, name, max_trajectory=cap)
            ), (name, t)


# --------------------------------------------------------------------------- experiments (tables)
def _fake_runs():
    from thesis_lib.chapters.defender import RUN_COLUMNS

    rows = []
    for seed in (0, 1):
        for algo in ("SAC", "TD3"):
            rows.append(
                {
                    "task": "Hopper-v5",
                    "algo": algo,
                    "trajectory": "none",
                    "strategy": "none",
                    "safe_strategy": None,
                    "unsafe_strategy": None,
                    "n_demos": 0,
                    "paper_compat": False,
                    "seed": seed,
                    "acc_reward": 100.0 + seed,
                    "crash_pct": 60.0,
                    "filtered_pct": 0.0,
                    "mean_last_100": 50.0,
                    "n_episodes": 10,
                    "wall_time_s": 10.0,
                }
            )
            rows.append(
                {
                    "task": "Hopper-v5",
                    "algo": algo,
                    "trajectory": "state",
                    "strategy": "MeanDemoW5/MeanDemoW10",
                    "safe_strategy": "MeanDemoW5",
                    "unsafe_strategy": "MeanDemoW10",
                    "n_demos": 5,
                    "paper_compat": False,
                    "seed": seed,
                    "acc_reward": 90.0,
                    "crash_pct": 10.0 + seed,
                    "filtered_pct": 50.0,
                    "mean_last_100": 40.0,
                    "n_episodes": 20,
                    "wall_time_s": 12.0,
                }
            )
    return pd.DataFrame(rows, columns=list(RUN_COLUMNS))


def test_summarize_and_compare_with_thesis():
    from thesis_lib.chapters.defender import (
        compare_table_4_5,
        compare_tables_4_3_4_4,
        summarize_runs,
    )

    summary = summarize_runs(_fake_runs())
    row = summary[(summary.algo == "SAC") & (summary.strategy != "none")].iloc[0]
    assert row.time_pct == pytest.approx(120.0) and row.crash_pct_mean == pytest.approx(10.5)
    assert row.crash_pct_std == pytest.approx(np.std([10, 11], ddof=1)) and row.n_seeds == 2
    cmp = compare_tables_4_3_4_4(summary, differs={"scale": "test"})
    sac = cmp[
        (cmp.table == "4.3")
        & (cmp.metric == "% Crash")
        & (cmp.algorithm == "SAC")
        & (cmp.env == "Hopper")
    ]
    got = dict(zip(sac.safe_strategy.fillna("none").astype(str), zip(sac.paper, sac.ours)))
    assert got["none"] == (64, 60.0) and got["MeanDemoW5"] == (11, 10.5)
    assert (cmp[cmp.env == "Walker2d"]["what differs"] == "not run").all()
    t45 = compare_table_4_5(summary[summary.strategy != "none"])
    assert set(t45[t45.env == "Hopper"].n_demos_ours.dropna()) == {5}


def test_defender_config_errors():
    from thesis_lib.chapters.defender import Config as DefenderConfig

    with pytest.raises(ValueError, match="Did you mean: 'MeanDemoW10'"):
        DefenderConfig(state_strategies=["MeanDemoW5/MeanDemoW1O"])
    with pytest.raises(ValueError, match="Unknown algo 'PPO'"):
        DefenderConfig(algos=["PPO"])
    with pytest.raises(ValueError, match="train_timesteps must be a positive int"):
        DefenderConfig(train_timesteps=0)
    with pytest.raises(ValueError, match="Unknown demo_source 'ars'. Valid: sac, expert, auto"):
        DefenderConfig(demo_source="ars")
    with pytest.raises(ValueError, match="paper_compat_tasks lists 'Walker2d-v5'"):
        DefenderConfig(tasks=["Hopper-v5"], paper_compat_tasks=["Walker2d-v5"])


@pytest.mark.slow
def test_chapter_pipeline_at_tiny_scale(tmp_path, monkeypatch):
    """make_demonstrations -> ablation -> Tables 4.3-4.5 on Hopper with a 20-step horizon, each
    grid through the sweep store; a second pass reads every task back and trains nothing."""
    from thesis_lib.chapters import defender as ex

    monkeypatch.setenv("THESIS_RESULTS_DIR", str(tmp_path))

    cfg = ex.Config(
        tasks=["Hopper-v5"],
        max_episode_steps=20,
        demo_timesteps=600,
        n_demos=3,
        n_demos_list=[2, 3],
        algos=["SAC", "TD3"],
        train_timesteps=200,
        net_arch=[16, 16],
        paper_compat_check=False,
    )
    runs = ex.make_demonstrations(cfg)
    scores = ex.run_ablation(cfg, runs)
    assert len(scores) == 2 * 576
    tables = ex.run_tables_4_3_4_4(cfg, runs, progress=False)
    assert len(tables.runs) == 6 and set(tables.runs.trajectory) == {
        "none",
        "state",
        "state_action",
    }
    t45 = ex.run_table_4_5(cfg, runs, progress=False)
    assert sorted(t45.runs.n_demos) == [2, 3] and set(t45.runs.algo) == {"SAC"}
    assert set(t45.episodes.algo) == {"SAC"} and len(t45.episodes) == t45.runs.n_episodes.sum()
    assert (tables.episodes.crashed & tables.episodes.filtered).sum() == 0
    store = tmp_path / "03_defender" / "tasks"
    assert len(list(store.glob("*.json"))) == 1 + 2 + 6 + 1  # Table 4.5's 3-demo run is 4.3's
    shared = tables.runs[(tables.runs.algo == "SAC") & (tables.runs.trajectory == "state")]
    pd.testing.assert_frame_equal(
        t45.runs[t45.runs.n_demos == 3].reset_index(drop=True), shared.reset_index(drop=True)
    )

    def no_training(*args, **kwargs):
        raise AssertionError("a finished task ran again")

    monkeypatch.setattr(ex.tasks, "train_run", no_training)
    monkeypatch.setattr(ex.tasks, "strategy_ablation", no_training)
    monkeypatch.setattr(ex.demos, "collect_demonstrations", no_training)
    back = ex.make_demonstrations(cfg)["Hopper-v5"]
    run = runs["Hopper-v5"]
    assert back.n_sac == run.n_sac and back.sources() == run.sources()
    assert [d.length for d in back.demos.safe] == [d.length for d in run.demos.safe]
    assert all(
        np.array_equal(a.observations, b.observations)
        for a, b in zip(back.pool.unsafe, run.pool.unsafe)
    )
    pd.testing.assert_frame_equal(ex.run_ablation(cfg, runs, progress=False), scores)
    again = ex.run_tables_4_3_4_4(cfg, runs, progress=False)
    pd.testing.assert_frame_equal(again.runs, tables.runs)


# --- the counterfactual: what a filtered action would have done (issue #35) ------------------


def test_filter_confusion_on_a_walk_with_known_answers(walk_demos):
    """The filter fires at x >= 3. Stepping +1 from 3 would crash (x = 4 > 3): a saved crash;
    stepping -1 would not: a false alarm; a walk the filter lets through crashes: a miss."""
    safe, unsafe = walk_demos
    env = DefenderWrapper(
        gym.wrappers.TimeLimit(CountingEnv(), 12),
        safe,
        unsafe,
        safe_method="MinFull",
        unsafe_method="MinFull",
        counterfactual=True,
    )
    inner = env.unwrapped
    fire_at_3 = lambda step: -np.inf if step[0] >= 3 else np.inf
    for action, fires in ((1.0, True), (-1.0, True), (1.0, False)):
        env._unsafe.append = fire_at_3 if fires else (lambda step: np.inf)
        env.reset()
        for _ in range(3):  # walk to x = 3 (real steps)
            env.step(np.array([1.0], np.float32))
        before = inner.n_steps
        *_, term, _, info = env.step(np.array([action], np.float32))
        if fires:
            assert info["filtered"] and info["would_crash"] == (action > 0) and term
            assert inner.n_steps == before and inner.x == 3.0  # the real env never moved
        else:
            assert not info["filtered"] and term  # the crash happened
    log = env.episodes
    assert log.would_crash.tolist() == [True, False, None]
    assert log.crashed.tolist() == [False, False, True]
    c = env.filter_confusion()
    assert (c["tp"], c["fp"], c["fn"], c["crashes_without_filter"]) == (1, 1, 1, 2)
    assert c["precision"] == 0.5 and c["recall"] == 0.5
    plain = make_walk(walk_demos)
    with pytest.raises(RuntimeError, match="counterfactual=True"):
        plain.filter_confusion()


def _twin_hoppers(seed: int, n_after: int):
    """Two Hoppers reset and stepped alike for 10 random actions, and ``n_after`` more actions
    for :func:`_continue_alike`."""
    a, b = gym.make("Hopper-v5"), gym.make("Hopper-v5")
    a.reset(seed=seed), b.reset(seed=seed)
    acts = np.random.default_rng(seed).uniform(-1, 1, (10 + n_after, 3)).astype(np.float32)
    for act in acts[:10]:
        a.step(act), b.step(act)
    return a, b, acts[10:]


def _continue_alike(a, b, acts) -> None:
    """``a`` (probed) continues exactly as ``b`` (never probed)."""
    for act in acts:
        oa, ra, *_ = a.step(act)
        ob, rb, *_ = b.step(act)
        assert np.array_equal(oa, ob) and ra == rb


def test_counterfactual_step_leaves_a_mujoco_env_bit_for_bit():
    from thesis_lib.defender.wrapper import counterfactual_terminates

    a, b, after = _twin_hoppers(0, 10)
    assert counterfactual_terminates(a, np.ones(3, np.float32)) in (True, False)
    _continue_alike(a, b, after)
    u = a.unwrapped  # a known answer: the torso below Hopper's healthy height ends the episode
    qpos, qvel = u.data.qpos.copy(), u.data.qvel.copy()
    low = qpos.copy()
    low[1] = 0.5  # healthy z range is (0.7, inf)
    u.set_state(low, qvel)
    assert counterfactual_terminates(a, np.zeros(3, np.float32)) is True
    u.set_state(u.init_qpos.copy(), u.init_qvel.copy())
    assert counterfactual_terminates(a, np.zeros(3, np.float32)) is False
    a.close(), b.close()


def test_counterfactual_crash_step_looks_ahead_with_the_policy_and_leaves_the_env_alone():
    """From x = 1 a step of +1 lands on 2 (no crash); a policy that keeps walking +1 crosses 3
    at the 3rd step (x = 4). A policy that steps towards 0 never crashes; one that walks back
    for good crosses -3 at the 7th step (x = -4)."""
    from thesis_lib.defender.wrapper import counterfactual_crash_step

    env = gym.wrappers.TimeLimit(CountingEnv(), 50)
    env.reset()
    env.step(np.array([1.0], np.float32))  # x = 1
    inner, fwd = env.unwrapped, np.array([1.0], np.float32)
    onward = lambda obs: fwd
    home = lambda obs: -fwd if obs[0] > 0 else fwd
    back = lambda obs: -fwd
    assert counterfactual_crash_step(env, fwd) is None  # the one-step look: x = 2
    assert counterfactual_crash_step(env, fwd, onward, max_steps=2) is None  # x = 3
    assert counterfactual_crash_step(env, fwd, onward, max_steps=3) == 3  # x = 4 > 3
    assert counterfactual_crash_step(env, fwd, onward, max_steps=100) == 3
    assert counterfactual_crash_step(env, fwd, home, max_steps=100) is None
    assert counterfactual_crash_step(env, fwd, back, max_steps=100) == 7
    assert counterfactual_crash_step(env, 3 * fwd) == 1  # x = 4 at once
    assert inner.x == 1.0 and env._elapsed_steps == 1  # never moved, no TimeLimit step spent
    seen = []
    counterfactual_crash_step(env, fwd, lambda obs: seen.append(obs[0]) or fwd, max_steps=5)
    assert seen == [2.0, 3.0]  # the policy is given the copy's states, in order
    with pytest.raises(ValueError, match="max_steps must be >= 1"):
        counterfactual_crash_step(env, fwd, onward, max_steps=0)
    with pytest.raises(ValueError, match="needs the agent's policy"):
        counterfactual_crash_step(env, fwd, max_steps=2)
    scaled = gym.wrappers.TransformObservation(env, lambda o: 2 * o, env.observation_space)
    with pytest.raises(ValueError, match="TransformObservation changes observations"):
        counterfactual_crash_step(scaled, fwd, onward, max_steps=2)


def test_counterfactual_crash_step_on_hopper_is_the_one_step_counterfactual_and_restores_it():
    from thesis_lib.defender.wrapper import counterfactual_crash_step, counterfactual_terminates

    a, b, after = _twin_hoppers(1, 20)
    u = a.unwrapped
    qpos, qvel = u.data.qpos.copy(), u.data.qvel.copy()
    low = qpos.copy()
    low[1] = 0.5  # below the healthy height: the next step terminates
    u.set_state(low, qvel)
    zero = np.zeros(3, np.float32)
    assert counterfactual_crash_step(a, zero) == 1 == int(counterfactual_terminates(a, zero))
    u.set_state(qpos, qvel)
    # a policy that pushes hard with every joint topples the hopper within 200 steps
    k = counterfactual_crash_step(a, zero, lambda o: np.ones(3, np.float32), max_steps=200)
    assert k is not None and 1 < k <= 200
    _continue_alike(a, b, after)  # probed for k steps, yet as b
    a.close(), b.close()


def test_filter_lookahead_on_a_walk_with_known_answers(walk_demos):
    """A policy of +0.5 a step crashes every episode at its 7th step (x = 3.5 > 3, horizon 12).
    Every firing at step j is then 7 - j steps from its crash; the control run's states are
    followed by a crash within k steps at min(k, 7) / 7."""
    from thesis_lib.chapters.defender.lookahead import filter_lookahead
    from thesis_lib.defender import DemoSet

    safe, unsafe = walk_demos
    half = np.array([0.5], np.float32)
    out = filter_lookahead(
        lambda obs: half,
        lambda: gym.wrappers.TimeLimit(CountingEnv(), 12),
        DemoSet(safe, unsafe, "walk"),
        "MinDemoW5/MinDemoW5",
        steps=70,
        lookahead=(1, 3, 7, 100),
    )
    f = out.firings
    assert len(f) > 0 and (f.filter_step + f.crash_in == 7).all()
    assert out.summary["firings"] == len(f) and out.summary["control_episodes"] == 10
    assert out.summary["control_crashes_per_1k_steps"] == 1000 * 10 / 70
    assert out.summary["control_length_p10"] == out.summary["control_length_p90"] == 7
    t = out.table.set_index("k")
    j = int(f.filter_step.iloc[0])
    assert (f.filter_step == j).all()  # the same walk every episode: it fires at the same step
    for k in (1, 3, 7, 100):
        assert t.loc[k, "filter"] == float(7 - j <= k)
        assert t.loc[k, "control_any"] == pytest.approx(min(k, 7) / 7)
        assert t.loc[k, "control_same_step"] == float(7 - j <= k)
    assert t.loc[100, "lift_any"] == 1.0  # everything crashes: no filter can beat the clock
    capped = filter_lookahead(
        lambda obs: half,
        lambda: gym.wrappers.TimeLimit(CountingEnv(), 12),
        DemoSet(safe, unsafe, "walk"),
        "MinDemoW5/MinDemoW5",
        steps=70,
        max_trajectory=2,  # the authors' cap, shortened: the filter sees the last 2 steps
    )
    assert (capped.firings.filter_step + capped.firings.crash_in == 7).all()
    with pytest.raises(ValueError, match="positive step counts"):
        filter_lookahead(lambda o: half, CountingEnv, DemoSet(safe, unsafe, "w"), lookahead=[0])
    with pytest.raises(ValueError, match="'<safe>/<unsafe>'"):
        filter_lookahead(lambda o: half, CountingEnv, DemoSet(safe, unsafe, "w"), "MinDemoW5")


def test_lookahead_table_by_hand():
    """Control: one crash at length 4, one episode to the horizon (length 6, no crash): 10
    states, of which 1 (k = 1), 2 (k = 2) and 4 (k >= 4) are within k of a crash. Firings at
    step 1 (crash in 2) and step 5 (no crash)."""
    from thesis_lib.chapters.defender.lookahead import lookahead_table

    eps = pd.DataFrame({"length": [4, 6], "crashed": [True, False]})
    fire = pd.DataFrame({"filter_step": [1, 5], "crash_in": [2.0, np.nan]})
    t = lookahead_table(fire, eps, (1, 2, 4)).set_index("k")
    assert t["filter"].tolist() == [0.0, 0.5, 0.5]
    assert t["control_any"].tolist() == pytest.approx([0.1, 0.2, 0.4])
    # step 1: both episodes reached it, the crash is 3 steps on: 0, 0, 1/2; step 5: only the
    # uncrashed one reached it: 0
    assert t["control_same_step"].tolist() == pytest.approx([0.0, 0.0, 0.25])
    assert np.isnan(t.loc[1, "lift_same_step"]) and t.loc[4, "lift_same_step"] == 2.0


def test_cli_lookahead_says_what_is_wrong(tmp_path, capsys):
    from thesis_lib.cli import main

    assert main(["defender", "lookahead", str(tmp_path / "none.zip"), "-q"]) == 1
    assert "No saved model" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        main(["defender", "lookahead", "m.zip", "--lookahead", "0,5"])
    assert "expect positive step counts" in capsys.readouterr().err


def test_lookahead_results_reads_the_committed_diagnostics(tmp_path):
    from thesis_lib.chapters.defender.lookahead import lookahead_results

    assert lookahead_results(tmp_path / "none").empty
    table = pd.DataFrame({"k": [1, 20], "filter": [0.0, 0.9], "control_any": [0.01, 0.2]})
    table = table.assign(control_same_step=[0.0, 0.85], lift_any=[0.0, 4.5], lift_same_step=1.0)
    for step, label in ((40000, "SAC+F"), (20000, "SAC")):
        table.to_csv(tmp_path / f"{label}-{step}.csv", index=False)
        summary = {"run_label": label, "run_seed": 2, "run_scale": "check", "run_step": step}
        (tmp_path / f"{label}-{step}.json").write_text(
            json.dumps({"summary": {**summary, "firings_per_1k_steps": 11.0}})
        )
    out = lookahead_results(tmp_path)
    assert out[["run_label", "run_step", "k"]].values.tolist() == [
        ["SAC", 20000, 1], ["SAC", 20000, 20], ["SAC+F", 40000, 1], ["SAC+F", 40000, 20]
    ]  # fmt: skip
    assert out["filter"].tolist() == [0.0, 0.9] * 2 and (out.firings_per_1k_steps == 11.0).all()
    assert out["control_length_median"].isna().all()  # not in these summaries


def test_summarize_lookahead_one_row_per_checkpoint():
    from thesis_lib.chapters.defender.lookahead import summarize_lookahead

    assert summarize_lookahead(pd.DataFrame()).empty
    long = pd.DataFrame(
        {
            "run_label": "SAC", "run_scale": "study", "run_seed": [0, 0, 1, 1],
            "run_step": 100000, "firings_per_1k_steps": [9.0, 9.0, 7.0, 7.0],
            "filter_step_median": 80.0, "control_length_median": 95.0,
            "control_crashed_share": 1.0, "k": [1, 20] * 2, "filter": [0.0, 0.8, 0.1, 0.9],
            "control_same_step": [0.0, 0.7, 0.0, 0.6],
        }
    )  # fmt: skip
    wide = summarize_lookahead(long, lookahead=(1, 20))
    assert wide["seed"].tolist() == [0, 1] and wide["firings per 1k steps"].tolist() == [9, 7]
    assert wide["fires at"].tolist() == [80.0, 80.0] and wide["fires at p90"].isna().all()
    assert wide["filter k=20"].tolist() == [0.8, 0.9]
    assert wide["same step k=20"].tolist() == [0.7, 0.6]


# --- the control: a filter firing at random (CLAIMS.md, C7) ----------------------------------


def test_random_filter_fires_at_its_rate_and_acts_as_the_filter_does(walk_demos):
    from thesis_lib.defender import RandomFilter

    safe, unsafe = walk_demos

    def run(seed, steps=4000):
        env = RandomFilter(
            gym.wrappers.TimeLimit(CountingEnv(), 12), safe, unsafe, rate=0.1, seed=seed
        )
        env.reset(seed=0)
        fired = []
        for _ in range(steps):
            x = env.unwrapped.x
            before = env.unwrapped.n_steps
            obs, reward, term, trunc, info = env.step(
                np.array([1.0 if x < 0 else -1.0], np.float32)
            )
            fired.append(info["filtered"])
            if info["filtered"]:  # the filter's contract: no real step, lowest reward, the end
                assert env.unwrapped.n_steps == before and term and reward == env.filter_reward
            if term or trunc:
                env.reset()
        return np.array(fired), env

    fired, env = run(0)
    # 4000 Bernoulli(0.1) draws: 400 +- 19; a 5-sigma band
    assert abs(fired.sum() - 400) < 5 * np.sqrt(4000 * 0.1 * 0.9)
    assert env.n_filtered_steps == fired.sum() and env.filter_reward == -5.0
    assert np.array_equal(run(0)[0], fired) and not np.array_equal(run(1)[0], fired)
    log = env.episodes  # the walk never crashes: every episode is filtered or truncated
    assert (log.filtered | log.truncated).all() and log.filtered.sum() == fired.sum()
    for rate in (1.0, -0.1, float("nan")):
        with pytest.raises(ValueError, match="rate must be a probability"):
            RandomFilter(CountingEnv(), safe, unsafe, rate=rate)
    # rate 0: the control of a filter that never fired never fires
    never = RandomFilter(gym.wrappers.TimeLimit(CountingEnv(), 12), safe, unsafe, rate=0.0, seed=0)
    never.reset(seed=0)
    for _ in range(500):
        *_, term, trunc, _ = never.step(np.array([0.0], np.float32))
        if term or trunc:
            never.reset()
    assert never.n_filtered_steps == 0


def test_timer_filter_fires_at_its_drawn_steps_in_its_share_of_episodes(walk_demos):
    """The blind timing control: an armed episode is filtered at the step drawn from the
    deciles (its length, the filtered step included), an unarmed one never; draws are seeded."""
    from thesis_lib.defender import TimerFilter

    safe, unsafe = walk_demos
    step = np.array([0.0], np.float32)

    def lengths(p, deciles, seed=0, episodes=150):
        env = TimerFilter(
            gym.wrappers.TimeLimit(CountingEnv(), 12),
            safe, unsafe, p_episode=p, step_deciles=deciles, seed=seed,
        )  # fmt: skip
        out = []
        for _ in range(episodes):
            env.reset(seed=0)
            for t in range(1, 13):
                before = env.unwrapped.n_steps
                *_, reward, term, trunc, info = env.step(step)
                if info["filtered"]:  # no real step, the lowest reward, the end
                    assert env.unwrapped.n_steps == before and term and reward == env.filter_reward
                    out.append(t)
                    break
                if term or trunc:
                    out.append(None)
                    break
        return out, env

    fixed, env = lengths(1.0, [5] * 11)
    assert fixed == [5] * 150 and env.n_filtered_steps == 150
    spread, _ = lengths(1.0, [2, 2, 3, 3, 4, 4, 5, 5, 6, 6, 7])
    assert set(spread) == {2, 3, 4, 5, 6, 7} and abs(np.median(spread) - 4.5) <= 0.5
    half, _ = lengths(0.5, [5] * 11)
    armed = sum(x == 5 for x in half)  # 150 Bernoulli(0.5): 75 +- 6.1; a 5-sigma band
    assert abs(armed - 75) < 5 * np.sqrt(150 * 0.25) and set(half) == {5, None}
    late, _ = lengths(1.0, [30] * 11)  # past the horizon: the episode ends first, unfiltered
    assert late == [None] * 150
    assert lengths(0.5, [5] * 11, seed=1)[0] != half and lengths(0.5, [5] * 11)[0] == half
    for bad in ([5] * 10, [0] + [5] * 10, [6, 5] + [5] * 9, [5] * 10 + [float("nan")]):
        with pytest.raises(ValueError, match="step_deciles must be 11"):
            TimerFilter(CountingEnv(), safe, unsafe, p_episode=1.0, step_deciles=bad)
    with pytest.raises(ValueError, match="p_episode must be a probability"):
        TimerFilter(CountingEnv(), safe, unsafe, p_episode=1.5, step_deciles=[5] * 11)


def test_timer_filter_resumed_after_a_reset_draws_that_reset_again(walk_demos):
    """A checkpoint is taken after the next episode's reset and that reset is made again on
    resume (thesis_lib.rl.resume): the resumed filter draws the same firing steps."""
    from thesis_lib.defender import TimerFilter

    safe, unsafe = walk_demos
    deciles = [2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12]

    def make():
        env = gym.wrappers.TimeLimit(CountingEnv(), 12)
        return TimerFilter(env, safe, unsafe, p_episode=0.7, step_deciles=deciles, seed=3)

    a = make()
    for _ in range(5):
        a.reset(seed=0)
    state = a.state_dict()  # after the 5th reset
    after = []
    for _ in range(20):
        after.append(a._fire_at)
        a.reset(seed=0)
    b = make()
    b.load_state_dict(state)
    redone = []
    for _ in range(20):
        b.reset(seed=0)  # the first one is the 5th reset, made again
        redone.append(b._fire_at)
    assert redone == after and len(set(after)) > 2


def test_random_filter_state_dict_continues_the_same_draws(walk_demos):
    from thesis_lib.defender import RandomFilter

    safe, unsafe = walk_demos
    step = np.array([0.0], np.float32)

    def draws(env, n):
        out = []
        for _ in range(n):
            *_, term, trunc, info = env.step(step)
            out.append(info["filtered"])
            if term or trunc:
                env.reset()
        return out

    a = RandomFilter(gym.wrappers.TimeLimit(CountingEnv(), 12), safe, unsafe, rate=0.3, seed=4)
    b = RandomFilter(gym.wrappers.TimeLimit(CountingEnv(), 12), safe, unsafe, rate=0.3, seed=9)
    a.reset(seed=0), b.reset(seed=0)
    draws(a, 7)
    b.load_state_dict(a.state_dict())  # b now draws what a draws next
    a.reset(), b.reset()
    assert draws(a, 60) == draws(b, 60)
    assert len(b.episodes) == len(a.episodes) and b.n_filtered_steps == a.n_filtered_steps
