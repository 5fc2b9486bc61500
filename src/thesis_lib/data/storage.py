"""Minari-format storage: where data sets live, writing them, and loading them as episodes.

Data sets made here and real Minari/D4RL data sets load through the same :func:`load`
and come back as the same :class:`Episode` objects.

Where data sets live (searched in this order):

1. ``$THESIS_DATA_DIR`` when set (our generated sets are written there too);
2. Minari's own root: ``$MINARI_DATASETS_PATH`` when set, else ``~/.minari/datasets``.

Without ``THESIS_DATA_DIR``, generated sets go to Minari's root, so ``minari list local``
and ``minari.load_dataset("thesis/hopper/medium-v0")`` see them too.

Used by HDT 5.2, Decision Mamba 5.3 and DEFENDER 4.3.
"""

from __future__ import annotations

import contextlib
import json
import os
import re
import shutil
import tempfile
import warnings
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np

from thesis_lib.paths import data_dir, minari_root  # every on-disk location: book.paths

from .envs import make_env
from .robotics import forget_maze_xml
from .tasks import NAMESPACE, TASKS, is_our_namespace, parse_dataset_id


class EpisodeFormatError(ValueError):
    """An episode whose arrays do not fit together (e.g. observations ≠ actions + 1)."""


def search_dirs() -> list[Path]:
    """Roots searched by :func:`load`, in order (duplicates removed)."""
    out: list[Path] = []
    for d in (data_dir(), minari_root()):
        if d not in out:
            out.append(d)
    return out


_MINARI_ID = re.compile(r"^([\w\-]+/)*[\w\-]+-v\d+$")


def check_minari_id(dataset_id: str) -> None:
    """Raise ``ValueError`` unless ``dataset_id`` reads as Minari's ``[namespace/]name-vN``."""
    if not _MINARI_ID.match(dataset_id):
        raise ValueError(
            f"Data-set id '{dataset_id}' does not read as 'namespace/task/tier-vN' (ours, e.g. "
            "'thesis/hopper/medium-v0') or Minari's '[namespace/]name-vN' "
            "(e.g. 'mujoco/hopper/medium-v0', 'D4RL/door/human-v2')."
        )


def find_dataset(dataset_id: str) -> Path | None:
    """Directory of ``dataset_id`` (the one holding ``data/``) or ``None``."""
    check_minari_id(dataset_id)
    for root in search_dirs():
        p = root / dataset_id
        if (p / "data" / "metadata.json").exists() or (p / "data" / "main_data.hdf5").exists():
            return p
    return None


@dataclass(frozen=True)
class Episode:
    """One trajectory, whatever data set it came from.

    ``T`` is the number of actions. Observations include the final one, so there are
    ``T + 1`` of them (Minari's convention). For goal-conditioned environments (PointMaze,
    AntMaze: dict observations) ``observations`` is the ``observation`` entry and the goals
    are kept beside it.

    Attributes:
        id: episode index in its data set.
        observations: ``(T + 1, obs_dim)``.
        actions: ``(T, act_dim)``.
        rewards: ``(T,)``.
        terminations: ``(T,)`` bool, the MDP ended (fell over).
        truncations: ``(T,)`` bool, the time limit (or the data-set size) cut it.
        desired_goals: ``(T + 1, goal_dim)`` or ``None``.
        achieved_goals: ``(T + 1, goal_dim)`` or ``None``.
    """

    id: int
    observations: np.ndarray
    actions: np.ndarray
    rewards: np.ndarray
    terminations: np.ndarray
    truncations: np.ndarray
    desired_goals: np.ndarray | None = None
    achieved_goals: np.ndarray | None = None

    def __len__(self) -> int:
        return len(self.rewards)

    @property
    def episode_return(self) -> float:
        """Undiscounted return."""
        return float(np.sum(self.rewards, dtype=np.float64))

    def validate(self, where: str = "") -> None:
        """Raise :class:`EpisodeFormatError` naming the episode if lengths disagree."""
        t = len(self.actions)
        name = f"Episode {self.id}{' of ' + where if where else ''}"
        if len(self.observations) != t + 1:
            raise EpisodeFormatError(
                f"{name} has {len(self.observations)} observations and {t} actions; "
                f"expected {t + 1} observations (actions + 1, the final observation included)."
            )
        for k in ("rewards", "terminations", "truncations"):
            n = len(getattr(self, k))
            if n != t:
                raise EpisodeFormatError(f"{name} has {n} {k} and {t} actions; expected {t}.")


