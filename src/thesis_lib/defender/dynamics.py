"""The dynamics model DEFENDER uses to answer a filtered step (thesis 4.3.1).

When the filter skips ``env.step``, the agent still needs a next state for temporal-difference
learning. DEFENDER predicts it with p_theta(s_{t+1} | s_t, a_t): an MLP s||a -> 256 -> 256 -> s
trained with an L2 loss (Adam, 3e-4) on the real transitions seen so far, one minibatch every
``train_every`` real steps (Algorithm 2: 1; :class:`~thesis_lib.defender.DefenderWrapper`'s
default: 4, for speed). Filtered (predicted) transitions never enter its training data.

Used in: DEFENDER (thesis 4.3).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
import torch
from numpy.typing import ArrayLike
from torch import nn

__all__ = ["DynamicsModel"]


class DynamicsModel:
    """An MLP next-state model trained online on real transitions.

    Args:
        obs_dim: state size.
        act_dim: action size.
        hidden: hidden layer widths (thesis: two of 256).
        learning_rate: Adam learning rate (thesis: 3e-4).
        batch_size: transitions per gradient step (256, as the agent's).
        buffer_size: real transitions kept (oldest overwritten).
        train_every: one gradient step every this many added transitions (1 = every real step,
            as Algorithm 2's "Optimize pi and theta").
        seed: seeds the weights and the minibatch sampling.

    Used in: DEFENDER (thesis 4.3).
    """

    def __init__(
        self,
        obs_dim: int,
        act_dim: int,
        *,
        hidden: Sequence[int] = (256, 256),
        learning_rate: float = 3e-4,
        batch_size: int = 256,
        buffer_size: int = 1_000_000,
        train_every: int = 1,
        seed: int = 0,
    ) -> None:
        if obs_dim < 1 or act_dim < 1:
            raise ValueError(
                f"DynamicsModel needs obs_dim and act_dim >= 1, got {obs_dim} and {act_dim}."
            )
        if train_every < 1 or batch_size < 1 or buffer_size < 1:
            raise ValueError(
                f"DynamicsModel needs positive train_every, batch_size and buffer_size, got "
                f"{train_every}, {batch_size}, {buffer_size}."
            )
        self.obs_dim, self.act_dim = int(obs_dim), int(act_dim)
        self.batch_size, self.train_every = int(batch_size), int(train_every)
        # Seeded weights without moving torch's global RNG (the agent's own seeding stays intact).
        with torch.random.fork_rng(devices=[]):
            torch.manual_seed(seed)
            layers: list[nn.Module] = []
            width = obs_dim + act_dim
            for h in hidden:
                layers += [nn.Linear(width, h), nn.ReLU()]
                width = h
            layers.append(nn.Linear(width, obs_dim))
            self.net = nn.Sequential(*layers)  # (B, obs_dim + act_dim) -> (B, obs_dim)
        self.optimizer = torch.optim.Adam(self.net.parameters(), lr=learning_rate)
        self._rng = np.random.default_rng(seed)
        self._inputs = np.zeros((buffer_size, obs_dim + act_dim), dtype=np.float32)  # s || a
        self._targets = np.zeros((buffer_size, obs_dim), dtype=np.float32)  # s'
        self._size = 0
        self._pos = 0
        self._added = 0
        self.n_updates = 0
        self.last_loss = float("nan")

    def state_dict(self) -> dict[str, Any]:
        """Everything a continued run needs: the network, its optimiser, the stored
        transitions, the counters and the minibatch sampler's state (a checkpoint,
        :mod:`thesis_lib.rl.resume`)."""
        return {
            "net": {k: v.clone() for k, v in self.net.state_dict().items()},
            "optimizer": self.optimizer.state_dict(),
            "rng": self._rng.bit_generator.state,
            "inputs": self._inputs[: self._size].copy(),
            "targets": self._targets[: self._size].copy(),
            "buffer_size": len(self._inputs),
            "size": self._size,
            "pos": self._pos,
            "added": self._added,
            "n_updates": self.n_updates,
            "last_loss": self.last_loss,
        }

    def load_state_dict(self, state: dict[str, Any]) -> None:
        """Continue from :meth:`state_dict`'s ``state``, taken from a model of the same sizes.

        Raises:
            ValueError: a state of another buffer size.
        """
        if state["buffer_size"] != len(self._inputs):
            raise ValueError(
                f"The dynamics state has a buffer of {state['buffer_size']}, this model "
                f"{len(self._inputs)}."
            )
        self.net.load_state_dict(state["net"])
        self.optimizer.load_state_dict(state["optimizer"])
        self._rng.bit_generator.state = state["rng"]
        n = int(state["size"])
        self._inputs[:n], self._targets[:n] = state["inputs"], state["targets"]
        self._size, self._pos, self._added = n, int(state["pos"]), int(state["added"])
        self.n_updates, self.last_loss = int(state["n_updates"]), float(state["last_loss"])

    @property
    def size(self) -> int:
        """Real transitions stored."""
        return self._size

    def add(self, obs: ArrayLike, action: ArrayLike, next_obs: ArrayLike) -> None:
        """Store one real transition (s, a, s')."""
        self._inputs[self._pos, : self.obs_dim] = np.asarray(obs, dtype=np.float32).reshape(-1)
        self._inputs[self._pos, self.obs_dim :] = np.asarray(action, dtype=np.float32).reshape(-1)
        self._targets[self._pos] = np.asarray(next_obs, dtype=np.float32).reshape(-1)
        self._pos = (self._pos + 1) % len(self._inputs)
        self._size = min(self._size + 1, len(self._inputs))
        self._added += 1

    def observe(self, obs: ArrayLike, action: ArrayLike, next_obs: ArrayLike) -> float | None:
        """Store a real transition and take a gradient step when due; returns the loss if one was taken."""
        self.add(obs, action, next_obs)
        if self._added % self.train_every == 0:
            return self.train_step()
        return None

    def train_step(self) -> float:
        """One Adam step on a minibatch of stored transitions (MSE); returns the loss."""
        if self._size == 0:
            raise RuntimeError(
                "DynamicsModel.train_step needs at least one stored transition; call add first."
            )
        idx = self._rng.integers(0, self._size, size=min(self.batch_size, self._size))
        x = torch.from_numpy(self._inputs[idx])  # (B, obs_dim + act_dim)
        y = torch.from_numpy(self._targets[idx])  # (B, obs_dim)
        loss = nn.functional.mse_loss(self.net(x), y)
        self.optimizer.zero_grad(set_to_none=True)
        loss.backward()
        self.optimizer.step()
        self.n_updates += 1
        self.last_loss = float(loss.detach())
        return self.last_loss

    def fit(self, n_steps: int) -> float:
        """Several gradient steps (e.g. to pre-train on demonstrations); returns the last loss."""
        loss = float("nan")
        for _ in range(n_steps):
            loss = self.train_step()
        return loss

    @torch.no_grad()
    def predict(self, obs: ArrayLike, action: ArrayLike) -> np.ndarray:
        """Predicted next state (obs_dim,) float32 for one (s, a); with no training yet, s itself."""
        obs = np.asarray(obs, dtype=np.float32).reshape(-1)
        if self.n_updates == 0:
            return (
                obs.copy()
            )  # an untrained net's output is noise; "nothing happens" is the safer guess
        x = np.concatenate([obs, np.asarray(action, dtype=np.float32).reshape(-1)])
        return self.net(torch.from_numpy(x)[None]).numpy()[0]
