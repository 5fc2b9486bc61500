"""The DEFENDER chapter's parameters: :class:`Config` (its defaults are the smoke scale).

Read without importing the chapter (``thesis params``, ``thesis run``): this module imports no
torch and nothing else of the chapter; ``Config.__post_init__`` imports the strategy parser
and the agents' names when a ``Config`` is made.

Used in: DEFENDER chapter (thesis 4.3), ``notebooks/03_defender.ipynb``.
"""

from __future__ import annotations

from dataclasses import dataclass, field

CHAPTER = "03_defender"
"""The chapter's notebook name (``results/03_defender/``, ``studies/03_defender/``)."""

DEMO_SOURCES: tuple[str, ...] = ("sac", "expert", "auto")
"""Where :func:`make_demonstrations` takes demonstrations from: ``"sac"`` the thesis's recipe only
(SAC roll-outs during training; fails when a group gets none), ``"expert"`` the shipped expert
(TQC or ARS, :func:`~thesis_lib.defender.shipped_expert_label`) with action noise
(:func:`~thesis_lib.defender.expert_demonstrations`) only, ``"auto"`` SAC
roll-outs, and a group with fewer than needed topped up from the expert."""


@dataclass
class Config:
    """Parameters of ``notebooks/03_defender.ipynb`` (one field per notebook parameter).

    Defaults are the smoke scale (a few minutes on 2 CPU cores; ``params/03_defender.smoke.yml``
    also limits the ``paper_compat`` check to Hopper); ``params/03_defender.full.yml`` holds the
    thesis's (5,000 episodes x 3 seeds, 50 demonstrations, horizon 1000, 256-256 nets).
    """

    seed: int = 0
    """Seed of the demonstration run (and the chapter's other draws)."""
    seeds: list[int] = field(default_factory=lambda: [0])
    """Seeds of every training run in Tables 4.3-4.5 (the thesis: 3)."""
    tasks: list[str] = field(
        default_factory=lambda: ["Hopper-v5", "InvertedDoublePendulum-v5", "Walker2d-v5"]
    )
    """Gymnasium tasks (the thesis: Hopper, InvertedDoublePendulum, Walker2d)."""
    max_episode_steps: int | None = 100
    """Episode horizon; None = the task's own (1000, the thesis's)."""
    demo_timesteps: int = 4000
    """SAC training steps of the demonstration run."""
    demo_every: int = 1
    """Training episodes between two demonstration roll-outs."""
    demo_deterministic: bool = True
    """Roll out the policy's mean action (True) or sample it."""
    demo_source: str = "auto"
    """Where demonstrations come from, one of :data:`DEMO_SOURCES` ("sac" = the thesis's recipe
    only; "auto" = SAC roll-outs, a short group topped up from the shipped expert)."""
    n_demos: int = 10
    """Demonstrations per group in Tables 4.3-4.4 (the thesis: 50)."""
    n_demos_list: list[int] = field(default_factory=lambda: [3, 6, 10])
    """Demonstrations per group in Table 4.5 (the thesis: 10, 20, 50)."""
    algos: list[str] = field(default_factory=lambda: ["SAC", "TD3"])
    """Agents of Tables 4.3-4.4."""
    train_timesteps: int = 500
    """Environment steps per training run (used when ``train_episodes`` is None)."""
    train_episodes: int | None = None
    """Episodes per training run (the thesis: 5000); None = use ``train_timesteps``."""
    state_strategies: list[str] = field(default_factory=lambda: ["MeanDemoW5/MeanDemoW10"])
    """Safe/unsafe strategies run with state trajectories (Table 4.3)."""
    state_action_strategies: list[str] = field(default_factory=lambda: ["MeanBothW5/MeanBothW5"])
    """Safe/unsafe strategies run with state-action trajectories (Table 4.4)."""
    net_arch: list[int] = field(default_factory=lambda: [64, 64])
    """Hidden layers of actor and critics (the thesis: 256, 256)."""
    learning_rate: float = 1e-3
    """Adam learning rate of actor and critics (the thesis: 3e-4)."""
    max_trajectory: int | None = None
    """Cap of the agent's trajectory before each comparison; None = whole episode (the thesis's
    text), 20 = the authors' code."""
    paper_compat_check: bool = True
    """Also run the first state strategy with SAC and ``paper_compat=True`` (FastDTW radius 1,
    20-step cap, strict >, dynamics trained every step) to measure what the authors' code changes."""
    paper_compat_tasks: list[str] | None = None
    """Tasks of that check; None = the first of ``tasks`` only (FastDTW is slow); list them all
    to run it on every task."""
    batch_size: int = 256
    """Minibatch of the agents' updates (the thesis: 256)."""
    dynamics_train_every: int | None = None
    """One dynamics-model update every this many real steps; None = the wrapper's default (4,
    measured in ``benchmarks/bench_defender.py``; 1 = Algorithm 2 to the letter)."""
    n_jobs: int = 1
    """Processes for the ablation replay (training runs stay sequential so % Time is fair)."""
    algo_tasks: dict[str, list[str]] = field(default_factory=dict)
    """Tasks of an algorithm that runs on fewer than all ``tasks`` (e.g. ``{"TD3": ["Hopper-v5"]}``);
    empty: every algorithm on every task."""
    eval_episodes: int = 10
    """Study: evaluation episodes of each run's final policy, without the filter."""
    no_topup_tasks: list[str] = field(default_factory=list)
    """Study: tasks where SAC with the first state strategy also runs on the SAC roll-outs alone
    (no expert top-up), to measure what the top-up changes."""
    random_filter_rates: list[float] = field(default_factory=list)
    """Study: control arms, the first of ``algos`` with a filter that fires at random with each
    of these probabilities per step (:class:`~thesis_lib.defender.RandomFilter`, CLAIMS.md's
    control for C7), its reward from ``n_demos`` demonstrations per group. Empty: none (the
    v1 and v2 studies)."""
    random_filter_matched: bool = False
    """Study: a control arm, the first of ``algos`` with a filter that fires at random at the rate
    the first of ``state_strategies`` fired in the same seed's and task's run (its filtered
    episodes per training step, read from that run's finished record:
    :data:`~thesis_lib.chapters.defender.tasks.MATCHED_RANDOM_STRATEGY`). These runs come
    last in the study's order, after every run they match. False: none (v1-v3)."""
    timer_filter_matched: bool = False
    """Study: a control arm, the first of ``algos`` with a blind filter that ends the share of
    episodes the first of ``state_strategies`` ended in the same seed's and task's run, each at
    a step drawn from that filter's own firing steps (:class:`~thesis_lib.defender.TimerFilter`,
    :data:`~thesis_lib.chapters.defender.tasks.MATCHED_TIMER_STRATEGY`): a filter that fires
    at about the same step of every episode cuts crashes by its timing alone. These runs come
    last, after the random ones. False: none (v1-v5)."""

    def __post_init__(self) -> None:
        from thesis_lib.defender import parse_strategy  # lazy: torch
        from thesis_lib.rl import ALGOS  # lazy: torch

        for name in ("demo_timesteps", "demo_every", "n_demos", "train_timesteps", "batch_size"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or value < 1:
                raise ValueError(f"Config.{name} must be a positive int, got {value!r}.")
        for name in (
            "max_episode_steps",
            "train_episodes",
            "max_trajectory",
            "dynamics_train_every",
        ):
            value = getattr(self, name)
            if value is not None and (
                isinstance(value, bool) or not isinstance(value, int) or value < 1
            ):
                raise ValueError(f"Config.{name} must be a positive int or None, got {value!r}.")
        if not self.seeds or not self.tasks or not self.algos:
            raise ValueError("Config needs at least one seed, one task and one algo.")
        bad = [a for a in self.algos if a not in ALGOS]
        if bad:
            raise ValueError(f"Unknown algo {bad[0]!r} in Config.algos. Valid: {', '.join(ALGOS)}.")
        bad_rates = [r for r in self.random_filter_rates if not 0.0 < float(r) < 1.0]
        if bad_rates:
            raise ValueError(
                f"random_filter_rates must be probabilities in (0, 1), got {bad_rates[0]!r}."
            )
        if not self.n_demos_list or any(int(n) < 1 for n in self.n_demos_list):
            raise ValueError(f"n_demos_list must list positive counts, got {self.n_demos_list!r}.")
        for s in [*self.state_strategies, *self.state_action_strategies]:
            parse_strategy(s)  # raises with the valid names
        if self.demo_source not in DEMO_SOURCES:
            raise ValueError(
                f"Unknown demo_source {self.demo_source!r}. Valid: {', '.join(DEMO_SOURCES)}."
            )
        if isinstance(self.eval_episodes, bool) or not isinstance(self.eval_episodes, int):
            raise ValueError(f"Config.eval_episodes must be an int, got {self.eval_episodes!r}.")
        if self.eval_episodes < 1:
            raise ValueError(f"Config.eval_episodes must be >= 1, got {self.eval_episodes}.")
        for name, listed in (
            *((f"algo_tasks[{a!r}]", ts) for a, ts in self.algo_tasks.items()),
            ("no_topup_tasks", self.no_topup_tasks),
        ):
            bad = [t for t in listed if t not in self.tasks]
            if bad:
                raise ValueError(f"{name} lists {bad[0]!r}, which is not in tasks {self.tasks}.")
        bad = [a for a in self.algo_tasks if a not in self.algos]
        if bad:
            raise ValueError(f"algo_tasks names {bad[0]!r}, which is not in algos {self.algos}.")
        if self.paper_compat_tasks is not None:
            bad = [t for t in self.paper_compat_tasks if t not in self.tasks]
            if bad:
                raise ValueError(
                    f"paper_compat_tasks lists {bad[0]!r}, which is not in tasks {self.tasks}."
                )
