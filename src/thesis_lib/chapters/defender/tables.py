"""The DEFENDER chapter's tables: summaries of its rows and comparisons with the thesis.

``summarize_*`` reduce rows (training runs, ablation scores, study rows) to a table,
``compare_*`` set a table beside the thesis's (Tables 4.3-4.5), ``describe_*`` narrate a table
in sentences.

Used in: DEFENDER chapter (thesis 4.3).
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from thesis_lib.book import compare_with_paper
from thesis_lib.chapters.defender.config import Config
from thesis_lib.chapters.defender.demos import thesis_env_name
from thesis_lib.chapters.defender.tasks import RUN_COLUMNS
from thesis_lib.defender import (
    METHODS,
    THESIS_STATE_ACTION_STRATEGIES,
    THESIS_STATE_STRATEGIES,
    DemoRun,
    parse_method,
    parse_strategy,
    shipped_expert_label,
)
from thesis_lib.defender.ablation import rank_strategies
from thesis_lib.stats import mean_interval


def scale_note(cfg: Config) -> str:
    """The run's scale in one line (the "what differs" note of every comparison)."""
    return (
        f"{', '.join(cfg.tasks)}, horizon {cfg.max_episode_steps or 1000}, "
        f"{cfg.train_episodes or cfg.train_timesteps} "
        f"{'episodes' if cfg.train_episodes else 'steps'} per run, "
        f"{len(cfg.seeds)} seed(s), {cfg.n_demos} demos per group, nets {cfg.net_arch}"
    )


def methods_table() -> pd.DataFrame:
    """The 24 comparison methods: aggregation, windowing, the trajectory's and the
    demonstration's side of the comparison, and whether the cost updates incrementally.

    Used in: DEFENDER chapter (thesis 4.3.1).
    """
    rows = []
    for m in METHODS:
        p = parse_method(m)
        rows.append(
            {
                "method": m,
                "aggregation": p.aggregation,
                "windowing": p.windowing_name,
                "trajectory side": f"last {p.x_window}" if p.x_window else "all",
                "demonstration side": {"Same": "last L (L = trajectory length)", "Full": "all"}.get(
                    p.windowing, f"last {p.y_window(0)}" if p.y_window(0) else "all"
                ),
                "incremental": p.incremental,
            }
        )
    return pd.DataFrame(rows)


def summarize_demonstrations(demo_runs: dict[str, DemoRun], cfg: Config) -> pd.DataFrame:
    """Per task and group: SAC roll-outs seen, demonstrations kept and where they came from.

    Used in: DEFENDER chapter (thesis 4.3).
    """
    rows = []
    for task, run in demo_runs.items():
        src = run.sources()
        for group in ("safe", "unsafe"):
            kept = getattr(run.demos, group)
            n_seen = run.n_sac.get(group, len(getattr(run.pool, group)))
            rows.append(
                {
                    "task": task,
                    "group": group,
                    "SAC roll-outs seen": n_seen,
                    "kept": len(kept),
                    "kept from SAC roll-outs": src[group][0],
                    "kept from the expert": src[group][1],
                    "recipe": _recipe(src[group], task),
                    "mean length": float(np.mean([d.length for d in kept])) if kept else np.nan,
                    "lowest step reward": min(float(d.rewards.min()) for d in kept)
                    if kept
                    else np.nan,
                }
            )
    return pd.DataFrame(rows)


def _recipe(counts: tuple[int, int], task: str) -> str:
    n_sac, n_expert = counts
    if n_expert == 0:
        return "SAC roll-outs (thesis)"
    if n_sac == 0:
        return f"{shipped_expert_label(task)} + noise"
    return f"SAC roll-outs, topped up from {shipped_expert_label(task)}"


