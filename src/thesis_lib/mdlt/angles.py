"""Human poses -> the first four UR3 joint angles (thesis 6.3.3, Fig 6.2).

The project defines its own 24-joint SMPL-like skeleton (:data:`JOINT_NAMES`, :data:`PARENTS`,
:data:`REST_JOINTS`: same joint order and parents as SMPL, rest positions of an average adult
in a T-pose, in metres, y up, x to the body's left, z forward) and its forward kinematics
(:func:`forward_kinematics`), so SMPL pose parameters (axis-angle, 24 x 3) become joint positions
without the SMPL model files. Bone lengths therefore differ from a real SMPL body a little; the
joint angles below depend on directions only, not on lengths.

:func:`pose_to_ur3_angles` follows the thesis:

1. centre the skeleton on the midpoint of the shoulders;
2. rotate so the shoulder line is parallel to the floor (on the x axis, right shoulder at -x);
3. rotate about that line so the spine (shoulder midpoint -> pelvis) points straight down;
4. read the angles from the right arm's vectors: upper arm ``u`` (shoulder -> elbow), forearm
   ``f`` (elbow -> wrist), hand ``h`` (wrist -> hand):

   * ``theta1 = atan2(u_z, -u_y)``: the upper arm's swing in the sagittal plane from hanging
     down (0) towards the front (+pi/2) or the back (-pi/2); 0 when the arm points exactly
     sideways, where it is undefined;
   * ``theta2 = -asin(-u_x)``: the upper arm's elevation out of the sagittal plane, negative when
     it is raised outwards (-pi/2 = straight out sideways), the authors' sign;
   * ``theta3 = -angle(u, f)``: elbow flexion (0 = straight arm, -pi/2 = elbow at 90 degrees);
   * ``theta4 = -angle(f, h)``: wrist flexion.

   ``(theta1, theta2)`` are spherical coordinates of ``u``, so the arm direction can be rebuilt
   from them (:func:`upper_arm_direction`).

Deviations from the authors' code (kept behind ``paper_compat=True``):

* their shoulder rotation matrix is multiplied by -1, a point reflection (det = -1): it mirrors
  the body, and because their rotation is the identity when the vectors are already (anti)
  parallel, whether a pose comes out mirrored depends on noise. We use proper rotations: one
  orthonormal body frame (shoulder line exact, spine orthogonalised against it);
* their second angle compares the (y, z) projection with (0, -1) (the code computes the (x, y)
  projection and then does not use it), so it only mirrors the first; ours is the elevation;
* their first angle is unsigned (arm forward and arm backward both give +pi/2);
* their ``arccos`` is not clipped, so rounding can give NaN;
* the hand point: the thesis uses the tip of the right middle finger of the SMPL mesh (45-joint
  index 42); without the SMPL model files the skeleton's hand joint (23) is used.
  :func:`smplx_fingertip_joints` uses ``smplx`` when a user has the model files.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

JOINT_NAMES: tuple[str, ...] = (
    "pelvis", "left_hip", "right_hip", "spine1", "left_knee", "right_knee", "spine2",
    "left_ankle", "right_ankle", "spine3", "left_foot", "right_foot", "neck", "left_collar",
    "right_collar", "head", "left_shoulder", "right_shoulder", "left_elbow", "right_elbow",
    "left_wrist", "right_wrist", "left_hand", "right_hand",
)  # fmt: skip
"""The 24 joints, in SMPL's order."""
PARENTS: tuple[int, ...] = (
    -1, 0, 0, 0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 9, 9, 12, 13, 14, 16, 17, 18, 19, 20, 21,
)  # fmt: skip
"""Parent of each joint (SMPL's kinematic tree); -1 for the root."""
J = {name: i for i, name in enumerate(JOINT_NAMES)}
PELVIS, L_SHOULDER, R_SHOULDER = J["pelvis"], J["left_shoulder"], J["right_shoulder"]
R_ELBOW, R_WRIST, R_HAND = J["right_elbow"], J["right_wrist"], J["right_hand"]

