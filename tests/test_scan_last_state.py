"""The selective scan's last state carries its gradient on every CPU backend.

A review found that the ``torch`` backend returned a last state with ``requires_grad=True``
and a silently zero gradient (``"auto"`` picks that backend on CUDA without ``mamba_ssm``).
"""

from __future__ import annotations

import pytest
import torch

from thesis_lib.seq import selective_scan


def _naive(u, delta, A, B, C):
    """The recurrence written out with autograd ops (float64): ``(y, h_last)``."""
    b, L, d = u.shape
    h = torch.zeros(b, d, A.shape[1], dtype=u.dtype)
    ys = []
    for t in range(L):
        dA = torch.exp(delta[:, t, :, None] * A)
        h = dA * h + (delta[:, t] * u[:, t])[:, :, None] * B[:, t, None, :]
        ys.append((h * C[:, t, None, :]).sum(-1))
    return torch.stack(ys, 1), h


def _inputs(seed: int = 0):
    g = torch.Generator().manual_seed(seed)
    b, L, d, n = 2, 7, 5, 3
    u = torch.randn(b, L, d, generator=g, dtype=torch.float64)
    delta = torch.rand(b, L, d, generator=g, dtype=torch.float64) * 0.5 + 0.05
    A = -torch.rand(d, n, generator=g, dtype=torch.float64) - 0.1
    B = torch.randn(b, L, n, generator=g, dtype=torch.float64)
    C = torch.randn(b, L, n, generator=g, dtype=torch.float64)
    wy = torch.randn(b, L, d, generator=g, dtype=torch.float64)
    wh = torch.randn(b, d, n, generator=g, dtype=torch.float64)
    return [x.requires_grad_() for x in (u, delta, A, B, C)], wy, wh


def _grads(loss, xs):
    """Gradients, zero for an input the loss does not use (C, when only h_last counts)."""
    gs = torch.autograd.grad(loss, xs, allow_unused=True)
    return [torch.zeros_like(x) if g is None else g for x, g in zip(xs, gs)]


@pytest.mark.parametrize("backend", ["numba", "torch"])
@pytest.mark.parametrize("with_y", [True, False])
def test_last_state_gradient_matches_the_written_out_recurrence(backend, with_y):
    xs, wy, wh = _inputs()
    y, h = selective_scan(*xs, return_last_state=True, backend=backend)
    loss = (h * wh).sum() + ((y * wy).sum() if with_y else 0.0)
    got = _grads(loss, xs)
    xs2 = [x.detach().clone().requires_grad_() for x in xs]
    y2, h2 = _naive(*xs2)
    torch.testing.assert_close(h.detach(), h2.detach())
    loss2 = (h2 * wh).sum() + ((y2 * wy).sum() if with_y else 0.0)
    want = _grads(loss2, xs2)
    for name, a, b in zip("u delta A B C".split(), got, want):
        torch.testing.assert_close(a, b, msg=f"{backend}: gradient of {name}")
    assert h.requires_grad and any(g.abs().sum() > 0 for g in got)
