"""The Decision Transformer against an independent formulation, its initialisation schemes, and
the peer-parity harness (issue #33).

* the forward pass equals a DT written out here in plain tensor algebra (explicit attention
  with a causal mask, GPT-2's pre-LN blocks, tokens interleaved by hand) at shared weights;
* the initialisation schemes draw what they say, and ``torch`` is bit for bit the v1 code's;
* a short learning test: on the hopper/medium smoke set our DT reaches BC's score, which the
  v1 initialisation does not (it fails on the old code);
* the harness's pieces: the Welch interval, the parity file, the d3rlpy export, the table.
"""

from __future__ import annotations

import math

import numpy as np
import pandas as pd
import pytest
import torch
import torch.nn.functional as F

from thesis_lib.chapters import CHAPTERS
from thesis_lib.seq import ArchSpec, TrainSpec
from thesis_lib.seq.models import (
    HDT,
    DecisionTransformer,
    DTConfig,
    HDTConfig,
    init_transformer,
    resolve_init,
)

torch.set_num_threads(1)
SD, AD, K = 4, 3, 6


# ----------------------------------------------------------------------------------------------
# An independent DT: the same computation written out without the library's modules


def _ln(x, w, b):
    mu = x.mean(-1, keepdim=True)
    var = ((x - mu) ** 2).mean(-1, keepdim=True)
    return (x - mu) / torch.sqrt(var + 1e-5) * w + b


def _reference_dt(p: dict[str, torch.Tensor], batch, n_layers: int, n_heads: int):
    """Actions of a DT with parameters ``p`` (the library's state dict), per Chen et al. 2021."""
    lin = lambda x, name: x @ p[f"{name}.weight"].T + p[f"{name}.bias"]
    time = p["transformer.embed_timestep.weight"][batch["timesteps"]]  # (B, T, d)
    r = lin(batch["returns_to_go"], "embed_rtg") + time
    s = lin(batch["states"], "embed_state") + time
    a = lin(batch["actions"], "embed_action") + time
    B, T, d = s.shape
    x = torch.zeros(B, 3 * T, d)
    x[:, 0::3], x[:, 1::3], x[:, 2::3] = r, s, a  # (r_0, s_0, a_0, r_1, ...)
    x = _ln(x, p["transformer.embed_ln.weight"], p["transformer.embed_ln.bias"])
    n = 3 * T
    allowed = torch.tril(torch.ones(n, n, dtype=torch.bool))
    hs = d // n_heads
    for i in range(n_layers):
        q = f"transformer.blocks.{i}"
        h = _ln(x, p[f"{q}.ln_1.weight"], p[f"{q}.ln_1.bias"])
        qkv = lin(h, f"{q}.attn.c_attn")
        heads = []
        for k in range(n_heads):
            Q = qkv[..., k * hs : (k + 1) * hs]
            Kt = qkv[..., d + k * hs : d + (k + 1) * hs]
            V = qkv[..., 2 * d + k * hs : 2 * d + (k + 1) * hs]
            scores = Q @ Kt.transpose(1, 2) / math.sqrt(hs)
            scores = scores.masked_fill(~allowed, float("-inf"))
            heads.append(torch.softmax(scores, -1) @ V)
        x = x + lin(torch.cat(heads, -1), f"{q}.attn.c_proj")
        h = _ln(x, p[f"{q}.ln_2.weight"], p[f"{q}.ln_2.bias"])
        x = x + lin(F.relu(lin(h, f"{q}.mlp.c_fc")), f"{q}.mlp.c_proj")
    x = _ln(x, p["transformer.ln_f.weight"], p["transformer.ln_f.bias"])
    return torch.tanh(lin(x[:, 1::3], "predict_action.0"))  # read at the s_t tokens