@dataclass
class OfflineDataset:
    """A loaded data set: its episodes plus what Minari knows about it.

    Attributes:
        id: the data-set id.
        episodes: the :class:`Episode` list.
        env_id: Gymnasium id of the environment, when recorded.
        ref_min_score: return of normalised score 0, when recorded.
        ref_max_score: return of normalised score 100, when recorded.
        metadata: the rest of Minari's metadata (``thesis_info`` parsed from JSON).
        path: the directory it was read from.
    """

    id: str
    episodes: list[Episode]
    env_id: str | None
    ref_min_score: float | None
    ref_max_score: float | None
    metadata: dict[str, Any] = field(default_factory=dict)
    path: Path | None = None

    def __len__(self) -> int:
        return len(self.episodes)

    def __iter__(self) -> Iterator[Episode]:
        return iter(self.episodes)

    def __getitem__(self, i: int) -> Episode:
        return self.episodes[i]

    @property
    def n_transitions(self) -> int:
        """Total number of actions over all episodes."""
        return int(sum(len(e) for e in self.episodes))

    @property
    def returns(self) -> np.ndarray:
        """Episode returns, shape ``(n_episodes,)``."""
        return np.array([e.episode_return for e in self.episodes])

    def normalized_scores(self, returns: np.ndarray | None = None) -> np.ndarray | None:
        """``100 · (R − ref_min) / (ref_max − ref_min)``, ``None`` without references."""
        if self.ref_min_score is None or self.ref_max_score is None:
            return None
        r = self.returns if returns is None else np.asarray(returns, dtype=np.float64)
        return 100.0 * (r - self.ref_min_score) / (self.ref_max_score - self.ref_min_score)

    def recover_environment(self, **kwargs: Any) -> Any:
        """``gymnasium.make`` of the recorded environment; for a set made here, the task's
        environment as :func:`thesis_lib.data.make_env` makes it (a Maze2D with its fixed
        target)."""
        if self.env_id is None:
            raise ValueError(f"Data set '{self.id}' records no environment.")
        try:
            ns, task, _, _ = parse_dataset_id(self.id)
        except ValueError:
            ns, task = "", ""
        if is_our_namespace(ns) and task in TASKS and TASKS[task].env_id == self.env_id:
            return make_env(task, **kwargs)
        return forget_maze_xml(gym.make(self.env_id, **kwargs))


def generate_command(dataset_id: str) -> str | None:
    """How to make ``dataset_id`` here (one of ours), or ``None`` (a real Minari/D4RL set).

    >>> generate_command("thesis/hopper/medium-v0")
    "'thesis data generate --task hopper --tier medium' (or thesis_lib.data.generate('hopper', 'medium'))"
    >>> generate_command("D4RL/door/human-v2") is None
    True
    """
    try:
        ns, task, tier, _ = parse_dataset_id(dataset_id)
    except ValueError:
        return None
    if not is_our_namespace(ns) or task not in TASKS:
        return None
    size = "" if ns == NAMESPACE else f" --n-transitions {_namespace_size(ns)}"
    return (
        f"'thesis data generate --task {task} --tier {tier}{size}' "
        f"(or thesis_lib.data.generate('{task}', '{tier}'"
        f"{'' if not size else ', n_transitions=' + str(_namespace_size(ns))}))"
    )


def _namespace_size(ns: str) -> int:
    """The transitions a size namespace stands for (``thesis-1m`` -> 1000000)."""
    tail = ns.removeprefix(f"{NAMESPACE}-")
    scale = {"k": 1000, "m": 1_000_000}.get(tail[-1:], 1)
    return int(tail.rstrip("km")) * scale


