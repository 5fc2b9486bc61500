"""Tests for `thesis_lib.rl`: episode logging, seeding, config errors, curves, evaluation."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pandas as pd
import pytest
from stable_baselines3.common.vec_env import DummyVecEnv

from thesis_lib.rl import (
    CURVE_COLUMNS,
    EPISODE_COLUMNS,
    EVAL_COLUMNS,
    EpisodeLogger,
    RLConfig,
    config_from_params,
    evaluate,
    find_horizon,
    learning_curves,
    make_model,
    train,
)


class PlannedEnv(gym.Env):
    """Ignores actions; episode k ends by termination after `plan[k]` steps (None: never).

    The reward at step t (1-based) of episode k is 10 * k + t, so returns are known in closed
    form. `info["episode_id"]` is k.
    """

    observation_space = gym.spaces.Box(-np.inf, np.inf, shape=(1,), dtype=np.float32)
    action_space = gym.spaces.Box(-1.0, 1.0, shape=(1,), dtype=np.float32)

    def __init__(self, plan: list[int | None]) -> None:
        self.plan = plan
        self.k = -1
        self.t = 0

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        self.k += 1
        self.t = 0
        return np.zeros(1, dtype=np.float32), {}

    def step(self, action):
        self.t += 1
        end = self.plan[self.k % len(self.plan)]
        terminated = end is not None and self.t >= end
        obs = np.array([self.t], dtype=np.float32)
        return obs, float(10 * self.k + self.t), terminated, False, {"episode_id": self.k}


def planned(plan: list[int | None], horizon: int | None) -> gym.Env:
    env = PlannedEnv(plan)
    return env if horizon is None else gym.wrappers.TimeLimit(env, max_episode_steps=horizon)


def returns_of(plan_lengths: list[int], first_k: int = 0) -> list[float]:
    return [
        float(sum(10 * k + t for t in range(1, n + 1))) for k, n in enumerate(plan_lengths, first_k)
    ]


# No gradient step happens before `learning_starts`, so these runs only step the env.
NO_LEARNING = dict(algo="TD3", learning_starts=1000, net_arch=[8], device="cpu")


def test_episode_logger_exact_rows_crash_vs_truncation():
    # Horizon 5: crash after 3, truncated at 5, terminated exactly at 5 (reached the horizon:
    # no crash; SB3 reports it as terminated), crash after 2.
    env = planned([3, None, 5, 2], horizon=5)
    assert find_horizon(env) == 5
    result = train(
        RLConfig(total_timesteps=15, **NO_LEARNING),
        env=env,
        progress=False,
        info_keys=["episode_id"],
    )
    ep = result.episodes
    assert list(ep.columns) == [*EPISODE_COLUMNS, "episode_id"]
    assert ep["episode"].tolist() == [0, 1, 2, 3]
    assert ep["length"].tolist() == [3, 5, 5, 2]
    assert ep["timestep"].tolist() == [3, 8, 13, 15]
    assert ep["return"].tolist() == returns_of([3, 5, 5, 2]) == [6.0, 65.0, 115.0, 63.0]
    assert ep["terminated"].tolist() == [True, False, True, True]
    assert ep["truncated"].tolist() == [False, True, False, False]
    assert ep["crashed"].tolist() == [True, False, False, True]
    assert ep["episode_id"].tolist() == [0, 1, 2, 3]
    assert (ep["env_index"] == 0).all()
    assert ep["wall_time_s"].is_monotonic_increasing and (ep["wall_time_s"] >= 0).all()


def test_episode_logger_without_time_limit_every_termination_is_a_crash():
    env = planned([2, 4], horizon=None)
    assert find_horizon(env) is None
    ep = train(RLConfig(total_timesteps=7, **NO_LEARNING), env=env, progress=False).episodes
    # The third episode (2 steps, starts at step 7) has not finished: it is not logged.
    assert ep["length"].tolist() == [2, 4]
    assert ep["return"].tolist() == returns_of([2, 4])
    assert ep["crashed"].all() and ep["terminated"].all() and not ep["truncated"].any()


def test_episode_logger_vector_env_logs_each_copy():
    venv = DummyVecEnv([lambda: planned([2], horizon=10), lambda: planned([None], horizon=3)])
    ep = train(RLConfig(total_timesteps=12, **NO_LEARNING), env=venv, progress=False).episodes
    # 6 vector steps = 12 env steps. Copy 0 crashes every 2 steps, copy 1 is truncated every 3.
    first = ep[ep["env_index"] == 0]
    second = ep[ep["env_index"] == 1]
    assert first["length"].tolist() == [2, 2, 2] and first["crashed"].all()
    assert first["return"].tolist() == returns_of([2, 2, 2])
    assert (
        second["length"].tolist() == [3, 3]
        and second["truncated"].all()
        and not second["crashed"].any()
    )
    assert second["return"].tolist() == returns_of([3, 3])
    assert ep["episode"].tolist() == list(range(5))
    # Rows are in order of completion; `timestep` counts both copies' steps.
    assert ep["timestep"].tolist() == [4, 6, 8, 12, 12]


def test_episode_logger_continues_across_learn_calls():
    model = make_model(RLConfig(total_timesteps=1, **NO_LEARNING), env=planned([None], horizon=5))
    logger = EpisodeLogger()
    model.learn(3, callback=logger)
    model.learn(4, callback=logger, reset_num_timesteps=False)  # the episode goes on
    assert logger.episodes["length"].tolist() == [5] and logger.episodes["timestep"].tolist() == [5]
    model.learn(6, callback=logger)  # SB3 resets the env: the unfinished 2-step episode is dropped
    assert logger.episodes["length"].tolist() == [5, 5] and logger.episodes[
        "timestep"
    ].tolist() == [5, 5]
    assert logger.episodes["return"].tolist() == returns_of([5, 5], first_k=0)[:1] + returns_of(
        [5], first_k=2
    )


def test_training_leaves_no_log_folder_in_the_temp_dir(tmp_path, monkeypatch):
    """SB3's default logger makes an empty SB3-<time> folder per learn(); make_model's does not."""
    import tempfile

    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path))
    model = make_model(RLConfig(total_timesteps=1, **NO_LEARNING), env=planned([None], horizon=5))
    model.learn(6)
    model.learn(6, reset_num_timesteps=False)
    assert list(tmp_path.iterdir()) == []


def test_same_seed_same_episodes_td3():
    config = RLConfig(
        algo="TD3", total_timesteps=600, learning_starts=100, net_arch=[32, 32], device="cpu"
    )
    a = train(config, progress=False).episodes.drop(columns="wall_time_s")
    b = train(config, progress=False).episodes.drop(columns="wall_time_s")
    pd.testing.assert_frame_equal(a, b)
    assert len(a) == 3 and (a["length"] == 200).all() and a["truncated"].all()
    other = RLConfig(
        algo="TD3",
        total_timesteps=600,
        learning_starts=100,
        net_arch=[32, 32],
        device="cpu",
        seed=1,
    )
    c = train(other, progress=False).episodes
    assert not np.allclose(a["return"], c["return"])


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"algo": "PPO"}, r"Unknown algo 'PPO'\. Valid: SAC, TD3, DDPG\."),
        ({"algo": "TD33"}, r"Did you mean: 'TD3'\?"),
        ({"total_timesteps": 0}, r"total_timesteps must be a positive int, got 0"),
        ({"learning_starts": -1}, r"learning_starts must be >= 0, got -1"),
        ({"net_arch": []}, r"net_arch must list positive layer widths"),
        (
            {"action_noise": "gaussian"},
            r"Unknown action_noise 'gaussian'.*Valid: auto, normal, ornstein-uhlenbeck",
        ),
        (
            {"algo": "TD3", "extra": {"policy_dely": 3}},
            r"TD3 does not accept\. Did you mean: 'policy_delay'\?",
        ),
        (
            {"algo": "SAC", "extra": {"policy_delay": 3}},
            r"'policy_delay', which SAC does not accept",
        ),
        ({"extra": {"seed": 3}}, r"which RLConfig fields own"),
    ],
)
def test_bad_config_raises(kwargs, match):
    with pytest.raises(ValueError, match=match):
        RLConfig(**kwargs)


def test_config_from_params_rejects_unknown_names():
    with pytest.raises(
        ValueError, match=r"Unknown RLConfig parameter 'seeds'\. Did you mean: 'seed'\?"
    ):
        config_from_params({"seeds": 3})
    assert config_from_params({"algo": "DDPG"}).action_noise_resolved == "ornstein-uhlenbeck"
    assert RLConfig(algo="SAC").action_noise_resolved is None
    assert RLConfig(algo="TD3", action_noise=None).action_noise_resolved is None


def test_learning_curves_tidy_rows():
    curves = learning_curves(
        ["SAC", "DDPG"], "Pendulum-v1", {"SAC": 400, "DDPG": 200}, seeds=[0, 1],
        progress=False, net_arch=[16], learning_starts=100, device="cpu",
    )  # fmt: skip
    assert list(curves.columns) == list(CURVE_COLUMNS)
    assert curves.groupby(["algo", "seed"]).size().to_dict() == {
        ("DDPG", 0): 1, ("DDPG", 1): 1, ("SAC", 0): 2, ("SAC", 1): 2,
    }  # fmt: skip
    assert (curves["length"] == 200).all() and not curves["crashed"].any()
    assert (curves["return"] < 0).all()
    with pytest.raises(ValueError, match=r"total_timesteps has no entry for \['TD3'\]"):
        learning_curves(["TD3"], "Pendulum-v1", {"SAC": 10}, seeds=[0])
    with pytest.raises(ValueError, match=r"Unknown RLConfig parameter 'net_arc'"):
        learning_curves(["TD3"], "Pendulum-v1", 10, seeds=[0], net_arc=[4])


class ConstantPolicy:
    """Duck-typed policy: always the same action, counts calls."""

    def __init__(self, action: float) -> None:
        self.action = np.array([action], dtype=np.float32)
        self.calls = 0

    def predict(self, observation, state=None, episode_start=None, deterministic=False):
        self.calls += 1
        return self.action, state


def test_evaluate_duck_typed_policy_on_planned_env():
    policy = ConstantPolicy(0.0)
    ev = evaluate(policy, planned([3, None, 5], horizon=4), n_episodes=3, seed=0)
    assert list(ev.columns) == list(EVAL_COLUMNS)
    assert ev["length"].tolist() == [3, 4, 4]
    assert ev["return"].tolist() == returns_of([3, 4, 4])
    assert ev["crashed"].tolist() == [True, False, False]
    assert ev["truncated"].tolist() == [False, True, True]
    assert policy.calls == 11


def test_evaluate_pendulum_is_seeded():
    a = evaluate(ConstantPolicy(1.0), "Pendulum-v1", n_episodes=2, seed=3)
    b = evaluate(ConstantPolicy(1.0), "Pendulum-v1", n_episodes=2, seed=3)
    pd.testing.assert_frame_equal(a, b)
    assert (a["length"] == 200).all() and a["return"].iloc[0] != a["return"].iloc[1]
    with pytest.raises(ValueError, match="n_episodes > 0"):
        evaluate(ConstantPolicy(0.0), "Pendulum-v1", n_episodes=0)


def test_learning_curves_processes_give_the_same_rows():
    kwargs = dict(progress=False, net_arch=[16], learning_starts=100, device="cpu")
    serial = learning_curves(["TD3"], "Pendulum-v1", 400, seeds=[0, 1], n_jobs=1, **kwargs)
    parallel = learning_curves(["TD3"], "Pendulum-v1", 400, seeds=[0, 1], n_jobs=2, **kwargs)
    pd.testing.assert_frame_equal(
        serial.drop(columns="wall_time_s"), parallel.drop(columns="wall_time_s")
    )


def test_learning_curves_resume_from_cache(tmp_path, monkeypatch):
    """Finished runs are saved and reused: a second call trains nothing and returns the same rows."""
    import sys

    from thesis_lib.rl import learning_curves

    train_mod = sys.modules["thesis_lib.rl.training"]

    kwargs = dict(
        algos=["TD3"],
        env_id="Pendulum-v1",
        total_timesteps=400,
        seeds=[0],
        progress=False,
        learning_starts=100,
        net_arch=[8],
        cache_dir=tmp_path,
    )
    first = learning_curves(**kwargs)
    assert sorted(p.name for p in tmp_path.iterdir()) == [
        "Pendulum-v1-TD3-seed0.csv",
        "Pendulum-v1-TD3-seed0.json",
    ]

    def no_training(*args, **kw):
        raise AssertionError("a cached run was trained again")

    monkeypatch.setattr(train_mod, "train", no_training)
    again = learning_curves(**kwargs)
    pd.testing.assert_frame_equal(first, again, check_dtype=False)
    with pytest.raises(AssertionError, match="trained again"):  # another config is not reused
        learning_curves(**{**kwargs, "total_timesteps": 500})
