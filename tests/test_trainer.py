"""Tests for thesis_lib.seq.trainer and thesis_lib.seq.evaluation (thesis 5.2.5)."""

from __future__ import annotations

import re

import gymnasium as gym
import numpy as np
import pandas as pd
import pytest
import torch
import torch.nn as nn

from thesis_lib.data import Episode, SequenceDataset
from thesis_lib.seq.dropout import lane_dropout_enabled
from thesis_lib.seq.evaluation import evaluate
from thesis_lib.seq.models import (
    BC,
    HDT,
    BCConfig,
    DecisionTransformer,
    DTConfig,
    HDTConfig,
    SeqOutput,
    readout_only,
    readout_only_enabled,
)
from thesis_lib.seq.subgoals import subgoal_fn
from thesis_lib.seq.trainer import TrainConfig, Trainer, batch_to_torch

torch.set_num_threads(1)
SD, AD, K = 3, 2, 4
SMALL = dict(K=K, d_model=16, n_layers=1, n_heads=1, dropout=0.1)


def _expert(obs):
    return np.tanh(obs[..., :AD] * 2.0)


def _episodes(n=6, T=30, seed=0):
    rng = np.random.default_rng(seed)
    eps = []
    for i in range(n):
        obs = rng.normal(size=(T + 1, SD))
        act = _expert(obs[:-1]).astype(np.float32)
        eps.append(Episode(i, obs, act, obs[:-1, 0] + 1.0, np.zeros(T, bool), np.zeros(T, bool)))
    return eps


def _dataset(seed=0, paper_compat=False):
    return SequenceDataset(
        _episodes(), K=K, subgoal_fn=subgoal_fn(paper_compat), paper_compat=paper_compat, seed=seed
    )


def _model(kind, paper_compat=False):
    torch.manual_seed(0)
    if kind == "bc":
        return BC(BCConfig(SD, AD, K=K, hidden_dim=32))
    if kind == "dt":
        return DecisionTransformer(DTConfig(SD, AD, paper_compat=paper_compat, **SMALL))
    return HDT(HDTConfig(SD, AD, paper_compat=paper_compat, **SMALL))


def _cfg(**kw):
    return TrainConfig(
        **{**dict(iterations=60, batch_size=8, warmup_steps=5, lr=3e-3, progress=False), **kw}
    )


@pytest.mark.parametrize(
    "kind,paper_compat", [("bc", False), ("dt", False), ("hdt", False), ("dt", True), ("hdt", True)]
)
def test_loss_falls_on_a_tiny_dataset(kind, paper_compat):
    trainer = Trainer(_model(kind, paper_compat), _dataset(paper_compat=paper_compat), _cfg())
    h = trainer.train()
    assert len(h) == 60 and h["iteration"].tolist() == list(range(1, 61))
    assert h["loss"].iloc[-10:].mean() < 0.5 * h["loss"].iloc[:10].mean()
    if kind == "hdt":
        assert {"loss_subgoal", "loss_action"} <= set(h.columns)


def test_trainer_leaves_the_global_rng_alone():
    torch.manual_seed(5)
    expected = torch.rand(3)
    trainer = Trainer(_model("dt"), _dataset(), _cfg(iterations=3))
    torch.manual_seed(5)
    trainer.train()
    torch.testing.assert_close(torch.rand(3), expected)


def test_same_seed_same_numbers():
    def run(seed):
        trainer = Trainer(_model("hdt"), _dataset(seed=seed), _cfg(iterations=15, seed=seed))
        return trainer.train()["loss"].to_numpy(), torch.nn.utils.parameters_to_vector(
            trainer.model.parameters()
        )

    (l1, p1), (l2, p2), (l3, _) = run(0), run(0), run(1)
    np.testing.assert_array_equal(l1, l2)
    torch.testing.assert_close(p1, p2, rtol=0, atol=0)
    assert not np.array_equal(l1, l3)


@pytest.mark.parametrize("kind", ["dt", "hdt"])
def test_resume_matches_an_uninterrupted_run(kind, tmp_path):
    full = Trainer(_model(kind), _dataset(), _cfg(iterations=12))
    h_full = full.train()

    path = tmp_path / "ckpt.pt"
    first = Trainer(
        _model(kind), _dataset(), _cfg(iterations=12, checkpoint_path=str(path), checkpoint_every=5)
    )
    first.train(iterations=6)  # stopped after 6 of 12
    torch.manual_seed(123)  # a fresh process: other global RNG, other initial weights
    second = Trainer(
        _model(kind), _dataset(seed=99), _cfg(iterations=12, checkpoint_path=str(path))
    )
    assert second.iteration == 6  # resumed from the checkpoint at construction
    h_resumed = second.train()
    np.testing.assert_array_equal(h_resumed["loss"].to_numpy(), h_full["loss"].to_numpy())
    for a, b in zip(full.model.parameters(), second.model.parameters()):
        torch.testing.assert_close(a, b, rtol=0, atol=0)


