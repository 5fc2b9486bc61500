"""D4RL-grade expert recipe (TQC/SAC exported to NumPy) and the data-set faults it fixed."""

from __future__ import annotations

import json

import numpy as np
import pytest

from thesis_lib import data
from thesis_lib.data import deep_experts, experts, recipe
from thesis_lib.data.deep_experts import DeepExpertConfig, MLPPolicy, export_actor


@pytest.fixture(autouse=True)
def _data_dirs(tmp_path, monkeypatch):
    monkeypatch.setenv("THESIS_DATA_DIR", str(tmp_path / "thesis"))
    monkeypatch.setenv("MINARI_DATASETS_PATH", str(tmp_path / "minari"))
    monkeypatch.setenv("THESIS_CACHE_DIR", str(tmp_path / "cache"))


TINY = DeepExpertConfig(
    algorithm="tqc",
    total_steps=600,
    learning_starts=100,
    snapshot_every=200,
    checkpoint_every=200,
    snapshot_eval_episodes=1,
    target_normalized=None,
    buffer_size=2_000,
    net_arch=(32, 32),
)


@pytest.mark.parametrize(
    "bad",
    [
        {"train_freq": 0},
        {"total_steps": -5},
        {"batch_size": 2.5},
        {"learning_starts": -1},
        {"learning_rate": 0.0},
        {"algorithm": "ppo"},
        {"critic_arch": ()},
        {"critic_arch": (64, 0)},
    ],
)
def test_deep_expert_config_rejects_bad_values_by_name(bad):
    with pytest.raises(ValueError, match=next(iter(bad))):
        DeepExpertConfig(**bad)


def test_mlp_policy_matches_a_hand_computed_squashed_gaussian():
    rng = np.random.default_rng(0)
    w = [rng.standard_normal((3, 4)), rng.standard_normal((4, 2)), rng.standard_normal((4, 2))]
    b = [rng.standard_normal(4), rng.standard_normal(2), rng.standard_normal(2)]
    pol = MLPPolicy(w, b, np.array([-2.0, 0.0]), np.array([2.0, 1.0]))
    obs = rng.standard_normal(3)
    h = np.maximum(obs @ w[0] + b[0], 0)
    u = np.tanh(h @ w[1] + b[1])
    expected = np.array([-2.0, 0.0]) + 0.5 * (u + 1) * np.array([4.0, 1.0])
    np.testing.assert_allclose(pol(obs), expected, rtol=1e-12)
    a = pol.sample(obs, np.random.default_rng(1))
    assert a.shape == (2,) and np.all(a >= [-2, 0]) and np.all(a <= [2, 1])
    assert not np.allclose(a, expected)  # sampling adds the actor's noise
    back = MLPPolicy.from_arrays(pol.to_arrays("x_"), pol.low, pol.high, prefix="x_")
    np.testing.assert_allclose(back(obs), pol(obs), rtol=1e-6)
    with pytest.raises(ValueError, match="No MLP policy"):
        MLPPolicy.from_arrays({}, pol.low, pol.high)