def _batch(B=3, T=K, seed=0):
    g = torch.Generator().manual_seed(seed)
    return {
        "states": torch.randn(B, T, SD, generator=g),
        "actions": torch.randn(B, T, AD, generator=g).clamp(-1, 1),
        "returns_to_go": torch.randn(B, T, 1, generator=g),
        "timesteps": torch.randint(0, 50, (B, 1), generator=g) + torch.arange(T),
        "mask": torch.ones(B, T, dtype=torch.bool),
    }


@pytest.mark.parametrize("init", ["normal", "original", "torch", "d3rlpy"])
@pytest.mark.parametrize("n_layers,n_heads", [(1, 1), (3, 2)])
def test_dt_forward_equals_an_independent_formulation(init, n_layers, n_heads):
    torch.manual_seed(0)
    cfg = DTConfig(SD, AD, K=K, d_model=16, n_layers=n_layers, n_heads=n_heads, dropout=0.0)
    model = DecisionTransformer(DTConfig(**{**cfg.__dict__, "init": init})).eval()
    batch = _batch()
    ours = model(batch).actions
    ref = _reference_dt(dict(model.state_dict()), batch, n_layers, n_heads)
    torch.testing.assert_close(ours, ref, atol=1e-5, rtol=1e-5)


# ----------------------------------------------------------------------------------------------
# Initialisation schemes


def _dt(init: str, paper_compat: bool = False, seed: int = 0) -> DecisionTransformer:
    torch.manual_seed(seed)
    return DecisionTransformer(
        DTConfig(SD, AD, K=K, d_model=64, n_layers=2, init=init, paper_compat=paper_compat)
    )


def test_normal_init_draws_every_linear_and_embedding_from_n0_002():
    m = _dt("normal")
    for name, p in m.named_parameters():
        if name.endswith("bias"):
            assert torch.all(p == 0), name
        elif p.ndim >= 2 and p.numel() >= 256:
            assert abs(p.std().item() - 0.02) < 0.004, (name, p.std().item())
    t = m.transformer.embed_timestep.weight
    assert abs(t.std().item() - 0.02) < 0.001  # was N(0, 1): the cause of the gap


def test_original_init_is_gpt2_in_the_trunk_and_torch_outside():
    m = _dt("original")
    blocks = m.transformer.blocks
    assert abs(blocks[0].attn.c_attn.weight.std().item() - 0.02) < 0.003
    resid = 0.02 / math.sqrt(2 * 2)
    assert abs(blocks[1].mlp.c_proj.weight.std().item() - resid) < 0.002
    assert torch.all(blocks[0].attn.c_attn.bias == 0)
    # outside the trunk: PyTorch's defaults, as the authors' embeddings
    assert abs(m.transformer.embed_timestep.weight.std().item() - 1.0) < 0.05
    bound = 1 / math.sqrt(SD)  # Kaiming-uniform's bound for a Linear with SD inputs
    w = m.embed_state.weight
    assert w.abs().max().item() <= bound and w.std().item() > 0.2 * bound


def test_d3rlpy_init_is_normal_in_the_trunk_and_torch_for_the_embeddings_and_head():
    """d3rlpy 2.8.1's ContinuousDecisionTransformer: ``apply(_init_weights)`` (N(0, 0.02), zero
    biases) reaches the position table and the GPT blocks, attached before it; the return,
    state and action embeddings and the output head, attached after it, keep PyTorch's
    defaults."""
    m = _dt("d3rlpy")
    trunk = m.transformer
    assert abs(trunk.embed_timestep.weight.std().item() - 0.02) < 0.001
    for name, p in trunk.blocks.named_parameters():
        if name.endswith("bias"):
            assert torch.all(p == 0), name
        elif p.ndim >= 2:  # every block weight, the residual projections unscaled
            assert abs(p.std().item() - 0.02) < 0.003, (name, p.std().item())
    for emb, fan_in in ((m.embed_rtg, 1), (m.embed_state, SD), (m.embed_action, AD)):
        bound = 1 / math.sqrt(fan_in)  # Kaiming-uniform's bound
        assert emb.weight.abs().max().item() <= bound and emb.weight.std().item() > 0.2 * bound
        assert emb.bias.abs().max().item() > 0  # not zeroed
    head = [p for p in m.predict_action.parameters() if p.ndim == 2][0]
    assert head.std().item() > 0.05  # 1/sqrt(64) bound: not N(0, 0.02)


