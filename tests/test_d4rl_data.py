"""Data sets with D4RL's statistics (issue #34): the size in the id, Maze2D's fixed target,
the medium tier's spread, and D4RL's published figures beside ours on the card."""

from __future__ import annotations

import numpy as np
import pytest

from thesis_lib.data import get_dataset
from thesis_lib.data.card import d4rl_comparison, data_card, format_card
from thesis_lib.data.d4rl_reference import (
    BAND_MIN_EPISODES,
    D4RL_STATS,
    SOURCES,
    band_transitions,
    d4rl_stats,
    in_band,
)
from thesis_lib.data.maze import D4RL_TARGET_CELLS, D4RL_TARGET_RADIUS, WaypointExpert
from thesis_lib.data.recipe import GENERATOR_VERSION, make_env, make_episodes
from thesis_lib.data.tasks import gen_dataset_id, is_our_namespace, parse_dataset_id


@pytest.fixture
def data_home(tmp_path, monkeypatch):
    monkeypatch.setenv("THESIS_DATA_DIR", str(tmp_path))
    monkeypatch.setenv("MINARI_DATASETS_PATH", str(tmp_path / "minari"))
    return tmp_path


# --- sizes never share an id ----------------------------------------------------------------


def test_the_size_is_in_the_id_and_sizes_coexist(data_home):
    small = get_dataset("maze2d-umaze", "random", n_transitions=600)
    smoke = get_dataset("maze2d-umaze", "random", n_transitions=900)
    assert (small.id, smoke.id) == (
        "thesis-600/maze2d-umaze/random-v0",
        "thesis-900/maze2d-umaze/random-v0",
    )
    again = get_dataset("maze2d-umaze", "random", n_transitions=600)  # not overwritten
    assert (
        again.n_transitions == 600
        and get_dataset("maze2d-umaze", "random", n_transitions=900).n_transitions == 900
    )
    assert gen_dataset_id("hopper", "medium") == "thesis/hopper/medium-v0"
    assert gen_dataset_id("hopper", "medium", n_transitions=10**6) == "thesis-1m/hopper/medium-v0"
    ns = parse_dataset_id(small.id)[0]
    assert is_our_namespace(ns) and is_our_namespace("thesis") and not is_our_namespace("D4RL")
    assert small.metadata["thesis_info"]["generator_version"] == GENERATOR_VERSION


def test_an_old_recipe_set_says_how_to_rebuild(data_home):
    card = data_card(get_dataset("maze2d-umaze", "random", n_transitions=600))
    card["info"] = {**card["info"], "generator_version": GENERATOR_VERSION - 1}
    text = format_card(card)
    assert f"made by recipe version {GENERATOR_VERSION - 1}, this is {GENERATOR_VERSION}" in text
    assert "thesis data generate --task maze2d-umaze --tier random --n-transitions 600" in text


# --- Maze2D as D4RL: one fixed target per layout ----------------------------------------------


def test_maze_layouts_and_targets_are_d4rls():
    """gymnasium-robotics' maps are D4RL's layouts; the target is D4RL's G cell, exactly, at
    every reset; the reward is 1 within 0.5 of it; the task never ends early."""
    from gymnasium_robotics.envs.maze import maps

    d4rl_u = ["#####", "#GOO#", "###O#", "#OOO#", "#####"]  # d4rl maze_model.U_MAZE
    assert [["#" if c == 1 else "O" for c in r] for r in maps.U_MAZE] == [
        ["#" if c == "#" else "O" for c in r] for r in d4rl_u
    ]
    assert D4RL_TARGET_CELLS["PointMaze_UMaze-v3"] == (1, 1)
    env = make_env("maze2d-umaze")
    targets = []
    for seed in range(4):
        obs, _ = env.reset(seed=seed)
        targets.append(obs["desired_goal"].copy())
        assert not np.allclose(obs["achieved_goal"], obs["desired_goal"], atol=0.5)
    assert np.ptp(np.array(targets), axis=0).max() == 0.0  # the same point every episode
    u = env.unwrapped
    assert np.allclose(targets[0], u.maze.cell_rowcol_to_xy(np.array([1, 1])))
    ex = WaypointExpert(noise_std=0.0)  # drive to the env's (fixed) goal
    ex.reset(env)
    rng = np.random.default_rng(0)
    rewards, terms = [], []
    done = False
    while not done:
        obs, r, term, trunc, info = env.step(ex(obs, rng))
        at = np.linalg.norm(obs["achieved_goal"] - targets[0]) <= D4RL_TARGET_RADIUS
        assert r == float(at) == float(info["success"])
        rewards.append(r)
        terms.append(term)
        done = term or trunc
    assert not any(terms) and len(rewards) == 300  # D4RL's umaze episode, never cut short
    assert sum(rewards) > 150  # the expert reaches the target and stays: far above the floor
    env.close()