def missing_message(dataset_id: str) -> str:
    """The ``FileNotFoundError`` text for a data set not found: where it was looked for, and
    how to make it (:func:`generate_command`) or where to put a downloaded copy."""
    roots = " or ".join(str(r) for r in search_dirs())
    msg = f"No Minari dataset '{dataset_id}' under {roots}."
    command = generate_command(dataset_id)
    if command:
        msg += f" Create it with {command}, or set MINARI_DATASETS_PATH to an existing copy."
    else:
        msg += (
            " Set MINARI_DATASETS_PATH to the directory holding it (e.g. a copy of a real "
            f"Minari/D4RL download), or download it with 'minari download {dataset_id}' "
            "(pip install 'minari[hf]'; it lands under $MINARI_DATASETS_PATH, else "
            "~/.minari/datasets), or make ours with 'thesis data generate'."
        )
    return msg


def _flat(x: Any) -> np.ndarray:
    # Nested dict goals (FrankaKitchen: one entry per sub-task): concatenated by sorted key.
    if isinstance(x, dict):
        return np.concatenate([_flat(x[k]).reshape(len(_flat(x[k])), -1) for k in sorted(x)], 1)
    return np.asarray(x)


def _split_obs(obs: Any) -> tuple[np.ndarray, np.ndarray | None, np.ndarray | None]:
    if isinstance(obs, dict):
        return (
            _flat(obs["observation"]),
            None if "desired_goal" not in obs else _flat(obs["desired_goal"]),
            None if "achieved_goal" not in obs else _flat(obs["achieved_goal"]),
        )
    return np.asarray(obs), None, None


def load(dataset_id: str, validate: bool = True) -> OfflineDataset:
    """Load a data set made here (``thesis/…``) or a real Minari one, as :class:`Episode` s.

    Args:
        dataset_id: e.g. ``"thesis/hopper/medium-v0"`` or ``"mujoco/hopper/medium-v0"``.
        validate: check every episode's array lengths.

    Returns:
        The :class:`OfflineDataset`.

    Raises:
        FileNotFoundError: no such data set; the message says how to make it.
        EpisodeFormatError: an episode's observations are not actions + 1 (names it).
        DamagedDatasetError: the files cannot be read (truncated, half-written); the message
            names the id and the command that rebuilds it.
    """
    path = find_dataset(dataset_id)
    if path is None:
        raise FileNotFoundError(missing_message(dataset_id))
    try:
        _check_metadata(path)
        return _read(dataset_id, path, validate)
    # AssertionError: Minari checks the metadata it reads with ``assert``
    except (OSError, KeyError, ValueError, AssertionError) as e:
        if isinstance(e, EpisodeFormatError):
            raise
        raise DamagedDatasetError(_damaged_message(dataset_id, path, e)) from e


class DamagedDatasetError(OSError):
    """A data set's files exist but cannot be read (a truncated or half-written HDF5 file, a
    ``metadata.json`` that is not Minari's)."""


def _check_metadata(path: Path) -> None:
    """Raise ``ValueError`` unless ``path/data/metadata.json`` is a JSON object holding what
    Minari reads first (the data format, and the spaces or the environment spec), so a damaged
    file is reported as such rather than as Minari's ``AttributeError`` or bare ``assert``."""
    md = json.loads((path / "data" / "metadata.json").read_text())
    if not isinstance(md, dict):
        raise ValueError(
            f"Expect metadata.json to hold a JSON object, actually: a {type(md).__name__}"
        )
    if "data_format" not in md:
        raise ValueError("Expect metadata.json to name its 'data_format', actually: none")
    spaces = all(isinstance(md.get(k), str) for k in ("observation_space", "action_space"))
    if not spaces and not isinstance(md.get("env_spec"), str):
        raise ValueError(
            "Expect metadata.json to hold the observation and action spaces or an 'env_spec', "
            "actually: neither"
        )


def _damaged_message(dataset_id: str, path: Path, err: BaseException) -> str:
    msg = f"Data set '{dataset_id}' at {path} is damaged and cannot be read ({err})."
    command = generate_command(dataset_id)
    if command:
        msg += f" Rebuild it with {command}."
    else:
        msg += f" Delete {path} and copy or download the data set again."
    return msg


