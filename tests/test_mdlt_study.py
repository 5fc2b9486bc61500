"""The MDLT study (claim C13): its data size, grid, per-run rows, metric, the packaged
checkpoint and the two undocumented choices (PhantomDance fps, MDLT-M's windows)."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path
from types import SimpleNamespace as NS

import numpy as np
import pandas as pd
import pytest

from thesis_lib.chapters import CHAPTERS
from thesis_lib.chapters import mdlt as ex
from thesis_lib.mdlt.train import load_checkpoint
from thesis_lib.mdlt.translate import (
    PACKAGED_RECORDING,
    PACKAGED_RECORDING_CREDIT,
    packaged_checkpoint,
    packaged_recording,
)

REPO = Path(__file__).resolve().parents[1]


def test_higher_is_better_columns_on_a_hand_case():
    assert ex.neg_aje(0.4) == -0.4 and ex.neg_aje(0.2) > ex.neg_aje(0.4)
    assert ex.gain_vs_mean_pose(0.25, 0.5) == pytest.approx(0.5)
    assert ex.gain_vs_mean_pose(0.5, 0.5) == 0.0 and ex.gain_vs_mean_pose(0.6, 0.5) < 0
    assert ex.study_label("MDLT-T", ex.ALL_SCOPE) == "MDLT-T (all genres)"


def test_piece_fingerprint_between_share_and_identification():
    rng = np.random.default_rng(0)
    # tempogram constant within a piece and different between pieces: share 1, named always
    const = [NS(features=np.tile(rng.random(438), (50, 1)).astype(np.float32)) for _ in range(4)]
    fp = ex.piece_fingerprint(const, "tempogram", frames_per_piece=20)
    assert fp["between_share"] == pytest.approx(1.0) and fp["id_accuracy"] == 1.0
    assert fp["pieces"] == 4 and fp["chance"] == 0.25
    # the same distribution in every piece: share near 0, naming near chance
    noise = [NS(features=rng.random((400, 438)).astype(np.float32)) for _ in range(4)]
    fp = ex.piece_fingerprint(noise, "tempogram", frames_per_piece=100)
    assert fp["between_share"] < 0.01 and fp["id_accuracy"] < 0.6
    with pytest.raises(ValueError, match="Unknown feature group"):
        ex.piece_fingerprint(noise, "tempo")


def test_aist_folds_group_pieces_beyond_six():
    seqs = [NS(genre="mHO", music_id=f"mHO{k:02d}", name=str(k)) for k in range(12)]
    folds = ex.aist_folds(seqs, "mHO", 6)
    assert len(folds) == 6
    assert [s.name for s in folds[0][1]] == ["0", "6"] and len(folds[0][0]) == 10
    held = sorted(int(s.name) for _, val in folds for s in val)
    assert held == list(range(12))  # every piece held out exactly once
    six = ex.aist_folds(seqs[:6], "mHO", 6)  # the thesis's: one piece per fold
    assert [[s.name for s in v] for _, v in six] == [[str(k)] for k in range(6)]


def test_study_file_parses_and_builds_its_grid():
    from thesis_lib.book.study import load_study, study_config, study_tasks

    study = load_study(REPO / "params" / "06_mdlt.study.yml")
    assert study.chapter == "06_mdlt" and study.metric == "neg_aje"
    cfg = study_config(study, CHAPTERS["06_mdlt"])
    assert cfg.data_size == "study" and cfg.n_folds == 6 and len(cfg.study_seeds) >= 3
    cfg = ex.Config(**{**study.config, "genres": ["mBR", "mHO"]})  # no data needed
    tasks = ex.study_tasks(cfg)
    # 2 genres (baselines + variants) + all genres (baselines + variants + probe + TF variants)
    per_seed = 2 * (1 + len(cfg.variants)) + (1 + len(cfg.variants) + 1 + len(cfg.variants))
    assert len(tasks) == per_seed * len(cfg.study_seeds)
    tf = [t for t in tasks if t.config.get("recipe") == "teacher forcing"]
    assert {t.config["scope"] for t in tf} == {ex.ALL_SCOPE}
    assert {t.config["cfg"]["pose_noise"] for t in tf} == {0.0}
    assert (
        {t.config["cfg"]["pose_noise"] for t in tasks if t not in tf} == {cfg.pose_noise} != {0.0}
    )
    assert {t.config["method"] for t in tasks} == {"baselines", "transformer", "mamba", "probe"}
    assert {t.config["seed"] for t in tasks} == set(cfg.study_seeds)
    assert all(t.config["folds"] == list(range(6)) for t in tasks)
    probe = next(t for t in tasks if t.config["method"] == "probe")
    assert probe.config["cfg"]["mute_features"] == ["tempogram"]
    assert len({t.key for t in tasks}) == len(tasks)
    assert len(study_tasks(study, CHAPTERS["06_mdlt"])) > len(
        ex.study_tasks(study_config(study, CHAPTERS["06_mdlt"]))
    )  # + scale check


TINY = dict(genres=["mHO"], n_folds=1, iterations=3, d_model=16, d_ff=32, n_layers=1,
            K_mamba=8, variants=["transformer", "mamba"], study_seeds=[0])  # fmt: skip


def test_study_run_rows_on_a_tiny_config():
    tasks = ex.study_tasks(ex.Config(**TINY))
    by = {(t.config["scope"], t.config["method"]): t for t in tasks}
    base = pd.DataFrame(by[(ex.ALL_SCOPE, "baselines")].fn(by[(ex.ALL_SCOPE, "baselines")].config))
    assert set(base.method) == {"mean pose (all genres)", "genre mean (all genres)"}
    assert base.setting.nunique() == 10 and (base.songs == 1).all()
    mp = base[base.method == "mean pose (all genres)"]
    np.testing.assert_allclose(mp.gain_vs_mean_pose, 0.0, atol=1e-12)
    t = by[(ex.PER_GENRE, "mamba")]
    rows = pd.DataFrame(t.fn(t.config))
    assert list(rows.method) == ["MDLT-M"] and list(rows.setting) == ["mHO"]
    r = rows.iloc[0]
    assert r.seed == 0 and r.scope == ex.PER_GENRE and r.scale == "study" and r.folds == 1
    for c in ("aje", "neg_aje", "aje_mean_pose", "gain_vs_mean_pose", "fid", "aje_windowed"):
        assert np.isfinite(r[c]), c
    assert r.neg_aje == -r.aje and r.mismatch_cost == pytest.approx(r.aje - r.aje_windowed)
    # both tasks name the same numbers of the data set
    assert len(r.data_sha) == 16 and set(base.data_sha) == {r.data_sha}


def test_windowed_generation_restarts_the_state():
    import torch

    from thesis_lib.mdlt.models import MDLTConfig, build_model

    torch.manual_seed(0)
    m = build_model(MDLTConfig(variant="mamba", K=4, d_model=8, n_layers=1, pose_input=True))
    m.eval()
    x = np.random.default_rng(0).random((10, 438)).astype(np.float32)
    whole, reset = m.generate(x), m.generate(x, reset_every=4)
    np.testing.assert_allclose(whole[:4], reset[:4], atol=1e-6)  # the first window: the same
    assert not np.allclose(whole[4:], reset[4:])
    np.testing.assert_allclose(m.generate(x, reset_every=100), whole, atol=1e-6)
    with pytest.raises(ValueError, match="reset_every"):
        m.generate(x, reset_every=0)


def test_phantomdance_fps_follows_the_text_unless_paper_compat():
    assert ex.Config().phantom_fps() == 60
    assert ex.Config(paper_compat=True).phantom_fps() == 30
    assert ex.Config(paper_compat=True, pd_fps=60).phantom_fps() == 60
    with pytest.raises(ValueError, match="pd_fps"):
        ex.Config(pd_fps=25)


def test_thesis_table_6_2_beside_an_empty_and_a_filled_study():
    empty = ex.compare_study_table_6_2(pd.DataFrame())
    assert (empty["what differs"] == "not run").all() and len(empty) == 22
    rows = pd.DataFrame(
        [
            {"method": m, "setting": g, "seed": s, "scope": sc, "scale": "study", "aje": a}
            for s in (0, 1)
            for g in ("mHO", "mBR")
            for m, sc, a in (
                ("MDLT-T", ex.PER_GENRE, 0.3),
                ("MDLT-T (all genres)", ex.ALL_SCOPE, 0.5),
                ("mean pose", ex.PER_GENRE, 0.4),
            )
        ]
    )
    t = ex.compare_study_table_6_2(rows)
    ours = t.dropna(subset=["ours"]).set_index(["genre", "variant"])["ours"]
    assert ours[("mHO", "MDLT-T")] == pytest.approx(0.3)
    assert ours[(ex.ALL_GENRES, "MDLT-T")] == pytest.approx(0.5)


def test_beat_check_against_a_shuffled_control():
    fps, n = 60, 600
    feats = np.zeros((n, 438), np.float32)
    feats[::30, ex.BEAT_COLUMN] = 1.0  # a beat every half second

    def translate(f):  # a "translator" that hits a pose on every beat it hears
        hit = f[:, ex.BEAT_COLUMN] > 0.5
        out = np.zeros((len(f), 4))
        phase = np.zeros(len(f))
        last = -100
        for i in range(len(f)):
            last = i if hit[i] else last
            phase[i] = i - last
        out[:, 0] = np.exp(-phase / 5.0)
        return out

    r = ex.beat_check(translate(feats), feats, translate, shuffles=3, block_s=0.35, fps=fps)
    assert r["beats"] == 20 and r["beat_align"] > r["beat_align_shuffled"]


@pytest.mark.skipif(
    not (REPO / "src/thesis_lib/mdlt/assets/mdlt_packaged.pt").is_file(),
    reason="no packaged checkpoint in this checkout",
)
def test_thesis_mdlt_dance_without_checkpoint(tmp_path):
    import soundfile as sf

    from thesis_lib.mdlt.synth import synth_music
    from thesis_lib.ur3.dance import map_dance
    from thesis_lib.ur3.model import POSITION_LIMITS
    from thesis_lib.ur3.safety import check_trajectory

    assert (REPO / "src/thesis_lib/mdlt/assets/mdlt_packaged.pt").stat().st_size < 400_000
    piece = synth_music("mPO", 118.0, 12.0, seed=7)
    import librosa

    y = librosa.resample(piece.audio, orig_sr=22050, target_sr=44100)
    wav = tmp_path / "song.ogg"
    sf.write(wav, np.stack([y, y], 1), 44100)  # a stereo OGG at 44.1 kHz, as a user's
    out = tmp_path / "angles.csv"
    res = subprocess.run(
        [sys.executable, "-m", "thesis_lib.cli.mdlt", "dance", "--audio", str(wav),
         "--out", str(out), "-q"],
        capture_output=True, text=True, cwd=REPO, timeout=300,
    )  # fmt: skip
    assert res.returncode == 0, res.stderr
    df = pd.read_csv(out)
    a = df.drop(columns="time_s").to_numpy()
    assert len(a) == pytest.approx(60 * piece.duration, abs=3) and np.isfinite(a).all()
    assert np.abs(a).max() <= np.pi
    q = map_dance(a)
    assert ((q >= POSITION_LIMITS[:, 0]) & (q <= POSITION_LIMITS[:, 1])).all()
    assert a.std(0).max() > 0.02  # it moves
    # speeds too: the packaged model moves faster than the UR3 may in some frames (on the
    # packaged recording as well), and `mdlt dance` says so in one line, as `ur3 check` would
    report = check_trajectory(q, 1 / 60)
    assert len(report.position_frames) == 0 and len(report.speed_frames) > 0
    assert f"UR3 limits (mapped as 'thesis ur3 play' plays it): {report.summary()[:-1]}" in (
        res.stdout
    ), res.stdout
    assert "playing it clips or slows" in res.stdout


def test_thesis_mdlt_train_writes_a_checkpoint_dance_reads(tmp_path):
    from thesis_lib.cli import main

    out = tmp_path / "ckpt.pt"
    rc = main(
        ["mdlt", "train", "--out", str(out), "--recipe", "defaults", "--data-size", "smoke",
         "--iterations", "3", "--d-model", "16", "--n-layers", "1", "-q"]
    )  # fmt: skip
    assert rc == 0 and out.is_file()
    model, scaler, meta = load_checkpoint(out)
    assert meta["variant"] == "mamba" and meta["pieces"] == 60 and meta["iterations"] == 3
    assert model.config.d_model == 16 and scaler.min_.shape == (438,)
    assert next(model.parameters()).dtype.is_floating_point  # float16 on disk, float32 loaded
    with pytest.raises(SystemExit):
        main(["mdlt", "train", "--out", str(out), "--variant", "gru"])


def test_thesis_mdlt_train_probe_mutes_the_tempogram_in_the_checkpoint(tmp_path):
    from thesis_lib.cli import main

    out = tmp_path / "probe.pt"
    rc = main(
        ["mdlt", "train", "--out", str(out), "--recipe", "defaults", "--data-size", "smoke",
         "--probe", "--iterations", "2", "--d-model", "16", "--n-layers", "1", "-q"]
    )  # fmt: skip
    assert rc == 0
    model, scaler, meta = load_checkpoint(out)
    assert meta["variant"] == "mamba_audio" and meta["iterations"] == 2
    assert meta["recipe"]["mute_features"] == ["tempogram"] and scaler.mute == ("tempogram",)
    assert meta["recipe"]["batch_size"] == ex.Config().probe_batch_size
    assert meta["recipe"]["grad_clip"] == ex.Config().probe_grad_clip
    assert main(["mdlt", "train", "--out", str(out), "--probe", "--variant", "transformer"]) == 2


@pytest.mark.skipif(
    not (REPO / "src/thesis_lib/mdlt/assets/mdlt_packaged.pt").is_file(),
    reason="no packaged checkpoint in this checkout",
)
def test_recorded_music_check_at_the_files_own_rate(tmp_path):
    import soundfile as sf

    from thesis_lib.mdlt.synth import synth_music

    piece = synth_music("mHO", 120.0, 10.0, seed=3)
    wav = tmp_path / "song.flac"
    sf.write(wav, piece.audio, 22050)
    r = ex.recorded_music_check(wav, shuffles=2)
    assert r["sample_rate"] == 22050 and r["checkpoint"] == "mdlt_packaged.pt"
    assert r["inside_position_limits"] and r["max_abs_angle"] <= np.pi
    assert r["speed_limit_frames"] >= 0 and r["peak_speed_ratio"] > 0  # checked, as ur3 check
    assert r["frames"] == pytest.approx(60 * piece.duration, abs=3) and r["beats"] > 5
    assert isinstance(r["beat_above_control"], bool)
    for k in ("beat_align", "beat_align_shuffled", "std_0"):
        assert np.isfinite(r[k]), k
    table = ex.recorded_music_table()  # the packaged recording first, with its credit
    first = table.iloc[0]
    assert first["file"] == PACKAGED_RECORDING and first["licence"] == "CC BY-SA 3.0"
    assert first["sample_rate"] == 44100 and first["seconds"] > 60
    assert bool(first["inside_position_limits"]) and first["beats"] > 60  # ~140 bpm for 62 s
    # the README: inside the joint limits and workspace, but 436 of 3,739 frames too fast (3.8x)
    assert first["workspace_frames"] == 0 and first["frames"] == pytest.approx(3739, abs=5)
    assert 400 <= first["speed_limit_frames"] <= 480 and 3.5 <= first["peak_speed_ratio"] <= 4.1
    # the README states the packaged model beats its shuffled controls (and that this check is weak)
    assert bool(first["beat_above_control"]), first.to_dict()
    # the README: the null that can fail passes on this recording, by a small margin
    assert first["null_p_shift"] < 0.05 and bool(first["null_follows_beat"])
    assert (
        first["null_shift_mean"] < first["beat_align"]
        and first["null_half_beat"] < first["beat_align"]
    )
    _, scaler, meta = load_checkpoint(packaged_checkpoint())
    assert meta["variant"] == "mamba_audio" and scaler.mute == ("tempogram",)


def test_packaged_recording_is_recorded_music_with_its_credit():
    import soundfile as sf

    path = packaged_recording()
    info = sf.info(str(path))
    assert (info.samplerate, info.channels) == (44100, 1) and 60 < info.duration < 65
    credit = (path.parent / "MUSIC.md").read_text()
    for field in PACKAGED_RECORDING_CREDIT.values():
        assert field.split(" (")[0] in credit, field
    assert PACKAGED_RECORDING not in [p.name for p in ex.find_packaged_music()]


def test_thesis_mdlt_dance_without_audio_dances_to_the_packaged_recording(tmp_path, capsys):
    from thesis_lib.cli import main

    out = tmp_path / "angles.csv"
    assert main(["mdlt", "dance", "--out", str(out), "-q"]) == 0
    said = capsys.readouterr().out
    assert "Will Savino" in said  # the credit is printed
    df = pd.read_csv(out)
    assert len(df) == pytest.approx(60 * 62.3, abs=3) and df["time_s"].iloc[-1] > 62
    # the README's claim for the packaged model on it: inside the UR3's joint limits and
    # workspace, faster than its speed limits in some frames (said, and slowed by ur3 play)
    lines = [x for x in said.splitlines() if x.startswith("UR3 limits")]
    assert len(lines) == 1, said
    line = lines[0]
    assert "joint limits" not in line and "workspace" not in line, line
    broken = re.search(r"speed limits broken in (\d+) of (\d+) frames", line)
    peak = re.search(r"peak speed ([\d.]+)x the allowed", line)
    assert broken and peak and "playing it clips or slows" in line, line
    assert 0 < int(broken[1]) < 0.25 * int(broken[2]) and 1 < float(peak[1]) < 5, line


def test_teacher_forcing_runs_are_labelled_apart():
    tasks = ex.study_tasks(ex.Config(**{**TINY, "genres": ["mHO"], "study_teacher_forcing": True}))
    t = next(t for t in tasks if t.config.get("recipe") == "teacher forcing"
             and t.config["method"] == "transformer")  # fmt: skip
    rows = pd.DataFrame(t.fn(t.config))
    assert set(rows.method) == {"MDLT-T TF (all genres)"} and rows.setting.nunique() == 10


def test_data_sha_names_the_numbers_of_the_data_set(monkeypatch):
    from types import SimpleNamespace

    def pieces(bump: float):
        feats = np.zeros((5, 438), np.float32)
        feats[2, 7] = bump
        return (SimpleNamespace(name="a", features=feats, angles=np.ones((5, 4), np.float32)),)

    shas = []
    for bump in (0.0, 0.0, 1e-6):
        monkeypatch.setattr(ex.data, "cached_sequences", lambda *a, b=bump: pieces(b))
        ex.data_sha.cache_clear()
        shas.append(ex.data_sha("aist", None, "smoke", 0))
    ex.data_sha.cache_clear()
    assert shas[0] == shas[1] != shas[2]  # one feature changed by 1e-6: another data set


def test_the_study_reduces_the_chapters_fold_task_and_keeps_no_files(tmp_path, monkeypatch):
    """A study run's songs are the chapter's fold task's rows (the tables' step), asked with
    ``windowed`` and ``keep: False``: the same rows, no checkpoint or predictions written."""
    monkeypatch.setenv("THESIS_RESULTS_DIR", str(tmp_path))
    t = next(
        t
        for t in ex.study_tasks(ex.Config(**TINY))
        if (t.config["scope"], t.config["method"]) == (ex.PER_GENRE, "mamba")
    )
    songs = ex.study_songs("mamba", t.config, t.config["genre"], 0)
    assert list(songs.method.unique()) == ["MDLT-M"] and set(songs.genre) == {"mHO"}
    assert songs.aje_windowed.notna().all() and songs.aje_mean_pose.notna().all()
    assert not [p for p in tmp_path.rglob("*") if p.is_file()]
    kept = ex.fold_task(
        {
            "data": t.config["data"],
            "experiment": "mHO",
            "genre": "mHO",
            "fold": 0,
            "checkpoint_dir": None,
            "cfg": t.config["cfg"],
            "method": "baselines",
            "seed_offset": 0,
        }  # fmt: skip
    )
    assert set(kept.song_genre) == {"mHO"} and list(tmp_path.rglob("*.npz"))
