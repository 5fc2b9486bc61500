"""The Background chapter (thesis ch. 2): its :class:`Config`, tables and figures.

Each function here is one step of ``notebooks/01_background.ipynb``: the notebook narrates and
calls; the computation lives in :mod:`thesis_lib.dtw`, :mod:`thesis_lib.seq` and
:mod:`thesis_lib.rl`, and the figures are drawn here so that tests can run them too.
Tables: :func:`run_attention_check`, :func:`run_ssm_check`, :func:`run_dtw_vs_fastdtw`,
:func:`run_rl_curves` (with :func:`summarise_rl`), :func:`run_dt_tokens`.

Used in: Background chapter (thesis 2.2–2.8).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Literal

import numpy as np
import pandas as pd

from thesis_lib import dtw as _dtw


@dataclass
class Config:
    """Parameters of ``notebooks/01_background.ipynb`` (one field per notebook parameter)."""

    seed: int = 0
    """Seed for every random draw of the chapter (sequences, SSM, RL)."""
    dtw_lengths: list[int] = field(default_factory=lambda: [20, 100, 400])
    """Sequence lengths for the exact-DTW-vs-FastDTW table (both sequences this long, ±10%)."""
    dtw_features: int = 11
    """Features per time step (11 = Hopper's observation size, as in DEFENDER)."""
    dtw_pairs: int = 10
    """Random sequence pairs per length."""
    fastdtw_radius: int = 1
    """FastDTW's radius; the DEFENDER code used 1."""
    pe_positions: int = 100
    """Positions in the positional-encoding heatmap."""
    pe_dim: int = 128
    """Embedding size of the positional-encoding heatmap (d = 128 in DT/HDT)."""
    ssm_state: int = 8
    """State size N of the SSM example."""
    ssm_length: int = 200
    """Sequence length of the SSM example."""
    rl_env: str = "Pendulum-v1"
    """Gymnasium task for the DDPG/TD3/SAC learning curves."""
    rl_algos: list[str] = field(default_factory=lambda: ["DDPG", "TD3", "SAC"])
    """Algorithms to train."""
    rl_timesteps: int | dict[str, int] = field(
        default_factory=lambda: {"DDPG": 5000, "TD3": 8000, "SAC": 4000}
    )
    """Environment steps per run: one number for all algorithms, or one per algorithm (the
    defaults are where each has learned Pendulum at seed 0 with the small networks)."""
    rl_learning_rate: float = 1e-3
    """Adam learning rate of actor and critics (3e-4 in the authors' DEFENDER code)."""
    rl_seeds: list[int] = field(default_factory=lambda: [0])
    """Seeds per algorithm."""
    rl_net: list[int] = field(default_factory=lambda: [64, 64])
    """Hidden layers of actor and critics (the thesis's algorithms use 256-256)."""
    n_jobs: int = 1
    """Processes for the RL runs; on a busy 2-core machine one is faster."""
    rl_resume: bool = False
    """Keep each finished RL run under ``results/01_background/rl_runs/`` and reuse it when the
    chapter is rerun with the same settings, so a long (full-profile) sweep that stops part-way
    resumes. Off by default so that the book always retrains."""

    def __post_init__(self) -> None:
        ints = {
            "dtw_features": self.dtw_features,
            "dtw_pairs": self.dtw_pairs,
            "fastdtw_radius": self.fastdtw_radius,
            "pe_positions": self.pe_positions,
            "pe_dim": self.pe_dim,
            "ssm_state": self.ssm_state,
            "ssm_length": self.ssm_length,
            "n_jobs": self.n_jobs,
        }
        for name, value in ints.items():
            if not isinstance(value, int) or isinstance(value, bool) or value < 1:
                raise ValueError(f"{name} must be a positive integer, got {value!r}")
        if self.pe_dim % 2:
            raise ValueError(f"pe_dim must be even (sin/cos pairs), got {self.pe_dim}")
        if not self.dtw_lengths or any(int(n) < 2 for n in self.dtw_lengths):
            raise ValueError(
                f"dtw_lengths must be a non-empty list of lengths ≥ 2, got {self.dtw_lengths!r}"
            )
        valid = ("DDPG", "TD3", "SAC")
        bad = [a for a in self.rl_algos if a not in valid]
        if bad:
            raise ValueError(
                f"Unknown algorithm {bad[0]!r} in rl_algos. Valid: {', '.join(valid)}."
            )
        steps = (
            self.rl_timesteps
            if isinstance(self.rl_timesteps, dict)
            else {a: self.rl_timesteps for a in self.rl_algos}
        )
        for algo in self.rl_algos:
            n = steps.get(algo)
            if not isinstance(n, int) or isinstance(n, bool) or n < 1:
                raise ValueError(f"rl_timesteps must give a positive integer for {algo}, got {n!r}")
        if not self.rl_learning_rate > 0:
            raise ValueError(f"rl_learning_rate must be positive, got {self.rl_learning_rate!r}")
        if not self.rl_seeds:
            raise ValueError("rl_seeds must name at least one seed")


# --------------------------------------------------------------------------- DTW (thesis 2.4)


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
    res = _dtw.dtw_path(*delayed_example(), metric="l1")
    return (2, 4) in {tuple(p) for p in res.path.tolist()}


def plot_dtw_matching():
    """Figs 2.3-2.4: the one-to-one matching and the DTW matching of :func:`delayed_example`."""
    import matplotlib.pyplot as plt

    x, y = delayed_example()
    res = _dtw.dtw_path(x, y, metric="l1")
    fig, axes = plt.subplots(1, 2, figsize=(12, 3.2))
    plot_matching(
        x, y, None, ax=axes[0], title=f"Fig 2.3: one-to-one, distance = {naive_distance(x, y):g}"
    )
    plot_matching(x, y, res.path, ax=axes[1], title=f"Fig 2.4: DTW matching, cost = {res.cost:g}")
    return fig


def plot_dtw_cost_matrices():
    """Figs 2.5-2.7: the initialised, the filled cost matrix, and the path through it."""
    import matplotlib.pyplot as plt

    res = _dtw.dtw_path(*delayed_example(), metric="l1")
    fig, axes = plt.subplots(1, 3, figsize=(16, 5))
    plot_cost_matrix(res.matrix, filled=False, ax=axes[0], title="Fig 2.5: initialised")
    plot_cost_matrix(res.matrix, ax=axes[1], title="Fig 2.6: filled")
    plot_cost_matrix(
        res.matrix, res.path, ax=axes[2], title=f"Fig 2.7: path, cost D[N,M] = {res.cost:g}"
    )
    fig.tight_layout()
    return fig


def plot_matching(x: np.ndarray, y: np.ndarray, pairs: np.ndarray | None, ax=None, title: str = ""):
    """Draw two 1-D sequences (y shifted down) and lines between matched points (Figs 2.3–2.4).

    ``pairs=None`` draws the one-to-one matching.
    """
    import matplotlib.pyplot as plt

    ax = ax or plt.subplots(figsize=(6, 3))[1]
    offset = (np.max(x) - np.min(y)) + 1.5
    ax.plot(x, "o-", color="tab:blue", label="x")
    ax.plot(np.asarray(y) - offset, "o-", color="tab:orange", label="y (shifted down)")
    if pairs is None:
        pairs = np.stack([np.arange(len(x)), np.arange(len(x))], axis=1)
    for i, j in pairs:
        ax.plot([i, j], [x[i], y[j] - offset], color="grey", lw=0.8, ls="--")
    ax.set_yticks([])
    ax.set_xlabel("time step")
    ax.set_title(title)
    ax.legend(loc="upper right", fontsize=8)
    return ax


def plot_cost_matrix(
    matrix: np.ndarray,
    path: np.ndarray | None = None,
    *,
    filled: bool = True,
    ax=None,
    title: str = "",
):
    """Draw the (N+1)×(M+1) DTW cost matrix with its values (Figs 2.5–2.7).

    Args:
        matrix: accumulated cost matrix with its ∞ border (``thesis_lib.dtw.cost_matrix``).
        path: optional (L, 2) 0-based alignment path, drawn on cells (i+1, j+1).
        filled: ``False`` shows the initialised matrix (Fig 2.5): 0 at (0,0), ∞ on the border,
            the rest empty.
    """
    import matplotlib.pyplot as plt

    n1, m1 = matrix.shape
    ax = ax or plt.subplots(figsize=(0.6 * m1 + 1, 0.6 * n1 + 1))[1]
    shown = matrix.copy() if filled else _dtw.initial_cost_matrix(n1 - 1, m1 - 1)
    finite = np.where(np.isfinite(shown), shown, np.nan)
    ax.imshow(finite, cmap="Blues", alpha=0.6)
    on_path = set()
    if path is not None:
        on_path = {(int(i) + 1, int(j) + 1) for i, j in path}
        rows, cols = zip(*sorted(on_path))
        ax.plot(cols, rows, color="tab:red", lw=2)
    for i in range(n1):
        for j in range(m1):
            v = shown[i, j]
            if np.isnan(v):
                continue
            text = "∞" if np.isinf(v) else f"{v:g}"
            ax.text(
                j,
                i,
                text,
                ha="center",
                va="center",
                fontsize=8,
                fontweight="bold" if (i, j) in on_path else "normal",
            )
    ax.set_xticks(range(m1), ["0"] + [str(j) for j in range(1, m1)])
    ax.set_yticks(range(n1), ["0"] + [str(i) for i in range(1, n1)])
    ax.set_xlabel("j (index in y)")
    ax.set_ylabel("i (index in x)")
    ax.set_title(title)
    return ax


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
    _dtw.dtw(np.zeros((2, n_features)), np.zeros((3, n_features)), metric=metric)  # compile
    rows = []
    for n in lengths:
        exact, approx, t_exact, t_fast = [], [], 0.0, 0.0
        for _ in range(n_pairs):
            m = max(2, int(round(n * rng.uniform(0.9, 1.1))))
            x = np.cumsum(rng.normal(size=(n, n_features)), axis=0)
            y = np.cumsum(rng.normal(size=(m, n_features)), axis=0)
            t0 = time.perf_counter()
            exact.append(_dtw.dtw(x, y, metric=metric))
            t1 = time.perf_counter()
            approx.append(_dtw.fastdtw_cost(x, y, radius=radius, metric=metric))
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


# --------------------------------------------------------------------------- Transformers (2.2)


def plot_positional_encoding(n_positions: int, d_model: int):
    """Heatmaps of Eq 2.1–2.2 with the standard base 10000 and with the thesis's printed 1000."""
    import matplotlib.pyplot as plt

    from thesis_lib.seq import sinusoidal_positional_encoding

    fig, axes = plt.subplots(1, 2, figsize=(12, 4), sharey=True)
    for ax, base, label in zip(
        axes, (10000.0, 1000.0), ("standard: base 10000", "as printed in Eq 2.1–2.2: base 1000")
    ):
        pe = sinusoidal_positional_encoding(n_positions, d_model, base=base).numpy()
        im = ax.imshow(pe, aspect="auto", cmap="RdBu_r", vmin=-1, vmax=1, interpolation="nearest")
        ax.set_title(label)
        ax.set_xlabel("embedding dimension")
    axes[0].set_ylabel("token index")
    fig.colorbar(im, ax=axes, shrink=0.8)
    return fig


def run_attention_check(cfg: Config) -> pd.DataFrame:
    """Eq 2.3 with causal, padding and combined masks, checked against PyTorch's fused attention.

    Returns:
        One row per mask: ``mask``, ``max_abs_diff_vs_torch`` (over real queries),
        ``weight_on_masked_keys``.
    """
    return _attention_check(seed=cfg.seed)[0]


def plot_attention_masks(cfg: Config):
    """One heatmap of attention weights per mask (the last sequence's first head)."""
    return plot_attention_weights(_attention_check(seed=cfg.seed)[1])


def _attention_check(
    lengths: tuple[int, ...] = (6, 4), n_heads: int = 2, head_dim: int = 8, seed: int = 0
) -> tuple[pd.DataFrame, dict[str, np.ndarray]]:
    import torch
    import torch.nn.functional as F

    from thesis_lib.seq import attention, causal_mask, combine_masks, padding_mask

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


def plot_attention_weights(weights: dict[str, np.ndarray]):
    """One heatmap of attention weights per mask (query rows, key columns)."""
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, len(weights), figsize=(3.2 * len(weights), 3.2))
    for ax, (name, w) in zip(np.atleast_1d(axes), weights.items()):
        ax.imshow(w, cmap="viridis", vmin=0, vmax=1)
        ax.set_title(name)
        ax.set_xlabel("key")
        ax.set_ylabel("query")
    fig.tight_layout()
    return fig


