"""The thesis's fourteen claims (``CLAIMS.md``) and their verdicts from a study's rows.

A study's parameter file (``params/<chapter>.study.yml``) pre-registers, for each claim it
tests, the comparisons: methods ``x`` and ``y``, the metric, the kind of claim
(``superior``: x beats y; ``noninferior``: x is at least as good as y, within ``margin``),
the margin and the aggregate. :func:`evaluate_comparisons` applies :func:`thesis_lib.stats.compare`
to the study's tidy rows; :func:`claim_verdicts` folds several comparisons of one claim into
one verdict (it holds only if every comparison holds; it fails if any fails).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
import pandas as pd

from . import AGGREGATES, compare, holm, shared_settings
from .gates import applies, check_gate, evaluate_gate

#: id -> (thesis section, statement), as in CLAIMS.md.
CLAIMS: dict[str, tuple[str, str]] = {
    "C1": ("5.2.5.1", "The DT depends on the RTG input: without it, it cannot learn the task."),
    "C2": ("5.2.5.2", "The HDT needs no RTG: adding it to the low level does not help."),
    "C3": (
        "5.2.5.3",
        "The HDT beats the DT and BC in most settings, most of all on long / sparse-reward tasks.",
    ),
    "C4": ("5.3.3", "The DM needs no RTG; the DM without it is at least as good."),
    "C5": ("5.3.3", "DM beats DT (15/27) and HDM beats HDT (22/27)."),
    "C6": (
        "5.3.4",
        "Mamba models act faster than their Transformer predecessors; HDT/HDM cost about "
        "twice to train.",
    ),
    "C7": (
        "4.3.3",
        "DEFENDER cuts the crash rate during training while keeping or improving the return.",
    ),
    "C8": (
        "4.3.3",
        "State trajectories beat state-action trajectories: fewer crashes, less compute.",
    ),
    "C9": ("4.3.3", "More demonstrations make DEFENDER safer."),
    "C10": ("4.2.2.1", "CLfD aligns views better than TCN in all setups and than CMC in 3 of 4."),
    "C11": (
        "4.2.2.1",
        "CLfD features are viewpoint-invariant: stage accuracy on unseen cameras is about that "
        "on seen ones.",
    ),
    "C12": (
        "4.2.2.2",
        "RL with CLfD features and rewards learns the pick stage; with TCN / CMC features it "
        "does not.",
    ),
    "C13": (
        "6.5",
        "MDLT translates unseen music into dance better than trivial answers; a single genre is "
        "easier than all genres.",
    ),
    "C14": ("5.2.5.4", "HDT reaches more UR3 goals than DT, with few demonstrations."),
}

#: id -> (the thesis's evidence, the chapter notebook that tests the claim).
EVIDENCE: dict[str, tuple[str, str]] = {
    "C1": ("Table 5.1: DT without RTG collapses on most D4RL sets", "04_hdt"),
    "C2": ("Table 5.2: HDT with RTG no better than without", "04_hdt"),
    "C3": ("Table 5.3: wins BC 1, DT 8, HDT 23 of 31 settings", "04_hdt"),
    "C4": ("Table 5.5, Fig 5.5: DM without RTG at least as good", "05_decision_mamba"),
    "C5": ("Table 5.5: DM beats DT 15/27, HDM beats HDT 22/27", "05_decision_mamba"),
    "C6": ("Table 5.6: per-action and training-step times", "05_decision_mamba"),
    "C7": ("Tables 4.3-4.4: crash rate and return with and without the filter", "03_defender"),
    "C8": ("Sec. 4.3.3: state strategies crash less and cost less", "03_defender"),
    "C9": ("Table 4.5: 10, 20, 50 demonstrations", "03_defender"),
    "C10": ("Table 4.1: alignment error per encoder and method", "02_clfd"),
    "C11": ("Table 4.2: stage accuracy on seen and unseen cameras", "02_clfd"),
    "C12": ("Fig 4.4: DDPG+HER success on the pick stage", "02_clfd"),
    "C13": ("Tables 6.2-6.3: AJE per genre and all genres", "06_mdlt"),
    "C14": ("Table 5.4: goals reached with 10-80 demonstrations", "07_ur3_deployment"),
}

#: Colours of the verdicts in the book's plots.
VERDICT_COLOURS = {
    "holds": "#2e7d32",
    "fails": "#c62828",
    "inconclusive": "#f9a825",
    "untestable": "#5c6bc0",
    "pending": "#9e9e9e",
}

COMPARISON_KEYS = {
    "override",
    "claim",
    "x",
    "y",
    "metric",
    "kind",
    "margin",
    "aggregate",
    "settings",
    "label",
    "note",
    "counts",
}


def check_comparison(spec: Mapping[str, Any]) -> None:
    """Raise ``ValueError`` for an unknown key, claim, kind or aggregate in one comparison spec,
    or a ``margin`` that is not a number >= 0 (all read before the study runs)."""
    unknown = set(spec) - COMPARISON_KEYS
    if unknown:
        raise ValueError(
            f"unknown comparison key(s) {sorted(unknown)}; valid: {sorted(COMPARISON_KEYS)}"
        )
    for k in ("claim", "x", "y"):
        if k not in spec:
            raise ValueError(f"comparison {dict(spec)} lacks '{k}'")
    if spec["claim"] not in CLAIMS:
        raise ValueError(f"unknown claim {spec['claim']!r}; valid: {', '.join(CLAIMS)}")
    if spec.get("kind", "superior") not in ("superior", "noninferior", "equivalent"):
        raise ValueError(
            f"kind must be 'superior', 'noninferior' or 'equivalent', got {spec['kind']!r}"
        )
    name = f"{spec['claim']} ({spec['x']} vs {spec['y']})"
    margin = spec.get("margin", 0.0)
    if isinstance(margin, bool) or not isinstance(margin, int | float) or not margin >= 0:
        raise ValueError(
            f"Expect `margin` of comparison {name} to be a number >= 0, actually: {margin!r}"
        )
    if spec.get("aggregate", "mean") not in AGGREGATES:
        raise ValueError(
            f"Expect `aggregate` of comparison {name} to be one of {sorted(AGGREGATES)}, "
            f"actually: {spec['aggregate']!r}"
        )


def evaluate_comparisons(
    rows: pd.DataFrame,
    comparisons: Sequence[Mapping[str, Any]],
    *,
    metric: str,
    method_col: str = "method",
    setting_col: str = "setting",
    seed_col: str = "seed",
    reps: int = 10_000,
    interval: str = "bootstrap",
    gates: Sequence[Mapping[str, Any]] = (),
    parity: pd.DataFrame | None = None,
) -> pd.DataFrame:
    """One row per comparison: effect, 95% interval (``interval``: see
    :func:`thesis_lib.stats.compare`; 90% for an ``equivalent`` claim, by TOST), P(X > Y), the
    one-sided ``p_value`` and ``p_holm`` (Holm over the deciding comparisons given here: a
    comparison that holds only before the adjustment is inconclusive), verdict, and its
    validity gates (:mod:`thesis_lib.stats.gates`).

    A comparison guarded by a gate that fails gets the verdict ``untestable``; ``stat_verdict``
    keeps what its interval alone says, ``validity`` is ``valid``, ``untestable`` or empty (no
    gate), and ``gates`` lists each gate's figure.
    """
    for g in gates:
        check_gate(g)
    cols = {"method": method_col, "setting": setting_col, "seed": seed_col}
    out = []
    for spec in comparisons:
        check_comparison(spec)
        m = spec.get("metric", metric)
        interval_here = interval if spec.get("aggregate", "mean") == "mean" else "bootstrap"

        def run(
            r: pd.DataFrame, x: str, y: str, mt: str, _iv: str = interval_here, **kw: Any
        ) -> Any:
            kw.setdefault("claim", "superior")
            return compare(
                r,
                x,
                y,
                mt,
                reps=reps,
                method_col=method_col,
                setting_col=setting_col,
                seed_col=seed_col,
                interval=_iv,
                **kw,
            )

        c = run(
            rows,
            spec["x"],
            spec["y"],
            m,
            settings=spec.get("settings"),
            aggregate=spec.get("aggregate", "mean"),
            claim=spec.get("kind", "superior"),
            margin=float(spec.get("margin", 0.0)),
        )
        settings = spec.get("settings") or shared_settings(
            rows, spec["x"], spec["y"], m, method_col, setting_col
        )
        results = [
            evaluate_gate(g, {**spec, "metric": m}, rows, settings, m, cols, run, parity)
            for g in gates
            if applies(g, {**spec, "metric": m}, settings)
        ]
        passed = all(ok for ok, _ in results)
        row = {
            "claim": spec["claim"],
            "label": spec.get("label", ""),
            "counts": bool(spec.get("counts", True)),
            **c.to_dict(),
            "stat_verdict": c.verdict,
            "validity": "" if not results else "valid" if passed else "untestable",
            "gates": "; ".join(f"{'passed' if ok else 'FAILED'} {fig}" for ok, fig in results),
        }
        if not passed:
            row["verdict"] = "untestable"
        if spec.get("override"):
            row["override"] = str(spec["override"])
        out.append(row)
    res = pd.DataFrame(out)
    return _holm_adjust(res) if len(res) else res


#: The one-sided level Holm's adjustment keeps over a study's deciding comparisons, as the
#: intervals decide them: 2.5% (a 95% two-sided interval's side), 5% for an equivalence
#: claim (TOST's two one-sided 5% tests, the 90% interval).
HOLM_ALPHA = 0.025
HOLM_ALPHA_EQUIVALENT = 0.05


def _holm_adjust(res: pd.DataFrame) -> pd.DataFrame:
    """Holm over the comparisons that decide claims (``counts``) with a p-value: ``p_holm``; a
    comparison that holds by its own interval but not after the adjustment (at
    :data:`HOLM_ALPHA`, or :data:`HOLM_ALPHA_EQUIVALENT`) becomes inconclusive
    (``stat_verdict`` keeps the unadjusted verdict)."""
    res = res.copy()
    counted = res["counts"].astype(bool).to_numpy()
    p = res["p_value"].astype(float).to_numpy() if "p_value" in res else np.full(len(res), np.nan)
    adj = np.full(len(res), np.nan)
    adj[counted] = holm(p[counted])
    res["p_holm"] = adj
    kind = res["kind"] if "kind" in res else pd.Series("superior", index=res.index)
    alpha = np.where(kind == "equivalent", HOLM_ALPHA_EQUIVALENT, HOLM_ALPHA)
    weak = (res["verdict"] == "holds") & (res["p_holm"] >= alpha)
    res.loc[weak, "verdict"] = "inconclusive"
    return res


def _name(r: Any) -> str:
    """A comparison's label, or ``x vs y`` where it has none."""
    label = getattr(r, "label", "")
    return str(label) if isinstance(label, str) and label else f"{r.x} vs {r.y}"