@pytest.mark.parametrize("kind", ["dt", "hdt"])
def test_bf16_trains_in_bfloat16_and_learns_as_float32_does(kind):
    """Mixed precision: the step's matrix products run in bfloat16 while the parameters,
    gradients and evaluation stay float32, and the run learns as the float32 run does (the two
    differ by rounding only, so their losses agree closely but not exactly)."""
    seen: list[torch.dtype] = []

    def run(precision):
        trainer = Trainer(_model(kind), _dataset(), _cfg(iterations=80, precision=precision))
        for m in trainer.model.modules():
            if isinstance(m, nn.Linear):
                m.register_forward_hook(lambda m, i, o: seen.append(o.dtype))
        return trainer, trainer.train()["loss"].to_numpy()

    t32, loss32 = run("fp32")
    assert set(seen) == {torch.float32}
    seen.clear()
    t16, loss16 = run("bf16")
    assert set(seen) == {torch.bfloat16}
    # the loss keeps float32 under autocast (the heads predict in bf16)
    batch = batch_to_torch(t16.dataset, t16.dataset.sample(4), "cpu")
    with torch.autocast("cpu", dtype=torch.bfloat16):
        assert t16.model(batch, targets=batch).loss.dtype == torch.float32
    # evaluation is float32: an eval_fn sees no autocast
    during_eval: list[bool] = []
    t16.eval_fn = lambda m: during_eval.append(torch.is_autocast_enabled("cpu")) or 0.0
    t16.config.eval_every = 40
    t16.train(iterations=120)
    assert during_eval == [False]
    # both learn, to the same level; not the same numbers
    assert loss16[-10:].mean() < 0.5 * loss16[:10].mean()
    assert loss16[0] == pytest.approx(loss32[0], rel=0.02)
    assert loss16[-20:].mean() == pytest.approx(loss32[-20:].mean(), rel=0.2)
    assert not np.array_equal(loss16, loss32)


def test_fast_kernels_without_dropout_are_torchs_numbers_up_to_rounding():
    """With no dropout, ``kernels="fast"`` differs from ``"torch"`` only by fused AdamW's
    rounding: the same run."""

    def run(kernels):
        torch.manual_seed(0)
        model = DecisionTransformer(DTConfig(SD, AD, **{**SMALL, "dropout": 0.0}))
        trainer = Trainer(model, _dataset(), _cfg(iterations=30, kernels=kernels))
        loss = trainer.train()["loss"].to_numpy()
        return trainer, loss, nn.utils.parameters_to_vector(model.parameters()).detach()

    t_torch, l_torch, p_torch = run("torch")
    t_fast, l_fast, p_fast = run("fast")
    assert t_fast.optimizer.defaults["fused"] and not t_torch.optimizer.defaults["fused"]
    np.testing.assert_allclose(l_fast, l_torch, rtol=1e-4)
    torch.testing.assert_close(p_fast, p_torch, rtol=1e-4, atol=1e-5)


@pytest.mark.parametrize("kind", ["bc", "dt", "hdt"])
def test_fast_kernels_draw_lane_masks_and_learn_as_torchs_do(kind):
    """With dropout, ``kernels="fast"`` trains with lane masks (other draws: not the same
    numbers) and learns as the torch run does; evaluation is outside the lane context."""
    seen: list[bool] = []

    def run(kernels):
        trainer = Trainer(_model(kind), _dataset(), _cfg(iterations=80, kernels=kernels))
        trainer.model.register_forward_hook(lambda m, i, o: seen.append(lane_dropout_enabled()))
        return trainer, trainer.train()["loss"].to_numpy()

    _, loss_torch = run("torch")
    assert set(seen) == {False}
    seen.clear()
    t_fast, loss_fast = run("fast")
    assert set(seen) == {True}
    during_eval: list[bool] = []
    t_fast.eval_fn = lambda m: during_eval.append(lane_dropout_enabled()) or 0.0
    t_fast.config.eval_every = 40
    t_fast.train(iterations=120)
    assert during_eval == [False]
    assert not np.array_equal(loss_fast, loss_torch)
    assert loss_fast[0] == pytest.approx(loss_torch[0], rel=0.1)
    assert loss_fast[-10:].mean() < 0.5 * loss_fast[:10].mean()
    assert loss_fast[-20:].mean() == pytest.approx(loss_torch[-20:].mean(), rel=0.25)


@pytest.mark.parametrize("kind", ["dt", "hdt"])
@pytest.mark.parametrize("n_layers", [1, 2])
def test_readout_kernels_without_dropout_are_fasts_numbers_up_to_float_error(kind, n_layers):
    """``kernels="fast+readout"`` runs the transformers' last block on the read tokens only:
    with no dropout it is ``"fast"``'s run (losses and weights after 30 updates) up to float
    error, on windows with padding (the episodes' first steps) as without."""

    def run(kernels):
        torch.manual_seed(0)
        arch = {**SMALL, "dropout": 0.0, "n_layers": n_layers}
        cfg = (DTConfig if kind == "dt" else HDTConfig)(SD, AD, **arch)
        model = (DecisionTransformer if kind == "dt" else HDT)(cfg)
        trainer = Trainer(model, _dataset(), _cfg(iterations=30, kernels=kernels))
        loss = trainer.train()["loss"].to_numpy()
        return trainer, loss, nn.utils.parameters_to_vector(model.parameters()).detach()

    t_fast, l_fast, p_fast = run("fast")
    t_read, l_read, p_read = run("fast+readout")
    assert t_read.optimizer.defaults["fused"]
    np.testing.assert_allclose(l_read, l_fast, rtol=1e-5)
    torch.testing.assert_close(p_read, p_fast, rtol=1e-4, atol=1e-5)
    batch = batch_to_torch(None, _dataset(seed=1).sample(64))
    assert not bool(batch["mask"].all())  # padding is exercised
    model = t_read.model.eval()
    with torch.no_grad():
        full = model(batch, targets=batch)
        with readout_only():
            part = model(batch, targets=batch)
    torch.testing.assert_close(part.actions, full.actions, atol=1e-6, rtol=0)
    torch.testing.assert_close(part.loss, full.loss)
    if kind == "hdt":
        torch.testing.assert_close(part.subgoals, full.subgoals, atol=1e-6, rtol=0)


