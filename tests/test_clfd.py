"""CLfD (thesis 4.2): losses, alignment error, the environment and its expert, the reader, training."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from thesis_lib.clfd import (
    CAMERAS,
    CLfD,
    MultiViewPickPlace,
    MultiViewVideos,
    alignment_error,
    cmc_loss,
    make_pick_place_dataset,
    nt_xent,
    read_multiview_folder,
    run_demonstration,
    triplet_loss,
)


def nt_xent_by_hand(z_a: torch.Tensor, z_p: torch.Tensor, tau: float) -> float:
    """Eq 4.1 and Algorithm 1 line 11, written as loops."""
    n = len(z_a)
    z = [*z_a, *z_p]  # items 0..N-1 anchors, N..2N-1 positives

    def sim(u, v):
        return float(u @ v / (u.norm() * v.norm()))

    def ell(i, j):
        den = sum(np.exp(sim(z[i], z[k]) / tau) for k in range(2 * n) if k != i)
        return -np.log(np.exp(sim(z[i], z[j]) / tau) / den)

    return sum(ell(k, n + k) + ell(n + k, k) for k in range(n)) / (2 * n)


def test_nt_xent_matches_direct_computation():
    g = torch.Generator().manual_seed(0)
    z_a, z_p = torch.randn(5, 7, generator=g), torch.randn(5, 7, generator=g)
    for tau in (0.5, 0.1):
        assert float(nt_xent(z_a, z_p, tau)) == pytest.approx(
            nt_xent_by_hand(z_a, z_p, tau), rel=1e-5
        )
    # aligned pairs have a lower loss than shuffled ones
    assert nt_xent(z_a, z_a + 0.01) < nt_xent(z_a, z_a.roll(1, 0))


def test_losses_reject_bad_input_and_behave():
    with pytest.raises(ValueError, match="same shape"):
        nt_xent(torch.zeros(3, 4), torch.zeros(2, 4))
    with pytest.raises(ValueError, match="at least 2 pairs"):
        nt_xent(torch.zeros(1, 4), torch.zeros(1, 4))
    a = torch.tensor([[1.0, 0.0], [0.0, 1.0]])
    # triplet: negative = anchor costs exactly the margin when the positive is the anchor
    assert float(triplet_loss(a, a, a, margin=0.2)) == pytest.approx(0.2)
    assert float(cmc_loss(a, a)) < float(cmc_loss(a, a.flip(0)))


def test_alignment_error_known_values():
    e = np.random.default_rng(0).normal(size=(10, 6))
    assert alignment_error(e, e) == 0.0
    # rolled by k: frame i matches i + k (mod N): N - k frames off by k, k frames off by N - k
    n, k = 10, 2
    assert alignment_error(e, np.roll(e, k, axis=0)) == pytest.approx(2 * k * (n - k) / n / n * 100)
    # 1-d embeddings, video 2 lags one frame: values 0.1, 0.1, 1.1, ..., 6.1 against 0, 1, ..., 7;
    # frames 1..6 match one frame late, frames 0 and 7 exactly: 6 frames off by 1 of 8, N = 8
    t = np.arange(8.0)[:, None]
    assert alignment_error(t, np.maximum(t - 1, 0) + 0.1) == pytest.approx(6 / 8 / 8 * 100)
    with pytest.raises(ValueError, match="same shape"):
        alignment_error(e, e[:5])
    with pytest.raises(ValueError, match="NaN"):
        alignment_error(np.full((3, 2), np.nan), np.zeros((3, 2)))


def test_scripted_demonstrations_succeed():
    env = MultiViewPickPlace()
    demos = [run_demonstration(env, seed, render=False) for seed in range(20)]
    env.close()
    success = np.mean([d.success for d in demos])
    assert success >= 0.95, f"scripted expert succeeded in {success:.0%} of 20 seeds"
    d = demos[0]
    assert set(np.unique(d.stages)) == {0, 1} and np.all(np.diff(d.stages) >= 0), "pick then place"
    assert d.joint_angles.shape == (len(d.stages), 7) and d.joint_velocities.shape == (
        len(d.stages),
        7,
    )
    # the box really ends on the goal plane
    assert np.linalg.norm(d.box_pos[-1, :2] - d.goal[:2]) < 0.04


def test_cameras_see_the_box():
    env = MultiViewPickPlace(image_size=64)

    def red_pixels():
        v = env.render_views().astype(int)
        return ((v[..., 0] > 100) & (v[..., 1] < 70) & (v[..., 2] < 70)).sum(axis=(1, 2))

    env.reset(seed=0, options={"box_xy": (0.0, -0.08), "goal_xy": (-0.1, 0.12)})
    seen = red_pixels()
    env.reset(
        seed=0, options={"box_xy": (3.0, 3.0), "goal_xy": (-0.1, 0.12)}
    )  # box far off the table
    gone = red_pixels()
    env.close()
    for cam, n_seen, n_gone in zip(CAMERAS, seen, gone):
        assert n_seen > 0, f"camera {cam} does not see the box"
        assert n_gone == 0, f"camera {cam} sees red where no box is"


def test_env_api_and_errors():
    env = MultiViewPickPlace(image_size=16, max_episode_steps=3)
    obs, info = env.reset(seed=1)
    assert obs.shape == env.observation_space.shape and info["stage"] == "pick"
    for _ in range(3):
        obs, r, term, trunc, info = env.step(env.action_space.sample())
    assert trunc and not term
    with pytest.raises(ValueError, match="shape \\(4,\\)"):
        env.step(np.zeros(3))
    with pytest.raises(ValueError, match="Unknown camera 'left'"):
        env.render_views(["left"])
    env.close()


def _write_views(folder, name, lengths, size=12):
    rng = np.random.default_rng(0)
    for v, n in enumerate(lengths):
        np.save(
            folder / f"{name}_view{v}.npy", rng.integers(0, 255, (n, size, size, 3), dtype=np.uint8)
        )


def test_reader_reads_synchronised_views_and_rejects_unsynchronised(tmp_path):
    _write_views(tmp_path, "pour_01", [9, 9])
    _write_views(tmp_path, "pour_02", [7, 7])
    vids = read_multiview_folder(tmp_path, image_size=8)
    assert vids.names == ["pour_01", "pour_02"] and vids.cameras == ("view0", "view1")
    assert vids.videos[0].shape == (9, 2, 8, 8, 3) and vids.videos[0].dtype == np.uint8
    _write_views(tmp_path, "pour_03", [10, 8])
    with pytest.raises(ValueError, match="'pour_03' is not synchronised.*view0: 10, view1: 8"):
        read_multiview_folder(tmp_path)
    bad = tmp_path / "missing"
    bad.mkdir()
    _write_views(bad, "a", [5, 5])
    np.save(bad / "b_view0.npy", np.zeros((5, 12, 12, 3), np.uint8))
    with pytest.raises(ValueError, match="'b' has views \\[0\\] but not \\[1\\]"):
        read_multiview_folder(bad, views=[0, 1])
    with pytest.raises(FileNotFoundError, match="No folder"):
        read_multiview_folder(tmp_path / "nope")


def test_dataset_is_rendered_split_and_cached(tmp_path):
    data = make_pick_place_dataset(
        n_demos=3, image_size=16, seed=0, cache_dir=tmp_path, progress=False
    )
    assert {k: len(v) for k, v in data.items()} == {"train": 1, "val": 1, "test": 1}
    d = data["train"]
    assert d.cameras == CAMERAS and d.videos[0].shape[1:] == (5, 16, 16, 3)
    assert len(d.stages[0]) == len(d.videos[0]) == len(d.extras["joint_angles"][0])
    again = make_pick_place_dataset(
        n_demos=3, image_size=16, seed=0, cache_dir=tmp_path, progress=False
    )
    np.testing.assert_array_equal(again["test"].videos[0], data["test"].videos[0])
    with pytest.raises(ValueError, match="expected \\(T, 2, H, W, 3\\)"):
        MultiViewVideos([np.zeros((4, 3, 8, 8, 3), np.uint8)], ("a", "b"))


def _tiny_videos(n_videos=2, n=8, size=16):
    rng = np.random.default_rng(0)
    return MultiViewVideos(
        [rng.integers(0, 255, (n, 2, size, size, 3), dtype=np.uint8) for _ in range(n_videos)],
        ("a", "b"),
    )


def test_paper_compat_keeps_the_anchor_view_out_of_the_loss():
    data = _tiny_videos()
    noisy = MultiViewVideos([v.copy() for v in data.videos], data.cameras)
    for v in noisy.videos:
        v[:, 0] = 255 - v[:, 0]  # change every anchor-view frame
    batch = np.array([(0, t, 0, 1, (t + 4) % 8) for t in range(6)])  # anchor camera 0, positive 1
    for compat, same in ((True, True), (False, False)):
        model = CLfD(encoder="tcn", width=4, paper_compat=compat, seed=0)
        model.encoder.eval(), model.projection.eval()
        with torch.no_grad():
            l1, l2 = float(model._loss(data, batch)), float(model._loss(noisy, batch))
        assert (l1 == pytest.approx(l2)) is same, f"paper_compat={compat}: {l1} vs {l2}"
    with pytest.raises(ValueError, match="method='clfd' only"):
        CLfD(method="tcn", paper_compat=True)


@pytest.mark.parametrize("encoder,method", [("tcn", "clfd"), ("resnet18", "tcn"), ("tcn", "cmc")])
def test_fit_reduces_the_loss_and_embeds(encoder, method):
    data = _tiny_videos()
    model = CLfD(encoder=encoder, method=method, width=8, batch_size=8, lr=0.003, seed=0)
    hist = model.fit(data, epochs=6, val=data, eval_every=3, progress=False)
    assert list(hist.columns) == ["epoch", "loss", "val_alignment_error"] and len(hist) == 6
    assert hist["loss"].iloc[-1] < hist["loss"].iloc[0]
    assert hist["val_alignment_error"].notna().sum() == 2
    emb = model.embed(data.videos[0])
    assert emb.shape == (8, 2, 32) and np.all(np.isfinite(emb))
    with pytest.raises(ValueError, match="Unknown camera 'c'"):
        model.fit(data, cameras=["a", "c"])


def test_clfd_save_load_same_embeddings(tmp_path):
    data = _tiny_videos(1)
    a = CLfD(encoder="resnet18", width=8, seed=1)
    b = CLfD(encoder="resnet18", width=8, seed=2).load(a.save(tmp_path / "m.pt"))
    np.testing.assert_allclose(a.embed(data.videos[0]), b.embed(data.videos[0]), rtol=1e-5)
    with pytest.raises(ValueError, match="Unknown encoder 'vgg'"):
        CLfD(encoder="vgg")


def test_embedding_reward_env_is_eq_4_2():
    from thesis_lib.clfd.rl import EmbeddingRewardEnv

    model = CLfD(encoder="tcn", width=4, seed=0)
    env = EmbeddingRewardEnv(model, demo_seed=5, image_size=16, max_episode_steps=2)
    obs, _ = env.reset()
    assert obs["observation"].shape == (32 + 15,)
    np.testing.assert_allclose(obs["desired_goal"], env.goal_embedding)
    obs, r, term, trunc, info = env.step(np.zeros(4))
    assert r == pytest.approx(-np.linalg.norm(obs["achieved_goal"] - obs["desired_goal"]), rel=1e-5)
    assert r == pytest.approx(model.reward(env.render(), env.goal_embedding), rel=1e-5)
    batch = env.compute_reward(np.zeros((3, 32)), np.ones((3, 32)), None)
    np.testing.assert_allclose(batch, -np.sqrt(32) * np.ones(3), rtol=1e-6)
    env.close()


def test_grasp_point_oracle_env_rewards_the_true_distance():
    """C12's positive control: the state holds the grasp point, the reward is minus its true
    distance to where the demonstration grasped, and replaying the demonstration reaches 0."""
    from thesis_lib.clfd.rl import EmbeddingRewardEnv, GraspPointOracle

    env = EmbeddingRewardEnv(GraspPointOracle(), demo_seed=5, image_size=16, max_episode_steps=40)
    assert env.goal_frame is None  # nothing rendered
    obs, _ = env.reset()
    assert obs["observation"].shape == (3 + 15,)
    np.testing.assert_allclose(obs["achieved_goal"], env.env.grip_pos, atol=1e-6)
    np.testing.assert_allclose(obs["observation"][:3], obs["achieved_goal"])
    rewards = []
    for a in env._demo_actions[: env._end_step]:
        obs, r, _, _, info = env.step(a)
        rewards.append(r)
        assert r == pytest.approx(-np.linalg.norm(env.env.grip_pos - env.goal_embedding), abs=1e-5)
    assert rewards[-1] == pytest.approx(0.0, abs=1e-5), "the demonstration's grasp is the goal"
    assert min(rewards) < -0.05  # metres away at the start
    # the goal is the grasp: the demonstration's grasp point sits at the box centre
    assert info["grip_box_distance"] < 0.03
    # ... checked apart from the replay: the box where the demonstration recorded it on the
    # last pick frame, within a centimetre of the goal
    from thesis_lib.clfd.env import MultiViewPickPlace, run_demonstration

    demo = run_demonstration(MultiViewPickPlace(image_size=16), 5, render=False)
    last = int(np.flatnonzero(demo.stages == 0)[-1])
    assert np.linalg.norm(demo.box_pos[last] - env.goal_embedding) < 0.01
    env.close()


def test_place_stage_starts_where_the_demonstration_left_the_pick_stage():
    """The place stage's episodes start from the demonstration's state at the stage's first
    step (box in hand), and its goal is the state at the stage's last step."""
    from thesis_lib.clfd.env import MultiViewPickPlace, run_demonstration
    from thesis_lib.clfd.rl import EmbeddingRewardEnv, GraspPointOracle

    env = EmbeddingRewardEnv(GraspPointOracle(), demo_seed=5, stage="place", image_size=16)
    demo = run_demonstration(MultiViewPickPlace(image_size=16), 5, render=False)
    first, last = (int(i) for i in np.flatnonzero(demo.stages == 1)[[0, -1]])
    assert env._start_step == first and env._end_step == last
    for _ in range(2):  # every reset replays from the layout, not from where the last episode ended
        obs, info = env.reset()
        np.testing.assert_allclose(env.env.box_pos, demo.box_pos[first], atol=1e-6)
        assert info["grip_box_distance"] < 0.03, "the box is in the gripper"
        env.step(np.array([1.0, 1.0, 1.0, -1.0]))
    # the goal: the grasp point on the stage's last frame, just above the released box
    np.testing.assert_allclose(env.goal_embedding[:2], demo.box_pos[last, :2], atol=0.01)
    assert env.goal_embedding[2] > demo.box_pos[last, 2]
    env.close()