def test_torch_init_is_the_v1_code_bit_for_bit():
    """``torch`` applies nothing: PyTorch's own draws, in the v1 code's order of construction
    (the three token embeddings, then the trunk's time-step table)."""
    torch.manual_seed(3)
    m = DecisionTransformer(DTConfig(SD, AD, K=K, d_model=16, n_layers=1, init="torch"))
    torch.manual_seed(3)
    rtg, state = torch.nn.Linear(1, 16), torch.nn.Linear(SD, 16)
    action, table = torch.nn.Linear(AD, 16), torch.nn.Embedding(m.config.max_timestep, 16)
    assert torch.equal(m.embed_rtg.weight, rtg.weight)
    assert torch.equal(m.embed_state.weight, state.weight)
    assert torch.equal(m.embed_action.bias, action.bias)
    assert torch.equal(m.transformer.embed_timestep.weight, table.weight)


def test_auto_resolves_by_paper_compat_and_bad_schemes_are_named():
    assert resolve_init("auto", False) == "normal"
    assert resolve_init("auto", True) == "original"
    assert _dt("auto", paper_compat=True).config.resolved_init == "original"
    with pytest.raises(ValueError, match="Unknown init 'gpt3'.*normal, original, torch, d3rlpy"):
        DTConfig(SD, AD, init="gpt3")
    with pytest.raises(ValueError, match="Unknown init"):
        ArchSpec(init="xavier")
    with pytest.raises(ValueError, match="Unknown init"):
        init_transformer(_dt("torch"), "auto", 2)  # resolve first


def test_hdt_initialises_both_levels():
    torch.manual_seed(0)
    m = HDT(HDTConfig(SD, AD, K=K, d_model=32, n_layers=1))
    for level in (m.high, m.low):
        assert abs(level.embed_timestep.weight.std().item() - 0.02) < 0.002


def test_task_dicts_keep_the_v1_keys():
    """A task stored before ``init`` existed has no ``init`` and ran with PyTorch's defaults."""
    assert "init" not in ArchSpec(init="torch").task_dict()
    assert ArchSpec().task_dict()["init"] == "normal"
    assert ArchSpec(paper_compat=True).task_dict()["init"] == "original"
    assert ArchSpec.from_task({"d_model": 32}).init == "torch"
    assert ArchSpec.from_task(ArchSpec().task_dict()) == ArchSpec(init="normal")
    # nor a precision: every task before it trained in float32
    assert "precision" not in TrainSpec().task_dict()
    assert TrainSpec.from_task(TrainSpec(precision="bf16").task_dict()).precision == "bf16"
    with pytest.raises(ValueError, match="Unknown precision 'half'"):
        TrainSpec(precision="half")


def test_v1_study_files_keep_their_init_and_task_keys():
    """The committed v1 studies were run before ``init``: their files name none, they read as
    ``torch``, and every stored task key is still one of the study's tasks."""
    import json

    from thesis_lib.book.study import load_study, studies_dir, study_config, study_tasks

    for chapter in ("04_hdt", "05_decision_mamba", "07_ur3_deployment"):
        study = load_study(chapter)
        assert "init" not in study.config
        assert study_config(study, CHAPTERS[study.chapter]).init == "torch"
        keys = {t.key for t in study_tasks(study, CHAPTERS[study.chapter])}
        stored = {
            json.loads(p.read_text())["key"]
            for p in (studies_dir(chapter) / "tasks").glob("*.json")
        }
        assert stored and stored <= keys, chapter


# ----------------------------------------------------------------------------------------------
# Learning: the DT reaches BC's level on hopper/medium (the v1 initialisation did not on the
# earlier data recipes)


