"""Where things are on disk: the project, its notebooks, results, data sets and caches.

Every location the library writes to comes from here, each with its environment variable.
"""

from __future__ import annotations

import os
from pathlib import Path


def project_root(start: str | Path | None = None) -> Path:
    """Return the checkout's root: the first folder upward holding ``_toc.yml`` and ``notebooks/``.

    ``THESIS_PROJECT_ROOT`` overrides the search.

    Raises:
        FileNotFoundError: if no such folder is found above ``start`` (default: the working
            directory).
    """
    env = os.environ.get("THESIS_PROJECT_ROOT")
    if env:
        return Path(env).resolve()
    here = Path(start or Path.cwd()).resolve()
    for folder in (here, *here.parents):
        if (folder / "_toc.yml").is_file() and (folder / "notebooks").is_dir():
            return folder
    # An editable install knows where the checkout is.
    pkg_root = Path(__file__).resolve().parents[3]
    if (pkg_root / "_toc.yml").is_file():
        return pkg_root
    raise FileNotFoundError(
        f"No thesis_lib checkout (a folder with _toc.yml and notebooks/) above {here}. "
        "Run from inside the project or set THESIS_PROJECT_ROOT."
    )


def results_dir(chapter: str | None = None) -> Path:
    """Folder where results are written: ``$THESIS_RESULTS_DIR`` or ``<project>/results``.

    Falls back to ``./results`` when run outside a checkout (e.g. a user's own notebook).
    With ``chapter`` given, returns (and creates) ``results/<chapter>/``.
    """
    env = os.environ.get("THESIS_RESULTS_DIR")
    if env:
        base = Path(env)
    else:
        try:
            base = project_root() / "results"
        except FileNotFoundError:
            base = Path.cwd() / "results"
    path = base / chapter if chapter else base
    path.mkdir(parents=True, exist_ok=True)
    return path


def minari_root() -> Path:
    """Minari's data-set root: ``$MINARI_DATASETS_PATH`` or ``~/.minari/datasets``."""
    p = os.environ.get("MINARI_DATASETS_PATH")
    return Path(p) if p else Path.home() / ".minari" / "datasets"


def data_dir() -> Path:
    """Where generated data sets are written: ``$THESIS_DATA_DIR``, else :func:`minari_root`.

    The CLfD videos and the MDLT music and feature caches live under it too.
    """
    p = os.environ.get("THESIS_DATA_DIR")
    return Path(p) if p else minari_root()


def cache_dir(name: str | None = None) -> Path:
    """Long-lived working files that are not results (e.g. expert-training runs):
    ``$THESIS_CACHE_DIR``, else ``~/.cache/thesis_lib``; with ``name``, that sub-folder."""
    p = os.environ.get("THESIS_CACHE_DIR")
    base = Path(p) if p else Path.home() / ".cache" / "thesis_lib"
    return base / name if name else base