def test_readout_kernels_train_with_dropout_and_evaluate_in_full():
    """With dropout, ``"fast+readout"`` trains inside :func:`readout_only` and the lane masks,
    learns as ``"torch"`` does (other draws), and evaluates outside both."""
    seen: list[tuple[bool, bool]] = []

    def run(kernels):
        trainer = Trainer(_model("dt"), _dataset(), _cfg(iterations=80, kernels=kernels))
        trainer.model.register_forward_hook(
            lambda m, i, o: seen.append((readout_only_enabled(), lane_dropout_enabled()))
        )
        return trainer, trainer.train()["loss"].to_numpy()

    _, loss_torch = run("torch")
    assert set(seen) == {(False, False)}
    seen.clear()
    t_read, loss_read = run("fast+readout")
    assert set(seen) == {(True, True)}
    during_eval: list[bool] = []
    t_read.eval_fn = lambda m: during_eval.append(readout_only_enabled()) or 0.0
    t_read.config.eval_every = 40
    t_read.train(iterations=120)
    assert during_eval == [False]
    assert not np.array_equal(loss_read, loss_torch)
    assert loss_read[-10:].mean() < 0.5 * loss_read[:10].mean()
    assert loss_read[-20:].mean() == pytest.approx(loss_torch[-20:].mean(), rel=0.25)


def test_token_transformer_read_errors_and_outputs():
    model = _model("dt").eval()
    batch = batch_to_torch(None, _dataset().sample(4))
    tokens = [torch.randn(4, K, SMALL["d_model"]) for _ in range(3)]
    trunk = model.transformer
    with torch.no_grad():
        every = trunk(tokens, batch["timesteps"], batch["mask"])
        assert len(every) == 3
        torch.testing.assert_close(
            trunk(tokens, batch["timesteps"], batch["mask"], read=1), every[1]
        )
        with readout_only():
            one = trunk(tokens, batch["timesteps"], batch["mask"], read=-1)
        torch.testing.assert_close(one, every[2], atol=1e-6, rtol=0)
    with pytest.raises(
        ValueError, match=r"Expect `read` in \[-3, 3\) for 3 token\(s\), actually: 3"
    ):
        trunk(tokens, batch["timesteps"], read=3)


def test_an_unknown_kernels_is_a_clear_error():
    with pytest.raises(ValueError, match=r"Unknown kernels 'triton'\. Valid: torch, fast"):
        TrainConfig(kernels="triton")
    from thesis_lib.seq.runner import TrainSpec

    with pytest.raises(ValueError, match=r"Unknown kernels 'triton'"):
        TrainSpec(kernels="triton")
    # left out of a task's key at its default, as every task stored before it ran
    assert "kernels" not in TrainSpec().task_dict()
    assert TrainSpec(kernels="fast").task_dict()["kernels"] == "fast"
    assert TrainSpec(kernels="fast+readout").task_dict()["kernels"] == "fast+readout"
    assert TrainSpec.from_task(TrainSpec().task_dict()).kernels == "torch"


def test_an_unknown_precision_is_a_clear_error():
    with pytest.raises(ValueError, match=r"Unknown precision 'fp16'\. Valid: fp32, bf16"):
        TrainConfig(precision="fp16")


@pytest.mark.parametrize("chapter", ["hdt", "decision_mamba", "ur3"])
def test_a_chapters_precision_reaches_the_trainer(chapter, monkeypatch):
    """``-p precision bf16`` (and ``-p kernels fast``) of a chapter goes to its runs' TrainSpec, and run_offline hands it
    to the Trainer."""
    import importlib

    from thesis_lib.seq import runner

    mod = importlib.import_module(f"thesis_lib.chapters.{chapter}")
    assert mod.Config().train_spec(0).precision == "fp32"
    assert mod.Config().train_spec(0).kernels == "torch"
    spec = mod.Config(precision="bf16", kernels="fast").train_spec(0)
    assert spec.precision == "bf16" and spec.kernels == "fast"

    class Stop(Exception):
        pass

    def capture(model, seq, config, eval_fn=None):
        raise Stop(f"{config.precision} {config.kernels}")

    monkeypatch.setattr(runner, "Trainer", capture)
    with pytest.raises(Stop, match="bf16 fast"):
        runner.run_offline("DT", _episodes(), runner.ArchSpec(K=K, d_model=16, n_layers=1), spec,
                           runner.EvalSpec(episodes=1), task="hopper")  # fmt: skip


def _checkpointed(path):
    """A tiny DT run of 10 iterations that leaves its checkpoint at ``path``."""
    trainer = Trainer(_model("dt"), _dataset(), _cfg(iterations=10, checkpoint_path=str(path)))
    trainer.train()
    return trainer


@pytest.mark.parametrize(
    "change,differs",
    [
        (dict(seed=1), "seed: 0 -> 1"),
        (dict(lr=1e-3), "lr: 0.003 -> 0.001"),
        (dict(weight_decay=0.0), "weight_decay: 0.0001 -> 0.0"),
        (dict(warmup_steps=2), "warmup_steps: 5 -> 2"),
        (dict(batch_size=4), "batch_size: 8 -> 4"),
        (dict(grad_clip=1.0), "grad_clip: 0.25 -> 1.0"),
        (dict(precision="bf16"), "precision: (absent) -> 'bf16'"),
        (dict(kernels="fast"), "kernels: (absent) -> 'fast'"),
    ],
)
def test_a_checkpoint_is_not_resumed_by_another_training_config(tmp_path, change, differs):
    path = tmp_path / "ckpt.pt"
    _checkpointed(path)
    with pytest.raises(ValueError, match=re.escape(differs)) as err:
        Trainer(_model("dt"), _dataset(), _cfg(iterations=20, checkpoint_path=str(path), **change))
    msg = str(err.value)
    assert str(path) in msg and "resume=False" in msg and "\n" not in msg
    # resume=False starts afresh (and its checkpoints replace the old one)
    fresh = Trainer(
        _model("dt"),
        _dataset(),
        _cfg(iterations=3, checkpoint_path=str(path), resume=False, **change),
    )
    assert fresh.iteration == 0 and len(fresh.train()) == 3


