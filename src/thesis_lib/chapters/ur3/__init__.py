"""The UR3 deployment chapter (thesis 5.2.5.4 and chapter 6; notebook ``07_ur3_deployment``).

* :class:`Config`: the notebook's parameters; defaults are the smoke scale.
* :func:`run_demonstrations`: the reaching demonstrations' statistics.
* :func:`run_table_5_4`: HDT and DT trained with 10, 20, ..., 80 demonstrations by the one
  offline runner (:func:`thesis_lib.seq.runner.run_offline`), each run from the 10 test starts
  for 200 steps, as a resumable sweep (``results/07_ur3_deployment/tasks``); one row per test
  start. :func:`summarize_table_5_4` gives the thesis's "mean ± std of goal positions reached",
  :func:`compare_table_5_4` puts it beside the thesis's, :func:`run_success_curves` gives the
  mean number of goals reached after each step.
* :func:`dance_angles`, :func:`run_dance_checks`: MDLT's dance on the arm, with the limit checks.
* ``plot_*``: Table 5.4, success curves, goals and a demonstration, sub-goals, the dance.

Used in: UR3 deployment chapter (Table 5.4, dance playback, 3-D viewer).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field
from functools import partial
from typing import Any, Literal

import numpy as np
import pandas as pd

from thesis_lib.seq.registry import LEGACY_INIT, ArchSpec, check_methods
from thesis_lib.seq.runner import EvalSpec, TrainSpec, run_offline

__all__ = [
    "METHODS",
    "Config",
    "compare_table_5_4",
    "dance_angles",
    "plot_dance",
    "plot_demo_subgoals",
    "plot_goals",
    "plot_success_curves",
    "plot_table_5_4",
    "reach_record",
    "reach_task",
    "run_reach",
    "run_dance_checks",
    "run_demonstrations",
    "run_success_curves",
    "run_table_5_4",
    "study_run",
    "study_table_5_4",
    "study_tasks",
    "summarize_table_5_4",
]

CHAPTER = "07_ur3_deployment"
METHODS: tuple[str, ...] = ("HDT", "DT")
"""The two methods of Table 5.4."""
N_DEMOS = 100
"""Demonstrations made: 80 train, 10 validation, 10 test starts (the thesis's split)."""
RTG_SCALE = 10.0
"""Returns-to-go divisor (returns are about -30 to -60 here, not thousands)."""
#: The columns of Table 5.4's runs (one row per test start).
RUN_COLUMNS = [
    "method",
    "train_demos",
    "seed",
    "start",
    "goals_reached",
    "steps",
    "reach_steps",
    "loss",
]


STUDY_FILE_DEFAULTS: dict[str, Any] = {"init": LEGACY_INIT}
"""What a study file that does not name these fields ran with (the v1 studies, registered
before the transformers' ``init`` existed): :func:`thesis_lib.book.study.study_config`."""


@dataclass
class Config:
    """The notebook's parameters (``params/07_ur3_deployment.*.yml``); defaults are the smoke scale.

    Used in: UR3 deployment chapter.
    """

    seed: int = 0
    """Seed of the demonstrations and of the stand-in dance."""
    seeds: list[int] = field(default_factory=lambda: [0])
    """Training seeds of Table 5.4."""
    train_demos: list[int] = field(default_factory=lambda: [10, 80])
    """Numbers of training demonstrations, the first n of the 80 (the thesis: 10, 20, ..., 80)."""
    methods: list[str] = field(default_factory=lambda: list(METHODS))
    """HDT and/or DT."""
    iterations: int = 1000
    """Training iterations per run (10k in the thesis)."""
    batch_size: int = 32
    """Windows per batch."""
    K: int = 20
    """Context length."""
    d_model: int = 32
    """Embedding size (128 in the thesis)."""
    n_layers: int = 1
    """GPT blocks (per HDT level; 3 in the thesis)."""
    n_heads: int = 1
    """Attention heads."""
    dropout: float = 0.0
    """Dropout (0.1 in the thesis; off at the smoke scale, where it slows the few hundred steps badly)."""
    lr: float = 0.001
    """Peak learning rate."""
    warmup_steps: int = 50
    """Warm-up steps."""
    max_eval_steps: int = 200
    """Steps per test episode (200 in the thesis)."""
    paper_compat: bool = False
    """The authors' behaviours in the sequence models (see the HDT chapter)."""
    dance_source: Literal["mdlt", "demo"] = "mdlt"
    """``"mdlt"``: the first sequence of MDLT's default AIST++-layout data set; ``"demo"``: a stand-in dance."""
    dance_seconds: float = 6.0
    """Seconds of dance to play."""
    dance_fps: int = 60
    """Frame rate of the dance angles (MDLT: 60)."""
    dance_mode: Literal["clip", "reject"] = "clip"
    """Limits: clip (clamp and rate-limit) or reject."""
    viewer_frames: int = 180
    """Frames stored in the 3-D viewer (subsampled)."""
    init: Literal["auto", "normal", "original", "torch"] = "auto"
    """Initialisation of the transformers (DT, HDT): ``auto`` (the authors' ``original`` with
    ``paper_compat``, else ``normal``: every Linear and Embedding N(0, 0.02), as CORL's and
    Hugging Face's DT) or ``torch`` (PyTorch's defaults, the v1 studies'; a study file that
    names no ``init`` ran with it)."""
    device: str = "cpu"
    """Training device."""
    progress: bool = False
    """Progress bars."""

    def __post_init__(self) -> None:
        for name in ("seeds", "train_demos", "methods"):
            value = getattr(self, name)
            if isinstance(value, str):
                raise ValueError(f"Expect `{name}` to be a list, got the string {value!r}.")
            setattr(self, name, list(value))
        check_methods(self.methods, METHODS)
        if self.dance_source not in ("mdlt", "demo"):
            raise ValueError(f"Unknown dance_source {self.dance_source!r}. Valid: mdlt, demo.")
        if self.dance_mode not in ("clip", "reject"):
            raise ValueError(f"Unknown dance_mode {self.dance_mode!r}. Valid: clip, reject.")
        n_train = N_DEMOS - 20
        bad = [n for n in self.train_demos if not 1 <= n <= n_train]
        if bad:
            raise ValueError(
                f"train_demos must lie in 1..{n_train} ({N_DEMOS} demonstrations - 10 validation - 10 test), got {bad}."
            )

    def arch(self) -> ArchSpec:
        """The :class:`~thesis_lib.seq.registry.ArchSpec` of both methods."""
        return ArchSpec(
            d_model=self.d_model,
            n_layers=self.n_layers,
            n_heads=self.n_heads,
            K=self.K,
            dropout=self.dropout,
            max_timestep=max(256, self.max_eval_steps + 1),
            paper_compat=self.paper_compat,
            init=self.init,
        )

    def train_spec(self, seed: int) -> TrainSpec:
        """The :class:`~thesis_lib.seq.runner.TrainSpec` of the run with ``seed`` (no evaluation
        during training)."""
        return TrainSpec(
            seed=seed,
            iterations=self.iterations,
            batch_size=self.batch_size,
            lr=self.lr,
            warmup_steps=self.warmup_steps,
            eval_every=0,
            rtg_scale=RTG_SCALE,
            device=self.device,
            progress=self.progress,
        )


def _demos(seed: int) -> Any:
    from thesis_lib.ur3.reach import get_reach_dataset, split_demonstrations

    return split_demonstrations(get_reach_dataset(N_DEMOS, seed).episodes)


def run_demonstrations(cfg: Config) -> pd.DataFrame:
    """The reaching data set in one row: demonstrations, steps, lengths, returns, all goals reached.

    Used in: UR3 deployment chapter.
    """
    from thesis_lib.ur3.reach import get_reach_dataset

    ds = get_reach_dataset(N_DEMOS, cfg.seed)
    lengths = np.array([len(e) for e in ds.episodes])
    return pd.DataFrame(
        [
            {
                "data set": ds.id,
                "demonstrations": len(ds),
                "steps": ds.n_transitions,
                "length mean": lengths.mean(),
                "length max": lengths.max(),
                "return mean": ds.returns.mean(),
                "return max": ds.returns.max(),
                "all goals reached": int(
                    sum(e.observations[-1, 6:].sum() == 5 for e in ds.episodes)
                ),
            }
        ]
    )


def reach_record(env: Any) -> dict[str, Any]:
    """What one test episode achieved, read from its ``UR3ReachEnv``: ``goals_reached, steps,
    reach_steps`` (the step each goal was reached, -1 if never, as text for CSV).

    Used in: UR3 deployment chapter (Table 5.4).
    """
    u = env.unwrapped
    done = u.completed
    rec = (
        done[0]
        if done
        else {"goals_reached": int(u.reached.sum()), "reach_steps": u.reach_steps, "steps": u.t}
    )
    return {
        "goals_reached": rec["goals_reached"],
        "steps": rec["steps"],
        "reach_steps": " ".join(str(int(s)) for s in rec["reach_steps"]),
    }


def run_reach(
    method: str,
    episodes: Any,
    test_starts: Any,
    arch: ArchSpec,
    train: TrainSpec,
    max_eval_steps: int = 200,
) -> list[dict[str, Any]]:
    """Train ``method`` on ``episodes`` and run it once from each of ``test_starts``.

    DT is evaluated at the training demonstrations' best return; the episodes' reset seed is
    the run's seed. Returns one row per test start: ``method, seed, start, goals_reached,
    steps, reach_steps, loss``.

    Used in: UR3 deployment chapter (Table 5.4).
    """
    import gymnasium as gym

    from thesis_lib.ur3.reach import UR3ReachEnv

    venv = gym.vector.SyncVectorEnv(
        [partial(UR3ReachEnv, start=s, max_steps=max_eval_steps) for s in test_starts]
    )

    def envs(n: int) -> Any:
        if n != len(test_starts):
            raise ValueError(
                f"Expect one environment per test start ({len(test_starts)}), asked {n}."
            )
        return venv

    try:
        rows = run_offline(
            method,
            episodes,
            arch,
            train,
            EvalSpec(
                episodes=len(test_starts),
                max_steps=max_eval_steps,
                targets=("max",),
                episode_seed="run",
            ),
            envs=envs,
            episode_info=reach_record,
        )
    finally:
        venv.close()
    return [r | {"start": r["episode"]} for r in rows]


def reach_task(config: dict[str, Any]) -> list[dict[str, Any]]:
    """One sweep task: train ``config["method"]`` on the first ``train_demos`` demonstrations
    and run it from every test start (:func:`run_reach`).

    ``config`` holds ``method, train_demos, data_seed, max_eval_steps`` and the ``arch`` and
    ``train`` specs as dicts. Returns :data:`RUN_COLUMNS` rows, one per test start.

    Used in: UR3 deployment chapter (Table 5.4).
    """
    demos = _demos(config["data_seed"])
    rows = run_reach(
        config["method"],
        demos.train[: config["train_demos"]],
        demos.test_starts,
        ArchSpec.from_task(config["arch"]),
        TrainSpec(**config["train"]),
        config["max_eval_steps"],
    )
    n = config["train_demos"]
    return [{k: (n if k == "train_demos" else r[k]) for k in RUN_COLUMNS} for r in rows]


def run_table_5_4(cfg: Config) -> pd.DataFrame:
    """Every demonstration count x method x seed of ``cfg``: one row per test start.

    A resumable sweep (store ``results/07_ur3_deployment/tasks``).

    Used in: UR3 deployment chapter (Table 5.4).
    """
    from thesis_lib.paths import results_dir
    from thesis_lib.sweep import Task, run_tasks

    arch = cfg.arch().task_dict()
    tasks = [
        Task(
            reach_task,
            {
                "method": m,
                "train_demos": n,
                "data_seed": cfg.seed,
                "max_eval_steps": cfg.max_eval_steps,
                "arch": arch,
                "train": asdict(cfg.train_spec(s)),
            },
        )
        for n in cfg.train_demos
        for m in cfg.methods
        for s in cfg.seeds
    ]
    rows = run_tasks(
        tasks, store=results_dir(CHAPTER) / "tasks", desc="Table 5.4", progress=cfg.progress
    )
    return rows.drop(columns="task_key").reset_index(drop=True)


def summarize_table_5_4(rows: pd.DataFrame) -> pd.DataFrame:
    """Mean and std (over test starts and seeds) of the goals reached per method and count.

    Used in: UR3 deployment chapter (Table 5.4).

    Returns:
        Columns ``method, train_demos, goals_mean, goals_std, all_five`` (share of test
        episodes that reached all goals), ``n_episodes``, as the reference ``table_5_4.csv``.
    """
    g = rows.groupby(["method", "train_demos"], sort=False)["goals_reached"]
    n_goals = 5
    out = pd.DataFrame({
        "goals_mean": g.mean(),
        "goals_std": g.std(ddof=0),
        "all_five": g.apply(lambda x: float(np.mean(x >= n_goals))),
        "n_episodes": g.size(),
    }).reset_index()  # fmt: skip
    return out


def run_success_curves(rows: pd.DataFrame, horizon: int = 200) -> pd.DataFrame:
    """Mean number of goals reached by each step ``0..horizon``, per method and count.

    Used in: UR3 deployment chapter (success over the test steps).

    Returns:
        Long table ``method, train_demos, step, goals_mean``.
    """
    out = []
    steps = np.arange(horizon + 1)
    for (m, n), g in rows.groupby(["method", "train_demos"], sort=False):
        reach = np.array(
            [[int(x) for x in s.split()] for s in g["reach_steps"]]
        )  # (episodes, goals)
        hit = (reach[:, :, None] >= 0) & (reach[:, :, None] <= steps[None, None, :])
        mean = hit.sum(axis=1).mean(axis=0)
        out.append(pd.DataFrame({"method": m, "train_demos": n, "step": steps, "goals_mean": mean}))
    return pd.concat(out, ignore_index=True)


def dance_angles(
    source: str = "mdlt", seconds: float = 6.0, fps: int = 60, seed: int = 0
) -> tuple[np.ndarray, str]:
    """``(T, 4)`` dance angles and where they came from.

    ``"mdlt"``: the choreography of the first sequence of MDLT's default data set in the AIST++
    layout (:func:`thesis_lib.mdlt.synth.default_dataset`, read by
    :func:`thesis_lib.mdlt.readers.load_aist`), the same angles MDLT learns to generate;
    ``"demo"``: :func:`thesis_lib.ur3.dance.demo_angles`.

    Used in: UR3 deployment chapter.
    """
    from thesis_lib.ur3.dance import demo_angles

    if source == "demo":
        return demo_angles(
            seconds, fps, seed=seed
        ), f"stand-in dance (thesis_lib.ur3.dance.demo_angles, seed {seed})"
    if source != "mdlt":
        raise ValueError(f"Unknown dance source {source!r}. Valid: mdlt, demo.")
    from thesis_lib.mdlt import readers, synth

    root = synth.default_dataset("aist", "smoke", seed=seed, progress=False)
    genre = readers.AIST_GENRES[0] if hasattr(readers, "AIST_GENRES") else None
    seqs = readers.load_aist(root, genres=[genre] if genre else None, progress=False)
    s = seqs[0]
    if int(s.fps) != int(fps):
        raise ValueError(f"MDLT sequence {s.name} is at {s.fps} fps, the chapter asked for {fps}.")
    n = min(len(s.angles), int(round(seconds * fps)))
    return np.asarray(
        s.angles[:n], dtype=np.float64
    ), f"MDLT default data set (AIST++ layout), sequence {s.name}"


def compare_table_5_4(ours: pd.DataFrame, differs: dict[str, str]) -> pd.DataFrame:
    """Our Table 5.4 beside the thesis's, mean and std of goals reached, with what differs."""
    from thesis_lib.book import compare_with_paper

    mean = compare_with_paper(
        "5.4", ours, on=["method", "train_demos"], value="goals_mean", differs=differs
    )
    std = compare_with_paper("5.4", ours, on=["method", "train_demos"], value="goals_std")
    out = mean.rename(columns={"paper": "paper_mean", "ours": "ours_mean"})
    out.insert(out.columns.get_loc("difference"), "paper_std", std["paper"].to_numpy())
    out.insert(out.columns.get_loc("difference"), "ours_std", std["ours"].to_numpy())
    return out


def plot_table_5_4(ours: pd.DataFrame, ax=None):
    """Goals reached vs. training demonstrations: ours (solid, ± std) and the thesis's (dashed)."""
    import matplotlib.pyplot as plt

    from thesis_lib.book import load_reference

    if ax is None:
        fig, ax = plt.subplots(figsize=(6.5, 4))
    else:
        fig = ax.figure
    paper = load_reference("5.4")
    colors = {"HDT": "tab:green", "DT": "tab:blue"}
    for m, g in paper.groupby("method", sort=False):
        ax.plot(
            g.train_demos,
            g.goals_mean,
            "--",
            color=colors.get(m),
            alpha=0.6,
            label=f"{m} (thesis, real UR3)",
        )
    for m, g in ours.groupby("method", sort=False):
        g = g.sort_values("train_demos")
        ax.errorbar(
            g.train_demos,
            g.goals_mean,
            yerr=g.goals_std,
            fmt="-o",
            capsize=3,
            color=colors.get(m),
            label=f"{m} (ours, simulation)",
        )
    ax.set_xlabel("training demonstrations")
    ax.set_ylabel("goal positions reached (of 5)")
    ax.set_ylim(-0.2, 5.5)
    ax.legend(fontsize=8)
    ax.set_title("Table 5.4: UR3 reaching within 200 steps")
    return fig


def plot_success_curves(curves: pd.DataFrame, ax=None):
    """Mean goals reached by each step of the test episodes, per method and demonstration count."""
    import matplotlib.pyplot as plt

    if ax is None:
        fig, ax = plt.subplots(figsize=(6.5, 4))
    else:
        fig = ax.figure
    styles = {"HDT": "-", "DT": "--"}
    counts = sorted(curves.train_demos.unique())
    cmap = plt.get_cmap("viridis")
    for (m, n), g in curves.groupby(["method", "train_demos"], sort=False):
        c = cmap(counts.index(n) / max(1, len(counts) - 1))
        ax.plot(g.step, g.goals_mean, styles.get(m, "-"), color=c, label=f"{m}, {n} demos")
    ax.set_xlabel("step of the test episode")
    ax.set_ylabel("goals reached so far (mean)")
    ax.set_ylim(-0.2, 5.2)
    ax.legend(fontsize=7, ncol=2)
    ax.set_title("Reaching success over the 200 test steps")
    return fig


def plot_goals(demo, ax=None):
    """The goals and one demonstration's tool path in 3-D (forward kinematics)."""
    import matplotlib.pyplot as plt

    from thesis_lib.ur3.model import UR3Kinematics
    from thesis_lib.ur3.reach import GOALS
    from thesis_lib.ur3.render import plot_arm

    if ax is None:
        fig = plt.figure(figsize=(6, 5))
        ax = fig.add_subplot(projection="3d")
    else:
        fig = ax.figure
    kin = UR3Kinematics()
    for k, g in enumerate(GOALS):
        plot_arm(ax, g, color="0.6", alpha=0.5, kin=kin)
        p = kin.tcp(g)
        ax.text(*p, f" G{k + 1}", fontsize=8)
    path = np.array([kin.tcp(o[:6]) for o in demo.observations])
    ax.plot(
        path[:, 0],
        path[:, 1],
        path[:, 2],
        color="tab:red",
        lw=1.5,
        label="tool path of a demonstration",
    )
    plot_arm(ax, demo.observations[0][:6], color="tab:blue", label="start", kin=kin)
    ax.set_xlim(-0.5, 0.5), ax.set_ylim(-0.5, 0.5), ax.set_zlim(0, 0.7)
    ax.set_xlabel("x (m)"), ax.set_ylabel("y (m)"), ax.set_zlabel("z (m)")
    ax.legend(fontsize=8)
    return fig


def plot_dance(angles: np.ndarray, playback, fps: float):
    """MDLT's four angles and the UR3 joints actually played (after the limit checks), over time."""
    import matplotlib.pyplot as plt

    from thesis_lib.ur3.dance import map_dance

    mapped = map_dance(angles)
    t = np.arange(len(angles)) / fps
    fig, axes = plt.subplots(2, 2, figsize=(11, 5), sharex=True)
    names = ("shoulder pan (j1)", "shoulder lift (j2)", "elbow (j3)", "wrist 1 (j4)")
    for j, ax in enumerate(axes.flat):
        ax.plot(t, mapped[:, j], color="0.6", label="mapped MDLT angle")
        ax.plot(t, playback.q[:, j], color="tab:red", lw=1, label=f"played ({playback.mode})")
        ax.set_title(names[j], fontsize=9)
        ax.set_ylabel("rad")
    for ax in axes[1]:
        ax.set_xlabel("s")
    axes[0, 0].legend(fontsize=8)
    fig.tight_layout()
    return fig


def run_dance_checks(playback: Any) -> pd.DataFrame:
    """The limit checks of the mapped dance and of what is played: counts, peak speed, lowest tool.

    Used in: UR3 deployment chapter (dance playback).
    """
    return pd.DataFrame(
        [
            {
                "trajectory": name,
                **report.counts(),
                "peak speed / allowed": report.max_speed_ratio,
                "lowest tool z (m)": report.min_tcp_z,
            }
            for name, report in (
                ("mapped dance angles", playback.before),
                (f"played ({playback.mode})", playback.after),
            )
        ]
    )


def plot_demo_subgoals(episode: Any, ax: Any = None) -> tuple[Any, list[int], list[int]]:
    """One demonstration's rewards with its sub-goal states (green) and goals reached (red).

    Returns:
        ``(figure, sub-goal states, steps where a goal was reached)``.

    Used in: UR3 deployment chapter (sub-goals on the reaching task).
    """
    import matplotlib.pyplot as plt

    from thesis_lib.seq.subgoals import select_subgoal_indices

    if ax is None:
        fig, ax = plt.subplots(figsize=(8, 3))
    else:
        fig = ax.figure
    idx = select_subgoal_indices(episode.rewards)
    reached_at = np.flatnonzero(np.diff(episode.observations[:, 6:].sum(axis=1))) + 1
    ax.plot(episode.rewards, label="reward")
    for j in np.unique(idx):
        ax.axvline(j, color="tab:green", ls="--", lw=1)
    for j in reached_at:
        ax.plot(j, 0, "rv")
    ax.set_xlabel("step"), ax.set_ylabel("reward")
    ax.set_title("one demonstration: sub-goal states (green) and goals reached (red)")
    return fig, np.unique(idx).tolist(), reached_at.tolist()


# ------------------------------------------------------------------------------------ the study

#: The columns of a study run's row (:func:`study_run`); the study engine checks the study
#: file's metrics against them.
STUDY_COLUMNS = [
    "method", "setting", "train_demos", "seed", "scale", "goals_mean", "goals_std", "all_five",
    "episodes",
]  # fmt: skip


def study_run(config: dict[str, Any]) -> list[dict[str, Any]]:
    """One C14 study task: :func:`reach_task` reduced to one row per run.

    Returns ``method, setting ("<n> demos"), train_demos, seed, scale, goals_mean`` (goals
    reached, mean over the 10 test starts; the primary metric), ``goals_std``, ``all_five``
    (share of test starts that reached all five goals) and ``episodes``.

    Used in: ``thesis study 07_ur3_deployment`` (C14).
    """
    import torch

    torch.set_num_threads(1)  # small models: one core per run
    rows = pd.DataFrame(reach_task({k: v for k, v in config.items() if k != "scale"}))
    goals = rows["goals_reached"].to_numpy(dtype=float)
    n = int(config["train_demos"])
    return [
        {
            "method": config["method"],
            "setting": f"{n} demos",
            "train_demos": n,
            "seed": int(config["train"]["seed"]),
            "scale": config.get("scale", "study"),
            "goals_mean": float(goals.mean()),
            "goals_std": float(goals.std()),
            "all_five": float(np.mean(goals >= 5)),
            "episodes": len(goals),
        }
    ]


def study_tasks(cfg: Config) -> list[Any]:
    """The tasks of the chapter's pre-registered study (``params/07_ur3_deployment.study.yml``):
    every demonstration count x method x seed of ``cfg``, one row per run (:func:`study_run`).

    Used in: ``thesis study 07_ur3_deployment`` (C14).
    """
    from thesis_lib.sweep import Task

    arch = cfg.arch().task_dict()
    return [
        Task(
            study_run,
            {
                "method": m,
                "train_demos": n,
                "data_seed": cfg.seed,
                "max_eval_steps": cfg.max_eval_steps,
                "arch": arch,
                "train": asdict(cfg.train_spec(s)) | {"progress": False},
            },
        )
        for n in cfg.train_demos
        for s in cfg.seeds
        for m in cfg.methods
    ]


def study_table_5_4(rows: pd.DataFrame) -> pd.DataFrame:
    """The study's runs as Table 5.4 (mean and std of goals reached over every test start of
    every seed), for :func:`compare_table_5_4`.

    Used in: UR3 deployment chapter ("Evidence at study scale").
    """
    if rows.empty:
        return pd.DataFrame(columns=["method", "train_demos", "goals_mean", "goals_std"])
    g = rows.groupby(["method", "train_demos"], sort=False)
    # pooled over test starts: the mean of the run means; the std from the runs' moments
    mean = g["goals_mean"].mean()
    second = g.apply(lambda x: float(np.mean(x["goals_std"] ** 2 + x["goals_mean"] ** 2)))
    out = pd.DataFrame({
        "goals_mean": mean,
        "goals_std": np.sqrt(np.maximum(second - mean**2, 0.0)),
        "all_five": g["all_five"].mean(),
        "n_seeds": g["seed"].nunique(),
    }).reset_index()  # fmt: skip
    return out
