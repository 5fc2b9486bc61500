"""Tests for thesis_lib.seq.models: BC, DT and HDT (thesis 2.8, 5.2)."""

from __future__ import annotations

import pytest
import torch

from thesis_lib.seq.models import (
    BC,
    HDT,
    BCConfig,
    DecisionTransformer,
    DTConfig,
    HDTConfig,
    masked_mse,
)

torch.set_num_threads(1)
SD, AD, K = 3, 2, 5
SMALL = dict(K=K, d_model=16, n_layers=2, n_heads=2, dropout=0.0)


def _batch(B=2, T=K, seed=0):
    g = torch.Generator().manual_seed(seed)
    actions = torch.randn(B, T, AD, generator=g)
    prev = torch.cat([torch.zeros(B, 1, AD), actions[:, :-1]], dim=1)
    subgoals = torch.randn(B, T, SD, generator=g)
    prev_g = torch.cat([torch.zeros(B, 1, SD), subgoals[:, :-1]], dim=1)
    return {
        "states": torch.randn(B, T, SD, generator=g),
        "actions": actions,
        "prev_actions": prev,
        "returns_to_go": torch.randn(B, T, 1, generator=g),
        "timesteps": torch.arange(T).repeat(B, 1),
        "mask": torch.ones(B, T, dtype=torch.bool),
        "subgoals": subgoals,
        "prev_subgoals": prev_g,
    }


def _models(paper_compat=False):
    torch.manual_seed(0)
    small = dict(SMALL, paper_compat=paper_compat)
    return {
        "dt": DecisionTransformer(DTConfig(SD, AD, **small)).eval(),
        "dt_no_rtg": DecisionTransformer(DTConfig(SD, AD, use_rtg=False, **small)).eval(),
        "hdt": HDT(HDTConfig(SD, AD, **small)).eval(),
        "hdt_rtg": HDT(HDTConfig(SD, AD, low_use_rtg=True, **small)).eval(),
    }


def _outputs(model, batch):
    out = model(batch)
    return out.actions if out.subgoals is None else torch.cat([out.actions, out.subgoals], dim=-1)


INPUTS = ("states", "actions", "prev_actions", "returns_to_go", "subgoals", "prev_subgoals")


@pytest.mark.parametrize("name", ["dt", "dt_no_rtg", "hdt", "hdt_rtg"])
@pytest.mark.parametrize("paper_compat", [False, True])
def test_no_output_depends_on_the_future(name, paper_compat):
    model = _models(paper_compat)[name]
    batch = _batch()
    base = _outputs(model, batch)
    t = 2
    for key in INPUTS:
        changed = {k: v.clone() for k, v in batch.items()}
        changed[key][:, t + 1 :] += 10.0  # only the future of step t changes
        out = _outputs(model, changed)
        torch.testing.assert_close(
            out[:, : t + 1], base[:, : t + 1], msg=f"{name}: {key} leaks from the future"
        )


@pytest.mark.parametrize("name", ["dt", "hdt"])
def test_padding_is_invisible(name):
    model = _models()[name]
    batch = _batch()
    batch["mask"][:, 3:] = False  # steps 3, 4 are right padding
    base = _outputs(model, batch)
    changed = {k: v.clone() for k, v in batch.items()}
    for key in INPUTS:
        changed[key][:, 3:] = 99.0
    changed["timesteps"][:, 3:] = 0
    torch.testing.assert_close(_outputs(model, changed)[:, :3], base[:, :3])


def test_action_token_default_vs_paper_compat():
    batch = _batch()
    t = 2
    # Default: a_t is predicted at s_t, which sees a_{t-1} (the previous step's action token).
    dt = _models()["dt"]
    changed = {k: v.clone() for k, v in batch.items()}
    changed["actions"][:, t - 1] += 10.0  # a_{t-1}
    assert not torch.allclose(dt(changed).actions[:, t], dt(batch).actions[:, t])
    changed = {k: v.clone() for k, v in batch.items()}
    changed["actions"][:, t] += 10.0  # a_t itself is hidden from its own prediction
    torch.testing.assert_close(dt(changed).actions[:, t], dt(batch).actions[:, t])
    # The authors' layout puts a_{t-1} after s_t: the prediction of a_t never sees a_{t-1}.
    dt_paper = _models(paper_compat=True)["dt"]
    changed = {k: v.clone() for k, v in batch.items()}
    changed["prev_actions"][:, t] += 10.0  # prev_actions[:, t] = a_{t-1}
    torch.testing.assert_close(dt_paper(changed).actions[:, t], dt_paper(batch).actions[:, t])