def test_training_resumes_from_its_checkpoint_and_export_equals_the_model(tmp_path):
    run = tmp_path / "run"
    st = deep_experts.train_deep_expert(
        "walker2d", TINY, run_dir=run, backend="sb3", max_wall_s=0.0, log=lambda s: None
    )
    assert (st.steps, st.checkpoint_steps, st.done) == (200, 200, False)
    assert (run / "model.zip").exists() and (run / "replay.pkl").exists()
    st = deep_experts.train_deep_expert(
        "walker2d", TINY, run_dir=run, backend="sb3", log=lambda s: None
    )
    assert st.done and st.stopped_by == "steps"
    assert [s["step"] for s in st.snapshots] == [200, 400, 600]
    # another config on the same folder is refused rather than mixed
    with pytest.raises(ValueError, match="another config"):
        deep_experts.train_deep_expert(
            "walker2d", DeepExpertConfig(total_steps=10), run_dir=run, backend="sb3"
        )
    # a larger step cap continues the finished run from its last checkpoint; a smaller is refused
    from dataclasses import replace

    with pytest.raises(ValueError, match="another config"):
        deep_experts.train_deep_expert(
            "walker2d", replace(TINY, total_steps=400), run_dir=run, backend="sb3"
        )
    st = deep_experts.train_deep_expert(
        "walker2d", replace(TINY, total_steps=800), run_dir=run, backend="sb3", log=lambda s: None
    )
    assert st.done and st.stopped_by == "steps" and st.config["total_steps"] == 800
    assert [s["step"] for s in st.snapshots] == [200, 400, 600, 800]
    from sb3_contrib import TQC

    model = TQC.load(run / "model.zip")
    assert model.num_timesteps == 800
    pol = export_actor(model, "sb3")
    obs = np.random.default_rng(0).standard_normal((4, 17)).astype(np.float32)
    np.testing.assert_allclose(pol(obs), model.predict(obs, deterministic=True)[0], atol=1e-5)


@pytest.mark.parametrize("backend", ["sb3", "sbx"])
def test_a_crossq_actor_exports_with_its_batch_renorm_folded_in(tmp_path, backend):
    """CrossQ normalises the actor's input and hidden layers with batch renormalisation; the
    export folds each into the next linear layer, so the NumPy policy is the same function
    (after training has moved the running statistics off 0 and 1)."""
    if backend == "sbx":
        pytest.importorskip("sbx")
    from dataclasses import replace

    cfg = replace(TINY, algorithm="crossq", total_steps=400, critic_arch=(64, 64))
    run = tmp_path / "run"
    st = deep_experts.train_deep_expert(
        "walker2d", cfg, run_dir=run, backend=backend, log=lambda s: None
    )
    assert st.done and st.config["critic_arch"] == [64, 64]
    model = deep_experts._algo_class("crossq", backend).load(run / "model.zip")
    if backend == "sb3":
        qf = [m.out_features for m in model.policy.critic.qf0 if hasattr(m, "out_features")]
        assert qf[:2] == [64, 64]  # the critics are as wide as critic_arch, not the actor
        norms = [m for m in model.policy.actor.latent_pi if hasattr(m, "ra_var")]
        assert len(norms) == 3 and not np.allclose(norms[0].ra_mean.numpy(), 0)
    pol = export_actor(model, backend)
    assert [w.shape for w in pol.weights] == [(17, 32), (32, 32), (32, 6), (32, 6)]
    obs = np.random.default_rng(0).standard_normal((5, 17)).astype(np.float32) * 3
    np.testing.assert_allclose(pol(obs), model.predict(obs, deterministic=True)[0], atol=1e-5)
    snap = MLPPolicy.from_arrays(
        np.load(run / "snapshots" / st.snapshots[-1]["file"]), pol.low, pol.high
    )
    np.testing.assert_allclose(snap(obs), pol(obs), atol=1e-6)  # snapshots are the folded actor


def test_folding_a_normalisation_into_a_linear_layer_is_exact():
    rng = np.random.default_rng(0)
    mean, var, g, beta = rng.standard_normal(3), rng.random(3) + 0.1, rng.random(3), rng.random(3)
    w, b, x = rng.standard_normal((3, 2)), rng.standard_normal(2), rng.standard_normal((4, 3))
    scale, shift = deep_experts._bn_affine(mean, var, g, beta, 1e-3)
    w2, b2 = deep_experts._fold_affine(scale, shift, w, b)
    expected = ((x - mean) / np.sqrt(var + 1e-3) * g + beta) @ w + b
    np.testing.assert_allclose(x @ w2 + b2, expected, rtol=1e-12)


