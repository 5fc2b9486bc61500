"""MDLT data side: audio features, poses -> UR3 angles, synchronisation, readers, default data set."""

from __future__ import annotations

import json
import pickle
import warnings
from pathlib import Path

import numpy as np
import pytest
import soundfile as sf
from scipy.spatial.transform import Rotation

from thesis_lib.mdlt import angles as A
from thesis_lib.mdlt import audio as AU
from thesis_lib.mdlt import readers as R
from thesis_lib.mdlt import sync as S
from thesis_lib.mdlt import synth as SY

SR = 22050


def click_track(
    bpm: float = 120.0, seconds: float = 4.0, sr: int = SR, start: float = 0.5
) -> tuple[np.ndarray, np.ndarray]:
    """Short decaying clicks at every beat, plus a quiet tone; returns (signal, click times)."""
    y = 0.01 * np.sin(2 * np.pi * 440 * np.arange(int(seconds * sr)) / sr)
    clicks = np.arange(start, seconds - 0.1, 60.0 / bpm)
    burst = np.exp(-np.arange(300) / 40.0) * np.sin(np.arange(300) * 1.3)
    for t in clicks:
        i = int(t * sr)
        y[i : i + 300] += burst
    return y.astype(np.float32), clicks


@pytest.fixture(autouse=True)
def _feature_cache(tmp_path_factory, monkeypatch):
    monkeypatch.setenv("THESIS_MDLT_CACHE", str(tmp_path_factory.getbasetemp() / "feature-cache"))


# ----------------------------------------------------------------------------- audio


@pytest.fixture(scope="module")
def click_features():
    y, clicks = click_track()
    return AU.audio_features(y, sr=SR), clicks, y