# Rest (T-pose) joint positions in metres: the project's own average-adult proportions.
REST_JOINTS = np.array([
    [0.000, 0.950, 0.000],    # pelvis
    [0.085, 0.870, -0.005],   # left_hip
    [-0.085, 0.870, -0.005],  # right_hip
    [0.000, 1.060, -0.015],   # spine1
    [0.095, 0.490, 0.000],    # left_knee
    [-0.095, 0.490, 0.000],   # right_knee
    [0.000, 1.190, -0.010],   # spine2
    [0.090, 0.080, -0.035],   # left_ankle
    [-0.090, 0.080, -0.035],  # right_ankle
    [0.000, 1.250, 0.000],    # spine3
    [0.110, 0.020, 0.100],    # left_foot
    [-0.110, 0.020, 0.100],   # right_foot
    [0.000, 1.460, -0.010],   # neck
    [0.075, 1.380, 0.000],    # left_collar
    [-0.075, 1.380, 0.000],   # right_collar
    [0.000, 1.610, 0.035],    # head
    [0.180, 1.410, 0.000],    # left_shoulder
    [-0.180, 1.410, 0.000],   # right_shoulder
    [0.445, 1.410, 0.000],    # left_elbow
    [-0.445, 1.410, 0.000],   # right_elbow
    [0.695, 1.410, 0.000],    # left_wrist
    [-0.695, 1.410, 0.000],   # right_wrist
    [0.780, 1.410, 0.000],    # left_hand
    [-0.780, 1.410, 0.000],   # right_hand
])  # fmt: skip
"""(24, 3) rest positions: T-pose, metres, y up, x = the body's left, z = forward.

The shoulders are level and straight above the pelvis and the arms lie along x, so with the
arm rotated straight down (``poses[17] = (0, 0, pi/2)``) all four angles are exactly 0."""
OFFSETS = REST_JOINTS - np.vstack([np.zeros(3), REST_JOINTS[list(PARENTS[1:])]])
"""(24, 3) bone offsets from the parent in the parent's rest frame (root: its rest position)."""


def world_rotations(local: np.ndarray) -> np.ndarray:
    """(T, 24, 3, 3) rotations relative to each joint's parent (SMPL's layout) -> world rotations."""
    world = np.empty_like(local)
    world[:, 0] = local[:, 0]
    for j in range(1, 24):
        world[:, j] = world[:, PARENTS[j]] @ local[:, j]
    return world


def local_rotations(world: np.ndarray) -> np.ndarray:
    """The inverse of :func:`world_rotations`: ``R_local[j] = R_world[parent]^T R_world[j]``."""
    local = np.empty_like(world)
    local[:, 0] = world[:, 0]
    for j in range(1, 24):
        local[:, j] = np.swapaxes(world[:, PARENTS[j]], -1, -2) @ world[:, j]
    return local


def forward_kinematics(
    poses: np.ndarray,
    trans: np.ndarray | None = None,
    scaling: float | np.ndarray = 1.0,
    rest_joints: np.ndarray | None = None,
) -> np.ndarray:
    """Joint positions of the project's skeleton for SMPL pose parameters.

    Args:
        poses: (T, 72) or (T, 24, 3) axis-angle rotations, SMPL's layout (joint 0 = global
            orientation, each other joint relative to its parent).
        trans: (T, 3) root translation (AIST++ ``smpl_trans``), or None.
        scaling: body scale (AIST++ ``smpl_scaling``); positions are
            ``scaling * fk(poses) + trans``, the AIST++ convention.
        rest_joints: (24, 3) rest positions; default :data:`REST_JOINTS`.

    Returns:
        (T, 24, 3) float64 joint positions.
    """
    from scipy.spatial.transform import Rotation

    poses = np.asarray(poses, dtype=np.float64)
    if poses.ndim == 2 and poses.shape[1] == 72:
        poses = poses.reshape(-1, 24, 3)
    if poses.ndim != 3 or poses.shape[1:] != (24, 3):
        raise ValueError(
            f"forward_kinematics expects poses of shape (T, 72) or (T, 24, 3), got {poses.shape}."
        )
    T = poses.shape[0]
    rest = REST_JOINTS if rest_joints is None else np.asarray(rest_joints, dtype=np.float64)
    offsets = rest - np.vstack([np.zeros(3), rest[list(PARENTS[1:])]])
    glob = world_rotations(
        Rotation.from_rotvec(poses.reshape(-1, 3)).as_matrix().reshape(T, 24, 3, 3)
    )
    pos = np.empty((T, 24, 3))
    pos[:, 0] = offsets[0]
    for j in range(1, 24):
        p = PARENTS[j]
        pos[:, j] = pos[:, p] + glob[:, p] @ offsets[j]
    # The global orientation turns the body about the root joint (pos[:, 0]), as in SMPL.
    out = np.asarray(scaling, dtype=np.float64).reshape(-1, 1, 1) * pos
    if trans is not None:
        trans = np.asarray(trans, dtype=np.float64)
        if trans.shape != (T, 3):
            raise ValueError(f"trans must have shape ({T}, 3) to match poses, got {trans.shape}.")
        out = out + trans[:, None, :]
    return out


