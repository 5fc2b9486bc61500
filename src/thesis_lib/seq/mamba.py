"""Mamba-1 blocks with a fast CPU selective scan and O(1)-per-token recurrent stepping.

The Decision Mamba (DM), the Hierarchical Decision Mamba (HDM) and MDLT-M stack the blocks of
thesis Fig. 2.2. Each block, in the pre-norm residual form of ``mamba_ssm`` (and nanoGPT)::

    x = x + mixer(norm(x))          # the Mamba layer below
    x = x + mlp(norm2(x))           # only with gated_mlp (the authors' later DM/HDM code)

and the mixer, for ``x`` of shape ``(B, L, d_model)``::

    x, z   = in_proj(x).chunk(2)                    # (B, L, d_inner) each, d_inner = expand * d_model
    x      = silu(causal depthwise conv1d(x))       # kernel d_conv, left-padded
    Δ, B, C = x_proj(x).split(dt_rank, N, N)         # input-dependent ("selective") parameters
    Δ      = softplus(dt_proj(Δ))                   # (B, L, d_inner), low-rank then per channel
    y      = scan(x, Δ, A = -exp(A_log), B, C, D) * silu(z)
    out    = out_proj(y)

The scan (:func:`selective_scan`) dispatches to ``mamba_ssm``'s CUDA kernel when that package is
importable and the tensors are on a GPU (what the authors ran), otherwise to a numba kernel with
a hand-written backward (:mod:`thesis_lib.seq._scan`), which is several times faster on CPU
than ``mambapy``'s parallel scan. Parameter names follow ``mamba_ssm`` (and ``mambapy``), so
their state dicts load into :class:`Mamba`.

Acting in an environment, the original code re-runs the whole K-window for every action.
:meth:`Mamba.step` instead carries a :class:`MambaState` (the last ``d_conv - 1`` conv inputs
and the SSM state ``h`` of every layer) and costs one token per token;
:meth:`Mamba.step_tokens` advances by the 2-3 tokens of one timestep. On CPU without autograd
both run one compiled call for the whole stack (:mod:`thesis_lib.seq._scan_step`): at batch 1,
six layers of small torch ops cost as much in dispatch as re-running the window.

Note that recurrent stepping over a whole episode conditions on all of it, while the original
windowed evaluation sees only the last K timesteps; the two agree only while the episode is
shorter than the window (or after :meth:`Mamba.forward` with ``return_state`` on the window).

Used in: Background chapter (thesis 2.3); Decision Mamba chapter (thesis 5.3); MDLT chapter.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from functools import lru_cache
from typing import Literal, NamedTuple, cast

import torch
import torch.nn.functional as F
from torch import nn

from thesis_lib.seq._scan import SelectiveScanCPU, SelectiveScanTorch, scan_cpu_forward
from thesis_lib.seq._scan_step import pack_weights, stack_step_kernel
from thesis_lib.seq.ssm import check_scan_inputs, selective_scan_reference, selective_scan_step

ScanBackend = Literal["auto", "numba", "torch", "mamba_ssm", "reference"]
SCAN_BACKENDS: tuple[str, ...] = ("auto", "numba", "torch", "mamba_ssm", "reference")


# --------------------------------------------------------------------------- selective scan
@lru_cache(maxsize=1)
def _mamba_ssm_scan_fn():
    """``mamba_ssm``'s fused CUDA ``selective_scan_fn``, or ``None`` if it is not installed."""
    try:
        from mamba_ssm.ops.selective_scan_interface import selective_scan_fn
    except Exception:  # ImportError, or a CUDA extension that fails to load
        return None
    return selective_scan_fn


def resolve_scan_backend(device: torch.device | str, backend: ScanBackend = "auto") -> str:
    """The scan implementation :func:`selective_scan` uses for tensors on ``device``.

    ``"auto"`` picks ``"mamba_ssm"`` on CUDA when ``mamba_ssm`` is importable, ``"numba"`` on
    CPU, and ``"torch"`` (a loop over L of vectorised ops) elsewhere.

    Example:
        >>> resolve_scan_backend("cpu")
        'numba'
    """
    if backend not in SCAN_BACKENDS:
        raise ValueError(f"Unknown scan backend {backend!r}. Valid: {', '.join(SCAN_BACKENDS)}.")
    device = torch.device(device)
    if backend == "auto":
        if device.type == "cuda" and _mamba_ssm_scan_fn() is not None:
            return "mamba_ssm"
        return "numba" if device.type == "cpu" else "torch"
    if backend == "mamba_ssm" and (_mamba_ssm_scan_fn() is None or device.type != "cuda"):
        raise RuntimeError(
            f"Scan backend 'mamba_ssm' needs CUDA tensors and the mamba_ssm package (got device "
            f"{device}, mamba_ssm {'found' if _mamba_ssm_scan_fn() else 'not installed'}). "
            "Install it with 'pip install mamba-ssm' on a CUDA machine, or use backend='auto'."
        )
    if backend == "numba" and device.type != "cpu":
        raise RuntimeError(f"Scan backend 'numba' runs on CPU tensors only, got device {device}.")
    return backend


