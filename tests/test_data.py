"""Tests of thesis_lib.data: storage round trip, tiers, scores, windows, errors, CLI."""

from __future__ import annotations

import argparse
import doctest
import warnings

import numpy as np
import pytest

from thesis_lib import data
from thesis_lib.data import (
    Episode,
    EpisodeFormatError,
    SequenceDataset,
    generate,
    load,
    make_episodes,
    normalized_score,
)
from thesis_lib.data.experts import has_policies

warnings.filterwarnings("ignore", message=".*reward functions were updated.*")

FIELDS = ("observations", "actions", "rewards", "terminations", "truncations")


@pytest.fixture(autouse=True)
def _data_dirs(tmp_path, monkeypatch):
    """Every test writes into its own directories, never ~/.minari."""
    monkeypatch.setenv("THESIS_DATA_DIR", str(tmp_path / "thesis"))
    monkeypatch.setenv("MINARI_DATASETS_PATH", str(tmp_path / "minari"))


def _same_bytes(a: np.ndarray, b: np.ndarray) -> bool:
    return a.dtype == b.dtype and a.shape == b.shape and a.tobytes() == b.tobytes()


# --- storage round trip -------------------------------------------------------------------


@pytest.mark.parametrize(
    "task,tier",
    [
        ("maze2d-umaze", "expert"),
        ("inverted-double-pendulum", "medium-replay"),
        ("inverted-double-pendulum", "random"),
    ],
)
def test_generate_store_load_round_trip_is_byte_identical(task, tier):
    if data.get_task(task).kind == "mujoco" and tier != "random" and not has_policies(task):
        pytest.skip(f"no shipped policy for {task}")
    did = generate(task, tier, n_transitions=1200, seed=3)
    assert did == f"thesis-1200/{task}/{tier}-v0"  # the size is in the id
    ds = load(did)
    eps, _ = make_episodes(task, tier, 1200, seed=3)
    assert ds.n_transitions == 1200 == sum(len(e) for e in eps)
    assert len(ds) == len(eps)
    for a, b in zip(ds, eps):
        for f in FIELDS:
            assert _same_bytes(getattr(a, f), getattr(b, f)), (f, a.id)
        if b.desired_goals is not None:
            assert _same_bytes(a.desired_goals, b.desired_goals)
    # The last episode is cut at exactly n_transitions and marked truncated.
    assert ds[-1].truncations[-1] or ds[-1].terminations[-1]


def test_same_seed_same_data_other_seed_other_data():
    a, _ = make_episodes("maze2d-umaze", "expert", 800, seed=1)
    b, _ = make_episodes("maze2d-umaze", "expert", 800, seed=1)
    c, _ = make_episodes("maze2d-umaze", "expert", 800, seed=2)
    assert all(_same_bytes(x.actions, y.actions) for x, y in zip(a, b))
    assert not _same_bytes(a[0].actions, c[0].actions)


def test_stored_reference_scores_work_with_minari():
    import minari

    did = generate("maze2d-umaze", "random", n_transitions=300, seed=0)
    ds = load(did)
    assert ds.ref_min_score == 23.85 and ds.ref_max_score == 161.86
    mds = minari.MinariDataset(ds.path / "data")
    got = minari.get_normalized_score(mds, np.array([100.0]))
    assert got[0] == pytest.approx(0.55177161075284396)  # Minari's is a fraction, not ×100