def test_feature_shape_frame_rate_and_order(click_features):
    f, _, y = click_features
    n = int(round(len(y) * AU.feature_sample_rate(60) / SR))
    assert f.dtype == np.float32 and f.shape[1] == 438 == AU.N_FEATURES
    assert abs(f.shape[0] - (1 + n // 512)) <= 1  # 60 frames per second, centred frames
    assert np.all(np.isfinite(f))
    sl = AU.FEATURE_SLICES
    assert [sl[k].stop - sl[k].start for k in sl] == [20, 20, 12, 1, 1, 384]
    assert set(np.unique(f[:, sl["beat"]])) <= {0.0, 1.0}
    chroma = f[:, sl["chroma_cqt"]]
    assert chroma.min() >= 0 and chroma.max() <= 1.0 + 1e-5


def test_beats_and_onsets_where_the_clicks_are(click_features):
    f, clicks, _ = click_features
    beat_t = np.flatnonzero(f[:, 53]) / 60.0
    assert len(beat_t) >= len(clicks) - 2
    # every detected beat lies on a click (within 2 frames = 33 ms)
    assert np.all(np.min(np.abs(beat_t[:, None] - clicks[None]), axis=1) <= 2 / 60 + 1e-9)
    onset = f[:, 52]
    peaks = [
        int(np.argmax(onset[int(c * 60) - 5 : int(c * 60) + 6])) + int(c * 60) - 5 for c in clicks
    ]
    assert np.all(np.abs(np.array(peaks) / 60.0 - clicks) <= 2 / 60 + 1e-9)
    # the onset envelope is much stronger on the clicks than between them
    between = onset[[int((c + 0.25) * 60) for c in clicks[:-1]]]
    assert np.median(onset[peaks]) > 5 * np.median(between) + 1e-6


def test_other_fps_and_resampling(tmp_path):
    y, _ = click_track(seconds=2.0)
    f30 = AU.audio_features(y, sr=SR, fps=30)
    assert abs(f30.shape[0] - (1 + int(2.0 * 30 * 512) // 512)) <= 1
    path = tmp_path / "song44k.wav"
    y44 = AU._resample(y, SR, 44100)
    sf.write(path, np.stack([y44, y44], axis=1), 44100)  # stereo at another rate
    loaded, sr = AU.load_audio(path, sr=30720)
    assert sr == 30720 and abs(len(loaded) - 2.0 * 30720) < 64
    f_file = AU.audio_features(path)
    f_arr = AU.audio_features(y, sr=SR)
    assert abs(f_file.shape[0] - f_arr.shape[0]) <= 1
    T = min(len(f_file), len(f_arr))
    # same music at another sample rate: same MFCCs up to resampling error
    assert np.corrcoef(f_file[:T, :20].ravel(), f_arr[:T, :20].ravel())[0, 1] > 0.98


def test_hpss_matches_librosa():
    import librosa

    y, _ = click_track(seconds=1.0)
    D = librosa.stft(y, n_fft=2048, hop_length=512)
    H, P = librosa.decompose.hpss(D)
    H2, P2 = AU._hpss_stft(D)
    np.testing.assert_allclose(np.abs(H2), np.abs(H), atol=1e-4 * np.abs(D).max())
    np.testing.assert_allclose(np.abs(P2), np.abs(P), atol=1e-4 * np.abs(D).max())


def test_bad_audio(tmp_path):
    with pytest.raises(AU.AudioError, match="silent"):
        AU.audio_features(np.zeros(SR, np.float32), sr=SR)
    y = np.random.default_rng(0).standard_normal(SR).astype(np.float32)
    y[100] = np.nan
    with pytest.raises(AU.AudioError, match="NaN"):
        AU.audio_features(y, sr=SR)
    with pytest.raises(AU.AudioError, match="too short"):
        AU.audio_features(np.ones(100, np.float32), sr=SR)
    with pytest.raises(AU.AudioError, match="1-D"):
        AU.audio_features(np.ones((2, SR), np.float32), sr=SR)
    with pytest.raises(ValueError, match="sr="):
        AU.audio_features(np.ones(SR, np.float32))
    bad = tmp_path / "not_audio.wav"
    bad.write_text("this is not a wav file")
    with pytest.raises(AU.AudioError, match="Cannot read"):
        AU.audio_features(bad)
    with pytest.raises(FileNotFoundError):
        AU.audio_features(tmp_path / "missing.wav")
    silent = tmp_path / "silent.wav"
    sf.write(silent, np.zeros(SR, np.float32), SR)
    with pytest.raises(AU.AudioError, match="silent"):
        AU.cached_audio_features(silent, cache_dir=tmp_path / "c")


@pytest.mark.parametrize("sr", [0, -22050, 0.5, float("nan")])
def test_a_sample_rate_that_is_not_positive_names_sr(tmp_path, sr):
    y = np.random.default_rng(0).standard_normal(SR).astype(np.float32)
    with pytest.raises(ValueError, match=r"`sr`.*actually"):  # was a ZeroDivisionError at 0
        AU.audio_features(y, sr=sr)
    wav = tmp_path / "a.wav"
    sf.write(wav, y, SR)
    with pytest.raises(ValueError, match=r"`sr`.*actually"):
        AU.load_audio(wav, sr=sr)


def test_feature_cache_is_keyed_by_content(tmp_path):
    y, _ = click_track(seconds=1.5)
    p = tmp_path / "a.wav"
    sf.write(p, y, SR)
    cdir = tmp_path / "cache"
    f1 = AU.cached_audio_features(p, cache_dir=cdir)
    files = list(cdir.glob("*.npy"))
    assert len(files) == 1
    np.testing.assert_array_equal(np.load(files[0]), f1)
    np.testing.assert_array_equal(AU.cached_audio_features(p, cache_dir=cdir), f1)
    sf.write(p, 0.5 * y, SR)  # same name, new content -> a new entry, new features
    f2 = AU.cached_audio_features(p, cache_dir=cdir)
    assert len(list(cdir.glob("*.npy"))) == 2
    assert not np.allclose(f1[:, :20], f2[:, :20])


def test_feature_scaler_train_only_and_paper_compat():
    rng = np.random.default_rng(0)
    train = [rng.uniform(0, 1, (50, 3)), rng.uniform(-1, 2, (40, 3))]
    val = [rng.uniform(-5, 5, (30, 3))]
    train[0][:, 2] = train[1][:, 2] = 7.0  # a constant dimension
    sc = AU.fit_feature_scaler(train, held_out=val, clip=False)
    z = np.concatenate([sc.transform(t) for t in train])
    np.testing.assert_allclose(z[:, :2].min(0), 0.1, atol=1e-6)
    np.testing.assert_allclose(z[:, :2].max(0), 0.9, atol=1e-6)
    np.testing.assert_allclose(z[:, 2], 0.1, atol=1e-6)  # constant: shifted, not divided by 0
    np.testing.assert_allclose(sc.min_[:2], np.minimum(train[0].min(0), train[1].min(0))[:2])
    v = sc.transform(val[0])
    assert v[:, :2].min() < 0.1 and v[:, :2].max() > 0.9  # unseen music may leave the range
    leak = AU.fit_feature_scaler(train, held_out=val, paper_compat=True)
    vz = leak.transform(val[0])
    assert vz.min() >= 0.1 - 1e-6 and vz.max() <= 0.9 + 1e-6  # fitted on validation too
    back = AU.FeatureScaler.from_state_dict(json.loads(json.dumps(sc.state_dict())))
    np.testing.assert_array_equal(back.transform(val[0]), v)
    clipped = AU.fit_feature_scaler(train, held_out=val)  # the default: unseen music stays in range
    c = clipped.transform(val[0])
    assert c.min() >= 0.1 - 1e-6 and c.max() <= 0.9 + 1e-6
    inside = (v >= 0.1) & (v <= 0.9)
    np.testing.assert_allclose(c[inside], v[inside], atol=1e-6)  # only the outliers change
    assert AU.FeatureScaler.from_state_dict(clipped.state_dict()).clip
    assert not leak.clip  # the authors' pipeline did not clip
    with pytest.raises(ValueError, match="fitted on 3"):
        sc.transform(np.zeros((2, 4)))
    with pytest.raises(RuntimeError, match="before fit"):
        AU.FeatureScaler().transform(np.zeros((1, 3)))


# ----------------------------------------------------------------------------- angles


def arm_pose(upper: np.ndarray, fore: np.ndarray, hand: np.ndarray | None = None) -> np.ndarray:
    """The rest skeleton with the right arm's segments pointing along the given directions."""
    j = A.REST_JOINTS.copy()
    hand = fore if hand is None else hand
    j[A.R_ELBOW] = j[A.R_SHOULDER] + 0.27 * np.asarray(upper, float) / np.linalg.norm(upper)
    j[A.R_WRIST] = j[A.R_ELBOW] + 0.25 * np.asarray(fore, float) / np.linalg.norm(fore)
    j[A.R_HAND] = j[A.R_WRIST] + 0.08 * np.asarray(hand, float) / np.linalg.norm(hand)
    return j


DOWN, FWD, BACK, OUT, UP = [0, -1, 0], [0, 0, 1], [0, 0, -1], [-1, 0, 0], [0, 1, 0]


@pytest.mark.parametrize(
    "upper, fore, hand, expected",
    [
        (DOWN, DOWN, DOWN, [0, 0, 0, 0]),  # arm hanging down
        (FWD, FWD, FWD, [np.pi / 2, 0, 0, 0]),  # arm straight forward
        (BACK, BACK, BACK, [-np.pi / 2, 0, 0, 0]),  # backward: signed, not the same as forward
        (UP, UP, UP, [np.pi, 0, 0, 0]),  # overhead
        (OUT, OUT, OUT, [0, -np.pi / 2, 0, 0]),  # raised out sideways
        (DOWN, FWD, FWD, [0, 0, -np.pi / 2, 0]),  # elbow at 90 degrees
        (FWD, UP, UP, [np.pi / 2, 0, -np.pi / 2, 0]),  # arm forward, forearm up
        (DOWN, DOWN, FWD, [0, 0, 0, -np.pi / 2]),  # wrist bent 90 degrees
        ([0, -1, 1], [0, -1, 1], [0, -1, 1], [np.pi / 4, 0, 0, 0]),  # 45 degrees forward
    ],
)
def test_angles_on_hand_built_poses(upper, fore, hand, expected):
    j = arm_pose(upper, fore, hand)[None]
    got = A.pose_to_ur3_angles(j)[0]
    d = np.angle(np.exp(1j * (got - np.asarray(expected))))  # wrap (pi == -pi)
    np.testing.assert_allclose(d, 0, atol=1e-5)


def test_angles_do_not_depend_on_where_the_body_is_or_faces():
    rng = np.random.default_rng(1)
    poses = rng.normal(0, 0.4, size=(20, 24, 3))
    j = A.forward_kinematics(poses)
    ref = A.pose_to_ur3_angles(j)
    R = Rotation.random(20, random_state=2).as_matrix()
    moved = 93.0 * np.einsum("tij,tkj->tki", R, j) + rng.normal(0, 50, (20, 1, 3))
    np.testing.assert_allclose(A.pose_to_ur3_angles(moved), ref, atol=1e-4)
    # a mirrored body is not a rotated one: proper rotations keep left and right apart
    mirrored = j * np.array([-1.0, 1.0, 1.0])
    assert np.abs(A.pose_to_ur3_angles(mirrored) - ref).max() > 0.1
    # the aligned skeleton: level shoulders on x (right at -x), spine down, facing +z
    al = A.align_skeleton(moved)
    np.testing.assert_allclose(al[:, A.R_SHOULDER, 1:], 0, atol=1e-9)
    assert np.all(al[:, A.R_SHOULDER, 0] < 0)
    np.testing.assert_allclose(al[:, A.PELVIS, 0 + 2], 0, atol=1e-9)
    assert np.all(al[:, A.PELVIS, 1] < 0)
    np.testing.assert_allclose(np.linalg.det(A.body_frame(moved)), 1.0, atol=1e-9)


def test_leaning_body_keeps_the_arm_angles():
    j = arm_pose(FWD, UP)[None]
    lean = Rotation.from_euler("xz", [0.5, 0.3]).as_matrix()  # whole body tipped over
    np.testing.assert_allclose(A.pose_to_ur3_angles(j @ lean.T), A.pose_to_ur3_angles(j), atol=1e-5)


def test_paper_compat_reproduces_the_authors_quirks():
    fwd, back = arm_pose(FWD, FWD)[None], arm_pose(BACK, BACK)[None]
    ours = A.pose_to_ur3_angles(np.concatenate([fwd, back]))
    theirs = A.pose_to_ur3_angles(np.concatenate([fwd, back]), paper_compat=True)
    assert ours[0, 0] == pytest.approx(np.pi / 2, abs=1e-5) and ours[1, 0] == pytest.approx(
        -np.pi / 2, abs=1e-5
    )
    assert theirs[0, 0] == pytest.approx(theirs[1, 0], abs=1e-5)  # unsigned: forward == backward
    np.testing.assert_allclose(theirs[:, 2:], ours[:, 2:], atol=1e-5)  # elbow and wrist agree
    # the reflection + identity-when-parallel: turning the body by 0.06 degrees flips their
    # second angle by pi, and their first angle reads a 45-degree forward arm as 135 degrees
    j = np.stack([arm_pose(FWD, UP), arm_pose([0, -1, 1], DOWN)])
    turned = j @ Rotation.from_euler("y", 1e-3).as_matrix().T
    p0, p1 = (
        A.pose_to_ur3_angles(j, paper_compat=True),
        A.pose_to_ur3_angles(turned, paper_compat=True),
    )
    assert np.abs(p0 - p1).max() > 1.0
    np.testing.assert_allclose(A.pose_to_ur3_angles(turned), A.pose_to_ur3_angles(j), atol=1e-5)
    assert p0[1, 0] == pytest.approx(3 * np.pi / 4, abs=1e-4)
    assert A.pose_to_ur3_angles(j)[1, 0] == pytest.approx(np.pi / 4, abs=1e-5)


def test_forward_kinematics_keeps_bone_lengths_and_applies_trans_scaling():
    rng = np.random.default_rng(3)
    poses = rng.normal(0, 0.7, size=(5, 72))
    trans = rng.normal(0, 1, size=(5, 3))
    j = A.forward_kinematics(poses, trans, scaling=2.0)
    bones = np.linalg.norm(j[:, 1:] - j[:, list(A.PARENTS[1:])], axis=-1)
    rest = np.linalg.norm(A.OFFSETS[1:], axis=-1)
    np.testing.assert_allclose(bones, 2.0 * np.broadcast_to(rest, bones.shape), rtol=1e-9)
    np.testing.assert_allclose(j[:, 0], 2.0 * A.REST_JOINTS[0] + trans)
    np.testing.assert_allclose(A.forward_kinematics(np.zeros((1, 72)))[0], A.REST_JOINTS)


def test_bad_poses():
    j = arm_pose(DOWN, DOWN)[None].repeat(3, axis=0)
    j[1, 5] = np.nan
    with pytest.raises(ValueError, match="NaN"):
        A.pose_to_ur3_angles(j)
    with pytest.raises(ValueError, match=r"\(T, 24, 3\)"):
        A.pose_to_ur3_angles(np.zeros((3, 17, 3)))
    j = arm_pose(DOWN, DOWN)[None]
    j[0, A.R_ELBOW] = j[0, A.R_SHOULDER]
    with pytest.raises(ValueError, match="upper arm"):
        A.pose_to_ur3_angles(j)
    with pytest.raises(ValueError, match=r"\(T, 72\)"):
        A.forward_kinematics(np.zeros((3, 70)))


def test_plot_angle_extraction():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    poses = np.zeros((1, 24, 3))
    poses[0, 0] = [0.2, 0.8, 0.1]
    poses[0, 17] = [0.3, 0.2, 0.9]
    poses[0, 19] = [0, 1.2, 0]
    fig = A.plot_angle_extraction(A.forward_kinematics(poses)[0])
    assert len(fig.axes) == 2 and "θ1" in fig.axes[1].get_title()
    plt.close(fig)


# ----------------------------------------------------------------------------- sync


def test_sync_on_jittered_timestamps_with_dropped_frames():
    rng = np.random.default_rng(0)
    n = 300
    ts = np.arange(n) / 60.0 + rng.normal(0, 0.002, n)
    keep = rng.random(n) > 0.1
    ts = np.sort(ts[keep])
    frames = S.frame_times(400, fps=60)
    idx = S.nearest_pose_indices(frames, ts)
    brute = np.argmin(np.abs(frames[:, None] - ts[None]), axis=1)
    np.testing.assert_array_equal(idx, brute)
    assert np.max(np.abs(ts[idx][: n - 10] - frames[: n - 10])) < 0.05  # nearest is close


def test_synchronize_pairs_trims_and_paper_compat():
    ts_us = np.array([0, 33_000, 66_700, 100_000, 133_300])  # ~30 fps poses, microseconds
    poses = np.arange(5)[:, None].astype(float)
    feats = np.arange(20)[:, None].astype(float)  # 20 frames at 60 fps = 0.33 s
    f, p, idx = S.synchronize(feats, poses, ts_us, fps=60)
    # frames later than the last pose + half the median interval (0.15 s) are dropped
    assert len(f) == 9
    np.testing.assert_array_equal(
        idx, [0, 1, 1, 2, 2, 2, 3, 4, 4]
    )  # nearest in time, ties: earlier
    np.testing.assert_array_equal(p[:, 0], idx)
    _, _, idx_pc = S.synchronize(
        feats, poses, ts_us, fps=60, paper_compat=True, trim_to_poses=False
    )
    assert len(idx_pc) == 20  # frame i at (i + 1) / 60: one frame later than ours
    np.testing.assert_array_equal(idx_pc[: len(idx) - 1], idx[1:])
    with pytest.raises(ValueError, match="strictly increasing"):
        S.nearest_pose_indices(np.zeros(3), np.array([0.0, 0.2, 0.1]))
    with pytest.raises(ValueError, match="pair up"):
        S.synchronize(feats, poses[:4], ts_us)


# ----------------------------------------------------------------------------- readers


def _arm_down_poses(n: int, elbow: np.ndarray | None = None) -> np.ndarray:
    poses = np.zeros((n, 24, 3))
    poses[:, 17] = [0, 0, np.pi / 2]  # right arm down
    if elbow is not None:
        poses[:, 19, 1] = elbow
    return poses


@pytest.fixture(scope="module")
def aist_fixture(tmp_path_factory):
    root = tmp_path_factory.mktemp("aist")
    for d in ("motions", "keypoints2d", "keypoints3d", "splits", "wav"):
        (root / d).mkdir()
    y, _ = click_track(seconds=2.0)
    for music in ("mBR0", "mHO1"):
        sf.write(root / "wav" / f"{music}.wav", y, SR)
    names = ["gBR_sBM_cAll_d04_mBR0_ch01", "gBR_sBM_cAll_d05_mBR0_ch02", "gHO_sBM_cAll_d20_mHO1_ch01",
             "gHO_sBM_cAll_d21_mHO1_ch02"]  # fmt: skip
    n = 60  # 30 fps poses for 2 s
    elbow = np.linspace(0, np.pi / 2, n)
    for k, name in enumerate(names):
        poses = _arm_down_poses(n, elbow if k == 0 else None).reshape(n, 72)
        if k == 1:
            poses[10:13] = np.nan  # missing detections
        with open(root / "motions" / f"{name}.pkl", "wb") as f:
            pickle.dump(
                {
                    "smpl_poses": poses,
                    "smpl_trans": np.zeros((n, 3)),
                    "smpl_scaling": np.array([90.0]),
                },
                f,
            )
        ts = (np.arange(n) * 1e6 / 30 + np.random.default_rng(k).normal(0, 1000, n)).astype(
            np.int64
        )
        with open(root / "keypoints2d" / f"{name}.pkl", "wb") as f:
            pickle.dump({"keypoints2d": np.zeros((1, n, 17, 3)), "timestamps": ts}, f)
        j = A.forward_kinematics(poses if k != 1 else _arm_down_poses(n).reshape(n, 72))
        with open(root / "keypoints3d" / f"{name}.pkl", "wb") as f:
            pickle.dump({"keypoints3d": SY.skeleton_to_coco17(j)}, f)
    (root / "splits" / "crossmodal_train.txt").write_text("\n".join(names) + "\n")
    (root / "ignore_list.txt").write_text("gHO_sBM_cAll_d20_mHO1_ch01\n")
    return root


def test_load_aist_one_sequence_per_music(aist_fixture):
    seqs = R.load_aist(aist_fixture, progress=False)
    assert [s.name for s in seqs] == [
        "gBR_sBM_cAll_d04_mBR0_ch01",
        "gHO_sBM_cAll_d21_mHO1_ch02",
    ]  # ignore list
    s = seqs[0]
    assert (s.music_id, s.genre, s.dancer, s.fps) == ("mBR0", "mBR", "d04", 60)
    assert (
        s.features.shape[1] == 438
        and s.angles.shape == (len(s), 4)
        and s.joints.shape == (len(s), 24, 3)
    )
    assert s.features.dtype == np.float32 and s.angles.dtype == np.float32
    assert 115 <= len(s) <= 122  # 2 s of 60 fps frames, trimmed to the poses
    # arm down throughout, the elbow bending from 0 to 90 degrees: 60 fps frames follow 30 fps poses
    np.testing.assert_allclose(s.angles[:, :2], 0, atol=1e-5)
    expected = -np.linspace(0, np.pi / 2, 60)[s.pose_index]
    np.testing.assert_allclose(s.angles[:, 2], expected, atol=1e-5)
    assert np.all(np.diff(s.angles[:, 2]) <= 1e-6)


def test_load_aist_all_sequences_missing_frames_and_keypoints3d(aist_fixture):
    with warnings.catch_warnings(record=True) as w:
        warnings.simplefilter("always")
        seqs = R.load_aist(aist_fixture, all_sequences=True, progress=False)
    assert len(seqs) == 3
    assert any("dropped 3 pose frame" in str(x.message) for x in w)
    s = seqs[1]  # the one with NaN frames: its audio frames use the nearest valid pose
    assert np.all(np.isfinite(s.angles)) and not set(range(10, 13)) & set(s.pose_index.tolist())
    kp = R.load_aist(aist_fixture, source="keypoints3d", genres=["mHO"], progress=False)
    assert len(kp) == 1 and np.all(np.isfinite(kp[0].angles))
    np.testing.assert_allclose(
        kp[0].angles[:, :3], 0, atol=0.02
    )  # mid-hip pelvis: spine tilts 0.5 deg


def test_load_aist_takes_one_genre_as_a_string(aist_fixture):
    """`genres="mHO"` was split into the characters 'm', 'H', 'O' (unknown genres)."""
    one = R.load_aist(aist_fixture, genres="mHO", progress=False)
    assert [s.genre for s in one] == ["mHO"]
    assert [s.name for s in one] == [
        s.name for s in R.load_aist(aist_fixture, genres=["mHO"], progress=False)
    ]


def test_aist_bad_layouts(aist_fixture, tmp_path):
    with pytest.raises(R.DatasetLayoutError, match="motions/"):
        R.load_aist(tmp_path, progress=False)
    with pytest.raises(FileNotFoundError, match="No AIST"):
        R.load_aist(tmp_path / "nope", progress=False)
    with pytest.raises(R.DatasetLayoutError, match="audio_dir"):
        R.load_aist(aist_fixture, audio_dir=tmp_path / "nope", progress=False)
    empty_music = tmp_path / "music"
    empty_music.mkdir()
    with pytest.raises(FileNotFoundError, match="no music"):
        R.load_aist(aist_fixture, audio_dir=empty_music, progress=False)
    with pytest.warns(UserWarning, match="Skipped"):
        assert (
            R.load_aist(
                aist_fixture, audio_dir=empty_music, skip_missing_audio=True, progress=False
            )
            == []
        )
    with pytest.raises(ValueError, match="Unknown genre"):
        R.load_aist(aist_fixture, genres=["mXX"], progress=False)
    with pytest.raises(R.DatasetLayoutError, match="neither"):
        R.load_dance_dataset(tmp_path)
    with pytest.raises(ValueError, match="not an AIST"):
        R.parse_aist_name("dance_01")


@pytest.fixture(scope="module")
def phantom_fixture(tmp_path_factory):
    root = tmp_path_factory.mktemp("phantom")
    (root / "motion").mkdir()
    (root / "music").mkdir()
    y, _ = click_track(seconds=2.0)
    n = 60  # 2 s at 30 fps
    bones = list(R.PHANTOM_BONES) + ["R_Hand_end"]
    order = np.random.default_rng(0).permutation(len(bones))  # the reader matches bones by name
    mirror = np.diag([-1.0, 1.0, 1.0])  # Unity is left-handed: x right, y up, z forward
    for k, name in enumerate(["001", "002"]):
        poses = _arm_down_poses(n, np.linspace(0, np.pi / 2, n) if k == 0 else None).reshape(
            n, 24, 3
        )
        local = Rotation.from_rotvec(poses.reshape(-1, 3)).as_matrix().reshape(n, 24, 3, 3)
        world = local.copy()  # the official format stores world rotations
        for j in range(1, 24):
            world[:, j] = world[:, A.PARENTS[j]] @ local[:, j]
        unity = mirror @ world @ mirror
        rot = np.concatenate(
            [unity, np.repeat(np.eye(3)[None, None], n, 0)], axis=1
        )  # + an extra bone
        q = (
            Rotation.from_matrix(rot.reshape(-1, 3, 3)).as_quat().reshape(n, len(bones), 4)
        )  # (x, y, z, w)
        obj = {"bone_name": [bones[i] for i in order], "root_positions": np.zeros((n, 3)).tolist(),
               "rotations": q[:, order].tolist()}  # fmt: skip
        (root / "motion" / f"{name}.json").write_text(json.dumps(obj))
        sf.write(root / "music" / f"{name}.wav", y, SR)
    return root


def test_load_phantomdance(phantom_fixture):
    # the thesis's 60 fps by default (6.3.2); the authors' code's 30 under paper_compat
    seqs60 = R.load_phantomdance(phantom_fixture, progress=False)
    assert seqs60[0].fps == 60 and abs(len(seqs60[0]) - 120) <= 2
    assert np.all(np.diff(seqs60[0].pose_index) >= 0)  # each 30-fps pose serves ~2 frames
    assert np.bincount(seqs60[0].pose_index).max() <= 3
    seqs = R.load_phantomdance(phantom_fixture, fps=30, progress=False)
    assert R.load_phantomdance(phantom_fixture, paper_compat=True, progress=False)[0].fps == 30
    assert [s.name for s in seqs] == ["001", "002"]
    s = seqs[0]
    assert s.fps == 30 and s.features.shape[1] == 438 and abs(len(s) - 60) <= 1
    np.testing.assert_allclose(s.angles[:, :2], 0, atol=1e-5)
    np.testing.assert_allclose(
        s.angles[:, 2], -np.linspace(0, np.pi / 2, 60)[s.pose_index], atol=1e-5
    )
    np.testing.assert_array_equal(s.pose_index, np.arange(len(s)))  # same rate: frame i = pose i
    assert len(R.load_dance_dataset(phantom_fixture, skip=["002"], fps=30, progress=False)) == 1


def test_phantom_world_rotations_and_unity_frame(tmp_path):
    """The official format: world rotations (a child of an unrotated bone carries its parent's
    rotation), (x, y, z, w), Unity's left-handed frame (a yaw turns the other way)."""
    n = 2
    raise_arm = Rotation.from_euler(
        "z", [[0.0], [np.pi / 2]]
    ).as_matrix()  # frame 1: right arm up sideways
    world = np.repeat(np.eye(3)[None, None], n, 0).repeat(24, 1)
    for j in (
        A.JOINT_NAMES.index(b)
        for b in ("right_shoulder", "right_elbow", "right_wrist", "right_hand")
    ):
        world[:, j] = (
            raise_arm  # rigid arm: every bone below the shoulder has the same world rotation
        )
    local = np.zeros((n, 24, 3))
    local[:, A.JOINT_NAMES.index("right_shoulder")] = Rotation.from_matrix(raise_arm).as_rotvec()
    expect = A.forward_kinematics(local)
    q = Rotation.from_matrix(world.reshape(-1, 3, 3)).as_quat().reshape(n, 24, 4)
    p = tmp_path / "m.json"
    p.write_text(
        json.dumps(
            {
                "bone_name": list(R.PHANTOM_BONES),
                "root_positions": np.zeros((n, 3)).tolist(),
                "rotations": q.tolist(),
            }
        )
    )
    got, _ = R.read_phantom_motion(p, frame="smpl")
    np.testing.assert_allclose(got, expect, atol=1e-9)
    as_local, _ = R.read_phantom_motion(p, frame="smpl", rotations="local")  # the old misreading
    assert np.abs(as_local[1] - expect[1]).max() > 0.05
    # Unity's frame: +x is the body's right; a yaw of +a there is a yaw of -a in ours
    yaw = Rotation.from_euler("y", 0.4).as_matrix()
    world_u = np.repeat(yaw[None, None], 1, 0).repeat(24, 1)  # the whole body turned
    pu = tmp_path / "u.json"
    pu.write_text(
        json.dumps(
            {
                "bone_name": list(R.PHANTOM_BONES),
                "root_positions": [[0.3, 0.9, 0.1]],
                "rotations": Rotation.from_matrix(world_u.reshape(-1, 3, 3))
                .as_quat()
                .reshape(1, 24, 4)
                .tolist(),
            }
        )
    )
    got_u, _ = R.read_phantom_motion(pu)
    exp_local = np.zeros((1, 24, 3))
    exp_local[:, 0] = [0.0, -0.4, 0.0]
    np.testing.assert_allclose(
        got_u, A.forward_kinematics(exp_local, np.array([[-0.3, 0.9, 0.1]])), atol=1e-9
    )
    # the writer of the default set is the reader's inverse
    poses = np.random.default_rng(0).normal(0, 0.4, (3, 24, 3))
    root = np.random.default_rng(1).normal(0, 1, (3, 3))
    qw, rp = R.smpl_to_phantom(poses, root)
    pw = tmp_path / "w.json"
    pw.write_text(
        json.dumps(
            {
                "bone_name": list(R.PHANTOM_BONES),
                "root_positions": rp.tolist(),
                "rotations": qw.tolist(),
            }
        )
    )
    np.testing.assert_allclose(
        R.read_phantom_motion(pw)[0], A.forward_kinematics(poses, root), atol=1e-9
    )
    with pytest.raises(ValueError, match="rotations must be"):
        R.read_phantom_motion(pw, rotations="global")


def test_phantomdance_bad_input(phantom_fixture, tmp_path):
    with pytest.raises(R.DatasetLayoutError, match="motion/"):
        R.load_phantomdance(tmp_path, progress=False)
    p = tmp_path / "bad.json"
    d = json.loads((phantom_fixture / "motion" / "001.json").read_text())
    d["bone_name"] = [b for b in d["bone_name"] if b != "R_Elbow"] + ["Other"]
    p.write_text(json.dumps(d))
    with pytest.raises(ValueError, match="R_Elbow"):
        R.read_phantom_motion(p)
    p.write_text(json.dumps({"bone_name": []}))
    with pytest.raises(ValueError, match="needs keys"):
        R.read_phantom_motion(p)


# ----------------------------------------------------------------------------- default data set


def _tree_bytes(root: Path) -> dict[str, bytes]:
    return {
        str(p.relative_to(root)): p.read_bytes() for p in sorted(root.rglob("*")) if p.is_file()
    }


def test_synthetic_aist_same_seed_same_data(tmp_path):
    kw = dict(per_genre=2, seconds=2.5, dancers=2, genres=("mKR", "mJB"), progress=False)
    a = SY.write_aist_layout(tmp_path / "a", seed=3, **kw)
    b = SY.write_aist_layout(tmp_path / "b", seed=3, **kw)
    c = SY.write_aist_layout(tmp_path / "c", seed=4, **kw)
    ta, tb, tc = _tree_bytes(a), _tree_bytes(b), _tree_bytes(c)
    assert ta == tb
    assert ta.keys() == tc.keys() and ta != tc
    assert "wav/mKR0.wav" in ta and "ignore_list.txt" in ta
    seqs = R.load_aist(a, progress=False, keep_joints=False)
    assert len(seqs) == 4 and {s.genre for s in seqs} == {"mKR", "mJB"}
    for s in seqs:
        assert np.all(np.isfinite(s.angles)) and s.angles[:, 0].std() > 0.05  # the arm moves
    # genres dance differently: ballet jazz holds the arm higher than krump (GenreStyle.center)
    mean_t1 = {
        g: np.mean([s.angles[:, 0].mean() for s in seqs if s.genre == g]) for g in ("mKR", "mJB")
    }
    assert mean_t1["mJB"] > mean_t1["mKR"]
    # pose timestamps: ~60 fps with jitter and dropped frames, strictly increasing
    ts = R._load_pickle(a / "keypoints2d" / f"{seqs[0].name}.pkl")["timestamps"]
    dt = np.diff(ts) / 1e3
    assert np.all(dt > 0) and 15 < np.median(dt) < 18.5 and dt.max() > 30 and dt.std() > 0.5


def test_synthetic_music_tempo_and_beats():
    for g in ("mBR", "mHO"):
        piece = SY.synth_music(g, 120.0, 4.0, seed=1)
        assert np.allclose(np.diff(piece.beat_times), 0.5)
        assert piece.audio.dtype == np.float32 and np.abs(piece.audio).max() <= 0.81
    f = AU.audio_features(piece.audio, sr=SY.AUDIO_SR)
    beats = np.flatnonzero(f[:, 53]) / 60
    near = np.min(np.abs(beats[:, None] - piece.beat_times[None]), axis=1)
    assert np.mean(near < 0.05) > 0.8  # librosa finds the synthesised beats
    for gs in SY.GENRES.values():
        assert 80 <= gs.bpm[0] <= gs.bpm[1] <= 135


def test_default_dataset_caches_and_validates(tmp_path, monkeypatch):
    calls = []
    real = SY.write_phantomdance_layout

    def small(root, n, seconds, seed, progress):
        calls.append(seed)
        return real(root, n=2, seconds=2.0, seed=seed, progress=False)

    monkeypatch.setattr(SY, "write_phantomdance_layout", small)
    root = SY.default_dataset("phantomdance", "smoke", seed=5, root=tmp_path / "pd", progress=False)
    assert (root / ".complete.json").is_file() and len(list((root / "music").glob("*.wav"))) == 2
    assert SY.default_dataset("phantomdance", "smoke", seed=5, root=root) == root
    assert calls == [5]  # the second call reused it
    seqs = R.load_phantomdance(root, progress=False)
    assert len(seqs) == 2 and seqs[0].genre == "mBR"
    marker = root / ".complete.json"
    spec = json.loads(marker.read_text())
    marker.write_text(
        json.dumps({**spec, "generator": "mdlt-synth-v0"})
    )  # made by an older generator
    with pytest.warns(UserWarning, match="remaking"):
        SY.default_dataset("phantomdance", "smoke", seed=5, root=root)
    assert calls == [5, 5] and json.loads(marker.read_text()) == spec
    with pytest.raises(FileExistsError, match="another data set"):
        SY.default_dataset("phantomdance", "smoke", seed=6, root=root)
    with pytest.raises(ValueError, match="aist/study"):
        SY.default_dataset("aistpp")


def test_feature_scaler_mutes_groups_and_keeps_the_rest():
    rng = np.random.default_rng(1)
    train, val = [rng.uniform(0, 1, (30, 438))], rng.uniform(0, 1, (20, 438))
    full = AU.fit_feature_scaler(train)
    muted = AU.fit_feature_scaler(train, mute=["tempogram", "beat"])
    a, b = full.transform(val), muted.transform(val)
    assert (b[:, 53:] == np.float32(0.1)).all()  # beat and tempogram: constant
    np.testing.assert_array_equal(a[:, :53], b[:, :53])
    back = AU.FeatureScaler.from_state_dict(json.loads(json.dumps(muted.state_dict())))
    np.testing.assert_array_equal(back.transform(val), b)
    with pytest.raises(ValueError, match="Unknown feature group"):
        AU.fit_feature_scaler(train, mute=["tempo"])
