"""The thesis's numbers beside ours.

The thesis's result tables ship with the package (``thesis_lib/book/reference/*.csv``, copied
from the transcription in ``shared/reference``; its README lists every oddity kept as printed).
:func:`compare_with_paper` joins one of them with a table we regenerated and adds a column that
says, for every row, what differs and why — the data, the scale, a fixed bug — so no chapter
shows a number without its context.

Used by every chapter notebook that regenerates a thesis table.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from importlib import resources
from typing import Any

import pandas as pd

#: The kinds of deviation a comparison names. ``same`` = same setting as the thesis.
DEVIATION_KINDS = ("same", "data", "scale", "fixed bug", "implementation", "not run")


def reference_tables() -> list[str]:
    """Ids of the packaged reference tables, e.g. ``['table_3_4', 'table_4_1', ...]``."""
    folder = resources.files("thesis_lib.book") / "reference"
    return sorted(p.name[:-4] for p in folder.iterdir() if p.name.endswith(".csv"))


def _table_key(table_id: str) -> str:
    key = table_id.strip().lower().replace(".", "_").replace(" ", "_")
    return key if key.startswith("table_") else f"table_{key}"


def load_reference(table_id: str) -> pd.DataFrame:
    """Load one of the thesis's tables as printed.

    Args:
        table_id: ``"5.3"``, ``"table_5_3"`` or ``"Table 5.3"``; Tables 4.3 and 4.4 share
            ``"4_3_4_4"`` (filter on its ``table`` column).

    Raises:
        ValueError: for an unknown id, listing the available ones.

    >>> load_reference("4.2")["viewpoints"].tolist()
    ['Seen', 'Seen + Unseen', 'Unseen']
    """
    key = _table_key(table_id)
    available = reference_tables()
    if key not in available:
        raise ValueError(f"No reference table '{table_id}'. Available: {', '.join(available)}.")
    with (resources.files("thesis_lib.book") / "reference" / f"{key}.csv").open() as fh:
        # "N/A" is text in Table 3.4 (no technique named), not a missing value.
        return pd.read_csv(fh, keep_default_na=False, na_values=[""])


def _explain(differs: str | Mapping[str, str] | None) -> str:
    if differs is None:
        return ""
    if isinstance(differs, str):
        return differs
    unknown = [k for k in differs if k not in DEVIATION_KINDS]
    if unknown:
        raise ValueError(
            f"Unknown deviation kind {unknown[0]!r}. Valid: {', '.join(DEVIATION_KINDS)}."
        )
    return "; ".join(f"{kind}: {why}" if why else kind for kind, why in differs.items())


def compare_with_paper(
    table_id: str,
    ours: pd.DataFrame,
    *,
    on: Sequence[str],
    value: str,
    paper_value: str | None = None,
    differs: str | Mapping[str, str] | None = None,
    where: Mapping[str, Any] | None = None,
) -> pd.DataFrame:
    """Put the thesis's numbers beside ours, with a column saying what differs and why.

    Args:
        table_id: the reference table (see :func:`load_reference`).
        ours: our regenerated table; must hold the key columns ``on`` (labelled as the thesis
            labels them: map names before calling) and ``value``. A column ``differs`` in
            ``ours``, if present, adds a per-row explanation.
        on: key columns shared by both tables.
        value: our value column.
        paper_value: the thesis's value column (default: ``value``).
        differs: what differs for every row, as free text or as ``{kind: why}`` with kinds
            from :data:`DEVIATION_KINDS`, e.g. ``{"data": "MuJoCo v5, not D4RL PyBullet",
            "scale": "2k of 100k iterations"}``.
        where: equality filters applied to the reference first, e.g. ``{"table": 4.3}``.

    Returns:
        One row per key present in either table, columns ``[*on, "paper", "ours",
        "difference", "what differs"]``. Rows the thesis has but we did not run say
        ``not run`` in ``what differs``; rows only we have leave ``paper`` empty.

    Raises:
        ValueError: a key or value column missing from either table (listing what exists).
    """
    paper = load_reference(table_id)
    paper_value = paper_value or value
    on = list(on)
    for name, frame, cols in (
        ("thesis table", paper, [*on, paper_value]),
        ("our table", ours, [*on, value]),
    ):
        missing = [c for c in cols if c not in frame.columns]
        if missing:
            raise ValueError(
                f"Column(s) {missing} not in the {name} for {table_id}. It has: {', '.join(map(str, frame.columns))}."
            )
    if where:
        for col, val in where.items():
            if col not in paper.columns:
                raise ValueError(
                    f"Cannot filter on '{col}': the thesis table {table_id} has {', '.join(paper.columns)}."
                )
            paper = paper[paper[col].astype(str) == str(val)]
    left = paper[on + [paper_value]].rename(columns={paper_value: "paper"})
    right_cols = on + [value] + (["differs"] if "differs" in ours.columns else [])
    right = ours[right_cols].rename(columns={value: "ours"})
    # Keys compare as text: the thesis prints '85.0' where we may compute 85.
    for frame in (left, right):
        for col in on:
            frame[col] = frame[col].astype(str)
    merged = left.merge(right, on=on, how="outer", indicator=True, sort=False)
    merged["paper"] = pd.to_numeric(merged["paper"], errors="coerce")
    merged["ours"] = pd.to_numeric(merged["ours"], errors="coerce")
    merged["difference"] = merged["ours"] - merged["paper"]
    common = _explain(differs)
    notes = []
    for _, row in merged.iterrows():
        parts = []
        if row["_merge"] == "left_only":
            parts.append("not run")
        elif row["_merge"] == "right_only":
            parts.append("not in the thesis")
        if common and row["_merge"] != "left_only":
            parts.append(common)
        extra = row.get("differs")
        if isinstance(extra, str) and extra:
            parts.append(extra)
        notes.append("; ".join(parts) if parts else "same")
    merged["what differs"] = notes
    return merged[[*on, "paper", "ours", "difference", "what differs"]].reset_index(drop=True)