@pytest.mark.slow
def test_dt_learns_to_bc_level_on_hopper_medium():
    """Our DT within 5 normalised points of BC on the hopper/medium smoke set, at the study's
    size (d32, 1 layer) with batch 16 for 10k updates (about 90 CPU-seconds a run; the two
    runs share the two cores through the parity harness's own task function).

    The v1 initialisation (``init="torch"``) is not run here: it fell more than 5 points short
    of the fixed DT on the recipe-2 data of the parity table (v1 12.0 and 15.0 against 35.2 and
    32.0) and on recipe 3 (16.8 against 23.9), but not on recipe 4's hopper medium at D4RL's
    level (seed 0: DT 32.0, v1 33.6, BC 34.8; data 41.9), so no bound on it would hold on every
    recipe; the parity table's `-r4` rows measure it over seeds. (It ran here as a third,
    unasserted run until 2026-12-01: a third of this test's CPU and half its wall time.)"""
    from thesis_lib.data.recipe import GENERATOR_VERSION
    from thesis_lib.parity import ours_run
    from thesis_lib.sweep import Task, run_tasks

    def task(method: str, init: str) -> Task:
        return Task(
            ours_run,
            {
                "method": method,
                "init": init,
                "dataset": "hopper/medium",
                "dataset_size": "smoke",
                "data_recipe": GENERATOR_VERSION,
                "arch": {"d_model": 32, "n_layers": 1},
                "train": {"seed": 0, "iterations": 10_000, "batch_size": 16, "lr": 3e-4,
                          "warmup_steps": 500},
                "episodes": 6,
            },
        )  # fmt: skip

    rows = run_tasks(
        [task("DT", "auto"), task("BC", "auto")], executor="local", n_jobs=2, progress=False
    )
    dt, bc = rows["score"].tolist()
    assert np.isfinite(dt) and np.isfinite(bc)
    assert dt >= bc - 5.0, {"DT": dt, "BC": bc}


def test_a_run_of_another_data_recipe_is_refused():
    """A stored parity run made on recipe-2 data cannot be redone by this checkout's generator:
    it is refused with what to do, never run on other data under the same key."""
    from thesis_lib.parity import LEGACY_DATA_RECIPE, Comparison, _load, parity_tasks

    with pytest.raises(ValueError, match="made by data recipe 2.*cannot be redone"):
        _load("hopper/medium", "smoke", LEGACY_DATA_RECIPE)
    old = Comparison(name="a", method="DT", data_recipe=2)
    new = Comparison(name="b", method="DT")
    t_old = parity_tasks([old])["a"]["ours"][0]
    t_new = parity_tasks([new])["b"]["ours"][0]
    assert "data_recipe" not in t_old.config and t_new.config["data_recipe"] >= 3
    assert t_old.key != t_new.key


# ----------------------------------------------------------------------------------------------
# The harness


def test_welch_interval_matches_scipy():
    from scipy import stats

    from thesis_lib.parity import welch_interval

    x, y = [31.0, 32.5, 30.2, 33.0], [29.0, 35.5, 30.0]
    d, lo, hi = welch_interval(x, y)
    res = stats.ttest_ind(x, y, equal_var=False)
    ci = res.confidence_interval(0.95)
    assert d == pytest.approx(np.mean(x) - np.mean(y))
    assert (lo, hi) == pytest.approx((ci.low, ci.high))
    with pytest.raises(ValueError, match=">= 2 seeds"):
        welch_interval([1.0], [1.0, 2.0])