class ScanOutput(NamedTuple):
    """Output of :func:`selective_scan` with ``return_last_state=True``."""

    y: torch.Tensor
    """``(B, L, Din)``."""
    h_last: torch.Tensor
    """Final SSM state ``(B, Din, N)``, to continue with :func:`selective_scan_step`."""


def selective_scan(
    u: torch.Tensor,
    delta: torch.Tensor,
    A: torch.Tensor,
    B: torch.Tensor,
    C: torch.Tensor,
    D: torch.Tensor | None = None,
    z: torch.Tensor | None = None,
    *,
    delta_bias: torch.Tensor | None = None,
    delta_softplus: bool = False,
    return_last_state: bool = False,
    backend: ScanBackend = "auto",
    check: bool = True,
) -> torch.Tensor | ScanOutput:
    """Mamba-1 selective scan, fast; same semantics and layout as ``selective_scan_reference``.

    ``h[t] = exp(Δ[t] A) h[t-1] + Δ[t] B[t] u[t]``, ``y[t] = C[t]·h[t] + D u[t]``, times
    ``silu(z[t])``; see :func:`thesis_lib.seq.ssm.selective_scan_reference` for the shapes.
    Differentiable in every tensor argument. Inputs of mixed dtype are promoted (float16 and
    bfloat16 compute in float32 on CPU); the output has the promoted dtype.

    Used in: Decision Mamba chapter (thesis 5.3); MDLT chapter.

    Args:
        u: Input ``(B, L, Din)``.
        delta: Step sizes ``(B, L, Din)``.
        A: Diagonal state matrices ``(Din, N)``, negative for a stable scan.
        B: ``(B, L, N)``.
        C: ``(B, L, N)``.
        D: Optional skip ``(Din,)``.
        z: Optional gate ``(B, L, Din)``.
        delta_bias: Optional ``(Din,)`` added to ``delta`` before the softplus.
        delta_softplus: Apply softplus to ``delta`` (after the bias), as Mamba does.
        return_last_state: Also return the final state ``h`` (differentiable with the
            ``numba`` and ``torch`` backends; ``mamba_ssm`` returns it without a gradient).
        backend: ``"auto"`` (see :func:`resolve_scan_backend`), ``"numba"`` (CPU kernel),
            ``"torch"`` (vectorised loop), ``"mamba_ssm"`` (CUDA) or ``"reference"`` (slow).
        check: Validate shapes and finiteness (what ``selective_scan_reference`` checks).

    Returns:
        ``y (B, L, Din)``, or :class:`ScanOutput` ``(y, h_last)`` with ``return_last_state``.

    Example:
        >>> u = torch.ones(1, 3, 1)  # B=1, L=3, Din=1
        >>> A = torch.full((1, 1), -1e9)  # forgets at once: y_t = Δ B C u
        >>> B = C = torch.ones(1, 3, 1)
        >>> selective_scan(u, 0.5 * u, A, B, C).flatten().tolist()
        [0.5, 0.5, 0.5]
    """
    if check:
        check_scan_inputs(u, delta, A, B, C, D, z, delta_bias)
    which = resolve_scan_backend(u.device, backend)
    if which == "mamba_ssm":
        return _scan_with_mamba_ssm(
            _mamba_ssm_scan_fn(),
            u,
            delta,
            A,
            B,
            C,
            D,
            z,
            delta_bias,
            delta_softplus,
            return_last_state,
        )
    if which == "reference":
        if return_last_state:
            raise ValueError(
                "backend='reference' cannot return the last state; use 'numba' or 'torch'."
            )
        return selective_scan_reference(
            u, delta, A, B, C, D, z, delta_bias=delta_bias, delta_softplus=delta_softplus
        )

    tensors = [x for x in (u, delta, A, B, C, D, z, delta_bias) if x is not None]
    dtype = tensors[0].dtype
    for x in tensors[1:]:
        dtype = torch.promote_types(dtype, x.dtype)
    compute = dtype if dtype in (torch.float32, torch.float64) else torch.float32
    u_, dl, A_, B_, C_ = (x.to(compute) for x in (u, delta, A, B, C))
    if delta_bias is not None:
        dl = dl + delta_bias.to(compute)
    if delta_softplus:
        dl = F.softplus(dl)
    if which == "numba":
        core = SelectiveScanCPU
        needs_grad = torch.is_grad_enabled() and any(x.requires_grad for x in (u_, dl, A_, B_, C_))
        if needs_grad:
            y, h_last = core.apply(
                u_.contiguous(), dl.contiguous(), A_.contiguous(), B_.contiguous(), C_.contiguous()
            )
        else:  # no autograd graph: skip storing the states for the backward
            y, h_last = scan_cpu_forward(u_, dl, A_, B_, C_)
    else:
        y, h_last = SelectiveScanTorch.apply(u_, dl, A_, B_, C_)
    if D is not None:
        y = y + u_ * D.to(compute)
    if z is not None:
        y = y * F.silu(z.to(compute))
    y = y.to(dtype)
    return ScanOutput(y, h_last) if return_last_state else y


