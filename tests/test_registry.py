"""The one registry of offline sequence methods (thesis_lib.seq.registry)."""

from __future__ import annotations

from types import SimpleNamespace

import pytest
import torch

from thesis_lib.seq import BC, HDM, HDT, DecisionMamba, DecisionTransformer
from thesis_lib.seq.registry import METHODS, RTG_METHODS, ArchSpec, build_model

SEQ = SimpleNamespace(states=torch.zeros(10, 11), actions=torch.zeros(10, 3), K=99)


@pytest.mark.parametrize(
    "method, cls",
    [
        ("BC", BC),
        ("DT", DecisionTransformer),
        ("DT-noRTG", DecisionTransformer),
        ("HDT", HDT),
        ("HDT-RTG", HDT),
        ("DM-RTG", DecisionMamba),
        ("DM-noRTG", DecisionMamba),
        ("HDM", HDM),
    ],
)
def test_every_method_is_built_from_one_arch_spec(method, cls):
    arch = ArchSpec(d_model=16, n_layers=2, n_heads=2, K=5, dropout=0.0, bc_hidden_dim=8)
    model = build_model(method, SEQ, arch, max_action=2.0)
    assert type(model) is cls
    c = model.config
    assert (c.state_dim, c.act_dim, c.K, c.max_action) == (11, 3, 5, 2.0)  # K from the spec
    if method != "BC":
        assert (c.d_model, c.n_layers) == (16, 2)
    rtg = getattr(c, "use_rtg", getattr(c, "low_use_rtg", False))
    assert rtg == (method in RTG_METHODS)
    assert arch.label == "L2 D16 K5"


def test_unknown_method_names_the_closest():
    assert len(METHODS) == 8
    with pytest.raises(ValueError, match="Unknown method 'HDTT'. Did you mean: 'HDT'"):
        build_model("HDTT", SEQ, ArchSpec())
