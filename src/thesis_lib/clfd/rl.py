"""RL with the embedding reward (thesis 4.2.1.3, Eq 4.2, Fig 4.4).

:class:`EmbeddingRewardEnv` turns :class:`~thesis_lib.clfd.env.MultiViewPickPlace` into the
thesis's RL problem for one stage of the task: the state is the encoder's embedding of the
current camera image together with the arm's joint angles, joint velocities and gripper state,
and the reward is ``R(t) = -||f(s_t) - f(s_dg)||`` (Eq 4.2), the distance to the embedding of
the demonstration's last frame of that stage. Every episode starts from the demonstration's
initial layout (box and goal where they were), since one demonstration guides the agent.

It is a goal-conditioned env (``observation``, ``achieved_goal`` = f(s_t), ``desired_goal`` =
f(s_dg), ``compute_reward``), so stable-baselines3's DDPG can use HER (the thesis text's choice;
the authors' code used prioritised replay instead and the reward ``-MSE`` to the demonstration
embedding at the same step).

Used in: CLfD (thesis 4.2), chapter 02_clfd.
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np
import pandas as pd

from thesis_lib.clfd.env import STAGES, MultiViewPickPlace, check_cameras, run_demonstration


class GraspPointOracle:
    """C12's positive control: an "encoder" that reads the grasp point's position (m) from the
    simulator instead of embedding an image.

    With it :class:`EmbeddingRewardEnv`'s state holds the true grasp point, and Eq 4.2's reward
    becomes minus the true distance (m) to where the guiding demonstration grasped the box: an
    ideal low-dimensional state, and a reward aligned with the success measure (the grasp point
    within a few cm of the box). If DDPG+HER does not learn the pick stage with it, the RL
    budget is too small for any encoder; if it does, the budget suffices for an ideal state,
    though not necessarily for an encoder's higher-dimensional one. The study labels its runs
    ``oracle`` (:data:`thesis_lib.chapters.clfd.ORACLE`).
    """

    def read_simulator(self, env: MultiViewPickPlace) -> np.ndarray:
        """The grasp point's position in ``env`` (3,), float32."""
        return np.asarray(env.grip_pos, dtype=np.float32)


class EmbeddingRewardEnv(gym.Env):
    """One stage of pick and place, observed through an encoder, rewarded by Eq 4.2.

    Args:
        encoder: anything with ``embed(frames (N, H, W, 3) uint8) -> (N, D)``, e.g. a :class:`CLfD`,
            or with ``read_simulator(env) -> (D,)``, which reads the simulator and renders nothing
            (:class:`GraspPointOracle`, the positive control).
        demo_seed: the reset seed of the guiding demonstration (its layout is every episode's start).
        stage: ``"pick"`` (reach and grasp) or ``"place"`` (the thesis's Fig 4.4 shows pick).
        camera: the camera whose image is embedded.
        image_size: frame size, as the encoder was trained on.
        max_episode_steps: episode length.

    ``info`` reports the task's own progress: ``grip_box_distance`` (m) and ``box_lifted``.
    """

    metadata = {"render_modes": ["rgb_array"]}

    def __init__(
        self,
        encoder: Any,
        demo_seed: int,
        stage: str = "pick",
        camera: str = "front",
        image_size: int = 64,
        max_episode_steps: int = 25,
    ) -> None:
        if stage not in STAGES:
            raise ValueError(f"Unknown stage {stage!r}. Valid: {', '.join(STAGES)}.")
        check_cameras([camera])
        self.encoder, self.demo_seed, self.stage, self.camera = encoder, demo_seed, stage, camera
        self.env = MultiViewPickPlace(
            image_size=image_size, max_episode_steps=10_000, render_camera=camera
        )
        self._reads_state = hasattr(encoder, "read_simulator")
        demo = run_demonstration(
            self.env, demo_seed, render=not self._reads_state, cameras=(camera,)
        )
        if not demo.success:
            raise RuntimeError(
                f"The demonstration with seed {demo_seed} failed; pick another seed."
            )
        s = STAGES.index(stage)
        last = int(np.flatnonzero(demo.stages == s)[-1])
        self._demo_actions = demo.actions
        self.goal_frame: np.ndarray | None = None
        if self._reads_state:  # the state of the last frame of the stage: replay up to it
            self._replay(last)
            self.goal_embedding = np.asarray(encoder.read_simulator(self.env), dtype=np.float32)
        else:
            if demo.frames is None:
                raise RuntimeError("run_demonstration(render=True) returned no frames.")
            self.goal_frame = demo.frames[last, 0]
            self.goal_embedding = np.asarray(
                encoder.embed(self.goal_frame[None])[0], dtype=np.float32
            )
        self._start_step = int(np.flatnonzero(demo.stages == s)[0])
        self._end_step = last
        d = len(self.goal_embedding)
        self.max_episode_steps = max_episode_steps
        self.action_space = self.env.action_space
        box = gym.spaces.Box(-np.inf, np.inf, (d,), np.float32)
        self.observation_space = gym.spaces.Dict({
            "observation": gym.spaces.Box(-np.inf, np.inf, (d + 15,), np.float32),
            "achieved_goal": box,
            "desired_goal": box,
        })  # fmt: skip
        self._steps = 0

    def _replay(self, n: int) -> None:
        """Reset to the demonstration's layout and step its first ``n`` actions."""
        self.env.reset(seed=self.demo_seed)
        for a in self._demo_actions[:n]:
            self.env.step(a)

    def _obs(self) -> dict[str, np.ndarray]:
        if self._reads_state:
            emb = np.asarray(self.encoder.read_simulator(self.env), dtype=np.float32)
        else:
            emb = np.asarray(self.encoder.embed(self.env.render()[None])[0], dtype=np.float32)
        robot = np.concatenate(
            [self.env.joint_angles, self.env.joint_velocities, [self.env.gripper_opening]]
        )
        return {
            "observation": np.concatenate([emb, robot]).astype(np.float32),
            "achieved_goal": emb,
            "desired_goal": self.goal_embedding.copy(),
        }

    def compute_reward(
        self, achieved_goal: np.ndarray, desired_goal: np.ndarray, info: Any
    ) -> np.ndarray:
        """Eq 4.2, vectorised for HER: ``-||achieved - desired||`` along the last axis."""
        return -np.linalg.norm(
            np.asarray(achieved_goal) - np.asarray(desired_goal), axis=-1
        ).astype(np.float32)

    def _info(self) -> dict[str, Any]:
        info = self.env._info()
        return {
            "grip_box_distance": float(np.linalg.norm(self.env.box_pos - self.env.grip_pos)),
            "box_lifted": info["box_lifted"],
            "is_success": info["box_lifted"] if self.stage == "pick" else info["is_success"],
        }

    def reset(self, *, seed: int | None = None, options: dict | None = None) -> tuple[dict, dict]:
        super().reset(seed=seed)
        # the place stage starts where the demonstration's pick stage ended
        self._replay(self._start_step if self.stage == "place" else 0)
        self._steps = 0
        return self._obs(), self._info()

    def step(self, action: np.ndarray) -> tuple[dict, float, bool, bool, dict]:
        self.env.step(action)
        self._steps += 1
        obs = self._obs()
        info = self._info()
        reward = float(self.compute_reward(obs["achieved_goal"], obs["desired_goal"], info))
        return obs, reward, False, self._steps >= self.max_episode_steps, info

    def render(self) -> np.ndarray:
        return self.env.render()

    def expert_return(self) -> float:
        """Accumulated reward of the demonstration itself over one episode (a reference for Fig 4.4).

        The demonstration's actions are replayed to the end of the stage, then the gripper holds still.
        """
        self.reset()
        total = 0.0
        for t in range(self.max_episode_steps):
            step = self._start_step + t if self.stage == "place" else t
            a = (
                self._demo_actions[step]
                if step <= self._end_step
                else np.array([0.0, 0.0, 0.0, 1.0])
            )
            total += self.step(a)[1]
        return total

    def close(self) -> None:
        self.env.close()


