"""The UR3 arm: DH parameters, limits, forward kinematics and an MJCF model built from them.

The UR3's published (standard, Denavit-Hartenberg) parameters, in metres and radians::

    joint   d         a          alpha
    1       0.1519    0          pi/2      base
    2       0         -0.24365   0         shoulder
    3       0         -0.21325   0         elbow
    4       0.11235   0          pi/2      wrist 1
    5       0.08535   0          -pi/2     wrist 2
    6       0.0819    0          0         wrist 3

Frame ``i`` follows from frame ``i-1`` by ``Rz(q_i) Tz(d_i) Tx(a_i) Rx(alpha_i)``. The MJCF
model (:func:`build_mjcf`, shipped as ``assets/ur3.xml``) nests one body per joint: body ``i``
is frame ``i-1`` with a hinge about its z axis, and its child sits at ``(a_i, 0, d_i)`` rotated
by ``alpha_i`` about x; so MuJoCo's forward kinematics is the DH product by construction, and
``tests/test_ur3.py`` checks it numerically. Geometry is simple capsules along the DH links
(the real arm's lateral offsets of the shoulder and elbow housings are not drawn).

Limits (UR3 CB3 data sheet): every joint ±360°, the last one unlimited on the robot (bounded
to ±360° here, as URScript's default); maximum speeds 180°/s for base, shoulder and elbow and
360°/s for the three wrist joints. MJCF has no velocity limit, so the speeds are stored in the
model as ``<custom><numeric name="max_speed">`` and read back by :func:`load_model`.

Used in: UR3 deployment chapter (thesis 5.2.5.4 and chapter 6's application).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path

import numpy as np

__all__ = [
    "DH",
    "JOINT_NAMES",
    "MAX_SPEED",
    "POSITION_LIMITS",
    "UR3Kinematics",
    "asset_path",
    "build_mjcf",
    "dh_transform",
    "fk_dh",
    "load_model",
    "tcp_position",
]

JOINT_NAMES = ("shoulder_pan", "shoulder_lift", "elbow", "wrist_1", "wrist_2", "wrist_3")
"""The six joints, base to tool (Universal Robots' names)."""


@dataclass(frozen=True)
class DHParameters:
    """Standard DH parameters of a 6-joint arm (metres, radians)."""

    d: tuple[float, ...]
    a: tuple[float, ...]
    alpha: tuple[float, ...]


DH = DHParameters(
    d=(0.1519, 0.0, 0.0, 0.11235, 0.08535, 0.0819),
    a=(0.0, -0.24365, -0.21325, 0.0, 0.0, 0.0),
    alpha=(np.pi / 2, 0.0, 0.0, np.pi / 2, -np.pi / 2, 0.0),
)
"""The UR3's published DH parameters (Universal Robots)."""

POSITION_LIMITS = np.array([[-2 * np.pi, 2 * np.pi]] * 6)
"""``(6, 2)`` joint position limits in radians: ±360° (wrist 3 is unlimited on the robot)."""

MAX_SPEED = np.array([np.pi, np.pi, np.pi, 2 * np.pi, 2 * np.pi, 2 * np.pi])
"""``(6,)`` maximum joint speeds in rad/s: 180°/s (base, shoulder, elbow), 360°/s (wrists)."""


def dh_transform(theta: float, d: float, a: float, alpha: float) -> np.ndarray:
    """The 4x4 homogeneous transform ``Rz(theta) Tz(d) Tx(a) Rx(alpha)``.

    >>> np.round(dh_transform(0.0, 0.1, 0.2, 0.0)[:3, 3], 3).tolist()
    [0.2, 0.0, 0.1]
    """
    ct, st, ca, sa = np.cos(theta), np.sin(theta), np.cos(alpha), np.sin(alpha)
    return np.array([
        [ct, -st * ca, st * sa, a * ct],
        [st, ct * ca, -ct * sa, a * st],
        [0.0, sa, ca, d],
        [0.0, 0.0, 0.0, 1.0],
    ])  # fmt: skip


def _check_q(q: np.ndarray, n: int = 6) -> np.ndarray:
    q = np.asarray(q, dtype=np.float64)
    if q.shape[-1] != n:
        raise ValueError(
            f"Expect joint angles of shape (..., {n}) in radians, got shape {q.shape}."
        )
    if not np.all(np.isfinite(q)):
        raise ValueError("Joint angles contain NaN or inf.")
    return q


def fk_dh(q: np.ndarray, dh: DHParameters = DH) -> np.ndarray:
    """Frames ``0..6`` of the arm at joint angles ``q`` by the DH product (reference FK).

    Args:
        q: ``(6,)`` joint angles in radians.
        dh: the DH parameters (the UR3's by default).

    Returns:
        ``(7, 4, 4)``: frame 0 (the base, identity) to frame 6 (the tool flange).

    >>> bool(np.allclose(fk_dh(np.zeros(6))[6][:3, 3], [-0.4569, -0.19425, 0.06655]))
    True
    """
    q = _check_q(q)
    frames = [np.eye(4)]
    for i in range(6):
        frames.append(frames[-1] @ dh_transform(q[i], dh.d[i], dh.a[i], dh.alpha[i]))
    return np.stack(frames)


def tcp_position(q: np.ndarray) -> np.ndarray:
    """Tool-flange position(s) in metres for joint angles ``(..., 6)`` (vectorised DH FK)."""
    q = _check_q(q)
    flat = q.reshape(-1, 6)
    out = np.array([fk_dh(x)[6][:3, 3] for x in flat])
    return out.reshape(q.shape[:-1] + (3,))


# ----------------------------------------------------------------------------------------------
# MJCF

_RADII = (0.045, 0.045, 0.035, 0.03, 0.03, 0.028)
_COLORS = ("0.35 0.55 0.8 1", "0.35 0.55 0.8 1", "0.6 0.7 0.85 1", "0.35 0.55 0.8 1",
           "0.6 0.7 0.85 1", "0.35 0.55 0.8 1")  # fmt: skip


def _f(x: float) -> str:
    return f"{x:.10g}"


def build_mjcf(dh: DHParameters = DH) -> str:
    """The UR3's MJCF model text, built from its DH parameters and limits (see module docstring).

    Bodies ``link1..link6`` carry the hinges ``shoulder_pan..wrist_3``; site ``tcp`` is frame 6
    (the tool flange); sites ``frame0..frame6`` mark every DH frame's origin.
    """
    lines = [
        '<mujoco model="ur3">',
        "  <!-- generated by thesis_lib.ur3.model.build_mjcf from the UR3's DH parameters -->",
        '  <compiler angle="radian" autolimits="true"/>',
        '  <option timestep="0.002" gravity="0 0 -9.81"/>',
        "  <custom>",
        f'    <numeric name="max_speed" data="{" ".join(_f(v) for v in MAX_SPEED)}"/>',
        f'    <numeric name="dh_d" data="{" ".join(_f(v) for v in dh.d)}"/>',
        f'    <numeric name="dh_a" data="{" ".join(_f(v) for v in dh.a)}"/>',
        f'    <numeric name="dh_alpha" data="{" ".join(_f(v) for v in dh.alpha)}"/>',
        "  </custom>",
        '  <visual><global offwidth="640" offheight="480"/></visual>',
        "  <asset>",
        '    <texture name="grid" type="2d" builtin="checker" rgb1="0.9 0.9 0.9" rgb2="0.8 0.8 0.8" width="256" height="256"/>',
        '    <material name="grid" texture="grid" texrepeat="8 8"/>',
        "  </asset>",
        "  <worldbody>",
        '    <light pos="0.5 -0.5 1.5" dir="-0.3 0.3 -1"/>',
        '    <camera name="front" pos="1.0 -1.0 0.7" xyaxes="0.707 0.707 0 -0.25 0.25 0.93"/>',
        '    <geom name="table" type="plane" size="0.8 0.8 0.01" material="grid"/>',
        '    <geom name="base" type="cylinder" pos="0 0 0.02" size="0.065 0.02" rgba="0.2 0.2 0.2 1" contype="0" conaffinity="0"/>',
        '    <site name="frame0" pos="0 0 0" size="0.005"/>',
    ]
    indent = "    "
    pos, quat = "0 0 0", "1 0 0 0"
    for i in range(6):
        lo, hi = POSITION_LIMITS[i]
        lines.append(f'{indent}<body name="link{i + 1}" pos="{pos}" quat="{quat}">')
        ind = indent + "  "
        lines.append(
            f'{ind}<joint name="{JOINT_NAMES[i]}" type="hinge" axis="0 0 1" range="{_f(lo)} {_f(hi)}" damping="1"/>'
        )
        a, d = dh.a[i], dh.d[i]
        r = _RADII[i]
        # a short cylinder around the joint axis (the motor housing) and a capsule along the link
        lines.append(
            f'{ind}<geom type="cylinder" size="{_f(r * 1.15)} {_f(r * 1.1)}" rgba="0.25 0.25 0.3 1" contype="0" conaffinity="0"/>'
        )
        if abs(a) + abs(d) > 1e-9:
            lines.append(
                f'{ind}<geom type="capsule" fromto="0 0 0 {_f(a)} 0 {_f(d)}" size="{_f(r)}" rgba="{_COLORS[i]}" contype="0" conaffinity="0"/>'
            )
        # the child frame: translate (a, 0, d), rotate alpha about x
        al = dh.alpha[i]
        pos, quat = f"{_f(a)} 0 {_f(d)}", f"{_f(np.cos(al / 2))} {_f(np.sin(al / 2))} 0 0"
        indent = ind
    lines.append(
        f'{indent}<site name="tcp" pos="{pos}" quat="{quat}" size="0.012" rgba="0.9 0.3 0.2 1"/>'
    )
    for _ in range(6, 0, -1):
        indent = indent[:-2]
        lines.append(f"{indent}</body>")
    lines += ["  </worldbody>", "</mujoco>", ""]
    return "\n".join(lines)


def asset_path() -> Path:
    """Path of the shipped ``assets/ur3.xml`` (equal to :func:`build_mjcf`'s text; a test checks)."""
    return Path(__file__).parent / "assets" / "ur3.xml"


@lru_cache(maxsize=1)
def _model_cached():
    import mujoco

    return mujoco.MjModel.from_xml_path(str(asset_path()))


def load_model():
    """The UR3 ``mujoco.MjModel`` from ``assets/ur3.xml`` (cached; treat as read-only)."""
    return _model_cached()


class UR3Kinematics:
    """MuJoCo forward kinematics of the UR3 model: link origins and the tool flange.

    >>> kin = UR3Kinematics()                                    # doctest: +SKIP
    >>> kin.tcp(np.zeros(6))                                     # doctest: +SKIP
    array([-0.4569 , -0.19425,  0.06655])
    """

    def __init__(self) -> None:
        import mujoco

        self._mj = mujoco
        self.model = load_model()
        self.data = mujoco.MjData(self.model)
        self.tcp_site = mujoco.mj_name2id(self.model, mujoco.mjtObj.mjOBJ_SITE, "tcp")
        self.body_ids = [
            mujoco.mj_name2id(self.model, mujoco.mjtObj.mjOBJ_BODY, f"link{i}") for i in range(1, 7)
        ]
        self.max_speed = np.array(self.model.numeric("max_speed").data)
        self.position_limits = np.array(self.model.jnt_range)

    def forward(self, q: np.ndarray) -> None:
        """Set the joint angles and run MuJoCo's kinematics."""
        self.data.qpos[:] = _check_q(q)
        self._mj.mj_kinematics(self.model, self.data)

    def tcp(self, q: np.ndarray) -> np.ndarray:
        """``(3,)`` tool-flange position of ``q``."""
        self.forward(q)
        return self.data.site_xpos[self.tcp_site].copy()

    def tcp_pose(self, q: np.ndarray) -> np.ndarray:
        """``(4, 4)`` tool-flange pose of ``q`` (compare with ``fk_dh(q)[6]``)."""
        self.forward(q)
        T = np.eye(4)
        T[:3, :3] = self.data.site_xmat[self.tcp_site].reshape(3, 3)
        T[:3, 3] = self.data.site_xpos[self.tcp_site]
        return T

    def points(self, q: np.ndarray) -> np.ndarray:
        """``(8, 3)``: the base, the six joint frames' origins (bodies ``link1..6``) and the flange.

        The arm drawn as a polyline through these points is the DH skeleton.
        """
        self.forward(q)
        pts = (
            [np.zeros(3)]
            + [self.data.xpos[b].copy() for b in self.body_ids]
            + [self.data.site_xpos[self.tcp_site].copy()]
        )
        return np.array(pts)

    def points_trajectory(self, q: np.ndarray) -> np.ndarray:
        """``(T, 8, 3)`` :meth:`points` of every row of ``q (T, 6)``."""
        q = _check_q(q)
        return np.stack([self.points(x) for x in q])
