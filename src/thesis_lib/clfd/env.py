"""The multi-view pick-and-place task (thesis 4.2.1.1, Fig 4.2) in MuJoCo, and its scripted expert.

The thesis's CoppeliaSim scene cannot be had here, so the task is rebuilt in MuJoCo
(``assets/pick_place.xml``): a 7-joint arm with a two-finger gripper, a red box and a green goal
plane whose positions are drawn anew each episode, and five fixed cameras (gripper, front, top,
overhead, right side). The model is our own rather than gymnasium-robotics' Fetch because
Mesa's software renderer draws its primitive shapes 5-10x faster than Fetch's meshes
(``benchmarks/bench_clfd.py`` on the busy 2-core machine: 2-3 ms against 14 ms per 64x64 frame),
and a data set has five frames per time step.

Rendering needs an OpenGL back end: ``MUJOCO_GL=egl`` (Mesa) is set when nothing is chosen.

Used in: CLfD (thesis 4.2), chapter 02_clfd.
"""

from __future__ import annotations

import os
import sys

# MuJoCo picks its OpenGL back end once, when it is first imported: remember whether that was
# before this module could choose EGL, to say so if rendering fails.
_MUJOCO_IMPORTED_FIRST = "mujoco" in sys.modules
os.environ.setdefault("MUJOCO_GL", "egl")

from importlib import resources  # noqa: E402
from typing import Any, NamedTuple  # noqa: E402

import gymnasium as gym  # noqa: E402
import mujoco  # noqa: E402
import numpy as np  # noqa: E402

#: The five viewpoints of thesis Fig 4.2, in the order frames are stored.
CAMERAS: tuple[str, ...] = ("gripper", "front", "top", "overhead", "right")
#: Stage labels (thesis 4.2.2.2): 0 = pick (approach and grasp), 1 = place (after the grasp).
STAGES: tuple[str, ...] = ("pick", "place")
ARM_JOINTS: tuple[str, ...] = ("j1", "j2", "j3", "j4", "j5", "j6", "j7")

_HAND_TO_GRIP = np.array([0.0, 0.0, 0.07])  # mocap (hand) above the grasp point, hand pointing down
_HOME = np.array([-0.12, 0.0, 0.22])
_LOW, _HIGH = np.array([-0.25, -0.3, 0.015]), np.array([0.3, 0.3, 0.35])  # grasp-point workspace
_OPEN, _CLOSED = 0.04, 0.0
BOX_HALF = 0.02
SUCCESS_DIST = (
    0.04  # box centre within 4 cm of the goal centre (the plane is 8 cm wide), on the table
)


def model_path() -> str:
    """Path of the packaged MJCF model."""
    return str(resources.files("thesis_lib.clfd") / "assets" / "pick_place.xml")


