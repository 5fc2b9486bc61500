"""Real Minari data sets by id (``D4RL/door/human-v2`` …) beside the ``task/tier`` sets made here.

A chapter's data-set list may hold either kind of name:

* ``task/tier`` (``hopper/medium``): a set made here by D4RL's recipe
  (:func:`thesis_lib.data.get_dataset`), evaluated in :func:`thesis_lib.data.make_env`'s
  environment and scored with :data:`thesis_lib.data.tasks.TASKS`' references;
* a Minari id ``namespace/task/tier-vN`` (``D4RL/door/human-v2``, ``D4RL/kitchen/complete-v2``,
  ``D4RL/antmaze/umaze-v1``): a download read from ``$MINARI_DATASETS_PATH`` (or
  ``~/.minari/datasets``) by :func:`thesis_lib.data.load`, evaluated in the environment Minari
  recorded for evaluation (``eval_env_spec``, else ``env_spec``) and scored with D4RL's reference
  returns (:data:`D4RL_REFERENCES`).

:func:`dataset_key` names both kinds the same way (``(task, tier)``, e.g. ``("door", "human")``)
so their rows land in the same tables; :func:`open_dataset` loads either;
:func:`env_name` is what the offline runner is given as ``task`` (the task for ``task/tier``,
the id itself for a Minari id), and :func:`make_minari_env`, :func:`reference_returns` and
:func:`minari_step_cap` are what the runner does with an id.

Reading an id and its reference returns (:func:`is_minari_id`, :func:`reference_returns`,
:data:`D4RL_REFERENCES`) live in :mod:`thesis_lib.data.minari_ids`, below the score
normalisation, and are re-exported here.

Used by HDT 5.2 (Table 5.3: Adroit, Kitchen) and Decision Mamba 5.3 (Table 5.5: Kitchen,
AntMaze).
"""

from __future__ import annotations

from typing import Any, cast

import gymnasium as gym
from gymnasium.envs.registration import EnvSpec

from .minari_ids import (
    D4RL_REFERENCES,
    is_minari_id,
    minari_id_parts,
    minari_metadata,
    reference_returns,
)
from .recipe import get_dataset
from .robotics import forget_maze_xml, register_robotics
from .storage import load

__all__ = [
    "D4RL_REFERENCES",
    "SPARSE_FAMILIES",
    "data_difference",
    "dataset_key",
    "env_name",
    "is_minari_id",
    "make_minari_env",
    "minari_step_cap",
    "open_dataset",
    "reference_returns",
]

#: Task families whose reward is sparse (a sub-task done, the goal reached): evaluated over
#: whole episodes, as Maze2D (:func:`thesis_lib.seq.evaluation.eval_step_cap`), since D4RL's
#: references assume them and a capped episode scores 0.
SPARSE_FAMILIES: tuple[str, ...] = ("antmaze", "kitchen", "pointmaze")

#: Environment arguments added to the recovered evaluation environment, per family. AntMaze:
#: the episode ends at the goal, so the return is the success (0 or 1) as D4RL scores it
#: (Minari records ``continuing_task=True``, under which the return counts steps at the goal).
_EVAL_KWARGS: dict[str, dict[str, Any]] = {"antmaze": {"continuing_task": False}}


def dataset_key(name: str) -> tuple[str, str]:
    """``(task, tier)`` of a data-set name: ``"hopper/medium"`` or ``"D4RL/door/human-v2"``.

    A Minari id keeps its task and tier (the namespace and version are dropped), so its rows
    carry the names the thesis's tables use.

    Example:
        >>> dataset_key("hopper/medium"), dataset_key("D4RL/antmaze/umaze-diverse-v1")
        (('hopper', 'medium'), ('antmaze', 'umaze-diverse'))

    Raises:
        ValueError: neither kind of name.
    """
    if is_minari_id(name):
        _, task, tier, _ = minari_id_parts(name)
        return task, tier
    if not isinstance(name, str) or name.count("/") != 1:
        raise ValueError(
            "Expect data sets as 'task/tier' (e.g. 'hopper/medium') or as a Minari id "
            f"'namespace/task/tier-vN' (e.g. 'D4RL/door/human-v2'); got {name!r}."
        )
    task, tier = name.split("/")
    return task, tier


def env_name(name: str) -> str:
    """What the offline runner is given as ``task``: the task of ``task/tier``, else the id."""
    return name if is_minari_id(name) else dataset_key(name)[0]


