"""Tests of thesis_lib.seq.mamba: the fast selective scan, the Mamba block, recurrent stepping."""

from __future__ import annotations

import pytest
import torch

from thesis_lib.seq._scan import SelectiveScanCPU, SelectiveScanTorch, scan_cpu_forward
from thesis_lib.seq.mamba import (
    Mamba,
    MambaBlock,
    MambaConfig,
    MambaState,
    ScanOutput,
    _scan_with_mamba_ssm,
    causal_depthwise_conv1d,
    resolve_scan_backend,
    selective_scan,
)
from thesis_lib.seq.ssm import selective_scan_reference, selective_scan_step

FAST = ("numba", "torch")
TOL = {torch.float32: 1e-5, torch.float64: 1e-10}


def scan_inputs(dtype=torch.float64, batch=2, L=9, Din=5, N=4, seed=0, requires_grad=False):
    g = torch.Generator().manual_seed(seed)
    r = lambda *s: torch.randn(*s, generator=g, dtype=dtype)
    out = {
        "u": r(batch, L, Din),
        "delta": r(batch, L, Din),  # raw: through bias + softplus, or made positive below
        "A": -torch.rand(Din, N, generator=g, dtype=dtype) * 3 - 0.1,
        "B": r(batch, L, N),
        "C": r(batch, L, N),
        "D": r(Din),
        "z": r(batch, L, Din),
        "delta_bias": r(Din) * 0.5,
    }
    if requires_grad:
        for t in out.values():
            t.requires_grad_(True)
    return out


OPTIONS = [
    pytest.param({}, id="plain"),
    pytest.param({"D": True}, id="D"),
    pytest.param({"z": True}, id="z"),
    pytest.param({"delta_bias": True, "delta_softplus": True}, id="bias+softplus"),
    pytest.param({"D": True, "z": True, "delta_bias": True, "delta_softplus": True}, id="all"),
]


def call_args(x, opts):
    args = (
        x["u"],
        x["delta"] if opts.get("delta_softplus") else x["delta"].abs() * 0.5,
        x["A"],
        x["B"],
        x["C"],
    )
    kw = {
        "D": x["D"] if opts.get("D") else None,
        "z": x["z"] if opts.get("z") else None,
        "delta_bias": x["delta_bias"] if opts.get("delta_bias") else None,
        "delta_softplus": bool(opts.get("delta_softplus")),
    }
    return args, kw


# --------------------------------------------------------------------------- scan
@pytest.mark.parametrize("backend", FAST)
@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
@pytest.mark.parametrize("opts", OPTIONS)
def test_scan_matches_reference(backend, dtype, opts):
    x = scan_inputs(dtype)
    args, kw = call_args(x, opts)
    want = selective_scan_reference(*args, **kw)
    got = selective_scan(*args, **kw, backend=backend)
    assert got.dtype == dtype and got.shape == want.shape
    torch.testing.assert_close(got, want, atol=TOL[dtype], rtol=0)


@pytest.mark.parametrize("backend", FAST)
def test_scan_gradients_match_reference(backend):
    """Hand-written backward == autograd through the naive loop, for every input."""
    x = scan_inputs(torch.float64, requires_grad=True)
    opts = {"D": True, "z": True, "delta_bias": True, "delta_softplus": True}
    args, kw = call_args(x, opts)
    inputs = [t for t in (*args, *kw.values()) if isinstance(t, torch.Tensor)]
    gy = torch.randn(args[0].shape, dtype=torch.float64, generator=torch.Generator().manual_seed(1))
    want = torch.autograd.grad((selective_scan_reference(*args, **kw) * gy).sum(), inputs)
    got = torch.autograd.grad((selective_scan(*args, **kw, backend=backend) * gy).sum(), inputs)
    for name, g, w in zip(["u", "delta", "A", "B", "C", "D", "z", "delta_bias"], got, want):
        torch.testing.assert_close(g, w, atol=1e-10, rtol=0, msg=f"gradient of {name}")


@pytest.mark.parametrize("fn", [SelectiveScanCPU, SelectiveScanTorch], ids=["numba", "torch"])
def test_scan_function_gradcheck(fn):
    x = scan_inputs(torch.float64, batch=2, L=5, Din=3, N=2, requires_grad=True)
    delta = (x["delta"].detach().abs() * 0.5).requires_grad_(True)
    inputs = (x["u"], delta, x["A"], x["B"], x["C"])
    assert torch.autograd.gradcheck(lambda *a: fn.apply(*a)[0], inputs)


def test_selective_scan_gradcheck_full():
    x = scan_inputs(torch.float64, batch=1, L=4, Din=2, N=3, requires_grad=True)

    def f(u, delta, A, B, C, D, z, bias):
        return selective_scan(
            u, delta, A, B, C, D, z, delta_bias=bias, delta_softplus=True, backend="numba"
        )

    assert torch.autograd.gradcheck(f, tuple(x.values()))