def test_train_expert_cli_switches_algorithm_with_its_learning_rate(monkeypatch, capsys):
    from thesis_lib.cli import main

    seen = {}

    def fake_train(task, cfg, **kw):
        seen["cfg"] = cfg
        return deep_experts.RunState(task=task, config={}, backend="sb3")

    monkeypatch.setattr(deep_experts, "train_deep_expert", fake_train)
    argv = ["data", "train-expert", "--task", "walker2d", "--algorithm", "crossq"]
    assert main([*argv, "--critic-arch", "512,512"]) == 0
    cfg = seen["cfg"]
    assert (cfg.algorithm, cfg.learning_rate, cfg.critic_arch) == ("crossq", 1e-3, (512, 512))
    assert main([*argv, "--learning-rate", "3e-4"]) == 0
    assert seen["cfg"].learning_rate == 3e-4 and seen["cfg"].critic_arch is None
    # leaving Ant's CrossQ recipe for TQC takes TQC's rate and plain critics, as TQC's run had
    assert main(["data", "train-expert", "--task", "ant", "--algorithm", "tqc"]) == 0
    assert (seen["cfg"].learning_rate, seen["cfg"].critic_arch) == (3e-4, None)
    assert main([*argv, "--critic-arch", "512,0"]) == 2
    assert "critic_arch must be whole numbers" in capsys.readouterr().err


def test_train_expert_medium_trains_then_ships_only_a_finished_run(monkeypatch, capsys, tmp_path):
    """``--medium``: the task's medium recipe trains in ``<runs>/<task>-medium``; an unfinished
    run ships nothing (unless ``--ship``), ``--ship-only`` ships without training."""
    import json
    from types import SimpleNamespace

    from thesis_lib.cli import main

    calls = []

    def fake_train(task, cfg, run_dir=None, **kw):
        calls.append(("train", task, cfg.total_steps, run_dir.name))
        return deep_experts.RunState(task=task, config={}, backend="sb3")  # not done

    def fake_ship(task, run_dir, **kw):
        calls.append(("ship", task, run_dir.name))
        return SimpleNamespace(
            expert_step=9, medium_normalized=40.0, medium_sampled_normalized=41.0
        )

    monkeypatch.setattr(deep_experts, "train_deep_expert", fake_train)
    monkeypatch.setattr(deep_experts, "ship_medium_run", fake_ship)
    monkeypatch.setattr(deep_experts, "runs_dir", lambda: tmp_path)
    argv = ["data", "train-expert", "--task", "hopper", "--medium"]
    assert main([*argv, "--steps", "1000"]) == 0
    assert calls == [("train", "hopper", 1000, "hopper-medium")]
    assert main([*argv, "--ship"]) == 0 and calls[-1] == ("ship", "hopper", "hopper-medium")
    calls.clear()
    capsys.readouterr()
    assert main([*argv, "--ship-only"]) == 0 and calls == [("ship", "hopper", "hopper-medium")]
    out = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert out == {
        "task": "hopper",
        "medium_step": 9,
        "medium_normalized": 40.0,
        "medium_sampled_normalized": 41.0,
    }
    assert main(["data", "train-expert", "--task", "ant", "--medium"]) == 2
    assert "No medium-run recipe for 'ant'" in capsys.readouterr().err


def test_train_freq_batches_updates_and_old_runs_resume_under_the_default(tmp_path):
    """``train_freq`` N collects N steps, then takes N gradient steps (ratio 1); a run whose
    state predates the field resumes as a run of its default, 1."""
    from dataclasses import replace

    run = tmp_path / "run"
    cfg = replace(TINY, total_steps=400, train_freq=50)
    st = deep_experts.train_deep_expert(
        "walker2d", cfg, run_dir=run, backend="sb3", max_wall_s=0.0, log=lambda s: None
    )
    assert st.config["train_freq"] == 50
    from sb3_contrib import TQC

    model = TQC.load(run / "model.zip")
    assert (model.train_freq.frequency, model.gradient_steps) == (50, 50)
    assert model._n_updates == 200 - TINY.learning_starts  # one gradient step per env step

    old = tmp_path / "old"
    deep_experts.train_deep_expert(
        "walker2d", TINY, run_dir=old, backend="sb3", max_wall_s=0.0, log=lambda s: None
    )
    state = json.loads((old / "state.json").read_text())
    del state["config"]["train_freq"]  # as written before the field existed
    (old / "state.json").write_text(json.dumps(state))
    st = deep_experts.train_deep_expert(
        "walker2d", TINY, run_dir=old, backend="sb3", max_wall_s=0.0, log=lambda s: None
    )
    assert st.steps == 400  # resumed at 200, not refused
    with pytest.raises(ValueError, match="another config"):
        deep_experts.train_deep_expert("walker2d", cfg, run_dir=old, backend="sb3")


