"""CPU kernels of Mamba's selective scan: numba loops with a hand-written backward.

The scan of :func:`thesis_lib.seq.ssm.selective_scan_reference` without its optional parts
(``D``, ``z``, ``delta_bias``, softplus), which :func:`thesis_lib.seq.mamba.selective_scan`
adds around it with ordinary autograd ops::

    h[t] = exp(Δ[t] A) * h[t-1] + Δ[t] u[t] B[t]      # (Din, N) per batch row
    y[t] = h[t] · C[t]                                  # (Din,)

Why this design (measured on the loaded 2-core CI machine, B=16, L=60, Din=256, N=16, one
thread; ``benchmarks/bench_mamba.py`` has the whole-model numbers):

* A loop over L of vectorised torch ops (:class:`SelectiveScanTorch`, kept for comparison)
  reads and writes ``(B, L, Din, N)`` temporaries at every step; ``mambapy``'s parallel scan
  too. One compiled loop per batch row keeps the state in cache instead.
* State-major ``(N, Din)`` layout: the inner loops run over ``Din`` contiguous channels and
  vectorise; the channel-major ``(Din, N)`` backward (N = 16 inner) was 2.3x slower.
* ``exp(Δ A)`` comes from torch (vectorised; numba's scalar ``exp`` costs more than the whole
  scan), as ``exp2(Δ A log2 e)``: torch's float32 ``exp2`` is 2.6x faster than its ``exp`` here.
* Batch rows go through in chunks of about :data:`CHUNK_BYTES`, with reused scratch buffers:
  fresh multi-MB tensors cost a page fault per 4 KiB on every call (a forward took 30-40 ms
  instead of 7 ms). Nothing of size ``(B, L, N, Din)`` is kept for the backward, which
  recomputes ``exp(Δ A)`` and the states chunk by chunk (as ``mamba_ssm`` does on GPU).

The backward runs the recurrence in reverse with the adjoint state ``g[t] = ∂loss/∂h[t]``::

    g[t]   = C[t] ∂y[t] + exp(Δ[t+1] A) * g[t+1]
    ∂Δ[t]  = Σ_n g[t] h[t-1] exp(Δ[t] A) A + u[t] Σ_n g[t] B[t]
    ∂A     = Σ_{b,t} g[t] h[t-1] exp(Δ[t] A) Δ[t]
    ∂u[t]  = Δ[t] Σ_n g[t] B[t]
    ∂B[t]  = Σ_d g[t] Δ[t] u[t],   ∂C[t] = Σ_d ∂y[t] h[t]

The kernels are serial: with ``prange`` over batch rows, numba's threads and torch's OpenMP
threads (which spin after each op) fought over the 2 cores, and a training step got 2-4x
slower. ``∂A`` is accumulated per batch row and summed by torch.
"""

from __future__ import annotations

import threading

import numpy as np
import torch
from numba import njit


@njit(cache=True, fastmath=True)
def _scan_fwd_kernel(u, delta, dA, B, C, y, hs, h_last, store):  # pragma: no cover - compiled
    # u, delta, y: (Bt, L, D); dA, hs: (Bt, L, N, D); B, C: (Bt, L, N); h_last: (Bt, N, D).
    # State-major (N, D) layout: the inner loops run over D contiguous channels and vectorise.
    n_batch, L, D = u.shape
    N = B.shape[2]
    for b in range(n_batch):
        h = np.zeros((N, D), dtype=u.dtype)
        du = np.empty(D, dtype=u.dtype)
        for t in range(L):
            yb = y[b, t]
            for d in range(D):
                du[d] = delta[b, t, d] * u[b, t, d]
                yb[d] = 0.0
            for n in range(N):
                Bn = B[b, t, n]
                Cn = C[b, t, n]
                hn = h[n]
                dAn = dA[b, t, n]
                for d in range(D):
                    v = dAn[d] * hn[d] + du[d] * Bn
                    hn[d] = v
                    yb[d] += v * Cn
                if store:
                    hs[b, t, n, :] = hn
        h_last[b] = h


