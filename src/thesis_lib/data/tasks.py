"""Task registry, data-set ids and D4RL reference scores.

Every data set this package makes has an id ``thesis/<task>/<tier>-v0`` at the smoke size
(``thesis-1m/…`` at D4RL's 1M, :func:`size_namespace`; Minari's ``namespace/dataset_name-vN``
grammar). :func:`parse_dataset_id` and
:func:`gen_dataset_id` are the parse/generate pair.

Used by the sequence-model chapters (HDT 5.2, Decision Mamba 5.3) and by DEFENDER 4.3
(InvertedDoublePendulum).
"""

from __future__ import annotations

import difflib
import re
from dataclasses import dataclass, field
from typing import Any, Literal

NAMESPACE = "thesis"
VERSION = 0

Kind = Literal["mujoco", "maze", "robotics"]


@dataclass(frozen=True)
class TaskSpec:
    """One environment the package can make data for.

    Attributes:
        name: short name used in ids (``hopper``, ``maze2d-umaze`` …).
        env_id: the Gymnasium id rolled out (``Hopper-v5`` …).
        kind: ``mujoco`` (trained linear experts), ``maze`` (scripted PointMaze expert) or
            ``robotics`` (environment checked only; no expert here).
        tiers: the tiers that can be generated for this task.
        ref_min_score: D4RL's random-policy return (normalised score 0), or ``None``.
        ref_max_score: D4RL's expert return (normalised score 100), or ``None``.
        max_episode_steps: episode limit used when rolling out.
        env_kwargs: extra ``gymnasium.make`` arguments.
    """

    name: str
    env_id: str
    kind: Kind
    tiers: tuple[str, ...]
    ref_min_score: float | None
    ref_max_score: float | None
    max_episode_steps: int
    env_kwargs: dict[str, Any] = field(default_factory=dict)


LOCO_TIERS = ("random", "medium", "medium-replay", "medium-expert", "expert")
MAZE_TIERS = ("expert", "random")

# AntMaze as D4RL: the episode ends at the goal, so the return is the success (0 or 1).
_ANT = {"continuing_task": False}

# D4RL reference returns (d4rl/infos.py REF_MIN_SCORE / REF_MAX_SCORE).
TASKS: dict[str, TaskSpec] = {
    "hopper": TaskSpec("hopper", "Hopper-v5", "mujoco", LOCO_TIERS, -20.272305, 3234.3, 1000),
    "walker2d": TaskSpec("walker2d", "Walker2d-v5", "mujoco", LOCO_TIERS, 1.629008, 4592.3, 1000),
    "halfcheetah": TaskSpec(
        "halfcheetah", "HalfCheetah-v5", "mujoco", LOCO_TIERS, -280.178953, 12135.0, 1000
    ),
    "ant": TaskSpec("ant", "Ant-v5", "mujoco", LOCO_TIERS, -325.6, 3879.7, 1000),
    # No D4RL reference: the normalised score is undefined (DEFENDER reports raw returns).
    "inverted-double-pendulum": TaskSpec(
        "inverted-double-pendulum",
        "InvertedDoublePendulum-v5",
        "mujoco",
        LOCO_TIERS,
        None,
        None,
        1000,
    ),
    # D4RL maze2d episode limits: umaze 300, medium 600, large 800.
    "maze2d-umaze": TaskSpec(
        "maze2d-umaze", "PointMaze_UMaze-v3", "maze", MAZE_TIERS, 23.85, 161.86, 300
    ),
    "maze2d-medium": TaskSpec(
        "maze2d-medium", "PointMaze_Medium-v3", "maze", MAZE_TIERS, 13.13, 277.39, 600
    ),
    "maze2d-large": TaskSpec(
        "maze2d-large", "PointMaze_Large-v3", "maze", MAZE_TIERS, 6.7, 273.99, 800
    ),
    # D4RL's infos.py: maze2d-open-v0 min 0.01, max 20.66 (its episodes last 150 steps).
    "maze2d-open": TaskSpec(
        "maze2d-open", "PointMaze_Open-v3", "maze", MAZE_TIERS, 0.01, 20.66, 150
    ),
    # Environment checks + random data only: no scripted or trained expert is feasible here
    # on 2 CPU cores (see the data card). References are D4RL's; gymnasium-robotics'
    # Adroit-v1 rewards differ from D4RL's v0, so treat those scores as indicative.
    "antmaze-umaze": TaskSpec(
        "antmaze-umaze", "AntMaze_UMaze-v5", "robotics", ("random",), 0.0, 1.0, 700, _ANT
    ),
    "antmaze-medium": TaskSpec(
        "antmaze-medium",
        "AntMaze_Medium_Diverse_GR-v5",
        "robotics",
        ("random",),
        0.0,
        1.0,
        1000,
        _ANT,
    ),
    "antmaze-large": TaskSpec(
        "antmaze-large",
        "AntMaze_Large_Diverse_GR-v5",
        "robotics",
        ("random",),
        0.0,
        1.0,
        1000,
        _ANT,
    ),
    "pen": TaskSpec("pen", "AdroitHandPen-v1", "robotics", ("random",), 96.262799, 3076.833, 100),
    "door": TaskSpec(
        "door", "AdroitHandDoor-v1", "robotics", ("random",), -56.512833, 2880.5693, 200
    ),
    "hammer": TaskSpec(
        "hammer", "AdroitHandHammer-v1", "robotics", ("random",), -274.856578, 12794.134, 200
    ),
    "relocate": TaskSpec(
        "relocate", "AdroitHandRelocate-v1", "robotics", ("random",), -6.425911, 4233.877, 200
    ),
    # FrankaKitchen's goals are nested dicts (one entry per sub-task): checked, no data.
    "kitchen": TaskSpec("kitchen", "FrankaKitchen-v1", "robotics", (), 0.0, 4.0, 280),
}