def train_embedding_agent(
    encoder: Any,
    demo_seed: int,
    episodes: int = 20,
    stage: str = "pick",
    camera: str = "front",
    image_size: int = 64,
    max_episode_steps: int = 25,
    her: bool = True,
    net_arch: list[int] | None = None,
    learning_rate: float = 1e-3,
    batch_size: int = 64,
    seed: int = 0,
    progress: bool = False,
) -> pd.DataFrame:
    """Train SB3's DDPG (with HER by default) on :class:`EmbeddingRewardEnv`; one row per episode.

    Uses the book's RL layer (:func:`thesis_lib.rl.train`). Columns: ``episode``, ``return``
    (accumulated Eq 4.2 reward, Fig 4.4), ``length``, ``final_grip_box_distance`` (m) and
    ``box_lifted``, the task's own measures of progress, and ``expert_return``, the return of the
    guiding demonstration replayed in the same env (the same on every row).

    Used in: CLfD (thesis 4.2), chapter 02_clfd.
    """
    from stable_baselines3 import HerReplayBuffer

    from thesis_lib.rl import RLConfig, train  # lazy: stable_baselines3

    env = EmbeddingRewardEnv(encoder, demo_seed, stage, camera, image_size, max_episode_steps)
    expert = env.expert_return()
    extra: dict[str, Any] = {}
    if her:
        extra = {
            "replay_buffer_class": HerReplayBuffer,
            "replay_buffer_kwargs": {"n_sampled_goal": 4, "goal_selection_strategy": "future"},
        }
    cfg = RLConfig(
        algo="DDPG", env_id=None, total_timesteps=episodes * max_episode_steps, seed=seed,
        learning_starts=max_episode_steps * 2, net_arch=list(net_arch or [64, 64]), learning_rate=learning_rate,
        batch_size=batch_size, buffer_size=100_000, gamma=0.99, action_noise="normal", action_noise_sigma=0.2,
        device="cpu", extra=extra,
    )  # fmt: skip
    result = train(cfg, env=env, progress=progress, info_keys=("grip_box_distance", "box_lifted"))
    env.close()
    ep = result.episodes.copy()
    ep = ep.rename(columns={"grip_box_distance": "final_grip_box_distance"})
    return ep.assign(expert_return=expert)