@njit(cache=True, fastmath=True)
def _scan_bwd_kernel(
    gy, u, delta, AT, dA, B, C, hs, g_last, gu, gdelta, gA_rows, gB, gC
):  # pragma: no cover
    # gy, u, delta, gu, gdelta: (Bt, L, D); dA, hs: (Bt, L, N, D); B, C, gB, gC: (Bt, L, N);
    # AT: (N, D) = A transposed; gA_rows: (Bt, N, D), summed over rows by the caller;
    # g_last: (Bt, N, D) = ∂loss/∂h_last, the adjoint the backward recursion starts from.
    n_batch, L, D = u.shape
    N = B.shape[2]
    for b in range(n_batch):
        g = g_last[b].copy()  # exp(Δ[t+1] A) * g[t+1], carried backwards
        accB = np.empty(D, dtype=u.dtype)
        accA = np.empty(D, dtype=u.dtype)
        du = np.empty(D, dtype=u.dtype)
        gA = gA_rows[b]
        for t in range(L - 1, -1, -1):
            gyb = gy[b, t]
            dl = delta[b, t]
            for d in range(D):
                du[d] = dl[d] * u[b, t, d]
                accB[d] = 0.0
                accA[d] = 0.0
            for n in range(N):
                Cn = C[b, t, n]
                Bn = B[b, t, n]
                gn = g[n]
                hsn = hs[b, t, n]
                dAn = dA[b, t, n]
                sC = 0.0
                sB = 0.0
                if t > 0:  # h[t-1] = 0 at t = 0: no ∂A, ∂Δ-through-A terms
                    hp = hs[b, t - 1, n]
                    An = AT[n]
                    gAn = gA[n]
                    for d in range(D):
                        x = gn[d] + gyb[d] * Cn  # g[t]
                        sC += gyb[d] * hsn[d]
                        sB += x * du[d]
                        accB[d] += x * Bn
                        w = x * hp[d] * dAn[d]  # ∂loss/∂(Δ A)
                        accA[d] += w * An[d]
                        gAn[d] += w * dl[d]
                        gn[d] = x * dAn[d]
                else:
                    for d in range(D):
                        x = gn[d] + gyb[d] * Cn
                        sC += gyb[d] * hsn[d]
                        sB += x * du[d]
                        accB[d] += x * Bn
                        gn[d] = x * dAn[d]
                gB[b, t, n] = sB
                gC[b, t, n] = sC
            for d in range(D):
                gdelta[b, t, d] = accA[d] + accB[d] * u[b, t, d]
                gu[b, t, d] = accB[d] * dl[d]


LOG2E = 1.4426950408889634
CHUNK_BYTES = 2 << 20
"""Batch rows per kernel call are chosen so that one chunk's ``(rows, L, N, Din)`` ``exp(Δ A)``
(and states) fill about this many bytes: they stay in cache between torch's ``exp`` and the
kernel, and the two scratch buffers are reused from call to call."""

_scratch = threading.local()


def _workspace(slot: int, numel: int, dtype: torch.dtype) -> torch.Tensor:
    """A reusable flat buffer (per thread, slot and dtype). Fresh multi-MB tensors cost a page
    fault per 4 KiB on every call, which measured slower than the scan itself."""
    key = (slot, dtype)
    bufs = getattr(_scratch, "bufs", None)
    if bufs is None:
        bufs = _scratch.bufs = {}
    buf = bufs.get(key)
    if buf is None or buf.numel() < numel:
        buf = bufs[key] = torch.empty(numel, dtype=dtype)
    return buf[:numel]


