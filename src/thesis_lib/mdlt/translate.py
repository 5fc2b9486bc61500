"""Translate any music file into UR3 joint angles, and draw the arm dancing.

:func:`dance` = audio features (60 fps) -> the checkpoint's feature scaler -> the trained
MDLT model's autoregressive translation over the whole song -> ``(T, 4)`` angles in radians
for the first four UR3 joints (thesis 6.3.3: two shoulder joints, elbow, wrist). It backs the
command ``thesis mdlt dance --audio song.wav --checkpoint ckpt.pt --out angles.csv``.

The drawing uses the UR3's standard Denavit-Hartenberg parameters (Universal Robots' published
values), joints not given at zero; ``thesis mdlt dance`` draws the angles as ``thesis ur3 play``
maps them onto the arm, and reports how the dance fares against the UR3's joint, speed and
workspace limits.

Used in: MDLT chapter (thesis 6.5); ``thesis mdlt dance``.
"""

from __future__ import annotations

import os
from collections.abc import Callable
from pathlib import Path
from typing import NamedTuple

import numpy as np
import pandas as pd

from thesis_lib.mdlt import train  # train.load_checkpoint looked up per call (a test swaps it)
from thesis_lib.mdlt.audio import audio_features

__all__ = [
    "JOINT_COLUMNS",
    "DanceResult",
    "animate_arm",
    "dance",
    "packaged_checkpoint",
    "packaged_recording",
    "plot_angles",
    "ur3_joint_positions",
]

JOINT_COLUMNS = ("shoulder_pan", "shoulder_lift", "elbow", "wrist_1")
"""The UR3 joints the four angles drive (radians)."""

# UR3 standard DH (Universal Robots): d, a, alpha per joint
_UR3_D = np.array([0.1519, 0.0, 0.0, 0.11235, 0.08535, 0.0819])
_UR3_A = np.array([0.0, -0.24365, -0.21325, 0.0, 0.0, 0.0])
_UR3_ALPHA = np.array([np.pi / 2, 0.0, 0.0, np.pi / 2, -np.pi / 2, 0.0])


class DanceResult(NamedTuple):
    """What :func:`dance` returns."""

    angles: np.ndarray
    """``(T, 4)`` joint angles in radians, one row per audio frame."""
    times: np.ndarray
    """``(T,)`` seconds of each frame (frame ``i`` at ``i / fps``)."""
    frame: pd.DataFrame
    """``time_s`` and one column per joint (what the CSV holds)."""
    fps: int = 60
    """Frames per second of ``angles`` (the checkpoint's feature rate)."""


ASSETS = Path(__file__).resolve().parent / "assets"
"""Folder of the files shipped with the package (checkpoint, recording, their credits)."""


def _asset(name: str, what: str, hint: str = "") -> Path:
    """``ASSETS / name``, or a FileNotFoundError that says the data files are missing."""
    path = ASSETS / name
    if not path.is_file():
        raise FileNotFoundError(
            f"No packaged {what} at {path}: the package was installed without its data files."
            + hint
        )
    return path


PACKAGED_CHECKPOINT = "mdlt_packaged.pt"
"""File name of the small checkpoint shipped in ``thesis_lib/mdlt/assets`` (see the README)."""


def packaged_checkpoint() -> Path:
    """The MDLT checkpoint shipped with the package, used by :func:`dance` (and ``thesis mdlt
    dance``) when no checkpoint is given. Made by ``thesis mdlt train`` (the README says how).

    Raises:
        FileNotFoundError: The package was installed without its data files.
    """
    return _asset(
        PACKAGED_CHECKPOINT,
        "MDLT checkpoint",
        " Train one with 'thesis mdlt train --out ckpt.pt' and pass --checkpoint.",
    )


PACKAGED_RECORDING = "savino_caribbean.ogg"
"""File name of the recorded music shipped in ``thesis_lib/mdlt/assets``: Will Savino's
"Caribbean" from HyperRogue's soundtrack (CC BY-SA 3.0, Debian's ``hyperrogue-music``), the
whole 62-s track at its own 44.1 kHz, downmixed to mono and re-encoded as Ogg Vorbis. The credit
and licence are in ``assets/MUSIC.md``; :data:`PACKAGED_RECORDING_CREDIT` gives them as fields."""

PACKAGED_RECORDING_CREDIT = {
    "title": "Caribbean",
    "artist": "Will Savino",
    "licence": "CC BY-SA 3.0",
    "source": "Debian package hyperrogue-music 12.0q-1 (music/hr-savino-caribbean.ogg)",
}
"""Credit of :data:`PACKAGED_RECORDING`, as the licence requires."""


def packaged_recording() -> Path:
    """The recorded music shipped with the package (:data:`PACKAGED_RECORDING`): real music the
    book does not synthesise, for trying the translator (``thesis mdlt dance --audio``) without
    finding a file first. Nothing is downloaded.

    Raises:
        FileNotFoundError: The package was installed without its data files.
    """
    return _asset(PACKAGED_RECORDING, "recording")


