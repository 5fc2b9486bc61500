"""Resumable SB3 training (``thesis_lib.rl.resume``): a run stopped after a checkpoint and run
again ends exactly where the run that was never stopped ends: the same episodes, networks,
replay buffer and, for DEFENDER's filter, the same dynamics model and episode log."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
import torch
from stable_baselines3.common.callbacks import BaseCallback, StopTrainingOnMaxEpisodes

from thesis_lib.defender import DefenderWrapper, Demonstration, RandomFilter
from thesis_lib.rl import RLConfig, config_from_params, resume, train

EPISODE_KEYS = ["episode", "timestep", "return", "length", "terminated", "crashed"]


class Interrupt(Exception):
    """Stands for the end of a session: raised inside training, as a kill would stop it."""


class StopAt(BaseCallback):
    """Raises :class:`Interrupt` at a step: the run dies between two checkpoints."""

    def __init__(self, step: int) -> None:
        super().__init__()
        self.step = step

    def _on_step(self) -> bool:
        if self.num_timesteps >= self.step:
            raise Interrupt
        return True

    def state_dict(self) -> dict:
        return {}

    def load_state_dict(self, state: dict) -> None:
        pass


def _params(model) -> torch.Tensor:
    return torch.cat([p.detach().flatten() for p in model.policy.parameters()])


def _same_run(a, b) -> None:
    assert a.model.num_timesteps == b.model.num_timesteps
    ea, eb = a.episodes, b.episodes
    assert len(ea) > 2
    assert ea[EPISODE_KEYS].equals(eb[EPISODE_KEYS])
    assert torch.equal(_params(a.model), _params(b.model))
    ra, rb = a.model.replay_buffer, b.model.replay_buffer
    assert ra.pos == rb.pos
    assert np.array_equal(ra.observations[: ra.pos], rb.observations[: rb.pos])
    assert np.array_equal(ra.actions[: ra.pos], rb.actions[: rb.pos])


def _pendulum(algo: str, **kw) -> RLConfig:
    return config_from_params(
        {
            "algo": algo,
            "env_id": "Pendulum-v1",
            "total_timesteps": 900,
            "seed": 1,
            "net_arch": [16, 16],
            "learning_starts": 100,
            "batch_size": 32,
            **kw,
        }
    )


class Record(BaseCallback):
    """Records what the model's schedules read at each step; stops training at ``stop``."""

    def __init__(self, stop: int | None = None) -> None:
        super().__init__()
        self.stop = stop
        self.progress: list[float] = []

    def _on_step(self) -> bool:
        self.progress.append(self.model._current_progress_remaining)
        return self.stop is None or self.num_timesteps < self.stop

    def state_dict(self) -> dict:
        return {"progress": list(self.progress)}

    def load_state_dict(self, state: dict) -> None:
        self.progress = list(state["progress"])


@pytest.mark.parametrize(
    "algo, kw",
    [
        ("SAC", {}),
        ("TD3", {"action_noise": "ornstein-uhlenbeck"}),  # a noise process SB3 resets per call
        ("SAC", {"learning_starts": 500}),  # random actions past the checkpoint: the space's RNG
    ],
)
def test_a_stopped_run_resumes_to_the_uninterrupted_run(tmp_path, algo, kw):
    cfg = _pendulum(algo, **kw)
    plain = train(cfg, progress=False)
    # 250 does not divide Pendulum's 200-step episodes: the run finishes the episode first
    with pytest.raises(Interrupt):
        train(
            cfg, progress=False, checkpoint=tmp_path, checkpoint_every=250, callbacks=[StopAt(550)]
        )
    assert resume.latest_checkpoint(tmp_path).name == "step-0000000400"
    # the same callbacks (a checkpoint is refused by a run with other parts), this one never fires
    resumed = train(
        cfg, progress=False, checkpoint=tmp_path, checkpoint_every=250, callbacks=[StopAt(10**9)]
    )
    _same_run(plain, resumed)
    # its cost: this part's CPU plus the earlier part's, up to its checkpoint
    assert 0 < resumed.resumed_cpu_s < resumed.cpu_time_s
    assert resumed.episodes.wall_time_s.is_monotonic_increasing


def test_checkpoints_leave_the_run_unchanged_and_keep_the_newest_two(tmp_path):
    cfg = _pendulum("SAC")
    seen = Record()
    plain = train(cfg, progress=False, callbacks=[seen])
    seen_chunked = Record()
    chunked = train(
        cfg, progress=False, checkpoint=tmp_path, checkpoint_every=150, callbacks=[seen_chunked]
    )
    _same_run(plain, chunked)
    # the schedules see the run's length, not the chunk's
    assert seen.progress == seen_chunked.progress and len(seen.progress) == 900
    assert sorted(p.name for p in tmp_path.iterdir()) == [
        "LATEST",
        "step-0000000600",
        "step-0000000800",
    ]
    assert (tmp_path / "LATEST").read_text() == "step-0000000800"
    # a checkpoint a crash of the machine cut short: the one before it is used
    (tmp_path / "step-0000000800" / "state.pt").write_bytes(b"")
    assert resume.latest_checkpoint(tmp_path).name == "step-0000000600"