def _chunks(n_batch: int, L: int, N: int, D: int, itemsize: int):
    rows = max(1, CHUNK_BYTES // max(1, L * N * D * itemsize))
    for b0 in range(0, n_batch, rows):
        yield b0, min(n_batch, b0 + rows)


def _exp_delta_A(delta: torch.Tensor, AT_log2e: torch.Tensor) -> torch.Tensor:
    """``exp(Δ A) = 2^(Δ A log2 e)`` for a chunk of rows, ``(rows, L, N, Din)``, in scratch slot 0.

    ``AT_log2e`` is ``A.T * log2(e)``: torch's float32 ``exp2`` measured 2.6x faster than its
    ``exp`` here (the rounding of the product adds ~1e-7 relative error per step).
    """
    rows, L, D = delta.shape
    dA = _workspace(0, rows * L * AT_log2e.shape[0] * D, delta.dtype).view(
        rows, L, AT_log2e.shape[0], D
    )
    torch.mul(delta.unsqueeze(2), AT_log2e, out=dA)
    return dA.exp2_()


def scan_cpu_forward(u, delta, A, B, C, store: bool = False):
    """Run the forward kernel; returns ``(y (B, L, Din), h_last (B, Din, N))``. No autograd.

    Inputs: CPU tensors of one float dtype, ``u, delta (B, L, Din)``, ``A (Din, N)``,
    ``B, C (B, L, N)``. The backward recomputes ``exp(Δ A)`` and the states chunk by chunk
    (as ``mamba_ssm`` does on GPU) instead of keeping ``(B, L, N, Din)`` tensors.
    """
    u, delta, B, C = (t.detach().contiguous() for t in (u, delta, B, C))
    AT = A.detach().T.contiguous()  # (N, Din)
    n_batch, L, D = u.shape
    N = AT.shape[0]
    y = torch.empty((n_batch, L, D), dtype=u.dtype)
    h_last = torch.empty((n_batch, N, D), dtype=u.dtype)
    hs = np.empty((1, 1, 1, 1), dtype=u.numpy().dtype)
    AT_log2e = AT * LOG2E
    for b0, b1 in _chunks(n_batch, L, N, D, u.element_size()):
        dA = _exp_delta_A(delta[b0:b1], AT_log2e)
        _scan_fwd_kernel(
            u[b0:b1].numpy(),
            delta[b0:b1].numpy(),
            dA.numpy(),
            B[b0:b1].numpy(),
            C[b0:b1].numpy(),
            y[b0:b1].numpy(),
            hs,
            h_last[b0:b1].numpy(),
            False,
        )
    return y, h_last.transpose(1, 2)


class SelectiveScanCPU(torch.autograd.Function):
    """``y = scan(u, Δ, A, B, C)`` on CPU tensors of one float dtype; layout ``(B, L, ·)``.

    Returns ``(y (B, L, Din), h_last (B, Din, N))``, both differentiable (the gradient of
    ``h_last`` seeds the backward recursion). Saves only its inputs: the backward reruns the forward kernel chunk by chunk to get the
    states ``h[t]`` back (cheaper here than writing and re-reading ``(B, L, N, Din)`` tensors).
    """

    @staticmethod
    def forward(ctx, u, delta, A, B, C):
        y, h_last = scan_cpu_forward(u, delta, A, B, C)
        ctx.save_for_backward(u, delta, A, B, C)
        return y, h_last

    @staticmethod
    def backward(ctx, gy, g_h_last):
        u, delta, A, B, C = (t.detach().contiguous() for t in ctx.saved_tensors)
        gy = torch.zeros_like(u) if gy is None else gy.contiguous()
        AT = A.T.contiguous()
        n_batch, L, D = u.shape
        N = AT.shape[0]
        gu = torch.empty_like(u)
        gdelta = torch.empty_like(u)
        gA_rows = torch.zeros((n_batch, N, D), dtype=u.dtype)
        gB = torch.empty_like(B)
        gC = torch.empty_like(C)
        y = torch.empty((n_batch, L, D), dtype=u.dtype)
        h_last = torch.empty((n_batch, N, D), dtype=u.dtype)
        AT_log2e = AT * LOG2E
        if g_h_last is None:
            g_last = torch.zeros((n_batch, N, D), dtype=u.dtype)
        else:  # (B, Din, N) -> the kernel's state-major (B, N, Din)
            g_last = g_h_last.to(u.dtype).transpose(1, 2).contiguous()
        for b0, b1 in _chunks(n_batch, L, N, D, u.element_size()):
            dA = _exp_delta_A(delta[b0:b1], AT_log2e)
            hs = _workspace(1, dA.numel(), u.dtype).view(dA.shape)
            args = (u[b0:b1].numpy(), delta[b0:b1].numpy())
            _scan_fwd_kernel(
                *args,
                dA.numpy(),
                B[b0:b1].numpy(),
                C[b0:b1].numpy(),
                y[b0:b1].numpy(),
                hs.numpy(),
                h_last[b0:b1].numpy(),
                True,
            )
            _scan_bwd_kernel(
                gy[b0:b1].numpy(),
                *args,
                AT.numpy(),
                dA.numpy(),
                B[b0:b1].numpy(),
                C[b0:b1].numpy(),
                hs.numpy(),
                g_last[b0:b1].numpy(),
                gu[b0:b1].numpy(),
                gdelta[b0:b1].numpy(),
                gA_rows[b0:b1].numpy(),
                gB[b0:b1].numpy(),
                gC[b0:b1].numpy(),
            )
        return gu, gdelta, gA_rows.sum(0).T, gB, gC


class SelectiveScanTorch(torch.autograd.Function):
    """The same scan as :class:`SelectiveScanCPU` as a loop over L of vectorised torch ops.

    Kept as the measured alternative (and for devices numba cannot reach, such as GPUs
    without ``mamba_ssm``). Internal layout ``(L, B, Din, N)`` so each step is contiguous.
    """

    @staticmethod
    def forward(ctx, u, delta, A, B, C):
        dt, ut = delta.transpose(0, 1), u.transpose(0, 1)  # (L, B, Din)
        Bt, Ct = B.transpose(0, 1), C.transpose(0, 1)  # (L, B, N)
        dA = torch.exp(dt.unsqueeze(-1) * A)  # (L, B, Din, N)
        hs = (dt * ut).unsqueeze(-1) * Bt.unsqueeze(2)  # Δ u B, overwritten in place by h
        for t in range(1, hs.shape[0]):
            hs[t].addcmul_(dA[t], hs[t - 1])
        y = (hs * Ct.unsqueeze(2)).sum(-1)  # (L, B, Din)
        ctx.save_for_backward(ut, dt, A, Bt, Ct, dA, hs)
        return y.transpose(0, 1), hs[-1].clone()

    @staticmethod
    def backward(ctx, gy, g_h_last):
        ut, dt, A, Bt, Ct, dA, hs = ctx.saved_tensors
        gyt = torch.zeros_like(ut) if gy is None else gy.transpose(0, 1)  # (L, B, Din)
        g = gyt.unsqueeze(-1) * Ct.unsqueeze(2)  # (L, B, Din, N), becomes ∂loss/∂h[t]
        if g_h_last is not None:  # the last state is an output too
            g[-1] += g_h_last
        for t in range(g.shape[0] - 2, -1, -1):
            g[t].addcmul_(dA[t + 1], g[t + 1])
        gC = torch.einsum("lbd,lbdn->lbn", gyt, hs)
        w = g[1:] * hs[:-1] * dA[1:]  # ∂loss/∂(Δ A) for t ≥ 1 (h[-1] = 0)
        gdelta = torch.zeros_like(dt)
        gdelta[1:] = (w * A).sum(-1)
        gA = torch.einsum("lbdn,lbd->dn", w, dt[1:])
        gBu = torch.einsum("lbdn,lbn->lbd", g, Bt)  # Σ_n g B
        gdelta = gdelta + gBu * ut
        gu = gBu * dt
        gB = torch.einsum("lbdn,lbd->lbn", g, dt * ut)
        return (
            gu.transpose(0, 1),
            gdelta.transpose(0, 1),
            gA,
            gB.transpose(0, 1),
            gC.transpose(0, 1),
        )