def test_a_checkpoint_is_not_resumed_by_another_model_or_data_set(tmp_path):
    path = tmp_path / "ckpt.pt"
    _checkpointed(path)
    cfg = _cfg(iterations=20, checkpoint_path=str(path))
    torch.manual_seed(0)
    wider = DecisionTransformer(DTConfig(SD, AD, **{**SMALL, "d_model": 32}))
    with pytest.raises(ValueError, match=r"model\.d_model: 16 -> 32"):
        Trainer(wider, _dataset(), cfg)
    other_data = SequenceDataset(_episodes(seed=1), K=K, subgoal_fn=subgoal_fn(False))
    with pytest.raises(ValueError, match=r"data\.sha256: '\w+' -> '\w+'"):
        Trainer(_model("dt"), other_data, cfg)
    fewer = SequenceDataset(_episodes(n=5), K=K, subgoal_fn=subgoal_fn(False))
    with pytest.raises(ValueError, match=r"data\.size: 180 -> 150"):
        Trainer(_model("dt"), fewer, cfg)
    # the same data sampled with another seed is the same data set: resumed
    assert Trainer(_model("dt"), _dataset(seed=7), cfg).iteration == 10


def test_a_checkpoint_grows_to_more_iterations_and_refuses_fewer(tmp_path):
    path = tmp_path / "ckpt.pt"
    _checkpointed(path)
    more = Trainer(_model("dt"), _dataset(), _cfg(iterations=15, checkpoint_path=str(path)))
    assert more.iteration == 10
    h = more.train()
    assert h["iteration"].tolist() == list(range(1, 16))  # continued up to the new total
    with pytest.raises(ValueError, match=r"holds 15 iterations, more than iterations=10"):
        Trainer(_model("dt"), _dataset(), _cfg(iterations=10, checkpoint_path=str(path)))
    with pytest.raises(ValueError, match=r"Expect `iterations` >= 15 .*actually: 12"):
        more.train(iterations=12)


def test_a_checkpoint_that_does_not_record_its_run_is_refused(tmp_path):
    path = tmp_path / "ckpt.pt"
    _checkpointed(path)
    old = torch.load(path, weights_only=True)
    del old["made_by"]  # as the code before the record wrote them
    torch.save(old, path)
    with pytest.raises(ValueError, match="does not record what made it") as err:
        Trainer(_model("dt"), _dataset(), _cfg(iterations=20, checkpoint_path=str(path)))
    assert str(path) in str(err.value) and "resume=False" in str(err.value)


def test_the_readme_example_gives_the_same_numbers_twice(tmp_path, monkeypatch):
    """The README's library example, as written there (``torch.manual_seed(0)`` before the
    model: the Trainer uses the model's initial weights as they are), at a few iterations."""
    from thesis_lib import data

    monkeypatch.setenv("THESIS_DATA_DIR", str(tmp_path))
    ds = data.get_dataset("hopper", "medium", n_transitions=300)

    def example(seeded=True):  # as a script run twice: the batches' generator starts afresh too
        seq = data.SequenceDataset(ds, K=20)
        if seeded:
            torch.manual_seed(0)
        model = DecisionTransformer(DTConfig.for_data(seq, d_model=32, n_layers=1))
        return Trainer(
            model, seq, TrainConfig(iterations=3, warmup_steps=10, progress=False)
        ).train()

    np.testing.assert_array_equal(example()["loss"], example()["loss"])
    # without the seed (the example before): other initial weights, other numbers
    assert not np.array_equal(example(seeded=False)["loss"], example(seeded=False)["loss"])


def test_dataset_model_mismatch_is_a_clear_error():
    with pytest.raises(ValueError, match=r"state_dim=11, but the data set's states have size 3"):
        Trainer(DecisionTransformer(DTConfig(11, AD, **SMALL)), _dataset(), _cfg())
    no_goals = SequenceDataset(_episodes(), K=K)
    with pytest.raises(ValueError, match="HDT needs sub-goals"):
        Trainer(_model("hdt"), no_goals, _cfg())
    with pytest.raises(ValueError, match="K=4"):
        Trainer(_model("dt"), SequenceDataset(_episodes(), K=8), _cfg())
    with pytest.raises(ValueError, match="Unknown device"):
        TrainConfig(device="gpu")


def test_prev_subgoals_come_from_the_episode():
    seq = _dataset()
    batch = seq.windows(
        np.array([0, 1, 2]), np.array([0, 5, 28])
    )  # starts: episode start, inside, near the end
    t = batch_to_torch(seq, batch)
    prev = t["prev_subgoals"].numpy()
    np.testing.assert_array_equal(prev[0, 0], 0.0)  # g_{-1} = 0
    np.testing.assert_array_equal(
        prev[1, 0], seq.subgoals[seq.offsets[1] + 4]
    )  # g_4 before a window at 5
    np.testing.assert_array_equal(
        prev[:, 1:][batch.mask[:, 1:]], batch.subgoals[:, :-1][batch.mask[:, 1:]]
    )
    assert not prev[2, 2:].any()  # padding


