"""A 3-D viewer of the UR3 playing a trajectory: a meshcat scene exported as static HTML.

:func:`trajectory_html` builds the MJCF model's geometry in a meshcat scene, records one
meshcat animation frame per trajectory frame (each link's pose from MuJoCo's forward
kinematics), and returns meshcat's ``static_html()``: one self-contained HTML file (three.js
and the scene inlined, about 1 MB, nothing fetched from the network) in which the reader can
rotate, zoom and replay the dancing arm. :func:`iframe` wraps it for a notebook output, so the
built book carries the viewer.

meshcat's export runs through its local ZeroMQ server, which this module starts as a
subprocess on a free localhost port and stops when done; no browser is needed.

Used in: UR3 deployment chapter (dance viewer).
"""

from __future__ import annotations

import contextlib
import html as _html
import io
from pathlib import Path

import numpy as np

from .model import load_model

__all__ = ["iframe", "save_html", "trajectory_html"]


def _color(rgba: np.ndarray) -> int:
    r, g, b = (np.clip(rgba[:3], 0, 1) * 255).astype(int)
    return int(r) << 16 | int(g) << 8 | int(b)


def _geom_objects(model):
    """(body id, name, meshcat geometry, local 4x4 transform, colour) of every drawable geom."""
    import meshcat.geometry as g
    import mujoco

    out = []
    to_y = np.array(
        [[1, 0, 0, 0], [0, 0, -1, 0], [0, 1, 0, 0], [0, 0, 0, 1.0]]
    )  # three.js cylinders run along y
    for i in range(model.ngeom):
        gtype, size = model.geom_type[i], model.geom_size[i]
        T = np.eye(4)
        T[:3, 3] = model.geom_pos[i]
        R = np.zeros(9)
        mujoco.mju_quat2Mat(R, model.geom_quat[i])
        T[:3, :3] = R.reshape(3, 3)
        color = _color(model.geom_rgba[i])
        body = int(model.geom_bodyid[i])
        if gtype == mujoco.mjtGeom.mjGEOM_CYLINDER:
            out.append((body, f"g{i}", g.Cylinder(2 * size[1], size[0]), T @ to_y, color))
        elif gtype == mujoco.mjtGeom.mjGEOM_CAPSULE:
            out.append((body, f"g{i}", g.Cylinder(2 * size[1], size[0]), T @ to_y, color))
            for k, sgn in (("a", 1), ("b", -1)):
                E = np.eye(4)
                E[2, 3] = sgn * size[1]
                out.append((body, f"g{i}{k}", g.Sphere(size[0]), T @ E, color))
        elif gtype == mujoco.mjtGeom.mjGEOM_PLANE:
            out.append((body, f"g{i}", g.Box([1.2, 1.2, 0.002]), T, 0xDDDDDD))
    return out


def _body_pose(data, b: int) -> np.ndarray:
    T = np.eye(4)
    T[:3, :3] = data.xmat[b].reshape(3, 3)
    T[:3, 3] = data.xpos[b]
    return T


def trajectory_html(
    q: np.ndarray, fps: float = 30.0, max_frames: int = 600, title: str | None = None
) -> str:
    """A self-contained HTML page with the UR3 playing ``q (T, 6)`` at ``fps``, looping.

    Args:
        q: joint angles (rad), one row per frame.
        fps: playback rate of ``q``.
        max_frames: longer trajectories are subsampled evenly to at most this many frames
            (the animation is stored in the page; the frame rate is lowered to match).
        title: optional text shown above the scene.

    Returns:
        The HTML text (meshcat's ``static_html``).

    Raises:
        ImportError: meshcat is not installed (``pip install meshcat==0.3.2``).

    Used in: UR3 deployment chapter.
    """
    try:
        import meshcat
        import meshcat.geometry as g
        from meshcat.animation import Animation
    except ImportError as err:  # pragma: no cover - meshcat is in requirements.txt
        raise ImportError("The 3-D viewer needs meshcat: pip install meshcat==0.3.2") from err
    import mujoco

    q = np.atleast_2d(np.asarray(q, dtype=np.float64))
    if q.ndim != 2 or q.shape[1] != 6 or not np.all(np.isfinite(q)):
        raise ValueError(f"Expect finite joint angles of shape (T, 6), got {q.shape}.")
    if fps <= 0:
        raise ValueError(f"Expect fps > 0, got {fps}.")
    stride = max(1, int(np.ceil(len(q) / max_frames)))
    q, fps = q[::stride], fps / stride
    model = load_model()
    data = mujoco.MjData(model)
    with contextlib.redirect_stdout(io.StringIO()):  # meshcat prints its local URL
        vis = meshcat.Visualizer()
    try:
        bodies = sorted({b for b, *_ in _geom_objects(model)})
        for b, name, geom, T, color in _geom_objects(model):
            node = vis["ur3"][f"body{b}"][name]
            node.set_object(geom, g.MeshLambertMaterial(color=color))
            node.set_transform(T)
        anim = Animation(default_framerate=max(1, int(round(fps))))
        for k, x in enumerate(q):
            data.qpos[:] = x
            mujoco.mj_kinematics(model, data)
            with anim.at_frame(vis, k) as frame:
                for b in bodies:
                    frame["ur3"][f"body{b}"].set_transform(_body_pose(data, b))
        # the first frame's pose also as the static pose (shown before the animation starts)
        data.qpos[:] = q[0]
        mujoco.mj_kinematics(model, data)
        for b in bodies:
            vis["ur3"][f"body{b}"].set_transform(_body_pose(data, b))
        vis.set_animation(anim, play=True, repetitions=0)
        page = vis.static_html()
    finally:
        proc = getattr(vis.window, "server_proc", None)
        if proc is not None:
            proc.kill()
            proc.wait()
    if title:
        page = page.replace(
            "<body>",
            f'<body><div style="position:absolute;z-index:10;font:14px sans-serif;'
            f'padding:4px">{_html.escape(title)}</div>',
            1,
        )
    return page


def save_html(page: str, path: str | Path) -> Path:
    """Write ``page`` to ``path`` (creating folders)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(page, encoding="utf-8")
    return path


def iframe(page: str, height: int = 420):
    """An ``IPython.display.HTML`` holding ``page`` in an ``<iframe srcdoc>`` (works in the built book, offline)."""
    import warnings

    from IPython.display import HTML

    doc = _html.escape(page, quote=True)
    with (
        warnings.catch_warnings()
    ):  # IPython suggests IFrame, which needs a URL; srcdoc keeps it in the page
        warnings.filterwarnings("ignore", message="Consider using IPython.display.IFrame")
        return HTML(
            f'<iframe srcdoc="{doc}" style="width:100%;height:{int(height)}px;border:1px solid #ccc" '
            f'title="UR3 3-D viewer"></iframe>'
        )
