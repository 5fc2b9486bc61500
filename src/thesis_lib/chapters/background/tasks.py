"""The Background chapter's computations: each is one step of ``notebooks/01_background.ipynb``.

The computation itself lives in :mod:`thesis_lib.dtw`, :mod:`thesis_lib.seq` and
:mod:`thesis_lib.rl`; here are the chapter's examples and checks. Tables:
:func:`run_attention_check`, :func:`run_ssm_check`, :func:`run_dtw_vs_fastdtw`,
:func:`run_rl_curves`, :func:`run_dt_tokens`; the examples the figures draw:
:func:`delayed_example`, :func:`attention_check`, :func:`ssm_example`.

Used in: Background chapter (thesis 2.2–2.8).
"""

from __future__ import annotations

import time
from pathlib import Path
from typing import Literal

import numpy as np
import pandas as pd
import torch
import torch.nn.functional as F

from thesis_lib import dtw
from thesis_lib.chapters.background.config import Config
from thesis_lib.rl import learning_curves
from thesis_lib.seq import (
    attention,
    causal_mask,
    combine_masks,
    hippo_legs,
    interleave_tokens,
    padding_mask,
    returns_to_go,
    selective_scan_reference,
    ssm_convolution,
    ssm_kernel,
    ssm_recurrence,
    zoh_discretize,
)

__all__ = [
    "attention_check",
    "delayed_example",
    "naive_distance",
    "peak_on_path",
    "run_attention_check",
    "run_dt_tokens",
    "run_dtw_vs_fastdtw",
    "run_rl_curves",
    "run_ssm_check",
    "ssm_example",
]


# ----------------------------------------------------------- DTW (thesis 2.4)


def delayed_example() -> tuple[np.ndarray, np.ndarray]:
    """The two sequences of the DTW figures: ``y`` is ``x`` delayed by two steps.

    Chosen so that, as in the thesis's Fig 2.7, the cell (3, 5) (1-based) lies on the path:
    the third point of ``x`` (the peak) is matched to the fifth point of ``y``.

    >>> x, y = delayed_example()
    >>> x.tolist(), y.tolist()
    ([0.0, 1.0, 3.0, 2.0, 1.0, 0.0, 0.0], [0.0, 0.0, 0.0, 1.0, 3.0, 2.0, 1.0])
    """
    x = np.array([0, 1, 3, 2, 1, 0, 0], dtype=float)
    y = np.concatenate([[0.0, 0.0], x[:-2]])
    return x, y


def naive_distance(x: np.ndarray, y: np.ndarray) -> float:
    """One-to-one (lock-step) L1 distance of two equal-length 1-D sequences (Fig 2.3).

    >>> naive_distance(*delayed_example())
    10.0
    """
    x, y = np.asarray(x, float), np.asarray(y, float)
    if x.shape != y.shape:
        raise ValueError(f"The one-to-one distance needs equal shapes, got {x.shape} and {y.shape}")
    return float(np.abs(x - y).sum())


def peak_on_path() -> bool:
    """Whether the cell (3, 5) (1-based) lies on the DTW path of :func:`delayed_example` (Fig 2.7).

    >>> peak_on_path()
    True
    """
    res = dtw.dtw_path(*delayed_example(), metric="l1")
    return (2, 4) in {tuple(p) for p in res.path.tolist()}


