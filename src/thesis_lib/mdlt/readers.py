"""Readers for the AIST++ and PhantomDance file layouts (thesis 6.3.1).

Both return :class:`DanceSequence` objects: raw audio features (T, 438) and the four UR3 joint
angles (T, 4), synchronised frame by frame (6.3.4). The default offline data sets of
:mod:`thesis_lib.mdlt.synth` are written in the same layouts, so these readers are what load
them; point ``root`` at a real download and the same code runs.

**AIST++** (``root`` = the annotations folder; music from the AIST Dance DB)::

    root/motions/<seq>.pkl       dict: smpl_poses (N, 72), smpl_trans (N, 3), smpl_scaling (1,)
    root/keypoints3d/<seq>.pkl   dict: keypoints3d (N, 17, 3) COCO-17 (optional; source="keypoints3d")
    root/keypoints2d/<seq>.pkl   dict: timestamps (N,) in microseconds (keypoints2d itself unused)
    root/splits/crossmodal_{train,val,test}.txt   sequence names (optional)
    root/ignore_list.txt         sequences to skip (optional)
    <audio_dir>/mXX#.wav         music; audio_dir defaults to the first of root/{wav,wavs,music,audio}

Sequence names look like ``gBR_sBM_cAll_d04_mBR0_ch01``: music ``mBR0`` (genre ``mBR``),
dancer ``d04``. As the thesis did, one sequence per music is kept (the first by name, after the
ignore list); ``all_sequences=True`` keeps every one.

**PhantomDance** (``root`` = e.g. ``PhantomDanceDatav1.1``)::

    root/motion/<name>.json   bone_name [B], root_positions (N, 3), rotations (N, B, 4)
    root/music/<name>.wav

30 pose frames per second; music at 16 kHz (resampled by the feature extractor). Rotations are
read as the data set's README (v1.2) defines them: **world** rotations, quaternions in
**(x, y, z, w)** order, positions and rotations in Unity3D's left-handed frame (x right, y up,
z forward). The reader mirrors them into the project's right-handed frame, turns them into
local rotations and computes joint positions with the project's skeleton
(:func:`angles.forward_kinematics`); ``quaternion_order``, ``rotations`` and ``frame`` read other
conventions (e.g. local rotations from the toolkit's conversion script; the project's previous
reader assumed local (w, x, y, z) quaternions, which on a real download gives wrong poses
without an error). The authors' code placed each bone's end at ``root + R_j (0, 0, j + 1)``,
which is not forward kinematics (``paper_compat`` does not reproduce that).

Bad input: a folder without the layout raises :class:`DatasetLayoutError` saying what was
expected; a sequence without its music raises (``skip_missing_audio=True`` skips it with a
warning); pose frames holding NaN are dropped before synchronisation, so their audio frames get
the nearest valid pose (more than half missing raises). Thesis chapter 6.
"""

from __future__ import annotations

import json
import pickle
import re
import warnings
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .angles import (
    JOINT_NAMES,
    forward_kinematics,
    local_rotations,
    pose_to_ur3_angles,
    world_rotations,
)
from .audio import cached_audio_features
from .sync import synchronize

AIST_GENRES = ("mBR", "mPO", "mLO", "mMH", "mLH", "mHO", "mWA", "mKR", "mJS", "mJB")
"""The ten AIST music genres: break, pop, lock, middle hip-hop, LA hip-hop, house, waack,
krump, street jazz, ballet jazz."""
AIST_FPS = 60
PHANTOM_FPS = 30
_SEQ_RE = re.compile(r"^g(?P<g>[A-Z]{2})_s\w+?_c\w+?_d(?P<d>\d+)_(?P<m>m[A-Z]{2}\d+)_ch\d+$")
_AUDIO_DIRS = ("wav", "wavs", "music", "audio")


class DatasetLayoutError(FileNotFoundError):
    """A folder that does not have the layout a reader expects."""