def dance(
    audio: str | os.PathLike,
    checkpoint: str | os.PathLike | None = None,
    out: str | os.PathLike | None = None,
    plot: str | os.PathLike | None = None,
    animation: str | os.PathLike | None = None,
    device: str = "cpu",
    progress: bool = False,
    animation_fps: int = 15,
    max_animation_s: float | None = 30.0,
    to_joints: Callable[[np.ndarray], np.ndarray] | None = None,
) -> DanceResult:
    """Translate the music in ``audio`` into UR3 joint angles with a trained MDLT checkpoint.

    Used in: MDLT chapter (thesis 6.5); ``thesis mdlt dance``.

    Args:
        audio: Any audio file librosa reads (wav, flac, ogg, mp3 with a backend); resampled
            to the feature rate.
        checkpoint: An MDLT checkpoint carrying its feature scaler
            (:func:`thesis_lib.mdlt.train.load_checkpoint`); ``None``: the packaged one
            (:func:`packaged_checkpoint`).
        out: Write the angles as CSV (``time_s`` + one column per joint, radians).
        plot: Write a PNG of the four angle curves.
        animation: Write the arm's motion as a GIF (``.gif``) or an HTML5 page (``.html``).
        device: Torch device.
        progress: Show a progress bar over the frames.
        animation_fps: Frames per second of the animation (the angles are subsampled).
        max_animation_s: Animate at most this many seconds (``None``: the whole song).
        to_joints: Maps the ``(T, 4)`` angles to the UR3 joint angles ``(T, 4..6)`` the
            animation draws. ``thesis mdlt dance`` passes
            :func:`thesis_lib.ur3.dance.map_dance`, so the arm is drawn in the pose
            ``thesis ur3 play`` plays (its offsets, halved swings and fixed wrist); ``None``:
            the raw angles on the first four joints. The CSV and the plot hold the raw angles.

    Raises:
        FileNotFoundError: Missing audio or checkpoint.
        ValueError: An unusable ``device`` or ``animation`` suffix (both checked before any
            work), unreadable/silent audio, or a checkpoint that is not MDLT's.
    """
    train.check_device(device)  # the cheap checks first: nothing is computed or written before them
    if animation is not None:
        _check_animation_path(animation)
    audio = Path(audio)
    if not audio.is_file():
        raise FileNotFoundError(f"No audio file at '{audio}'.")
    if checkpoint is None:
        checkpoint = packaged_checkpoint()
    model, scaler, meta = train.load_checkpoint(checkpoint, device=device)
    fps = int(meta.get("fps", 60))
    feats = scaler.transform(audio_features(audio, fps=fps))
    angles = np.asarray(model.generate(feats, progress=progress), dtype=np.float64)
    times = np.arange(len(angles)) / fps
    frame = pd.DataFrame(
        {"time_s": times, **{c: angles[:, j] for j, c in enumerate(JOINT_COLUMNS)}}
    )
    if out is not None:
        Path(out).parent.mkdir(parents=True, exist_ok=True)
        frame.to_csv(out, index=False, float_format="%.6f")
    if plot is not None:
        import matplotlib.pyplot as plt

        fig = plot_angles(angles, fps=fps, title=f"{audio.name} -> UR3 joint angles")
        fig.savefig(plot, dpi=110, bbox_inches="tight")
        plt.close(fig)
    if animation is not None:
        animate_arm(
            angles if to_joints is None else to_joints(angles),
            fps=fps,
            path=animation,
            animation_fps=animation_fps,
            max_seconds=max_animation_s,
        )
    return DanceResult(angles, times, frame, fps)


def plot_angles(
    angles: np.ndarray, fps: int = 60, true: np.ndarray | None = None, title: str = "", axes=None
):
    """Four stacked curves of joint angle (rad) against time; ``true`` drawn dashed beside.

    Used in: MDLT chapter (thesis 6.5).
    """
    import matplotlib.pyplot as plt

    angles = np.asarray(angles)
    t = np.arange(len(angles)) / fps
    if axes is None:
        fig, axes = plt.subplots(
            angles.shape[1], 1, figsize=(8, 1.6 * angles.shape[1]), sharex=True
        )
    else:
        fig = np.ravel(axes)[0].figure
    for j, ax in enumerate(np.ravel(axes)):
        ax.plot(t, angles[:, j], lw=1.2, label="predicted")
        if true is not None:
            ax.plot(t, np.asarray(true)[:, j], lw=1.0, ls="--", color="k", alpha=0.7, label="true")
        ax.set_ylabel(f"{JOINT_COLUMNS[j]}\n(rad)" if j < len(JOINT_COLUMNS) else f"q{j + 1}")
    np.ravel(axes)[-1].set_xlabel("time (s)")
    if true is not None:
        np.ravel(axes)[0].legend(loc="upper right", fontsize=8)
    if title:
        fig.suptitle(title)
    return fig