def run_dtw_vs_fastdtw(
    cfg: Config, metric: Literal["l1", "l2", "sqeuclidean"] = "l1"
) -> pd.DataFrame:
    """Exact DTW against FastDTW on random multi-dimensional sequences: cost error and time.

    ``cfg.dtw_lengths`` sequence lengths, ``cfg.dtw_features`` features, ``cfg.dtw_pairs`` pairs
    per length, FastDTW radius ``cfg.fastdtw_radius``, seed ``cfg.seed``.

    Sequences are random walks (so that they have structure to align); the second of each pair
    is 0.9–1.1× as long as the first. Timings exclude numba's one-off compilation.

    Returns:
        One row per length: ``length, features, pairs, exact_cost, fastdtw_cost,
        rel_error_pct`` (mean of (fastdtw − exact)/exact × 100; FastDTW never finds a cheaper
        path than the exact one), ``max_rel_error_pct``, ``exact_ms``, ``fastdtw_ms``, ``speedup``.
    """
    lengths, n_features, n_pairs = cfg.dtw_lengths, cfg.dtw_features, cfg.dtw_pairs
    radius = cfg.fastdtw_radius
    rng = np.random.default_rng(cfg.seed)
    dtw.dtw(np.zeros((2, n_features)), np.zeros((3, n_features)), metric=metric)  # compile
    rows = []
    for n in lengths:
        exact, approx, t_exact, t_fast = [], [], 0.0, 0.0
        for _ in range(n_pairs):
            m = max(2, int(round(n * rng.uniform(0.9, 1.1))))
            x = np.cumsum(rng.normal(size=(n, n_features)), axis=0)
            y = np.cumsum(rng.normal(size=(m, n_features)), axis=0)
            t0 = time.perf_counter()
            exact.append(dtw.dtw(x, y, metric=metric))
            t1 = time.perf_counter()
            approx.append(dtw.fastdtw_cost(x, y, radius=radius, metric=metric))
            t2 = time.perf_counter()
            t_exact += t1 - t0
            t_fast += t2 - t1
        exact_a, approx_a = np.array(exact), np.array(approx)
        rel = (approx_a - exact_a) / exact_a * 100
        rows.append(
            {
                "length": n,
                "features": n_features,
                "pairs": n_pairs,
                "exact_cost": exact_a.mean(),
                "fastdtw_cost": approx_a.mean(),
                "rel_error_pct": rel.mean(),
                "max_rel_error_pct": rel.max(),
                "exact_ms": 1000 * t_exact / n_pairs,
                "fastdtw_ms": 1000 * t_fast / n_pairs,
                "speedup": t_fast / max(t_exact, 1e-12),
            }
        )
    return pd.DataFrame(rows)


# --------------------------------------------------------- Transformers (2.2)


def run_attention_check(cfg: Config) -> pd.DataFrame:
    """Eq 2.3 with causal, padding and combined masks, checked against PyTorch's fused attention.

    Returns:
        One row per mask: ``mask``, ``max_abs_diff_vs_torch`` (over real queries),
        ``weight_on_masked_keys``.
    """
    return attention_check(seed=cfg.seed)[0]


def attention_check(
    lengths: tuple[int, ...] = (6, 4), n_heads: int = 2, head_dim: int = 8, seed: int = 0
) -> tuple[pd.DataFrame, dict[str, np.ndarray]]:
    """Eq 2.3 on random queries, keys and values (``lengths`` sequences, padded) under each
    mask, beside PyTorch's fused attention.

    Returns:
        ``(table, weights)``: the table of :func:`run_attention_check` and, per mask, the
        attention weights of the last sequence's first head (:func:`plot_attention_masks
        <thesis_lib.chapters.background.figures.plot_attention_masks>`).
    """
    gen = torch.Generator().manual_seed(seed)
    B, T = len(lengths), max(lengths)
    q, k, v = (
        torch.randn(B, n_heads, T, head_dim, generator=gen, dtype=torch.float64) for _ in range(3)
    )
    pad = padding_mask(list(lengths), T)
    masks = {
        "none": None,
        "causal": causal_mask(T),
        "padding": combine_masks(None, pad),
        "causal + padding": combine_masks(causal_mask(T), pad),
    }
    rows, weights = [], {}
    real_q = pad[:, None, :, None]  # (B, 1, T, 1): padded queries' outputs are not compared
    for name, mask in masks.items():
        ours = attention(q, k, v, mask)
        ref = F.scaled_dot_product_attention(q, k, v, attn_mask=mask)
        diff = (ours.out - ref).abs().where(real_q, torch.zeros(()))
        allowed = (
            torch.ones(B, 1, T, T, dtype=torch.bool) if mask is None else mask.expand(B, 1, T, T)
        )
        leaked = ours.weights.where(~allowed & real_q, torch.zeros(())).abs().max()
        rows.append(
            {
                "mask": name,
                "max_abs_diff_vs_torch": float(diff.max()),
                "weight_on_masked_keys": float(leaked),
            }
        )
        weights[name] = ours.weights[-1, 0].numpy()
    return pd.DataFrame(rows), weights


# ----------------------------------------------------------------- SSMs (2.3)


def run_ssm_check(cfg: Config) -> pd.DataFrame:
    """Convolution vs recurrence, and the selective scan vs the LTI system: max differences.

    One row per check (``check``, ``max_abs_diff``); see :func:`ssm_example`.
    """
    return ssm_example(n_state=cfg.ssm_state, length=cfg.ssm_length, seed=cfg.seed)["table"]