class MultiViewPickPlace(gym.Env):
    """Pick the red box and place it on the green plane, seen by five fixed cameras.

    Actions (4,) in [-1, 1]: the grasp point's displacement (x, y, z) in units of ``max_move``
    metres per step, and the gripper command (+1 closes, -1 opens). One step is 20 physics steps
    of 2 ms (as in Fetch). Observations (flat, 27,): the arm's 7 joint angles and 7 joint
    velocities, the gripper opening (m), the grasp point, the box and the goal positions, and the
    box relative to the grasp point. ``info`` holds ``stage`` ("pick" until the box is held off
    the table, then "place"), ``is_success`` and ``box_lifted``. ``render()`` draws
    ``render_camera``; :meth:`render_views` draws several cameras at once.

    Args:
        image_size: side of the square frames (pixels).
        max_episode_steps: episode length limit (``truncated``).
        render_camera: the camera ``render()`` shows (one of :data:`CAMERAS`).
        max_move: metres per step at action 1.

    Example:
        >>> env = MultiViewPickPlace(image_size=32)
        >>> obs, info = env.reset(seed=0)
        >>> obs.shape, info["stage"], env.render_views().shape
        ((27,), 'pick', (5, 32, 32, 3))
        >>> env.close()

    Used in: CLfD (thesis 4.2), chapter 02_clfd.
    """

    metadata = {"render_modes": ["rgb_array"], "render_fps": 25}

    def __init__(
        self,
        image_size: int = 64,
        max_episode_steps: int = 100,
        render_camera: str = "front",
        max_move: float = 0.03,
        render_mode: str | None = "rgb_array",
    ) -> None:
        if image_size < 8:
            raise ValueError(f"image_size must be >= 8 pixels, got {image_size}.")
        check_cameras([render_camera])
        self.model = mujoco.MjModel.from_xml_path(model_path())
        self.data = mujoco.MjData(self.model)
        self.image_size = int(image_size)
        self.max_episode_steps = int(max_episode_steps)
        self.render_camera = render_camera
        self.render_mode = render_mode
        self.max_move = float(max_move)
        self.n_substeps = 20
        self.action_space = gym.spaces.Box(-1.0, 1.0, (4,), np.float32)
        self.observation_space = gym.spaces.Box(-np.inf, np.inf, (27,), np.float64)
        self._arm_qpos = np.array(
            [self.model.jnt_qposadr[self.model.joint(j).id] for j in ARM_JOINTS]
        )
        self._arm_qvel = np.array(
            [self.model.jnt_dofadr[self.model.joint(j).id] for j in ARM_JOINTS]
        )
        self._box_qpos = self.model.jnt_qposadr[self.model.joint("box").id]
        self._fingers = [
            self.model.jnt_qposadr[self.model.joint(j).id] for j in ("finger_left", "finger_right")
        ]
        self._renderer: mujoco.Renderer | None = None
        self._steps = 0
        self._lifted = False
        self.goal = np.zeros(3)

    # -- state ---------------------------------------------------------------------------------
    @property
    def grip_pos(self) -> np.ndarray:
        return self.data.site("grip").xpos.copy()

    @property
    def box_pos(self) -> np.ndarray:
        return self.data.qpos[self._box_qpos : self._box_qpos + 3].copy()

    @property
    def gripper_opening(self) -> float:
        return float(sum(self.data.qpos[i] for i in self._fingers))

    @property
    def joint_angles(self) -> np.ndarray:
        return self.data.qpos[self._arm_qpos].copy()

    @property
    def joint_velocities(self) -> np.ndarray:
        return self.data.qvel[self._arm_qvel].copy()

    def _obs(self) -> np.ndarray:
        grip, box = self.grip_pos, self.box_pos
        return np.concatenate([
            self.joint_angles, self.joint_velocities, [self.gripper_opening], grip, box, self.goal, box - grip,
        ])  # fmt: skip

    def _info(self) -> dict[str, Any]:
        box = self.box_pos
        on_goal = (
            np.linalg.norm(box[:2] - self.goal[:2]) < SUCCESS_DIST and box[2] < BOX_HALF + 0.01
        )
        return {
            "stage": STAGES[int(self._lifted)],
            "is_success": bool(on_goal and not self._held()),
            "box_lifted": bool(self._lifted),
        }

    def _held(self) -> bool:
        """The box is off the table and between the fingers."""
        d = self.box_pos - self.grip_pos
        return bool(
            self.box_pos[2] > BOX_HALF + 0.01 and np.abs(d[:2]).max() < 0.03 and abs(d[2]) < 0.04
        )

    # -- gymnasium API -------------------------------------------------------------------------
    def reset(
        self, *, seed: int | None = None, options: dict | None = None
    ) -> tuple[np.ndarray, dict]:
        """New episode: box and goal at random places at least 10 cm apart.

        ``options`` may fix ``box_xy`` and/or ``goal_xy``.
        """
        super().reset(seed=seed)
        options = options or {}
        mujoco.mj_resetDataKeyframe(self.model, self.data, 0)
        rng = self.np_random
        box_xy = np.asarray(options.get("box_xy", rng.uniform([-0.12, -0.15], [0.12, 0.15])), float)
        goal_xy = options.get("goal_xy")
        while goal_xy is None:
            cand = rng.uniform([-0.12, -0.15], [0.12, 0.15])
            if np.linalg.norm(cand - box_xy) >= 0.1:
                goal_xy = cand
        self.goal = np.array([*np.asarray(goal_xy, float), 0.0])
        self.data.qpos[self._box_qpos : self._box_qpos + 3] = [*box_xy, BOX_HALF]
        self.data.qpos[self._box_qpos + 3 : self._box_qpos + 7] = [1, 0, 0, 0]
        self.data.mocap_pos[self.model.body("goal").mocapid[0]] = self.goal
        self.data.mocap_pos[self.model.body("target").mocapid[0]] = _HOME + _HAND_TO_GRIP
        self.data.ctrl[:] = _OPEN
        mujoco.mj_forward(self.model, self.data)
        for _ in range(5):  # let the arm settle on the home pose (the keyframe is close to it)
            mujoco.mj_step(self.model, self.data, nstep=self.n_substeps)
        self._steps = 0
        self._lifted = False
        return self._obs(), self._info()

    def step(self, action: np.ndarray) -> tuple[np.ndarray, float, bool, bool, dict]:
        a = np.asarray(action, dtype=float).reshape(-1)
        if a.shape != (4,) or not np.all(np.isfinite(a)):
            raise ValueError(
                f"MultiViewPickPlace expects a finite action of shape (4,), got {np.asarray(action)!r}."
            )
        a = np.clip(a, -1.0, 1.0)
        mid = self.model.body("target").mocapid[0]
        grip_target = np.clip(
            self.data.mocap_pos[mid] - _HAND_TO_GRIP + a[:3] * self.max_move, _LOW, _HIGH
        )
        self.data.mocap_pos[mid] = grip_target + _HAND_TO_GRIP
        self.data.ctrl[:] = _OPEN * (1.0 - a[3]) / 2.0
        mujoco.mj_step(self.model, self.data, nstep=self.n_substeps)
        self._steps += 1
        self._lifted = self._lifted or self._held()
        info = self._info()
        reward = (
            float(info["is_success"]) - 1.0
        )  # sparse, as Fetch; the chapter uses Eq 4.2 instead
        truncated = self._steps >= self.max_episode_steps
        return self._obs(), reward, False, truncated, info

    # -- rendering -----------------------------------------------------------------------------
    def _get_renderer(self) -> mujoco.Renderer:
        if self._renderer is None:
            try:
                self._renderer = mujoco.Renderer(self.model, self.image_size, self.image_size)
            except Exception as exc:
                why = (
                    "mujoco was imported before thesis_lib.clfd could choose EGL"
                    if _MUJOCO_IMPORTED_FIRST
                    else f"MUJOCO_GL={os.environ.get('MUJOCO_GL')!r}"
                )
                raise RuntimeError(
                    f"MuJoCo could not create an OpenGL context for rendering ({why}): {exc}. Set "
                    "MUJOCO_GL=egl (or osmesa) in the environment before anything imports mujoco, e.g. "
                    "`MUJOCO_GL=egl jupyter ...`, or import thesis_lib.clfd first."
                ) from exc
        return self._renderer

    def render_views(self, cameras: tuple[str, ...] | list[str] | None = None) -> np.ndarray:
        """Frames of ``cameras`` (default all five) at the current state: uint8 (V, H, W, 3)."""
        cameras = CAMERAS if cameras is None else tuple(cameras)
        check_cameras(cameras)
        r = self._get_renderer()
        out = np.empty((len(cameras), self.image_size, self.image_size, 3), np.uint8)
        for i, cam in enumerate(cameras):
            r.update_scene(self.data, camera=cam)
            out[i] = r.render()
        return out

    def render(self) -> np.ndarray:
        return self.render_views([self.render_camera])[0]

    def close(self) -> None:
        if self._renderer is not None:
            self._renderer.close()
            self._renderer = None