def describe_demonstrations(demo_runs: dict[str, DemoRun], cfg: Config) -> list[str]:
    """One sentence per task: which recipe each group used and why.

    Used in: DEFENDER chapter (thesis 4.3), so the narration follows the run.
    """
    n = max(cfg.n_demos, *cfg.n_demos_list)
    lines = []
    for task, run in demo_runs.items():
        src = run.sources()
        parts = []
        for group, what in (("safe", "reached the horizon"), ("unsafe", "fell before it")):
            seen = run.n_sac.get(group, len(getattr(run.pool, group)))
            n_sac, n_exp = src[group]
            if n_exp == 0:
                parts.append(
                    f"{group}: {n_sac} SAC roll-outs (the thesis's recipe; {seen} of them {what})"
                )
            elif cfg.demo_source == "expert":
                parts.append(
                    f"{group}: {n_exp} from the {shipped_expert_label(task)} with noise "
                    "(demo_source='expert')"
                )
            else:
                got = f"only {seen} SAC roll-out(s) {what}" if seen else f"no SAC roll-out {what}"
                parts.append(
                    f"{group}: {got} in {cfg.demo_timesteps} training steps, "
                    f"fewer than the {n} needed, so {n_exp} came from the shipped "
                    f"{shipped_expert_label(task)} "
                    f"({'small' if group == 'safe' else 'heavy'} action noise)"
                )
        lines.append(f"{thesis_env_name(task)}: " + "; ".join(parts) + ".")
    return lines


def summarize_top_strategies(scores: pd.DataFrame, top: int = 5) -> pd.DataFrame:
    """The ``top`` strategies per trajectory kind, ranked by the score averaged over tasks."""
    return rank_strategies(scores, top=top, by=("trajectory",))


def compare_thesis_strategies(scores: pd.DataFrame) -> pd.DataFrame:
    """Where the thesis's top-5 strategies (Tables 4.3-4.4) land in our ablation.

    Returns:
        One row per thesis strategy: ``trajectory``, ``thesis strategy`` (as printed), ``score``,
        ``kept_fraction``, ``crashes_stopped`` (averaged over tasks) and ``our rank`` among 576.

    Used in: DEFENDER chapter (thesis 4.3.2).
    """
    cols = ["score", "kept_fraction", "crashes_stopped"]
    mean = scores.groupby(["trajectory", "strategy"])[cols].mean()
    mean["our rank"] = mean.groupby(level=0)["score"].rank(ascending=False, method="min")
    rows = []
    for kind, printed in (
        ("state", THESIS_STATE_STRATEGIES),
        ("state_action", THESIS_STATE_ACTION_STRATEGIES),
    ):
        for label in printed:
            key = (kind, parse_strategy(label).name)
            if key in mean.index:
                rows.append(
                    {"trajectory": kind, "thesis strategy": label, **mean.loc[key].to_dict()}
                )
    out = pd.DataFrame(rows, columns=["trajectory", "thesis strategy", *cols, "our rank"])
    out["our rank"] = out["our rank"].astype(int)
    return out


def compare_top_strategies(top: pd.DataFrame) -> pd.DataFrame:
    """Our top 5 per trajectory kind (:func:`summarize_top_strategies`) beside the thesis's Tables 4.3-4.4."""
    thesis_top = pd.DataFrame(
        {
            "rank": range(1, 6),
            "state (Table 4.3)": THESIS_STATE_STRATEGIES,
            "state-action (Table 4.4)": THESIS_STATE_ACTION_STRATEGIES,
        }
    )
    side = (
        top.pivot(index="rank", columns="trajectory", values="strategy")
        .rename(columns={"state": "state (ours)", "state_action": "state-action (ours)"})
        .reset_index()
    )
    return side.merge(thesis_top, on="rank")


