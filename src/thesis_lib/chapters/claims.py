"""The Claims page: the thesis's fourteen claims, the evidence for each, and its verdict.

It renders ``studies/claims.csv``, which ``thesis claims`` writes from the committed studies
(:func:`thesis_lib.book.study.write_claims`); nothing is recomputed when the book is built.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from thesis_lib.stats.claims import CLAIMS, EVIDENCE, VERDICT_COLOURS


@dataclass
class Config:
    """Parameters of the Claims page."""

    claims_csv: str = ""
    """``studies/claims.csv`` of the checkout when empty."""


def load_claims(cfg: Config) -> pd.DataFrame:
    """The claims ledger: every claim of CLAIMS.md, its verdict and interval.

    A missing ``claims.csv`` (no study committed yet) gives every claim ``pending``.
    """
    from thesis_lib.book.paths import project_root

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
    gave the verdict, that one too (``decided_by``).
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
    """How many claims hold, fail, are inconclusive or pending."""
    v = ledger_table(claims)["verdict"]
    return v.value_counts().reindex(list(VERDICT_COLOURS), fill_value=0)


def plot_claims(claims: pd.DataFrame, ax: Any = None) -> Any:
    """Effects with their 95% intervals, one row per judged claim, coloured by verdict."""
    import matplotlib.pyplot as plt

    judged = claims.dropna(subset=["effect"]) if "effect" in claims else claims.iloc[:0]
    if ax is None:
        _, ax = plt.subplots(figsize=(6, 0.45 * max(len(judged), 2) + 1))
    if judged.empty:
        ax.text(0.5, 0.5, "no claim judged yet", ha="center", va="center")
        ax.set_axis_off()
        return ax.figure
    y = np.arange(len(judged))[::-1]
    for yi, r in zip(y, judged.itertuples()):
        c = VERDICT_COLOURS.get(r.verdict, "k")
        ax.plot([r.ci_low, r.ci_high], [yi, yi], color=c, lw=2)
        ax.plot([r.effect], [yi], "o", color=c)
    ax.axvline(0, color="k", lw=0.8)
    ax.set_yticks(y, judged["claim"])
    ax.set_xlabel("effect (x - y) with its 95% interval")
    return ax.figure


__all__ = [
    "Config",
    "VERDICT_COLOURS",
    "ledger_table",
    "link_chapters",
    "load_claims",
    "plot_claims",
    "verdict_counts",
]