def test_eval_callback_every_n_iterations():
    calls = []

    def eval_fn(model):
        calls.append(model.training)
        return float(len(calls))

    h = Trainer(
        _model("bc"), _dataset(), _cfg(iterations=10, eval_every=4), eval_fn=eval_fn
    ).train()
    assert calls == [False, False]  # called in eval mode, at 4 and 8
    assert h["eval_return"].notna().tolist() == [i in (4, 8) for i in range(1, 11)]
    assert h.loc[h.iteration == 8, "eval_return"].item() == 2.0


# ----------------------------------------------------------------------------------------------
# Evaluation


class _ScriptedEnv(gym.Env):
    """obs = (t, 0, 0); reward r_t from a fixed list; terminates after the list."""

    def __init__(self, rewards):
        self.rewards = list(rewards)
        self.observation_space = gym.spaces.Box(-np.inf, np.inf, (SD,), np.float64)
        self.action_space = gym.spaces.Box(-1.0, 1.0, (AD,), np.float32)

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        self.t = 0
        return np.array([0.0, 0.0, 0.0]), {}

    def step(self, action):
        r = self.rewards[self.t]
        self.t += 1
        return np.array([float(self.t), 0.0, 0.0]), r, self.t == len(self.rewards), False, {}


class _Recorder(nn.Module):
    """Duck-typed model: records each history it is shown, returns known actions/sub-goals."""

    def __init__(self, hdt=False):
        super().__init__()
        self.config = HDTConfig(SD, AD, K=2, low_use_rtg=True) if hdt else DTConfig(SD, AD, K=2)
        self.hdt = hdt
        self.seen = []
        self.dummy = nn.Parameter(torch.zeros(1))

    def act(self, history):
        self.seen.append({k: v.clone() for k, v in history.items()})
        n = len(self.seen)
        B = history["states"].shape[0]
        g = torch.full((B, SD), float(n)) if self.hdt else None  # sub-goal n at call n
        return SeqOutput(torch.full((B, AD), 0.1 * n), g)


def test_rtg_bookkeeping_and_history_window():
    model = _Recorder()
    res = evaluate(
        model,
        lambda: _ScriptedEnv([1.0, 2.0, 3.0, 4.0]),
        n_episodes=2,
        target_return=100.0,
        rtg_scale=10.0,
        state_mean=np.zeros(SD),
        state_std=np.ones(SD),
    )
    np.testing.assert_array_equal(res.returns, [10.0, 10.0])
    np.testing.assert_array_equal(res.lengths, [4, 4])
    assert res.scores is None
    last_rtg = [h["returns_to_go"][0, -1, 0].item() for h in model.seen]
    np.testing.assert_allclose(last_rtg, [10.0, 9.9, 9.7, 9.4], rtol=1e-6)  # rtg -= r / scale
    h3 = model.seen[3]  # step 3 with K = 2: steps 2 and 3 only
    np.testing.assert_allclose(h3["returns_to_go"][0, :, 0], [9.7, 9.4], rtol=1e-6)
    assert h3["timesteps"][0].tolist() == [2, 3]
    assert h3["states"][0, :, 0].tolist() == [2.0, 3.0]
    np.testing.assert_allclose(h3["prev_actions"][0, :, 0], [0.2, 0.3], rtol=1e-6)  # a_1, a_2
    np.testing.assert_allclose(h3["actions"][0, :, 0], [0.3, 0.0], rtol=1e-6)  # a_2, placeholder
    np.testing.assert_array_equal(model.seen[0]["prev_actions"][0, 0], 0.0)  # a_{-1} = 0


def test_one_target_per_episode_in_one_batch():
    model = _Recorder()
    res = evaluate(
        model,
        lambda: _ScriptedEnv([1.0, 2.0]),
        n_episodes=3,
        target_return=[100.0, 50.0, 10.0],
        rtg_scale=10.0,
        state_mean=np.zeros(SD),
        state_std=np.ones(SD),
    )
    np.testing.assert_array_equal(res.returns, [3.0, 3.0, 3.0])
    assert len(model.seen) == 2  # all three targets stepped together
    np.testing.assert_allclose(model.seen[0]["returns_to_go"][:, 0, 0], [10.0, 5.0, 1.0], rtol=1e-6)
    np.testing.assert_allclose(model.seen[1]["returns_to_go"][:, -1, 0], [9.9, 4.9, 0.9], rtol=1e-5)
    # more episodes than environments: each round takes its own slice of the targets
    model = _Recorder()
    venv = gym.vector.SyncVectorEnv([lambda: _ScriptedEnv([1.0])] * 2)
    evaluate(
        model,
        venv,
        n_episodes=3,
        target_return=[30.0, 20.0, 10.0],
        rtg_scale=10.0,
        state_mean=np.zeros(SD),
        state_std=np.ones(SD),
    )
    assert [h["returns_to_go"][:, 0, 0].tolist() for h in model.seen] == [[3.0, 2.0], [1.0, 1.0]]
    with pytest.raises(ValueError, match=r"one per episode \(3,\)"):
        evaluate(_Recorder(), lambda: _ScriptedEnv([1.0]), n_episodes=3, target_return=[1.0, 2.0])