def test_chapter_config_rejects_unknown_names():
    from thesis_lib.chapters.clfd import Config

    with pytest.raises(ValueError, match="Unknown encoder 'vgg'"):
        Config(encoders=["vgg"])
    with pytest.raises(ValueError, match="Unknown camera 'left'"):
        Config(seen_cameras=["front", "left"])
    with pytest.raises(ValueError, match="both seen and unseen"):
        Config(unseen_cameras=["front"])


def test_demonstration_earns_the_best_embedding_reward_at_its_end():
    """Eq 4.2 with the demonstration's own goal frame: replaying the demonstration ends at reward 0."""
    from thesis_lib.clfd.rl import EmbeddingRewardEnv

    model = CLfD(encoder="tcn", width=4, seed=0)
    env = EmbeddingRewardEnv(model, demo_seed=5, image_size=16, max_episode_steps=40)
    env.reset()
    rewards = [env.step(a)[1] for a in env._demo_actions[: env._end_step]]
    assert rewards[-1] == pytest.approx(0.0, abs=1e-4), "the last pick frame is the goal frame"
    assert min(rewards) < -1e-3
    env.close()


def test_reader_reads_videos(tmp_path):
    pytest.importorskip("av")
    import imageio.v3 as iio

    rng = np.random.default_rng(0)
    for v, n in enumerate([6, 6]):
        iio.imwrite(
            tmp_path / f"pour_view{v}.mp4",
            rng.integers(0, 255, (n, 16, 16, 3), dtype=np.uint8),
            plugin="pyav",
            codec="libx264",
            fps=10,
        )
    vids = read_multiview_folder(tmp_path, image_size=16)
    assert vids.videos[0].shape == (6, 2, 16, 16, 3)
    iio.imwrite(
        tmp_path / "pour_view1.mp4",
        rng.integers(0, 255, (4, 16, 16, 3), dtype=np.uint8),
        plugin="pyav",
        codec="libx264",
        fps=10,
    )
    with pytest.raises(ValueError, match="not synchronised"):
        read_multiview_folder(tmp_path)