def check_cameras(cameras: tuple[str, ...] | list[str]) -> None:
    """Raise ``ValueError`` for a camera name that is not one of :data:`CAMERAS`."""
    for c in cameras:
        if c not in CAMERAS:
            raise ValueError(f"Unknown camera {c!r}. Valid: {', '.join(CAMERAS)}.")


# -- the scripted expert -----------------------------------------------------------------------
PHASES: tuple[str, ...] = (
    "reach",
    "descend",
    "grasp",
    "lift",
    "carry",
    "lower",
    "release",
    "retreat",
)
_PHASE_STAGE = {
    "reach": 0,
    "descend": 0,
    "grasp": 0,
    "lift": 1,
    "carry": 1,
    "lower": 1,
    "release": 1,
    "retreat": 1,
}


class ScriptedPickPlace:
    """The demonstrator: reach above the box, descend, grasp, lift, carry, lower, release, retreat.

    It reads the box and goal positions from the simulator (thesis 4.2.1.1: "performed
    automatically by having access to the position of the objects") and moves the grasp point
    with a proportional controller. ``phase`` and ``stage`` name what it is doing; the stage
    label of a frame is "pick" (reach, descend, grasp) or "place" (the rest).

    Used in: CLfD (thesis 4.2), chapter 02_clfd.
    """

    def __init__(self, env: MultiViewPickPlace, gain: float = 1.0 / 0.03) -> None:
        self.env = env
        self.gain = gain
        self.phase = "reach"
        self._count = 0

    def reset(self) -> None:
        self.phase, self._count = "reach", 0

    @property
    def stage(self) -> int:
        return _PHASE_STAGE[self.phase]

    def _move(self, target: np.ndarray, grip: float) -> tuple[np.ndarray, float]:
        err = target - self.env.grip_pos
        return np.array([*np.clip(err * self.gain, -1, 1), grip]), float(np.linalg.norm(err))

    def act(self) -> np.ndarray:
        """The action for the current state; advances the phase when its goal is reached."""
        env, box, goal = self.env, self.env.box_pos, self.env.goal
        carry_z = 0.12
        if self.phase == "reach":
            a, e = self._move(box + [0, 0, 0.07], -1)
            if e < 0.012:
                self.phase = "descend"
        if self.phase == "descend":
            a, e = self._move(box + [0, 0, 0.0], -1)
            if e < 0.008:
                self.phase, self._count = "grasp", 0
        if self.phase == "grasp":
            a = np.array([0.0, 0.0, 0.0, 1.0])
            self._count += 1
            if self._count > 4:
                self.phase = "lift"
        if self.phase == "lift":
            a, e = self._move(np.array([*env.grip_pos[:2], carry_z]), 1)
            if env.grip_pos[2] > carry_z - 0.02:
                self.phase = "carry"
        if self.phase == "carry":
            a, e = self._move(np.array([*goal[:2], carry_z]), 1)
            if e < 0.01:
                self.phase = "lower"
        if self.phase == "lower":
            a, e = self._move(goal + [0, 0, BOX_HALF + 0.025], 1)
            if e < 0.01:
                self.phase, self._count = "release", 0
        if self.phase == "release":
            a = np.array([0.0, 0.0, 0.0, -1.0])
            self._count += 1
            if self._count > 3:
                self.phase, self._count = "retreat", 0
        if self.phase == "retreat":
            a, _ = self._move(np.array([*goal[:2], carry_z]), -1)
            self._count += 1
        return a

    @property
    def done(self) -> bool:
        return self.phase == "retreat" and self._count > 4


