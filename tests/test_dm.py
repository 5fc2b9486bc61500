"""Tests for the Decision Mamba and the Hierarchical Decision Mamba (thesis 5.3): thesis_lib.seq.dm."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pandas as pd
import pytest
import torch

from thesis_lib.data import Episode, SequenceDataset
from thesis_lib.seq.dm import HDM, DecisionMamba, DMConfig, HDMConfig, RecurrentPolicy
from thesis_lib.seq.evaluation import evaluate
from thesis_lib.seq.subgoals import subgoal_fn
from thesis_lib.seq.trainer import TrainConfig, Trainer, batch_to_torch

torch.set_num_threads(1)
SD, AD, K = 3, 2, 6
SMALL = dict(K=K, d_model=16, n_layers=2)


def _episodes(n=6, T=30, seed=0):
    rng = np.random.default_rng(seed)
    eps = []
    for i in range(n):
        obs = rng.normal(size=(T + 1, SD))
        act = np.tanh(obs[:-1, :AD] * 2.0).astype(np.float32)
        eps.append(Episode(i, obs, act, obs[:-1, 0] + 1.0, np.zeros(T, bool), np.zeros(T, bool)))
    return eps


def _dataset(seed=0, paper_compat=False, hier=False):
    sg = subgoal_fn(paper_compat) if hier else None
    return SequenceDataset(_episodes(), K=K, subgoal_fn=sg, paper_compat=paper_compat, seed=seed)


def _model(kind, **kw):
    torch.manual_seed(0)
    if kind == "hdm":
        return HDM(HDMConfig(SD, AD, **{**SMALL, **kw}))
    return DecisionMamba(DMConfig(SD, AD, use_rtg=kind == "dm-rtg", **{**SMALL, **kw}))


@pytest.mark.parametrize(
    "kind,paper_compat",
    [("dm", False), ("dm-rtg", False), ("hdm", False), ("dm", True), ("hdm", True)],
)
def test_loss_falls_on_a_tiny_dataset(kind, paper_compat):
    seq = _dataset(paper_compat=paper_compat, hier=kind == "hdm")
    cfg = TrainConfig(iterations=60, batch_size=8, warmup_steps=5, lr=3e-3, progress=False)
    h = Trainer(_model(kind, paper_compat=paper_compat), seq, cfg).train()
    assert h["loss"].iloc[-10:].mean() < 0.5 * h["loss"].iloc[:10].mean()
    if kind == "hdm":
        assert {"loss_subgoal", "loss_action"} <= set(h.columns)


@pytest.mark.parametrize("kind", ["dm", "hdm"])
def test_bf16_training_keeps_the_residual_stream_float32_and_learns(kind):
    """Under bfloat16 autocast the token embeddings come in bf16; the trunk lifts them to
    float32 (the RMSNorms would otherwise warn and leave their fused kernel), and the model
    learns as in float32."""
    import warnings

    seq = _dataset(hier=kind == "hdm")
    model = _model(kind)
    streams: list[torch.dtype] = []
    linears: list[torch.dtype] = []
    for m in model.modules():
        if type(m).__name__ == "MambaBlock":
            m.register_forward_hook(lambda m, i, o: streams.append(o.dtype))
        if isinstance(m, torch.nn.Linear):
            m.register_forward_hook(lambda m, i, o: linears.append(o.dtype))
    cfg = TrainConfig(
        iterations=60, batch_size=8, warmup_steps=5, lr=3e-3, progress=False, precision="bf16"
    )
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # the mismatched-dtype RMSNorm warns
        h = Trainer(model, seq, cfg).train()
    assert streams and set(streams) == {torch.float32}
    assert torch.bfloat16 in linears  # the step ran under autocast
    assert h["loss"].iloc[-10:].mean() < 0.5 * h["loss"].iloc[:10].mean()


def test_no_positional_input_and_causal():
    """Timesteps are not read; a later token does not change earlier outputs (right padding is harmless)."""
    m = _model("dm-rtg").eval()
    b = batch_to_torch(None, _dataset().sample(4))
    out = m(b).actions
    shifted = dict(b, timesteps=b["timesteps"] + 100)
    assert torch.equal(m(shifted).actions, out)
    changed = dict(b, states=b["states"].clone())
    changed["states"][:, -1] += 5.0
    later = m(changed).actions
    torch.testing.assert_close(later[:, :-1], out[:, :-1])
    assert not torch.allclose(later[:, -1], out[:, -1])


def test_action_is_read_at_the_state_token():
    """a_t must not see its own action token (the s_t token comes before a_t)."""
    m = _model("dm").eval()
    b = batch_to_torch(None, _dataset().sample(3))
    leak = dict(b, actions=b["actions"] + 1.0)  # changes every a_t token
    a0, a1 = m(b).actions, m(leak).actions
    torch.testing.assert_close(a0[:, 0], a1[:, 0])  # step 0 sees no action token
    assert not torch.allclose(a0[:, 1:], a1[:, 1:])  # later steps see a_{t-1}


def test_hdm_loss_is_high_plus_low_and_head():
    m = _model("hdm")
    b = batch_to_torch(*(lambda s: (s, s.sample(4)))(_dataset(hier=True)))
    out = m(b, targets=b)
    assert out.loss.item() == pytest.approx(out.losses["subgoal"] + out.losses["action"], rel=1e-5)
    assert isinstance(m.predict_subgoal, torch.nn.Linear)  # z-scored targets: no Tanh by default
    assert isinstance(_model("hdm", paper_compat=True).predict_subgoal[-1], torch.nn.Tanh)


def _rollout_histories(T, paper_compat=False, hier=False, seed=0):
    """Histories as the evaluator builds them, for T steps with random states (the full episode)."""
    g = torch.Generator().manual_seed(seed)
    states = torch.randn(2, T, SD, generator=g)
    actions = torch.zeros(2, T + 1, AD)
    actions[:, 1:] = torch.rand(2, T, AD, generator=g) * 2 - 1
    rtg = torch.randn(2, T, 1, generator=g)
    return states, actions, rtg


@pytest.mark.parametrize(
    "kind,paper_compat", [("dm", False), ("dm-rtg", False), ("dm", True), ("hdm", False)]
)
def test_recurrent_policy_equals_full_forward(kind, paper_compat):
    """Stepping conditions on the whole episode: equal to one forward over it (model built with K = T)."""
    T = 9
    m = _model(kind, paper_compat=paper_compat, K=T, eval_mode="recurrent").eval()
    states, actions, rtg = _rollout_histories(T)
    pol = m.recurrent_policy(2)
    assert isinstance(pol, RecurrentPolicy)
    subgoals = torch.zeros(2, T + 1, SD)
    got = []
    for t in range(T):
        h = {
            "states": states[:, : t + 1],
            "actions": actions[:, 1 : t + 2],
            "prev_actions": actions[:, : t + 1],
            "returns_to_go": rtg[:, : t + 1],
            "subgoals": subgoals[:, 1 : t + 2],
            "prev_subgoals": subgoals[:, : t + 1],
        }
        out = pol.act(h, torch.arange(2))
        if out.subgoals is not None:
            subgoals[:, t + 1] = out.subgoals
        got.append(out.actions)
    full = {
        "states": states,
        "actions": actions[:, 1:],
        "prev_actions": actions[:, :-1],
        "returns_to_go": rtg,
        "subgoals": subgoals[:, 1:],
        "prev_subgoals": subgoals[:, :-1],
    }
    with torch.no_grad():
        want = m(full).actions
    torch.testing.assert_close(torch.stack(got, 1), want, atol=1e-5, rtol=1e-4)


def _pendulum(T):
    return lambda: gym.make("Pendulum-v1", max_episode_steps=T)


def _pendulum_model(kind, paper_compat, mode):
    """A model for Pendulum (state 3, action 1 in [-2, 2]) with the same weights in every mode."""
    cls, ccls = (HDM, HDMConfig) if kind == "hdm" else (DecisionMamba, DMConfig)
    extra = {"use_rtg": True} if kind == "dm-rtg" else {}
    torch.manual_seed(1)
    return cls(
        ccls(SD, 1, max_action=2.0, paper_compat=paper_compat, eval_mode=mode, **SMALL, **extra)
    )


@pytest.mark.parametrize("kind,paper_compat", [("dm", False), ("dm-rtg", True), ("hdm", False)])
def test_recurrent_and_windowed_evaluation_agree_on_short_episodes(kind, paper_compat):
    """Episodes of at most K steps: both modes see the same tokens, so the same actions and returns."""
    kw = dict(target_return=-100.0) if kind == "dm-rtg" else {}
    stats = dict(state_mean=np.zeros(SD), state_std=np.ones(SD))
    res = {
        mode: evaluate(
            _pendulum_model(kind, paper_compat, mode), _pendulum(K), 3, seed=5, **stats, **kw
        ).returns
        for mode in ("recurrent", "window")
    }
    np.testing.assert_allclose(res["recurrent"], res["window"], rtol=1e-5)


def test_recurrent_and_windowed_differ_after_K_steps():
    """Up to K steps the recurrent and the windowed action agree; past K the window forgets, the state does not.

    The SSMs get a long memory (A close to 0) so that what happened before the window matters
    visibly; at the random init, A = -(1..16) forgets within a few tokens.
    """
    m = _model("dm", eval_mode="recurrent").eval()
    with torch.no_grad():
        for block in m.trunk.mamba.layers:
            block.mixer.A_log.fill_(-6.0)
    T = 3 * K
    states, actions, _ = _rollout_histories(T)
    pol = m.recurrent_policy(2)
    diff = []
    for t in range(T):
        lo = max(0, t - K + 1)
        h = {
            "states": states[:, lo : t + 1],
            "actions": actions[:, lo + 1 : t + 2],
            "prev_actions": actions[:, lo : t + 1],
        }
        diff.append((pol.act(h).actions - m.act(h).actions).abs().max().item())
    assert max(diff[:K]) < 1e-6  # float rounding only
    assert min(diff[K:]) > 20 * max(max(diff[:K]), 1e-7)


def test_eval_mode_auto_and_errors():
    assert DMConfig(SD, AD).resolved_eval_mode == "recurrent"
    assert DMConfig(SD, AD, paper_compat=True).resolved_eval_mode == "window"
    assert _model("dm", eval_mode="window").recurrent_policy(2) is None
    with pytest.raises(ValueError, match="Unknown eval_mode 'fast'"):
        DMConfig(SD, AD, eval_mode="fast")
    with pytest.raises(ValueError, match=r"states of shape \(batch, seq_len, 3\)"):
        _model("dm")({"states": torch.zeros(1, 2, 5), "actions": torch.zeros(1, 2, AD)})
    with pytest.raises(KeyError, match="prev_subgoals"):
        _model("hdm")({"states": torch.zeros(1, 2, SD), "actions": torch.zeros(1, 2, AD)})
    with pytest.raises(TypeError, match="DecisionMamba or an HDM"):
        RecurrentPolicy(torch.nn.Linear(2, 2), 1)


# --------------------------------------------------------------------------- chapter functions


def test_parse_arch_and_config_errors():
    from thesis_lib.chapters.decision_mamba import Config, parse_arch

    assert parse_arch("2/32/10").label == "L2 D32 K10"
    assert Config().arch_spec("2/32/10").label == "L2 D32 K10"
    with pytest.raises(ValueError, match="Did you mean: 'HDM'"):
        Config(methods=["HDMM"])
    with pytest.raises(ValueError, match="Unknown method 'DM'. Did you mean: 'HDM'"):
        Config(methods=["DM"])  # one spelling: DM-noRTG
    with pytest.raises(ValueError, match="layers/d_model/K"):
        Config(sweep_archs=["2/32"])


def test_summary_and_win_counts_on_synthetic_curves():
    from thesis_lib.chapters.decision_mamba import (
        compare_table_5_5,
        compare_win_counts_5_5,
        summarize_curves,
    )

    rows = []
    for seed, (dm, dt) in enumerate([(10.0, 5.0), (20.0, 7.0)]):
        for it, scale in ((1, 0.5), (2, 1.0)):
            base = dict(task="hopper", tier="medium", seed=seed, arch="L1 D8 K4", iteration=it)
            rows.append(
                dict(
                    base,
                    method="DM-noRTG",
                    target="none",
                    eval_mode="recurrent",
                    return_mean=dm * scale,
                )
            )
            rows.append(
                dict(base, method="HDM", target="none", eval_mode="recurrent", return_mean=1.0)
            )
            rows.append(
                dict(base, method="HDT", target="none", eval_mode="window", return_mean=2.0)
            )
            for tgt in ("half", "max", "10k"):
                rows.append(
                    dict(base, method="DT", target=tgt, eval_mode="window", return_mean=dt * scale)
                )
    s = summarize_curves(pd.DataFrame(rows))
    dm = s[s.method == "DM-noRTG"].iloc[0]
    assert (
        dm.best_mean == pytest.approx(15.0)
        and dm.best_std == pytest.approx(5.0)
        and dm.n_seeds == 2
    )
    t = compare_table_5_5(s)
    row = t[
        (t.metric == "best during training (thesis)")
        & (t.method == "DM_without_R")
        & (t.task == "Hopper")
        & (t.dataset == "medium")
    ].iloc[0]
    assert row.paper == pytest.approx(1383.51) and row.ours == pytest.approx(15.0)
    wins = compare_win_counts_5_5(t).set_index(["comparison", "metric"])
    w = wins.loc[("DM wo/ R beats DT (all three targets)", "best during training (thesis)")]
    assert (
        w["ours"] == "1/1" and w["thesis table (our settings)"] == "1/1"
    )  # 1383.51 > 1144.2, 1241.6, 1252.95
    h = wins.loc[("HDM beats HDT", "best during training (thesis)")]
    assert h["ours"] == "0/1" and h["thesis table (all settings)"] == "21/27"


def test_chapter_functions_run_end_to_end_at_tiny_scale(tmp_path, monkeypatch):
    """Table 5.5 runs, the sweeps (reusing a run), Table 5.6 timing, figures: shapes and invariants."""
    import matplotlib

    matplotlib.use("Agg")
    from thesis_lib.chapters import decision_mamba as ch

    monkeypatch.setenv("THESIS_DATA_DIR", str(tmp_path / "data"))  # a tiny data set
    monkeypatch.setenv("THESIS_RESULTS_DIR", str(tmp_path / "results"))
    cfg = ch.Config(
        datasets=["maze2d-open/expert"],
        iterations=4,
        batch_size=4,
        arch="1/8/4",
        eval_every=2,
        eval_episodes=1,
        max_eval_steps=5,
        warmup_steps=2,
        sweep_datasets=["maze2d-open/expert"],
        sweep_archs=["1/8/4", "1/8/2"],
        timing_datasets=["maze2d-open/expert"],
        timing_arch="1/8/4",
        timing_train_iters=1,
        timing_infer_steps=3,
        timing_infer_episodes=1,
        n_transitions=300,
    )
    curves = ch.run_table_5_5(cfg)
    # evaluations at iterations 2 and 4; RTG methods at 3 targets; DM/HDM once more in the other mode
    n = {"DT": 6, "HDT": 2, "DM-RTG": 6 + 3, "DM-noRTG": 2 + 1, "HDM": 2 + 1}
    assert curves.groupby("method").size().to_dict() == n
    assert set(curves[curves.method == "DM-noRTG"].eval_mode) == {"recurrent", "window"}
    assert len(list((tmp_path / "results" / ch.CHAPTER / "tasks").glob("*.json"))) == 5
    summary = ch.summarize_curves(curves)
    t55 = ch.compare_table_5_5(summary, "recurrent")
    assert set(t55.dropna(subset=["ours"]).method) == {
        "DT",
        "HDT",
        "DM_with_R",
        "DM_without_R",
        "HDM",
    }
    assert len(ch.format_table_5_5(t55)) == 1
    sweep = ch.run_sweeps(cfg, reuse=curves)
    reused = sweep[sweep.arch == "L1 D8 K4"]
    assert len(reused) == len(
        curves[curves.method.isin(cfg.sweep_methods)]
    )  # taken from Table 5.5, not re-run
    assert set(sweep[(sweep.arch == "L1 D8 K2") & (sweep.method == "DM-RTG")].target) == {"max"}
    data = ch.load_datasets(cfg.datasets, cfg)
    timing = ch.run_table_5_6(cfg, data)
    assert len(timing) == 5 + 5 + 3  # train x5, window inference x5, recurrent inference x3
    assert (timing.time_ms_mean > 0).all()
    t56 = ch.compare_table_5_6(timing)
    assert "DM_without_R (recurrent step)" in set(t56.dropna(subset=["ours"]).method)
    ratios = ch.summarize_timing_ratios(timing).set_index("method")
    assert ratios.loc["DT", "train / DT"] == pytest.approx(1.0)
    assert ratios.loc["HDM", "window / recurrent"] == pytest.approx(
        ratios.loc["HDM", "inference (window)"] / ratios.loc["HDM", "inference (recurrent)"]
    )
    counts = ch.run_parameter_counts(d_model=16, n_layers=1).set_index("model").parameters
    assert counts["DM, plain Mamba blocks"] < counts["DM, gated MLP (authors' later code)"]
    ax = ch.plot_methods(summary, data)
    labels = [t.get_text() for t in ax.get_legend().get_texts()]
    names = [ch.THESIS_METHOD[m].replace("_", " ") for m in ch.DM_METHODS]
    assert labels == [n for n in names if n in labels] and len(labels) == 5
    assert len(ax.patches) == len(labels) * len(ax.get_xticks())  # a bar per method and set
    ax = ch.plot_sweep(ch.summarize_curves(sweep), "DM-noRTG", data)
    archs = [t.get_text() for t in ax.get_legend().get_texts()]
    assert "L1 D8 K2" in archs and len(ax.patches) == len(archs) * len(ax.get_xticks())


@pytest.mark.parametrize("method", ["DM-RTG", "HDM"])
def test_paper_compat_run_acts_on_the_window(method):
    """The authors' behaviour end to end: a_{t-1} tokens, windowed acting (and the other mode compared)."""
    from thesis_lib.seq.registry import ArchSpec
    from thesis_lib.seq.runner import EvalSpec, TrainSpec, run_offline

    rng = np.random.default_rng(1)
    eps = [
        Episode(
            i,
            rng.normal(size=(9, 11)),
            rng.uniform(-1, 1, size=(8, 3)).astype(np.float32),
            rng.uniform(0, 2, size=8),
            np.zeros(8, bool),
            np.zeros(8, bool),
        )
        for i in range(3)
    ]
    arch = ArchSpec(d_model=8, n_layers=1, K=4, eval_mode="window", paper_compat=True)
    train = TrainSpec(iterations=2, batch_size=4, eval_every=2, warmup_steps=1)
    ev = EvalSpec(episodes=1, max_steps=6, compare_eval_modes=True)
    rows = pd.DataFrame(run_offline(method, eps, arch, train, ev, task="hopper"))
    assert set(rows.eval_mode) == {"window", "recurrent"}
    assert set(rows.iteration) == {2}
    assert rows.paper_compat.all()
    with pytest.raises(ValueError, match="Unknown target 'best'"):
        EvalSpec(targets=("best",))