def test_a_callback_that_stops_training_stops_a_checkpointed_run_as_a_plain_one(tmp_path):
    cfg = _pendulum("SAC")
    plain = train(cfg, progress=False, callbacks=[Record(stop=650)])
    chunked = train(
        cfg, progress=False, checkpoint=tmp_path, checkpoint_every=200, callbacks=[Record(stop=650)]
    )
    assert plain.model.num_timesteps == chunked.model.num_timesteps == 650
    _same_run(plain, chunked)


def _hopper_demos(n: int, seed: int) -> list[Demonstration]:
    env = gym.make("Hopper-v5")
    rng = np.random.default_rng(seed)
    demos = []
    for i in range(n):
        obs, _ = env.reset(seed=seed + i)
        xs, acts, rews = [obs], [], []
        for _ in range(15):
            act = rng.uniform(-1, 1, 3).astype(np.float32)
            obs, r, term, _, _ = env.step(act)
            xs.append(obs), acts.append(act), rews.append(r)
            if term:
                break
        demos.append(Demonstration(np.array(xs), np.array(acts), np.array(rews), term, not term))
    return demos


def _defended_hopper(kind: str = "defender") -> DefenderWrapper:
    common = {
        "counterfactual": True,
        "dynamics_kwargs": {"hidden": [16, 16], "batch_size": 32},
        "seed": 2,
    }
    if kind == "random":  # the control: its firing draws must resume too
        return RandomFilter(
            gym.make("Hopper-v5"), _hopper_demos(3, 0), _hopper_demos(3, 10), rate=0.02, **common
        )
    return DefenderWrapper(
        gym.make("Hopper-v5"),
        _hopper_demos(3, 0),
        _hopper_demos(3, 10),
        safe_method="MeanDemoW5",
        unsafe_method="MeanDemoW10",
        **common,
    )


@pytest.mark.parametrize("kind", ["defender", "random"])
def test_defenders_filter_resumes_with_its_dynamics_model_and_log(tmp_path, kind):
    cfg = config_from_params(
        {
            "algo": "SAC",
            "env_id": None,
            "total_timesteps": 500,
            "seed": 0,
            "net_arch": [16, 16],
            "learning_starts": 50,
            "batch_size": 32,
        }
    )
    keys = [*EPISODE_KEYS, "filtered", "would_crash"]
    a_env = _defended_hopper(kind)
    plain = train(cfg, env=a_env, progress=False, info_keys=["filtered", "would_crash"])
    with pytest.raises(Interrupt):
        train(
            cfg,
            env=_defended_hopper(kind),
            progress=False,
            info_keys=["filtered", "would_crash"],
            checkpoint=tmp_path,
            checkpoint_every=150,
            callbacks=[StopAt(400)],
        )
    assert resume.latest_checkpoint(tmp_path) is not None
    b_env = _defended_hopper(kind)
    resumed = train(
        cfg,
        env=b_env,
        progress=False,
        info_keys=["filtered", "would_crash"],
        checkpoint=tmp_path,
        checkpoint_every=150,
        callbacks=[StopAt(10**9)],
    )
    assert resumed.resumed_cpu_s > 0  # it resumed: a fresh start would match too
    _same_run(plain, resumed)
    assert plain.episodes[keys].equals(resumed.episodes[keys])
    assert plain.episodes["filtered"].any()  # the filter fired: its state mattered
    assert a_env.episodes.equals(b_env.episodes)
    assert (a_env.n_real_steps, a_env.n_filtered_steps) == (
        b_env.n_real_steps,
        b_env.n_filtered_steps,
    )
    assert a_env.dynamics.n_updates == b_env.dynamics.n_updates > 0
    for pa, pb in zip(
        a_env.dynamics.net.parameters(), b_env.dynamics.net.parameters(), strict=True
    ):
        assert torch.equal(pa, pb)


def test_a_checkpoint_of_another_run_is_refused_before_it_is_loaded(tmp_path):
    train(_pendulum("SAC"), progress=False, checkpoint=tmp_path, checkpoint_every=200)
    with pytest.raises(ValueError, match="another run.*config"):
        train(_pendulum("SAC", seed=2), progress=False, checkpoint=tmp_path, checkpoint_every=200)
    other_env = gym.wrappers.TimeLimit(gym.make("Pendulum-v1").unwrapped, 100)
    with pytest.raises(ValueError, match="another run.*env"):
        train(
            _pendulum("SAC"),
            env=other_env,
            progress=False,
            checkpoint=tmp_path,
            checkpoint_every=200,
        )


def test_the_same_env_built_again_is_the_same_run(tmp_path):
    """An env class without a ``repr`` of its own (its default names a memory address) still
    resumes: the check reads gymnasium's ``str`` of the chain."""
    from gymnasium.envs.classic_control import PendulumEnv

    cfg = _pendulum("SAC")
    with pytest.raises(Interrupt):
        train(
            cfg,
            env=gym.wrappers.TimeLimit(PendulumEnv(), 200),
            progress=False,
            checkpoint=tmp_path,
            checkpoint_every=200,
            callbacks=[StopAt(500)],
        )
    resumed = train(
        cfg,
        env=gym.wrappers.TimeLimit(PendulumEnv(), 200),
        progress=False,
        checkpoint=tmp_path,
        checkpoint_every=200,
        callbacks=[StopAt(10**9)],
    )
    assert resumed.resumed_cpu_s > 0 and resumed.model.num_timesteps == 900


