"""`RLConfig`: one typed configuration for every SB3 off-policy run in the book.

Used in: Background (thesis 2.5-2.7), CLfD (4.2), DEFENDER (4.3).
"""

from __future__ import annotations

import difflib
import inspect
from dataclasses import dataclass, field
from typing import Any, Literal, get_args

Algo = Literal["SAC", "TD3", "DDPG"]
NoiseKind = Literal["auto", "normal", "ornstein-uhlenbeck"]

ALGOS: tuple[str, ...] = get_args(Algo)
NOISE_KINDS: tuple[str, ...] = get_args(NoiseKind)

# Exploration noise that `action_noise="auto"` resolves to. DDPG gets Ornstein-Uhlenbeck noise,
# as thesis Sec. 2.5 describes; TD3 gets Gaussian noise, as in the TD3 paper and the authors'
# DEFENDER code ("exploration 0.1"); SAC explores through its stochastic policy and gets none.
AUTO_NOISE: dict[str, str | None] = {"SAC": None, "TD3": "normal", "DDPG": "ornstein-uhlenbeck"}


def algo_class(algo: str) -> type[Any]:
    """The stable-baselines3 class for `algo` (imported lazily: SB3 imports torch)."""
    import stable_baselines3

    return getattr(stable_baselines3, algo)


def did_you_mean(name: str, valid: list[str] | tuple[str, ...]) -> str:
    """`` Did you mean: 'x'?`` for the closest of ``valid`` to ``name``, or ``""``.

    >>> did_you_mean("SAX", ["SAC", "TD3"])
    " Did you mean: 'SAC'?"
    """
    close = difflib.get_close_matches(name, valid, n=1)
    return f" Did you mean: {close[0]!r}?" if close else ""