def test_shipping_a_run_whose_first_snapshot_is_best_says_it_has_not_learned(tmp_path, monkeypatch):
    """Ant's untrained start earns the healthy bonus: if no later snapshot beats it, there is
    no earlier one to be the medium policy, and the error says so (not an empty ``min``)."""
    run = tmp_path / "run"
    deep_experts.train_deep_expert("walker2d", TINY, run_dir=run, backend="sb3", log=lambda s: None)
    monkeypatch.setattr(
        deep_experts, "_load_snapshot", lambda folder, snap, low, high: snap["step"]
    )
    monkeypatch.setattr(  # the 'policy' is its step: the first scores best
        deep_experts, "evaluate", lambda pol, task, n, seed=0: np.full(n, 1_000.0 - pol)
    )
    with pytest.raises(ValueError, match=r"is its first \(step 200.*has not learned yet"):
        deep_experts.ship_deep_expert(
            "walker2d", run_dir=run, out_dir=tmp_path / "out", log=lambda s: None
        )
    assert not (tmp_path / "out" / "walker2d.npz").exists()


def test_shipped_run_makes_every_tier_with_independent_halves(tmp_path, monkeypatch):
    run = tmp_path / "run"
    deep_experts.train_deep_expert("walker2d", TINY, run_dir=run, backend="sb3", log=lambda s: None)
    out = tmp_path / "policies"
    rec = deep_experts.ship_deep_expert(
        "walker2d",
        run_dir=run,
        out_dir=out,
        n_eval_episodes=2,
        n_select_episodes=1,
        log=lambda s: None,
    )
    assert rec.policy_kind == "mlp" and rec.steps_trained == 600
    assert rec.checkpoint_steps[-1] < rec.expert_step
    saved = json.loads((out / "walker2d.json").read_text())
    assert saved["expert_step"] == rec.expert_step
    monkeypatch.setattr(experts, "POLICY_DIR", out)
    assert isinstance(data.load_policy("walker2d", "expert"), MLPPolicy)
    with pytest.raises(ValueError, match="not shipped"):
        data.load_policy("walker2d", "ckpt99")

    med, _ = recipe.make_episodes("walker2d", "medium", 300, seed=0)
    exp, _ = recipe.make_episodes("walker2d", "expert", 300, seed=0)
    both, _ = recipe.make_episodes("walker2d", "medium-expert", 300, seed=0)
    assert sum(len(e) for e in both) == 600
    np.testing.assert_array_equal(both[0].observations, med[0].observations)
    np.testing.assert_array_equal(both[len(med)].observations, exp[0].observations)
    # D4RL collected the two halves independently: no shared initial state
    assert not np.allclose(med[0].observations[0], exp[0].observations[0])

    replay, info = recipe.make_episodes("walker2d", "medium-replay", 500, seed=0)
    assert sum(len(e) for e in replay) == 500
    assert "warm-up" in info["algorithm"] and info["generator_version"] == recipe.GENERATOR_VERSION