def test_hdt_high_level_reads_previous_subgoal_and_low_level_the_current():
    hdt = _models()["hdt"]
    batch = _batch()
    t = 2
    changed = {k: v.clone() for k, v in batch.items()}
    changed["subgoals"][:, t] += (
        10.0  # g_t: the low level's input at step t, the high level's target
    )
    out, base = hdt(changed), hdt(batch)
    assert not torch.allclose(out.actions[:, t], base.actions[:, t])
    torch.testing.assert_close(out.subgoals, base.subgoals)  # high level reads prev_subgoals only


def test_action_heads_are_bounded_by_max_action():
    torch.manual_seed(0)
    batch = _batch()
    batch["states"] *= 1e3
    for model in (
        BC(BCConfig(SD, AD, K=K, max_action=0.4)),
        DecisionTransformer(DTConfig(SD, AD, max_action=0.4, **SMALL)),
    ):
        a = model(batch).actions
        assert a.abs().max() <= 0.4 + 1e-6


def test_losses_are_masked_mse():
    torch.manual_seed(0)
    batch = _batch()
    batch["mask"][0, 3:] = False
    for model in _models().values():
        out = model(batch, targets=batch)
        expected = masked_mse(out.actions, batch["actions"], batch["mask"])
        if out.subgoals is not None:
            expected = expected + masked_mse(out.subgoals, batch["subgoals"], batch["mask"])
        torch.testing.assert_close(out.loss, expected)
    p, y = torch.zeros(1, 3, 2), torch.tensor([[[1.0, 1.0], [2.0, 2.0], [100.0, 100.0]]])
    assert masked_mse(p, y, torch.tensor([[True, True, False]])).item() == pytest.approx(2.5)


def test_act_returns_the_last_step():
    models = _models()
    batch = _batch(T=3)
    a = models["dt"].act(batch)
    torch.testing.assert_close(a.actions, models["dt"](batch).actions[:, -1])
    out = models["hdt"].act(batch)
    assert out.actions.shape == (2, AD) and out.subgoals.shape == (2, SD)
    # act feeds the high level's prediction to the low level at the last step
    fed = {k: v.clone() for k, v in batch.items()}
    fed["subgoals"][:, -1] = out.subgoals
    torch.testing.assert_close(out.actions, models["hdt"](fed).actions[:, -1])
    bc = BC(BCConfig(SD, AD, K=K)).eval()
    torch.testing.assert_close(bc.act(batch).actions, bc(batch).actions[:, -1])


def test_state_dimension_mismatch_names_both_shapes():
    model = DecisionTransformer(DTConfig(11, AD, **SMALL))
    with pytest.raises(
        ValueError, match=r"expects states of shape \(batch, seq_len, 11\), got \(2, 5, 3\)"
    ):
        model(_batch())
    with pytest.raises(ValueError, match=r"HDT expects states of shape \(batch, seq_len, 11\)"):
        HDT(HDTConfig(11, AD, **SMALL))(_batch())
    with pytest.raises(ValueError, match=r"BC expects states"):
        BC(BCConfig(11, AD))(_batch())
    dt = DecisionTransformer(DTConfig(SD, 4, **SMALL))
    with pytest.raises(ValueError, match=r"expects actions of shape \(batch, seq_len, 4\)"):
        dt(_batch())
    with pytest.raises(ValueError, match="context K=3"):
        DecisionTransformer(DTConfig(SD, AD, **dict(SMALL, K=3)))(_batch())
    with pytest.raises(KeyError, match="missing: subgoals, prev_subgoals"):
        HDT(HDTConfig(SD, AD, **SMALL))({k: v for k, v in _batch().items() if "subgoal" not in k})
    with pytest.raises(ValueError, match="max_timestep"):
        b = _batch()
        b["timesteps"] += 5000
        DecisionTransformer(DTConfig(SD, AD, **SMALL))(b)


def test_configs_are_validated():
    with pytest.raises(ValueError, match="d_model must be divisible by n_heads"):
        DTConfig(SD, AD, d_model=10, n_heads=3)
    with pytest.raises(ValueError, match="`state_dim` to be a positive int"):
        HDTConfig(0, AD)
    with pytest.raises(ValueError, match="Unknown activation 'tanh'. Valid:"):
        DTConfig(SD, AD, activation="tanh")
    with pytest.raises(ValueError, match="max_action"):
        BCConfig(SD, AD, max_action=0.0)


def test_hdt_clip_groups_split_the_two_levels():
    hdt = HDT(HDTConfig(SD, AD, **SMALL))
    high, low = hdt.clip_groups()
    assert len(high) + len(low) == len(list(hdt.parameters()))
    assert {id(p) for p in high}.isdisjoint(id(p) for p in low)
    # the high level's loss has no gradient in the low group, and vice versa
    batch = _batch()
    out = hdt(batch, targets=batch)
    from thesis_lib.seq.models import masked_mse as mse

    mse(out.subgoals, batch["subgoals"], batch["mask"]).backward()
    assert all(p.grad is None or not p.grad.any() for p in low)
    assert any(p.grad is not None and p.grad.any() for p in high)