def test_raw_state_datasets_are_evaluated_on_raw_observations():
    seq = SequenceDataset(_episodes(), K=K, normalize_states=False)
    assert not seq.normalize_states
    np.testing.assert_array_equal(seq.normalize(np.ones((2, SD))), np.ones((2, SD)))
    model = _Recorder()
    evaluate(
        model, lambda: _ScriptedEnv([1.0, 1.0, 1.0]), n_episodes=1, target_return=1.0, dataset=seq
    )
    assert model.seen[2]["states"][0, -1].tolist() == [2.0, 0.0, 0.0]  # obs as the env gave it
    model = _Recorder()
    z = SequenceDataset(_episodes(), K=K)
    evaluate(
        model, lambda: _ScriptedEnv([1.0, 1.0, 1.0]), n_episodes=1, target_return=1.0, dataset=z
    )
    want = (np.array([2.0, 0.0, 0.0]) - z.state_mean) / z.state_std
    np.testing.assert_allclose(model.seen[2]["states"][0, -1].numpy(), want, rtol=1e-5)


def test_dataset_returns_to_go_use_the_one_implementation():
    from thesis_lib import data, seq
    from thesis_lib.seq.tokens import returns_to_go

    assert data.returns_to_go is seq.returns_to_go is returns_to_go
    r = np.array([1.0, -2.0, 0.5, 3.0])
    direct = [sum(0.9 ** (k - t) * r[k] for k in range(t, 4)) for t in range(4)]
    np.testing.assert_allclose(returns_to_go(r, 0.9), direct)
    eps = _episodes(n=2, T=5)
    seq = SequenceDataset(eps, K=K, gamma=0.9, rtg_scale=2.0)
    np.testing.assert_allclose(
        seq.returns_to_go[5:], returns_to_go(eps[1].rewards, 0.9) / 2.0, rtol=1e-6
    )


def test_batch_prev_subgoals_are_the_shifted_episode_subgoals():
    seq = _dataset()
    batch = seq.sample(64)
    assert batch.prev_subgoals.shape == batch.subgoals.shape
    for b in range(64):
        e, st = batch.episode_index[b], batch.start[b]
        g = seq.subgoals[seq.offsets[e] : seq.offsets[e] + seq.lengths[e]]
        n = int(batch.mask[b].sum())  # the window's real steps (they come first)
        want = np.vstack([np.zeros((1, SD)), g[:-1]])[st : st + n]  # g_{t-1}, zero at t = 0
        np.testing.assert_array_equal(batch.prev_subgoals[b, : len(want)], want)
        assert not batch.prev_subgoals[b, len(want) :].any()  # padding
    assert SequenceDataset(_episodes(), K=K).sample(2).prev_subgoals is None


def test_hdt_rolls_its_subgoals_forward():
    model = _Recorder(hdt=True)
    evaluate(
        model,
        lambda: _ScriptedEnv([0.0] * 4),
        n_episodes=1,
        target_return=0.0,
        state_mean=np.zeros(SD),
        state_std=np.ones(SD),
    )
    # the high level sees its own earlier predictions g_{t-1} (call n predicted n), zero at the start
    assert [h["prev_subgoals"][0, -1, 0].item() for h in model.seen] == [0.0, 1.0, 2.0, 3.0]
    assert model.seen[3]["subgoals"][0, :, 0].tolist() == [3.0, 0.0]  # g_2, placeholder for g_3


def test_episodes_of_different_lengths_and_rounds():
    lengths = iter([2, 5, 3])

    def make():
        return _ScriptedEnv([1.0] * next(lengths))

    res = evaluate(
        _Recorder(),
        make,
        n_episodes=3,
        target_return=1.0,
        state_mean=np.zeros(SD),
        state_std=np.ones(SD),
    )
    np.testing.assert_array_equal(res.lengths, [2, 5, 3])
    np.testing.assert_array_equal(res.returns, [2.0, 5.0, 3.0])


def test_evaluate_errors():
    with pytest.raises(ValueError, match="target_return="):
        evaluate(_Recorder(), lambda: _ScriptedEnv([1.0]), n_episodes=1)
    wrong = BC(BCConfig(5, AD))
    with pytest.raises(
        ValueError, match="state_dim=5, the environment gives observations of size 3"
    ):
        evaluate(
            wrong,
            lambda: _ScriptedEnv([1.0]),
            n_episodes=1,
            state_mean=np.zeros(5),
            state_std=np.ones(5),
        )
    with pytest.raises(ValueError, match="Unknown task 'hoper'. Did you mean: 'hopper'"):
        evaluate(wrong, "hoper", n_episodes=1)


def test_evaluate_on_a_real_task_gives_d4rl_scores():
    model = HDT(HDTConfig(11, 3, K=5, d_model=16, n_layers=1))
    res = evaluate(
        model, "hopper", n_episodes=2, max_steps=5, state_mean=np.zeros(11), state_std=np.ones(11)
    )
    assert res.returns.shape == (2,) and res.scores.shape == (2,)
    np.testing.assert_allclose(res.scores, 100 * (res.returns + 20.272305) / (3234.3 + 20.272305))


class _ImitationEnv(gym.Env):
    """Random observations; reward 1 - ||a - expert(obs)||^2; 20 steps. The expert scores 20."""

    def __init__(self):
        self.observation_space = gym.spaces.Box(-np.inf, np.inf, (SD,), np.float64)
        self.action_space = gym.spaces.Box(-1.0, 1.0, (AD,), np.float32)

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        self.t, self.obs = 0, self.np_random.normal(size=SD)
        return self.obs, {}

    def step(self, action):
        r = 1.0 - float(np.sum((np.asarray(action) - _expert(self.obs)) ** 2))
        self.t += 1
        self.obs = self.np_random.normal(size=SD)
        return self.obs, r, False, self.t == 20, {}


