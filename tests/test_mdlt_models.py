"""MDLT model side: MDLT-T / MDLT-M, metrics, training, folds, the dance command (thesis 6.4-6.5)."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pandas as pd
import pytest
import torch

from thesis_lib.chapters.mdlt import (
    Config,
    aist_folds,
    phantomdance_folds,
    run_fold,
    summarize_folds,
    table_6_1,
    train_model,
)
from thesis_lib.mdlt.metrics import (
    aje,
    beat_alignment,
    evaluate_songs,
    frechet_distance,
    mae_degrees,
    mean_pose_baseline,
    random_baseline,
)
from thesis_lib.mdlt.models import MDLTConfig, MDLTMamba, MDLTTransformer, build_model
from thesis_lib.mdlt.train import DanceWindows, MDLTTrainer, load_checkpoint, save_checkpoint
from thesis_lib.seq.trainer import TrainConfig

TINY = dict(d_model=16, n_layers=1, n_heads=2, d_ff=32, dropout=0.1)


def _song(T: int, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """Raw-ish features and angles that follow them (a learnable toy mapping)."""
    f = rng.random((T, 438)).astype(np.float32)
    slow = np.cumsum(f[:, :4] - 0.5, axis=0) / 6.0
    angles = (1.2 * np.tanh(slow) + 0.3 * (f[:, 4:8] - 0.5)).astype(np.float32)
    return f, angles


def _sequences(n_genres=2, n_music=3, T=50, seed=0):
    rng = np.random.default_rng(seed)
    out = []
    for g in range(n_genres):
        for m in range(n_music):
            f, a = _song(T + 7 * m, rng)
            out.append(
                SimpleNamespace(
                    name=f"g{g}_m{m}", music_id=f"mG{g}{m}", genre=f"gG{g}", features=f, angles=a
                )
            )
    return out


def _tiny_cfg(**kw) -> Config:
    base = dict(
        variants=["transformer", "mamba"],
        data_size="smoke",
        iterations=30,
        batch_size=8,
        lr=0.003,
        eval_every=0,
        K_transformer=6,
        K_mamba=12,
        n_folds=2,
        progress=False,
        **TINY,
    )
    base.update(kw)
    return Config(**base)


# ---------------------------------------------------------------------------------- metrics


def test_aje_mae_against_direct_computation():
    rng = np.random.default_rng(0)
    p, t = rng.normal(size=(30, 4)), rng.normal(size=(30, 4))
    assert aje(p, t) == pytest.approx(np.sqrt(((p - t) ** 2).sum() / p.size))
    assert mae_degrees(p, t) == pytest.approx(np.abs(p - t).mean() * 180 / np.pi)
    with pytest.raises(ValueError, match="same shape"):
        aje(p, t[:-1])
    with pytest.raises(ValueError, match="NaN"):
        aje(p * np.nan, t)


def test_frechet_distance_closed_form_for_diagonal_gaussians():
    rng = np.random.default_rng(1)
    x = rng.normal(size=(4000, 4)) * [1.0, 2.0, 0.5, 1.5] + [0.0, 1.0, -1.0, 2.0]
    y = rng.normal(size=(3000, 4)) * [0.5, 1.0, 1.5, 1.5] + [1.0, 0.0, -1.0, 0.0]
    mx, my = x.mean(0), y.mean(0)
    sx, sy = x.std(0, ddof=1), y.std(0, ddof=1)
    # sample covariances are only nearly diagonal: compare with the general formula, and with the
    # diagonal closed form within the off-diagonal noise
    cx, cy = np.cov(x, rowvar=False), np.cov(y, rowvar=False)
    w, v = np.linalg.eig(cx @ cy)
    direct = (
        ((mx - my) ** 2).sum() + np.trace(cx) + np.trace(cy) - 2 * np.sqrt(w.real.clip(0)).sum()
    )
    assert frechet_distance(x, y) == pytest.approx(direct, rel=1e-6)
    assert frechet_distance(x, y) == pytest.approx(
        ((mx - my) ** 2).sum() + ((sx - sy) ** 2).sum(), rel=0.02
    )
    assert frechet_distance(x, x) == pytest.approx(0.0, abs=1e-8)
    const = np.tile(x.mean(0), (100, 1))  # a constant prediction: singular covariance
    assert frechet_distance(const, x) == pytest.approx(np.trace(cx), rel=1e-3)


def test_beat_alignment_exact_and_bounded():
    t = np.arange(240)[:, None]
    angles = np.sin(2 * np.pi * t / 40) * np.ones(
        (1, 4)
    )  # speed minima every 20 frames at 10, 30, ...
    beats_on = np.arange(10, 240, 20)
    assert beat_alignment(angles, beats_on) == pytest.approx(1.0)
    off = beat_alignment(angles, beats_on + 3)  # 3 frames off: exp(-9 / 18)
    assert off == pytest.approx(np.exp(-0.5), rel=1e-6)
    onehot = np.zeros(240)
    onehot[beats_on] = 1
    assert beat_alignment(angles, onehot) == pytest.approx(1.0)
    assert np.isnan(beat_alignment(angles, np.array([], dtype=np.int64)))


def test_baselines_and_evaluate_songs():
    train = [np.array([[0.0, 1, 2, 3], [2.0, 3, 4, 5]])]
    mean = mean_pose_baseline(train, [5])[0]
    assert mean.shape == (5, 4) and np.allclose(mean, [1, 2, 3, 4])
    r1, r2 = random_baseline(train, [50], seed=3)[0], random_baseline(train, [50], seed=3)[0]
    assert np.array_equal(r1, r2) and np.abs(r1).max() <= np.pi
    df = evaluate_songs([mean], [np.zeros((5, 4))], ["s"])
    assert df.loc[0, "aje"] == pytest.approx(np.sqrt(np.mean(np.array([1, 2, 3, 4.0]) ** 2)))


def test_table_6_1_is_the_thesis_table():
    t = table_6_1()
    assert len(t) == 9 and t.loc[t.Method == "Bailando [233]", "Tempogram"].item() == "x"
    assert t.loc[t.Method == "Choreomaster [228]", "Mel Spectrogram"].item() == "x"
    assert t.loc[t.Method == "Choreomaster [228]", "MFCC"].item() == ""


# ---------------------------------------------------------------------------------- models


def test_config_errors():
    with pytest.raises(ValueError, match="Unknown MDLT variant 'gru'"):
        MDLTConfig(variant="gru")
    with pytest.raises(ValueError, match="divisible"):
        MDLTConfig(d_model=10, n_heads=3)
    with pytest.raises(ValueError, match=r"shape \(T, 438\)"):
        build_model(MDLTConfig(**TINY, K=4)).generate(np.zeros((5, 7), np.float32))
    with pytest.raises(ValueError, match="NaN"):
        build_model(MDLTConfig(**TINY, K=4)).generate(np.full((5, 438), np.nan, np.float32))


def test_transformer_padding_and_causal_masks():
    torch.manual_seed(0)
    m = MDLTTransformer(MDLTConfig(K=8, **TINY)).eval()
    rng = np.random.default_rng(0)
    f, a = _song(5, rng)
    batch = {
        "audio": torch.tensor(f)[None],
        "poses_in": torch.tensor(np.vstack([np.zeros((1, 4)), a[:-1]]), dtype=torch.float32)[None],
        "timesteps": torch.arange(1, 6)[None],
        "mask": torch.ones(1, 5, dtype=torch.bool),
    }
    out = m(batch).actions
    padded = {
        k: torch.cat([v, torch.zeros_like(v[:, :3]) + (7 if k != "mask" else 0)], 1)
        for k, v in batch.items()
    }
    padded["mask"][:, 5:] = False
    padded["timesteps"][:, 5:] = 0
    out_p = m(padded).actions
    assert torch.allclose(out, out_p[:, :5], atol=1e-5), (
        "padding changed the outputs at real frames"
    )
    # causal: changing the pose input at frame 3 must not change predictions at frames 0..2
    changed = {k: v.clone() for k, v in batch.items()}
    changed["poses_in"][:, 3] += 1.0
    out_c = m(changed).actions
    assert torch.allclose(out[:, :3], out_c[:, :3], atol=1e-6) and not torch.allclose(
        out[:, 3:], out_c[:, 3:]
    )
    assert out.abs().max() <= np.pi


def test_transformer_generate_equals_windowed_forward_on_its_own_predictions():
    torch.manual_seed(1)
    K = 4
    m = MDLTTransformer(MDLTConfig(K=K, **TINY)).eval()
    f = np.random.default_rng(2).random((11, 438)).astype(np.float32)
    pred = m.generate(f)
    for t in (0, 2, 3, 7, 10):
        s = max(0, t - K + 1)
        poses_in = np.vstack([np.zeros((1, 4)), pred[s:t]]).astype(np.float32)
        batch = {
            "audio": torch.tensor(f[s : t + 1])[None],
            "poses_in": torch.tensor(poses_in)[None],
            "timesteps": torch.arange(s + 1, t + 2)[None],
            "mask": torch.ones(1, t - s + 1, dtype=torch.bool),
        }
        assert np.allclose(m(batch).actions[0, -1].detach().numpy(), pred[t], atol=1e-5)
    # a batch of songs gives what each song gives alone
    g = np.random.default_rng(3).random((7, 438)).astype(np.float32)
    both = m.generate([f, g])
    assert np.allclose(both[0], pred, atol=1e-5) and np.allclose(both[1], m.generate(g), atol=1e-5)


def test_transformer_past_its_time_step_table_warns_once_and_slides_the_window():
    """A song longer than MDLT-T's time-step table capped every later slot at the table's last
    entry (never trained), silently: a trained MDLT-T then nearly stopped after the table
    (9.5 s). Now it warns once and each later window gets consecutive trained steps."""
    import warnings

    torch.manual_seed(1)
    K, table, T = 4, 10, 40
    m = MDLTTransformer(MDLTConfig(K=K, max_timestep=table, **TINY)).eval()
    f = np.random.default_rng(2).random((T, 438)).astype(np.float32)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        pred = m.generate(f)
        short = m.generate(f[:table])  # inside the table: no warning, the same translation
    said = [str(w.message) for w in caught if "max_timestep" in str(w.message)]
    assert len(said) == 1 and f"table has {table} frames" in said[0] and str(T) in said[0]
    assert np.allclose(short, pred[:table], atol=1e-5)
    period = table - K  # the steps restart every `period` frames
    for t in (table, 15, 21, T - 1):
        s = t - K + 1
        steps = torch.arange(K) + s % period + 1  # consecutive, inside the trained 1..table-1
        assert steps.max() < table
        poses_in = np.vstack([np.zeros((1, 4)), pred[s:t]]).astype(np.float32)
        batch = {
            "audio": torch.tensor(f[s : t + 1])[None],
            "poses_in": torch.tensor(poses_in)[None],
            "timesteps": steps[None],
            "mask": torch.ones(1, K, dtype=torch.bool),
        }
        assert np.allclose(m(batch).actions[0, -1].detach().numpy(), pred[t], atol=1e-5), t


def test_mamba_recurrent_inference_equals_full_forward():
    torch.manual_seed(2)
    m = MDLTMamba(MDLTConfig(variant="mamba", K=16, **TINY)).eval()
    rng = np.random.default_rng(4)
    f, a = _song(30, rng)
    shifted = np.vstack([np.zeros((1, 4)), a[:-1]]).astype(np.float32)
    full = {
        "audio": torch.tensor(f)[None],
        "poses_in": torch.tensor(shifted)[None],
        "mask": torch.ones(1, 30, dtype=torch.bool),
    }
    with torch.no_grad():
        forward = m(full).actions[0].numpy()
    # teacher-forced recurrence == one parallel scan over the whole song
    assert np.allclose(m.generate(f, teacher_poses=a), forward, atol=1e-4)
    # free-running recurrence == forward over the song fed its own previous predictions
    pred = m.generate(f)
    own = dict(
        full,
        poses_in=torch.tensor(np.vstack([np.zeros((1, 4)), pred[:-1]]), dtype=torch.float32)[None],
    )
    with torch.no_grad():
        assert np.allclose(m(own).actions[0].numpy(), pred, atol=1e-4)
    # a training window from the song's start (shorter than K, right-padded) sees the same
    w = DanceWindows([f], [a], K=40, variant="mamba")
    padded = {k: torch.cat([v, torch.zeros_like(v[:, :10])], 1) for k, v in full.items()}
    with torch.no_grad():
        assert np.allclose(m(padded).actions[0, :30].numpy(), forward, atol=1e-5)
    assert w.sample(3).poses_in.shape == (3, 40, 4)
    # the audio-only variant (the authors' code) also steps == scans
    m2 = MDLTMamba(MDLTConfig(variant="mamba", K=16, pose_input=False, **TINY)).eval()
    with torch.no_grad():
        scan = m2(full).actions[0].numpy()
        state = m2.backbone.allocate_state(1)
        steps = []
        for t in range(30):
            y, state = m2.backbone.step(m2.embed(torch.tensor(f[t : t + 1]), None), state)
            steps.append(m2._out(y)[0].numpy())
    assert np.allclose(np.stack(steps), scan, atol=1e-4) and np.allclose(
        m2.generate(f), scan, atol=1e-6
    )


def test_dance_windows_layout():
    rng = np.random.default_rng(0)
    f, a = _song(30, rng)
    wt = DanceWindows([f], [a], K=5, variant="transformer", seed=1)
    wm = DanceWindows([f], [a], K=5, variant="mamba", seed=1)
    bt, bm = wt.sample(64), wm.sample(64)
    for b in (bt, bm):
        n = b.mask.sum(1)
        for i in range(64):
            t0 = b.timesteps[i, 0] - 1
            assert np.array_equal(b.poses[i, : n[i]], a[t0 : t0 + n[i]])
            assert np.array_equal(b.poses_in[i, 1 : n[i]], a[t0 : t0 + n[i] - 1])
            assert (b.timesteps[i, n[i] :] == 0).all() and (b.audio[i, n[i] :] == 0).all()
    assert (bt.poses_in[:, 0] == 0).all()  # MDLT-T: always the zero start pose
    late = bm.timesteps[:, 0] > 1
    assert late.any() and np.array_equal(
        bm.poses_in[late, 0], a[bm.timesteps[late, 0] - 2]
    )  # MDLT-M: previous pose


@pytest.mark.parametrize("variant", ["transformer", "mamba"])
def test_loss_falls_and_same_seed_same_numbers(variant, tmp_path):
    seqs = _sequences(1, 3, T=60)
    cfg = _tiny_cfg(iterations=60)
    m1, h1, _ = train_model(variant, seqs[:2], seqs[2:], cfg)
    m2, h2, _ = train_model(variant, seqs[:2], seqs[2:], cfg)
    loss = h1["loss"].to_numpy()
    assert loss[-10:].mean() < 0.6 * loss[:10].mean(), (
        f"{variant} loss did not fall: {loss[:10].mean()} -> {loss[-10:].mean()}"
    )
    assert np.array_equal(h1["loss"].to_numpy(), h2["loss"].to_numpy())
    f = seqs[2].features
    assert np.array_equal(m1.generate(f[:, :] * 0 + 0.5), m2.generate(f[:, :] * 0 + 0.5))


def test_checkpoint_carries_scaler_and_resumes(tmp_path):
    from thesis_lib.mdlt.audio import FeatureScaler

    seqs = _sequences(1, 3, T=40)
    scaler = FeatureScaler().fit([s.features for s in seqs[:2]])
    feats = [scaler.transform(s.features) for s in seqs[:2]]
    angles = [s.angles for s in seqs[:2]]
    cfg = MDLTConfig(variant="transformer", K=6, **TINY)

    def run(iters, path, fresh_model=True):
        torch.manual_seed(0)
        model = build_model(cfg)
        tr = MDLTTrainer(
            model,
            DanceWindows(feats, angles, K=6, seed=0),
            TrainConfig(
                iterations=iters,
                batch_size=4,
                lr=0.001,
                warmup_steps=1,
                progress=False,
                checkpoint_path=str(path),
            ),
            scaler=scaler,
            meta={"fps": 60},
        )
        return tr, tr.train()

    _, h_full = run(20, tmp_path / "a.pt")
    run(10, tmp_path / "b.pt")
    _, h_resumed = run(20, tmp_path / "b.pt")  # picks up at iteration 10
    assert np.allclose(h_full["loss"].to_numpy(), h_resumed["loss"].to_numpy())
    model, sc, meta = load_checkpoint(tmp_path / "a.pt")
    assert meta["fps"] == 60 and np.allclose(sc.min_, scaler.min_)
    assert isinstance(model, MDLTTransformer) and not model.training
    torch.save({"model": {}}, tmp_path / "bad.pt")
    with pytest.raises(ValueError, match="not an MDLT checkpoint"):
        load_checkpoint(tmp_path / "bad.pt")
    save_checkpoint(tmp_path / "noscaler.pt", model)
    with pytest.raises(ValueError, match="no feature scaler"):
        load_checkpoint(tmp_path / "noscaler.pt")
    with pytest.raises(FileNotFoundError, match="No checkpoint"):
        load_checkpoint(tmp_path / "missing.pt")


# ---------------------------------------------------------------------------------- experiments


def test_folds_follow_the_thesis():
    seqs = _sequences(3, 6, T=10)
    folds = aist_folds(seqs, "mG1", 6)
    assert len(folds) == 6
    held = [f[1][0].music_id for f in folds]
    assert sorted(held) == sorted(s.music_id for s in seqs if s.genre == "gG1")
    assert all(len(tr) == 5 and all(s.genre == "gG1" for s in tr) for tr, _ in folds)
    allg = aist_folds(seqs, None, 6)
    assert all(
        len(va) == 3 and len({s.genre for s in va}) == 3 and len(tr) == 15 for tr, va in allg
    )
    with pytest.raises(ValueError, match="No sequences of genre 'mXX'"):
        aist_folds(seqs, "mXX")
    pd_seqs = [SimpleNamespace(name=f"{i:03d}") for i in range(260)]
    pfolds = phantomdance_folds(pd_seqs, 10)
    assert [len(v) for _, v in pfolds] == [26] * 10
    assert sorted(s.name for _, v in pfolds for s in v) == sorted(s.name for s in pd_seqs)


def test_run_fold_scores_models_and_baselines():
    seqs = _sequences(2, 3, T=40)
    tr, va = aist_folds(seqs, None, 1)[0]
    res = run_fold(tr, va, _tiny_cfg(iterations=5), "All Genres", 0)
    assert set(res.rows["method"]) == {
        "MDLT-T",
        "MDLT-M",
        "mean pose",
        "last pose",
        "random",
        "genre mean pose (oracle)",
    }
    assert len(res.rows) == 6 * len(va) and res.rows[["aje", "fid", "mae_deg"]].notna().all().all()
    table = summarize_folds(res.rows)
    assert len(table) == 6 and (table["n_folds"] == 1).all()
    row = table[table.variant == "mean pose"].iloc[0]
    mean = np.concatenate([s.angles for s in tr]).mean(0)
    assert row.aje_rad_mean == pytest.approx(
        np.mean([aje(np.tile(mean, (len(s.angles), 1)), s.angles) for s in va]), rel=1e-5
    )


def test_table_6_2_folds_run_as_resumable_tasks(tmp_path, monkeypatch):
    """run_table_6_2's sweep tasks give run_fold's rows; a second call trains nothing; each task
    leaves its checkpoint and predictions under the results, none in the temp dir."""
    import tempfile

    from thesis_lib.chapters import mdlt as ch
    from thesis_lib.chapters.mdlt import data, tasks

    seqs = _sequences(2, 3, T=40)
    monkeypatch.setattr(data, "cached_sequences", lambda *a: tuple(seqs))
    monkeypatch.setenv("THESIS_RESULTS_DIR", str(tmp_path / "results"))
    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path / "tmp"))
    (tmp_path / "tmp").mkdir()
    cfg = _tiny_cfg(iterations=5, n_folds=1, genres=[])
    run = ch.run_table_6_2(cfg)
    tr, va = aist_folds(seqs, None, 1)[0]
    direct = run_fold(tr, va, cfg, "All Genres", 0).rows
    cols = [c for c in direct.columns if c != "train_s"]
    pd.testing.assert_frame_equal(run.rows[cols], direct[cols])
    out = tmp_path / "results" / "06_mdlt"
    assert len(list((out / "tasks").glob("*.json"))) == 3  # two variants + the baselines
    assert len(list((out / "checkpoints").glob("All_Genres_fold0_*.pt"))) == 2
    assert ch.example_checkpoint(cfg, "mamba").is_file()
    assert np.array_equal(run.examples["predictions"]["mamba"][0].shape, va[0].angles.shape)
    monkeypatch.setattr(tasks, "train_model", lambda *a, **k: pytest.fail("trained again"))
    again = ch.run_table_6_2(cfg)
    pd.testing.assert_frame_equal(again.rows, run.rows)
    assert list((tmp_path / "tmp").iterdir()) == []


# ---------------------------------------------------------------------------------- dance command


def test_dance_command_end_to_end_on_foreign_audio(tmp_path):
    """A chirp + noise at 22.05 kHz (not the project's synthesiser) through `thesis mdlt dance`."""
    import soundfile as sf

    from thesis_lib.cli import main
    from thesis_lib.mdlt.audio import FeatureScaler, audio_features

    sr, dur = 22050, 2.0
    t = np.arange(int(sr * dur)) / sr
    rng = np.random.default_rng(0)
    y = 0.4 * np.sin(2 * np.pi * (200 * t + 400 * t**2)) + 0.05 * rng.normal(size=t.size)
    y[(t % 0.5) < 0.02] += 0.5  # clicks
    wav = tmp_path / "song.wav"
    sf.write(wav, y.astype(np.float32), sr)
    raw = audio_features(wav)  # read back from the file: resampled to 30720 Hz
    scaler = FeatureScaler().fit([raw[::2]])
    torch.manual_seed(0)
    model = build_model(MDLTConfig(variant="mamba", K=8, **TINY)).eval()
    ckpt = save_checkpoint(tmp_path / "tiny.pt", model, scaler, {"fps": 60})
    out, png, gif = tmp_path / "angles.csv", tmp_path / "angles.png", tmp_path / "arm.gif"
    rc = main(
        [
            "mdlt",
            "dance",
            "--audio",
            str(wav),
            "--checkpoint",
            str(ckpt),
            "--out",
            str(out),
            "--plot",
            str(png),
            "--animation",
            str(gif),
            "--animation-seconds",
            "0.5",
            "-q",
        ]
    )
    assert rc == 0
    df = pd.read_csv(out)
    assert list(df.columns) == ["time_s", "shoulder_pan", "shoulder_lift", "elbow", "wrist_1"]
    assert abs(len(df) - dur * 60) <= 2 and np.isfinite(df.to_numpy()).all()
    assert df.iloc[:, 1:].abs().to_numpy().max() <= np.pi and np.allclose(
        df.time_s.diff().iloc[1:], 1 / 60, atol=2e-6
    )
    assert png.stat().st_size > 1000 and gif.read_bytes()[:3] == b"GIF"
    # the same translation as the library call
    feats = scaler.transform(raw)
    assert np.allclose(df.iloc[:, 1:].to_numpy(), model.generate(feats), atol=1e-5)
    # bad input: one-line errors, exit code 1
    assert (
        main(
            [
                "mdlt",
                "dance",
                "--audio",
                str(tmp_path / "nope.wav"),
                "--checkpoint",
                str(ckpt),
                "--out",
                str(out),
            ]
        )
        == 1
    )
    assert (
        main(
            [
                "mdlt",
                "dance",
                "--audio",
                str(wav),
                "--checkpoint",
                str(tmp_path / "nope.pt"),
                "--out",
                str(out),
            ]
        )
        == 1
    )


def test_dance_command_reports_the_ur3_limits_and_animates_the_played_pose(
    tmp_path, monkeypatch, capsys
):
    """`thesis mdlt dance` said nothing about the UR3's limits (the packaged model breaks the
    speed limits on real music) and animated the raw angles, not the pose `thesis ur3 play`
    plays (offsets, halved swings)."""
    import soundfile as sf

    from thesis_lib.cli import main
    from thesis_lib.mdlt import translate
    from thesis_lib.mdlt.audio import FeatureScaler, audio_features
    from thesis_lib.ur3.dance import map_dance
    from thesis_lib.ur3.safety import check_trajectory, clip_trajectory

    sr = 22050
    wav = tmp_path / "noise.wav"
    sf.write(wav, 0.3 * np.random.default_rng(0).normal(size=sr).astype(np.float32), sr)
    scaler = FeatureScaler().fit([audio_features(wav)])
    torch.manual_seed(0)
    model = build_model(MDLTConfig(variant="mamba", K=8, **TINY)).eval()
    ckpt = save_checkpoint(tmp_path / "tiny.pt", model, scaler, {"fps": 60})
    drawn, draw = [], translate.ur3_joint_positions
    monkeypatch.setattr(
        translate, "ur3_joint_positions", lambda q: drawn.append(np.array(q)) or draw(q)
    )
    out, gif = tmp_path / "angles.csv", tmp_path / "arm.gif"
    argv = ["mdlt", "dance", "--audio", str(wav), "--checkpoint", str(ckpt), "--out", str(out)]
    assert main([*argv, "--animation", str(gif), "-q"]) == 0
    said = capsys.readouterr().out
    angles = pd.read_csv(out).drop(columns="time_s").to_numpy()
    q = map_dance(angles)  # what `thesis ur3 play` plays (before clipping)
    # the animation (15 fps: every 4th frame) draws the mapped angles, wrist included
    assert len(drawn) == 1 and drawn[0].shape == (len(q[::4]), 6)
    assert np.allclose(drawn[0], q[::4], atol=1e-5)
    # one line: which limits break in how many frames, and what clipping would change
    report = check_trajectory(q, 1 / 60)
    assert len(report.speed_frames) > 0  # an untrained model jitters faster than the arm may
    clipped = int((np.abs(clip_trajectory(q, 1 / 60) - q).max(axis=1) > 1e-9).sum())
    lines = [line for line in said.splitlines() if line.startswith("UR3 limits")]
    assert len(lines) == 1, said
    assert f"speed limits broken in {len(report.speed_frames)} of {len(q)} frames" in lines[0]
    assert report.summary()[:-1] in lines[0]
    assert f"playing it clips or slows {clipped} of {len(q)} frames" in lines[0]


def _no_work(*args, **kwargs):
    raise AssertionError("dance() started loading the checkpoint before checking its arguments")


def _dance_argv(tmp_path, monkeypatch) -> list[str]:
    """`thesis mdlt dance` on an empty file, with the checkpoint loader made to fail the test."""
    from thesis_lib.mdlt import train

    wav = tmp_path / "song.wav"
    wav.write_bytes(b"")  # never read: the checks come first
    monkeypatch.setattr(train, "load_checkpoint", _no_work)
    return ["mdlt", "dance", "--audio", str(wav), "--out", str(tmp_path / "angles.csv"), "-q"]


def test_dance_checks_the_device_before_the_checkpoint(tmp_path, monkeypatch, capsys):
    """`--device cuda` on a machine without CUDA was blamed on the checkpoint."""
    from thesis_lib.cli import main

    argv = _dance_argv(tmp_path, monkeypatch)
    monkeypatch.setattr(torch.cuda, "is_available", lambda: False)
    assert main([*argv, "--device", "cuda"]) == 1
    err = capsys.readouterr().err
    assert "`device` 'cuda'" in err and "no CUDA GPU" in err and "checkpoint" not in err
    assert main([*argv, "--device", "gpu"]) == 1
    assert "`device`" in capsys.readouterr().err


def test_dance_refuses_an_animation_suffix_before_any_work(tmp_path, monkeypatch, capsys):
    """`--animation x.mp4` was refused only after ~14 s, with the CSV already written."""
    from thesis_lib.cli import main

    argv = _dance_argv(tmp_path, monkeypatch)
    assert main([*argv, "--animation", str(tmp_path / "x.mp4")]) == 1
    err = capsys.readouterr().err
    assert "`animation`" in err and "x.mp4" in err and ".gif or .html" in err
    assert not (tmp_path / "angles.csv").exists()


def test_a_missing_checkpoint_points_to_thesis_mdlt_train(tmp_path):
    with pytest.raises(FileNotFoundError, match=r"thesis mdlt train --out .*nope\.pt") as err:
        load_checkpoint(tmp_path / "nope.pt")
    assert "save_checkpoint" not in str(err.value)
    with pytest.raises(ValueError, match="`device`"):
        load_checkpoint(tmp_path / "nope.pt", device="cuda:99")


@pytest.mark.parametrize("variant", ["transformer", "mamba"])
def test_init_output_at_starts_at_the_given_pose(variant):
    from thesis_lib.mdlt.models import init_output_at

    torch.manual_seed(0)
    m = build_model(
        MDLTConfig(variant=variant, K=6, d_model=16, n_layers=1, n_heads=2, d_ff=32)
    ).eval()
    pose = np.array(
        [1.2, -0.5, 0.8, 3.5]
    )  # the last one beyond pi: the head saturates near pi, no inf
    f = np.random.default_rng(0).uniform(0.1, 0.9, (40, 438)).astype(np.float32)
    before = m.generate(f)
    init_output_at(m, pose)
    out = m.generate(f)
    assert np.abs(out[:, :3] - pose[:3]).max() < 0.25 < np.abs(before[:, :3] - pose[:3]).max()
    assert np.isfinite(out).all() and (out[:, 3] > 2.9).all() and (np.abs(out) <= np.pi).all()
    assert out.std(0).max() > 0  # still depends on the input (weights scaled, not zeroed)
    with pytest.raises(ValueError, match="finite pose of shape"):
        init_output_at(m, np.array([0.0, np.nan, 0.0, 0.0]))
    with pytest.raises(ValueError, match="finite pose of shape"):
        init_output_at(m, np.zeros(3))


def test_mute_features_reach_the_models_and_bad_names_fail():
    with pytest.raises(ValueError, match="mute_features"):
        Config(mute_features=["tempo"])
    with pytest.raises(ValueError, match="probe_mute"):
        Config(probe_mute=["tempo"])
    seqs = _sequences(1, 3, T=60)
    cfg = _tiny_cfg(iterations=2, mute_features=["tempogram"])
    _, _, scaler = train_model("mamba", seqs[:2], seqs[2:], cfg)
    assert (
        scaler.mute == ("tempogram",)
        and (scaler.transform(seqs[2].features)[:, 54:] == np.float32(0.1)).all()
    )


def _dance_on(beats: np.ndarray) -> np.ndarray:
    """A motion swinging between two poses, at rest exactly on each of ``beats``."""
    T = int(beats[-1] + 20)
    x, sign = np.zeros(T), 1.0
    for b0, b1 in zip(beats[:-1], beats[1:]):
        phase = (np.arange(b0, b1) - b0) / (b1 - b0)
        x[b0:b1] = sign * np.cos(np.pi * phase)
        sign = -sign
    x[beats[-1] :], x[: beats[0]] = sign, x[beats[0]]
    return np.stack([x, 0.5 * x], 1)


def test_the_beat_null_can_fail():
    """Issue #35: the beat check must be able to fail. A motion at rest on the music's own
    (irregular) beats follows them; the same motion 13 frames late does not; busy noise scores
    ~0.95 against any beats yet does not follow them."""
    from thesis_lib.mdlt.metrics import beat_alignment_null

    rng = np.random.default_rng(1)
    beats = np.cumsum(rng.integers(20, 45, size=30))
    dance = _dance_on(beats)
    on = beat_alignment_null(dance, beats, n=200)
    assert on["follows_beat"] and on["p_shift"] < 0.01 and on["score"] > 0.9 > on["shift_q95"]
    late = beat_alignment_null(np.roll(dance, 13, axis=0), beats, n=200)
    assert not late["follows_beat"] and late["p_shift"] > 0.5
    busy = beat_alignment_null(rng.standard_normal((len(dance), 4)), beats, n=200)
    assert busy["score"] > 0.9 and busy["random_beats_mean"] > 0.9 and not busy["follows_beat"]
    none = beat_alignment_null(dance, np.array([5]), n=10)
    assert not none["follows_beat"] and np.isnan(none["p_shift"])