# --------------------------------------------------------------------------- SSMs (2.3)


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
    import torch

    from thesis_lib.seq import (
        hippo_legs,
        selective_scan_reference,
        ssm_convolution,
        ssm_kernel,
        ssm_recurrence,
        zoh_discretize,
    )

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


def plot_ssm(cfg: Config):
    """The kernel K̄ and the two outputs (convolution and recurrence) on top of each other."""
    import matplotlib.pyplot as plt

    check = ssm_example(n_state=cfg.ssm_state, length=cfg.ssm_length, seed=cfg.seed)
    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(12, 3.5))
    ax1.plot(check["kernel"], color="tab:purple")
    ax1.set_title("convolution kernel $\\bar K_k = C\\bar A^k \\bar B$")
    ax1.set_xlabel("k")
    ax2.plot(check["x"], color="grey", lw=1, label="input x")
    ax2.plot(check["y_recurrence"], lw=3, alpha=0.5, label="y by recurrence (2.6)")
    ax2.plot(check["y_convolution"], "--", color="k", lw=1, label="y by convolution (2.7)")
    ax2.set_xlabel("time step")
    ax2.legend(fontsize=8)
    fig.tight_layout()
    return fig


# --------------------------------------------------------------------------- DDPG, TD3, SAC (2.5–2.7)