def ssm_example(n_state: int = 8, length: int = 200, delta: float = 0.05, seed: int = 0) -> dict:
    """ZOH-discretise a HiPPO-LegS SSM and compare the convolution (Eq 2.7) with the recurrence (Eq 2.6).

    Also runs the Mamba-style selective scan with Δ, B, C held constant, which must give the
    same output as the time-invariant system with a ZOH Ā and an Euler B̄ (= ΔB).

    Returns:
        dict with ``x`` (input), ``kernel`` (K̄), ``y_recurrence``, ``y_convolution``, and a
        one-row-per-check DataFrame ``table`` with the maximum absolute differences.
    """
    rng = np.random.default_rng(seed)
    A, B = hippo_legs(n_state)
    C = rng.normal(size=n_state)
    t = np.arange(length)
    x = np.sin(2 * np.pi * t / 50) + 0.5 * (t % 40 < 5)  # a slow wave plus periodic pulses
    A_bar, B_bar = zoh_discretize(A, B, delta)
    y_rec = ssm_recurrence(A_bar, B_bar, C, x)
    K = ssm_kernel(A_bar, B_bar, C, length)
    y_conv = ssm_convolution(x, K)

    # Selective scan with constant parameters on a diagonal system (Mamba's A is diagonal).
    a_diag = -np.exp(rng.normal(size=n_state))
    b, c = rng.normal(size=n_state), rng.normal(size=n_state)
    u = torch.tensor(x, dtype=torch.float64)[None, :, None]  # (1, L, 1)
    dt = torch.full_like(u, delta)
    Bt = torch.tensor(b)[None, None, :].expand(1, length, n_state)
    Ct = torch.tensor(c)[None, None, :].expand(1, length, n_state)
    y_sel = selective_scan_reference(u, dt, torch.tensor(a_diag)[None, :], Bt, Ct)[0, :, 0].numpy()
    A_lti = np.exp(delta * a_diag)
    y_lti = ssm_recurrence(A_lti, delta * b, c, x)
    table = pd.DataFrame(
        [
            {
                "check": "convolution (Eq 2.7) vs recurrence (Eq 2.6)",
                "max_abs_diff": float(np.abs(y_conv - y_rec).max()),
            },
            {
                "check": "selective scan, constant Δ,B,C vs LTI recurrence (ZOH Ā, Euler B̄)",
                "max_abs_diff": float(np.abs(y_sel - y_lti).max()),
            },
        ]
    )
    return {"x": x, "kernel": K, "y_recurrence": y_rec, "y_convolution": y_conv, "table": table}


# --------------------------------------------------- DDPG, TD3, SAC (2.5–2.7)


def run_rl_curves(cfg: Config, cache_dir: str | Path | None = None) -> pd.DataFrame:
    """DDPG, TD3 and SAC on ``cfg.rl_env``: every training episode (one row each).

    Args:
        cache_dir: keep each finished (algo, seed) run there and reuse it (``cfg.rl_resume``;
            the notebook passes ``results/01_background/rl_runs``).

    Returns:
        :data:`thesis_lib.rl.CURVE_COLUMNS` rows (algo, seed, episode, timestep, return, ...).
    """
    episodes = learning_curves(
        cfg.rl_algos,
        cfg.rl_env,
        cfg.rl_timesteps,
        cfg.rl_seeds,
        n_jobs=cfg.n_jobs,
        net_arch=cfg.rl_net,
        learning_rate=cfg.rl_learning_rate,
        cache_dir=cache_dir if cfg.rl_resume else None,
    )
    empty = [a for a in cfg.rl_algos if a not in set(episodes["algo"])]
    if empty:
        raise ValueError(
            f"No {cfg.rl_env} episode ended within rl_timesteps={cfg.rl_timesteps!r} for "
            f"{', '.join(empty)}: give each algorithm at least one episode's steps "
            "(Pendulum-v1: 200)."
        )
    return episodes


# ------------------------------------------------- Decision Transformer (2.8)


def run_dt_tokens() -> pd.DataFrame:
    """A four-step trajectory laid out as DT tokens (rtg, s, a) with its returns-to-go."""
    rewards = np.array([1.0, 0.0, 2.0, 1.0])
    states = np.array([[0.0, 1.0], [0.5, 0.8], [1.0, 0.4], [1.4, 0.1]])
    actions = np.array([[0.3], [-0.1], [0.2], [0.0]])
    return interleave_tokens(returns_to_go(rewards), states, actions)
