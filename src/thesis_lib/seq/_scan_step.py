"""Fused CPU kernel for :meth:`thesis_lib.seq.mamba.Mamba.step`: a whole stack, T tokens, one call.

At batch 1 (one environment) a recurrent step through 6 layers of torch ops is ~30 small ops
per layer and token, each costing more in dispatch than in arithmetic; the whole step then
costs about as much as re-running the 60-token window. This kernel does the same arithmetic
as :meth:`thesis_lib.seq.mamba.MambaBlock.step` (RMSNorm, in_proj, conv window, SiLU, x_proj,
softplus Δ, one scan step, SiLU gate, out_proj, residual, optional gated MLP, final norm) in one
compiled loop, with the weights of all layers stacked once (:func:`pack_weights`).

Inference only: no autograd. The tests check it against the torch path and the full forward.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
import torch
from numba import njit


class PackedWeights(NamedTuple):
    """All layers' parameters stacked on a leading layer axis, as contiguous numpy arrays."""

    norm_w: np.ndarray  # (nl, d)
    in_w: np.ndarray  # (nl, 2 Din, d)
    in_b: np.ndarray  # (nl, 2 Din), zeros without bias
    conv_w: np.ndarray  # (nl, Din, K)
    conv_b: np.ndarray  # (nl, Din)
    xp_w: np.ndarray  # (nl, R + 2N, Din)
    dt_w: np.ndarray  # (nl, Din, R)
    dt_b: np.ndarray  # (nl, Din)
    A: np.ndarray  # (nl, Din, N) = -exp(A_log)
    D: np.ndarray  # (nl, Din)
    out_w: np.ndarray  # (nl, d, Din)
    out_b: np.ndarray  # (nl, d)
    norm2_w: np.ndarray  # (nl, d) or (nl, 1) without MLP
    fc1: np.ndarray  # (nl, 2H, d) or (nl, 1, 1)
    fc2: np.ndarray  # (nl, d, H) or (nl, 1, 1)
    norm_f: np.ndarray  # (d,) or (1,)
    has_mlp: bool
    has_norm_f: bool
    eps: float


@torch.no_grad()
def pack_weights(model, dtype: torch.dtype) -> PackedWeights:
    """Stack a :class:`thesis_lib.seq.mamba.Mamba`'s parameters for :func:`stack_step_kernel`."""
    blocks = list(model.layers)
    cfg = model.config

    def st(get, default_shape=None):
        ts = []
        for b in blocks:
            t = get(b)
            ts.append(
                torch.zeros(default_shape, dtype=dtype)
                if t is None
                else t.detach().to("cpu", dtype)
            )
        return torch.stack(ts).contiguous().numpy()

    m = lambda b: b.mixer
    has_mlp = blocks[0].mlp is not None
    np_dtype = torch.empty(0, dtype=dtype).numpy().dtype
    n = len(blocks)
    return PackedWeights(
        norm_w=st(lambda b: b.norm.weight),
        in_w=st(lambda b: m(b).in_proj.weight),
        in_b=st(lambda b: m(b).in_proj.bias, (2 * cfg.d_inner,)),
        conv_w=st(lambda b: m(b).conv1d.weight[:, 0, :]),
        conv_b=st(lambda b: m(b).conv1d.bias, (cfg.d_inner,)),
        xp_w=st(lambda b: m(b).x_proj.weight),
        dt_w=st(lambda b: m(b).dt_proj.weight),
        dt_b=st(lambda b: m(b).dt_proj.bias),
        A=st(lambda b: -torch.exp(m(b).A_log.float())),
        D=st(lambda b: m(b).D),
        out_w=st(lambda b: m(b).out_proj.weight),
        out_b=st(lambda b: m(b).out_proj.bias, (cfg.d_model,)),
        norm2_w=st(lambda b: b.norm2.weight) if has_mlp else np.zeros((n, 1), np_dtype),
        fc1=st(lambda b: b.mlp.fc1.weight) if has_mlp else np.zeros((n, 1, 1), np_dtype),
        fc2=st(lambda b: b.mlp.fc2.weight) if has_mlp else np.zeros((n, 1, 1), np_dtype),
        norm_f=(
            model.norm_f.weight.detach().to("cpu", dtype).contiguous().numpy()
            if model.norm_f is not None
            else np.ones(1, np_dtype)
        ),
        has_mlp=has_mlp,
        has_norm_f=model.norm_f is not None,
        eps=float(cfg.norm_eps),
    )