@dataclass
class DanceSequence:
    """One music-dance pair, synchronised to the audio feature frames.

    Attributes:
        name: sequence name (AIST++: ``gBR_sBM_cAll_d04_mBR0_ch01``; PhantomDance: file stem).
        music_id: the music (AIST++ ``mBR0``; PhantomDance: the file stem).
        genre: AIST++ music genre (``mBR``); PhantomDance: ``""`` unless the JSON says.
        audio_path: the music file.
        features: (T, 438) float32 raw (unscaled) audio features at ``fps``.
        angles: (T, 4) float32 UR3 joint angles in radians, frame ``i`` paired with feature ``i``.
        fps: feature (and angle) frames per second.
        joints: (T, 24, 3) float32 synchronised joint positions, or None.
        dancer: dancer id (AIST++ ``d04``), or ``""``.
        pose_index: (T,) index of the original pose frame each feature frame was paired with.
    """

    name: str
    music_id: str
    genre: str
    audio_path: Path
    features: np.ndarray
    angles: np.ndarray
    fps: int = 60
    joints: np.ndarray | None = None
    dancer: str = ""
    pose_index: np.ndarray | None = field(default=None, repr=False)

    def __post_init__(self) -> None:
        if self.features.ndim != 2 or self.angles.ndim != 2 or self.angles.shape[1] != 4:
            raise ValueError(
                f"DanceSequence {self.name}: features must be (T, D) and angles (T, 4), got "
                f"{self.features.shape} and {self.angles.shape}."
            )
        if self.features.shape[0] != self.angles.shape[0]:
            raise ValueError(
                f"DanceSequence {self.name}: {self.features.shape[0]} feature frames but "
                f"{self.angles.shape[0]} angle frames; synchronise them first."
            )

    def __len__(self) -> int:
        return int(self.features.shape[0])


# ----------------------------------------------------------------------------- helpers


def _load_pickle(path: Path) -> dict:
    try:
        with open(path, "rb") as f:
            obj = pickle.load(f)
    except Exception as e:
        raise ValueError(f"Cannot read {path} as a pickle ({type(e).__name__}: {e}).") from e
    if not isinstance(obj, dict):
        raise ValueError(f"{path}: expected a pickled dict, got {type(obj).__name__}.")
    return obj


def _read_names(path: Path) -> list[str]:
    if not path.is_file():
        return []
    return [
        ln.strip() for ln in path.read_text().splitlines() if ln.strip() and not ln.startswith("#")
    ]