def test_parity_file_merges_common_and_rejects_unknown_keys(tmp_path):
    from thesis_lib.parity import load_parity_file

    f = tmp_path / "p.yml"
    f.write_text(
        "common: {seeds: [0, 1], arch: {d_model: 32, K: 20}, train: {iterations: 10}}\n"
        "comparisons:\n- {name: a, method: DT, arch: {n_layers: 2}}\n- {name: b, method: BC}\n"
    )
    a, b = load_parity_file(f)
    assert a.arch == {"d_model": 32, "K": 20, "n_layers": 2} and a.seeds == (0, 1)
    assert b.method == "BC" and b.train == {"iterations": 10}
    f.write_text("comparisons:\n- {name: a, method: DT, sedes: [0]}\n")
    with pytest.raises(ValueError, match=r"Unknown key\(s\) \['sedes'\] in parity comparison 'a'"):
        load_parity_file(f)
    f.write_text("comparisons:\n- {name: a, method: HDT}\n")
    with pytest.raises(ValueError, match="No peer for 'HDT'.*peer: false"):
        load_parity_file(f)
    f.write_text("comparisons:\n- {name: a, method: HDT, peer: false}\n")
    assert load_parity_file(f)[0].method == "HDT"
    f.write_text("comparisons:\n- {name: a, method: HTD, peer: false}\n")
    with pytest.raises(ValueError, match="Unknown method 'HTD'. Did you mean: 'HDT'"):
        load_parity_file(f)
    f.write_text("comparisons:\n- {name: a, method: DT, init: xavier}\n")
    with pytest.raises(ValueError, match="Unknown init 'xavier'.*in parity comparison 'a'"):
        load_parity_file(f)
    with pytest.raises(FileNotFoundError):
        load_parity_file(tmp_path / "nope.yml")


def test_the_committed_parity_file_parses_and_peer_runs_are_shared():
    from thesis_lib.parity import load_parity_file, parity_tasks, unique_tasks
    from thesis_lib.paths import project_root

    comps = load_parity_file(project_root() / "params" / "parity.yml")
    tasks = parity_tasks(comps)
    # dt-study, -v1 and -original differ only in our init: one set of peer runs
    peer = {t.key for name in ("dt-study", "dt-study-v1", "dt-study-original")
            for t in tasks[name]["peer"]}  # fmt: skip
    assert len(peer) == 3
    # ... and so do the d64 medium-replay DTs at three initialisations
    mr = [
        {t.key for t in tasks[n]["peer"]}
        for n in ("dt-mr-d64", "dt-mr-d64-torch", "dt-mr-d64-d3rlpy")
    ]
    assert mr[1] < mr[0] == mr[2] and len(mr[0]) == 5  # torch: three of the five seeds
    # bfloat16 training is ours to vary: dt-peer-r4-bf16 reads dt-peer-r4's peer runs, and its
    # own side is new runs, which train in bf16
    # (and so are the fast kernels: dt-peer-r4-bf16-fast too)
    names = ("dt-peer-r4", "dt-peer-r4-bf16", "dt-peer-r4-bf16-fast")
    bf = {n: tasks[n] for n in names}
    assert len({tuple(t.key for t in bf[n]["peer"]) for n in names}) == 1
    ours = [{t.key for t in bf[n]["ours"]} for n in names]
    assert all(len(o) == 3 for o in ours) and len(set().union(*ours)) == 9
    assert [t.config["train"].get("kernels") for t in bf["dt-peer-r4-bf16-fast"]["ours"]] == [
        "fast"
    ] * 3
    assert all("kernels" not in t.config["train"] for t in bf["dt-peer-r4-bf16"]["ours"])
    assert all(t.config["train"]["precision"] == "bf16" for t in bf["dt-peer-r4-bf16"]["ours"])
    assert all("precision" not in t.config["train"] for t in bf["dt-peer-r4-bf16"]["peer"])
    # an explicit fp32 is the default: the same runs
    from thesis_lib.parity import Comparison

    plain, fp32 = (
        Comparison(name=n, method="DT", train={"iterations": 5, **extra})
        for n, extra in (("plain", {}), ("fp32", {"precision": "fp32"}))
    )
    same = parity_tasks([plain, fp32])
    assert [t.key for t in same["plain"]["ours"]] == [t.key for t in same["fp32"]["ours"]]
    assert len(unique_tasks(tasks)) < sum(len(s["ours"]) + len(s["peer"]) for s in tasks.values())