def test_a_truncated_set_names_its_id_and_the_rebuild_command():
    did = data.generate("hopper", "random", n_transitions=50)
    h5 = data.storage.find_dataset(did) / "data" / "main_data.hdf5"
    raw = h5.read_bytes()
    h5.write_bytes(raw[: len(raw) // 2])
    with pytest.raises(data.DamagedDatasetError) as err:
        data.load(did)
    msg = str(err.value)
    assert did in msg and "thesis data generate --task hopper --tier random" in msg


def test_an_interrupted_write_leaves_no_set_and_keeps_the_old_one(monkeypatch):
    did = data.generate("hopper", "random", n_transitions=50)
    before = data.load(did).n_transitions

    def boom(*a, **k):
        raise KeyboardInterrupt

    monkeypatch.setattr(data.storage, "_write", boom)
    with pytest.raises(KeyboardInterrupt):
        data.generate("hopper", "random", n_transitions=80)
    assert data.load(did).n_transitions == before  # the old set is intact
    root = data.data_dir()
    assert not [p for p in root.iterdir() if p.name.startswith(".staging")]
    assert data.list_datasets() == [did]


def test_maze2d_open_has_d4rls_reference_returns():
    assert data.normalized_score("maze2d-open", 20.66) == pytest.approx(100.0)
    assert data.normalized_score("maze2d-open", 0.01) == pytest.approx(0.0)


@pytest.mark.parametrize("task", sorted(deep_experts.DEEP_EXPERT_CONFIGS))
def test_each_shipped_expert_was_trained_by_its_recipe(task):
    """``thesis data train-expert --task <task>`` reproduces the shipped policy: the record's
    config is the recipe's (fields added since the run at their defaults, as a resume reads
    them), and the expert meets the issue's D4RL-normalised target on its 100 episodes."""
    from dataclasses import asdict

    rec = experts.load_policy_record(task)
    assert rec.policy_kind == "mlp" and rec.n_eval_episodes == 100
    shipped = {k: v for k, v in rec.config.items() if k != "backend"}
    want = deep_experts._jsonable(asdict(deep_experts.DEEP_EXPERT_CONFIGS[task]))
    assert deep_experts.recorded_config(shipped) == want
    target = {"walker2d": 90.0, "halfcheetah": 85.0, "ant": 90.0}[task]
    assert rec.expert_normalized >= target
    assert rec.expert_normalized == pytest.approx(
        data.normalized_score(task, rec.expert_return_mean)
    )


def test_a_separate_medium_run_feeds_the_medium_tiers_and_not_the_expert(tmp_path, monkeypatch):
    """Issue #34: D4RL's medium sets sit above "a third of the expert", so a task may ship a
    medium run apart from its expert (``<task>-medium``); the medium and medium-replay tiers
    then come from it, sampled, and the expert tier from the expert run."""
    run = tmp_path / "run"
    deep_experts.train_deep_expert("walker2d", TINY, run_dir=run, backend="sb3", log=lambda s: None)
    out = tmp_path / "policies"
    deep_experts.ship_deep_expert(
        "walker2d",
        run_dir=run,
        out_dir=out,
        n_eval_episodes=2,
        n_select_episodes=1,
        log=lambda s: None,
    )
    monkeypatch.setattr(experts, "POLICY_DIR", out)
    before = experts.policy_fingerprint("walker2d")
    assert not experts.has_medium_run("walker2d")
    rec = deep_experts.ship_medium_run(
        "walker2d",
        run,
        out_dir=out,
        target_normalized=1.0,
        n_candidates=2,
        n_select_episodes=1,
        n_eval_episodes=2,
        log=lambda s: None,
    )
    assert experts.has_medium_run("walker2d") and rec.role == "medium"
    assert rec.medium_sampled_normalized is not None and rec.checkpoint_steps[-1] == rec.expert_step
    assert experts.policy_fingerprint("walker2d") != before  # sets made before are made again
    assert experts.load_policy_record("walker2d", "medium").role == "medium"
    assert experts.load_policy_record("walker2d").role == "expert"
    _, med = recipe.make_episodes("walker2d", "medium", 200, seed=0)
    _, exp = recipe.make_episodes("walker2d", "expert", 200, seed=0)
    _, rep = recipe.make_episodes("walker2d", "medium-replay", 300, seed=0)
    assert med["policy"]["role"] == "medium" and "sampled" in med["algorithm"]
    assert exp["policy"]["role"] == "expert" and rep["policy"]["role"] == "medium"
    with pytest.raises(ValueError, match="Unknown role"):
        experts.load_policy_record("walker2d", "replay")