def summarize_runs(runs: pd.DataFrame) -> pd.DataFrame:
    """Mean ± std over seeds, and % Time relative to the plain algorithm (thesis Tables 4.3-4.5).

    Returns:
        One row per (task, algo, trajectory, strategy, n_demos, paper_compat) with
        ``acc_reward_mean/std``, ``crash_pct_mean/std``, ``filtered_pct``, ``mean_last_100``,
        ``time_pct`` (100 x wall time / the same algorithm's plain run on the same task and seed,
        averaged over seeds) and ``n_seeds``.

    Used in: DEFENDER chapter (thesis 4.3.3).
    """
    r = runs.copy()
    base = r[r.strategy == "none"].set_index(["task", "algo", "seed"])["wall_time_s"]
    idx = pd.MultiIndex.from_frame(r[["task", "algo", "seed"]])
    r["time_pct"] = 100 * r["wall_time_s"].to_numpy() / base.reindex(idx).to_numpy()
    keys = [
        "task",
        "algo",
        "trajectory",
        "strategy",
        "safe_strategy",
        "unsafe_strategy",
        "n_demos",
        "paper_compat",
    ]
    g = r.groupby(keys, dropna=False, sort=False)
    out = g.agg(
        acc_reward_mean=("acc_reward", "mean"),
        acc_reward_std=("acc_reward", "std"),
        crash_pct_mean=("crash_pct", "mean"),
        crash_pct_std=("crash_pct", "std"),
        filtered_pct=("filtered_pct", "mean"),
        mean_last_100=("mean_last_100", "mean"),
        time_pct=("time_pct", "mean"),
        n_seeds=("seed", "nunique"),
    ).reset_index()
    return out


def compare_tables_4_3_4_4(
    summary: pd.DataFrame, differs: dict[str, str] | None = None
) -> pd.DataFrame:
    """Tables 4.3 and 4.4 beside the thesis: Acc Reward, % Crash and % Time per row.

    Returns:
        ``compare_with_paper`` rows with extra columns ``table`` and ``metric``.

    Used in: DEFENDER chapter (thesis 4.3.3).
    """
    s = summary[~summary.paper_compat.astype(bool)].copy()
    s["env"] = s.task.map(thesis_env_name)
    s["algorithm"] = s.algo
    frames = []
    for table, kind in (("4.3", "state"), ("4.4", "state_action")):
        part = s[s.trajectory.isin(["none", kind])].copy()
        for col in ("safe_strategy", "unsafe_strategy"):
            part[col] = part[col].where(part.strategy != "none", np.nan)
        for metric, ours, paper in (
            ("Acc Reward", "acc_reward_mean", "acc_reward_mean"),
            ("% Crash", "crash_pct_mean", "crash_pct_mean"),
            ("% Time", "time_pct", "time_pct"),
        ):
            cmp = compare_with_paper(
                "4_3_4_4",
                part,
                on=["algorithm", "safe_strategy", "unsafe_strategy", "env"],
                value=ours,
                paper_value=paper,
                differs=differs,
                where={"table": table},
            )
            cmp.insert(0, "metric", metric)
            cmp.insert(0, "table", table)
            frames.append(cmp)
    return pd.concat(frames, ignore_index=True)


def compare_table_4_5(summary: pd.DataFrame, differs: dict[str, str] | None = None) -> pd.DataFrame:
    """Table 4.5 beside the thesis (Acc Reward and % Crash per number of demonstrations).

    Our demonstration counts are matched to the thesis's by rank (smallest to 10, ...), since the
    smoke scale uses fewer; the ``n_demos`` column keeps ours.
    """
    s = summary.copy()
    s["env"] = s.task.map(thesis_env_name)
    thesis_ns = [10, 20, 50]
    ours_ns = sorted(s.n_demos.unique())
    rank = {n: thesis_ns[i] if i < len(thesis_ns) else n for i, n in enumerate(ours_ns)}
    s["n_demos_ours"] = s.n_demos
    s["n_demos"] = s.n_demos.map(rank)
    frames = []
    for metric, col in (("Acc Reward", "acc_reward_mean"), ("% Crash", "crash_pct_mean")):
        cmp = compare_with_paper("4.5", s, on=["n_demos", "env"], value=col, differs=differs)
        cmp.insert(0, "metric", metric)
        frames.append(cmp)
    out = pd.concat(frames, ignore_index=True)
    back = {str(v): k for k, v in rank.items()}
    out.insert(2, "n_demos_ours", out.n_demos.map(back))
    return out


