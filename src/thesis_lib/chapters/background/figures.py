"""The Background chapter's figures, drawn here so that tests can run them too.

Used in: Background chapter (thesis 2.2–2.8).
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from thesis_lib import dtw
from thesis_lib.chapters.background.config import Config
from thesis_lib.chapters.background.tasks import (
    attention_check,
    delayed_example,
    naive_distance,
    ssm_example,
)
from thesis_lib.seq import sinusoidal_positional_encoding

__all__ = [
    "plot_attention_masks",
    "plot_attention_weights",
    "plot_cost_matrix",
    "plot_dtw_cost_matrices",
    "plot_dtw_matching",
    "plot_learning_curves",
    "plot_matching",
    "plot_positional_encoding",
    "plot_ssm",
]


# ----------------------------------------------------------- DTW (thesis 2.4)


def plot_dtw_matching():
    """Figs 2.3-2.4: the one-to-one matching and the DTW matching of :func:`delayed_example`."""
    import matplotlib.pyplot as plt

    x, y = delayed_example()
    res = dtw.dtw_path(x, y, metric="l1")
    fig, axes = plt.subplots(1, 2, figsize=(12, 3.2))
    plot_matching(
        x, y, None, ax=axes[0], title=f"Fig 2.3: one-to-one, distance = {naive_distance(x, y):g}"
    )
    plot_matching(x, y, res.path, ax=axes[1], title=f"Fig 2.4: DTW matching, cost = {res.cost:g}")
    return fig


def plot_dtw_cost_matrices():
    """Figs 2.5-2.7: the initialised, the filled cost matrix, and the path through it."""
    import matplotlib.pyplot as plt

    res = dtw.dtw_path(*delayed_example(), metric="l1")
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
    shown = matrix.copy() if filled else dtw.initial_cost_matrix(n1 - 1, m1 - 1)
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


# --------------------------------------------------------- Transformers (2.2)


def plot_positional_encoding(n_positions: int, d_model: int):
    """Heatmaps of Eq 2.1–2.2 with the standard base 10000 and with the thesis's printed 1000."""
    import matplotlib.pyplot as plt

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


def plot_attention_masks(cfg: Config):
    """One heatmap of attention weights per mask (the last sequence's first head)."""
    return plot_attention_weights(attention_check(seed=cfg.seed)[1])


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


# ----------------------------------------------------------------- SSMs (2.3)


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


# --------------------------------------------------- DDPG, TD3, SAC (2.5–2.7)


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