def _scan_with_mamba_ssm(
    fn, u, delta, A, B, C, D, z, delta_bias, delta_softplus, return_last_state
):
    """Call ``mamba_ssm``'s ``selective_scan_fn`` (layout ``(B, Din, L)``) on our ``(B, L, Din)``."""
    t = lambda x: None if x is None else x.transpose(1, 2).contiguous()
    out = fn(
        t(u),
        t(delta),
        A,
        t(B),
        t(C),
        D,
        t(z),
        delta_bias=delta_bias,
        delta_softplus=delta_softplus,
        return_last_state=return_last_state,
    )
    if return_last_state:
        return ScanOutput(out[0].transpose(1, 2), out[1])
    return out.transpose(1, 2)


def causal_depthwise_conv1d(
    x: torch.Tensor, weight: torch.Tensor, bias: torch.Tensor | None = None
) -> torch.Tensor:
    """Causal depthwise convolution in the token-major layout: ``y[t] = b + Σ_k w[:, k] x[t - K + 1 + k]``.

    Same result as ``nn.Conv1d(D, D, K, groups=D, padding=K - 1)`` on ``x.transpose(1, 2)``
    with the right ``K - 1`` outputs dropped (Mamba's convolution), as K shifted
    multiply-adds: on CPU with small K this measured faster than the (mkldnn) convolution's
    backward, and it skips two transposes. A lower-precision ``x`` (bfloat16, under
    ``TrainConfig(precision="bf16")``) is cast to the weights' dtype once, first: each product
    would compute in that dtype anyway, but a mixed-dtype product costs about three times a
    same-dtype one on a CPU, and its gradient would be rounded to bfloat16 at every tap.

    Args:
        x: ``(B, L, D)``.
        weight: ``(D, 1, K)`` (an ``nn.Conv1d`` weight) or ``(D, K)``.
        bias: Optional ``(D,)``.

    Returns:
        ``(B, L, D)``.
    """
    w = weight.reshape(weight.shape[0], -1)  # (D, K)
    x = x.to(torch.promote_types(x.dtype, w.dtype))  # once, not in each mixed-dtype product
    K, L = w.shape[1], x.shape[1]
    xp = F.pad(x, (0, 0, K - 1, 0))  # (B, L + K - 1, D): zeros before the first token
    y = xp[:, K - 1 :] * w[:, K - 1]
    for k in range(K - 1):
        y = y + xp[:, k : k + L] * w[:, k]
    return y if bias is None else y + bias