@pytest.mark.parametrize("backend", FAST)
def test_scan_last_state_continues_with_step(backend):
    """h_last from the scan of L-1 steps, then one selective_scan_step == the full scan's last y."""
    x = scan_inputs(torch.float64)
    delta = x["delta"].abs() * 0.5
    full = selective_scan(x["u"], delta, x["A"], x["B"], x["C"], x["D"], backend=backend)
    y, h = selective_scan(
        x["u"][:, :-1],
        delta[:, :-1],
        x["A"],
        x["B"][:, :-1],
        x["C"][:, :-1],
        x["D"],
        return_last_state=True,
        backend=backend,
    )
    assert isinstance(y, torch.Tensor) and h.shape == (2, 5, 4)
    last = selective_scan_step(
        h, x["u"][:, -1], delta[:, -1], x["A"], x["B"][:, -1], x["C"][:, -1], x["D"]
    )
    torch.testing.assert_close(last.y, full[:, -1], atol=1e-12, rtol=0)


def test_scan_forward_without_autograd():
    x = scan_inputs(torch.float32)
    args = (x["u"], x["delta"].abs(), x["A"], x["B"], x["C"])
    y, h = scan_cpu_forward(*args)
    assert h.shape == (2, 5, 4)
    torch.testing.assert_close(y, selective_scan_reference(*args), atol=1e-5, rtol=0)


def test_scan_promotes_mixed_dtypes():
    x = scan_inputs(torch.float32)
    y = selective_scan(x["u"], x["delta"].abs(), x["A"].double(), x["B"], x["C"])
    assert y.dtype == torch.float64


def test_scan_rejects_bad_shapes():
    x = scan_inputs()
    with pytest.raises(ValueError, match=r"Expect `B` of shape \(2, 9, 4\)"):
        selective_scan(x["u"], x["delta"], x["A"], x["B"][:, :3], x["C"])


def test_mamba_ssm_layout_adapter():
    """The CUDA dispatch transposes to mamba_ssm's (B, Din, L) layout and back."""

    def fake_selective_scan_fn(
        u,
        delta,
        A,
        B,
        C,
        D=None,
        z=None,
        delta_bias=None,
        delta_softplus=False,
        return_last_state=False,
    ):
        assert u.shape == (2, 5, 9) and B.shape == (2, 4, 9)  # (B, Din, L), (B, N, L)
        t = lambda x: None if x is None else x.transpose(1, 2)
        y = selective_scan_reference(
            t(u),
            t(delta),
            A,
            t(B),
            t(C),
            D,
            t(z),
            delta_bias=delta_bias,
            delta_softplus=delta_softplus,
        ).transpose(1, 2)
        return (y, None) if return_last_state else y

    x = scan_inputs()
    args, kw = call_args(x, {"D": True, "z": True, "delta_bias": True, "delta_softplus": True})
    got = _scan_with_mamba_ssm(
        fake_selective_scan_fn, *args, kw["D"], kw["z"], kw["delta_bias"], True, False
    )
    torch.testing.assert_close(got, selective_scan_reference(*args, **kw), atol=1e-12, rtol=0)
    assert isinstance(
        _scan_with_mamba_ssm(fake_selective_scan_fn, *args, None, None, None, True, True),
        ScanOutput,
    )


def test_backend_dispatch(monkeypatch):
    import thesis_lib.seq.mamba as mamba_mod

    assert resolve_scan_backend("cpu") == "numba"
    with pytest.raises(ValueError, match="Unknown scan backend 'cuda'. Valid: auto, numba"):
        resolve_scan_backend("cpu", "cuda")
    monkeypatch.setattr(mamba_mod, "_mamba_ssm_scan_fn", lambda: None)
    assert resolve_scan_backend("cuda") == "torch"  # no mamba_ssm: the vectorised loop
    with pytest.raises(RuntimeError, match="pip install mamba-ssm"):
        resolve_scan_backend("cpu", "mamba_ssm")
    monkeypatch.setattr(mamba_mod, "_mamba_ssm_scan_fn", lambda: object())
    assert resolve_scan_backend("cuda") == "mamba_ssm"
    assert resolve_scan_backend("cpu") == "numba"  # CPU tensors never go to the CUDA kernel


@pytest.mark.parametrize("K", [1, 4])
def test_causal_conv_matches_conv1d(K):
    conv = torch.nn.Conv1d(6, 6, K, groups=6, padding=K - 1)
    x = torch.randn(2, 7, 6)
    want = conv(x.transpose(1, 2))[..., :7].transpose(1, 2)
    torch.testing.assert_close(
        causal_depthwise_conv1d(x, conv.weight, conv.bias), want, atol=1e-6, rtol=0
    )


