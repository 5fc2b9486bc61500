"""Structured state space models (thesis Sec. 2.3, Eq. 2.4-2.7) and Mamba's selective scan.

**The continuous system (Eq. 2.4).** A 1-D input ``x(t)`` drives an ``N``-dim state ``h(t)``:
``h'(t) = A h(t) + B x(t)``, ``y(t) = C h(t)``. The thesis prints ``y(t) = C h'(t)`` in Eq. 2.4
and 2.6; the output reads the state, ``y = C h``, not its derivative (S4, Mamba).

**Discretisation (Eq. 2.5).** With step ``Δ`` and zero-order hold (the input is held constant
over each step), ``Ā = exp(ΔA)`` and ``B̄ = (ΔA)^{-1} (exp(ΔA) - I) ΔB``
(:func:`zoh_discretize`). S4 itself used the bilinear transform; S4D and Mamba use ZOH.

**Recurrence and convolution (Eq. 2.6-2.7).** In discrete time the system is
``h_k = Ā h_{k-1} + B̄ x_k``, ``y_k = C h_k`` with ``h_{-1} = 0`` (:func:`ssm_recurrence`; Eq. 2.6
writes it with ``h'`` and ``t``). Unrolling gives ``y_k = Σ_{j<=k} C Ā^j B̄ x_{k-j}``: a causal
convolution of ``x`` with the kernel ``K̄ = (CB̄, CĀB̄, ..., CĀ^{L-1}B̄)`` (:func:`ssm_kernel`,
:func:`ssm_convolution`). Training uses the convolution (parallel, FFT); generation uses the
recurrence (constant memory per step). Both give the same ``y``.

**What Mamba makes selective.** In S4 the parameters ``Δ, A, B, C`` are the same at every step:
a linear time-invariant (LTI) system, which is why one kernel ``K̄`` serves every position. Mamba
computes ``Δ_t``, ``B_t`` and ``C_t`` from the input token ``x_t`` (linear projections; ``Δ``
through a softplus), so the model can choose, token by token, what to write into the state and
what to forget. The system becomes time-varying:
``y_t = Σ_{s<=t} C_t (Ā_t Ā_{t-1} ... Ā_{s+1}) B̄_s x_s``. That is no longer a function of
``t - s`` alone, so there is no single kernel and no convolution: Mamba evaluates the
recurrence with a scan (a hardware-aware parallel scan on GPU; a sequential loop in
:func:`selective_scan_reference`, which later fast kernels are checked against).

Conventions: the LTI functions are single-input single-output (the thesis's ``B, C ∈ R^{N×1}``)
and take NumPy arrays in float64; ``A`` is a full ``(N, N)`` matrix or, when 1-D ``(N,)``, the
diagonal of a diagonal matrix (S4D, Mamba). The selective scan takes torch tensors.

Used in: Background chapter (thesis 2.3); Decision Mamba chapter.
"""

from __future__ import annotations

from typing import Any, Literal, NamedTuple

import numpy as np
import scipy.linalg
import scipy.signal
import torch
import torch.nn.functional as F

# ----------------------------------------------------------------------------------------------
# Validation helpers


def _as_finite(name: str, x: Any, ndims: tuple[int, ...]) -> np.ndarray:
    arr = np.asarray(x, dtype=np.float64) if not np.iscomplexobj(x) else np.asarray(x)
    if np.iscomplexobj(arr):
        raise ValueError(f"Expect `{name}` to be real, got complex dtype {arr.dtype}.")
    if arr.ndim not in ndims:
        want = " or ".join(f"{n}-D" for n in ndims)
        raise ValueError(f"Expect `{name}` to be {want}, got shape {arr.shape}.")
    if not np.all(np.isfinite(arr)):
        raise ValueError(
            f"Expect `{name}` to be finite, it has {int(np.sum(~np.isfinite(arr)))} NaN/inf entries."
        )
    return arr


def _check_A(A: object) -> np.ndarray:
    A = _as_finite("A", A, (1, 2))
    if A.ndim == 2 and A.shape[0] != A.shape[1]:
        raise ValueError(f"Expect `A` to be square (N, N) or a diagonal (N,), got shape {A.shape}.")
    return A


