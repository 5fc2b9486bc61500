"""The Claims page's tables: the claims ledger (:func:`load_claims`, :func:`ledger_table`,
:func:`gates_table`, :func:`verdict_counts`), the peer-parity table (:func:`load_parity`,
:func:`parity_view`, :func:`no_peer_table`) and the scale ladder (:func:`load_ladder`,
:func:`ladder_view`, :func:`ladder_choice`).

Used in: the Claims page of the book.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from thesis_lib.book.study import history_entries
from thesis_lib.chapters.claims.config import Config
from thesis_lib.paths import project_root
from thesis_lib.stats.claims import CLAIMS, EVIDENCE, VERDICT_COLOURS

__all__ = [
    "gates_table",
    "headline",
    "ladder_choice",
    "ladder_view",
    "ledger_table",
    "link_chapters",
    "load_claims",
    "load_ladder",
    "load_parity",
    "no_peer_table",
    "parity_view",
    "studies_table",
    "verdict_counts",
]


def load_claims(cfg: Config) -> pd.DataFrame:
    """The claims ledger: every claim of CLAIMS.md, its verdict and interval.

    A missing ``claims.csv`` (no study committed yet) gives every claim ``pending``.
    """
    path = Path(cfg.claims_csv) if cfg.claims_csv else project_root() / "studies" / "claims.csv"
    if path.exists():
        df = pd.read_csv(path, dtype={"claim": str})
    else:
        df = pd.DataFrame({"claim": list(CLAIMS), "verdict": "pending"})
    unknown = sorted(set(df["claim"]) - set(CLAIMS))
    if unknown:
        raise ValueError(f"{path}: unknown claim ids {unknown}")
    return df


def _fmt(x: Any, digits: int = 3) -> str:
    return "" if x is None or (isinstance(x, float) and np.isnan(x)) else f"{x:.{digits}g}"


def ledger_table(claims: pd.DataFrame) -> pd.DataFrame:
    """Per claim: the statement, the thesis's evidence, ours, the verdict and the chapter.

    "ours" is the headline comparison's effect and interval, and, where another comparison
    gave the verdict, that one too (``decided_by``); where several studies registered the claim
    (a later one beside the first), each with its verdict or progress (``history``).
    """
    by = claims.set_index("claim")
    rows = []
    for cid, (section, statement) in CLAIMS.items():
        evidence, chapter = EVIDENCE[cid]
        r = by.loc[cid] if cid in by.index else pd.Series(dtype=object)
        verdict = r.get("verdict", "pending")
        if verdict == "pending" or pd.isna(r.get("effect", np.nan)):
            ours = str(r.get("comparisons", "") or "no study yet")
        else:
            ours = (
                f"effect {_fmt(r['effect'])} [{_fmt(r['ci_low'])}, {_fmt(r['ci_high'])}], "
                f"P(X>Y) {_fmt(r['prob_improvement'], 2)}, {int(r['seeds'])} seeds x "
                f"{int(r['settings'])} settings"
            )
            decided = r.get("decided_by", "")
            if isinstance(decided, str) and decided:
                ours += f"; decided by {decided}"
        history = r.get("history", "")
        if isinstance(history, str) and ";" in history:  # a later study beside the first
            ours += f" (studies: {history})"
        rows.append(
            {
                "claim": cid,
                "statement": statement,
                "thesis (section, evidence)": f"{section}: {evidence}",
                "ours": ours,
                "verdict": verdict,
                "chapter": chapter,
            }
        )
    return pd.DataFrame(rows)


def studies_table(claims: pd.DataFrame) -> pd.DataFrame:
    """Per claim, its first study and its latest side by side (the v1 study and the second
    study that supersedes it, issue #36), each with its verdict, or its progress while it runs;
    read from ``history`` of ``claims.csv``. The verdict the ledger shows is the latest
    *complete* study's. A study read beside another (``, beside <id>`` in its entry) is left
    out: it is shown in the chapter.

    >>> t = studies_table(pd.DataFrame({"claim": ["C14"], "verdict": ["untestable"],
    ...     "history": ["ur3-c14-v1: untestable; ur3-c14-v2: pending, 0/52 tasks"]}))
    >>> t.loc[t.claim == "C14", ["v1 study", "v1", "v2 study", "v2"]].values.tolist()
    [['ur3-c14-v1', 'untestable', 'ur3-c14-v2', 'pending, 0/52 tasks']]
    """
    by = claims.set_index("claim")
    rows = []
    for cid in CLAIMS:
        r = by.loc[cid] if cid in by.index else pd.Series(dtype=object)
        entries = history_entries(r.get("history", ""))
        if not entries and isinstance(r.get("study", None), str):
            entries.append((r["study"], str(r.get("verdict", "pending"))))
        first = entries[0] if entries else ("no study yet", "pending")
        # a study read beside another (C6 on a GPU) is not the claim's later study
        own = [e for e in entries[1:] if ", beside " not in e[1]]
        later = own[-1] if own else ("none registered yet", "")
        rows.append(
            {
                "claim": cid,
                "v1 study": first[0],
                "v1": first[1],
                "v2 study": later[0],
                "v2": later[1],
                "verdict shown": str(r.get("verdict", "pending")),
            }
        )
    return pd.DataFrame(rows)


def link_chapters(ledger: pd.DataFrame, section: str = "evidence-at-study-scale") -> pd.DataFrame:
    """The ledger with each chapter as an HTML link to its section "Evidence at study scale"
    in the built book (pages are ``<chapter>.html``, sections anchored by their title).

    >>> link_chapters(pd.DataFrame({"chapter": ["04_hdt"]})).chapter[0]
    '<a href="04_hdt.html#evidence-at-study-scale">04_hdt</a>'
    """
    out = ledger.copy()
    out["chapter"] = [f'<a href="{c}.html#{section}">{c}</a>' for c in out["chapter"]]
    return out


def verdict_counts(claims: pd.DataFrame) -> pd.Series:
    """How many claims hold, fail, are inconclusive, untestable or pending."""
    v = ledger_table(claims)["verdict"]
    return v.value_counts().reindex(list(VERDICT_COLOURS), fill_value=0)


def gates_table(claims: pd.DataFrame) -> pd.DataFrame:
    """Per claim: its validity gates and their figures (``validity`` of ``claims.csv``): why a
    verdict is trusted, or why it was withheld (``untestable``).

    >>> t = gates_table(pd.DataFrame({"claim": ["C2", "C12"], "verdict": ["holds", "untestable"],
    ...     "validity": ["no gate", "untestable: CLfD vs TCN: FAILED level: CLfD 0.025 < 0.1"]}))
    >>> t["gates"].tolist()
    ['no gate', 'untestable: CLfD vs TCN: FAILED level: CLfD 0.025 < 0.1']
    """
    cols = ["claim", "verdict", "validity"]
    have = claims.reindex(columns=cols)
    return pd.DataFrame(
        {
            "claim": have["claim"],
            "verdict": have["verdict"].fillna("pending"),
            "gates": have["validity"].fillna("no study yet").astype(str),
        }
    )


def headline(comparisons: Any) -> str:
    """The headline comparison (the one whose effect the ledger quotes) from ``comparisons``.

    >>> headline("DT vs DT-noRTG (score_final): inconclusive [-6.45, 4.56]; x vs y (m): holds [1, 2]")
    'DT vs DT-noRTG (score_final)'
    """
    if not isinstance(comparisons, str):
        return ""
    return comparisons.split("; ")[0].rsplit(":", 1)[0].strip()


def load_parity(path: str | Path | None = None) -> pd.DataFrame:
    """The peer-parity table ``studies/parity/parity.csv`` (``thesis parity`` writes it); empty
    where no parity run is committed."""
    p = Path(path) if path else project_root() / "studies" / "parity" / "parity.csv"
    return pd.read_csv(p) if p.exists() else pd.DataFrame()


def parity_view(table: pd.DataFrame) -> pd.DataFrame:
    """The parity table for reading: per comparison, both sides' mean score (and each seed's),
    the data set's own mean, the difference ours - peer with its 95% interval, and the verdict
    (``at parity``: the interval holds 0 and the difference is at most 3 points, over 3 seeds a
    side or more; ``gap``: the interval excludes 0; ``not shown``: neither; ``fewer than 3
    seeds a side``: an interval, no verdict yet)."""
    if table.empty:
        return pd.DataFrame({"comparison": [], "result": []})

    def diff(r: pd.Series) -> str:
        if pd.isna(r["difference"]):
            return ""
        return f"{r['difference']:+.1f} [{r['ci_low']:.1f}, {r['ci_high']:.1f}]"

    def verdict(r: pd.Series) -> str:
        if pd.isna(r.get("peer")) or r["seeds"] == 0:
            return "no peer" if r["seeds"] else "not run"
        if str(r["parity"]) == "True":
            return "at parity"
        if str(r["parity"]) != "False" and not pd.isna(r["difference"]):
            return "fewer than 3 seeds a side"  # an interval, no verdict yet (issue #33's rule)
        # a gap only where the interval excludes 0; otherwise neither parity nor a gap is shown
        return "gap" if r["ci_high"] < 0 or r["ci_low"] > 0 else "not shown"

    def side(mean: Any, seeds: Any) -> str:
        return "" if pd.isna(mean) else f"{mean:.1f} ({seeds})"

    return pd.DataFrame({
        "comparison": table["comparison"],
        "method": table["method"],
        "init": table["init"].fillna(""),
        "windows": table["sampling"] if "sampling" in table else "start",  # drawn by
        "precision": table["precision"] if "precision" in table else "fp32",  # ours trained in
        "model": table["arch"],
        "updates": table["updates"],
        "ours (seeds)": [side(m, s) for m, s in zip(table["ours"], table["ours_seeds"], strict=True)],
        "d3rlpy (seeds)": [side(m, s) for m, s in zip(table["peer"], table["peer_seeds"], strict=True)],
        "data mean": table["data_mean"].round(1),
        "ours − peer [95% CI]": table.apply(diff, axis=1),
        "result": table.apply(verdict, axis=1),
    })  # fmt: skip


def no_peer_table() -> pd.DataFrame:
    """The learned methods with no peer package, and what stands in for one."""
    from thesis_lib.parity import NO_PEER  # lazy: torch

    return pd.DataFrame(
        {"method": list(NO_PEER), "no peer package; instead": list(NO_PEER.values())}
    )


def _ladder_name(name: str | None) -> str:
    from thesis_lib.ladder import CURRENT_LADDER  # lazy: torch

    return name or CURRENT_LADDER


def load_ladder(name: str | None = None) -> pd.DataFrame:
    """The scale ladder's table, ``studies/<name>/ladder.csv`` (``thesis ladder`` writes it;
    ``name`` defaults to the current ladder file, ``ladder.v2``); empty where none is
    committed."""
    p = project_root() / "studies" / _ladder_name(name) / "ladder.csv"
    return pd.read_csv(p) if p.exists() else pd.DataFrame()


def load_ladder_curves(name: str | None = None) -> pd.DataFrame:
    """The learning curves of ladder runs, ``studies/<name>/curves.csv`` (``thesis ladder
    --curve`` writes it); empty where none is committed."""
    p = project_root() / "studies" / _ladder_name(name) / "curves.csv"
    return pd.read_csv(p) if p.exists() else pd.DataFrame()


def ladder_view(table: pd.DataFrame) -> pd.DataFrame:
    """The ladder for reading: per rung, checkpoint and data set, each method's mean score over
    the seeds run (their number in brackets), the data set's mean, the level BC is held to,
    and the rung's verdicts at that checkpoint (``yes``, ``no``, or blank while a method or a
    seed is missing).

    >>> t = pd.DataFrame({"dataset": ["hopper/medium"] * 2, "rung": ["d32 L1"] * 2,
    ...     "updates": [30000] * 2, "method": ["BC", "DT"], "seeds": [3, 1],
    ...     "mean": [31.9, 33.2], "data_mean": [43.8] * 2, "bc_reference": [31.5] * 2,
    ...     "level": [None] * 2, "targets": [None] * 2, "stable": [None] * 2,
    ...     "passes": [None] * 2})
    >>> ladder_view(t).iloc[0].to_dict()["DT"]
    '33.2 (1)'
    """
    if table.empty:
        return pd.DataFrame({"rung": [], "updates": [], "data set": []})
    methods = list(dict.fromkeys(table["method"]))
    keys = ["rung", "updates", "dataset"]

    def verdict(x: Any) -> str:
        if x is None or (isinstance(x, float) and np.isnan(x)) or str(x) in ("", "nan", "None"):
            return ""
        return "yes" if str(x) in ("True", "1", "1.0") else "no"

    out = []
    for (rung, n, d), g in table.groupby(keys, sort=False):
        by = g.set_index("method")
        row: dict[str, Any] = {"rung": rung, "updates": int(n), "data set": d}
        for m in methods:
            row[m] = f"{by.at[m, 'mean']:.1f} ({int(by.at[m, 'seeds'])})" if m in by.index else ""
        row["data mean"] = round(float(g["data_mean"].iloc[0]), 1)
        row["BC held to"] = round(float(g["bc_reference"].iloc[0]), 1)
        for k in ("level", "targets", "stable", "passes"):
            row[k] = verdict(g[k].iloc[0])
        out.append(row)
    return pd.DataFrame(out)


def ladder_choice(table: pd.DataFrame, name: str | None = None) -> str:
    """The size the ladder chose and why, or why none is chosen yet
    (:func:`thesis_lib.ladder.choose_rung` on the ladder file ``params/<name>.yml``)."""
    from thesis_lib.ladder import choose_rung, load_ladder_file  # lazy: torch

    ladder = load_ladder_file(project_root() / "params" / f"{_ladder_name(name)}.yml")
    chosen, why = choose_rung(ladder, table)
    if chosen:
        return f"Chosen: {chosen[0]} at {chosen[1]:,} updates. {why}."
    return f"No size chosen yet: {why}."