def test_real_minari_dataset_under_minari_path_loads_the_same_way(tmp_path):
    """A data set written by Minari itself (not by us) under MINARI_DATASETS_PATH."""
    from minari import create_dataset_from_buffers
    from minari.data_collector import EpisodeBuffer

    rng = np.random.default_rng(0)
    bufs = []
    for i, T in enumerate([7, 4]):
        bufs.append(
            EpisodeBuffer(
                id=i,
                observations=rng.standard_normal((T + 1, 11)),
                actions=rng.uniform(-1, 1, (T, 3)).astype(np.float32),
                rewards=rng.standard_normal(T),
                terminations=np.r_[np.zeros(T - 1, bool), True],
                truncations=np.zeros(T, bool),
                infos={},
            )
        )
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        create_dataset_from_buffers(
            "mujoco/hopper/medium-v0",
            bufs,
            env="Hopper-v5",
            eval_env="Hopper-v5",
            ref_min_score=-20.272305,
            ref_max_score=3234.3,
            data_format="hdf5",
        )
    assert (tmp_path / "minari" / "mujoco" / "hopper" / "medium-v0").exists()
    ds = load("mujoco/hopper/medium-v0")
    assert isinstance(ds[0], Episode) and ds.env_id == "Hopper-v5"
    assert ds[0].observations.shape == (8, 11) and ds[1].actions.shape == (4, 3)
    assert "mujoco/hopper/medium-v0" in data.list_datasets()
    SequenceDataset(ds, K=5).sample(4)  # the same downstream path


def test_get_dataset_generates_once_then_caches():
    a = data.get_dataset("maze2d-open", "expert", n_transitions=400)
    mtime = (a.path / "data" / "main_data.hdf5").stat().st_mtime_ns
    b = data.get_dataset("maze2d-open", "expert", n_transitions=400)
    assert (b.path / "data" / "main_data.hdf5").stat().st_mtime_ns == mtime
    c = data.get_dataset("maze2d-open", "expert", n_transitions=500)  # other size: remade
    assert c.n_transitions == 500


def test_a_newly_shipped_expert_remakes_its_cached_sets(monkeypatch):
    """A set made by an earlier expert is never served for the one shipped now (the TQC
    experts replace the ARS ones under the same names and the same generator version)."""
    from thesis_lib.data import experts

    a = data.get_dataset("hopper", "medium", n_transitions=300)
    shipped = experts.policy_fingerprint("hopper")
    assert a.metadata["thesis_info"]["policy_fingerprint"] == shipped and len(shipped) == 16
    mtime = (a.path / "data" / "main_data.hdf5").stat().st_mtime_ns
    again = data.get_dataset("hopper", "medium", n_transitions=300)  # same expert: cached
    assert (again.path / "data" / "main_data.hdf5").stat().st_mtime_ns == mtime
    r = data.get_dataset("hopper", "random", n_transitions=300)
    assert r.metadata["thesis_info"]["policy_fingerprint"] is None  # no policy in a random set
    monkeypatch.setattr(experts, "policy_fingerprint", lambda task: "a-new-expert")
    b = data.get_dataset("hopper", "medium", n_transitions=300)
    assert b.metadata["thesis_info"]["policy_fingerprint"] == "a-new-expert"
    assert (b.path / "data" / "main_data.hdf5").stat().st_mtime_ns != mtime
    r2 = data.get_dataset("hopper", "random", n_transitions=300)  # not made from the expert
    assert r2.metadata["thesis_info"] == r.metadata["thesis_info"]


# --- tiers ---------------------------------------------------------------------------------


SHIPPED = [
    t
    for t in ("hopper", "inverted-double-pendulum", "halfcheetah", "walker2d", "ant")
    if has_policies(t)
]


@pytest.mark.parametrize("task", SHIPPED[:2] or ["hopper"])
def test_tier_ordering_random_medium_expert(task):
    if not has_policies(task):
        pytest.skip(f"no shipped policy for {task}")
    means = {}
    for tier in ("random", "medium", "expert"):
        eps, _ = make_episodes(task, tier, 2500, seed=0)
        full = [e for e in eps if not (e.truncations[-1] and len(e) < 1000)] or eps
        means[tier] = np.mean([e.episode_return for e in full])
    assert means["random"] < means["medium"] < means["expert"], means


def test_medium_expert_is_medium_then_expert():
    task = SHIPPED[0] if SHIPPED else pytest.skip("no shipped policy")
    me, _ = make_episodes(task, "medium-expert", 600, seed=5)
    m, _ = make_episodes(task, "medium", 600, seed=5)
    e, _ = make_episodes(task, "expert", 600, seed=5)
    assert [x.id for x in me] == list(range(len(m) + len(e)))
    for x, y in zip(me, m + e):
        assert _same_bytes(x.actions, y.actions)