# --------------------------------------------------------------------------- config
@dataclass
class MambaConfig:
    """Configuration of a :class:`Mamba` stack (and of each :class:`MambaBlock`).

    Defaults are Mamba-1's (``mamba_ssm``'s ``Mamba``: d_state 16, d_conv 4, expand 2) with the
    thesis's DM/HDM size (6 layers, d_model 128, thesis 5.3.1).

    Used in: Decision Mamba chapter (thesis 5.3); MDLT chapter.

    Example:
        >>> cfg = MambaConfig(d_model=128, n_layers=6)
        >>> (cfg.d_inner, cfg.dt_rank_value)
        (256, 8)
        >>> MambaConfig(expand=0)
        Traceback (most recent call last):
        ...
        ValueError: Expect `expand` to be a positive int, actually: 0.
    """

    d_model: int = 128
    """Embedding size of every token."""
    n_layers: int = 6
    """Number of stacked :class:`MambaBlock` s (6 in the thesis's DM/HDM)."""
    d_state: int = 16
    """SSM state size ``N`` per channel."""
    d_conv: int = 4
    """Kernel size of the causal depthwise convolution."""
    expand: int = 2
    """Inner width ``d_inner = expand * d_model``."""
    dt_rank: int | Literal["auto"] = "auto"
    """Rank of Δ's projection; ``"auto"`` = ``ceil(d_model / 16)`` as in Mamba."""
    dt_min: float = 0.001
    """Smallest initial Δ (after the softplus); initial Δ are log-uniform in [dt_min, dt_max]."""
    dt_max: float = 0.1
    """Largest initial Δ."""
    dt_init: Literal["random", "constant"] = "random"
    """Init of ``dt_proj.weight``: uniform in ±dt_scale/sqrt(dt_rank), or that constant."""
    dt_scale: float = 1.0
    """Scale of ``dt_proj.weight``'s init."""
    dt_init_floor: float = 1e-4
    """Initial Δ are clamped from below at this value."""
    bias: bool = False
    """Biases in ``in_proj`` and ``out_proj`` (Mamba has none)."""
    conv_bias: bool = True
    """Bias in the depthwise convolution (Mamba has one)."""
    gated_mlp: bool = False
    """Add ``x + mlp(norm2(x))`` with a SiLU-gated MLP after each mixer, as the authors' DM/HDM
    code does from July 2024 (``mamba_ssm``'s ``GatedMLP``); off in the original Mamba."""
    mlp_hidden: int | Literal["auto"] = "auto"
    """Gated MLP width; ``"auto"`` = ``8/3 d_model`` rounded up to a multiple of 128 (GatedMLP's default)."""
    norm_eps: float = 1e-5
    """Epsilon of the RMSNorms."""
    final_norm: bool = True
    """RMSNorm after the last block (``mamba_ssm``'s ``norm_f``; ``mambapy.Mamba`` has none)."""
    d_inner: int = field(init=False)
    """Derived: ``expand * d_model``."""
    dt_rank_value: int = field(init=False)
    """Derived: ``dt_rank`` with ``"auto"`` resolved."""
    mlp_hidden_value: int = field(init=False)
    """Derived: ``mlp_hidden`` with ``"auto"`` resolved (unused without ``gated_mlp``)."""

    def __post_init__(self) -> None:
        for name in ("d_model", "n_layers", "d_state", "d_conv", "expand"):
            value = getattr(self, name)
            if not isinstance(value, int) or isinstance(value, bool) or value <= 0:
                raise ValueError(f"Expect `{name}` to be a positive int, actually: {value!r}.")
        for name in ("dt_rank", "mlp_hidden"):
            value = getattr(self, name)
            if value != "auto" and (
                not isinstance(value, int) or isinstance(value, bool) or value <= 0
            ):
                raise ValueError(
                    f"Expect `{name}` to be 'auto' or a positive int, actually: {value!r}."
                )
        if not (0 < self.dt_min <= self.dt_max):
            raise ValueError(
                f"Expect 0 < dt_min <= dt_max, actually: dt_min={self.dt_min}, dt_max={self.dt_max}. "
                "Mamba's defaults are dt_min=0.001, dt_max=0.1."
            )
        if self.dt_init not in ("random", "constant"):
            raise ValueError(f"Unknown dt_init {self.dt_init!r}. Valid: random, constant.")
        for name in ("dt_scale", "dt_init_floor", "norm_eps"):
            if not getattr(self, name) > 0:
                raise ValueError(
                    f"Expect `{name}` to be positive, actually: {getattr(self, name)!r}."
                )
        self.d_inner = self.expand * self.d_model
        self.dt_rank_value = (
            math.ceil(self.d_model / 16) if self.dt_rank == "auto" else self.dt_rank
        )
        hidden = int(8 * self.d_model / 3) if self.mlp_hidden == "auto" else self.mlp_hidden
        self.mlp_hidden_value = (hidden + 127) // 128 * 128 if self.mlp_hidden == "auto" else hidden


