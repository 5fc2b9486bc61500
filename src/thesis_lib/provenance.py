"""Provenance: what produced a file. The git commit, the package versions, the platform.

Every ``run.json`` (a chapter run), every study task and every sweep record carries
:func:`run_metadata` or its parts, so a number can be traced back to the code that made it.
On the ground floor: anything may import it; it imports nothing of the library's but
:mod:`thesis_lib.paths`.
"""

from __future__ import annotations

import dataclasses
import platform
import subprocess
import sys
from datetime import UTC, datetime
from importlib import metadata
from pathlib import Path
from typing import Any

from thesis_lib.paths import project_root

#: Packages whose versions are recorded in every run.json.
RECORDED_PACKAGES = (
    "thesis_lib",
    "numpy",
    "scipy",
    "pandas",
    "numba",
    "torch",
    "gymnasium",
    "mujoco",
    "gymnasium-robotics",
    "minari",
    "stable-baselines3",
    "sb3-contrib",
    "librosa",
    "fastdtw",
    "papermill",
    "jupyter-book",
)


def git_output(args: list[str], path: str | Path | None = None) -> str | None:
    """``git <args>``'s standard output in the checkout (``path`` or the project root), or
    ``None`` where git fails or is missing (outside a checkout, an unknown commit)."""
    try:
        cwd = Path(path) if path else project_root()
    except FileNotFoundError:
        cwd = Path.cwd()
    try:
        out = subprocess.run(["git", *args], cwd=cwd, capture_output=True, text=True, timeout=10)
    except (OSError, subprocess.SubprocessError):
        return None
    return out.stdout if out.returncode == 0 else None


def git_commit(path: str | Path | None = None) -> str:
    """The checkout's commit hash, suffixed ``-dirty`` when tracked files have uncommitted
    changes, other than the committed evidence under ``studies/`` (a running study rewrites its
    own ``rows.csv`` and ``run.json``; that is not a change of the code that ran).

    Returns ``"unknown"`` outside a git checkout.
    """
    return commit_record(path)["git_commit"]


def git_dirty_paths(path: str | Path | None = None) -> list[str] | None:
    """The tracked files (from the checkout's top) whose uncommitted changes make
    :func:`git_commit` ``-dirty``: everything but ``studies/``; both names of a renamed file.
    Recorded beside a ``-dirty`` commit, so that a reader can tell a code change from an edit
    of the prose. ``None`` outside a git checkout.
    """
    out = git_output(
        [
            "--no-optional-locks",  # a read: never take the index lock a study's commit needs
            "status",
            "--porcelain",
            "-z",  # NUL-separated, names unquoted
            "--untracked-files=no",
            "--",
            ":(top)",
            ":(top,exclude)studies",
        ],
        path,
    )
    if out is None:
        return None
    # porcelain v1 with -z: "XY path", and for a rename or copy the old path as the next field
    fields, paths = iter(out.split("\0")), []
    for entry in fields:
        if entry:
            paths.append(entry[3:])
            if "R" in entry[:2] or "C" in entry[:2]:
                paths.append(next(fields))
    return sorted(paths)


def commit_record(path: str | Path | None = None) -> dict[str, Any]:
    """``{"git_commit": ...}`` (:func:`git_commit`), with ``"git_dirty"``, the paths of
    :func:`git_dirty_paths`, when the commit is ``-dirty``; from one ``git status``."""
    sha = git_output(["rev-parse", "HEAD"], path)
    dirty = git_dirty_paths(path)
    if sha is None or dirty is None:
        return {"git_commit": "unknown"}
    if not dirty:
        return {"git_commit": sha.strip()}
    return {"git_commit": f"{sha.strip()}-dirty", "git_dirty": dirty}


def package_versions(names: tuple[str, ...] = RECORDED_PACKAGES) -> dict[str, str]:
    """Installed versions of ``names`` (missing packages are left out)."""
    out = {"python": platform.python_version()}
    for name in names:
        try:
            out[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            continue
    return out


def jsonable(config: Any) -> Any:
    """A dataclass instance as a dict (``dataclasses.asdict``); anything else as it is."""
    if dataclasses.is_dataclass(config) and not isinstance(config, type):
        return dataclasses.asdict(config)
    return config


def run_metadata(config: Any, seed: int | None, **extra: Any) -> dict[str, Any]:
    """The provenance record written as ``run.json``: config, seed, commit, versions, platform."""
    return {
        "config": jsonable(config),
        "seed": seed,
        **commit_record(),
        "versions": package_versions(),
        "platform": {
            "machine": platform.machine(),
            "system": platform.system(),
            "argv": sys.argv[:1],
        },
        "created_utc": datetime.now(UTC).isoformat(timespec="seconds"),
        **extra,
    }


__all__ = [
    "RECORDED_PACKAGES",
    "commit_record",
    "git_commit",
    "git_dirty_paths",
    "git_output",
    "jsonable",
    "package_versions",
    "run_metadata",
]
