"""Evaluation of CLfD embeddings: alignment error (thesis 4.2.2.1) and stage classification (4.2.2.2).

Used in: CLfD (thesis 4.2), chapter 02_clfd.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import torch
from torch import nn


def alignment_error(emb1: np.ndarray, emb2: np.ndarray) -> float:
    """Alignment error of two synchronised videos' embeddings, in % of the video length.

    For every frame i of video 1 the nearest frame j* of video 2 in embedding space (Euclidean)
    is found; the error is the mean of ``|i - j*| / N`` over i, × 100 (TCN's metric, as the authors'
    code computes it). The thesis's Eq 4.3 prints the sum of the nearest *distances* instead; the
    table reports frame-index errors in %, so this is the metric behind Table 4.1.

    Args:
        emb1: (N, D) embeddings of video 1's frames, in time order.
        emb2: (N, D) embeddings of video 2's frames (same instants).

    >>> e = np.eye(4)
    >>> alignment_error(e, e)
    0.0
    >>> alignment_error(e, e[::-1])  # reversed: |i - (3 - i)| = 3, 1, 1, 3 over N = 4
    50.0
    """
    a, b = np.asarray(emb1, dtype=float), np.asarray(emb2, dtype=float)
    if a.ndim != 2 or b.ndim != 2 or a.shape != b.shape:
        raise ValueError(
            f"alignment_error expects two (N, D) arrays of the same shape (synchronised videos), "
            f"got {a.shape} and {b.shape}."
        )
    if not (np.all(np.isfinite(a)) and np.all(np.isfinite(b))):
        raise ValueError("alignment_error: embeddings contain NaN or infinite values.")
    n = len(a)
    d = ((a[:, None, :] - b[None, :, :]) ** 2).sum(-1)  # (N, N) squared distances
    j = d.argmin(axis=1)
    return float(np.abs(np.arange(n) - j).mean() / n * 100.0)


def alignment_distance(emb1: np.ndarray, emb2: np.ndarray) -> float:
    """Eq 4.3 as printed: the mean over frames of video 1 of the distance to the nearest frame of video 2.

    >>> alignment_distance(np.zeros((3, 2)), np.ones((3, 2))).__round__(4)
    1.4142
    """
    a, b = np.asarray(emb1, dtype=float), np.asarray(emb2, dtype=float)
    d = np.sqrt(((a[:, None, :] - b[None, :, :]) ** 2).sum(-1))
    return float(d.min(axis=1).mean())


def balanced_indices(
    labels: np.ndarray, rng: np.random.Generator, per_class: int | None = None
) -> np.ndarray:
    """Indices with the same number of examples of every class (the smallest class's count, or ``per_class``)."""
    labels = np.asarray(labels)
    classes = np.unique(labels)
    n = min(int((labels == c).sum()) for c in classes)
    if per_class is not None:
        n = min(n, per_class)
    idx = [rng.choice(np.flatnonzero(labels == c), n, replace=False) for c in classes]
    return np.sort(np.concatenate(idx))


def train_stage_classifier(
    features: np.ndarray,
    labels: np.ndarray,
    epochs: int = 500,
    hidden: int = 64,
    lr: float = 0.01,
    seed: int = 0,
) -> nn.Module:
    """The thesis's MLP with two fully connected layers on frozen features, full-batch Adam.

    Features are standardised with the training set's mean and std (stored in the model).
    """
    x = torch.as_tensor(np.asarray(features), dtype=torch.float32)
    y = torch.as_tensor(np.asarray(labels), dtype=torch.long)
    if x.ndim != 2 or len(x) != len(y):
        raise ValueError(
            f"Expected features (N, D) and labels (N,), got {tuple(x.shape)} and {tuple(y.shape)}."
        )
    torch.manual_seed(seed)
    mlp = nn.Sequential(
        nn.Linear(x.shape[1], hidden), nn.ReLU(), nn.Linear(hidden, int(y.max()) + 1)
    )
    mean, std = x.mean(0), x.std(0) + 1e-6
    mlp.register_buffer("mean", mean)
    mlp.register_buffer("std", std)
    opt = torch.optim.Adam(mlp.parameters(), lr=lr)
    xs = (x - mean) / std
    for _ in range(epochs):
        opt.zero_grad()
        nn.functional.cross_entropy(mlp(xs), y).backward()
        opt.step()
    return mlp


def classifier_accuracy(mlp: nn.Module, features: np.ndarray, labels: np.ndarray) -> float:
    """Accuracy (%) of :func:`train_stage_classifier`'s model on ``features``."""
    x = torch.as_tensor(np.asarray(features), dtype=torch.float32)
    with torch.no_grad():
        pred = mlp((x - mlp.get_buffer("mean")) / mlp.get_buffer("std")).argmax(1).numpy()
    return float((pred == np.asarray(labels)).mean() * 100.0)


def pca_2d(features: Sequence[np.ndarray]) -> list[np.ndarray]:
    """Project several (N_i, D) arrays onto the first two principal components of all of them."""
    allf = np.concatenate([np.asarray(f, float) for f in features])
    mean = allf.mean(0)
    _, _, vt = np.linalg.svd(allf - mean, full_matrices=False)
    return [(np.asarray(f, float) - mean) @ vt[:2].T for f in features]