@pytest.mark.parametrize("kind", ["dt", "hdt"])
def test_trained_models_beat_a_random_policy(kind):
    rng = np.random.default_rng(0)
    eps = []
    for i in range(10):
        obs = rng.normal(size=(21, SD))
        eps.append(
            Episode(
                i,
                obs,
                _expert(obs[:-1]).astype(np.float32),
                np.ones(20),
                np.zeros(20, bool),
                np.zeros(20, bool),
            )
        )
    seq = SequenceDataset(eps, K=K, rtg_scale=10.0, subgoal_fn=subgoal_fn(), seed=0)
    trainer = Trainer(_model(kind), seq, _cfg(iterations=150, batch_size=16))
    trainer.train()
    trained = evaluate(trainer.model, _ImitationEnv, n_episodes=4, target_return=20.0, dataset=seq)
    env, random_returns = _ImitationEnv(), []
    env.action_space.seed(0)
    for k in range(4):
        env.reset(seed=k)
        random_returns.append(sum(env.step(env.action_space.sample())[1] for _ in range(20)))
    assert trained.mean_return > np.mean(random_returns) + 10.0  # measured: about 19 vs -15


def test_offline_runner_rows_and_both_metrics():
    from thesis_lib.chapters.hdt import Config, summarize_curves
    from thesis_lib.seq.runner import run_offline

    rng = np.random.default_rng(0)
    data = []
    for i in range(3):
        obs = rng.normal(size=(16, 11))
        data.append(
            Episode(
                i,
                obs,
                rng.uniform(-1, 1, (15, 3)).astype(np.float32),
                rng.normal(size=15) + 3 * i,
                np.zeros(15, bool),
                np.zeros(15, bool),
            )
        )
    cfg = Config(
        datasets=["hopper/medium"],
        iterations=4,
        eval_every=2,
        eval_episodes=2,
        max_eval_steps=3,
        K=4,
        d_model=16,
        n_layers=1,
        batch_size=4,
        warmup_steps=2,
        seeds=(0, 1),
        extra_seeds=[],
        extra_seed_datasets=[],
        progress=False,
    )
    curves = pd.DataFrame(
        [
            r | {"task": "hopper", "tier": "medium"}
            for m in ("DT", "HDT")
            for s in cfg.seeds
            for r in run_offline(
                m, data, cfg.arch(), cfg.train_spec(s), cfg.eval_spec(), task="hopper"
            )
        ]
    )
    dt = curves[curves.method == "DT"]
    assert sorted(dt.target.unique()) == ["10k", "half", "max"]
    assert dt[dt.seed == 0].iteration.tolist() == [2, 2, 2, 4, 4, 4]
    assert dt.target_return[dt.target == "max"].iloc[0] == pytest.approx(
        max(e.rewards.sum() for e in data)
    )
    assert curves[curves.method == "HDT"].target.unique().tolist() == ["none"]
    s = summarize_curves(curves)
    assert len(s) == 4 and (s.n_seeds == 2).all()
    row = s[(s.method == "HDT")].iloc[0]
    hdt = curves[curves.method == "HDT"]
    assert row.best_return == pytest.approx(hdt.groupby("seed").return_mean.max().mean())
    assert row.final_return_mean == pytest.approx(hdt[hdt.iteration == 4].return_mean.mean())
    assert curves.paper_compat.eq(False).all()
    assert row.best_return_std == pytest.approx(hdt.groupby("seed").return_mean.max().std(ddof=0))
    with pytest.raises(ValueError, match="Unknown method 'HTD'. Did you mean: 'HDT'"):
        Config(methods=("HTD",))
    with pytest.raises(ValueError, match="Unknown method 'DM'"):
        run_offline("DM", data, cfg.arch(), cfg.train_spec(0), cfg.eval_spec(), task="hopper")
    with pytest.raises(ValueError, match="task's name"):
        run_offline("DT", data, cfg.arch(), cfg.train_spec(0), cfg.eval_spec())


def test_experiment_config_errors_and_seeds():
    from thesis_lib.chapters.hdt import Config

    cfg = Config(
        datasets=["hopper/medium", "maze2d-umaze/expert"],
        seeds=[0],
        extra_seeds=[1, 0],
        extra_seed_datasets=["maze2d-umaze/expert"],
    )
    assert cfg.seeds_for("hopper/medium") == [0] and cfg.seeds_for("maze2d-umaze/expert") == [0, 1]
    assert cfg.arch().n_layers == cfg.n_layers and cfg.train_spec(3).seed == 3
    with pytest.raises(ValueError, match="'task/tier'"):
        Config(datasets=["hopper-medium"])
    with pytest.raises(ValueError, match="not in datasets"):
        Config(datasets=["hopper/medium"], extra_seed_datasets=["hopper/expert"])
    with pytest.raises(ValueError, match="to be a list"):
        Config(datasets="hopper/medium")
    with pytest.raises(ValueError, match="Unknown method 'DTT'"):
        Config(compat_methods=["DTT"])
    with pytest.raises(ValueError, match="Unknown dataset_size 'tiny'"):
        Config(dataset_size="tiny")


def test_paper_compat_is_measured_beside_the_default():
    from thesis_lib.chapters.hdt import summarize_paper_compat

    def rows(compat, offset):
        return pd.DataFrame([
            {"method": "HDT", "task": "hopper", "tier": "medium", "seed": s, "target": "none", "iteration": it,
             "return_mean": offset + 10 * s + it, "score_mean": np.nan, "paper_compat": compat}
            for s in (0, 1) for it in (1, 2)
        ] + [{"method": "BC", "task": "hopper", "tier": "medium", "seed": 0, "target": "none", "iteration": 2,
              "return_mean": 5.0, "score_mean": np.nan, "paper_compat": compat}])  # fmt: skip

    c = summarize_paper_compat(rows(False, 0.0), rows(True, 100.0)[lambda d: d.method == "HDT"])
    assert c.method.unique().tolist() == ["HDT"]  # only what was measured both ways
    final = c[c.metric == "final checkpoint"].iloc[0]
    assert final.correct == pytest.approx(7.0) and final.paper_compat == pytest.approx(107.0)
    assert final.difference == pytest.approx(100.0) and final.correct_std == pytest.approx(5.0)