def test_maze_planner_reaches_the_goal():
    assert data.maze_success_rate("maze2d-umaze", n_episodes=10) >= 0.9
    d = data.bfs_distances([[1, 1, 1, 1], [1, 0, 0, 1], [1, 1, 0, 1], [1, 1, 1, 1]], (2, 2))
    assert d.tolist() == [[-1] * 4, [-1, 2, 1, -1], [-1, -1, 0, -1], [-1] * 4]


def test_random_returns_are_seeded_full_episodes():
    # Hopper's random episodes fall within tens of steps (healthy reward 1 a step)
    h = data.random_returns("hopper", n_episodes=5, seed=0)
    assert h.shape == (5,) and np.array_equal(h, data.random_returns("hopper", 5, seed=0))
    assert not np.array_equal(h, data.random_returns("hopper", 5, seed=1))
    assert 0 < h.mean() < 300, h
    with pytest.raises(ValueError, match="n_episodes"):
        data.random_returns("maze2d-umaze", n_episodes=0)


def test_shipped_maze_record_is_measured_in_this_maze():
    """The shipped ``policies/maze2d.json`` reproduces in the maze the models are evaluated in
    (the fixed-target PointMaze): the planner's and the random actions' mean returns, at the
    record's own episodes and seed. (The record of 1e621d7 predated the fixed targets: 247.34
    against 230.81 on umaze.)"""
    from thesis_lib.data.card import expert_quality

    rec = data.maze_reference("maze2d-umaze")
    n, seed = rec["n_episodes"], rec["seed"]
    sr, rets = data.maze_success_rate("maze2d-umaze", n, seed, return_returns=True)
    assert sr == rec["success_rate"]
    assert float(rets.mean()) == pytest.approx(rec["return_mean"], abs=0.01)
    rand = float(data.random_returns("maze2d-umaze", n, seed).mean())
    assert rand == pytest.approx(rec["random_return_mean"], abs=0.01)
    assert rec["random_normalized"] == pytest.approx(normalized_score("maze2d-umaze", rand))
    q = expert_quality().set_index("task")
    assert q.loc["maze2d-umaze", "random_return"] == rec["random_return_mean"]
    assert q.loc["maze2d-umaze", "algorithm"] == "planner"
    # a maze set's card says where this maze's random actions and planner fall on D4RL's scale
    text = data.format_card(data.data_card(generate("maze2d-umaze", "random", n_transitions=300)))
    assert f"uniform random actions {rec['random_return_mean']:.1f}" in text
    assert f"the planner {rec['return_mean']:.1f} ({rec['normalized']:.1f})" in text
    hopper = data.format_card(data.data_card(generate("hopper", "random", n_transitions=300)))
    assert "in this maze" not in hopper
    # the planner far above random actions; D4RL's references put both elsewhere than 100 and 0
    assert rec["random_normalized"] < 0 < 100 < rec["normalized"]


# --- scores --------------------------------------------------------------------------------


def test_normalized_scores_against_hand_computed_values():
    # 100 * (R - min) / (max - min) with D4RL's references, computed by hand.
    assert normalized_score("hopper", 1000.0) == pytest.approx(31.34889040358868)
    assert normalized_score("walker2d", 2000.0) == pytest.approx(43.5311307537066)
    assert normalized_score("maze2d-umaze", 100.0) == pytest.approx(55.177161075284396)
    assert normalized_score("halfcheetah", -280.178953) == pytest.approx(0.0)
    assert normalized_score("ant", 3879.7) == pytest.approx(100.0)
    np.testing.assert_allclose(
        normalized_score("hopper", np.array([-20.272305, 3234.3])), [0.0, 100.0]
    )
    assert normalized_score("inverted-double-pendulum", 5.0, missing="none") is None
    with pytest.raises(ValueError, match="no D4RL reference"):
        normalized_score("inverted-double-pendulum", 5.0)


# --- SequenceDataset -----------------------------------------------------------------------


