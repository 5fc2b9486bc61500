"""Validity gates: a verdict only where the study could have shown the effect (issue #35).

A comparison's interval says how sure the difference is; a gate says whether the set-up could
have shown a difference at all. Each gate is pre-registered (in a study file's ``gates``, or,
for the v1 studies, in the post-hoc review ``params/<chapter>.gates.yml``) and names the
comparisons it guards; a comparison with a failed gate gets the verdict ``untestable``, with the
gate and its figure, whatever its interval says.

Gate kinds (every gate has ``kind``, ``claim`` and ``why``; ``x``, ``y``, ``label`` and
``setting`` narrow the comparisons it applies to, ``setting`` by substring):

- ``level``: ``method`` (default: both ``x`` and ``y``) scores at least ``low`` and/or at most
  ``high`` on ``metric`` (default: the comparison's), in *each* setting of the comparison
  (mean over seeds). ``low``/``high`` may be a number or a ``{setting: number}`` mapping (a floor
  per setting). With ``relative_to: <method>`` and ``slack``, the bound is that method's mean
  minus ``slack`` (e.g. DT >= BC - 5). A floor or a ceiling is a ``level`` gate with both bounds
  (a rate between 10% and 90% of its range). ``require: either`` (default ``each``) fails a
  bound only where *every* method is past it: the pair sits at the floor together (no method
  reaches ``low``) or at the ceiling together (every method above ``high``). That is the gate
  of a claim that one method learns and the other does not: with ``each`` the claim's own
  predicted outcome (the other method at the floor) would withhold its verdict.
- ``control``: ``method`` must beat ``control`` on ``metric`` (its interval above 0; e.g. an
  untrained encoder, a shuffled-audio control). ``better: lower`` for a metric where less is
  better (crashes: the interval of ``control - method`` above 0).
- ``fidelity``: ``method``'s row ``parity`` in ``studies/parity/parity.csv`` is at parity with a
  peer implementation.
- ``untestable``: the set-up cannot answer the claim at all (e.g. synthetic data whose rule is
  ours); it always fails, with its ``why``.
- ``none``: no gate applies, and ``why`` says why (e.g. a timing on this CPU); it always passes,
  so that every claim lists its gates.

``comparison_metric`` selects the comparisons on one metric (a claim may compare crashes and
returns); a ``control`` gate with ``control_setting`` takes the control's rows from that setting
(e.g. the same classifier on an untrained encoder's features).

Used by: :func:`thesis_lib.stats.claims.evaluate_comparisons`, the Claims page.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

GATE_KINDS = ("level", "control", "fidelity", "untestable", "none")
#: a level gate's ``require``: every method within the bounds, or not all past the same bound.
LEVEL_REQUIRE = ("each", "either")
_SELECT = ("claim", "x", "y", "label", "setting", "comparison_metric")
_KEYS = {
    "level": {"method", "metric", "low", "high", "relative_to", "slack", "require"},
    "control": {"method", "control", "metric", "control_setting", "better"},
    "fidelity": {"method", "parity"},
    "untestable": set(),
    "none": set(),
}


def check_gate(gate: Mapping[str, Any]) -> None:
    """Raise ``ValueError`` naming what is wrong with one gate spec (read before anything runs)."""
    kind = gate.get("kind")
    if kind not in GATE_KINDS:
        raise ValueError(f"Expect a gate's `kind` to be one of {GATE_KINDS}, actually: {kind!r}")
    for k in ("claim", "why"):
        if not isinstance(gate.get(k), str) or not gate[k]:
            raise ValueError(f"a {kind} gate needs `{k}` (text), got {gate.get(k)!r}")
    allowed = set(_SELECT) | {"kind", "why"} | _KEYS[kind]
    unknown = set(gate) - allowed
    if unknown:
        raise ValueError(
            f"unknown key(s) {sorted(unknown)} in a {kind} gate; valid: {sorted(allowed)}"
        )
    if kind == "level":
        if not any(k in gate for k in ("low", "high", "relative_to")):
            raise ValueError("a level gate needs `low`, `high` or `relative_to`")
        if gate.get("require", "each") not in LEVEL_REQUIRE:
            raise ValueError(
                f"Expect a level gate's `require` to be one of {LEVEL_REQUIRE}, "
                f"actually: {gate.get('require')!r}"
            )
        for k in ("low", "high"):
            v = gate.get(k)
            ok = (
                v is None
                or _number(v)
                or (isinstance(v, Mapping) and all(_number(b) for b in v.values()))
            )
            if not ok:
                raise ValueError(
                    f"Expect a level gate's `{k}` to be a number or {{setting: number}}, actually: {v!r}"
                )
    if kind == "control" and not (gate.get("method") and gate.get("control")):
        raise ValueError("a control gate needs `method` and `control`")
    if kind == "control" and gate.get("better", "higher") not in ("higher", "lower"):
        raise ValueError(
            f"Expect a control gate's `better` to be 'higher' or 'lower', actually: "
            f"{gate.get('better')!r}"
        )
    if kind == "fidelity" and not (gate.get("method") and gate.get("parity")):
        raise ValueError("a fidelity gate needs `method` and `parity` (a row of parity.csv)")


def _number(v: Any) -> bool:
    return isinstance(v, int | float) and not isinstance(v, bool) and np.isfinite(v)


def applies(
    gate: Mapping[str, Any], comparison: Mapping[str, Any], settings: Sequence[str]
) -> bool:
    """Whether ``gate`` guards ``comparison`` (whose settings are ``settings``)."""
    for k in ("claim", "x", "y", "label"):
        if k in gate and str(comparison.get(k, "")) != str(gate[k]):
            return False
    if "comparison_metric" in gate and str(comparison.get("metric")) != str(
        gate["comparison_metric"]
    ):
        return False
    if "setting" in gate and not any(str(gate["setting"]) in s for s in settings):
        return False
    return True


def _setting_means(
    rows: pd.DataFrame, method: str, metric: str, settings: Sequence[str], cols: Mapping[str, str]
) -> dict[str, float]:
    sub = rows[(rows[cols["method"]] == method) & rows[cols["setting"]].isin(list(settings))]
    if sub.empty:
        raise ValueError(f"a gate names method {method!r}, which has no rows in {list(settings)}")
    values = pd.to_numeric(sub[metric], errors="coerce")
    return {str(k): float(v) for k, v in values.groupby(sub[cols["setting"]]).mean().items()}


def _bound(b: Any, setting: str) -> float | None:
    if b is None:
        return None
    if isinstance(b, Mapping):
        return float(b[setting]) if setting in b else None
    return float(b)


def evaluate_gate(
    gate: Mapping[str, Any],
    comparison: Mapping[str, Any],
    rows: pd.DataFrame,
    settings: Sequence[str],
    metric: str,
    cols: Mapping[str, str],
    compare: Callable[..., Any] | None = None,
    parity: pd.DataFrame | None = None,
) -> tuple[bool, str]:
    """``(passed, figure)`` of one gate on one comparison's rows.

    ``figure`` says what was measured against what, e.g.
    ``"level: CLfD success_final 0.013 < 0.1 in 'RL pick (TCN encoder)'"``.
    """
    kind = gate["kind"]
    if kind == "untestable":
        return False, f"untestable: {gate['why']}"
    if kind == "none":
        return True, f"no gate needed: {gate['why']}"
    metric = str(gate.get("metric", comparison.get("metric") or metric))
    if kind == "level":
        methods = [gate["method"]] if gate.get("method") else [comparison["x"], comparison["y"]]
        either = gate.get("require", "each") == "either"
        failed: list[str] = []
        shown: list[str] = []
        ref = (
            _setting_means(rows, gate["relative_to"], metric, settings, cols)
            if gate.get("relative_to")
            else None
        )
        # with `either`: per setting, per method, the bounds it is past ({"low" | "high": figure})
        by_setting: dict[str, list[dict[str, str]]] = {}
        for m in methods:
            means = _setting_means(rows, m, metric, settings, cols)
            for s, v in means.items():
                low = _bound(gate.get("low"), s)
                if ref is not None:
                    rel = ref[s] - float(gate.get("slack", 0.0))
                    low = rel if low is None else max(low, rel)
                high = _bound(gate.get("high"), s)
                shown.append(f"{m} {metric} {v:.3g} in {s!r}")
                past: dict[str, str] = {}
                if low is not None and v < low:
                    past["low"] = f"{m} {metric} {v:.3g} < {low:.3g} in {s!r}"
                if high is not None and v > high:
                    past["high"] = f"{m} {metric} {v:.3g} > {high:.3g} in {s!r}"
                if either:
                    by_setting.setdefault(s, []).append(past)
                else:
                    failed += past.values()
        for entries in by_setting.values():
            for side in ("low", "high"):  # only where every method is past the same bound
                if all(side in e for e in entries):
                    failed += [e[side] for e in entries]
        if failed:
            return False, "level" + (" (both)" if either else "") + ": " + "; ".join(failed)
        return True, "level" + (" (either)" if either else "") + ": " + "; ".join(shown)
    if kind == "control":
        if compare is None:
            raise ValueError("a control gate needs the comparison function")
        control, data = str(gate["control"]), rows
        if gate.get("control_setting"):  # the control's rows from another setting, as this one
            if len(settings) != 1:
                raise ValueError(
                    "a control gate with control_setting needs a one-setting comparison"
                )
            m, st = cols["method"], cols["setting"]
            twin = rows[(rows[m] == control) & (rows[st] == gate["control_setting"])]
            if twin.empty:
                raise ValueError(f"no rows of {control!r} in {gate['control_setting']!r}")
            control = f"{control} ({gate['control_setting']})"
            data = pd.concat([rows, twin.assign(**{m: control, st: settings[0]})])
        better, worse = str(gate["method"]), control
        if gate.get("better", "higher") == "lower":  # less is better: control - method > 0
            better, worse = worse, better
        c = compare(data, better, worse, metric, settings=list(settings))
        figure = (
            f"control: {better} - {worse} on {metric} = {c.effect:.3g} "
            f"[{c.ci_low:.3g}, {c.ci_high:.3g}]"
            + (" (lower is better)" if gate.get("better") == "lower" else "")
        )
        return bool(c.ci_low > 0), figure
    # fidelity
    name = str(gate["parity"])
    if parity is None or name not in set(parity.get("comparison", [])):
        return False, f"fidelity: no parity run {name!r} for {gate['method']} (thesis parity)"
    row = parity[parity["comparison"] == name].iloc[0]
    ok = str(row.get("parity")).strip().lower() == "true"
    figure = (
        f"fidelity: {gate['method']} {name}: {'at parity' if ok else 'not at parity'} with "
        f"{row.get('peer_name', 'the peer')}, difference {float(row['difference']):.3g} "
        f"[{float(row['ci_low']):.3g}, {float(row['ci_high']):.3g}]"
    )
    return ok, figure


def load_gates(path: str | Path) -> list[dict[str, Any]]:
    """The gates of a review file (``gates: [...]``), each checked."""
    return load_review(path)[0]


#: What a review file's ``retest`` entry may change in a comparison (and must say why).
RETEST_KEYS = {"kind", "margin"}


def load_review(path: str | Path) -> tuple[list[dict[str, Any]], list[dict[str, Any]]]:
    """``(gates, retests)`` of a review file: ``gates`` (each checked by :func:`check_gate`) and
    ``retest``, post-hoc corrections of a comparison's test (``kind``, ``margin``), each with
    the selectors of a gate (``claim``, ``x``, ``y``, ``label``) and a ``why``; e.g. an
    equivalence claim registered one-sided, retested by TOST."""
    import yaml

    p = Path(path)
    data = yaml.safe_load(p.read_text()) or {}
    if not isinstance(data, Mapping) or not isinstance(data.get("gates", []), list):
        raise ValueError(f"{p}: expect a mapping with a list `gates`")
    unknown = set(data) - {"gates", "retest"}
    if unknown:
        raise ValueError(f"{p}: unknown key(s) {sorted(unknown)}; valid: gates, retest")
    for g in data.get("gates", []):
        try:
            check_gate(g)
        except ValueError as e:
            raise ValueError(f"{e} (in {p})") from None
    retests = [dict(r) for r in data.get("retest", []) or []]
    for r in retests:
        bad = set(r) - set(_SELECT) - RETEST_KEYS - {"why"}
        if bad or "claim" not in r or not r.get("why") or not (set(r) & RETEST_KEYS):
            raise ValueError(
                f"{p}: a retest needs `claim`, `why` and one of {sorted(RETEST_KEYS)}; "
                f"selectors {list(_SELECT)}; got {r}"
            )
    return [dict(g) for g in data.get("gates", [])], retests


def apply_retests(
    comparisons: Sequence[Mapping[str, Any]], retests: Sequence[Mapping[str, Any]]
) -> list[dict[str, Any]]:
    """``comparisons`` with each matching retest's ``kind``/``margin`` applied, and its
    ``why`` kept as the comparison's ``override``."""
    out = []
    for c in comparisons:
        c = dict(c)
        for r in retests:
            if all(str(c.get(k, "")) == str(r[k]) for k in ("claim", "x", "y", "label") if k in r):
                c.update({k: r[k] for k in RETEST_KEYS if k in r})
                c["override"] = (
                    f"retested post hoc ({', '.join(f'{k} {r[k]}' for k in RETEST_KEYS if k in r)}): {r['why']}"
                )
        out.append(c)
    return out


__all__ = [
    "GATE_KINDS",
    "RETEST_KEYS",
    "applies",
    "apply_retests",
    "check_gate",
    "evaluate_gate",
    "load_gates",
    "load_review",
]