@pytest.mark.parametrize(
    "kw, message",
    [
        ({"cfg": {"n_envs": 2}}, "n_envs 1"),
        ({"cfg": {"train_freq": 2}}, "train_freq 1"),
        ({"callbacks": [StopTrainingOnMaxEpisodes(3)]}, "StopTrainingOnMaxEpisodes"),
        ({"every": 0}, "positive number of steps"),
    ],
)
def test_what_cannot_resume_exactly_is_refused(tmp_path, kw, message):
    cfg = _pendulum("SAC", **kw.get("cfg", {}))
    with pytest.raises(ValueError, match=message):
        train(
            cfg,
            progress=False,
            checkpoint=tmp_path,
            checkpoint_every=kw.get("every", 200),
            callbacks=kw.get("callbacks", ()),
        )


def test_reset_recorder_replays_the_reset_it_saw():
    env = resume.ResetRecorder(gym.make("Hopper-v5"))
    env.reset(seed=5)
    for _ in range(3):
        env.step(env.action_space.sample())
    first, _ = env.reset()
    qpos = env.unwrapped.data.qpos.copy()
    env.unwrapped.np_random.bit_generator.state = env.rng_before_reset
    again, _ = env.reset()
    assert np.array_equal(first, again) and np.array_equal(qpos, env.unwrapped.data.qpos)


def test_a_defender_study_task_resumes_from_its_scratch_folder(tmp_path, monkeypatch):
    """The study's path: ``train_task`` run by the sweep with a scratch folder, killed after its
    first checkpoint, run again: the same rows as a run in one go, and the cost of both parts."""
    from thesis_lib.chapters.defender import tasks
    from thesis_lib.rl import training
    from thesis_lib.sweep import Task
    from thesis_lib.sweep._tasks import execute, scratch_of

    monkeypatch.setattr(tasks, "CHECKPOINT_EVERY", 200)
    train_fields = {
        "max_episode_steps": None, "train_timesteps": 700, "train_episodes": None,
        "net_arch": [16, 16], "learning_rate": 3e-4, "batch_size": 32,
        "max_trajectory": None, "dynamics_train_every": None,
    }  # fmt: skip
    config = {
        "task": "Hopper-v5", "algo": "SAC", "seed": 0, "strategy": None, "trajectory": "state",
        "paper_compat": False, "demos": None, "train": train_fields, "eval_episodes": 2,
    }  # fmt: skip
    task = Task(tasks.train_task, config)
    whole = execute(task)  # no store: no scratch, no checkpoint
    saved = training.save_checkpoint

    def save_then_die(*args, **kw):
        saved(*args, **kw)
        raise Interrupt

    monkeypatch.setattr(training, "save_checkpoint", save_then_die)
    with pytest.raises(Interrupt):
        execute(task, scratch_root=tmp_path)
    assert resume.latest_checkpoint(scratch_of(tmp_path, task.key)) is not None
    monkeypatch.setattr(training, "save_checkpoint", saved)
    again = execute(task, scratch_root=tmp_path)
    timing = {"wall_time_s", "train_cpu_s"}
    strip = [{k: v for k, v in r.items() if k not in timing} for r in whole["rows"]]
    assert strip == [{k: v for k, v in r.items() if k not in timing} for r in again["rows"]]
    assert 0 < again["resumed_cpu_s"] < again["cpu_s"]
    assert again["rows"][0]["train_cpu_s"] > again["resumed_cpu_s"]


def test_check_resumable_refuses_a_model_that_a_checkpoint_could_not_continue():
    """``check_resumable`` is public: a model built elsewhere is checked on its own."""
    from stable_baselines3 import SAC
    from stable_baselines3.common.env_util import make_vec_env

    def sac(n_envs=1, **kw):
        env = make_vec_env("Pendulum-v1", n_envs=n_envs, seed=0)
        return SAC("MlpPolicy", env, policy_kwargs={"net_arch": [8]}, seed=0, **kw)

    resume.check_resumable(sac())  # the checkpointed set-up passes
    with pytest.raises(ValueError, match="one env copy, got 2"):
        resume.check_resumable(sac(n_envs=2))
    unbound = sac()
    unbound.env = None  # as SAC.load leaves a model given no env
    with pytest.raises(ValueError, match="one env copy, got 0"):
        resume.check_resumable(unbound)
    with pytest.raises(ValueError, match="train_freq 1"):
        resume.check_resumable(sac(train_freq=(1, "episode")))
    other = sac()
    other.replay_buffer.__class__ = type("Sub", (type(other.replay_buffer),), {})
    with pytest.raises(ValueError, match="a plain ReplayBuffer, got Sub"):
        resume.check_resumable(other)