@dataclass
class RLConfig:
    """Configuration of one off-policy training run (SB3's SAC, TD3 or DDPG).

    Field defaults are the thesis's hyper-parameters (DEFENDER, Sec. 4.3: learning rate 3e-4,
    batch 256, two hidden layers of 256, TD3 policy delay 2, target noise 0.2 clipped at 0.5,
    exploration noise 0.1). `SMOKE_DEFAULTS` in `thesis_lib.rl` holds the small CPU scale
    the book runs by default. Every choice is checked at construction.

    Used in: Background (thesis 2.5-2.7), CLfD (4.2), DEFENDER (4.3).

    Example:
        >>> RLConfig(algo="TD3", total_timesteps=1000).action_noise_resolved
        'normal'
        >>> RLConfig(algo="PPO")
        Traceback (most recent call last):
        ...
        ValueError: Unknown algo 'PPO'. Valid: SAC, TD3, DDPG.
    """

    algo: Algo = "SAC"
    """Which SB3 algorithm: "SAC", "TD3" or "DDPG" (thesis Secs. 2.7, 2.6, 2.5)."""
    env_id: str | None = "Pendulum-v1"
    """Gymnasium id passed to `gymnasium.make`; ignored when `train(env=...)` gets an env."""
    total_timesteps: int = 100_000
    """Environment steps to train for (summed over the `n_envs` parallel copies)."""
    seed: int = 0
    """Seeds torch, NumPy, Python's `random`, the action space and the env resets."""
    n_envs: int = 1
    """Number of env copies stepped together (a `DummyVecEnv`); only used with `env_id`."""
    learning_starts: int = 100
    """Steps of uniformly random actions before the first gradient step (SB3's default)."""
    net_arch: list[int] = field(default_factory=lambda: [256, 256])
    """Hidden layer widths of the actor and of each critic."""
    learning_rate: float = 3e-4
    """Adam learning rate of actor and critics."""
    buffer_size: int = 1_000_000
    """Replay buffer capacity in transitions."""
    batch_size: int = 256
    """Transitions per gradient step."""
    gamma: float = 0.99
    """Discount factor."""
    tau: float = 0.005
    """Target-network EMA rate: target <- (1 - tau) * target + tau * online (thesis rho = 1 - tau)."""
    train_freq: int = 1
    """Env steps (per env copy) between two rounds of gradient steps."""
    gradient_steps: int = 1
    """Gradient steps per round; -1 means as many as env steps were collected."""
    action_noise: NoiseKind | None = "auto"
    """Exploration noise added to TD3/DDPG actions: "normal", "ornstein-uhlenbeck", None, or
    "auto" (see `AUTO_NOISE`: OU for DDPG, normal for TD3, none for SAC)."""
    action_noise_sigma: float = 0.1
    """Standard deviation of the exploration noise, in units of the normalised action ([-1, 1])."""
    device: str = "auto"
    """Torch device: "auto" picks CUDA when present, else CPU."""
    extra: dict[str, Any] = field(default_factory=dict)
    """Further keyword arguments for the SB3 constructor (e.g. `ent_coef`, `policy_delay`), checked
    against the algorithm's signature. HER: `{"replay_buffer_class": HerReplayBuffer,
    "replay_buffer_kwargs": {"n_sampled_goal": 4, "goal_selection_strategy": "future"}}` on a
    goal env (its Dict observations select SB3's "MultiInputPolicy")."""

    action_noise_resolved: str | None = field(init=False)
    """`action_noise` with "auto" resolved for `algo` (derived, not settable)."""

    def __post_init__(self) -> None:
        if self.algo not in ALGOS:
            raise ValueError(
                f"Unknown algo {self.algo!r}.{did_you_mean(str(self.algo), ALGOS)} "
                f"Valid: {', '.join(ALGOS)}."
            )
        for name in ("total_timesteps", "n_envs", "batch_size", "buffer_size", "train_freq"):
            value = getattr(self, name)
            if not isinstance(value, int) or value <= 0:
                raise ValueError(f"RLConfig.{name} must be a positive int, got {value!r}.")
        if self.learning_starts < 0:
            raise ValueError(f"RLConfig.learning_starts must be >= 0, got {self.learning_starts}.")
        if self.gradient_steps == 0 or self.gradient_steps < -1:
            raise ValueError(
                f"RLConfig.gradient_steps must be a positive int or -1 (as many as env steps), "
                f"got {self.gradient_steps}."
            )
        if not self.net_arch or any(int(w) <= 0 for w in self.net_arch):
            raise ValueError(
                f"RLConfig.net_arch must list positive layer widths, got {self.net_arch!r}."
            )
        self.net_arch = [int(w) for w in self.net_arch]
        if not self.learning_rate > 0:
            raise ValueError(f"RLConfig.learning_rate must be > 0, got {self.learning_rate}.")
        if not 0.0 <= self.gamma <= 1.0 or not 0.0 < self.tau <= 1.0:
            raise ValueError(
                f"RLConfig needs 0 <= gamma <= 1 and 0 < tau <= 1, got gamma={self.gamma}, tau={self.tau}."
            )
        if self.action_noise is not None and self.action_noise not in NOISE_KINDS:
            raise ValueError(
                f"Unknown action_noise {self.action_noise!r}."
                f"{did_you_mean(str(self.action_noise), NOISE_KINDS)} "
                f"Valid: {', '.join(NOISE_KINDS)} or None."
            )
        if self.action_noise_sigma < 0:
            raise ValueError(
                f"RLConfig.action_noise_sigma must be >= 0, got {self.action_noise_sigma}."
            )
        auto = self.action_noise == "auto"
        self.action_noise_resolved = AUTO_NOISE[self.algo] if auto else self.action_noise
        self._check_extra()

    def _check_extra(self) -> None:
        """Reject `extra` keys the SB3 constructor would not accept, or that a field already sets."""
        owned = {
            "policy", "env", "seed", "learning_starts", "learning_rate", "buffer_size", "batch_size",
            "gamma", "tau", "train_freq", "gradient_steps", "action_noise", "device",
        }  # fmt: skip
        clash = sorted(owned & set(self.extra))
        if clash:
            raise ValueError(
                f"RLConfig.extra sets {clash}, which RLConfig fields own; set the field instead."
            )
        params = [
            p for p in inspect.signature(algo_class(self.algo).__init__).parameters if p != "self"
        ]
        for key in self.extra:
            if key not in params:
                raise ValueError(
                    f"RLConfig.extra has {key!r}, which {self.algo} does not accept."
                    f"{did_you_mean(key, params)} Valid: {', '.join(p for p in params if p not in owned)}."
                )

    def sb3_kwargs(self) -> dict[str, Any]:
        """Keyword arguments for the SB3 constructor, except `policy`, `env` and `action_noise`.

        `net_arch` is merged into `extra["policy_kwargs"]` when that is given.
        """
        extra = dict(self.extra)
        policy_kwargs = {"net_arch": list(self.net_arch), **extra.pop("policy_kwargs", {})}
        return dict(
            learning_rate=self.learning_rate,
            buffer_size=self.buffer_size,
            learning_starts=self.learning_starts,
            batch_size=self.batch_size,
            tau=self.tau,
            gamma=self.gamma,
            train_freq=self.train_freq,
            gradient_steps=self.gradient_steps,
            policy_kwargs=policy_kwargs,
            seed=self.seed,
            device=self.device,
            **extra,
        )