def describe_effects(summary: pd.DataFrame) -> list[str]:
    """One sentence per DEFENDER run group: crash rate, filtered share and best return vs the plain agent.

    Used in: DEFENDER chapter (thesis 4.3.3), so the narration follows the numbers of each run.
    """
    base = summary[summary.strategy == "none"].set_index(["task", "algo"])
    lines = []
    for _, r in summary[summary.strategy != "none"].iterrows():
        if (r.task, r.algo) not in base.index:
            continue
        b = base.loc[(r.task, r.algo)]
        setting = f"{r.trajectory}" + (", paper_compat" if r.paper_compat else "")
        lines.append(
            f"{thesis_env_name(r.task)} {r.algo} with {r.strategy} ({setting}): crashed episodes "
            f"{b.crash_pct_mean:.0f}% -> {r.crash_pct_mean:.0f}%, {r.filtered_pct:.0f}% of episodes ended by "
            f"the filter, best return {b.acc_reward_mean:.0f} -> {r.acc_reward_mean:.0f}, "
            f"time {r.time_pct:.0f}% of the plain run."
            + (
                " The filter never fired, so the agent saw exactly the plain run's episodes (same seed); "
                "only the time differs."
                if r.filtered_pct == 0
                else ""
            )
        )
    return lines


def summarize_paper_compat_effect(cfg: Config, summary: pd.DataFrame) -> pd.DataFrame:
    """SAC with the first state strategy, default and ``paper_compat=True``, on the tasks of the
    check: Acc Reward, % Crash, % filtered and % Time side by side.

    Used in: DEFENDER chapter (thesis 4.3.3, the authors' setting).
    """
    pc = summary[
        (summary.algo == "SAC")
        & (summary.strategy == cfg.state_strategies[0])
        & (summary.trajectory == "state")
    ]
    pc = pc[pc.task.isin(pc[pc.paper_compat.astype(bool)].task)]  # the tasks of the check
    cols = ["task", "strategy", "paper_compat", "acc_reward_mean", "crash_pct_mean"]
    return pc[[*cols, "filtered_pct", "time_pct"]]


def summarize_study(rows: pd.DataFrame) -> pd.DataFrame:
    """Study rows (one per run) as :func:`summarize_runs` output (``time_pct``: wall time in % of
    the plain agent's on the same task and seed), with the final evaluation and the CPU time
    (``cpu_s``, ``cpu_pct`` likewise) beside, so that :func:`compare_tables_4_3_4_4` and :func:`compare_table_4_5` set the thesis's tables beside
    them. Runs without the expert top-up are left out (they repeat a method's keys).

    Used in: DEFENDER chapter ("Evidence at study scale").
    """
    keep = rows[rows["top_up"].fillna(True).astype(bool)] if "top_up" in rows else rows
    if keep.empty:
        return summarize_runs(pd.DataFrame(columns=list(RUN_COLUMNS)))
    out = summarize_runs(keep[list(RUN_COLUMNS)])
    keys = ["task", "algo", "trajectory", "strategy", "n_demos"]
    plain = keep[keep.strategy == "none"].set_index(["task", "algo", "seed"])["train_cpu_s"]
    idx = pd.MultiIndex.from_frame(keep[["task", "algo", "seed"]])
    keep = keep.assign(cpu_pct=100 * keep["train_cpu_s"].to_numpy() / plain.reindex(idx).to_numpy())
    ev = keep.groupby(keys, sort=False).agg(
        eval_return_mean=("eval_return", "mean"),
        eval_return_std=("eval_return", "std"),
        eval_crash_rate=("eval_crash_rate", "mean"),
        cpu_s=("train_cpu_s", "mean"),
        cpu_pct=("cpu_pct", "mean"),
    )
    return out.merge(ev.reset_index(), on=keys, how="left")