def minari_step_cap(dataset_id: str, cap: int | None) -> int | None:
    """The evaluation step cap of a Minari id: ``None`` (whole episodes) for a sparse family
    (:data:`SPARSE_FAMILIES`), else ``cap``.

    Example:
        >>> minari_step_cap("D4RL/door/human-v2", 100), minari_step_cap("D4RL/kitchen/mixed-v2", 100)
        (100, None)
    """
    _, task, _, _ = minari_id_parts(dataset_id)
    return None if task in SPARSE_FAMILIES else cap


def make_minari_env(dataset_id: str, **kwargs: Any) -> Any:
    """The evaluation environment of a Minari data set, as Minari recovers it.

    Minari's ``eval_env_spec`` when the data set records one, else its ``env_spec`` (what
    ``minari.load_dataset(id).recover_environment(eval_env=True)`` returns), with the family's
    D4RL evaluation arguments (AntMaze: ``continuing_task=False``) and ``kwargs`` on top.

    Raises:
        FileNotFoundError: the data set is not downloaded; names the id and where Minari looks.
        ValueError: the data set records no environment.
    """
    register_robotics()
    md = minari_metadata(dataset_id)
    spec_json = md.get("eval_env_spec") or md.get("env_spec")
    if not spec_json:
        raise ValueError(f"Data set '{dataset_id}' records no environment to evaluate in.")
    spec_json = (  # gymnasium 1.0 dropped these fields (as minari.MinariDataset does)
        str(spec_json)
        .replace('"order_enforce": true,', "")
        .replace('"apply_api_compatibility": false,', "")
        .replace('"autoreset": false, ', "")
    )
    spec = EnvSpec.from_json(spec_json)
    _, task, _, _ = minari_id_parts(dataset_id)
    return forget_maze_xml(gym.make(spec, **(_EVAL_KWARGS.get(task, {}) | kwargs)))


def open_dataset(name: str, dataset_size: str = "smoke", n_transitions: int | None = None) -> Any:
    """The :class:`~thesis_lib.data.OfflineDataset` of a data-set name (either kind).

    ``task/tier``: :func:`thesis_lib.data.get_dataset` (made on first use, at ``dataset_size``
    or ``n_transitions``). A Minari id: :func:`thesis_lib.data.load`; ``dataset_size`` does
    not apply, ``n_transitions`` keeps the first whole episodes up to that many transitions,
    and the reference returns are :func:`reference_returns` (D4RL's for a ``D4RL/…`` id; the
    data set's own metadata stays in ``metadata``).

    Raises:
        FileNotFoundError: a Minari id that is not downloaded; the message names the id, the
            folders searched and ``minari download``.
    """
    if not is_minari_id(name):
        task, tier = dataset_key(name)
        return get_dataset(task, tier, cast(Any, dataset_size), n_transitions=n_transitions)
    ds = load(name)
    ref = reference_returns(name, ds.metadata)
    if ref is not None:  # the data card's normalised scores as the evaluation's: D4RL's
        ds.ref_min_score, ds.ref_max_score = ref
    if n_transitions is not None:
        kept: list[Any] = []
        total = 0
        for e in ds.episodes:
            if kept and total + len(e) > n_transitions:
                break
            kept.append(e)
            total += len(e)
        ds.episodes = kept
    return ds


#: What differs from the thesis's data, per kind of name (the chapters' "what differs" column).
_MADE_HERE = (
    "data sets made here (MuJoCo v5 / PointMaze), the thesis used D4RL (PyBullet locomotion)"
)
_MINARI = (
    "Minari's re-recordings of D4RL for the Minari ids (gymnasium-robotics environments: Adroit "
    "v1 rewards, FrankaKitchen-v1, AntMaze), the thesis used D4RL's originals"
)


def data_difference(names: list[str]) -> str:
    """The "what differs: data" text of a chapter's data-set list (made here, Minari ids, both).

    Example:
        >>> data_difference(["hopper/medium"]) == _MADE_HERE
        True
        >>> data_difference(["D4RL/door/human-v2"]).startswith("Minari's re-recordings")
        True
    """
    kinds = {is_minari_id(n) for n in names}
    return "; ".join(
        ([_MADE_HERE] if False in kinds else []) + ([_MINARI] if True in kinds else [])
    )