def _check_vector(name: str, v: object, N: int) -> np.ndarray:
    v = _as_finite(name, v, (1, 2))
    if v.size != N or (v.ndim == 2 and 1 not in v.shape):
        raise ValueError(
            f"Expect `{name}` of shape (N,) = ({N},) (or ({N}, 1) / (1, {N})) to match A, got shape {v.shape}."
        )
    return v.reshape(N)


# ----------------------------------------------------------------------------------------------
# LTI SSM (S4): Eq. 2.4-2.7


class Discretization(NamedTuple):
    """What :func:`zoh_discretize` returns."""

    A_bar: np.ndarray
    """Discrete state matrix ``exp(ΔA)``: ``(N, N)``, or ``(N,)`` for diagonal ``A``."""
    B_bar: np.ndarray
    """Discrete input vector ``(ΔA)^{-1}(exp(ΔA) - I) ΔB``: ``(N,)``."""


def zoh_discretize(A: np.ndarray, B: np.ndarray, delta: float) -> Discretization:
    """Zero-order-hold discretisation of ``h' = A h + B x`` with step ``delta`` (Eq. 2.5).

    ``Ā = exp(ΔA)`` and ``B̄ = (ΔA)^{-1} (exp(ΔA) - I) ΔB``.

    * Full ``A`` (2-D): both come from one matrix exponential of the augmented matrix
      ``Δ [[A, B], [0, 0]]``, whose top row is ``[Ā, B̄]``. This equals Eq. 2.5 when ``A`` is
      invertible and stays exact when it is not (``B̄ = ∫_0^Δ exp(As) ds B`` always).
    * Diagonal ``A`` (1-D, the diagonal entries): the closed form, elementwise,
      ``Ā = exp(ΔA)``, ``B̄ = (exp(ΔA) - 1) / A · B`` (``ΔB`` in the limit ``A → 0``).

    Used in: Background chapter (thesis 2.3); Decision Mamba chapter.

    Args:
        A: Continuous state matrix ``(N, N)``, or its diagonal ``(N,)``.
        B: Continuous input vector ``(N,)`` (or ``(N, 1)``).
        delta: Step size ``Δ > 0``.

    Returns:
        :class:`Discretization` ``(A_bar, B_bar)`` in float64; ``A_bar`` has ``A``'s shape.

    Raises:
        ValueError: On non-square ``A``, a ``B`` that does not match it, non-finite values or
            ``delta <= 0``.

    Example:
        >>> A_bar, B_bar = zoh_discretize([-1.0], [1.0], delta=0.5)  # scalar system
        >>> round(float(A_bar[0]), 6), round(float(B_bar[0]), 6)  # exp(-0.5), 1 - exp(-0.5)
        (0.606531, 0.393469)
    """
    A = _check_A(A)
    N = A.shape[0]
    B = _check_vector("B", B, N)
    if not (np.isscalar(delta) or np.ndim(delta) == 0) or not np.isfinite(delta) or not delta > 0:
        raise ValueError(
            f"Expect the step `delta` to be a positive finite scalar, actually: {delta!r}."
        )
    delta = float(delta)
    if A.ndim == 1:
        dA = delta * A  # (N,)
        # (exp(ΔA) - 1) / A = Δ (exp(ΔA) - 1) / (ΔA), whose limit at A = 0 is Δ.
        safe = np.where(dA == 0.0, 1.0, dA)
        phi = np.where(dA == 0.0, 1.0, np.expm1(dA) / safe)  # (N,)
        return Discretization(np.exp(dA), phi * delta * B)
    M = np.zeros((N + 1, N + 1))
    M[:N, :N] = A
    M[:N, N] = B
    E = scipy.linalg.expm(delta * M)  # [[exp(ΔA), B̄], [0, 1]]
    return Discretization(E[:N, :N], E[:N, N].copy())