class Demonstration(NamedTuple):
    """One scripted demonstration: per time step t (T steps)."""

    frames: np.ndarray | None
    """uint8 (T, V, H, W, 3): the V cameras' frames, synchronised (None when not rendered)."""
    joint_angles: np.ndarray
    """(T, 7) arm joint angles (rad)."""
    joint_velocities: np.ndarray
    """(T, 7) arm joint velocities (rad/s)."""
    gripper: np.ndarray
    """(T,) gripper opening (m)."""
    stages: np.ndarray
    """(T,) int: 0 = pick, 1 = place."""
    actions: np.ndarray
    """(T, 4) the action taken after the frame (the last row repeats a zero action)."""
    box_pos: np.ndarray
    """(T, 3) box position."""
    goal: np.ndarray
    """(3,) goal position."""
    success: bool
    """The box ended on the goal plane, released."""


def run_demonstration(
    env: MultiViewPickPlace,
    seed: int,
    render: bool = True,
    cameras: tuple[str, ...] = CAMERAS,
    max_steps: int = 100,
) -> Demonstration:
    """Run the scripted expert once from ``env.reset(seed=seed)`` and record everything.

    Frames are recorded at every time step before the action, from all ``cameras`` at the same
    simulator state, so they are synchronised by construction.

    Used in: CLfD (thesis 4.2), chapter 02_clfd.
    """
    env.reset(seed=seed)
    expert = ScriptedPickPlace(env)
    rec: dict[str, list] = {k: [] for k in ("frames", "q", "dq", "g", "stage", "a", "box")}
    for _ in range(max_steps):
        a = expert.act()
        if render:
            rec["frames"].append(env.render_views(cameras))
        rec["q"].append(env.joint_angles)
        rec["dq"].append(env.joint_velocities)
        rec["g"].append(env.gripper_opening)
        rec["stage"].append(expert.stage)
        rec["a"].append(a)
        rec["box"].append(env.box_pos)
        if expert.done:
            break
        env.step(a)
    info = env._info()
    return Demonstration(
        frames=np.stack(rec["frames"]) if render else None,
        joint_angles=np.array(rec["q"]),
        joint_velocities=np.array(rec["dq"]),
        gripper=np.array(rec["g"]),
        stages=np.array(rec["stage"], dtype=np.int64),
        actions=np.array(rec["a"], dtype=np.float32),
        box_pos=np.array(rec["box"]),
        goal=env.goal.copy(),
        success=bool(info["is_success"] and expert.done),
    )