def _unit(v: np.ndarray, what: str) -> np.ndarray:
    n = np.linalg.norm(v, axis=-1, keepdims=True)
    if np.any(n < 1e-9):
        bad = np.flatnonzero(n.reshape(-1) < 1e-9)[:5]
        raise ValueError(f"Degenerate pose: the {what} has zero length in frame(s) {bad.tolist()}.")
    return v / n


def body_frame(joints: np.ndarray) -> np.ndarray:
    """(T, 3, 3) rotations whose rows are the body's axes: x to its left, y up the spine, z forward.

    The shoulder line fixes x exactly; y is the shoulder-midpoint-minus-pelvis direction with
    its x component removed; z = x cross y. Each matrix is a proper rotation (det +1), so applying
    it never mirrors the body.
    """
    x = _unit(joints[:, L_SHOULDER] - joints[:, R_SHOULDER], "shoulder line")
    mid = 0.5 * (joints[:, L_SHOULDER] + joints[:, R_SHOULDER])
    up = mid - joints[:, PELVIS]
    up = up - np.sum(up * x, axis=-1, keepdims=True) * x
    y = _unit(up, "spine (orthogonal to the shoulder line)")
    z = np.cross(x, y)
    return np.stack([x, y, z], axis=1)


def align_skeleton(joints: np.ndarray) -> np.ndarray:
    """Centre on the shoulder midpoint and rotate into the body frame (Fig 6.2, steps 1-3).

    Returns (T, 24, 3): shoulders on the x axis (right shoulder at -x), spine pointing down
    (-y, up to a sideways lean), the body facing +z.
    """
    joints = _check_joints(joints)
    mid = 0.5 * (joints[:, L_SHOULDER] + joints[:, R_SHOULDER])
    R = body_frame(joints)
    return np.einsum("tij,tkj->tki", R, joints - mid[:, None, :])