def _toy(lengths=(5, 30, 2), obs_dim=3, act_dim=2, seed=0):
    rng = np.random.default_rng(seed)
    return [
        Episode(
            i,
            rng.standard_normal((T + 1, obs_dim)),
            rng.standard_normal((T, act_dim)),
            rng.standard_normal(T),
            np.zeros(T, bool),
            np.zeros(T, bool),
        )
        for i, T in enumerate(lengths)
    ]


def test_windows_are_right_padded_with_mask_and_aligned_timesteps():
    eps = _toy()
    ds = SequenceDataset(eps, K=4, rtg_scale=10.0, normalize_states=False)
    b = ds.windows(np.array([0, 1, 2]), np.array([3, 0, 1]))
    assert b.mask.tolist() == [[True, True, False, False], [True] * 4, [True, False, False, False]]
    assert b.timesteps.tolist() == [[3, 4, 0, 0], [0, 1, 2, 3], [1, 0, 0, 0]]
    # Each real step carries its own state, action, a_{t-1} and return-to-go.
    np.testing.assert_allclose(b.states[0, :2], eps[0].observations[3:5], rtol=1e-6)
    np.testing.assert_allclose(b.actions[0, :2], eps[0].actions[3:5], rtol=1e-6)
    np.testing.assert_allclose(b.prev_actions[0, :2], eps[0].actions[2:4], rtol=1e-6)
    np.testing.assert_allclose(b.prev_actions[1, 0], 0.0)  # a_{-1} = 0
    rtg = np.cumsum(eps[0].rewards[::-1])[::-1] / 10.0
    np.testing.assert_allclose(b.returns_to_go[0, :2, 0], rtg[3:5], rtol=1e-5)
    # Padding is zero everywhere.
    for arr in (b.states, b.actions, b.prev_actions, b.returns_to_go, b.rewards):
        assert not np.any(arr[~b.mask])
    assert b.states.shape == (3, 4, 3) and b.returns_to_go.shape == (3, 4, 1)


def test_paper_compat_left_pads_the_timesteps_only():
    eps = _toy()
    ds = SequenceDataset(eps, K=4, normalize_states=False, paper_compat=True)
    b = ds.windows(np.array([0, 2]), np.array([3, 1]))
    assert b.mask.tolist() == [[True, True, False, False], [True, False, False, False]]
    assert b.timesteps.tolist() == [[0, 0, 3, 4], [0, 0, 0, 1]]  # the authors' misalignment
    np.testing.assert_allclose(b.states[0, :2], eps[0].observations[3:5], rtol=1e-6)


def test_state_normalisation_and_subgoal_hook():
    eps = _toy()
    ds = SequenceDataset(eps, K=3, subgoal_fn=lambda e: e.observations[1:])
    allstates = np.concatenate([e.observations[:-1] for e in eps])
    np.testing.assert_allclose(ds.state_mean, allstates.mean(0))
    np.testing.assert_allclose(ds.state_std, allstates.std(0) + 1e-6)
    b = ds.windows(np.array([1]), np.array([0]))
    want = (eps[1].observations[1:4] - ds.state_mean) / ds.state_std
    np.testing.assert_allclose(b.subgoals[0], want, rtol=1e-5)
    with pytest.raises(ValueError, match="one sub-goal per step"):
        SequenceDataset(eps, K=3, subgoal_fn=lambda e: e.observations)


def test_sampling_is_proportional_to_length_and_uses_its_own_generator():
    eps = _toy(lengths=(10, 30, 60))
    a = SequenceDataset(eps, K=5, seed=7)
    np.random.seed(0)  # noqa: NPY002 - the test checks the global generator is untouched
    b1 = a.sample(20_000)
    counts = np.bincount(b1.episode_index, minlength=3) / 20_000
    np.testing.assert_allclose(counts, [0.1, 0.3, 0.6], atol=0.02)
    assert np.all(b1.start < np.array([10, 30, 60])[b1.episode_index])
    b2 = SequenceDataset(eps, K=5, seed=7).sample(20_000)
    assert np.array_equal(b1.start, b2.start)
    assert np.random.random() == np.random.RandomState(0).random_sample()  # noqa: NPY002  # global untouched
    assert b1.states.shape == (20_000, 5, 3) and b1.mask.dtype == bool