def test_chapter_pipeline_at_tiny_scale(tmp_path, monkeypatch):
    from thesis_lib.chapters.hdt import Config, run_curves, run_paper_compat, summarize_paper_compat

    monkeypatch.setenv(
        "THESIS_DATA_DIR", str(tmp_path / "data")
    )  # a tiny data set, not the cached smoke one
    monkeypatch.setenv("THESIS_RESULTS_DIR", str(tmp_path / "results"))
    cfg = Config(
        datasets=["maze2d-open/expert"],
        methods=["DT", "HDT"],
        seeds=[0],
        extra_seeds=[1],
        extra_seed_datasets=["maze2d-open/expert"],
        compat_dataset="maze2d-open/expert",
        compat_methods=["HDT"],
        iterations=2,
        eval_every=1,
        eval_episodes=2,
        max_eval_steps=3,
        K=4,
        d_model=8,
        n_layers=1,
        batch_size=4,
        warmup_steps=1,
        n_transitions=300,
        progress=False,
    )
    curves = run_curves(cfg)
    # 2 seeds x (DT: 3 targets, HDT: 1) x 2 evaluations
    assert (
        len(curves) == 2 * (3 + 1) * 2
        and set(curves.seed) == {0, 1}
        and not curves.paper_compat.any()
    )
    # max_eval_steps caps locomotion only: Maze2D's sparse-reward scores need whole episodes
    assert (curves.length_mean > 3).all() and curves.length_mean.nunique() == 1
    store = tmp_path / "results" / "04_hdt" / "tasks"
    assert len(list(store.glob("*.json"))) == 4  # one finished task per seed x method
    again = run_curves(cfg)  # read back from the store
    pd.testing.assert_frame_equal(curves, again)
    monkeypatch.setenv("THESIS_SWEEP_FORCE", "1")
    recomputed = run_curves(cfg)  # trained again: same seeds, same numbers
    pd.testing.assert_frame_equal(curves, recomputed)
    monkeypatch.delenv("THESIS_SWEEP_FORCE")
    compat = run_paper_compat(cfg)
    assert compat.paper_compat.all() and set(compat.method) == {"HDT"}
    table = summarize_paper_compat(curves, compat)
    assert (
        set(table.method) == {"HDT"} and (table.n_seeds == 2).all() and len(table) == 2
    )  # two metrics


@pytest.mark.parametrize("method", ["DT", "DM-noRTG"])
def test_a_run_cut_off_resumes_from_its_checkpoint_with_the_same_rows(
    tmp_path, monkeypatch, method
):
    """run_offline(checkpoint=...): cut off after its checkpoint at 4 updates and called again,
    a run gives the rows of an uninterrupted one (evaluations before the cut included) and tells
    its task the CPU seconds of the part cut off; a checkpoint of another run's evaluation is
    refused; the total may grow."""
    from thesis_lib.seq.registry import ArchSpec
    from thesis_lib.seq.runner import EvalSpec, TrainSpec, run_offline

    rng = np.random.default_rng(0)
    data = [
        Episode(
            i,
            rng.normal(size=(16, 11)),
            rng.uniform(-1, 1, (15, 3)).astype(np.float32),
            rng.normal(size=15) + 3 * i,
            np.zeros(15, bool),
            np.zeros(15, bool),
        )
        for i in range(3)
    ]
    arch = ArchSpec(K=4, d_model=16, n_layers=1)
    train = TrainSpec(seed=1, iterations=6, batch_size=4, warmup_steps=2, eval_every=2)
    ev = EvalSpec(episodes=2, max_steps=3)

    def run(**kw):
        spec = TrainSpec(**{**train.task_dict(), **kw.pop("train", {})})
        return pd.DataFrame(run_offline(method, data, arch, spec, ev, task="hopper", **kw))

    straight = run()
    ckpt = tmp_path / "run.pt"
    step = Trainer.step

    def cut_off(self):
        if self.iteration == 4:
            raise RuntimeError("cut off")
        return step(self)

    monkeypatch.setattr(Trainer, "step", cut_off)
    with pytest.raises(RuntimeError, match="cut off"):
        run(checkpoint=ckpt, checkpoint_every=2)
    monkeypatch.setattr(Trainer, "step", step)
    saved = torch.load(ckpt, weights_only=True)
    assert saved["iteration"] == 4 and saved["cpu_s"] > 0
    told: list[float] = []  # what the running task is told its cut-off part cost
    monkeypatch.setattr("thesis_lib.seq.runner.note_resumed_cpu", told.append)
    resumed = run(checkpoint=ckpt, checkpoint_every=2)
    assert told == [pytest.approx(saved["cpu_s"])]
    assert sorted(set(resumed["iteration"])) == [2, 4, 6]
    pd.testing.assert_frame_equal(resumed, straight)
    with pytest.raises(ValueError, match=r"made by another run \(eval: .*'episodes': 2"):
        pd.DataFrame(
            run_offline(
                method,
                data,
                arch,
                train,
                EvalSpec(episodes=1, max_steps=3),
                task="hopper",
                checkpoint=ckpt,
            )
        )
    longer = run(checkpoint=ckpt, train={"iterations": 8})
    assert sorted(set(longer["iteration"])) == [2, 4, 6, 8]
    pd.testing.assert_frame_equal(longer[longer["iteration"] <= 6], straight)
