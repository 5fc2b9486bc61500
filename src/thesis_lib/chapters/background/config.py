"""The Background chapter's parameters: :class:`Config`, one field per parameter of
``notebooks/01_background.ipynb`` (defaults are the smoke scale).

Used in: Background chapter (thesis 2.2–2.8).
"""

from __future__ import annotations

from dataclasses import dataclass, field

__all__ = ["RL_ALGOS", "Config"]

RL_ALGOS: tuple[str, ...] = ("DDPG", "TD3", "SAC")
"""The algorithms of the learning curves (thesis 2.5–2.7)."""


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
        valid = RL_ALGOS
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