def drop_missing_frames(
    joints: np.ndarray, timestamps: np.ndarray, name: str = "", max_missing: float = 0.5
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Drop pose frames holding NaN/inf (missing detections) and their timestamps.

    With nearest-timestamp synchronisation the audio frames of a dropped pose take the nearest
    valid pose, which is what a player holding the last pose would show.

    Returns:
        ``(joints, timestamps, kept_index)``.

    Raises:
        ValueError: more than ``max_missing`` of the frames are missing.
    """
    ok = np.all(np.isfinite(joints.reshape(joints.shape[0], -1)), axis=1) & np.isfinite(timestamps)
    n_bad = int((~ok).sum())
    if n_bad > max_missing * len(ok):
        raise ValueError(
            f"{name}: {n_bad} of {len(ok)} pose frames are missing (NaN); more than "
            f"{max_missing:.0%} is too many to synchronise."
        )
    if n_bad:
        warnings.warn(
            f"{name}: dropped {n_bad} pose frame(s) holding NaN; their audio frames use the nearest valid pose.",
            stacklevel=2,
        )
    idx = np.flatnonzero(ok)
    return joints[idx], timestamps[idx], idx


def coco17_to_skeleton(kp: np.ndarray) -> np.ndarray:
    """Approximate (T, 24, 3) skeleton joints from COCO-17 keypoints (AIST++ keypoints3d).

    Filled from COCO: shoulders, elbows, wrists, hips, knees, ankles; pelvis = mid-hips;
    spine/neck/collars interpolated; head = nose; hands extrapolated 30 % of the forearm past
    the wrists (COCO has no hand point, so the wrist angle theta4 is always 0 on this source).
    """
    kp = np.asarray(kp, dtype=np.float64)
    if kp.ndim != 3 or kp.shape[1:] != (17, 3):
        raise ValueError(f"COCO-17 keypoints must have shape (T, 17, 3), got {kp.shape}.")
    j = np.zeros((kp.shape[0], 24, 3))
    J = {n: i for i, n in enumerate(JOINT_NAMES)}
    coco = {"left_shoulder": 5, "right_shoulder": 6, "left_elbow": 7, "right_elbow": 8,
            "left_wrist": 9, "right_wrist": 10, "left_hip": 11, "right_hip": 12, "left_knee": 13,
            "right_knee": 14, "left_ankle": 15, "right_ankle": 16, "head": 0}  # fmt: skip
    for n, c in coco.items():
        j[:, J[n]] = kp[:, c]
    pelvis = 0.5 * (kp[:, 11] + kp[:, 12])
    neck = 0.5 * (kp[:, 5] + kp[:, 6])
    j[:, J["pelvis"]] = pelvis
    for n, a in (("spine1", 0.25), ("spine2", 0.5), ("spine3", 0.75)):
        j[:, J[n]] = pelvis + a * (neck - pelvis)
    j[:, J["neck"]] = neck
    j[:, J["left_collar"]] = 0.5 * (neck + kp[:, 5])
    j[:, J["right_collar"]] = 0.5 * (neck + kp[:, 6])
    j[:, J["left_foot"]] = kp[:, 15]
    j[:, J["right_foot"]] = kp[:, 16]
    j[:, J["left_hand"]] = kp[:, 9] + 0.3 * (kp[:, 9] - kp[:, 7])
    j[:, J["right_hand"]] = kp[:, 10] + 0.3 * (kp[:, 10] - kp[:, 8])
    return j


def _find_audio_dir(root: Path, audio_dir: str | Path | None) -> Path:
    if audio_dir is not None:
        d = Path(audio_dir)
        if not d.is_dir():
            raise DatasetLayoutError(f"audio_dir {d} is not a folder.")
        return d
    for name in _AUDIO_DIRS:
        if (root / name).is_dir():
            return root / name
    raise DatasetLayoutError(
        f"No music folder under {root} (looked for {', '.join(_AUDIO_DIRS)}). AIST++ annotations "
        "do not contain the music: download it from the AIST Dance DB and pass "
        "audio_dir=<folder with mBR0.wav ...>."
    )


def _progress(it: Iterable, total: int, desc: str, progress: bool):
    if not progress:
        return it
    from tqdm.auto import tqdm

    return tqdm(it, total=total, desc=desc, leave=False)


# ----------------------------------------------------------------------------- AIST++


def parse_aist_name(name: str) -> dict[str, str]:
    """``gBR_sBM_cAll_d04_mBR0_ch01`` -> ``{'genre': 'mBR', 'music_id': 'mBR0', 'dancer': 'd04'}``.

    >>> parse_aist_name("gBR_sBM_cAll_d04_mBR0_ch01")["music_id"]
    'mBR0'
    """
    m = _SEQ_RE.match(name)
    if not m:
        raise ValueError(
            f"'{name}' is not an AIST++ sequence name (expected e.g. gBR_sBM_cAll_d04_mBR0_ch01)."
        )
    return {"genre": m["m"][:3], "music_id": m["m"], "dancer": f"d{m['d']}"}


def list_aist_sequences(root: str | Path, all_sequences: bool = False) -> list[str]:
    """Sequence names the AIST++ reader loads, in order (see :func:`load_aist`)."""
    root = Path(root)
    if not root.is_dir():
        raise FileNotFoundError(f"No AIST++ folder at {root}.")
    motions = root / "motions"
    if not motions.is_dir():
        raise DatasetLayoutError(
            f"{root} does not have the AIST++ layout: no 'motions/' folder. Expected "
            "motions/*.pkl, keypoints2d/*.pkl (timestamps), splits/, ignore_list.txt and the "
            "music (wav/mXX#.wav). Point root at the AIST++ annotations folder, or create the "
            "default set with thesis_lib.mdlt.synth.default_dataset('aist')."
        )
    available = sorted(p.stem for p in motions.glob("*.pkl"))
    if not available:
        raise DatasetLayoutError(f"{motions} holds no .pkl motion files.")
    split_names: list[str] = []
    for split in ("train", "val", "test"):
        split_names += _read_names(root / "splits" / f"crossmodal_{split}.txt")
    names = sorted(set(split_names) & set(available)) if split_names else available
    ignore = set(_read_names(root / "ignore_list.txt"))
    names = [n for n in names if n not in ignore]
    if not all_sequences:
        seen, kept = set(), []
        for n in names:
            music = parse_aist_name(n)["music_id"]
            if music not in seen:
                seen.add(music)
                kept.append(n)
        names = kept
    if not names:
        raise DatasetLayoutError(
            f"No AIST++ sequences left under {root} after splits and ignore_list.txt."
        )
    return names


def read_aist_motion(
    root: str | Path, name: str, source: str = "smpl"
) -> tuple[np.ndarray, np.ndarray]:
    """Joint positions (N, 24, 3) and pose timestamps (N,) in microseconds of one sequence.

    Args:
        source: ``"smpl"`` (forward kinematics of ``motions/<name>.pkl``, as the thesis) or
            ``"keypoints3d"`` (COCO-17 from ``keypoints3d/<name>.pkl``, :func:`coco17_to_skeleton`).
    """
    root = Path(root)
    if source == "smpl":
        m = _load_pickle(root / "motions" / f"{name}.pkl")
        missing = {"smpl_poses", "smpl_trans"} - set(m)
        if missing:
            raise ValueError(
                f"{root / 'motions' / name}.pkl lacks {sorted(missing)}; keys are {sorted(m)}."
            )
        poses = np.asarray(m["smpl_poses"], dtype=np.float64)
        if poses.ndim != 2 or poses.shape[1] != 72:
            raise ValueError(f"{name}: smpl_poses must be (N, 72), got {poses.shape}.")
        scaling = float(np.asarray(m.get("smpl_scaling", 1.0)).reshape(-1)[0])
        bad = ~np.all(np.isfinite(poses), axis=1)
        joints = np.full((poses.shape[0], 24, 3), np.nan)
        trans = np.asarray(m["smpl_trans"], dtype=np.float64)
        joints[~bad] = forward_kinematics(poses[~bad], trans[~bad], scaling)
    elif source == "keypoints3d":
        k = _load_pickle(root / "keypoints3d" / f"{name}.pkl")
        key = "keypoints3d_optim" if "keypoints3d_optim" in k else "keypoints3d"
        if key not in k:
            raise ValueError(
                f"{name}: keypoints3d pickle lacks 'keypoints3d'; keys are {sorted(k)}."
            )
        joints = coco17_to_skeleton(k[key])
    else:
        raise ValueError(f"Unknown source '{source}'. Valid: 'smpl', 'keypoints3d'.")
    n = joints.shape[0]
    kp2d = root / "keypoints2d" / f"{name}.pkl"
    if kp2d.is_file():
        ts = np.asarray(_load_pickle(kp2d).get("timestamps"), dtype=np.float64).reshape(-1)
        if ts.shape[0] != n:
            raise ValueError(f"{name}: {n} pose frames but {ts.shape[0]} timestamps in {kp2d}.")
    else:
        warnings.warn(f"{name}: no {kp2d}; assuming poses exactly at {AIST_FPS} fps.", stacklevel=2)
        ts = np.arange(n) * 1e6 / AIST_FPS
    return joints, ts


def load_aist(
    root: str | Path,
    all_sequences: bool = False,
    audio_dir: str | Path | None = None,
    fps: int = AIST_FPS,
    source: str = "smpl",
    genres: str | Sequence[str] | None = None,
    cache_dir: str | Path | None | bool = None,
    paper_compat: bool = False,
    skip_missing_audio: bool = False,
    keep_joints: bool = True,
    progress: bool = True,
) -> list[DanceSequence]:
    """Load AIST++ (or the default set in its layout) as synchronised :class:`DanceSequence` s.

    Args:
        root: the annotations folder (``motions/``, ``keypoints2d/``, ``splits/`` ...).
        all_sequences: every sequence instead of one per music (the thesis: one per music).
        audio_dir: the music folder; default ``root/wav`` (or wavs, music, audio).
        fps: audio feature frames per second.
        source: joints from SMPL (``"smpl"``) or from COCO-17 ``"keypoints3d"``.
        genres: keep only these music genres (``["mBR", "mHO"]``; one name alone: ``"mHO"``).
        cache_dir: feature cache (see :func:`audio.cached_audio_features`); False disables it.
        paper_compat: the authors' angle computation and frame times (see angles, sync).
        skip_missing_audio: skip sequences whose music is missing instead of raising.
        keep_joints: attach the synchronised (T, 24, 3) joints.
    """
    root = Path(root)
    if isinstance(genres, str):  # one genre, not its characters
        genres = [genres]
    names = list_aist_sequences(root, all_sequences=all_sequences)
    if genres is not None:
        unknown = set(genres) - set(AIST_GENRES)
        if unknown:
            raise ValueError(
                f"Unknown genre(s) {sorted(unknown)}. Valid: {', '.join(AIST_GENRES)}."
            )
        names = [n for n in names if parse_aist_name(n)["genre"] in set(genres)]
    adir = _find_audio_dir(root, audio_dir)
    names = _with_audio(
        names,
        lambda n: adir / f"{parse_aist_name(n)['music_id']}.wav",
        skip_missing_audio,
        "sequence(s)",
        " Pass audio_dir= or skip_missing_audio=True.",
    )
    out = []
    for name in _progress(names, len(names), "AIST++", progress):
        info = parse_aist_name(name)
        audio_path = adir / f"{info['music_id']}.wav"
        joints, ts = read_aist_motion(root, name, source=source)
        out.append(_pair(name, info["music_id"], info["genre"], audio_path, joints, ts, 1e-6, fps,
                         cache_dir, paper_compat, keep_joints, info["dancer"]))  # fmt: skip
    return out


def _with_audio(
    names: list[str], audio_of, skip_missing_audio: bool, what: str, hint: str
) -> list[str]:
    """``names`` whose music file ``audio_of(name)`` exists; raise for the others (``hint`` says
    how to go on), or drop them with a warning when ``skip_missing_audio``."""
    missing = [n for n in names if not audio_of(n).is_file()]
    if not missing:
        return names
    first = audio_of(missing[0])
    msg = f"{len(missing)} {what} have no music in {first.parent}, e.g. {first.name}" + (
        f" for {missing[0]}." if first.stem != missing[0] else "."
    )
    if not skip_missing_audio:
        raise FileNotFoundError(msg + hint)
    warnings.warn(msg + " Skipped.", stacklevel=2)
    return [n for n in names if n not in set(missing)]


def _pair(name, music_id, genre, audio_path, joints, ts, unit, fps, cache_dir, paper_compat,
          keep_joints, dancer="") -> DanceSequence:  # fmt: skip
    joints, ts, kept = drop_missing_frames(joints, ts, name=name)
    order = np.argsort(ts, kind="stable")
    joints, ts, kept = joints[order], ts[order], kept[order]
    angles = pose_to_ur3_angles(joints, paper_compat=paper_compat)
    feats = cached_audio_features(audio_path, fps=fps, cache_dir=cache_dir)
    feats, _, idx = synchronize(
        feats, angles, ts, fps=fps, timestamp_unit=unit, paper_compat=paper_compat
    )
    return DanceSequence(
        name=name, music_id=music_id, genre=genre, audio_path=Path(audio_path),
        features=feats.astype(np.float32), angles=angles[idx].astype(np.float32), fps=int(fps),
        joints=joints[idx].astype(np.float32) if keep_joints else None, dancer=dancer,
        pose_index=kept[idx],
    )  # fmt: skip


# ----------------------------------------------------------------------------- PhantomDance

PHANTOM_BONES = ("Pelvis", "L_Hip", "R_Hip", "Spine1", "L_Knee", "R_Knee", "Spine2", "L_Ankle",
                 "R_Ankle", "Spine3", "L_Foot", "R_Foot", "Neck", "L_Collar", "R_Collar", "Head",
                 "L_Shoulder", "R_Shoulder", "L_Elbow", "R_Elbow", "L_Wrist", "R_Wrist", "L_Hand",
                 "R_Hand")  # fmt: skip
"""SMPL bone names as PhantomDance spells them, in :data:`angles.JOINT_NAMES` order."""


_UNITY_MIRROR = np.diag([-1.0, 1.0, 1.0])
"""Unity's left-handed frame (x right, y up, z forward) to the project's right-handed SMPL frame
(x to the body's left, y up, z forward): mirror x. A rotation matrix R becomes M R M."""


def smpl_to_phantom(poses: np.ndarray, root_positions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """SMPL parameters -> PhantomDance's motion arrays, the inverse of :func:`read_phantom_motion`.

    Args:
        poses: (T, 72) or (T, 24, 3) local axis-angle rotations (SMPL's layout, our frame).
        root_positions: (T, 3) root positions in metres (our frame).

    Returns:
        ``rotations (T, 24, 4)``: world rotations as (x, y, z, w) quaternions in Unity's frame, in
        :data:`PHANTOM_BONES` order; ``root_positions (T, 3)`` in Unity's frame.
    """
    from scipy.spatial.transform import Rotation

    poses = np.asarray(poses, dtype=np.float64).reshape(-1, 24, 3)
    T = len(poses)
    world = world_rotations(
        Rotation.from_rotvec(poses.reshape(-1, 3)).as_matrix().reshape(T, 24, 3, 3)
    )
    unity = _UNITY_MIRROR @ world @ _UNITY_MIRROR
    q = Rotation.from_matrix(unity.reshape(-1, 3, 3)).as_quat().reshape(T, 24, 4)
    return q, np.asarray(root_positions, dtype=np.float64) @ _UNITY_MIRROR


def read_phantom_motion(path: str | Path, quaternion_order: str = "xyzw", rotations: str = "world",
                        frame: str = "unity") -> tuple[np.ndarray, dict]:  # fmt: skip
    """Joint positions (N, 24, 3) of one PhantomDance motion JSON, plus its other fields.

    The official format (PhantomDance README, v1.2): ``bone_name`` (N bones), ``root_positions``
    (T, 3) in metres, ``rotations`` (T, N, 4) quaternions **(x, y, z, w)**, positions and
    rotations in **world coordinates of Unity3D** (x right, y up, z forward: left-handed), 30 fps.
    The defaults read exactly that: the rotations are mirrored into the project's right-handed
    frame (:data:`_UNITY_MIRROR`), turned into local rotations (``R_parent^T R_bone``) and run
    through :func:`angles.forward_kinematics` with the project's rest skeleton.

    Bones are matched by name (case-insensitive; :data:`PHANTOM_BONES`); the 24 SMPL bones must
    all be present, other bones are ignored.

    Args:
        quaternion_order: ``"xyzw"`` (official) or ``"wxyz"``.
        rotations: ``"world"`` (official) or ``"local"`` (each bone relative to its parent, as
            the toolkit's conversion script writes them).
        frame: ``"unity"`` (official: left-handed) or ``"smpl"`` (already right-handed, ours).
    """
    from scipy.spatial.transform import Rotation

    if quaternion_order not in ("wxyz", "xyzw"):
        raise ValueError(f"quaternion_order must be 'wxyz' or 'xyzw', got '{quaternion_order}'.")
    if rotations not in ("world", "local"):
        raise ValueError(f"rotations must be 'world' or 'local', got '{rotations}'.")
    if frame not in ("unity", "smpl"):
        raise ValueError(f"frame must be 'unity' or 'smpl', got '{frame}'.")
    path = Path(path)
    try:
        d = json.loads(path.read_text())
    except Exception as e:
        raise ValueError(f"Cannot read {path} as JSON ({type(e).__name__}: {e}).") from e
    need = {"bone_name", "root_positions", "rotations"}
    if not isinstance(d, dict) or need - set(d):
        raise ValueError(
            f"{path}: a PhantomDance motion needs keys {sorted(need)}, got {sorted(d) if isinstance(d, dict) else type(d).__name__}."
        )
    names = [str(b).lower() for b in d["bone_name"]]
    index = {n: i for i, n in enumerate(names)}
    lacking = [b for b in PHANTOM_BONES if b.lower() not in index]
    if lacking:
        raise ValueError(f"{path}: bones {lacking} are missing; found {d['bone_name']}.")
    rot = np.asarray(d["rotations"], dtype=np.float64)
    root_pos = np.asarray(d["root_positions"], dtype=np.float64)
    if rot.ndim != 3 or rot.shape[1:] != (len(names), 4) or root_pos.shape != (rot.shape[0], 3):
        raise ValueError(
            f"{path}: expected rotations (N, {len(names)}, 4) and root_positions (N, 3), got "
            f"{rot.shape} and {root_pos.shape}."
        )
    q = rot[:, [index[b.lower()] for b in PHANTOM_BONES]]  # (N, 24, 4)
    if quaternion_order == "wxyz":
        q = q[..., [1, 2, 3, 0]]  # scipy wants (x, y, z, w)
    n = q.shape[0]
    bad = ~np.all(np.isfinite(q.reshape(n, -1)), axis=1) | ~np.all(np.isfinite(root_pos), axis=1)
    bad |= np.any(np.linalg.norm(q, axis=-1) < 1e-8, axis=1)
    joints = np.full((n, 24, 3), np.nan)
    if (~bad).any():
        m = Rotation.from_quat(q[~bad].reshape(-1, 4)).as_matrix().reshape(-1, 24, 3, 3)
        pos = root_pos[~bad]
        if frame == "unity":
            m, pos = _UNITY_MIRROR @ m @ _UNITY_MIRROR, pos @ _UNITY_MIRROR
        if rotations == "world":
            m = local_rotations(m)
        rotvec = Rotation.from_matrix(m.reshape(-1, 3, 3)).as_rotvec().reshape(-1, 24, 3)
        joints[~bad] = forward_kinematics(rotvec, pos)
    return joints, d


def load_phantomdance(
    root: str | Path,
    fps: int | None = None,
    cache_dir: str | Path | None | bool = None,
    paper_compat: bool = False,
    skip: Sequence[str] = (),
    skip_missing_audio: bool = False,
    keep_joints: bool = True,
    quaternion_order: str = "xyzw",
    rotations: str = "world",
    frame: str = "unity",
    progress: bool = True,
) -> list[DanceSequence]:
    """Load PhantomDance (or the default set in its layout), sorted by name.

    Args:
        root: folder with ``motion/*.json`` and ``music/*.wav``.
        fps: audio feature frames per second (``DanceSequence.fps`` says which); ``None``:
            60, as the thesis says (6.3.2: "60 times per second"), or with ``paper_compat``
            30, the data set's pose rate, as the authors' code used for PhantomDance.
        skip: names to leave out (the authors skipped ``'000'``, broken in their download).
        quaternion_order, rotations, frame: how the motion files store rotations; the defaults
            are the official format (see :func:`read_phantom_motion`).
    """
    root = Path(root)
    if fps is None:
        fps = PHANTOM_FPS if paper_compat else 60
    if not root.is_dir():
        raise FileNotFoundError(f"No PhantomDance folder at {root}.")
    mdir, adir = root / "motion", root / "music"
    if not mdir.is_dir() or not adir.is_dir():
        raise DatasetLayoutError(
            f"{root} does not have the PhantomDance layout: expected 'motion/<name>.json' (bone_name, "
            "root_positions, rotations) and 'music/<name>.wav'. Create the default set with "
            "thesis_lib.mdlt.synth.default_dataset('phantomdance')."
        )
    names = [p.stem for p in sorted(mdir.glob("*.json")) if p.stem not in set(skip)]
    if not names:
        raise DatasetLayoutError(f"{mdir} holds no .json motion files.")
    names = _with_audio(
        names,
        lambda n: adir / f"{n}.wav",
        skip_missing_audio,
        "motion(s)",
        " Pass skip_missing_audio=True to skip them.",
    )
    out = []
    for name in _progress(names, len(names), "PhantomDance", progress):
        joints, meta = read_phantom_motion(
            mdir / f"{name}.json",
            quaternion_order=quaternion_order,
            rotations=rotations,
            frame=frame,
        )
        pose_fps = float(meta.get("fps", PHANTOM_FPS))
        ts = np.arange(joints.shape[0]) / pose_fps
        out.append(_pair(name, name, str(meta.get("genre", "")), adir / f"{name}.wav", joints, ts, 1.0,
                         fps, cache_dir, paper_compat, keep_joints, str(meta.get("dancer", ""))))  # fmt: skip
    return out


def load_dance_dataset(root: str | Path, **kwargs) -> list[DanceSequence]:
    """Load a folder in either layout, detected from its contents (``motions/`` or ``motion/``)."""
    root = Path(root)
    if (root / "motions").is_dir():
        return load_aist(root, **kwargs)
    if (root / "motion").is_dir():
        return load_phantomdance(root, **kwargs)
    raise DatasetLayoutError(
        f"{root} has neither the AIST++ layout (motions/) nor the PhantomDance layout (motion/, music/)."
    )