def summarize_study_curves(rows: pd.DataFrame, reps: int = 1000) -> pd.DataFrame:
    """The per-span curves of the study rows (:func:`training_run_numbers`) in long form: per
    method, setting and span, the mean over seeds of the crash rate, filtered rate and return,
    each with a 95% bootstrap interval over seeds.

    Returns:
        Columns ``method, setting, span, step`` (the span's end, environment steps),
        ``measure`` (``crash_rate``, ``filtered_rate``, ``return``), ``mean``, ``ci_low``,
        ``ci_high``, ``seeds``.

    Used in: DEFENDER chapter ("Evidence at study scale").
    """
    cols = ["method", "setting", "span", "step", "measure", "mean", "ci_low", "ci_high", "seeds"]
    spans = sorted(int(c.rsplit("_b", 1)[1]) for c in rows.columns if c.startswith("crash_rate_b"))
    if rows.empty or not spans:
        return pd.DataFrame(columns=cols)
    out = []
    for (method, setting), g in rows.groupby(["method", "setting"], sort=False):
        steps = float(g["steps"].mean())
        for b in spans:
            for measure in ("crash_rate", "filtered_rate", "return"):
                v = g[f"{measure}_b{b}"].dropna().to_numpy(dtype=float)
                m, lo, hi = mean_interval(v, reps=reps)
                out.append(
                    {
                        "method": method,
                        "setting": setting,
                        "span": b,
                        "step": steps * (b + 1) / len(spans),
                        "measure": measure,
                        "mean": m,
                        "ci_low": lo,
                        "ci_high": hi,
                        "seeds": len(v),
                    }
                )
    return pd.DataFrame(out, columns=cols)


def summarize_study_topup(rows: pd.DataFrame) -> pd.DataFrame:
    """What the expert top-up changes: per setting, the first state strategy with the topped-up
    demonstrations and on the SAC roll-outs alone, mean over seeds of the crash rate, filtered
    rate, evaluation return and the demonstrations' sources.

    Used in: DEFENDER chapter ("Evidence at study scale").
    """
    cols = [
        "setting", "method", "seeds", "crash_rate", "filtered_rate", "eval_return",
        "demos_safe", "demos_safe_expert", "demos_unsafe", "demos_unsafe_expert",
    ]  # fmt: skip
    if rows.empty or "top_up" not in rows or not (rows["top_up"] == False).any():  # noqa: E712
        return pd.DataFrame(columns=cols)
    off = rows[rows["top_up"] == False]  # noqa: E712
    pairs = rows[
        rows["setting"].isin(off["setting"])
        & rows["strategy"].isin(off["strategy"])
        & rows["n_demos"].isin(off["n_demos"])
        & (rows["trajectory"] == "state")
        & (rows["algo"].isin(off["algo"]))
    ]
    g = pairs.groupby(["setting", "method"], sort=False)
    out = g.agg(
        seeds=("seed", "nunique"),
        crash_rate=("crash_rate", "mean"),
        filtered_rate=("filtered_rate", "mean"),
        eval_return=("eval_return", "mean"),
        demos_safe=("demos_safe", "mean"),
        demos_safe_expert=("demos_safe_expert", "mean"),
        demos_unsafe=("demos_unsafe", "mean"),
        demos_unsafe_expert=("demos_unsafe_expert", "mean"),
    ).reset_index()
    return out[cols]


def summarize_study_demo_sources(rows: pd.DataFrame) -> pd.DataFrame:
    """Per setting, demonstration count and draw: how many of the kept demonstrations came from
    the SAC run and how many from the shipped expert (the top-up), how many roll-outs of each
    group the SAC run gave, and which runs (``runs``, ``seeds``) used them. Empty before the
    study ran.

    A draw is one ``demos_file`` (its name is a hash of every array). A study that moved
    machines before its demonstrations were pinned (:func:`pinned_demonstrations`) can have
    more than one draw per setting; this table says which runs used which.

    Used in: DEFENDER chapter ("Evidence at study scale").
    """
    cols = [
        "setting", "n_demos", "top_up", "demos_file", "runs", "seeds", "sac_rollouts_safe",
        "sac_rollouts_unsafe", "demos_safe", "demos_safe_expert", "demos_unsafe",
        "demos_unsafe_expert",
    ]  # fmt: skip
    if rows.empty or "demos_file" not in rows:
        return pd.DataFrame(columns=cols)
    d = rows[rows["demos_file"].notna()]
    keys = [c for c in cols if c not in ("runs", "seeds")]
    out = (
        d.groupby(keys, sort=False, dropna=False)["seed"]
        .agg(runs="size", seeds=lambda s: ",".join(str(int(v)) for v in sorted(set(s))))
        .reset_index()
    )
    out["_first"] = d.groupby(keys, sort=False, dropna=False)["seed"].min().to_numpy()
    out = out.sort_values(["setting", "n_demos", "top_up", "_first"])
    return out[cols].reset_index(drop=True)


