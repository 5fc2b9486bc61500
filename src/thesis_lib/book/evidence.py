"""A chapter's section "Evidence at study scale": its committed study, read and shown.

Every chapter with a pre-registered study (``params/<chapter>.study.yml``) renders the same
things from ``studies/<chapter>/``, which ``thesis study <chapter>`` writes; nothing here
trains or evaluates a model, and the book build never reruns a study.

* :func:`load_evidence`: the study, its rows (study scale and scale check apart), its
  ``run.json`` and, once the study is complete, its pre-registered comparisons and verdicts;
* :func:`status_line`: what has run, at which commit, at what cost;
* :func:`per_setting_table`, :func:`plot_per_setting`: each method's mean per setting with a
  95% bootstrap interval over seeds (the dot-and-interval plot), the secondary metric beside;
* :func:`aggregate_table`, :func:`plot_performance_profiles`: each method's aggregate (IQM
  and mean) over every setting with stratified intervals, and rliable's run-score
  distributions;
* :func:`comparisons_table`, :func:`plot_comparisons`: the claims' comparisons (effect, 95%
  stratified interval, P(X > Y), verdict), or why they are pending;
* :func:`scale_check_table`: the scale check's level and ranking at both scales;
* :func:`secondary_comparisons`, :func:`claim_readings`: the verdicts on the thesis's metric
  too, and per claim where our answer differs from the thesis's and what may explain it.

A shared service of the chapters, like :func:`thesis_lib.book.compare_with_paper`.

Used in: HDT, Decision Mamba and UR3 deployment chapters ("Evidence at study scale"), and
every chapter that gets a study.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from thesis_lib.book import study as st
from thesis_lib.book.chapter import Chapter
from thesis_lib.paths import project_root
from thesis_lib.provenance import git_output
from thesis_lib.stats import aggregate_interval, mean_interval, performance_profile, score_matrix
from thesis_lib.stats.claims import CLAIMS, VERDICT_COLOURS, claim_verdicts, evaluate_comparisons

__all__ = [
    "Evidence",
    "aggregate_table",
    "claim_readings",
    "code_changes_since",
    "comparisons_table",
    "input_versions",
    "load_evidence",
    "per_setting_table",
    "plot_comparisons",
    "plot_performance_profiles",
    "plot_per_setting",
    "scale_check_table",
    "secondary_comparisons",
    "status_line",
    "study_code_paths",
]


@dataclass
class Evidence:
    """A chapter's committed study.

    Attributes:
        study: the :class:`~thesis_lib.book.study.Study` (its parameter file).
        rows: the study-scale rows (one per run; ``scale == "study"``).
        check: the scale check's rows, with the study-scale rows of the same setting.
        info: ``run.json`` (``{}`` before the study ran).
        comparisons: the evaluated comparisons (empty until the study is complete).
    """

    study: Any
    rows: pd.DataFrame
    check: pd.DataFrame
    info: dict[str, Any]
    comparisons: pd.DataFrame = field(default_factory=pd.DataFrame)

    @property
    def complete(self) -> bool:
        """Every pre-registered task has run under this study file."""
        return bool(self.info.get("complete")) and self.info.get("study_hash") == self.study.hash


def load_evidence(chapter: Chapter, reps: int = 10_000, study: str = "") -> Evidence:
    """Read a study's committed rows (``studies/<chapter>/``: the rows of this study file's
    tasks), for the chapter's registered :class:`~thesis_lib.book.chapter.Chapter`.

    ``study``: the tag of a later study of the chapter (``"v2"``: ``params/<chapter>.v2.study.yml``,
    ``studies/<chapter>/v2/``); default its first.

    Raises:
        FileNotFoundError: the chapter has no such study file.
    """
    registered = st.load_study(st.study_ref(chapter.name, study))
    rows = st.study_rows(registered)
    if len(rows):  # the grid's order (settings, seeds, methods as registered), not the files'
        order = {t.key: i for i, t in enumerate(st.study_tasks(registered, chapter))}
        rows = rows.sort_values("task_key", key=lambda k: k.map(order), kind="stable")
    info = st.read_run_info(registered)
    scale = rows["scale"].fillna("study") if "scale" in rows else pd.Series("study", rows.index)
    main, check = rows[scale == "study"], rows[scale == "check"]
    if len(check):
        setting = registered.columns["setting"]
        same = main[main[setting].isin(set(check[setting]))]
        check = pd.concat([same, check], ignore_index=True)
    ev = Evidence(registered, main.reset_index(drop=True), check.reset_index(drop=True), info)
    if ev.complete:
        ev.comparisons = st.evaluate_study(registered, reps=reps)
    return ev


def status_line(ev: Evidence) -> str:
    """The study, tasks done of total (and, short of complete, whether it is still running or a
    later study replaced it: :func:`~thesis_lib.book.study.superseded_by`), CPU-hours, the
    commits it ran at (a commit with uncommitted changes says so), and once it is complete
    whether the library changed since (:func:`code_changes_since`)."""
    i = ev.info
    if not i or i.get("study_hash") != ev.study.hash:
        return f"Study {ev.study.study}: not run yet (`thesis study {ev.study.ref}`)."
    commits = (
        ", ".join(
            c[:7] + (" with uncommitted changes" if c.endswith("-dirty") else "")
            for c in i.get("commits", [])
        )
        or "none"
    )
    later = None if ev.complete else st.superseded_by(ev.study)
    state = (
        "complete"
        if ev.complete
        else f"stopped: superseded by {later}"
        if later
        else "in progress: verdicts wait for the full grid"
    )
    line = (
        f"Study {i['study']}: {i['tasks_done']}/{i['tasks_total']} tasks ({state}), "
        f"{i.get('cpu_hours', 0):.1f} CPU-hours, run at commit(s) {commits}."
    )
    since = code_changes_since(ev) if ev.complete else None
    if since is not None:
        code = since[since.changed.str.contains("code")]
        file = since[since.changed.str.contains("study file")]
        line += (
            " The code its tasks run has not changed since."
            if code.empty
            else f" Since then, {len(code)} commit(s) changed the code its tasks run (newest "
            f"{code.commit.iloc[0]}, {code.date.iloc[0]}); they took no part in these rows"
            + (
                ", except as the uncommitted changes its latest tasks ran with (each task's "
                "record lists its changed files)."
                if f"{since.attrs.get('since')}-dirty" in i.get("commits", [])
                else "."
            )
        )
        if not file.empty:  # a later study that reads earlier runs (``reuse``) is one of these
            line += (
                f" Its study file ({ev.study.file}) was written or changed since, at "
                f"{len(file)} commit(s) (newest {file.commit.iloc[0]}, {file.date.iloc[0]}): "
                "the verdicts read the file as it is now."
            )
    return line


#: What a study's rows depend on when its task functions cannot be traced (a task function
#: outside the library): the whole library, less the book's rendering code.
STUDY_CODE_PATHS = ("src/thesis_lib", ":(exclude)src/thesis_lib/book")


def _module_file(name: str, src: Path) -> Path | None:
    base = src.joinpath(*name.split("."))
    for f in (base.with_suffix(".py"), base / "__init__.py"):
        if f.is_file():
            return f
    return None


def _imported_modules(name: str, file: Path, src: Path) -> set[str]:
    """The ``thesis_lib`` modules ``file`` (module ``name``) imports, anywhere in it (a lazy
    import inside a function runs too): ``import a.b``, ``from a import b`` (``a`` and, where
    it is a module, ``a.b``), relative imports resolved against ``name``'s package."""
    import ast

    package = name if file.name == "__init__.py" else name.rpartition(".")[0]
    found: set[str] = set()
    for node in ast.walk(ast.parse(file.read_text(), str(file))):
        if isinstance(node, ast.Import):
            found.update(a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                parts = package.split(".")
                base = ".".join(parts[: len(parts) - node.level + 1])
                mod = f"{base}.{node.module}" if node.module else base
            else:
                mod = node.module or ""
            found.add(mod)
            found.update(
                f"{mod}.{a.name}" for a in node.names if _module_file(f"{mod}.{a.name}", src)
            )
    return {m for m in found if m == "thesis_lib" or m.startswith("thesis_lib.")}


def study_code_paths(modules: set[str], root: Path | None = None) -> list[str] | None:
    """The library files a study's task functions run, relative to the project ``root``: the
    modules named (``thesis_lib.chapters.defender``, ...) and, transitively, every
    ``thesis_lib`` module they import, with the ``__init__.py`` of each package on the way.
    ``thesis_lib.book`` (paths, provenance, rendering) is left out, as in
    :data:`STUDY_CODE_PATHS`. ``None`` where a module is not a file under ``root/src``.

    Example: the 07 study's tasks (``thesis_lib.chapters.ur3``) run ``ur3``, ``seq``, ``data``,
    ``sweep`` and ``mdlt`` (the dance checks) code, but no ``defender`` or ``clfd`` module: a
    commit that only changes DEFENDER did not change what the 07 rows depend on.
    """
    root = Path(root) if root is not None else project_root()
    src = root / "src"
    todo, seen, files = list(modules), set(), set()
    while todo:
        name = todo.pop()
        if name in seen or name == "thesis_lib.book" or name.startswith("thesis_lib.book."):
            continue
        seen.add(name)
        f = _module_file(name, src)
        if f is None:
            if name in modules:
                return None
            continue  # a name imported from a module (a function), not a module
        files.add(f)
        parts = name.split(".")
        todo += [".".join(parts[:i]) for i in range(1, len(parts))]  # its packages run first
        todo += _imported_modules(name, f, src)
    return sorted(str(f.relative_to(root)) for f in files)


def code_changes_since(ev: Evidence) -> pd.DataFrame | None:
    """The commits after the study's last commit that changed what its rows depend on: the
    library code its task functions run (:func:`study_code_paths`; the whole library, less
    ``book/``, where they cannot be traced) and its study file. Columns ``commit, date,
    subject, changed`` (``code``, ``study file`` or ``code, study file``), newest first, and
    ``attrs["since"]``, the study's newest commit, which the list starts after;
    ``None`` where it cannot be known: before the study ran, or where git or the study's
    commits cannot be read (a copy without history).

    CLAIMS.md asks each page to say at which commit a study was computed and what changed
    since: a change listed here did not take part in the verdicts.
    """
    cols = ["commit", "date", "subject", "changed"]
    commits = [c.removesuffix("-dirty") for c in ev.info.get("commits", [])]
    stamps = {}
    for c in commits:
        t = git_output(["log", "-1", "--format=%ct", c, "--"])
        if t and t.strip():
            stamps[c] = int(t.strip())
    if not stamps:
        return None
    last = max(stamps, key=lambda c: stamps[c])
    fns = st.study_task_functions(ev.study)
    traced = study_code_paths({f.partition(":")[0] for f in fns}) if fns else None
    fmt = "--format=%h%x09%cs%x09%s"
    logs = {
        "code": git_output(["log", fmt, f"{last}..HEAD", "--", *(traced or STUDY_CODE_PATHS)]),
        "study file": git_output(["log", fmt, f"{last}..HEAD", "--", ev.study.file]),
    }
    if any(log is None for log in logs.values()):
        return None
    found: dict[str, list[str]] = {}  # newest first, as git log lists them
    for what in ("code", "study file"):
        for line in (logs[what] or "").splitlines():
            if line.count("\t") >= 2:
                found.setdefault(line, []).append(what)
    order = git_output(["log", "--format=%h", f"{last}..HEAD"]) or ""
    rank = {h: i for i, h in enumerate(order.split())}
    rows = [[*line.split("\t", 2), ", ".join(w)] for line, w in found.items()]
    rows.sort(key=lambda r: rank.get(r[0], len(rank)))
    out = pd.DataFrame(rows, columns=cols)
    out.attrs["since"] = last  # the study's newest commit, which the list starts after
    return out


def input_versions(ev: Evidence, column: str) -> pd.DataFrame:
    """The versions of one input the study's rows record (``column``: a hash such as
    ``data_sha``), with how many rows and which seeds saw each, the most used first.

    A study runs across sessions, on whichever machine each gets; an input a task makes anew
    (a synthesised or rendered data set) should come out the same on each. One row here: it
    did. Empty when the rows do not record ``column`` (not run yet, or made before it was
    recorded); rows without it are counted as ``not recorded``.
    """
    cols = [column, "rows", "seeds"]
    if ev.rows.empty or column not in ev.rows:
        return pd.DataFrame(columns=cols)
    values = ev.rows[column].fillna("not recorded").astype(str)
    out = [
        [v, len(g), ",".join(str(int(x)) for x in sorted(set(g["seed"])))]
        for v, g in ev.rows.groupby(values, sort=False)
    ]
    return (
        pd.DataFrame(out, columns=cols)
        .sort_values("rows", ascending=False, kind="stable")
        .reset_index(drop=True)
    )


def per_setting_table(
    ev: Evidence,
    metric: str | None = None,
    secondary: str | None = None,
    rows: pd.DataFrame | None = None,
    reps: int = 2000,
) -> pd.DataFrame:
    """Per method x setting: the mean of ``metric`` over seeds, its 95% bootstrap interval,
    the number of seeds and the secondary metric's mean.

    Args:
        ev: :func:`load_evidence` output.
        metric: default the study's primary metric.
        secondary: default the study's secondary metric (``None`` in the file: left out).
        rows: other rows than ``ev.rows`` (e.g. ``ev.check``).
    """
    c = ev.study.columns
    metric = metric or ev.study.metric
    secondary = secondary if secondary is not None else ev.study.secondary
    df = ev.rows if rows is None else rows
    keys = [c["method"], c["setting"]] + (["scale"] if "scale" in df and rows is not None else [])
    cols = keys + ["mean", "ci_low", "ci_high", "seeds"]
    cols += [f"{secondary} (mean)"] if secondary else []
    if metric not in df:
        return pd.DataFrame(columns=cols)
    df = df[df[metric].notna()]
    out = []
    for k, g in df.groupby(keys, sort=False):
        mean, lo, hi = mean_interval(g[metric].to_numpy(), reps)
        r = dict(zip(keys, k if isinstance(k, tuple) else (k,)))
        r |= {"mean": mean, "ci_low": lo, "ci_high": hi, "seeds": g[c["seed"]].nunique()}
        if secondary and secondary in g:
            r[f"{secondary} (mean)"] = float(g[secondary].mean())
        out.append(r)
    return pd.DataFrame(out, columns=cols)


def plot_per_setting(
    ev: Evidence,
    metric: str | None = None,
    methods: list[str] | None = None,
    ncols: int = 3,
    secondary: bool = True,
) -> Any:
    """Dot-and-interval plot: one panel per setting, each method's mean and 95% interval over
    seeds (the secondary metric, when the study names one, as an open circle on the same axis;
    ``secondary=False`` where its units differ from the primary's)."""
    import matplotlib.pyplot as plt

    metric = metric or ev.study.metric
    table = per_setting_table(ev, metric)
    c = ev.study.columns
    if table.empty:
        fig, ax = plt.subplots(figsize=(5, 1.5))
        ax.text(0.5, 0.5, "no study rows yet", ha="center", va="center")
        ax.set_axis_off()
        return fig
    settings = list(dict.fromkeys(table[c["setting"]]))
    methods = methods or list(dict.fromkeys(table[c["method"]]))
    n = len(settings)
    ncols = min(ncols, n)
    nrows = -(-n // ncols)
    fig, axes = plt.subplots(
        nrows, ncols, figsize=(3.6 * ncols, 0.35 * len(methods) * nrows + 1.2), squeeze=False
    )
    # the secondary metric is the primary's counterpart: drawn beside the primary only
    primary = metric == ev.study.metric
    sec = f"{ev.study.secondary} (mean)" if ev.study.secondary and primary and secondary else None
    for ax, s in zip(axes.flat, settings):
        t = table[table[c["setting"]] == s].set_index(c["method"]).reindex(methods)
        y = np.arange(len(methods))[::-1]
        err = np.vstack([t["mean"] - t["ci_low"], t["ci_high"] - t["mean"]])
        ax.errorbar(t["mean"], y, xerr=np.nan_to_num(err), fmt="o", color="C0", capsize=3)
        if sec and sec in t:
            ax.plot(t[sec], y, "o", mfc="none", color="C1", label=ev.study.secondary)
        ax.set_yticks(
            y, [f"{m} (n={int(k)})" if k == k else m for m, k in zip(methods, t["seeds"])]
        )
        ax.set_title(s, fontsize=9)
        ax.set_xlabel(metric, fontsize=8)
    for ax in list(axes.flat)[n:]:
        ax.set_axis_off()
    if sec:
        axes.flat[0].legend(fontsize=7, loc="best")
    fig.tight_layout()
    return fig


def _complete_methods(ev: Evidence, metric: str, settings: list[str] | None) -> dict[str, Any]:
    """Per method, its ``(seeds, settings)`` matrix over ``settings`` (default: every setting
    the method ran), once the study is complete (``{}`` before: like the verdicts, the
    aggregates wait for the full grid)."""
    c = ev.study.columns
    if not ev.complete or metric not in ev.rows or c["method"] not in ev.rows:
        return {}
    df = ev.rows[ev.rows[metric].notna()]
    out = {}
    for m, g in df.groupby(c["method"], sort=False):
        own = settings or list(dict.fromkeys(g[c["setting"]]))
        try:
            out[str(m)] = score_matrix(
                df, str(m), metric, own, c["method"], c["setting"], c["seed"]
            )[0]
        except ValueError:  # an incomplete grid (study in progress) or a missing setting
            continue
    return out


def aggregate_table(
    ev: Evidence,
    metric: str | None = None,
    settings: list[str] | None = None,
    reps: int = 2000,
) -> pd.DataFrame:
    """Per method, over ``settings`` (default: all the method ran): the IQM and the mean of
    every (seed, setting) score, each with its 95% interval from a bootstrap stratified over
    settings (rliable's aggregate estimates). Empty until the study is complete."""
    metric = metric or ev.study.metric
    cols = ["method", "settings", "runs", "iqm", "iqm_low", "iqm_high"]
    cols += ["mean", "mean_low", "mean_high"]
    out = []
    for m, mat in _complete_methods(ev, metric, settings).items():
        r: dict[str, Any] = {"method": m, "settings": mat.shape[1], "runs": mat.size}
        for agg in ("iqm", "mean"):
            p, lo, hi = aggregate_interval(mat, agg, reps=reps)
            r |= {agg: p, f"{agg}_low": lo, f"{agg}_high": hi}
        out.append(r)
    return pd.DataFrame(out, columns=cols)


def plot_performance_profiles(
    ev: Evidence,
    metric: str | None = None,
    settings: list[str] | None = None,
    methods: list[str] | None = None,
    n_taus: int = 101,
    reps: int = 1000,
    ax: Any = None,
) -> Any:
    """rliable's run-score distributions: per method, the share of (seed, setting) runs that
    score above ``tau``, against ``tau``, with a 95% stratified bootstrap band. A curve that
    lies above another everywhere dominates it stochastically."""
    import matplotlib.pyplot as plt

    metric = metric or ev.study.metric
    mats = _complete_methods(ev, metric, settings)
    if methods:
        mats = {m: mats[m] for m in methods if m in mats}
    if ax is None:
        _, ax = plt.subplots(figsize=(6, 3.5))
    if not mats:
        ax.text(0.5, 0.5, status_line(ev), ha="center", va="center", wrap=True, fontsize=8)
        ax.set_axis_off()
        return ax.figure
    allv = np.concatenate([m.ravel() for m in mats.values()])
    taus = np.linspace(allv.min(), allv.max(), n_taus)
    for i, (m, mat) in enumerate(mats.items()):
        share, lo, hi = performance_profile(mat, taus, reps=reps)
        ax.plot(taus, share, color=f"C{i}", label=f"{m} ({mat.shape[1]} settings)")
        ax.fill_between(taus, lo, hi, color=f"C{i}", alpha=0.2, lw=0)
    ax.set_xlabel(f"{metric} threshold tau")
    ax.set_ylabel("share of runs with score > tau")
    ax.legend(fontsize=7)
    ax.figure.tight_layout()
    return ax.figure


def comparisons_table(ev: Evidence) -> pd.DataFrame:
    """The pre-registered comparisons: claim, x vs y, metric, settings, effect with its 95%
    interval, P(X > Y), the verdict, whether it decides the claim, and its validity gates
    with their figures (:mod:`thesis_lib.stats.gates`); before the study is
    complete, the comparisons as registered with the verdict ``pending``."""
    cols = [
        "claim",
        "comparison",
        "metric",
        "kind",
        "margin",
        "x_score",
        "y_score",
        "effect",
        "ci_low",
        "ci_high",
        "prob_improvement",
        "seeds",
        "settings",
        "verdict",
        "decides the claim",
        "gates",
    ]
    if not ev.complete or ev.comparisons.empty:
        return pd.DataFrame(
            [
                {
                    "claim": s["claim"],
                    "comparison": s.get("label") or f"{s['x']} vs {s['y']}",
                    "metric": s.get("metric", ev.study.metric),
                    "kind": s.get("kind", "superior"),
                    "margin": s.get("margin", 0.0),
                    "verdict": "pending",
                    "decides the claim": bool(s.get("counts", True)),
                }
                for s in ev.study.comparisons
            ],
            columns=cols,
        )
    r = ev.comparisons
    return pd.DataFrame(
        {
            "claim": r["claim"],
            "comparison": [lb or f"{x} vs {y}" for lb, x, y in zip(r["label"], r["x"], r["y"])],
            "metric": r["metric"],
            "kind": r["kind"],
            "margin": r["margin"],
            "x_score": r["x_score"],
            "y_score": r["y_score"],
            "effect": r["effect"],
            "ci_low": r["ci_low"],
            "ci_high": r["ci_high"],
            "prob_improvement": r["prob_improvement"],
            "seeds": r["seeds"],
            "settings": r["settings"],
            "verdict": r["verdict"],
            "decides the claim": r["counts"] if "counts" in r else True,
            "gates": r["gates"] if "gates" in r else "",
        },
        columns=cols,
    )


def plot_comparisons(ev: Evidence, metric: str | None = None, ax: Any = None) -> Any:
    """The effect (x - y) of each comparison on ``metric`` (default the study's) with its 95%
    interval, coloured by verdict, the margin shaded; a note while the study is incomplete."""
    import matplotlib.pyplot as plt

    metric = metric or ev.study.metric
    t = comparisons_table(ev)
    t = t[t["metric"] == metric].reset_index(drop=True)
    if ax is None:
        _, ax = plt.subplots(figsize=(7, 0.5 * max(len(t), 2) + 1))
    if t["effect"].isna().all():
        ax.text(0.5, 0.5, status_line(ev), ha="center", va="center", wrap=True, fontsize=8)
        ax.set_axis_off()
        return ax.figure
    y = np.arange(len(t))[::-1]
    for yi, r in zip(y, t.to_dict("records")):
        colour = VERDICT_COLOURS.get(r["verdict"], "k")
        ax.plot([r["ci_low"], r["ci_high"]], [yi, yi], color=colour, lw=2)
        fill = colour if r["decides the claim"] else "none"
        ax.plot([r["effect"]], [yi], "o", mfc=fill, color=colour)
    margins = sorted({float(m) for m in t["margin"] if m})
    if len(margins) == 1:
        ax.axvspan(-margins[0], margins[0], color="0.92", zorder=0, label="margin")
    ax.axvline(0, color="k", lw=0.8)
    ax.set_yticks(y, [f"{c}: {s}" for c, s in zip(t["claim"], t["comparison"])], fontsize=7)
    ax.set_xlabel(f"effect x - y in {metric} (95% stratified interval); open: reported apart")
    ax.figure.tight_layout()
    return ax.figure


def scale_check_table(
    ev: Evidence, metric: str | None = None, higher_is_better: bool = True
) -> pd.DataFrame:
    """The scale check: per method, the mean of ``metric`` at the study's scale and at the
    check's, with each scale's rank (1 = best: the highest, or with ``higher_is_better=False``
    the lowest, e.g. crashes)."""
    metric = metric or ev.study.metric
    c = ev.study.columns
    if ev.check.empty:
        return pd.DataFrame(columns=["method", "study", "check", "rank (study)", "rank (check)"])
    chk = ev.check
    chk = chk.assign(scale=chk["scale"].fillna("study"))
    means = chk.groupby([c["method"], "scale"])[metric].mean().unstack("scale")
    seeds = chk.groupby([c["method"], "scale"])[c["seed"]].nunique().unstack("scale")
    means = means.dropna(subset=[s for s in ("check",) if s in means])
    out = pd.DataFrame({"method": means.index})
    for s in ("study", "check"):
        if s in means:
            out[s] = means[s].to_numpy()
            out[f"seeds ({s})"] = seeds[s].reindex(means.index).to_numpy()
            out[f"rank ({s})"] = (
                out[s].rank(ascending=not higher_is_better, method="min").to_numpy()
            )
    return out


def secondary_comparisons(ev: Evidence, reps: int = 10_000) -> pd.DataFrame:
    """The comparisons registered on the primary metric, recomputed on the secondary one (the
    thesis's best evaluation during training): does the verdict depend on the metric?
    Empty until the study is complete or when the study names no secondary metric; a
    comparison with a method that has no value of it (an untrained control has no best
    validation checkpoint) is left out."""
    sec = ev.study.secondary
    if not ev.complete or not sec or sec not in ev.rows:
        return pd.DataFrame()
    c = ev.study.columns
    measured = set(ev.rows.loc[ev.rows[sec].notna(), c["method"]])
    specs = [
        {**s, "metric": sec}
        for s in ev.study.comparisons
        if s.get("metric", ev.study.metric) == ev.study.metric and {s["x"], s["y"]} <= measured
    ]
    if not specs:
        return pd.DataFrame()
    return evaluate_comparisons(
        ev.rows,
        specs,
        metric=sec,
        method_col=c["method"],
        setting_col=c["setting"],
        seed_col=c["seed"],
        reps=reps,
    )


def claim_readings(
    ev: Evidence,
    data_note: str = "the data (our data sets are made here, not the thesis's)",
    reps: int = 10_000,
    secondary: bool = True,
    claim_notes: Mapping[str, str] | None = None,
) -> pd.DataFrame:
    """Per claim of the study: our verdict, the verdict on the thesis's metric, whether the
    scale check kept the ranking, and one sentence that says where we differ from the thesis
    (which states every claim as holding) and which of data, scale or metric may explain it.
    The effect quoted is the claim's headline comparison (its first); where another
    comparison decided the verdict (C8's compute, say), the sentence names it too.

    Args:
        ev: :func:`load_evidence` output.
        data_note: the chapter's own difference in data or setting, named as a reason
            (e.g. ``"the data (simulated demonstrations, not the real arm's)"``).
        reps: bootstrap replications of the secondary-metric comparisons.
        secondary: judge the comparisons on the study's secondary metric too, with the same
            margins; set ``False`` where the secondary metric has other units than the
            primary (UR3: the share of test starts reaching all five goals).
        claim_notes: a claim's own reason, used for it instead of ``data_note`` where the
            data cannot be why (C6's timings: the hardware), e.g.
            ``{"C6": "the hardware (CPU times here, GPU times in the thesis)"}``.

    Raises:
        ValueError: ``claim_notes`` names a claim the study does not answer.
    """
    claims = list(dict.fromkeys(s["claim"] for s in ev.study.comparisons))
    claim_notes = dict(claim_notes or {})
    unknown = sorted(set(claim_notes) - set(claims))
    if unknown:
        raise ValueError(f"claim_notes names {unknown}; this study answers {claims}")
    if not ev.complete or ev.comparisons.empty:
        return pd.DataFrame(
            {
                "claim": claims,
                "ours": "pending",
                "on the thesis's metric": "pending",
                "reading": status_line(ev),
            }
        )
    ours = claim_verdicts(ev.comparisons).set_index("claim")
    sec = secondary_comparisons(ev, reps) if secondary else pd.DataFrame()
    theirs = claim_verdicts(sec).set_index("claim") if len(sec) else pd.DataFrame()
    check = scale_check_table(ev)
    same_rank = (
        bool((check["rank (study)"] == check["rank (check)"]).all())
        if {"rank (study)", "rank (check)"} <= set(check.columns) and len(check)
        else None
    )
    rows = []
    for cl in claims:
        r = ours.loc[cl]
        v2 = theirs["verdict"].get(cl, "n/a") if len(theirs) else "n/a"
        text = (
            f"{cl} ({CLAIMS[cl][1]}) The thesis: holds. Ours: **{r['verdict']}**, effect "
            f"{r['effect']:.3g} [{r['ci_low']:.3g}, {r['ci_high']:.3g}], "
            f"P(X>Y) {r['prob_improvement']:.2f}, {int(r['seeds'])} seeds x "
            f"{int(r['settings'])} settings."
        )
        if r["decided_by"]:
            text += f" Decided by {r['decided_by']}."
        if r["verdict"] != "holds":
            why = []
            if v2 == "holds":
                why.append("the metric (on the thesis's best-during-training metric it holds)")
            if same_rank is False:
                why.append("the scale (the scale check ranked the methods differently)")
            why.append(claim_notes.get(cl, data_note))
            text += " It may differ because of " + "; ".join(why) + "."
        elif v2 not in ("holds", "n/a"):
            text += f" On the thesis's metric it is {v2}."
        rows.append(
            {
                "claim": cl,
                "ours": r["verdict"],
                "on the thesis's metric": v2,
                "scale check: same ranking": same_rank,
                "reading": text,
            }
        )
    return pd.DataFrame(rows)