def test_export_npz_flattens_episodes_with_terminals_and_timeouts(tmp_path):
    from types import SimpleNamespace

    from thesis_lib.parity import export_npz

    def ep(n, terminated):
        t = np.zeros(n, dtype=bool)
        t[-1] = terminated
        return SimpleNamespace(
            observations=np.arange((n + 1) * 2.0).reshape(n + 1, 2),
            actions=np.ones((n, 1)),
            rewards=np.full(n, 0.5),
            terminations=t,
        )

    z = np.load(
        export_npz(SimpleNamespace(episodes=[ep(3, True), ep(2, False)]), tmp_path / "d.npz")
    )
    assert z["observations"].shape == (5, 2)  # the final observation of each episode dropped
    assert z["terminals"].tolist() == [0, 0, 1, 0, 0]
    assert z["timeouts"].tolist() == [0, 0, 0, 0, 1]
    assert z["rewards"].sum() == 2.5


def test_parity_table_says_parity_only_inside_the_band():
    from thesis_lib.parity import Comparison, parity_table

    def rows(scores):
        return [
            {"score": s, "data_score_mean": 32.0, "data_sha": "x", "peer": "d3rlpy"} for s in scores
        ]

    comps = [Comparison(n, "DT") for n in ("same", "gap")] + [
        Comparison("two", "DT", train={"precision": "bf16"}),
        Comparison("half", "BC"),
    ]
    got = {
        "same": {"ours": rows([31, 32, 33]), "peer": rows([32, 31, 33])},
        "gap": {"ours": rows([16, 17, 18]), "peer": rows([32, 31, 33])},
        "two": {"ours": rows([31, 33]), "peer": rows([32, 32])},
        "half": {"ours": rows([30]), "peer": []},
    }
    t = parity_table(comps, got).set_index("comparison")
    assert bool(t.loc["same", "parity"]) and t.loc["same", "difference"] == pytest.approx(0.0)
    assert not bool(t.loc["gap", "parity"]) and t.loc["gap", "ci_high"] < 0
    # two seeds a side: an interval, but no verdict (issue #33 asks for >= 3 each)
    assert t.loc["two", "ci_low"] < 0 < t.loc["two", "ci_high"] and t.loc["two", "parity"] is None
    assert pd.isna(t.loc["half", "difference"]) and t.loc["half", "parity"] is None
    # the Claims page's reading of each line
    from thesis_lib.chapters.claims import parity_view

    view = parity_view(t.reset_index()).set_index("comparison")
    assert view["precision"].to_dict() == {
        "same": "fp32",
        "gap": "fp32",
        "two": "bf16",
        "half": "fp32",
    }
    view = view["result"]
    assert view.to_dict() == {
        "same": "at parity",
        "gap": "gap",
        "two": "fewer than 3 seeds a side",
        "half": "no peer",
    }


def test_thesis_parity_skips_runs_it_cannot_redo(tmp_path, capsys):
    """`make parity` runs what is missing; a missing run of another data recipe cannot be made
    (its data is gone), so it is skipped and named, and the table is still written."""
    from thesis_lib.cli import main

    f = tmp_path / "parity.yml"
    f.write_text(
        "common: {dataset: hopper/medium, dataset_size: smoke, seeds: [0, 1], episodes: 2}\n"
        "comparisons:\n- {name: old, method: DT, data_recipe: 2}\n"
    )
    store = tmp_path / "runs" / "tasks"
    assert main(["parity", "-f", str(f), "--store", str(store)]) == 0
    out = capsys.readouterr()
    assert "skipping 4 run(s) of old" in out.err and "cannot be redone" in out.err
    assert (store.parent / "parity.csv").is_file() and not list(store.glob("*.json"))