def test_chapter_experiments_at_tiny_scale(clfd_tiny, tmp_path):
    from thesis_lib.chapters import clfd as ex

    cfg = ex.Config(**clfd_tiny, rl_episodes=2, compat_encoders=["tcn"])
    t41 = ex.run_table_4_1(cfg)
    assert list(t41["method"]) == ["untrained", "CLfD", "TCN"]
    assert t41["alignment_error_pct"].between(0, 100).all()
    store = tmp_path / "results" / "02_clfd" / "tasks"
    assert len(list(store.glob("*.json"))) == 2  # one task per trained encoder
    hist = ex.run_training_histories(cfg)
    assert list(hist["method"]) == ["CLfD", "TCN"] and set(hist["epoch"]) == {1}
    cmp = ex.compare_table_4_1(t41, {"scale": "tiny"})
    assert cmp.loc[cmp.dataset == "Pouring", "what differs"].eq("not run").all()
    compat = ex.run_paper_compat(cfg)
    assert list(compat["paper_compat"]) == [False, True]
    assert (
        compat.loc[0, "alignment_error_pct"] == t41.loc[1, "alignment_error_pct"]
    )  # reused, not retrained
    assert len(list(store.glob("*.json"))) == 3  # only the paper_compat encoder was added
    model = ex.chapter_encoder(cfg)
    assert ex.alignment_error_examples()["identical"] == 0.0
    seen = ex.camera_pairs(cfg.seen_cameras)
    assert ex.mean_alignment_error(model, ex.load_data(cfg)["test"], seen) == pytest.approx(
        t41.loc[1, "alignment_error_pct"]
    )  # the weights read back from the store are the trained ones
    t42 = ex.run_table_4_2(cfg)
    assert list(t42["viewpoints"]) == ["Seen", "Seen + Unseen", "Unseen"]
    assert t42["accuracy_pct"].between(0, 100).all()
    rl = ex.run_fig_4_4(cfg)
    assert len(rl) == 2 and {"return", "final_grip_box_distance", "expert_return"} <= set(
        rl.columns
    )