_ID_RE = re.compile(r"^(?P<ns>[\w\-]+)/(?P<task>[\w\-]+)/(?P<tier>[\w\-]+)-v(?P<version>\d+)$")


def _did_you_mean(word: str, options: list[str] | tuple[str, ...]) -> str:
    close = difflib.get_close_matches(word, list(options), n=1)
    return f" Did you mean: '{close[0]}'?" if close else ""


def get_task(task: str) -> TaskSpec:
    """Return the :class:`TaskSpec` of ``task``.

    Raises:
        ValueError: unknown task; the message lists the valid ones.
    """
    if task not in TASKS:
        raise ValueError(
            f"Unknown task '{task}'.{_did_you_mean(task, list(TASKS))} "
            f"Valid tasks: {', '.join(TASKS)}."
        )
    return TASKS[task]


def check_tier(task: str, tier: str) -> None:
    """Raise ``ValueError`` listing the valid tiers when ``tier`` is not one of ``task``'s."""
    spec = get_task(task)
    if not spec.tiers:
        raise ValueError(
            f"No data set can be made for task '{task}' here (environment check only); "
            "see `thesis data card` / the data card for why."
        )
    if tier not in spec.tiers:
        raise ValueError(
            f"Unknown tier '{tier}' for task '{task}'.{_did_you_mean(tier, spec.tiers)} "
            f"Valid tiers: {', '.join(spec.tiers)}."
        )


#: transitions of the smoke-size sets, whose ids keep the plain namespace ``thesis``.
SMOKE_TRANSITIONS = 20_000


def size_namespace(n_transitions: int | None = None) -> str:
    """The namespace of a set of ``n_transitions`` made here, so that sizes never share an id:
    ``thesis`` at the smoke size (20k, or ``None``), ``thesis-1m`` for D4RL's 1M, else
    ``thesis-<n>`` (``k``/``m`` where whole).

    >>> size_namespace(), size_namespace(1_000_000), size_namespace(200_000), size_namespace(1234)
    ('thesis', 'thesis-1m', 'thesis-200k', 'thesis-1234')
    """
    n = SMOKE_TRANSITIONS if n_transitions is None else int(n_transitions)
    if n == SMOKE_TRANSITIONS:
        return NAMESPACE
    if n % 1_000_000 == 0:
        return f"{NAMESPACE}-{n // 1_000_000}m"
    if n % 1000 == 0:
        return f"{NAMESPACE}-{n // 1000}k"
    return f"{NAMESPACE}-{n}"


def is_our_namespace(namespace: str) -> bool:
    """Whether ``namespace`` is one :func:`size_namespace` makes (``thesis``, ``thesis-1m`` …)."""
    return re.fullmatch(rf"{NAMESPACE}(-\d+[km]?)?", namespace) is not None


def gen_dataset_id(
    task: str, tier: str, version: int = VERSION, n_transitions: int | None = None
) -> str:
    """Build the id of a data set made here; the size is in the namespace
    (:func:`size_namespace`).

    >>> gen_dataset_id("hopper", "medium"), gen_dataset_id("hopper", "medium", n_transitions=10**6)
    ('thesis/hopper/medium-v0', 'thesis-1m/hopper/medium-v0')
    """
    check_tier(task, tier)
    return f"{size_namespace(n_transitions)}/{task}/{tier}-v{version}"


def parse_dataset_id(dataset_id: str) -> tuple[str, str, str, int]:
    """Split ``namespace/task/tier-vN`` into its four parts.

    >>> parse_dataset_id("thesis/hopper/medium-v0")
    ('thesis', 'hopper', 'medium', 0)

    Raises:
        ValueError: the id does not follow the grammar.
    """
    m = _ID_RE.match(dataset_id)
    if m is None:
        raise ValueError(
            f"Data-set id '{dataset_id}' does not read as 'namespace/task/tier-vN', "
            "e.g. 'thesis/hopper/medium-v0' or 'mujoco/hopper/medium-v0'."
        )
    return m["ns"], m["task"], m["tier"], int(m["version"])