def _read(dataset_id: str, path: Path, validate: bool) -> OfflineDataset:
    from minari import MinariDataset  # lazy: minari

    mds = MinariDataset(path / "data")
    md = dict(mds.storage.metadata)
    episodes = []
    for ep in mds.iterate_episodes():
        obs, dg, ag = _split_obs(ep.observations)
        e = Episode(
            id=int(ep.id),
            observations=obs,
            actions=np.asarray(ep.actions),
            rewards=np.asarray(ep.rewards),
            terminations=np.asarray(ep.terminations, dtype=bool),
            truncations=np.asarray(ep.truncations, dtype=bool),
            desired_goals=dg,
            achieved_goals=ag,
        )
        if validate:
            e.validate(dataset_id)
        episodes.append(e)
    env_id = mds.env_spec.id if mds.env_spec is not None else None
    if "thesis_info" in md and isinstance(md["thesis_info"], str):
        md["thesis_info"] = json.loads(md["thesis_info"])
    return OfflineDataset(
        id=dataset_id,
        episodes=episodes,
        env_id=env_id,
        ref_min_score=md.get("ref_min_score"),
        ref_max_score=md.get("ref_max_score"),
        metadata=md,
        path=path,
    )


@contextlib.contextmanager
def _minari_path(root: Path) -> Iterator[None]:
    old = os.environ.get("MINARI_DATASETS_PATH")
    os.environ["MINARI_DATASETS_PATH"] = str(root)
    try:
        yield
    finally:
        if old is None:
            del os.environ["MINARI_DATASETS_PATH"]
        else:
            os.environ["MINARI_DATASETS_PATH"] = old


def write_dataset(
    dataset_id: str,
    episodes: Sequence[Episode],
    env_id: Any,
    ref_min_score: float | None = None,
    ref_max_score: float | None = None,
    description: str = "",
    info: dict[str, Any] | None = None,
    overwrite: bool = True,
    root: Path | str | None = None,
) -> Path:
    """Write ``episodes`` as a Minari HDF5 data set with ``create_dataset_from_buffers``.

    The reference scores are stored so ``minari.get_normalized_score`` works; both are
    given, so Minari rolls out nothing to estimate them. Goal-conditioned episodes are
    stored with the environment's dict observations.

    Args:
        dataset_id: ``thesis/<task>/<tier>-v0``.
        episodes: validated episodes.
        env_id: Gymnasium id or ``EnvSpec`` recorded as the data set's (and evaluation)
            environment.
        ref_min_score: normalised-score 0 return (D4RL's), or ``None``.
        ref_max_score: normalised-score 100 return, or ``None``.
        description: free text.
        info: JSON-serialisable generation record stored as ``thesis_info``.
        overwrite: replace an existing data set of that id.
        root: data-set root; :func:`data_dir` by default.

    Returns:
        The data set's directory.

    Raises:
        ValueError: no transitions to write (an existing set of that id is kept).
        EpisodeFormatError: an episode's arrays do not fit together (the set is kept too).
    """
    root = Path(root) if root is not None else data_dir()
    path = root / dataset_id
    n_steps = sum(len(e) for e in episodes)
    if n_steps < 1:  # checked before anything is written: an existing set is kept
        raise ValueError(
            f"Expect at least one transition for data set '{dataset_id}', actually: "
            f"{len(episodes)} episode(s) with {n_steps} transitions."
        )
    if path.exists() and not overwrite:
        raise FileExistsError(f"Data set '{dataset_id}' exists at {path}.")
    # Written into a staging root, then renamed into place: an interrupted write never
    # leaves a half-written data set under its id. A folder swap, so not
    # thesis_lib._io.atomic_write (which writes one file).
    staging_root = Path(tempfile.mkdtemp(prefix=".staging-", dir=_mkdirs(root)))
    try:
        _write(
            staging_root,
            dataset_id,
            episodes,
            env_id,
            ref_min_score,
            ref_max_score,
            description,
            info,
        )
        path.parent.mkdir(parents=True, exist_ok=True)
        try:
            os.replace(staging_root / dataset_id, path)  # no set there yet
        except OSError:
            if not path.exists():
                raise
            if not overwrite:  # another process made this id since the check above
                raise FileExistsError(f"Data set '{dataset_id}' exists at {path}.") from None
            # a set there (an older one, or the same one just made by a concurrent process):
            # moved aside first, as a directory cannot be renamed over a non-empty one
            trash = Path(tempfile.mkdtemp(prefix=".trash-", dir=root))
            os.replace(path, trash / "old")
            os.replace(staging_root / dataset_id, path)
            shutil.rmtree(trash, ignore_errors=True)
    finally:
        shutil.rmtree(staging_root, ignore_errors=True)
    return path