def test_maze_data_visit_random_goals_and_score_the_fixed_target():
    eps, info = make_episodes("maze2d-umaze", "expert", 3000, seed=0)
    assert info["target_cell"] == [1, 1] and "random goals" in info["algorithm"]
    target = eps[0].desired_goals[0]
    returns = []
    for e in eps:
        assert np.allclose(e.desired_goals, target)  # one target for the whole set
        near = np.linalg.norm(e.achieved_goals[1:] - target, axis=1) <= D4RL_TARGET_RADIUS
        assert np.array_equal(e.rewards, near.astype(float))  # D4RL's sparse reward
        returns.append(e.rewards.sum())
    # the recorder wanders to random goals: some episodes pass the target, some never do
    assert min(returns) == 0 and max(returns) > 0


@pytest.mark.slow
def test_bc_on_maze2d_umaze_is_above_the_floor(data_home):
    """With the fixed target, BC on maze2d-umaze/expert scores above the floor (zero return,
    normalised -17.3), as D4RL's BC does (3.8 normalised); under v1's goal-per-reset mazes it
    sat at the floor (study 04: BC -17.3)."""
    import torch

    from thesis_lib.seq import ArchSpec, EvalSpec, TrainSpec, run_offline

    torch.manual_seed(0)
    ds = get_dataset("maze2d-umaze", "expert")
    rows = run_offline(
        "BC",
        ds,
        ArchSpec(d_model=32, n_layers=1, n_heads=1, K=20, bc_hidden_dim=256),
        TrainSpec(iterations=1500, batch_size=64, eval_every=0),
        EvalSpec(episodes=10, targets=("max",)),
        task="maze2d-umaze",
    )
    assert rows[-1]["return_mean"] > 5.0, rows[-1]


# --- the medium tier spreads, and the card shows D4RL's figures --------------------------------


@pytest.mark.parametrize("task", ["hopper", "walker2d"])
def test_medium_tier_returns_spread(task):
    """D4RL's medium sets were sampled from the medium policy, so their returns spread; ours
    were once a deterministic roll-out (hopper: std 0.5 points, best 3% above the mean).
    (HalfCheetah's medium spreads by rare failed episodes, as D4RL's does: the band test judges
    it on 100 episodes.)"""
    eps, info = make_episodes(task, "medium", 6000, seed=0)
    assert "sampled" in info["algorithm"] or "perturbed" in info["algorithm"]
    from thesis_lib.data.tasks import get_task

    spec = get_task(task)
    r = np.array([e.rewards.sum() for e in eps if e.terminations[-1] or len(e.rewards) == 1000])
    norm = 100 * (r - spec.ref_min_score) / (spec.ref_max_score - spec.ref_min_score)
    assert len(norm) >= 5 and norm.std() > 5.0, norm


def test_d4rl_reference_figures_and_sources():
    hm = d4rl_stats("hopper", "medium")
    assert hm is not None and hm.name == "hopper-medium-v2"
    assert (round(hm.mean, 1), round(hm.std, 1), round(hm.min, 1), round(hm.max, 1)) == (
        44.3,
        11.6,
        10.3,
        99.6,
    )
    assert round(hm.mean_length) == 457
    me = d4rl_stats("walker2d", "medium-expert")
    m, e = d4rl_stats("walker2d", "medium"), d4rl_stats("walker2d", "expert")
    assert min(m.mean, e.mean) < me.mean < max(m.mean, e.mean) and me.episodes == 2191
    assert me.max == e.max and me.min == m.min
    for stats in D4RL_STATS.values():
        assert stats.source and all(k in SOURCES for k in stats.source)
    assert d4rl_stats("maze2d-umaze", "expert").mean is None  # not published
    assert d4rl_stats("ant", "medium") is None
    assert in_band(hm.mean - 9.9, 5.9, hm)[0] and not in_band(hm.mean - 10.1, 20.0, hm)[0]
    assert not in_band(hm.mean, 5.8, hm)[0]  # spread below half of D4RL's (11.64)