def _validity(counted: pd.DataFrame) -> str:
    """The gates of a claim's counted comparisons, in one line: the failed ones first."""
    if "gates" not in counted or not counted["gates"].astype(str).str.len().any():
        return "no gate"
    failed = counted[counted["validity"] == "untestable"]
    shown = failed if len(failed) else counted
    head = "untestable: " if len(failed) else "gates passed: "
    return head + " | ".join(f"{_name(r)}: {r.gates}" for r in shown.itertuples() if r.gates)


def claim_verdicts(comparisons: pd.DataFrame) -> pd.DataFrame:
    """Fold comparisons into one row per claim.

    A claim *holds* when every comparison of it holds, *fails* when any fails, is *untestable*
    when none fails but one could not have shown the effect (a failed validity gate,
    :mod:`thesis_lib.stats.gates`), and is *inconclusive* otherwise. Its effect, interval, kind and margin are those of its first
    comparison (the study file lists the headline comparison first); where the verdict is not the
    headline's, ``decided_by`` names the comparisons that gave it (else it is empty).
    Comparisons pre-registered with ``counts: false`` (reported apart, e.g. C3's
    sparse-reward settings) are listed but do not take part in the verdict.
    """
    rows = []
    for claim, grp in comparisons.groupby("claim", sort=False):
        counted = grp[grp["counts"].astype(bool)] if "counts" in grp else grp
        if counted.empty:  # every comparison reported apart: they are all the claim has
            counted = grp
        v = counted["verdict"].tolist()
        verdict = (
            "fails"
            if "fails" in v
            else "untestable"
            if "untestable" in v
            else "holds"
            if all(x == "holds" for x in v)
            else ("inconclusive")
        )
        head = counted.iloc[0]
        deciding = counted[counted["verdict"] == verdict] if head["verdict"] != verdict else grp[:0]
        rows.append(
            {
                "claim": claim,
                "statement": CLAIMS[str(claim)][1],
                "verdict": verdict,
                "effect": head["effect"],
                "ci_low": head["ci_low"],
                "ci_high": head["ci_high"],
                "prob_improvement": head["prob_improvement"],
                "kind": head["kind"],
                "margin": head["margin"],
                "seeds": int(grp["seeds"].min()),
                "settings": int(grp["settings"].max()),
                "decided_by": "; ".join(
                    f"{_name(r)} ({r.metric}): {r.verdict}, effect {r.effect:.3g} "
                    f"[{r.ci_low:.3g}, {r.ci_high:.3g}]"
                    for r in deciding.itertuples()
                ),
                "validity": _validity(counted),
                "comparisons": "; ".join(
                    f"{r.x} vs {r.y} ({r.metric}"
                    + ("" if getattr(r, "counts", True) else ", reported apart")
                    + f"): {r.verdict} [{r.ci_low:.3g}, {r.ci_high:.3g}]"
                    for r in grp.itertuples()
                ),
            }
        )
    return pd.DataFrame(rows)


__all__ = [
    "CLAIMS",
    "EVIDENCE",
    "VERDICT_COLOURS",
    "check_comparison",
    "claim_verdicts",
    "evaluate_comparisons",
]