def run_rl_curves(cfg: Config, cache_dir: str | Path | None = None) -> pd.DataFrame:
    """DDPG, TD3 and SAC on ``cfg.rl_env``: every training episode (one row each).

    Args:
        cache_dir: keep each finished (algo, seed) run there and reuse it (``cfg.rl_resume``;
            the notebook passes ``results/01_background/rl_runs``).

    Returns:
        :data:`thesis_lib.rl.CURVE_COLUMNS` rows (algo, seed, episode, timestep, return, ...).
    """
    from thesis_lib.rl import learning_curves

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


def summarise_rl(episodes: pd.DataFrame, last: int = 5) -> pd.DataFrame:
    """First and last-``last``-episode mean returns per algorithm (mean over seeds)."""
    rows = []
    for (algo, seed), g in episodes.groupby(["algo", "seed"], sort=False):
        g = g.sort_values("episode")
        rows.append(
            {
                "algo": algo,
                "seed": seed,
                "episodes": len(g),
                "first_return": g["return"].iloc[0],
                f"mean_return_last_{last}": g["return"].tail(last).mean(),
                "best_return": g["return"].max(),
            }
        )
    per_seed = pd.DataFrame(rows)
    return (
        per_seed.groupby("algo", sort=False)
        .mean(numeric_only=True)
        .drop(columns="seed")
        .reset_index()
    )


def plot_learning_curves(episodes: pd.DataFrame, window: int = 3):
    """Episode return against environment steps, one line per algorithm (mean over seeds, smoothed)."""
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7, 4))
    for algo, g in episodes.groupby("algo", sort=False):
        curve = g.groupby("episode").agg(timestep=("timestep", "mean"), ret=("return", "mean"))
        ax.plot(curve["timestep"], curve["ret"].rolling(window, min_periods=1).mean(), label=algo)
    ax.set_xlabel("environment steps")
    ax.set_ylabel(f"episode return (rolling mean of {window})")
    ax.legend()
    ax.grid(alpha=0.3)
    return fig


# --------------------------------------------------------------------------- Decision Transformer (2.8)


def run_dt_tokens() -> pd.DataFrame:
    """A four-step trajectory laid out as DT tokens (rtg, s, a) with its returns-to-go."""
    from thesis_lib.seq import interleave_tokens, returns_to_go

    rewards = np.array([1.0, 0.0, 2.0, 1.0])
    states = np.array([[0.0, 1.0], [0.5, 0.8], [1.0, 0.4], [1.4, 0.1]])
    actions = np.array([[0.3], [-0.1], [0.2], [0.0]])
    return interleave_tokens(returns_to_go(rewards), states, actions)