@njit(cache=True, fastmath=True)
def _silu(x):  # pragma: no cover - compiled
    return x / (1.0 + math.exp(-x))


@njit(cache=True, fastmath=True)
def _rmsnorm(x, w, eps, out):  # pragma: no cover - compiled
    ms = 0.0
    for k in range(x.shape[0]):
        ms += x[k] * x[k]
    inv = 1.0 / math.sqrt(ms / x.shape[0] + eps)
    for k in range(x.shape[0]):
        out[k] = x[k] * inv * w[k]


@njit(cache=True, fastmath=True)
def _matvec(W, v, out):  # pragma: no cover - compiled
    for j in range(W.shape[0]):
        acc = 0.0
        for k in range(W.shape[1]):
            acc += W[j, k] * v[k]
        out[j] = acc


@njit(cache=True, fastmath=True)
def stack_step_kernel(
    x,
    conv,
    h,
    out,
    norm_w,
    in_w,
    in_b,
    conv_w,
    conv_b,
    xp_w,
    dt_w,
    dt_b,
    A,
    D,
    out_w,
    out_b,
    norm2_w,
    fc1,
    fc2,
    norm_f,
    has_mlp,
    has_norm_f,
    eps,
):  # pragma: no cover - compiled
    """Advance ``conv (nl, B, Din, K-1)`` and ``h (nl, B, Din, N)`` in place over ``x (T, B, d)``."""
    T, n_batch, d = x.shape
    nl, Din, K = conv_w.shape
    N = A.shape[2]
    R = dt_w.shape[2]
    H = fc2.shape[2]
    dtype = x.dtype
    res = np.empty(d, dtype)
    hn = np.empty(d, dtype)
    xz = np.empty(2 * Din, dtype)
    xc = np.empty(Din, dtype)
    dbc = np.empty(R + 2 * N, dtype)
    y = np.empty(Din, dtype)
    o = np.empty(d, dtype)
    f1 = np.empty(2 * H, dtype)
    gm = np.empty(H, dtype)
    for t in range(T):
        for b in range(n_batch):
            for k in range(d):
                res[k] = x[t, b, k]
            for layer in range(nl):
                _rmsnorm(res, norm_w[layer], eps, hn)
                _matvec(in_w[layer], hn, xz)
                for c in range(Din):  # causal depthwise conv over the cached window, then SiLU
                    xi = xz[c] + in_b[layer, c]
                    acc = conv_b[layer, c] + conv_w[layer, c, K - 1] * xi
                    for k in range(K - 1):
                        acc += conv_w[layer, c, k] * conv[layer, b, c, k]
                    for k in range(K - 2):
                        conv[layer, b, c, k] = conv[layer, b, c, k + 1]
                    if K > 1:
                        conv[layer, b, c, K - 2] = xi
                    xc[c] = _silu(acc)
                _matvec(xp_w[layer], xc, dbc)
                for c in range(Din):  # Δ, one scan step, skip, gate
                    acc = dt_b[layer, c]
                    for r in range(R):
                        acc += dt_w[layer, c, r] * dbc[r]
                    dl = acc if acc > 20.0 else math.log1p(math.exp(acc))  # torch's softplus
                    du = dl * xc[c]
                    yc = 0.0
                    for n in range(N):
                        hh = math.exp(dl * A[layer, c, n]) * h[layer, b, c, n] + du * dbc[R + n]
                        h[layer, b, c, n] = hh
                        yc += hh * dbc[R + N + n]
                    z = xz[Din + c] + in_b[layer, Din + c]
                    y[c] = (yc + D[layer, c] * xc[c]) * _silu(z)
                _matvec(out_w[layer], y, o)
                for k in range(d):
                    res[k] += o[k] + out_b[layer, k]
                if has_mlp:
                    _rmsnorm(res, norm2_w[layer], eps, hn)
                    _matvec(fc1[layer], hn, f1)
                    for j in range(H):
                        gm[j] = f1[j] * _silu(f1[H + j])
                    _matvec(fc2[layer], gm, o)
                    for k in range(d):
                        res[k] += o[k]
            if has_norm_f:
                _rmsnorm(res, norm_f, eps, hn)
                for k in range(d):
                    out[t, b, k] = hn[k]
            else:
                for k in range(d):
                    out[t, b, k] = res[k]