def test_causal_conv_of_bfloat16_input_computes_in_float32():
    """A bfloat16 input (under ``precision="bf16"``, ``in_proj``'s output) with float32 weights
    convolves in float32: the forward is the float32 input's exactly, and the input's gradient
    is summed over the K taps in float32, then rounded once."""
    torch.manual_seed(0)
    conv = torch.nn.Conv1d(6, 6, 4, groups=6, padding=3)
    x16 = torch.randn(2, 7, 6).bfloat16().requires_grad_()
    x32 = x16.detach().float().requires_grad_()
    y16 = causal_depthwise_conv1d(x16, conv.weight, conv.bias)
    y32 = causal_depthwise_conv1d(x32, conv.weight, conv.bias)
    assert y16.dtype == torch.float32
    torch.testing.assert_close(y16, y32, atol=0, rtol=0)
    g = torch.randn_like(y32)
    (g16,) = torch.autograd.grad(y16, x16, g)
    (g32,) = torch.autograd.grad(y32, x32, g)
    assert g16.dtype == torch.bfloat16
    torch.testing.assert_close(g16, g32.bfloat16(), atol=0, rtol=0)


# --------------------------------------------------------------------------- config
@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"d_model": 0}, r"Expect `d_model` to be a positive int, actually: 0"),
        ({"n_layers": 2.5}, r"Expect `n_layers` to be a positive int, actually: 2.5"),
        ({"dt_rank": "big"}, r"Expect `dt_rank` to be 'auto' or a positive int, actually: 'big'"),
        (
            {"dt_min": 0.5, "dt_max": 0.1},
            r"Expect 0 < dt_min <= dt_max, actually: dt_min=0.5, dt_max=0.1",
        ),
        ({"dt_init": "normal"}, r"Unknown dt_init 'normal'. Valid: random, constant"),
        ({"norm_eps": 0.0}, r"Expect `norm_eps` to be positive"),
    ],
)
def test_config_errors(kwargs, match):
    with pytest.raises(ValueError, match=match):
        MambaConfig(**kwargs)


def test_config_derived_fields():
    cfg = MambaConfig(d_model=128, gated_mlp=True)
    assert (cfg.d_inner, cfg.dt_rank_value, cfg.mlp_hidden_value) == (256, 8, 384)
    assert MambaConfig(d_model=20, dt_rank=3, mlp_hidden=50).dt_rank_value == 3


# --------------------------------------------------------------------------- model
def tiny(seed=0, **kw) -> Mamba:
    torch.manual_seed(seed)
    cfg = dict(d_model=8, n_layers=2, d_state=4)
    cfg.update(kw)
    return Mamba(MambaConfig(**cfg)).eval()


@pytest.mark.parametrize("fused", [True, False], ids=["fused", "torch-ops"])
@pytest.mark.parametrize("gated_mlp", [False, True])
@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
def test_recurrent_step_equals_forward(gated_mlp, fused, dtype):
    model = tiny(gated_mlp=gated_mlp, bias=True).to(dtype)
    x = torch.randn(3, 11, 8, dtype=dtype)
    with torch.no_grad():
        full, full_state = model(x, return_state=True)
        state = model.allocate_state(batch=3)
        ys = []
        for t in range(x.shape[1]):
            y_t, state = model.step(x[:, t], state, fused=fused)
            ys.append(y_t)
    tol = TOL[dtype]
    torch.testing.assert_close(torch.stack(ys, 1), full, atol=tol, rtol=0)
    torch.testing.assert_close(state.ssm, full_state.ssm, atol=tol, rtol=0)
    torch.testing.assert_close(state.conv, full_state.conv, atol=tol, rtol=0)


def test_step_tokens_equals_steps_and_follows_weight_updates():
    """step_tokens == repeated step; the fused kernel's packed weights follow optimiser updates."""
    model = tiny(gated_mlp=True)
    x = torch.randn(2, 5, 8)
    with torch.no_grad():
        y, s = model.step_tokens(x, model.allocate_state(2))
        torch.testing.assert_close(y, model(x), atol=1e-5, rtol=0)
        y1, _ = model.step(x[:, 0], model.allocate_state(2))  # fills the weight cache
    opt = torch.optim.SGD(model.parameters(), lr=0.1)
    model(x).square().sum().backward()
    opt.step()
    with torch.no_grad():
        y2, _ = model.step(x[:, 0], model.allocate_state(2))
        torch.testing.assert_close(y2, model(x[:, :1])[:, 0], atol=1e-5, rtol=0)
    assert not torch.allclose(y1, y2)


