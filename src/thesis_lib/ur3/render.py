"""Pictures of the UR3 model: MuJoCo offscreen frames, a matplotlib fallback, a GIF writer.

:func:`render_frames` renders joint configurations with MuJoCo's offscreen renderer when an
OpenGL context can be had (set ``MUJOCO_GL=egl`` before importing MuJoCo on a headless
machine) and falls back to a matplotlib drawing of the arm's DH skeleton otherwise, so the
chapter runs everywhere. :func:`plot_arm` draws one configuration into a 3-D matplotlib axis.

Used in: UR3 deployment chapter (reaching pictures, dance playback).
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Literal

import numpy as np

from .model import UR3Kinematics, load_model

__all__ = ["plot_arm", "render_frames", "save_gif"]


def plot_arm(
    ax,
    q: np.ndarray,
    color: str = "tab:blue",
    alpha: float = 1.0,
    label: str | None = None,
    kin=None,
) -> None:
    """Draw the arm at ``q (6,)`` as its DH skeleton (base → joint origins → flange) on a 3-D axis."""
    kin = kin or UR3Kinematics()
    p = kin.points(q)
    ax.plot(p[:, 0], p[:, 1], p[:, 2], "-o", color=color, alpha=alpha, lw=3, ms=3, label=label)
    ax.scatter(*p[-1], color="tab:red", s=12, alpha=alpha)


def _setup_axis(ax) -> None:
    ax.set_xlim(-0.5, 0.5), ax.set_ylim(-0.5, 0.5), ax.set_zlim(0, 0.8)
    ax.set_xlabel("x (m)"), ax.set_ylabel("y (m)"), ax.set_zlabel("z (m)")
    ax.set_box_aspect((1, 1, 0.8))


def _mpl_frames(q: np.ndarray, width: int, height: int) -> np.ndarray:
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    kin = UR3Kinematics()
    fig = Figure(figsize=(width / 100, height / 100), dpi=100)
    canvas = FigureCanvasAgg(fig)
    ax = fig.add_subplot(projection="3d")
    frames = []
    for x in q:
        ax.cla()
        _setup_axis(ax)
        ax.view_init(elev=20, azim=-60)
        plot_arm(ax, x, kin=kin)
        canvas.draw()
        frames.append(np.asarray(canvas.buffer_rgba())[..., :3].copy())
    return np.stack(frames)


def _mujoco_frames(q: np.ndarray, width: int, height: int, camera: str) -> np.ndarray:
    import mujoco

    model = load_model()
    data = mujoco.MjData(model)
    renderer = mujoco.Renderer(model, height, width)
    try:
        frames = []
        for x in q:
            data.qpos[:] = x
            mujoco.mj_kinematics(model, data)
            mujoco.mj_camlight(model, data)  # cameras and lights: mj_kinematics leaves them at zero
            renderer.update_scene(data, camera=camera)
            frames.append(renderer.render().copy())
    finally:
        renderer.close()
    return np.stack(frames)


def render_frames(
    q: np.ndarray,
    width: int = 320,
    height: int = 240,
    backend: Literal["auto", "mujoco", "matplotlib"] = "auto",
    camera: str = "front",
) -> np.ndarray:
    """``(T, height, width, 3)`` uint8 pictures of the arm at each row of ``q (T, 6)``.

    Args:
        q: joint angles (rad).
        width, height: image size (MuJoCo's offscreen buffer is 640x480 at most).
        backend: ``"mujoco"`` (offscreen OpenGL: ``MUJOCO_GL=egl`` headless), ``"matplotlib"``
            (always works), or ``"auto"``: MuJoCo when ``MUJOCO_GL`` is ``egl``/``osmesa`` or
            a display exists (and rendering works), else matplotlib.
        camera: MuJoCo camera name.

    Used in: UR3 deployment chapter.
    """
    q = np.atleast_2d(np.asarray(q, dtype=np.float64))
    if q.shape[1] != 6:
        raise ValueError(f"Expect joint angles of shape (T, 6), got {q.shape}.")
    if backend not in ("auto", "mujoco", "matplotlib"):
        raise ValueError(f"Unknown backend {backend!r}. Valid: auto, mujoco, matplotlib.")
    global _MUJOCO_FAILED
    if backend == "mujoco" or (backend == "auto" and _mujoco_can_try()):
        try:
            return _mujoco_frames(q, width, height, camera)
        except Exception as err:
            _MUJOCO_FAILED = True  # a second failed context can take the process down: never retry
            if backend == "mujoco":
                raise RuntimeError(
                    f"MuJoCo cannot render here ({err}). On a headless machine set MUJOCO_GL=egl (or osmesa) "
                    "before importing mujoco, or use backend='matplotlib'."
                ) from err
    return _mpl_frames(q, width, height)


_MUJOCO_FAILED = False


def _mujoco_can_try() -> bool:
    """``auto`` tries MuJoCo only with a headless GL backend chosen (``MUJOCO_GL=egl|osmesa``) or a display.

    Without either, MuJoCo would try GLFW, which fails (and a repeated failure can crash the process).
    """
    if _MUJOCO_FAILED:
        return False
    gl = os.environ.get("MUJOCO_GL", "").lower()
    return gl in ("egl", "osmesa") or (gl in ("", "glfw") and bool(os.environ.get("DISPLAY")))


def mujoco_gl() -> str | None:
    """The ``MUJOCO_GL`` setting in force (``None``: MuJoCo's default, GLFW, which needs a display)."""
    return os.environ.get("MUJOCO_GL")


def save_gif(frames: np.ndarray, path: str | Path, fps: float = 15.0) -> Path:
    """Write ``(T, H, W, 3)`` uint8 frames as a looping GIF (Pillow)."""
    from PIL import Image

    frames = np.asarray(frames)
    if frames.ndim != 4 or frames.shape[-1] != 3:
        raise ValueError(f"Expect frames of shape (T, H, W, 3), got {frames.shape}.")
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    imgs = [Image.fromarray(f.astype(np.uint8)) for f in frames]
    imgs[0].save(
        path, save_all=True, append_images=imgs[1:], duration=int(round(1000 / fps)), loop=0
    )
    return path