# --------------------------------------------------------------------------- state
class MambaState(NamedTuple):
    """Recurrent state of a :class:`Mamba` stack, for :meth:`Mamba.step`.

    Tensors are replaced, never modified in place, so an old state stays valid.
    """

    conv: torch.Tensor
    """Last ``d_conv - 1`` inputs of every layer's convolution ``(n_layers, B, d_inner, d_conv - 1)``."""
    ssm: torch.Tensor
    """SSM state ``h`` of every layer ``(n_layers, B, d_inner, d_state)``."""


class LayerState(NamedTuple):
    """Recurrent state of one :class:`MambaMixer` (one slice of :class:`MambaState`)."""

    conv: torch.Tensor
    """``(B, d_inner, d_conv - 1)``: the last inputs of the convolution, oldest first."""
    ssm: torch.Tensor
    """``(B, d_inner, d_state)``."""


# --------------------------------------------------------------------------- modules
class MambaMixer(nn.Module):
    """The Mamba layer of thesis Fig. 2.2 (``mamba_ssm``'s ``Mamba``): ``(B, L, d) -> (B, L, d)``.

    Used in: Decision Mamba chapter (thesis 5.3); MDLT chapter.
    """

    def __init__(self, config: MambaConfig, scan_backend: ScanBackend = "auto") -> None:
        super().__init__()
        c = config
        self.config = c
        self.scan_backend = scan_backend
        self.in_proj = nn.Linear(c.d_model, 2 * c.d_inner, bias=c.bias)
        # An nn.Conv1d for its parameters' names and init (mamba_ssm's); applied by
        # causal_depthwise_conv1d in the (B, L, D) layout.
        self.conv1d = nn.Conv1d(
            c.d_inner, c.d_inner, c.d_conv, groups=c.d_inner, padding=c.d_conv - 1, bias=c.conv_bias
        )
        self.x_proj = nn.Linear(c.d_inner, c.dt_rank_value + 2 * c.d_state, bias=False)
        self.dt_proj = nn.Linear(c.dt_rank_value, c.d_inner, bias=True)
        # S4D-real init: A[d, n] = -(n + 1), stored as its log so A stays negative.
        A = torch.arange(1, c.d_state + 1, dtype=torch.float32).repeat(c.d_inner, 1)  # (d_inner, N)
        self.A_log = nn.Parameter(torch.log(A))
        self.D = nn.Parameter(torch.ones(c.d_inner))
        # as mamba_ssm: optimisers may skip decay on these
        setattr(self.A_log, "_no_weight_decay", True)  # noqa: B010 - Parameter has no such field
        setattr(self.D, "_no_weight_decay", True)  # noqa: B010
        self.out_proj = nn.Linear(c.d_inner, c.d_model, bias=c.bias)
        self._init_dt()

    @torch.no_grad()
    def _init_dt(self) -> None:
        """Mamba's Δ init: softplus(dt_proj.bias) log-uniform in [dt_min, dt_max]."""
        c = self.config
        std = c.dt_rank_value**-0.5 * c.dt_scale
        if c.dt_init == "constant":
            nn.init.constant_(self.dt_proj.weight, std)
        else:
            nn.init.uniform_(self.dt_proj.weight, -std, std)
        dt = torch.exp(
            torch.rand(c.d_inner) * (math.log(c.dt_max) - math.log(c.dt_min)) + math.log(c.dt_min)
        )
        dt = dt.clamp(min=c.dt_init_floor)
        self.dt_proj.bias.copy_(dt + torch.log(-torch.expm1(-dt)))  # inverse of softplus
        setattr(self.dt_proj.bias, "_no_reinit", True)  # noqa: B010

    def _ssm_params(self, x: torch.Tensor):
        """Δ (before bias and softplus), B, C from the conv output ``x`` (..., d_inner)."""
        c = self.config
        dt, B, C = self.x_proj(x).split([c.dt_rank_value, c.d_state, c.d_state], dim=-1)
        return F.linear(dt, self.dt_proj.weight), B, C  # the bias goes to the scan as delta_bias

    def forward(self, x: torch.Tensor, return_state: bool = False):
        """Apply the layer to ``x (B, L, d_model)``.

        Args:
            x: Token embeddings ``(B, L, d_model)``.
            return_state: Also return the :class:`LayerState` after the last token.

        Returns:
            ``(B, L, d_model)``, or ``(output, LayerState)`` with ``return_state``.
        """
        c = self.config
        x, z = self.in_proj(x).chunk(2, dim=-1)  # (B, L, d_inner) each
        x_in = x
        x = F.silu(causal_depthwise_conv1d(x, self.conv1d.weight, self.conv1d.bias))
        delta, B, C = self._ssm_params(x)
        A = -torch.exp(self.A_log.float())  # (d_inner, N)
        out = selective_scan(
            x,
            delta,
            A,
            B,
            C,
            self.D.float(),
            z,
            delta_bias=self.dt_proj.bias.float(),
            delta_softplus=True,
            return_last_state=return_state,
            backend=self.scan_backend,
            check=False,
        )
        if not return_state:
            return self.out_proj(out)
        y, h_last = out
        tail = (
            x_in[:, -(c.d_conv - 1) :].transpose(1, 2)
            if c.d_conv > 1
            else x_in[:, :0].transpose(1, 2)
        )
        conv = F.pad(
            tail, (c.d_conv - 1 - tail.shape[-1], 0)
        )  # left-pad short sequences with zeros
        return self.out_proj(y), LayerState(conv, h_last.to(x.dtype))

    def allocate_state(self, batch: int, device=None, dtype=None) -> LayerState:
        """Zero state, as before the first token."""
        c = self.config
        device = device if device is not None else self.A_log.device
        dtype = dtype if dtype is not None else self.in_proj.weight.dtype
        return LayerState(
            torch.zeros(batch, c.d_inner, c.d_conv - 1, device=device, dtype=dtype),
            torch.zeros(batch, c.d_inner, c.d_state, device=device, dtype=dtype),
        )

    def step(self, x_t: torch.Tensor, state: LayerState) -> tuple[torch.Tensor, LayerState]:
        """One token ``x_t (B, d_model)`` -> ``(y_t (B, d_model), new state)``, O(1) in the length."""
        x, z = self.in_proj(x_t).chunk(2, dim=-1)  # (B, d_inner)
        window = torch.cat([state.conv, x.unsqueeze(-1)], dim=-1)  # (B, d_inner, d_conv)
        xc = (window * self.conv1d.weight[:, 0, :]).sum(-1)
        if self.conv1d.bias is not None:
            xc = xc + self.conv1d.bias
        xc = F.silu(xc)
        delta, B, C = self._ssm_params(xc)
        delta = F.softplus(delta + self.dt_proj.bias)
        A = -torch.exp(self.A_log.float())
        y, h = selective_scan_step(
            state.ssm, xc, delta, A.to(xc.dtype), B, C, self.D.to(xc.dtype), z
        )
        return self.out_proj(y), LayerState(window[..., 1:], h)