def test_step_with_autograd_uses_torch_ops():
    model = tiny()
    x_t = torch.randn(2, 8)
    y, _ = model.step(x_t, model.allocate_state(2))  # grad enabled: differentiable path
    y.sum().backward()
    assert model.layers[0].mixer.in_proj.weight.grad is not None
    with pytest.raises(
        RuntimeError, match=r"wrap the call in torch.no_grad\(\) or pass fused=False"
    ):
        model.step(x_t, model.allocate_state(2), fused=True)


def test_prefill_then_step_equals_forward():
    """forward(return_state=True) on a prefix, then steps: as one forward (incl. a prefix < d_conv)."""
    model = tiny(d_conv=4)
    x = torch.randn(2, 9, 8)
    with torch.no_grad():
        full = model(x)
        for n_prefix in (2, 6):
            _, state = model(x[:, :n_prefix], return_state=True)
            assert isinstance(state, MambaState)
            for t in range(n_prefix, x.shape[1]):
                y_t, state = model.step(x[:, t], state)
            torch.testing.assert_close(y_t, full[:, -1], atol=1e-5, rtol=0)


def test_step_does_not_modify_old_state():
    model = tiny()
    state = model.allocate_state(1)
    with torch.no_grad():
        _, new = model.step(torch.randn(1, 8), state)
    assert state.ssm.abs().sum() == 0 and new.ssm.abs().sum() > 0


def test_step_rejects_wrong_state():
    model = tiny()
    with pytest.raises(ValueError, match=r"Create one with allocate_state\(batch=2\)"):
        model.step(torch.randn(2, 8), model.allocate_state(batch=3))
    with pytest.raises(ValueError, match=r"Expect input of shape \(B, L, d_model\) with d_model=8"):
        model(torch.randn(2, 5, 7))


def test_causal_right_padding_does_not_change_real_tokens():
    model = tiny()
    x = torch.randn(2, 6, 8)
    padded = torch.cat([x, torch.zeros(2, 4, 8)], dim=1)
    with torch.no_grad():
        torch.testing.assert_close(model(padded)[:, :6], model(x), atol=1e-6, rtol=0)


@pytest.mark.parametrize("backend", ["numba", "torch"])
def test_scan_backends_agree_in_the_model(backend):
    ref = tiny(seed=3)
    model = tiny(seed=3)
    for block in model.layers:
        block.mixer.scan_backend = backend
    for block in ref.layers:
        block.mixer.scan_backend = "reference"
    x = torch.randn(2, 7, 8, dtype=torch.float64)
    ref, model = ref.double(), model.double()
    torch.testing.assert_close(model(x), ref(x), atol=1e-10, rtol=0)
    g = torch.autograd.grad(model(x).square().sum(), list(model.parameters()))
    g_ref = torch.autograd.grad(ref(x).square().sum(), list(ref.parameters()))
    for a, b in zip(g, g_ref):
        torch.testing.assert_close(a, b, atol=1e-9, rtol=0)


def test_matches_mambapy_given_same_weights():
    mambapy = pytest.importorskip("mambapy.mamba", reason="mambapy==1.2.0 not installed")
    torch.manual_seed(0)
    theirs = mambapy.Mamba(mambapy.MambaConfig(d_model=16, n_layers=2, d_state=8, pscan=True))
    ours = Mamba(MambaConfig(d_model=16, n_layers=2, d_state=8, final_norm=False))
    ours.load_state_dict(theirs.state_dict())  # strict: the parameter names line up one to one
    x = torch.randn(3, 10, 16)
    torch.testing.assert_close(ours(x), theirs(x), atol=1e-5, rtol=1e-5)
    ours(x).square().sum().backward()
    theirs(x).square().sum().backward()
    grads = dict(theirs.named_parameters())
    for name, p in ours.named_parameters():
        torch.testing.assert_close(p.grad, grads[name].grad, atol=1e-4, rtol=1e-4, msg=name)


def test_block_shape_and_loss_falls():
    """A 2-layer model learns a causal sequence regression (running mean of a channel)."""
    torch.manual_seed(0)
    model = Mamba(MambaConfig(d_model=8, n_layers=2, d_state=4))
    head = torch.nn.Linear(8, 1)
    x = torch.randn(16, 12, 8)
    target = x[..., :1].cumsum(1) / torch.arange(1, 13).view(1, -1, 1)
    opt = torch.optim.AdamW([*model.parameters(), *head.parameters()], lr=1e-2)
    losses = []
    for _ in range(60):
        opt.zero_grad()
        loss = torch.nn.functional.mse_loss(head(model(x)), target)
        loss.backward()
        opt.step()
        losses.append(loss.item())
    assert losses[-1] < 0.3 * losses[0], (losses[0], losses[-1])


def test_block_api():
    block = MambaBlock(MambaConfig(d_model=8, n_layers=1, gated_mlp=True))
    assert block(torch.randn(2, 3, 8)).shape == (2, 3, 8)
    assert block.mlp is not None and block.mixer.A_log._no_weight_decay