def test_the_card_prints_d4rl_beside_ours(data_home):
    card = data_card(get_dataset("hopper", "medium", n_transitions=3000))
    cmp = d4rl_comparison(card)
    assert cmp is not None and cmp["d4rl"].name == "hopper-medium-v2"
    assert isinstance(cmp["in_band"], bool) and "of 44.3" in cmp["why"]
    text = format_card(card)
    assert "hopper-medium-v2: 999,906 transitions, 2,187 episodes (mean length 457)" in text
    assert "normalised 44.3 ± 11.6 [10.3, 99.6]" in text
    assert "source" in text and "download_d4rl_datasets.py" in text
    for k in ("normalized_std", "normalized_min", "normalized_max", "mean_length"):
        assert np.isfinite(card[k]), k


#: Our tiers outside D4RL's band today, and why (issue #34); empty since the medium runs at
#: D4RL's level shipped. A row that leaves the band must be named here, and the test says which.
KNOWN_OUTSIDE: dict[tuple[str, str], str] = {}


@pytest.mark.slow
def test_our_tiers_beside_d4rls_band():
    """The band test of issue #34: a normalised mean within 10 points of D4RL's and a std of
    at least half of D4RL's, for hopper, walker2d and halfcheetah x medium, medium-replay and
    medium-expert, judged on at least 100 episodes (BAND_MIN_EPISODES). A chapter's smoke set
    (20k transitions) holds 20 to 134 episodes: where it holds fewer, the set is made at the
    size the card names (``band_transitions``). HalfCheetah's medium shows why: its 20-episode
    smoke set spreads 1.1 points, the 100-episode set 2.7 (D4RL's 2.9), the difference being
    the rare failed episodes that D4RL's set holds too (its minimum is -0.2)."""
    inside, outside, judged = set(), set(), {}
    for task in ("hopper", "walker2d", "halfcheetah"):
        for tier in ("medium", "medium-replay", "medium-expert"):
            cmp = d4rl_comparison(data_card(get_dataset(task, tier)))
            assert cmp is not None and isinstance(cmp["in_band"], bool)
            if cmp["band_transitions"] is not None:
                card = data_card(get_dataset(task, tier, n_transitions=cmp["band_transitions"]))
                assert card["episodes"] >= BAND_MIN_EPISODES, card["id"]
                cmp = d4rl_comparison(card)
                assert cmp is not None and cmp["band_transitions"] is None
            judged[(task, tier)] = cmp["why"]
            (inside if cmp["in_band"] else outside).add((task, tier))
    assert outside == set(KNOWN_OUTSIDE), (
        f"now outside: {sorted(outside)}; update KNOWN_OUTSIDE (and the README) to match. {judged}"
    )
    assert len(inside) == 9 - len(KNOWN_OUTSIDE)


def test_a_small_set_is_judged_with_the_size_that_holds_enough_episodes(data_home):
    """A set of fewer than BAND_MIN_EPISODES episodes gets its verdict with a caveat and the
    size to make; one with enough gets none."""
    assert band_transitions(20_000, 20) == 100_000
    assert band_transitions(20_000, 44) == 50_000  # 45,455 rounded up to 10k
    assert band_transitions(20_000, BAND_MIN_EPISODES) is None
    with pytest.raises(ValueError, match="positive"):
        band_transitions(1000, 0)
    cmp = d4rl_comparison(data_card(get_dataset("hopper", "medium", n_transitions=3000)))
    assert cmp is not None and cmp["band_transitions"] is not None
    assert f"--n-transitions {cmp['band_transitions']}" in cmp["why"]
    assert cmp["band_transitions"] % 10_000 == 0 and cmp["band_transitions"] > 3000