def _angle(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    cos = np.sum(a * b, axis=-1) / (np.linalg.norm(a, axis=-1) * np.linalg.norm(b, axis=-1))
    return np.arccos(np.clip(cos, -1.0, 1.0))


def _check_joints(joints: np.ndarray) -> np.ndarray:
    joints = np.asarray(joints, dtype=np.float64)
    if joints.ndim == 2:
        joints = joints[None]
    if joints.ndim != 3 or joints.shape[1] < 24 or joints.shape[2] != 3:
        raise ValueError(
            f"Expected joints of shape (T, 24, 3) in the order of JOINT_NAMES (SMPL's), got {joints.shape}."
        )
    if not np.all(np.isfinite(joints[:, :24])):
        bad = np.flatnonzero(~np.all(np.isfinite(joints[:, :24]), axis=(1, 2)))
        raise ValueError(
            f"joints hold NaN/inf in {bad.size} frame(s) (first: {bad[:5].tolist()}); drop or "
            "interpolate them first (readers.interpolate_missing_frames)."
        )
    return joints


def pose_to_ur3_angles(
    joints: np.ndarray, paper_compat: bool = False, hand: np.ndarray | None = None
) -> np.ndarray:
    """The four UR3 joint angles of the right arm, in radians.

    Args:
        joints: (T, 24, 3) joint positions (order :data:`JOINT_NAMES`), any units, any global
            position and orientation.
        paper_compat: reproduce the authors' computation (reflection, their angles 1 and 2,
            unclipped arccos; see the module docstring).
        hand: (T, 3) end point of the hand vector, e.g. the middle fingertip from
            :func:`smplx_fingertip_joints`; default the hand joint (23).

    Returns:
        (T, 4) float32: ``theta1`` in (-pi, pi], ``theta2`` in [-pi/2, pi/2], ``theta3`` and
        ``theta4`` in [-pi, 0].

    >>> poses = np.zeros((2, 24, 3))
    >>> poses[:, 17] = [0, 0, np.pi / 2]  # right arm from the T-pose straight down
    >>> poses[1, 19] = [0, np.pi / 2, 0]  # ... and the elbow bent 90 degrees forwards
    >>> (np.degrees(pose_to_ur3_angles(forward_kinematics(poses))).round(1) + 0.0).tolist()
    [[0.0, 0.0, 0.0, 0.0], [0.0, 0.0, -90.0, 0.0]]
    """
    joints = _check_joints(joints)
    if hand is None:
        hand_pt = joints[:, R_HAND]
    else:
        hand_pt = np.asarray(hand, dtype=np.float64).reshape(-1, 3)
        if hand_pt.shape[0] != joints.shape[0]:
            raise ValueError(f"hand must have shape ({joints.shape[0]}, 3), got {np.shape(hand)}.")
    if paper_compat:
        return _paper_angles(joints, hand_pt)
    mid = 0.5 * (joints[:, L_SHOULDER] + joints[:, R_SHOULDER])
    R = body_frame(joints)

    def body(p: np.ndarray) -> np.ndarray:
        return np.einsum("tij,tj->ti", R, p - mid)

    sh, el, wr, hd = (
        body(joints[:, R_SHOULDER]),
        body(joints[:, R_ELBOW]),
        body(joints[:, R_WRIST]),
        body(hand_pt),
    )
    u = _unit(el - sh, "upper arm")
    f = _unit(wr - el, "forearm")
    h = _unit(hd - wr, "hand")
    sagittal = np.hypot(u[:, 1], u[:, 2])
    # theta1 is undefined for an arm pointing exactly sideways; call it 0 there
    theta1 = np.where(sagittal > 1e-6, np.arctan2(u[:, 2], -u[:, 1]), 0.0)
    theta2 = -np.arcsin(np.clip(-u[:, 0], -1.0, 1.0))
    theta3 = -_angle(u, f)
    theta4 = -_angle(f, h)
    return np.stack([theta1, theta2, theta3, theta4], axis=1).astype(np.float32)


def upper_arm_direction(theta1: np.ndarray, theta2: np.ndarray) -> np.ndarray:
    """Inverse of the first two angles: the unit upper-arm vector in the body frame.

    ``u = (sin(theta2), -cos(theta2) cos(theta1), cos(theta2) sin(theta1))``.
    """
    t1, t2 = np.asarray(theta1, dtype=np.float64), np.asarray(theta2, dtype=np.float64)
    return np.stack([np.sin(t2), -np.cos(t2) * np.cos(t1), np.cos(t2) * np.sin(t1)], axis=-1)


def _rotation_between(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """The authors' Rodrigues rotation taking a onto b (identity when nearly (anti)parallel)."""
    a = a / np.linalg.norm(a)
    b = b / np.linalg.norm(b)
    v = np.cross(a, b)
    c = float(np.dot(a, b))
    s = float(np.linalg.norm(v))
    if s < 1e-12:
        return np.eye(3)
    K = np.array([[0, -v[2], v[1]], [v[2], 0, -v[0]], [-v[1], v[0], 0]])
    return np.eye(3) + K + K @ K * ((1 - c) / s**2)


def _paper_angles(joints: np.ndarray, hand: np.ndarray) -> np.ndarray:
    """The authors' computation, frame by frame (reflection and all), for ``paper_compat``."""
    out = np.empty((joints.shape[0], 4))
    with np.errstate(invalid="ignore", divide="ignore"):
        for t in range(joints.shape[0]):
            k = np.stack([joints[t, PELVIS], joints[t, L_SHOULDER], joints[t, R_SHOULDER],
                          joints[t, R_ELBOW], joints[t, R_WRIST], hand[t]])  # fmt: skip
            k = k - 0.5 * (k[1] + k[2])
            k = k @ (-_rotation_between(k[2], np.array([1.0, 0, 0]))).T  # the reflection
            k = k @ _rotation_between(k[0], np.array([0, -1.0, 0])).T
            u = (k[3] - k[2]) / np.linalg.norm(k[3] - k[2])
            f = (k[4] - k[3]) / np.linalg.norm(k[4] - k[3])
            h = (k[5] - k[4]) / np.linalg.norm(k[5] - k[4])

            def ang(a, b):  # unclipped, as in the original
                return np.arccos(np.dot(a, b) / (np.linalg.norm(a) * np.linalg.norm(b)))

            yz = np.array([u[1], u[2]])
            out[t] = [
                ang(yz, np.array([-1.0, 0])),
                -ang(yz, np.array([0, -1.0])),
                -ang(u, f),
                -ang(f, h),
            ]
    return out.astype(np.float32)


def smplx_fingertip_joints(
    model_path: str,
    poses: np.ndarray,
    trans: np.ndarray | None = None,
    scaling: float = 1.0,
    gender: str = "male",
) -> np.ndarray:  # pragma: no cover - needs the SMPL model files, which cannot be shipped
    """(T, 45, 3) SMPL joints with fingertips from the real SMPL model (needs ``smplx`` + files).

    Index 42 is the right middle fingertip the thesis used as the hand point:
    ``pose_to_ur3_angles(j[:, :24], hand=j[:, 42])``.
    """
    try:
        import smplx
        import torch
    except ImportError as e:
        raise ImportError(
            "smplx_fingertip_joints needs 'pip install smplx' and the SMPL model files."
        ) from e
    poses_t = torch.as_tensor(np.asarray(poses, dtype=np.float32).reshape(-1, 72))
    model = smplx.SMPL(model_path=model_path, gender=gender.upper(), batch_size=poses_t.shape[0])
    out = model(global_orient=poses_t[:, :3], body_pose=poses_t[:, 3:],
                transl=None if trans is None else torch.as_tensor(np.asarray(trans, np.float32) / scaling))  # fmt: skip
    joints = out.joints.detach().numpy() * scaling
    return joints[:, :45]


class AngleExtraction(NamedTuple):
    """The intermediate points of Fig 6.2 for one frame."""

    raw: np.ndarray  # (24, 3) input joints
    aligned: np.ndarray  # (24, 3) after centring and the two rotations
    angles: np.ndarray  # (4,) radians


def explain_angle_extraction(joints_frame: np.ndarray) -> AngleExtraction:
    """The aligned skeleton and the angles of one (24, 3) frame, for figures."""
    j = _check_joints(np.asarray(joints_frame)[None])
    return AngleExtraction(j[0], align_skeleton(j)[0], pose_to_ur3_angles(j)[0])


def plot_angle_extraction(joints_frame: np.ndarray, ax=None, title: bool = True):
    """Draw Fig 6.2 for one skeleton frame: the raw pose, the aligned pose and the four angles.

    Args:
        joints_frame: (24, 3) joint positions.
        ax: a sequence of two 3-D matplotlib axes to draw on, or None (a new 1 x 2 figure).

    Returns:
        The matplotlib Figure.
    """
    import matplotlib.pyplot as plt

    ex = explain_angle_extraction(joints_frame)
    if ax is None:
        fig = plt.figure(figsize=(10, 4.8))
        axes = [fig.add_subplot(1, 2, i + 1, projection="3d") for i in range(2)]
    else:
        axes = list(ax)
        if len(axes) != 2:
            raise ValueError("plot_angle_extraction: ax must be two 3-D axes (raw, aligned).")
        fig = axes[0].figure
    arm = [R_SHOULDER, R_ELBOW, R_WRIST, R_HAND]
    names = ["upper arm", "forearm", "hand"]
    for a, pts, label in ((axes[0], ex.raw, "keypoints"), (axes[1], ex.aligned, "aligned")):
        # plot with y (up) drawn as the vertical axis: (x, z, y)
        for j, p in enumerate(PARENTS):
            if p >= 0:
                seg = pts[[p, j]]
                a.plot(seg[:, 0], seg[:, 2], seg[:, 1], color="0.6", lw=1.5)
        a.scatter(pts[:, 0], pts[:, 2], pts[:, 1], color="0.3", s=8)
        for (i, k), n, c in zip(
            zip(arm[:-1], arm[1:]), names, ["tab:red", "tab:orange", "tab:green"]
        ):
            seg = pts[[i, k]]
            a.plot(seg[:, 0], seg[:, 2], seg[:, 1], color=c, lw=3, label=n)
        sh = pts[[L_SHOULDER, R_SHOULDER]]
        a.plot(sh[:, 0], sh[:, 2], sh[:, 1], color="tab:blue", lw=2.5, label="shoulder line")
        sp = np.stack([0.5 * (pts[L_SHOULDER] + pts[R_SHOULDER]), pts[PELVIS]])
        a.plot(sp[:, 0], sp[:, 2], sp[:, 1], color="tab:purple", lw=2.5, ls="--", label="spine")
        c = 0.5 * (pts.min(axis=0) + pts.max(axis=0))
        r = 0.5 * np.ptp(pts, axis=0).max()
        a.set_box_aspect((1, 1, 1))
        a.view_init(elev=12, azim=-60)
        a.set_xlim(c[0] - r, c[0] + r)
        a.set_ylim(c[2] - r, c[2] + r)
        a.set_zlim(c[1] - r, c[1] + r)
        a.set_xlabel("x")
        a.set_ylabel("z")
        a.set_zlabel("y (up)")
        if title:
            a.set_title(label)
    if title:
        t1, t2, t3, t4 = np.degrees(ex.angles)
        axes[1].set_title(
            f"aligned: θ1={t1:.0f}°, θ2={t2:.0f}°, θ3={t3:.0f}°, θ4={t4:.0f}°", fontsize=9
        )
    axes[1].legend(loc="upper left", fontsize=7)
    return fig
