"""The two kinds of shipped policy, in NumPy: :class:`LinearPolicy` (ARS) and :class:`MLPPolicy`
(TQC / SAC / CrossQ).

Both map an observation (or a batch) to an action; loading one needs NumPy only. Trained and
exported by :mod:`thesis_lib.data.experts` (ARS) and :mod:`thesis_lib.data.deep_experts`
(TQC / SAC / CrossQ), loaded by :func:`thesis_lib.data.experts.load_policy`; both modules
re-export the class they make.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

__all__ = ["LOG_STD_MAX", "LOG_STD_MIN", "LinearPolicy", "MLPPolicy"]

# VecNormalize's defaults (stable-baselines3): obs clipped to ±10 after z-scoring, eps 1e-8.
_CLIP_OBS = 10.0
_EPS = 1e-8


@dataclass
class LinearPolicy:
    """A deterministic linear policy ``a = clip(W · clip((o - mean)/sqrt(var + 1e-8), ±10))``.

    This is exactly sb3-contrib's ``LinearPolicy`` (no bias, clipped output) behind
    stable-baselines3's ``VecNormalize(norm_obs=True)``, in NumPy.

    Attributes:
        weights: ``(act_dim, obs_dim)`` float64.
        obs_mean: ``(obs_dim,)`` running mean of the observations.
        obs_var: ``(obs_dim,)`` running variance of the observations.
        low: ``(act_dim,)`` lower action bound.
        high: ``(act_dim,)`` upper action bound.
    """

    weights: np.ndarray
    obs_mean: np.ndarray
    obs_var: np.ndarray
    low: np.ndarray
    high: np.ndarray

    def __call__(self, obs: np.ndarray) -> np.ndarray:
        """Act on one ``(obs_dim,)`` or a batch ``(n, obs_dim)`` of observations."""
        z = np.clip((obs - self.obs_mean) / np.sqrt(self.obs_var + _EPS), -_CLIP_OBS, _CLIP_OBS)
        return np.clip(z @ self.weights.T, self.low, self.high)

    def perturbed(self, rng: np.random.Generator, std: float) -> LinearPolicy:
        """A copy with Gaussian noise of ``std`` on the weights (ARS's exploration)."""
        w = self.weights + std * rng.standard_normal(self.weights.shape)
        return LinearPolicy(w, self.obs_mean, self.obs_var, self.low, self.high)


LOG_STD_MIN, LOG_STD_MAX = -20.0, 2.0  # SB3's and sbx's clamp of the actor's log-std


@dataclass
class MLPPolicy:
    """A squashed-Gaussian MLP actor (SAC / TQC) in NumPy.

    ``h = relu(... relu(o W0 + b0) ...)``, ``mean = h Wm + bm``, ``log_std = h Ws + bs``
    (clamped to [-20, 2]); the deterministic action is ``tanh(mean)``, a sampled one
    ``tanh(mean + exp(log_std) * eps)``, both scaled from [-1, 1] to ``[low, high]``.

    Attributes:
        weights: hidden layers' ``(in, out)`` matrices, then the mean head, then the
            log-std head.
        biases: their biases, same order.
        low: ``(act_dim,)`` lower action bound.
        high: ``(act_dim,)`` upper action bound.
    """

    weights: list[np.ndarray]
    biases: list[np.ndarray]
    low: np.ndarray
    high: np.ndarray

    def _heads(self, obs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        h = np.asarray(obs, dtype=np.float64)
        for w, b in zip(self.weights[:-2], self.biases[:-2]):
            h = np.maximum(h @ w + b, 0.0)
        mean = h @ self.weights[-2] + self.biases[-2]
        log_std = np.clip(h @ self.weights[-1] + self.biases[-1], LOG_STD_MIN, LOG_STD_MAX)
        return mean, log_std

    def _scale(self, u: np.ndarray) -> np.ndarray:
        return self.low + 0.5 * (np.tanh(u) + 1.0) * (self.high - self.low)

    def __call__(self, obs: np.ndarray) -> np.ndarray:
        """Deterministic action for one ``(obs_dim,)`` or a batch ``(n, obs_dim)``."""
        mean, _ = self._heads(obs)
        return self._scale(mean)

    def sample(self, obs: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        """An action drawn from the actor's Gaussian (its exploration during training)."""
        mean, log_std = self._heads(obs)
        return self._scale(mean + np.exp(log_std) * rng.standard_normal(mean.shape))

    def to_arrays(self, prefix: str = "") -> dict[str, np.ndarray]:
        """Flat ``{name: array}`` for ``np.savez`` (float32)."""
        out = {}
        for i, (w, b) in enumerate(zip(self.weights, self.biases)):
            out[f"{prefix}w{i}"] = w.astype(np.float32)
            out[f"{prefix}b{i}"] = b.astype(np.float32)
        return out

    @classmethod
    def from_arrays(cls, z: Any, low: np.ndarray, high: np.ndarray, prefix: str = "") -> MLPPolicy:
        """Inverse of :meth:`to_arrays` (``z`` a mapping such as an ``NpzFile``)."""
        ws, bs, i = [], [], 0
        while f"{prefix}w{i}" in z:
            ws.append(np.asarray(z[f"{prefix}w{i}"], dtype=np.float64))
            bs.append(np.asarray(z[f"{prefix}b{i}"], dtype=np.float64))
            i += 1
        if i < 3:
            raise ValueError(f"No MLP policy with prefix '{prefix}' (found {i} layers, need ≥ 3).")
        return cls(ws, bs, np.asarray(low, np.float64), np.asarray(high, np.float64))
