"""What a Minari id is (``namespace/task/tier-vN``) and the reference returns it is scored with.

The part of :mod:`thesis_lib.data.minari_sets` that the score normalisation
(:func:`thesis_lib.data.normalized_score`) needs: reading an id, D4RL's reference returns of
the ``D4RL/…`` ids (:data:`D4RL_REFERENCES`), and a downloaded set's own metadata. It sits below
:mod:`~thesis_lib.data.scores` and :mod:`~thesis_lib.data.minari_sets` (which re-exports it),
and imports only :mod:`~thesis_lib.data.storage`.
"""

from __future__ import annotations

import re
from typing import Any

from .storage import find_dataset, missing_message

__all__ = [
    "D4RL_REFERENCES",
    "is_minari_id",
    "minari_id_parts",
    "minari_metadata",
    "reference_returns",
]

_ID = re.compile(r"^(?P<ns>[\w\-]+)/(?P<task>[\w\-]+)/(?P<tier>[\w\-]+)-v(?P<version>\d+)$")

_ADROIT_MIN = {"pen": 96.262799, "hammer": -274.856578, "relocate": -6.425911, "door": -56.512833}
_ADROIT_MAX = {
    "pen": 3076.8331017826877,
    "hammer": 12794.134825156867,
    "relocate": 4233.877797728884,
    "door": 2880.5693087298737,
}

#: D4RL's reference returns (normalised score 0 and 100) of the Minari ``D4RL/…`` ids, as
#: ``{"D4RL/<task>/<tier>": (ref_min, ref_max, d4rl_name)}`` (any version of the id).
#: Carried over from D4RL's ``d4rl/infos.py`` (``REF_MIN_SCORE`` / ``REF_MAX_SCORE``; the
#: Adroit v1 entries copy the ``<task>-human-v0`` numbers, the AntMaze v2 and Kitchen v0
#: entries are 0 and 1, 0 and 4): Minari's D4RL sets are the D4RL data re-recorded, and the
#: thesis's Tables 5.3 and 5.5 are in D4RL's terms.
D4RL_REFERENCES: dict[str, tuple[float, float, str]] = {
    **{
        f"D4RL/{t}/{tier}": (_ADROIT_MIN[t], _ADROIT_MAX[t], f"{t}-{tier}-v1")
        for t in ("pen", "door", "hammer", "relocate")
        for tier in ("human", "cloned", "expert")
    },
    **{
        f"D4RL/kitchen/{tier}": (0.0, 4.0, f"kitchen-{tier}-v0")
        for tier in ("complete", "mixed", "partial")
    },
    **{
        f"D4RL/antmaze/{tier}": (0.0, 1.0, f"antmaze-{tier}-v2")
        for tier in (
            "umaze",
            "umaze-diverse",
            "medium-play",
            "medium-diverse",
            "large-play",
            "large-diverse",
        )
    },
}


def is_minari_id(name: str) -> bool:
    """Whether ``name`` reads as a Minari id ``namespace/task/tier-vN`` (not ``task/tier``).

    Example:
        >>> is_minari_id("D4RL/door/human-v2"), is_minari_id("hopper/medium")
        (True, False)
    """
    return isinstance(name, str) and _ID.match(name) is not None


def minari_id_parts(dataset_id: str) -> tuple[str, str, str, int]:
    """``(namespace, task, tier, version)`` of a Minari id.

    Example:
        >>> minari_id_parts("D4RL/antmaze/umaze-diverse-v1")
        ('D4RL', 'antmaze', 'umaze-diverse', 1)

    Raises:
        ValueError: ``dataset_id`` is not a Minari id (the message shows both kinds of name).
    """
    m = _ID.match(dataset_id)
    if m is None:
        raise ValueError(
            f"Data set {dataset_id!r} is neither 'task/tier' (e.g. 'hopper/medium') nor a Minari "
            "id 'namespace/task/tier-vN' (e.g. 'D4RL/door/human-v2')."
        )
    return m["ns"], m["task"], m["tier"], int(m["version"])


def reference_returns(
    dataset_id: str, metadata: dict[str, Any] | None = None
) -> tuple[float, float] | None:
    """``(ref_min, ref_max)`` of a Minari id: D4RL's (:data:`D4RL_REFERENCES`) when listed, else
    the data set's own ``ref_min_score``/``ref_max_score`` metadata, else ``None``.

    Example:
        >>> reference_returns("D4RL/door/human-v2")
        (-56.512833, 2880.5693087298737)
    """
    ns, task, tier, _ = minari_id_parts(dataset_id)
    ref = D4RL_REFERENCES.get(f"{ns}/{task}/{tier}")
    if ref is not None:
        return ref[0], ref[1]
    md = metadata if metadata is not None else minari_metadata(dataset_id)
    lo, hi = md.get("ref_min_score"), md.get("ref_max_score")
    if lo is None or hi is None:
        return None
    return float(lo), float(hi)


def minari_metadata(dataset_id: str) -> dict[str, Any]:
    """The metadata Minari stored with a downloaded data set (``data/metadata.json``, read).

    Raises:
        FileNotFoundError: the data set is not downloaded; names the id and where Minari looks.
    """
    from minari.dataset.minari_storage import MinariStorage  # lazy: minari

    path = find_dataset(dataset_id)
    if path is None:
        raise FileNotFoundError(missing_message(dataset_id))
    return dict(MinariStorage.read(path / "data").metadata)