class GatedMLP(nn.Module):
    """SiLU-gated MLP ``fc2(a * silu(g))`` with ``a, g = fc1(x).chunk(2)``, no biases.

    The per-block MLP of the authors' later DM/HDM code (``mamba_ssm``'s ``GatedMLP``).

    Used in: Decision Mamba chapter (thesis 5.3).
    """

    def __init__(self, d_model: int, hidden: int) -> None:
        super().__init__()
        self.fc1 = nn.Linear(d_model, 2 * hidden, bias=False)
        self.fc2 = nn.Linear(hidden, d_model, bias=False)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """``(..., d_model) -> (..., d_model)``."""
        a, g = self.fc1(x).chunk(2, dim=-1)
        return self.fc2(a * F.silu(g))


class MambaBlock(nn.Module):
    """Pre-norm residual Mamba block: ``x + mixer(norm(x))`` (then ``x + mlp(norm2(x))``).

    Used in: Decision Mamba chapter (thesis 5.3); MDLT chapter.

    Example:
        >>> _ = torch.manual_seed(0)
        >>> block = MambaBlock(MambaConfig(d_model=8, n_layers=1))
        >>> tuple(block(torch.randn(3, 5, 8)).shape)
        (3, 5, 8)
    """

    def __init__(self, config: MambaConfig, scan_backend: ScanBackend = "auto") -> None:
        super().__init__()
        self.norm = nn.RMSNorm(config.d_model, eps=config.norm_eps)
        self.mixer = MambaMixer(config, scan_backend)
        self.norm2: nn.RMSNorm | None = None
        self.mlp: GatedMLP | None = None
        if config.gated_mlp:
            self.norm2 = nn.RMSNorm(config.d_model, eps=config.norm_eps)
            self.mlp = GatedMLP(config.d_model, config.mlp_hidden_value)

    def forward(self, x: torch.Tensor, return_state: bool = False):
        """``(B, L, d_model) -> (B, L, d_model)`` (and the :class:`LayerState` with ``return_state``)."""
        out = self.mixer(self.norm(x), return_state=return_state)
        h, state = out if return_state else (out, None)
        x = x + h
        if self.mlp is not None and self.norm2 is not None:
            x = x + self.mlp(self.norm2(x))
        return (x, state) if return_state else x

    def step(self, x_t: torch.Tensor, state: LayerState) -> tuple[torch.Tensor, LayerState]:
        """One token ``(B, d_model)`` -> ``(y_t, new state)``."""
        h, state = self.mixer.step(self.norm(x_t), state)
        x_t = x_t + h
        if self.mlp is not None and self.norm2 is not None:
            x_t = x_t + self.mlp(self.norm2(x_t))
        return x_t, state