def ssm_recurrence(
    A_bar: np.ndarray, B_bar: np.ndarray, C: np.ndarray, x: np.ndarray
) -> np.ndarray:
    """Run the discrete SSM as a recurrence: ``h_k = Ā h_{k-1} + B̄ x_k``, ``y_k = C h_k``, ``h_{-1} = 0``.

    This is Eq. 2.6 in discrete time (the thesis writes ``h'(t)`` for ``h_k`` and ``C h'`` for
    ``C h``). Cost ``O(L N^2)`` (``O(L N)`` for diagonal ``Ā``), memory ``O(N)`` per sequence.

    Used in: Background chapter (thesis 2.3); Decision Mamba chapter.

    Args:
        A_bar: Discrete state matrix ``(N, N)``, or its diagonal ``(N,)``.
        B_bar: Discrete input vector ``(N,)``.
        C: Output vector ``(N,)``.
        x: Input sequence ``(L,)``, or a batch ``(..., L)`` of independent sequences.

    Returns:
        ``y`` with ``x``'s shape, float64.

    Raises:
        ValueError: On mismatched shapes or non-finite values.

    Example:
        >>> ssm_recurrence([0.5], [1.0], [2.0], [1.0, 0.0, 0.0]).tolist()  # impulse response
        [2.0, 1.0, 0.5]
    """
    A_bar = _check_A(A_bar)
    N = A_bar.shape[0]
    B_bar = _check_vector("B_bar", B_bar, N)
    C = _check_vector("C", C, N)
    x = np.asarray(x, dtype=np.float64)
    if x.ndim < 1 or not np.all(np.isfinite(x)):
        raise ValueError(f"Expect a finite input `x` of shape (..., L), got shape {x.shape}.")
    L = x.shape[-1]
    h = np.zeros((*x.shape[:-1], N))  # (..., N), h_{-1} = 0
    y = np.empty_like(x)  # (..., L)
    for k in range(L):
        h = (h * A_bar if A_bar.ndim == 1 else h @ A_bar.T) + x[..., k, None] * B_bar  # (..., N)
        y[..., k] = h @ C
    return y


def ssm_kernel(A_bar: np.ndarray, B_bar: np.ndarray, C: np.ndarray, L: int) -> np.ndarray:
    """The SSM convolution kernel of Eq. 2.7: ``K̄ = (CB̄, CĀB̄, ..., CĀ^{L-1}B̄)``.

    ``K̄_j`` is the impulse response: the output ``j`` steps after a unit input.

    Used in: Background chapter (thesis 2.3).

    Args:
        A_bar: Discrete state matrix ``(N, N)``, or its diagonal ``(N,)``.
        B_bar: Discrete input vector ``(N,)``.
        C: Output vector ``(N,)``.
        L: Kernel length (the thesis's ``K``: the input length); positive.

    Returns:
        ``K̄`` of shape ``(L,)``, float64; plot it against ``range(L)``.

    Raises:
        ValueError: On mismatched shapes, non-finite values or ``L <= 0``.

    Example:
        >>> ssm_kernel([0.5], [1.0], [2.0], 4).tolist()
        [2.0, 1.0, 0.5, 0.25]
    """
    A_bar = _check_A(A_bar)
    N = A_bar.shape[0]
    B_bar = _check_vector("B_bar", B_bar, N)
    C = _check_vector("C", C, N)
    if not isinstance(L, (int, np.integer)) or L <= 0:
        raise ValueError(f"Expect the kernel length `L` to be a positive int, actually: {L!r}.")
    if A_bar.ndim == 1:
        powers = A_bar[None, :] ** np.arange(L)[:, None]  # (L, N) Vandermonde: Ā_n^j
        return powers @ (C * B_bar)
    K = np.empty(L)
    v = B_bar.copy()  # Ā^j B̄
    for j in range(L):
        K[j] = C @ v
        v = A_bar @ v
    return K