def ur3_joint_positions(q: np.ndarray) -> np.ndarray:
    """Positions of the UR3's base and joint frames for angles ``q (..., 4..6)`` (missing = 0).

    Returns ``(..., 7, 3)`` metres: base, then the origin of each of the six DH frames.

    Example:
        >>> p = ur3_joint_positions(np.zeros(4))
        >>> p.shape, np.round(p[-1], 4).tolist()   # arm stretched out along -x at zero angles
        ((7, 3), [-0.4569, -0.1943, 0.0666])
    """
    q = np.asarray(q, dtype=np.float64)
    lead = q.shape[:-1]
    full = np.zeros(lead + (6,))
    full[..., : q.shape[-1]] = q[..., :6]
    T = np.broadcast_to(np.eye(4), lead + (4, 4)).copy()
    points = [T[..., :3, 3].copy()]
    for i in range(6):
        ct, st = np.cos(full[..., i]), np.sin(full[..., i])
        ca, sa = np.cos(_UR3_ALPHA[i]), np.sin(_UR3_ALPHA[i])
        A = np.zeros(lead + (4, 4))
        A[..., 0, 0], A[..., 0, 1], A[..., 0, 2], A[..., 0, 3] = (
            ct,
            -st * ca,
            st * sa,
            _UR3_A[i] * ct,
        )
        A[..., 1, 0], A[..., 1, 1], A[..., 1, 2], A[..., 1, 3] = (
            st,
            ct * ca,
            -ct * sa,
            _UR3_A[i] * st,
        )
        A[..., 2, 1], A[..., 2, 2], A[..., 2, 3] = sa, ca, _UR3_D[i]
        A[..., 3, 3] = 1.0
        T = T @ A
        points.append(T[..., :3, 3].copy())
    return np.stack(points, axis=-2)


#: the animation formats :func:`animate_arm` writes, by file suffix.
ANIMATION_SUFFIXES = (".gif", ".html", ".htm")


def _check_animation_path(path: str | os.PathLike) -> None:
    suffix = Path(path).suffix.lower()
    if suffix not in ANIMATION_SUFFIXES:
        raise ValueError(f"Expect `animation` to end in .gif or .html, actually: '{path}'.")


def animate_arm(
    angles: np.ndarray,
    fps: int = 60,
    path: str | os.PathLike | None = None,
    animation_fps: int = 15,
    max_seconds: float | None = 30.0,
    true: np.ndarray | None = None,
):
    """A matplotlib animation of the UR3 arm following ``angles (T, 4..6)`` (joint angles, the
    missing ones at zero: :func:`ur3_joint_positions`); saved when ``path`` is given (``.gif``
    with Pillow, ``.html`` as a self-contained HTML5/JS player).

    ``true``: also draw the ground-truth arm (grey). Returns the ``FuncAnimation`` (in a
    notebook: ``IPython.display.HTML(anim.to_jshtml())``).

    Used in: MDLT chapter (thesis 6.5); ``thesis mdlt dance --animation``.
    """
    import matplotlib.pyplot as plt
    from matplotlib.animation import FuncAnimation, PillowWriter

    if path is not None:
        _check_animation_path(path)
    angles = np.asarray(angles)
    step = max(1, int(round(fps / animation_fps)))
    n = len(angles) if max_seconds is None else min(len(angles), int(max_seconds * fps))
    idx = np.arange(0, max(n, 1), step)
    pts = ur3_joint_positions(angles[idx])  # (F, 7, 3)
    true_pts = ur3_joint_positions(np.asarray(true)[idx]) if true is not None else None
    fig = plt.figure(figsize=(4.2, 4.2))
    ax = fig.add_subplot(projection="3d")
    reach = 0.55
    ax.set(
        xlim=(-reach, reach),
        ylim=(-reach, reach),
        zlim=(0, 2 * reach),
        xlabel="x (m)",
        ylabel="y (m)",
        zlabel="z (m)",
    )
    ax.view_init(elev=20, azim=-60)
    ghost = (
        ax.plot([], [], [], "o-", color="0.6", lw=3, alpha=0.6, label="true")[0]
        if true is not None
        else None
    )
    (line,) = ax.plot([], [], [], "o-", color="tab:blue", lw=4, label="predicted")
    label = ax.text2D(0.02, 0.95, "", transform=ax.transAxes)
    if ghost is not None:
        ax.legend(loc="upper right", fontsize=8)

    def update(k):
        p = pts[k]
        line.set_data(p[:, 0], p[:, 1])
        line.set_3d_properties(p[:, 2])
        if ghost is not None:
            g = true_pts[k]
            ghost.set_data(g[:, 0], g[:, 1])
            ghost.set_3d_properties(g[:, 2])
        label.set_text(f"t = {idx[k] / fps:5.2f} s")
        return (line, label) if ghost is None else (line, ghost, label)

    anim = FuncAnimation(fig, update, frames=len(idx), interval=1000 / animation_fps, blit=False)
    if path is not None:
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        if path.suffix.lower() == ".gif":
            anim.save(path, writer=PillowWriter(fps=animation_fps))
        else:  # .html or .htm (checked above)
            path.write_text(anim.to_jshtml(fps=animation_fps))
        plt.close(fig)
    return anim