def test_pouring_rows_run_on_a_pouring_layout_folder(tmp_path, monkeypatch):
    from thesis_lib.chapters import clfd as ex

    monkeypatch.setenv("THESIS_RESULTS_DIR", str(tmp_path / "results"))
    for split in ("train", "val", "test"):
        (tmp_path / split).mkdir()
        _write_views(tmp_path / split, f"pour_{split}", [8, 8], size=16)
    cfg = ex.Config(
        image_size=16,
        encoders=["tcn"],
        methods=["clfd"],
        epochs=1,
        eval_every=1,
        tcn_width=4,
        pouring_dir=str(tmp_path),
        pouring_max_frames=6,
    )
    pouring = ex.load_pouring(cfg)
    assert pouring["train"].cameras == ("view0", "view1") and len(pouring["test"].videos[0]) == 6
    t41 = ex.run_table_4_1(cfg, dataset="Pouring")
    cmp = ex.compare_table_4_1(t41, {"scale": "tiny"})
    row = cmp[(cmp.dataset == "Pouring") & (cmp.encoder == "TCN") & (cmp.method == "CLfD")].iloc[0]
    assert (
        row["paper"] == 19.84 and 0 <= row["ours"] <= 100 and "not run" not in row["what differs"]
    )
    with pytest.raises(FileNotFoundError, match="no \\['train', 'val', 'test'\\] sub-folder"):
        ex.load_pouring(ex.Config(pouring_dir=str(tmp_path / "train")))