def test_end_sampling_makes_every_step_the_last_of_a_window_equally_often():
    """The default (d3rlpy's DT): a step uniform over all steps, the window the K steps ending
    at it. An episode's first steps are last steps as often as any other; under "start"
    sampling (the original DT code) step t < K - 1 is covered by only (t + 1) / K of its share."""
    eps = _toy(lengths=(10, 30, 60))
    ds = SequenceDataset(eps, K=5, seed=3, normalize_states=False)
    assert ds.sampling == "end"
    b = ds.sample(60_000)
    n = b.mask.sum(axis=1)
    assert np.all(b.mask[np.arange(len(n)), n - 1]) and np.all(b.mask.cumsum(1) <= n[:, None])
    last = b.start + n - 1  # the window's last real step, in its episode
    flat = ds.offsets[b.episode_index] + last
    freq = np.bincount(flat, minlength=len(ds)) / len(flat)
    np.testing.assert_allclose(freq, 1 / len(ds), atol=0.004)  # uniform over the 100 steps
    # a window holds the K steps up to its last one, or all of them from the episode's start
    assert np.all(n == np.minimum(last + 1, 5)) and np.all(b.start == np.maximum(last - 4, 0))
    i = int(np.flatnonzero((b.episode_index == 2) & (last == 7))[0])
    np.testing.assert_allclose(b.actions[i, :5], eps[2].actions[3:8], rtol=1e-6)
    for arr in (b.states, b.actions, b.returns_to_go, b.timesteps):
        assert not np.any(arr[~b.mask])
    # the first steps of an episode as often as its middle under "end", less under "start"
    s = SequenceDataset(eps, K=5, seed=3, sampling="start").sample(60_000)
    covered = lambda bb, t: np.mean(
        (bb.episode_index == 2) & (bb.start <= t) & (t < bb.start + bb.mask.sum(1))
    )
    assert covered(b, 0) == pytest.approx(covered(b, 30), rel=0.15)
    assert covered(s, 0) == pytest.approx(covered(s, 30) / 5, rel=0.2)


def test_sampling_defaults_and_errors():
    eps = _toy()
    assert SequenceDataset(eps, K=4).sampling == "end"
    assert SequenceDataset(eps, K=4, paper_compat=True).sampling == "start"  # the authors' code
    assert SequenceDataset(eps, K=4, paper_compat=True, sampling="end").sampling == "end"
    with pytest.raises(ValueError, match="Unknown sampling 'middle'. Valid: end, start"):
        SequenceDataset(eps, K=4, sampling="middle")


# --- errors --------------------------------------------------------------------------------


def test_unknown_task_and_tier_list_the_valid_ones():
    msg = r"Unknown task 'hoper'\. Did you mean: 'hopper'\?.*Valid tasks: hopper, walker2d"
    with pytest.raises(ValueError, match=msg):
        generate("hoper", "medium")
    msg = r"Unknown tier 'meduim'.*Valid tiers: random, medium, medium-replay, medium-expert, exp"
    with pytest.raises(ValueError, match=msg):
        generate("hopper", "meduim")
    with pytest.raises(ValueError, match="Valid tiers: expert, random"):
        data.gen_dataset_id("maze2d-umaze", "medium")
    with pytest.raises(ValueError, match="namespace/task/tier-vN"):
        load("hopper-medium")


def test_missing_dataset_says_how_to_make_it():
    msg = (
        r"No Minari dataset 'thesis/hopper/medium-v0'.*"
        r"'thesis data generate --task hopper --tier medium'"
    )
    with pytest.raises(FileNotFoundError, match=msg):
        load("thesis/hopper/medium-v0")
    with pytest.raises(FileNotFoundError, match="Set MINARI_DATASETS_PATH"):
        load("mujoco/hopper/expert-v0")


