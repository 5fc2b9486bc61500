"""D4RL's published data-set statistics, to set our sets beside (``thesis data card``).

Each figure was read from a public source (:data:`SOURCES`) or computed from figures read there
(marked so in :data:`D4RL_STATS`' ``computed`` field): nothing here was recomputed from D4RL's
files, which this project never downloads.

- ``dt-log``: the Decision Transformer's ``download_d4rl_datasets.py`` run on the ``-v2`` files,
  its printed output kept in a fork of kzl/decision-transformer: transitions in closed
  episodes, and raw returns' mean / std (population) / max / min.
- ``tfds``: TensorFlow Datasets' catalog, episodes of each ``v2-*`` config.
- ``d4rl-maze``: D4RL's ``maze_model.py`` (layouts, target cell, sparse reward within 0.5) and
  its issue #85 (maze2d is one continuous stream of about 1M steps, cut where a random goal is
  reached, so its episodes and returns depend on the cutting; no published return statistics).

The normalised figures are ``100 (R - random) / (expert - random)`` with D4RL's reference
returns (:data:`thesis_lib.data.tasks.TASKS`). ``medium-expert`` is D4RL's concatenation of
its medium and expert sets; its statistics are computed here from theirs (pooled over
episodes), and its episode count is TFDS's.

Used by: :func:`thesis_lib.data.card.d4rl_comparison`, ``thesis data card``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

SOURCES: dict[str, str] = {
    "dt-log": "https://github.com/SiliHuang-ai/IDT/blob/96e81ac560b44830a53d869b518a3919a3f43fef/"
    "gym/data/download_d4rl_datasets.py (output of kzl/decision-transformer's "
    "download_d4rl_datasets.py on the -v2 files)",
    "tfds": "https://www.tensorflow.org/datasets/catalog/d4rl_mujoco_hopper (and _walker2d, "
    "_halfcheetah): episodes of the v2-* configs",
    "d4rl-maze": "https://github.com/Farama-Foundation/D4RL/blob/master/d4rl/pointmaze/"
    "maze_model.py and https://github.com/Farama-Foundation/D4RL/issues/85",
}

#: The band a set of ours must fall in beside D4RL's (issue #34): the normalised mean within
#: this many points of D4RL's, and a normalised std of at least this share of D4RL's.
MEAN_BAND = 10.0
STD_SHARE = 0.5
#: The episodes a set needs before its spread is judged against D4RL's: D4RL's sets hold
#: 1,000 to 3,214, and part of their spread comes from rare failed episodes (halfcheetah-medium:
#: 40.7 +- 2.9 with a minimum of -0.2), which a set of 20 seldom holds. A smaller set's verdict
#: is printed with the size that would hold enough episodes (:func:`band_transitions`).
BAND_MIN_EPISODES = 100


@dataclass(frozen=True)
class D4RLStats:
    """One D4RL data set's published statistics (normalised returns; ``None``: not published).

    Attributes:
        name: D4RL's id, e.g. ``hopper-medium-v2``.
        transitions: transitions (in closed episodes, as the DT loader counts them).
        episodes: episodes (TFDS's count).
        mean: normalised return, mean over episodes.
        std: its standard deviation (population).
        min: the lowest episode's.
        max: the highest episode's.
        source: keys of :data:`SOURCES`.
        computed: what was computed here rather than read.
    """

    name: str
    transitions: int | None
    episodes: int | None
    mean: float | None
    std: float | None
    min: float | None
    max: float | None
    source: tuple[str, ...]
    computed: str = ""

    @property
    def mean_length(self) -> float | None:
        """Transitions per episode (computed)."""
        if self.transitions is None or not self.episodes:
            return None
        return self.transitions / self.episodes


# D4RL's reference returns (random, expert), as in tasks.TASKS, for the raw-to-normalised step.
_REF = {
    "hopper": (-20.272305, 3234.3),
    "walker2d": (1.629008, 4592.3),
    "halfcheetah": (-280.178953, 12135.0),
}

# Raw figures read from dt-log (transitions, mean, std, max, min) and TFDS (episodes).
_RAW: dict[tuple[str, str], tuple[int, int, float, float, float, float]] = {
    ("halfcheetah", "medium"): (1_000_000, 1000, 4770.33, 355.75, 5309.38, -310.23),
    ("halfcheetah", "medium-replay"): (202_000, 202, 3093.29, 1680.69, 4985.14, -638.49),
    ("halfcheetah", "expert"): (1_000_000, 1000, 10656.43, 441.68, 11252.04, 2045.83),
    ("hopper", "medium"): (999_906, 2187, 1422.06, 378.95, 3222.36, 315.87),
    ("hopper", "medium-replay"): (402_000, 2041, 467.30, 511.03, 3192.93, -1.44),
    ("hopper", "expert"): (999_494, 1028, 3511.36, 328.59, 3759.08, 1645.28),
    ("walker2d", "medium"): (999_995, 1191, 2852.09, 1095.44, 4226.94, -6.61),
    ("walker2d", "medium-replay"): (302_000, 1093, 682.70, 895.96, 4132.00, -50.20),
    ("walker2d", "expert"): (999_214, 1001, 4920.51, 136.39, 5011.69, 763.42),
}
#: TFDS's episodes of the medium-expert configs.
_ME_EPISODES = {"hopper": 3214, "walker2d": 2191, "halfcheetah": 2000}


def _normalised(task: str, tier: str) -> D4RLStats:
    n, eps, mean, std, hi, lo = _RAW[(task, tier)]
    rmin, rmax = _REF[task]
    scale = 100.0 / (rmax - rmin)
    return D4RLStats(
        f"{task}-{tier}-v2",
        n,
        eps,
        (mean - rmin) * scale,
        std * scale,
        (lo - rmin) * scale,
        (hi - rmin) * scale,
        ("dt-log", "tfds"),
        "normalised from dt-log's raw returns",
    )


def _pooled(task: str) -> D4RLStats:
    m, e = _normalised(task, "medium"), _normalised(task, "expert")
    assert m.episodes and e.episodes and m.transitions and e.transitions
    assert m.mean is not None and e.mean is not None and m.std is not None and e.std is not None
    nm, ne = m.episodes, e.episodes
    mean = (nm * m.mean + ne * e.mean) / (nm + ne)
    second = (nm * (m.std**2 + m.mean**2) + ne * (e.std**2 + e.mean**2)) / (nm + ne)
    return D4RLStats(
        f"{task}-medium-expert-v2",
        m.transitions + e.transitions,
        _ME_EPISODES[task],
        mean,
        math.sqrt(max(second - mean**2, 0.0)),
        min(m.min or 0.0, e.min or 0.0),
        max(m.max or 0.0, e.max or 0.0),
        ("dt-log", "tfds"),
        "pooled from the medium and expert rows (D4RL's medium-expert concatenates them)",
    )


def _maze(layout: str) -> D4RLStats:
    return D4RLStats(
        f"maze2d-{layout}-{'v0' if layout == 'open' else 'v1'}",
        1_000_000 if layout == "umaze" else None,
        None,
        None,
        None,
        None,
        None,
        ("d4rl-maze",),
        "no return statistics are published: one continuous stream cut at random goals",
    )


#: D4RL's statistics by our ``(task, tier)``.
D4RL_STATS: dict[tuple[str, str], D4RLStats] = {
    **{k: _normalised(*k) for k in _RAW},
    **{(t, "medium-expert"): _pooled(t) for t in _REF},
    **{(f"maze2d-{m}", "expert"): _maze(m) for m in ("umaze", "medium", "large", "open")},
}


def d4rl_stats(task: str, tier: str) -> D4RLStats | None:
    """D4RL's published statistics for our ``task``/``tier``, or ``None`` where D4RL has no
    such set (``random`` tiers are not tabulated here; ant and InvertedDoublePendulum are not
    D4RL ``-v2`` sets with published figures).

    >>> s = d4rl_stats("hopper", "medium")
    >>> round(s.mean, 1), round(s.std, 1), round(s.max, 1), s.episodes
    (44.3, 11.6, 99.6, 2187)
    """
    return D4RL_STATS.get((task, tier))


def in_band(mean: float, std: float, ref: D4RLStats) -> tuple[bool, str]:
    """Whether our normalised ``mean``/``std`` fall in the band around ``ref``
    (:data:`MEAN_BAND`, :data:`STD_SHARE`), and a short reason.

    >>> ok, why = in_band(40.0, 8.0, d4rl_stats("hopper", "medium"))
    >>> ok, why
    (True, 'mean 40.0 within 10 of 44.3; std 8.0 >= 0.5 x 11.6')
    """
    if ref.mean is None or ref.std is None:
        return False, "D4RL publishes no return statistics for this set"
    near = abs(mean - ref.mean) <= MEAN_BAND
    spread = std >= STD_SHARE * ref.std
    why = (
        f"mean {mean:.1f} {'within' if near else 'not within'} {MEAN_BAND:g} of {ref.mean:.1f}; "
        f"std {std:.1f} {'>=' if spread else '<'} {STD_SHARE:g} x {ref.std:.1f}"
    )
    return near and spread, why


def band_transitions(n_transitions: int, n_episodes: int) -> int | None:
    """The size (transitions, rounded up to 10k) at which a set like this one, of
    ``n_transitions`` in ``n_episodes`` episodes, would hold :data:`BAND_MIN_EPISODES`; ``None``
    where it holds that many already.

    >>> band_transitions(20_000, 20), band_transitions(20_000, 44), band_transitions(20_000, 134)
    (100000, 50000, None)
    """
    if n_episodes <= 0:
        raise ValueError(f"n_episodes must be positive, got {n_episodes}")
    if n_episodes >= BAND_MIN_EPISODES:
        return None
    need = n_transitions * BAND_MIN_EPISODES / n_episodes
    return int(-(-need // 10_000) * 10_000)


__all__ = [
    "BAND_MIN_EPISODES",
    "D4RL_STATS",
    "MEAN_BAND",
    "SOURCES",
    "STD_SHARE",
    "D4RLStats",
    "band_transitions",
    "d4rl_stats",
    "in_band",
]