def ssm_convolution(
    x: np.ndarray, K_bar: np.ndarray, method: Literal["direct", "fft"] = "direct"
) -> np.ndarray:
    """Causal convolution ``y_k = Σ_{j=0}^{k} K̄_j x_{k-j}`` (Eq. 2.7, ``y = x * K̄``).

    Equals :func:`ssm_recurrence` when ``K̄ = ssm_kernel(Ā, B̄, C, L)``.

    Used in: Background chapter (thesis 2.3).

    Args:
        x: Input ``(L,)`` or a batch ``(..., L)``.
        K_bar: Kernel of length at least ``L`` (entries beyond ``L`` are unused).
        method: ``"direct"`` (a lower-triangular Toeplitz product, ``O(L^2)``, exact) or
            ``"fft"`` (``O(L log L)``, as S4 trains; round-off around 1e-15 relative).

    Returns:
        ``y`` with ``x``'s shape, float64.

    Raises:
        ValueError: If the kernel is shorter than ``x``, inputs are not finite, or ``method``
            is unknown.

    Example:
        >>> ssm_convolution([1.0, 1.0, 1.0], [2.0, 1.0, 0.5]).tolist()
        [2.0, 3.0, 3.5]
    """
    if method not in ("direct", "fft"):
        raise ValueError(f"Unknown convolution method {method!r}. Valid: direct, fft.")
    x = np.asarray(x, dtype=np.float64)
    K_bar = _as_finite("K_bar", K_bar, (1,))
    if x.ndim < 1 or not np.all(np.isfinite(x)):
        raise ValueError(f"Expect a finite input `x` of shape (..., L), got shape {x.shape}.")
    L = x.shape[-1]
    if K_bar.shape[0] < L:
        raise ValueError(
            f"The kernel has length {K_bar.shape[0]} but the input has length L={L}; "
            f"build it with ssm_kernel(A_bar, B_bar, C, L={L})."
        )
    K_bar = K_bar[:L]
    if method == "fft":
        shape = (1,) * (x.ndim - 1) + (L,)
        return scipy.signal.fftconvolve(x, K_bar.reshape(shape), mode="full", axes=-1)[..., :L]
    T = scipy.linalg.toeplitz(K_bar, np.zeros(L))  # (L, L), T[k, i] = K̄_{k-i} for i <= k
    return x @ T.T


def hippo_legs(N: int) -> tuple[np.ndarray, np.ndarray]:
    """HiPPO-LegS matrices ``(A, B)``, the initialisation of S4 (Gu et al., 2020).

    ``A[n, k] = -sqrt(2n+1) sqrt(2k+1)`` for ``n > k``, ``-(n+1)`` for ``n = k``, ``0`` for
    ``n < k``; ``B[n] = sqrt(2n+1)``. The state then tracks the coefficients of a Legendre
    expansion of the input history. ``A`` is lower triangular with eigenvalues ``-(n+1)``, so
    the system is stable for any ``Δ > 0``. (Mamba's real initialisation keeps only this
    diagonal, ``A = -(1, 2, ..., N)``.)

    Used in: Background chapter (thesis 2.3).

    Args:
        N: State size; positive.

    Returns:
        ``A`` of shape ``(N, N)`` and ``B`` of shape ``(N,)``, float64.

    Raises:
        ValueError: If ``N`` is not a positive int.

    Example:
        >>> A, B = hippo_legs(3)
        >>> A.round(3).tolist()
        [[-1.0, 0.0, 0.0], [-1.732, -2.0, 0.0], [-2.236, -3.873, -3.0]]
    """
    if not isinstance(N, (int, np.integer)) or N <= 0:
        raise ValueError(f"Expect the state size `N` to be a positive int, actually: {N!r}.")
    q = np.sqrt(2.0 * np.arange(N) + 1.0)  # (N,)
    n, k = np.indices((N, N))
    A = np.where(n > k, -q[:, None] * q[None, :], 0.0) - np.diag(np.arange(N) + 1.0)  # (N, N)
    return A, q.copy()


# ----------------------------------------------------------------------------------------------
# Selective SSM (Mamba-1): naive reference scan


class ScanStep(NamedTuple):
    """What :func:`selective_scan_step` returns."""

    y: torch.Tensor
    """Output at this step, ``(B, Din)``."""
    h: torch.Tensor
    """New state, ``(B, Din, N)``."""