def test_a_set_made_concurrently_by_another_process_is_replaced_not_an_error(monkeypatch):
    """Two processes make the same new set at once: both found no folder, one renames its set
    into place first; the other's rename onto it must not fail (a directory cannot be renamed
    over a non-empty one), and the set left is complete."""
    from thesis_lib.data import storage

    def episodes(n: int) -> list[Episode]:
        T = 6
        return [Episode(i, np.zeros((T + 1, 3)), np.zeros((T, 2)), np.full(T, float(n)),
                        np.r_[np.zeros(T - 1, bool), True], np.zeros(T, bool)) for i in range(n)]  # fmt: skip

    real_replace, raced = storage.os.replace, []

    def lose_the_race(src, dst):  # the other process renames its set in just before ours
        if not raced and str(dst).endswith("random-v0"):
            raced.append(1)
            data.write_dataset("thesis/hopper/random-v0", episodes(2), "Hopper-v5")
        return real_replace(src, dst)

    monkeypatch.setattr(storage.os, "replace", lose_the_race)
    data.write_dataset("thesis/hopper/random-v0", episodes(3), "Hopper-v5")
    assert raced
    ds = load("thesis/hopper/random-v0")
    assert len(ds) == 3 and float(ds[0].rewards[0]) == 3.0  # the last rename wins, whole
    monkeypatch.setattr(storage.os, "replace", real_replace)
    with pytest.raises(FileExistsError, match="exists"):
        data.write_dataset("thesis/hopper/random-v0", episodes(1), "Hopper-v5", overwrite=False)


def test_episode_with_wrong_observation_count_is_named():
    bad = Episode(
        7, np.zeros((5, 3)), np.zeros((5, 2)), np.zeros(5), np.zeros(5, bool), np.zeros(5, bool)
    )
    msg = r"Episode 7 .*has 5 observations and 5 actions; expected 6"
    with pytest.raises(EpisodeFormatError, match=msg):
        data.write_dataset("thesis/hopper/random-v0", [bad], "Hopper-v5")
    with pytest.raises(EpisodeFormatError, match="Episode 7"):
        SequenceDataset([bad], K=2)


def test_n_transitions_below_one_is_refused_and_the_good_set_kept(capsys):
    """`--n-transitions 0` (or -5) used to exit 0 and replace the set by an empty one."""
    did = generate("maze2d-umaze", "random", n_transitions=50)
    for n in (0, -5):
        with pytest.raises(ValueError, match=rf"`n_transitions`.*actually: {n}"):
            generate("maze2d-umaze", "random", n_transitions=n)
        with pytest.raises(ValueError, match="`n_transitions`"):
            data.get_dataset("maze2d-umaze", "random", n_transitions=n)
        argv = ["data", "generate", "--task", "maze2d-umaze", "--tier", "random"]
        assert _cli([*argv, "--n-transitions", str(n)]) == 2
        err = capsys.readouterr().err.strip()
        assert "--n-transitions" in err and str(n) in err and "\n" not in err
    with pytest.raises(ValueError, match="at least one transition"):  # the storage refuses too
        data.write_dataset(did, [], "PointMaze_UMaze-v3")
    ds = load(did)
    assert len(ds) >= 1 and ds.n_transitions == 50
    assert ds.metadata["thesis_info"]["n_transitions"] == 50


