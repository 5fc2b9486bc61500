"""Tests for thesis_lib.seq.ssm: ZOH (Eq. 2.5), recurrence == convolution (Eq. 2.6-2.7), selective scan."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.linalg
import torch

from thesis_lib.seq import (
    hippo_legs,
    selective_scan_reference,
    selective_scan_step,
    ssm_convolution,
    ssm_kernel,
    ssm_recurrence,
    zoh_discretize,
)


def _random_stable(N: int, rng: np.random.Generator) -> np.ndarray:
    """A random dense A whose eigenvalues have negative real part (shifted by its spectral abscissa)."""
    M = rng.normal(size=(N, N))
    return M - (np.max(np.linalg.eigvals(M).real) + 0.5) * np.eye(N)


# ---------------------------------------------------------------- ZOH (Eq. 2.5)


@pytest.mark.parametrize(
    "a, b, delta", [(-1.0, 1.0, 0.5), (-3.0, 2.0, 0.01), (0.7, -1.5, 0.2), (0.0, 2.0, 0.3)]
)
def test_zoh_scalar_closed_form(a, b, delta):
    A_bar, B_bar = zoh_discretize([a], [b], delta)
    assert A_bar[0] == pytest.approx(np.exp(delta * a), rel=1e-14)
    expected_B = (np.exp(delta * a) - 1.0) / a * b if a != 0 else delta * b  # A -> 0 limit: Δ B
    assert B_bar[0] == pytest.approx(expected_B, rel=1e-12)
    # The full-matrix path (augmented expm) agrees with the diagonal closed form.
    A_full, B_full = zoh_discretize([[a]], [b], delta)
    assert A_full[0, 0] == pytest.approx(A_bar[0], rel=1e-13)
    assert B_full[0] == pytest.approx(B_bar[0], rel=1e-12)


def test_zoh_diagonal_matches_matrix_path():
    a = np.array([-1.0, -0.5, -4.0, 0.0])
    b = np.array([1.0, 2.0, -1.0, 0.5])
    A_bar, B_bar = zoh_discretize(a, b, 0.1)
    np.testing.assert_allclose(A_bar, np.exp(0.1 * a), rtol=1e-14)
    np.testing.assert_allclose(
        B_bar, np.where(a != 0, np.expm1(0.1 * a) / np.where(a != 0, a, 1), 0.1) * b, rtol=1e-13
    )
    A_full, B_full = zoh_discretize(np.diag(a), b, 0.1)
    np.testing.assert_allclose(A_full, np.diag(A_bar), atol=1e-15)
    np.testing.assert_allclose(B_full, B_bar, rtol=1e-12)


def test_zoh_dense_matches_equation_2_5():
    rng = np.random.default_rng(0)
    A = _random_stable(5, rng)
    B = rng.normal(size=5)
    delta = 0.3
    A_bar, B_bar = zoh_discretize(A, B, delta)
    dA = delta * A
    expected_A = scipy.linalg.expm(dA)
    expected_B = np.linalg.solve(
        dA, (expected_A - np.eye(5)) @ (delta * B)
    )  # (ΔA)^{-1}(exp(ΔA) - I) ΔB
    np.testing.assert_allclose(A_bar, expected_A, rtol=1e-12, atol=1e-14)
    np.testing.assert_allclose(B_bar, expected_B, rtol=1e-10, atol=1e-13)


def test_zoh_is_exact_for_constant_input():
    # ZOH is exact for piecewise-constant input: x(t) = 1, h(0) = 0 gives h(t) = A^{-1}(e^{At} - I) B.
    A, B = hippo_legs(4)
    delta, steps = 0.05, 20
    A_bar, B_bar = zoh_discretize(A, B, delta)
    h = np.zeros(4)
    for _ in range(steps):
        h = A_bar @ h + B_bar
    t = delta * steps
    exact = np.linalg.solve(A, (scipy.linalg.expm(A * t) - np.eye(4)) @ B)
    np.testing.assert_allclose(h, exact, rtol=1e-10, atol=1e-12)


def test_zoh_errors():
    with pytest.raises(ValueError, match=r"square.*\(2, 3\)"):
        zoh_discretize(np.zeros((2, 3)), np.zeros(2), 0.1)
    with pytest.raises(ValueError, match=r"`B` of shape \(N,\) = \(3,\).*\(2,\)"):
        zoh_discretize(-np.eye(3), np.zeros(2), 0.1)
    with pytest.raises(ValueError, match=r"positive finite scalar.*-0.1"):
        zoh_discretize([-1.0], [1.0], -0.1)
    with pytest.raises(ValueError, match=r"`A` to be finite.*1 NaN"):
        zoh_discretize([-1.0, np.nan], [1.0, 1.0], 0.1)


# ---------------------------------------------------------------- recurrence == convolution (Eq. 2.6-2.7)


@pytest.mark.parametrize("kind", ["hippo", "random-dense", "diagonal"])
@pytest.mark.parametrize("method", ["direct", "fft"])
def test_convolution_equals_recurrence(kind, method):
    rng = np.random.default_rng(1)
    N, L = 8, 64
    if kind == "hippo":
        A, B = hippo_legs(N)
    elif kind == "random-dense":
        A, B = _random_stable(N, rng), rng.normal(size=N)
    else:
        A, B = -rng.uniform(0.1, 3.0, size=N), rng.normal(size=N)
    C = rng.normal(size=N)
    A_bar, B_bar = zoh_discretize(A, B, 0.1)
    x = rng.normal(size=(3, L))  # a batch of 3 sequences
    y_rec = ssm_recurrence(A_bar, B_bar, C, x)
    K = ssm_kernel(A_bar, B_bar, C, L)
    y_conv = ssm_convolution(x, K, method=method)
    assert y_rec.shape == y_conv.shape == (3, L)
    np.testing.assert_allclose(y_conv, y_rec, rtol=0, atol=1e-10)
    np.testing.assert_allclose(
        ssm_convolution(x[0], K, method=method), y_rec[0], rtol=0, atol=1e-10
    )


def test_kernel_is_impulse_response():
    A, B = hippo_legs(6)
    C = np.arange(6.0)
    A_bar, B_bar = zoh_discretize(A, B, 0.2)
    impulse = np.zeros(10)
    impulse[0] = 1.0
    np.testing.assert_allclose(
        ssm_kernel(A_bar, B_bar, C, 10), ssm_recurrence(A_bar, B_bar, C, impulse), atol=1e-13
    )
    # Diagonal Ā (Vandermonde path) equals the same system given as a diagonal matrix.
    a, b = -np.arange(1.0, 7.0), np.ones(6)
    Ad, Bd = zoh_discretize(a, b, 0.2)
    np.testing.assert_allclose(
        ssm_kernel(Ad, Bd, C, 10), ssm_kernel(np.diag(Ad), Bd, C, 10), rtol=1e-13, atol=1e-15
    )
    # K̄_j = C Ā^j B̄ by hand for a scalar system.
    np.testing.assert_allclose(ssm_kernel([0.9], [2.0], [0.5], 4), [1.0, 0.9, 0.81, 0.729])


def test_convolution_longer_kernel_is_truncated_and_errors():
    x = np.array([1.0, 0.0, 2.0])
    np.testing.assert_allclose(ssm_convolution(x, [1.0, 1.0, 1.0, 5.0]), [1.0, 1.0, 3.0])
    with pytest.raises(ValueError, match=r"kernel has length 2 but the input has length L=3.*L=3"):
        ssm_convolution(x, [1.0, 1.0])
    with pytest.raises(ValueError, match=r"Unknown convolution method 'loop'. Valid: direct, fft"):
        ssm_convolution(x, [1.0, 1.0, 1.0], method="loop")
    with pytest.raises(ValueError, match=r"finite input"):
        ssm_recurrence([0.5], [1.0], [1.0], [1.0, np.inf])
    with pytest.raises(ValueError, match=r"`C` of shape \(N,\) = \(1,\)"):
        ssm_recurrence([0.5], [1.0], [1.0, 2.0], [1.0])
    with pytest.raises(ValueError, match=r"positive int"):
        ssm_kernel([0.5], [1.0], [1.0], 0)


def test_hippo_legs_structure():
    A, B = hippo_legs(5)
    assert A.shape == (5, 5) and B.shape == (5,)
    assert np.allclose(np.triu(A, 1), 0)  # lower triangular
    np.testing.assert_allclose(
        np.sort(np.linalg.eigvals(A).real), -np.arange(5.0, 0.0, -1)
    )  # -(n+1)
    assert A[3, 1] == pytest.approx(-np.sqrt(7 * 3))
    np.testing.assert_allclose(B, np.sqrt(2 * np.arange(5) + 1))
    with pytest.raises(ValueError, match=r"positive int, actually: 0"):
        hippo_legs(0)


# ---------------------------------------------------------------- selective scan (Mamba-1)


def _scan_inputs(batch=2, L=12, Din=3, N=4, seed=0, dtype=torch.float64):
    g = torch.Generator().manual_seed(seed)
    u = torch.randn(batch, L, Din, generator=g, dtype=dtype)
    delta = torch.rand(batch, L, Din, generator=g, dtype=dtype) * 0.5 + 0.01
    A = -torch.rand(Din, N, generator=g, dtype=dtype) * 3 - 0.1
    B = torch.randn(batch, L, N, generator=g, dtype=dtype)
    C = torch.randn(batch, L, N, generator=g, dtype=dtype)
    return u, delta, A, B, C


def test_selective_scan_constant_params_equals_lti_recurrence():
    # Input-independent Δ, B, C: every channel is an LTI SSM with Ā = exp(ΔA) (ZOH) and B̄ = Δ B (Euler).
    batch, L, Din, N = 2, 16, 3, 4
    rng = np.random.default_rng(3)
    deltas = np.array([0.1, 0.3, 0.05])  # one Δ per channel
    A = -rng.uniform(0.2, 2.0, size=(Din, N))
    b, c = rng.normal(size=N), rng.normal(size=N)
    u = rng.normal(size=(batch, L, Din))
    y = selective_scan_reference(
        torch.from_numpy(u),
        torch.from_numpy(np.broadcast_to(deltas, (batch, L, Din)).copy()),
        torch.from_numpy(A),
        torch.from_numpy(np.broadcast_to(b, (batch, L, N)).copy()),
        torch.from_numpy(np.broadcast_to(c, (batch, L, N)).copy()),
    ).numpy()
    assert y.shape == (batch, L, Din)
    for d in range(Din):
        A_bar = np.exp(deltas[d] * A[d])  # ZOH for A
        B_bar = deltas[d] * b  # Euler for B
        np.testing.assert_allclose(
            y[:, :, d], ssm_recurrence(A_bar, B_bar, c, u[:, :, d]), rtol=0, atol=1e-12
        )
        # ... and the same LTI channel is also the convolution of Eq. 2.7.
        K = ssm_kernel(A_bar, B_bar, c, L)
        np.testing.assert_allclose(y[:, :, d], ssm_convolution(u[:, :, d], K), rtol=0, atol=1e-12)


def test_selective_scan_euler_b_differs_from_zoh_b_by_delta_squared():
    # Mamba's B̄ = ΔB against the exact ZOH B̄: the gap shrinks like Δ² (first-order rule).
    a, b = np.array([-1.0]), np.array([1.0])
    gaps = []
    for delta in (0.1, 0.05, 0.025):
        zoh_B = zoh_discretize(a, b, delta).B_bar[0]
        gaps.append(abs(delta * b[0] - zoh_B))
    assert gaps[0] > 0
    np.testing.assert_allclose(np.array(gaps[:-1]) / np.array(gaps[1:]), 4.0, rtol=0.06)


def test_selective_scan_matches_explicit_formula():
    # Unrolled time-varying system: y_t = Σ_{s<=t} C_t (Π_{r=s+1}^{t} Ā_r) B̄_s u_s, per channel.
    u, delta, A, B, C = _scan_inputs(batch=1, L=6, Din=2, N=3)
    y = selective_scan_reference(u, delta, A, B, C)
    for d in range(2):
        for t in range(6):
            total = 0.0
            for s in range(t + 1):
                decay = torch.exp(
                    delta[0, s + 1 : t + 1, d].sum() * A[d]
                )  # Π exp(Δ_r A) = exp(ΣΔ_r A)
                total += (C[0, t] * decay * delta[0, s, d] * B[0, s] * u[0, s, d]).sum()
            assert y[0, t, d].item() == pytest.approx(total.item(), abs=1e-12)


def test_selective_scan_D_z_bias_softplus():
    u, delta, A, B, C = _scan_inputs()
    g = torch.Generator().manual_seed(5)
    D = torch.randn(3, generator=g, dtype=torch.float64)
    z = torch.randn(2, 12, 3, generator=g, dtype=torch.float64)
    bias = torch.randn(3, generator=g, dtype=torch.float64)
    base = selective_scan_reference(u, delta, A, B, C)
    full = selective_scan_reference(u, delta, A, B, C, D, z)
    torch.testing.assert_close(
        full, (base + D * u) * torch.nn.functional.silu(z), atol=1e-12, rtol=0
    )
    raw = delta - 0.3
    fused = selective_scan_reference(u, raw, A, B, C, delta_bias=bias, delta_softplus=True)
    manual = selective_scan_reference(u, torch.nn.functional.softplus(raw + bias), A, B, C)
    torch.testing.assert_close(fused, manual, atol=1e-12, rtol=0)


def test_selective_scan_is_causal_and_step_matches():
    u, delta, A, B, C = _scan_inputs()
    y = selective_scan_reference(u, delta, A, B, C)
    u2, B2 = u.clone(), B.clone()
    u2[:, 7:] += 1.0
    B2[:, 7:] *= -1.0
    y2 = selective_scan_reference(u2, delta, A, B2, C)
    torch.testing.assert_close(y2[:, :7], y[:, :7], atol=0, rtol=0)
    # Stepping one token at a time (recurrent generation) reproduces the scan.
    h = torch.zeros(2, 3, 4, dtype=torch.float64)
    for t in range(12):
        y_t, h = selective_scan_step(h, u[:, t], delta[:, t], A, B[:, t], C[:, t])
        torch.testing.assert_close(y_t, y[:, t], atol=1e-13, rtol=0)


def test_selective_scan_dtypes():
    u, delta, A, B, C = _scan_inputs(dtype=torch.float32)
    y32 = selective_scan_reference(u, delta, A, B, C)
    assert y32.dtype == torch.float32
    y64 = selective_scan_reference(*(t.double() for t in (u, delta, A, B, C)))
    torch.testing.assert_close(y32.double(), y64, atol=1e-5, rtol=1e-5)


def test_selective_scan_errors():
    u, delta, A, B, C = _scan_inputs()
    with pytest.raises(ValueError, match=r"`u` of shape \(B, L, Din\), got \(12, 3\)"):
        selective_scan_reference(u[0], delta, A, B, C)
    with pytest.raises(ValueError, match=r"`A` of shape \(Din, N\) = \(3, N\), got \(4, 3\)"):
        selective_scan_reference(u, delta, A.T, B, C)
    with pytest.raises(ValueError, match=r"`B` of shape \(2, 12, 4\).*got \(2, 4, 12\)"):
        selective_scan_reference(u, delta, A, B.transpose(1, 2), C)
    with pytest.raises(ValueError, match=r"`D` of shape \(3,\)"):
        selective_scan_reference(u, delta, A, B, C, D=torch.ones(4, dtype=torch.float64))
    bad = delta.clone()
    bad[0, 0, 0] = float("nan")
    with pytest.raises(ValueError, match=r"`delta` to be finite, it has 1 NaN"):
        selective_scan_reference(u, bad, A, B, C)
    with pytest.raises(TypeError, match=r"`u` to be a torch.Tensor, got ndarray"):
        selective_scan_reference(u.numpy(), delta, A, B, C)