@contextlib.contextmanager
def _private_tempdir() -> Iterator[None]:
    """Point :mod:`tempfile` at a fresh folder for the block, then delete the folder and all
    that was left in it (the model files gymnasium-robotics' maze envs write and never remove)."""
    old = tempfile.tempdir
    tmp = tempfile.mkdtemp(prefix="thesis-maze-")
    tempfile.tempdir = tmp
    try:
        yield
    finally:
        tempfile.tempdir = old
        shutil.rmtree(tmp, ignore_errors=True)


def _mkdirs(p: Path) -> Path:
    p.mkdir(parents=True, exist_ok=True)
    return p


def _write(
    root: Path,
    dataset_id: str,
    episodes: Sequence[Episode],
    env_id: Any,
    ref_min_score: float | None,
    ref_max_score: float | None,
    description: str,
    info: dict[str, Any] | None,
) -> None:
    from minari import create_dataset_from_buffers  # lazy: minari
    from minari.data_collector import EpisodeBuffer  # lazy: minari

    path = root / dataset_id
    env = forget_maze_xml(gym.make(env_id))
    dict_obs = isinstance(env.observation_space, gym.spaces.Dict)
    buffers = []
    for i, e in enumerate(episodes):
        e.validate(dataset_id)
        obs: Any = e.observations
        if dict_obs:
            obs = {
                "observation": e.observations,
                "desired_goal": e.desired_goals,
                "achieved_goal": e.achieved_goals,
            }
        buffers.append(
            EpisodeBuffer(
                id=i,
                observations=obs,
                actions=e.actions,
                rewards=e.rewards,
                terminations=e.terminations,
                truncations=e.truncations,
                infos={},
            )
        )
    has_ref = ref_min_score is not None and ref_max_score is not None
    # Minari makes the env (twice, with reference scores) and never closes it: a maze env's
    # model file goes to a temp folder of its own, removed after.
    maze = hasattr(env.unwrapped, "tmp_xml_file_path")
    with (
        _minari_path(root),
        warnings.catch_warnings(),
        _private_tempdir() if maze else contextlib.nullcontext(),
    ):
        warnings.filterwarnings("ignore", message=".*author_email.*")
        create_dataset_from_buffers(
            dataset_id,
            buffers,
            env=env_id,
            eval_env=env_id,
            algorithm_name=(info or {}).get("algorithm", "thesis_lib.data"),
            author="thesis_lib",
            code_permalink="thesis_lib.data.recipe (this project)",
            ref_min_score=ref_min_score if has_ref else None,
            ref_max_score=ref_max_score if has_ref else None,
            description=description or dataset_id,
            data_format="hdf5",
        )
    if info is not None:
        from minari.dataset.minari_storage import MinariStorage  # lazy: minari

        MinariStorage.read(path / "data").update_metadata(
            {"thesis_info": json.dumps(info, default=float)}
        )
    env.close()


def list_datasets() -> list[str]:
    """Ids of every data set found under :func:`search_dirs` (ours and Minari's)."""
    found: list[str] = []
    for root in search_dirs():
        if not root.exists():
            continue
        for meta in root.glob("**/data/metadata.json"):
            rel = meta.parent.parent.relative_to(root)
            if any(part.startswith(".") for part in rel.parts):
                continue  # a staging or trash folder of an unfinished write
            did = str(rel)
            if did not in found:
                found.append(did)
    return sorted(found)