@pytest.mark.parametrize("damage", ["[]", "{}", "not json", "half hdf5"])
def test_a_damaged_set_is_reported_in_one_line_and_rebuilt_by_get_dataset(damage, capsys):
    a = data.get_dataset("maze2d-umaze", "random", n_transitions=50)
    if damage == "half hdf5":
        h5 = a.path / "data" / "main_data.hdf5"
        h5.write_bytes(h5.read_bytes()[: h5.stat().st_size // 2])
    else:
        (a.path / "data" / "metadata.json").write_text(damage)
    with pytest.raises(data.DamagedDatasetError, match=r"thesis data generate --task maze2d-umaze"):
        load(a.id)
    assert _cli(["data", "card", a.id]) == 1  # one line, not a traceback
    err = capsys.readouterr().err.strip()
    assert "damaged" in err and a.id in err and "\n" not in err
    with pytest.warns(UserWarning, match=r"'thesis-50/maze2d-umaze/random-v0' is damaged"):
        b = data.get_dataset("maze2d-umaze", "random", n_transitions=50)
    assert b.n_transitions == 50 and load(a.id).n_transitions == 50


def test_a_damaged_set_we_cannot_make_names_what_to_do(tmp_path):
    meta = tmp_path / "minari" / "D4RL" / "door" / "human-v2" / "data" / "metadata.json"
    meta.parent.mkdir(parents=True)
    meta.write_text("[]")
    with pytest.raises(data.DamagedDatasetError, match=r"JSON object.*download the data set again"):
        data.open_dataset("D4RL/door/human-v2")


def test_making_and_closing_a_maze_env_leaves_no_file_in_the_temp_dir(tmp_path, monkeypatch):
    """gymnasium-robotics writes <temp dir>/ant_maze<time>.xml for every maze env it makes."""
    import tempfile

    tmp = tmp_path / "tmp"
    tmp.mkdir()
    monkeypatch.setattr(tempfile, "tempdir", str(tmp))
    env = data.make_env("maze2d-umaze")
    env.reset(seed=0)
    env.step(env.action_space.sample())
    env.close()
    generate("maze2d-open", "random", n_transitions=20)  # the storage makes one too
    data.load("thesis-20/maze2d-open/random-v0").recover_environment().close()
    assert sorted(p.name for p in tmp.iterdir()) == []


# --- CLI, cards, environments --------------------------------------------------------------


def _cli(argv):
    from thesis_lib.cli.data import register

    parser = argparse.ArgumentParser(prog="thesis")
    register(parser.add_subparsers(dest="command"))
    args = parser.parse_args(argv)
    return args.func(args)


def test_cli_generate_list_card(capsys):
    assert (
        _cli(
            [
                "data",
                "generate",
                "--task",
                "maze2d-umaze",
                "--tier",
                "expert",
                "--n-transitions",
                "600",
            ]
        )
        == 0
    )
    assert _cli(["data", "list"]) == 0
    assert "thesis-600/maze2d-umaze/expert-v0" in capsys.readouterr().out
    assert _cli(["data", "card", "thesis-600/maze2d-umaze/expert-v0"]) == 0
    out = capsys.readouterr().out
    assert "transitions: 600" in out and "D4RL-normalised" in out and "success rate" in out
    card = data.data_card("thesis-600/maze2d-umaze/expert-v0")
    assert card["transitions"] == 600 and card["info"]["seed"] == 0
    assert _cli(["data", "card", "--experts"]) == 0


def test_expert_quality_reports_the_policy_each_medium_tier_is_made_from():
    """A task with a separate medium run reports that run's figures (the one its medium tiers
    sample), not the expert run's medium snapshot."""
    from thesis_lib.data.card import expert_quality
    from thesis_lib.data.experts import has_medium_run, load_policy_record

    q = expert_quality().set_index("task")
    for task in ("hopper", "halfcheetah", "walker2d"):
        med = load_policy_record(task, role="medium")
        assert q.loc[task, "medium_source"] == (
            "medium run" if has_medium_run(task) else "expert run"
        )
        assert q.loc[task, "medium_normalized"] == pytest.approx(med.medium_normalized)
    assert has_medium_run("hopper") and q.loc["hopper", "medium_sampled_normalized"] > 40


def test_robotics_environments_load_and_roll_out():
    df = data.check_environments(n_steps=5, tasks=["antmaze-umaze", "pen"])
    assert df["ok"].all(), df.to_dict("records")


@pytest.mark.parametrize("module", ["tasks", "scores", "maze", "sequence"])
def test_doctests(module):
    import importlib

    res = doctest.testmod(importlib.import_module(f"thesis_lib.data.{module}"))
    assert res.failed == 0 and res.attempted > 0


@pytest.mark.slow
def test_every_task_generates_every_tier():
    """Every task's data sets, through ``get_dataset`` as `make book` gets them (made where
    missing, into an empty data dir: a fresh machine). At a tenth of the smoke size (2,000
    transitions, several episodes of every task): the code paths are the smoke size's, and the
    chapters' smoke runs make the smoke-size sets they read (``test_chapters.py``)."""
    n = data.DATASET_SIZES["smoke"] // 10
    for task, spec in data.TASKS.items():
        for tier in spec.tiers:
            if spec.kind == "mujoco" and tier != "random" and not has_policies(task):
                continue
            ds = data.get_dataset(task, tier, n_transitions=n, seed=0)
            assert ds.metadata["thesis_info"]["generator_version"] == data.recipe.GENERATOR_VERSION
            want = 2 * n if tier == "medium-expert" else n
            assert ds.n_transitions == want, (task, tier)
            assert len(ds) >= 2, (task, tier)  # episodes, not one cut-off rollout


def test_batch_to_torch():
    b = SequenceDataset(_toy(), K=3).sample(2).to_torch()
    assert b["states"].shape == (2, 3, 3) and str(b["mask"].dtype) == "torch.bool"
    assert "subgoals" not in b


def test_numpy_linear_policy_matches_sb3_contrib_ars_behind_vecnormalize():
    import gymnasium as gym
    import torch
    from sb3_contrib import ARS
    from stable_baselines3.common.vec_env import DummyVecEnv, VecNormalize

    from thesis_lib.data.experts import LinearPolicy, _snapshot

    venv = VecNormalize(DummyVecEnv([lambda: gym.make("Hopper-v5")]), norm_reward=False)
    model = ARS("LinearPolicy", venv, seed=0)
    rng = np.random.default_rng(0)
    model.weights = torch.as_tensor(rng.standard_normal(model.n_params), dtype=torch.float32)
    model.policy.load_from_vector(model.weights.numpy())
    venv.obs_rms.mean = rng.standard_normal(11)
    venv.obs_rms.var = rng.uniform(0.5, 2.0, 11)
    w, m, v = _snapshot(model, venv)
    sp = venv.action_space
    pol = LinearPolicy(w, m, v, sp.low.astype(np.float64), sp.high.astype(np.float64))
    obs = rng.standard_normal((16, 11)) * 3
    want, _ = model.predict(venv.normalize_obs(obs), deterministic=True)
    np.testing.assert_allclose(pol(obs), want, atol=1e-5)


def test_cards_table_and_return_histogram():
    import matplotlib

    matplotlib.use("Agg")
    ids = [generate("hopper", t, n_transitions=700, seed=0) for t in ("random", "expert")]
    df = data.cards_table(ids)
    assert list(df["transitions"]) == [700, 700]
    assert df.loc[1, "return_mean"] > df.loc[0, "return_mean"]
    ax = data.plot_return_histograms(ids, normalized=True)
    assert [t.get_text() for t in ax.get_legend().get_texts()] == ["random-v0", "expert-v0"]


def test_expert_training_is_deterministic_by_seed(tmp_path):
    from dataclasses import replace

    from thesis_lib.data.experts import ARS_CONFIGS, train_experts

    cfg = replace(
        ARS_CONFIGS["inverted-double-pendulum"],
        n_delta=2,
        n_top=2,
        total_steps=1500,
        checkpoint_every=500,
    )
    recs = []
    for run in ("a", "b"):
        recs.append(
            train_experts(
                "inverted-double-pendulum",
                cfg,
                out_dir=tmp_path / run,
                n_eval_episodes=2,
                n_ckpt_eval_episodes=1,
                n_select_episodes=1,
                log=lambda s: None,
            )
        )
    za, zb = (np.load(tmp_path / r / "inverted-double-pendulum.npz") for r in ("a", "b"))
    for k in za.files:
        assert _same_bytes(za[k], zb[k]), k
    assert recs[0].checkpoint_steps == recs[1].checkpoint_steps
    assert recs[0].steps_trained >= 1500