def _compute_dtype(*xs: torch.Tensor | None) -> torch.dtype:
    return (
        torch.float64
        if any(x is not None and x.dtype == torch.float64 for x in xs)
        else torch.float32
    )


def selective_scan_step(
    h: torch.Tensor,
    u: torch.Tensor,
    delta: torch.Tensor,
    A: torch.Tensor,
    B: torch.Tensor,
    C: torch.Tensor,
    D: torch.Tensor | None = None,
    z: torch.Tensor | None = None,
) -> ScanStep:
    """One step of Mamba's selective SSM, for recurrent generation (see :func:`selective_scan_reference`).

    Same semantics as one iteration of :func:`selective_scan_reference` (after its ``delta_bias``
    and softplus). It does not check its inputs, since it runs once per generated token; pass
    tensors of one dtype.

    Used in: Decision Mamba chapter.

    Args:
        h: Previous state ``(B, Din, N)`` (zeros before the first step).
        u: Input at this step ``(B, Din)``.
        delta: Step sizes ``(B, Din)``, already positive (after any softplus).
        A: Continuous diagonal state matrices ``(Din, N)`` (negative for stability).
        B: Input projection at this step ``(B, N)``.
        C: Output projection at this step ``(B, N)``.
        D: Optional skip ``(Din,)``.
        z: Optional gate ``(B, Din)``.

    Returns:
        :class:`ScanStep` ``(y (B, Din), h (B, Din, N))``.
    """
    dA = torch.exp(delta[..., None] * A)  # (B, Din, N): ZOH for A
    dBu = delta[..., None] * B[:, None, :] * u[..., None]  # (B, Din, N): Euler for B
    h = dA * h + dBu  # (B, Din, N)
    y = (h * C[:, None, :]).sum(-1)  # (B, Din)
    if D is not None:
        y = y + D * u
    if z is not None:
        y = y * F.silu(z)
    return ScanStep(y, h)


def selective_scan_reference(
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
) -> torch.Tensor:
    """Mamba-1 selective scan, a naive sequential loop: the reference for fast kernels.

    Each of the ``Din`` channels is an independent SISO SSM with a diagonal ``A[d] ∈ R^N``; all
    channels share the input-dependent ``B_t, C_t ∈ R^N`` at step ``t``. With
    ``Δ = delta (+ delta_bias) (then softplus if delta_softplus)``, for every batch ``b``,
    channel ``d``, step ``t`` (``h_{-1} = 0``)::

        deltaA[t]   = exp(Δ[b,t,d] * A[d, :])                 # (N,)  ZOH for A
        deltaB_u[t] = Δ[b,t,d] * B[b,t,:] * u[b,t,d]          # (N,)  Euler for B
        h[t]        = deltaA[t] * h[t-1] + deltaB_u[t]        # (N,)
        y[b,t,d]    = h[t] · C[b,t,:] + D[d] * u[b,t,d]
        y[b,t,d]   *= silu(z[b,t,d])                          # if z is given

    ``B̄ = Δ B`` is Mamba's simplification of the ZOH ``B̄ = (exp(ΔA) - 1)/A · B`` of Eq. 2.5:
    the forward-Euler (first-order) rule for ``B``, while ``A`` keeps the exact ZOH
    ``exp(ΔA)``. The two ``B̄`` differ by ``O(Δ²)``. This matches ``selective_scan_ref`` of the
    ``mamba_ssm`` package, except for the layout: ours is ``(B, L, Din)`` (token-major, like the
    Transformer code), theirs ``(B, Din, L)``.

    Computed in float64 if any input is float64, else float32; returned in ``u``'s dtype.
    Cost ``O(B L Din N)``, one Python iteration per step: fine for checks, slow for training.

    Used in: Background chapter (thesis 2.3); Decision Mamba chapter.

    Args:
        u: Input ``(B, L, Din)``.
        delta: Step sizes ``(B, L, Din)``; positive unless ``delta_softplus`` makes them so.
        A: Continuous diagonal state matrices ``(Din, N)``, real; negative for a stable scan
            (Mamba stores ``A = -exp(A_log)``).
        B: Input-dependent input projections ``(B, L, N)``.
        C: Input-dependent output projections ``(B, L, N)``.
        D: Optional skip connection ``(Din,)``.
        z: Optional gate ``(B, L, Din)``; the output is multiplied by ``silu(z)``.
        delta_bias: Optional ``(Din,)`` added to ``delta`` (before the softplus).
        delta_softplus: Apply ``softplus`` to ``delta`` (after the bias), as Mamba does.

    Returns:
        ``y`` of shape ``(B, L, Din)``.

    Raises:
        ValueError: On shapes that do not match the ones above (both are named), complex or
            non-finite inputs.

    Example:
        >>> u = torch.ones(1, 3, 1, dtype=torch.float64)  # B=1, L=3, Din=1
        >>> A = torch.full((1, 1), -1e9, dtype=torch.float64)  # forgets at once: h_t = Δ B u
        >>> B = C = torch.ones(1, 3, 1, dtype=torch.float64)
        >>> selective_scan_reference(u, 0.5 * u, A, B, C).flatten().tolist()
        [0.5, 0.5, 0.5]
    """
    check_scan_inputs(u, delta, A, B, C, D, z, delta_bias)
    dtype = _compute_dtype(u, delta, A, B, C, D, z, delta_bias)
    u_, dl, A_, B_, C_ = (t.to(dtype) for t in (u, delta, A, B, C))
    D_ = None if D is None else D.to(dtype)
    z_ = None if z is None else z.to(dtype)
    if delta_bias is not None:
        dl = dl + delta_bias.to(dtype)
    if delta_softplus:
        dl = F.softplus(dl)
    batch, L, Din = u.shape
    h = torch.zeros(batch, Din, A.shape[1], dtype=dtype, device=u.device)  # (B, Din, N)
    ys = []
    for t in range(L):
        y_t, h = selective_scan_step(
            h, u_[:, t], dl[:, t], A_, B_[:, t], C_[:, t], D_, None if z_ is None else z_[:, t]
        )
        ys.append(y_t)  # (B, Din)
    return torch.stack(ys, dim=1).to(u.dtype)  # (B, L, Din)