class Mamba(nn.Module):
    """A stack of :class:`MambaBlock` s (plus a final RMSNorm): ``(B, L, d) -> (B, L, d)``.

    No positional input: the recurrence orders the tokens (thesis 5.3.1). The model is causal,
    so right-padding (as DM batches have) does not change the outputs at real tokens.

    Used in: Decision Mamba chapter (thesis 5.3); MDLT chapter.

    Example:
        >>> _ = torch.manual_seed(0)
        >>> model = Mamba(MambaConfig(d_model=8, n_layers=2)).eval()
        >>> x = torch.randn(2, 5, 8)
        >>> state = model.allocate_state(batch=2)
        >>> ys = []
        >>> for t in range(5):
        ...     y_t, state = model.step(x[:, t], state)
        ...     ys.append(y_t)
        >>> torch.allclose(torch.stack(ys, 1), model(x), atol=1e-5)
        True
    """

    def __init__(self, config: MambaConfig, scan_backend: ScanBackend = "auto") -> None:
        super().__init__()
        if not isinstance(config, MambaConfig):
            raise TypeError(f"Expect a MambaConfig, got {type(config).__name__}.")
        self.config = config
        self.layers = nn.ModuleList(
            MambaBlock(config, scan_backend) for _ in range(config.n_layers)
        )
        self.norm_f = nn.RMSNorm(config.d_model, eps=config.norm_eps) if config.final_norm else None
        self._rescale_residual_projections()

    @property
    def blocks(self) -> list[MambaBlock]:
        """The layers, typed (``nn.ModuleList`` items are plain modules to a type checker)."""
        return [cast(MambaBlock, b) for b in self.layers]

    @torch.no_grad()
    def _rescale_residual_projections(self) -> None:
        """GPT-2/mamba_ssm init: residual-branch outputs scaled by 1/sqrt(branches * n_layers)."""
        n = self.config.n_layers * (2 if self.config.gated_mlp else 1)
        for block in self.blocks:
            block.mixer.out_proj.weight /= math.sqrt(n)
            if block.mlp is not None:
                block.mlp.fc2.weight /= math.sqrt(n)

    def _check(self, x: torch.Tensor, ndim: int) -> None:
        d = self.config.d_model
        if x.ndim != ndim or x.shape[-1] != d:
            want = "(B, L, d_model)" if ndim == 3 else "(B, d_model)"
            raise ValueError(
                f"Expect input of shape {want} with d_model={d}, got {tuple(x.shape)}."
            )

    def forward(self, x: torch.Tensor, return_state: bool = False):
        """Apply the stack.

        Args:
            x: Token embeddings ``(B, L, d_model)``.
            return_state: Also return the :class:`MambaState` after the last token, to continue
                with :meth:`step` (prefill).

        Returns:
            ``(B, L, d_model)``, or ``(output, MambaState)`` with ``return_state``.
        """
        self._check(x, 3)
        # Under bfloat16 autocast (TrainConfig.precision) token embeddings may come in bfloat16:
        # the residual stream stays float32 and the RMSNorms get their weights' dtype. A no-op
        # for float32 and float64.
        x = x.to(torch.promote_types(x.dtype, torch.float32))
        states = []
        for block in self.layers:
            if return_state:
                x, s = block(x, return_state=True)
                states.append(s)
            else:
                x = block(x)
        if self.norm_f is not None:
            x = self.norm_f(x)
        if not return_state:
            return x
        return x, MambaState(
            torch.stack([s.conv for s in states]), torch.stack([s.ssm for s in states])
        )

    def allocate_state(
        self, batch: int, device: torch.device | str | None = None, dtype: torch.dtype | None = None
    ) -> MambaState:
        """Zero :class:`MambaState` for ``batch`` sequences, as before their first token."""
        if not isinstance(batch, int) or isinstance(batch, bool) or batch <= 0:
            raise ValueError(f"Expect `batch` to be a positive int, actually: {batch!r}.")
        states = [block.mixer.allocate_state(batch, device, dtype) for block in self.blocks]
        return MambaState(
            torch.stack([s.conv for s in states]), torch.stack([s.ssm for s in states])
        )

    def step(
        self, x_t: torch.Tensor, state: MambaState, fused: bool | None = None
    ) -> tuple[torch.Tensor, MambaState]:
        """Advance every sequence by one token, O(1) in the length so far.

        Args:
            x_t: The next token's embedding ``(B, d_model)``.
            state: From :meth:`allocate_state`, :meth:`forward` with ``return_state``, or the
                previous :meth:`step`.
            fused: Use the compiled one-call kernel (CPU, float32/64, no autograd); ``None``
                picks it whenever it applies, ``False`` runs the layers' torch ops
                (differentiable, any device).

        Returns:
            ``(y_t (B, d_model), new MambaState)``; ``y_t`` equals the last output of
            :meth:`forward` over the whole sequence so far.
        """
        self._check(x_t, 2)
        y, state = self.step_tokens(x_t.unsqueeze(1), state, fused=fused)
        return y[:, 0], state

    def step_tokens(
        self, x: torch.Tensor, state: MambaState, fused: bool | None = None
    ) -> tuple[torch.Tensor, MambaState]:
        """Advance every sequence by ``T`` tokens, one at a time: :meth:`step` over ``x (B, T, d_model)``.

        Acting with a DM, each action appends one timestep's tokens (e.g. R, s, a): one call.

        Returns:
            ``(y (B, T, d_model), new MambaState)``.
        """
        self._check(x, 3)
        if state.ssm.shape[:2] != (self.config.n_layers, x.shape[0]):
            raise ValueError(
                f"Expect a MambaState for {self.config.n_layers} layers and batch {x.shape[0]}, got "
                f"ssm of shape {tuple(state.ssm.shape)}. Create one with allocate_state(batch={x.shape[0]})."
            )
        can_fuse = (
            x.device.type == "cpu"
            and x.dtype in (torch.float32, torch.float64)
            and not (
                torch.is_grad_enabled()
                and (x.requires_grad or any(p.requires_grad for p in self.parameters()))
            )
        )
        if fused is None:
            fused = can_fuse
        elif fused and not can_fuse:
            raise RuntimeError(
                "The fused step needs CPU float32/float64 tensors and no autograd; wrap the call in "
                "torch.no_grad() or pass fused=False."
            )
        if fused:
            return self._step_fused(x, state)
        ys = []
        for t in range(x.shape[1]):
            x_t = x[:, t]
            convs, ssms = [], []
            for i, block in enumerate(self.blocks):
                x_t, s = block.step(x_t, LayerState(state.conv[i], state.ssm[i]))
                convs.append(s.conv)
                ssms.append(s.ssm)
            if self.norm_f is not None:
                x_t = self.norm_f(x_t)
            ys.append(x_t)
            state = MambaState(torch.stack(convs), torch.stack(ssms))
        return torch.stack(ys, 1), state

    def _packed(self, dtype: torch.dtype):
        """Stacked numpy weights for the fused step, rebuilt when any parameter changed."""
        key = (dtype, tuple((id(p), p._version) for p in self.parameters()))
        cache = getattr(self, "_packed_cache", None)
        if cache is None or cache[0] != key:
            cache = (key, pack_weights(self, dtype))
            self._packed_cache = cache
        return cache[1]

    def _step_fused(self, x: torch.Tensor, state: MambaState) -> tuple[torch.Tensor, MambaState]:
        w = self._packed(x.dtype)
        conv = state.conv.to(x.dtype, copy=True).contiguous()
        ssm = state.ssm.to(x.dtype, copy=True).contiguous()
        xs = x.detach().transpose(0, 1).contiguous()  # (T, B, d)
        out = torch.empty_like(xs)
        stack_step_kernel(
            xs.numpy(),
            conv.numpy(),
            ssm.numpy(),
            out.numpy(),
            w.norm_w,
            w.in_w,
            w.in_b,
            w.conv_w,
            w.conv_b,
            w.xp_w,
            w.dt_w,
            w.dt_b,
            w.A,
            w.D,
            w.out_w,
            w.out_b,
            w.norm2_w,
            w.fc1,
            w.fc2,
            w.norm_f,
            w.has_mlp,
            w.has_norm_f,
            w.eps,
        )
        return out.transpose(0, 1), MambaState(conv, ssm)