def summarize_study_counterfactual(rows: pd.DataFrame) -> pd.DataFrame:
    """What the filter saved (the second study's measure, :func:`training_run_numbers`): per
    setting and method, the mean over seeds of the real crashes per 1,000 training steps, the
    filtered episodes whose action would have crashed (``saved_crashes``) and would not
    (``false_alarms``), the filter's precision and recall, the crash rate the run would have
    had without the filter, and the final policy's score without the filter; and how often the
    filter fired (``firings_per_1k_steps``: saved crashes and false alarms per 1,000 training
    steps, which a random-filter control is matched to). Runs without a filter have NaN
    counterfactuals. Empty before the study ran.

    Used in: DEFENDER chapter ("The second study").
    """
    cols = [
        "setting", "method", "seeds", "crashes_per_1k_steps", "firings_per_1k_steps",
        "saved_crashes", "false_alarms", "filter_precision", "filter_recall", "crash_rate",
        "crash_rate_without_filter", "eval_score",
    ]  # fmt: skip
    if rows.empty:
        return pd.DataFrame(columns=cols)
    missing = sorted(set(cols) - {"seeds", "firings_per_1k_steps"} - set(rows.columns))
    if "steps" not in rows:
        missing.append("steps")
    if missing:
        raise ValueError(
            f"Study rows lack {missing}: runs made before the counterfactual was recorded "
            "(the first study's) cannot be summarised this way."
        )
    # every firing is a saved crash or a false alarm: the filter's firings per training step,
    # which the random-filter control is matched to
    fired = rows["saved_crashes"] + rows["false_alarms"]
    rows = rows.assign(firings_per_1k_steps=1000 * fired / rows["steps"])
    g = rows.groupby(["setting", "method"], sort=False)
    out = g[cols[3:]].mean()
    out.insert(0, "seeds", g["seed"].nunique())
    return out.reset_index()[cols]


STUDY_DATA_NOTE = (
    "the setting (SB3's SAC v2 and TD3 with 64-64 networks for 30,000 steps per run, not the "
    "authors' SAC v1 for 5,000 episodes; demonstrations from a 30,000-step SAC run, a group "
    "with too few roll-outs topped up from the ARS expert then shipped)"
)
"""What may make the study's answer differ from the thesis's (the readings' last reason)."""

STUDY_V2_DATA_NOTE = (
    "the setting (SB3's SAC v2 with the thesis's 256-256 networks for 200,000 steps per run on "
    "Hopper, not the authors' SAC v1 for 5,000 episodes; demonstrations from a 30,000-step SAC "
    "run with those networks, a group with too few roll-outs topped up from the ARS expert)"
)
"""The same for the second study (``defender-c7c9-v2``)."""

STUDY_V4_DATA_NOTE = (
    "the setting (SB3's SAC v2 with the thesis's 256-256 networks for 200,000 steps per run on "
    "Hopper, not the authors' SAC v1 for 5,000 episodes; both demonstration groups from one "
    "200,000-step SAC run with those networks, rolled out after every episode, as the thesis "
    "did; the MeanDemoW5/MeanDemoW10 filter that the thesis's ablation chose, not one chosen "
    "on these runs)"
)
"""The same for the fourth study (``defender-c7c9-v4``)."""

STUDY_V5_DATA_NOTE = (
    "the setting (SB3's SAC v2 with the thesis's 256-256 networks for 200,000 steps per run on "
    "Hopper, not the authors' SAC v1 for 5,000 episodes; both demonstration groups from one "
    "200,000-step SAC run with those networks, as the thesis did; the MeanDemoW5/MeanDemoW10 "
    "filter on the trajectory's last 20 states, as the authors' code has it, since on the whole "
    "trajectory, as the text has it, it stopped firing)"
)
"""The same for the fifth study (``defender-c7c9-v5``)."""