def check_scan_inputs(u, delta, A, B, C, D, z, delta_bias) -> None:
    """Raise a ``ValueError`` naming the input unless the selective scan's inputs have the
    shapes and dtypes it needs (used by every scan: the reference, the step and Mamba's)."""
    named = {
        "u": u,
        "delta": delta,
        "A": A,
        "B": B,
        "C": C,
        "D": D,
        "z": z,
        "delta_bias": delta_bias,
    }
    for name, t in named.items():
        if t is None:
            continue
        if not isinstance(t, torch.Tensor):
            raise TypeError(f"Expect `{name}` to be a torch.Tensor, got {type(t).__name__}.")
        if t.is_complex():
            raise ValueError(
                f"Expect `{name}` to be real; complex A is not supported by this reference."
            )
    if u.ndim != 3:
        raise ValueError(f"Expect `u` of shape (B, L, Din), got {tuple(u.shape)}.")
    batch, L, Din = u.shape
    if A.ndim != 2 or A.shape[0] != Din:
        raise ValueError(f"Expect `A` of shape (Din, N) = ({Din}, N), got {tuple(A.shape)}.")
    N = A.shape[1]
    want = {
        "delta": (batch, L, Din),
        "B": (batch, L, N),
        "C": (batch, L, N),
        "D": (Din,),
        "z": (batch, L, Din),
        "delta_bias": (Din,),
    }
    for name, shape in want.items():
        t = named[name]
        if t is not None and tuple(t.shape) != shape:
            raise ValueError(
                f"Expect `{name}` of shape {shape} (from u {tuple(u.shape)} = (B, L, Din) and "
                f"A {tuple(A.shape)} = (Din, N)), got {tuple(t.shape)}."
            )
    for name, t in named.items():
        if t is not None and not bool(torch.isfinite(t).all()):
            n_bad = int((~torch.isfinite(t)).sum())
            raise ValueError(f"Expect `{name}` to be finite, it has {n_bad} NaN/inf entries.")
