"""Writing a chapter's results: tables (CSV), figures (PNG) and ``run.json``.

Every file lands in ``results/<chapter>/`` and is also *glued* (myst-nb) so the book can show it
by name. ``run.json`` records what produced the files: the config, the seed, the git commit,
package versions and wall time, so a table can always be traced back to its run.

Used by every chapter notebook.
"""

from __future__ import annotations

import json
import time
from pathlib import Path
from typing import Any

import pandas as pd

from thesis_lib.paths import results_dir
from thesis_lib.provenance import jsonable, run_metadata


def _glue(name: str, value: Any) -> None:
    try:
        from myst_nb import glue
    except ImportError:  # outside a notebook build the glue is optional
        return
    try:
        glue(name, value, display=False)
    except Exception:
        pass


class ChapterResults:
    """Collects one chapter run's outputs under ``results/<chapter>/``.

    Example:
        >>> import tempfile, os, pandas as pd
        >>> tmp = tempfile.TemporaryDirectory()  # removed below, with what the run wrote
        >>> os.environ["THESIS_RESULTS_DIR"] = tmp.name
        >>> res = ChapterResults("demo", config={"n": 3}, seed=0)
        >>> res.table("numbers", pd.DataFrame({"x": [1, 2]})).name
        'numbers.csv'
        >>> sorted(res.finish()["artifacts"])
        ['numbers.csv']
        >>> del os.environ["THESIS_RESULTS_DIR"]
        >>> tmp.cleanup()

    Args:
        chapter: folder name, e.g. ``"01_background"``.
        config: the chapter's config (a dataclass or a dict), recorded in ``run.json``.
        seed: the run's seed, recorded in ``run.json``.
    """

    def __init__(self, chapter: str, config: Any = None, seed: int | None = None) -> None:
        self.chapter = chapter
        self.config = config
        self.seed = seed
        self.dir = results_dir(chapter)
        self.artifacts: list[str] = []
        self._names: dict[str, str] = {}  # glue key -> kind: the book allows one of each key
        self._t0 = time.perf_counter()

    def _claim(self, name: str, kind: str) -> None:
        """Reserve ``name`` for one artifact: a table and a figure of one name would be glued
        under one key, which the book's strict build rejects (and a rerun of the same cell
        rewrites its own artifact, which is fine)."""
        other = self._names.setdefault(name, kind)
        if other != kind:
            raise ValueError(
                f"'{name}' is already a {other} of {self.chapter}; give the {kind} another name "
                f"(e.g. '{name}_{'plot' if kind == 'figure' else 'table'}')"
            )

    def table(self, name: str, df: pd.DataFrame, *, index: bool = False, glue: bool = True) -> Path:
        """Write ``df`` to ``<name>.csv`` and glue it as ``<chapter>/<name>``."""
        if not isinstance(df, pd.DataFrame):
            raise TypeError(f"table '{name}' must be a pandas DataFrame, got {type(df).__name__}")
        self._claim(name, "table")
        path = self.dir / f"{name}.csv"
        df.to_csv(path, index=index)
        self._record(path.name)
        if glue:
            _glue(f"{self.chapter}/{name}", df)
        return path

    def figure(self, name: str, fig: Any, *, dpi: int = 120, glue: bool = True) -> Path:
        """Save a matplotlib figure to ``<name>.png`` and glue it as ``<chapter>/<name>``."""
        self._claim(name, "figure")
        path = self.dir / f"{name}.png"
        fig.savefig(path, dpi=dpi, bbox_inches="tight")
        self._record(path.name)
        if glue:
            _glue(f"{self.chapter}/{name}", fig)
        return path

    def json(self, name: str, data: Any) -> Path:
        """Write any JSON-serialisable object to ``<name>.json``."""
        path = self.dir / f"{name}.json"
        path.write_text(json.dumps(jsonable(data), indent=2, default=str))
        self._record(path.name)
        return path

    def path(self, filename: str) -> Path:
        """The path of a file the caller writes itself (a GIF, a CSV from a CLI), listed in ``run.json``."""
        if Path(filename).name != filename:
            raise ValueError(f"give a file name, not a path: {filename!r}")
        self._record(filename)
        return self.dir / filename

    def finish(self, **extra: Any) -> dict[str, Any]:
        """Write ``run.json`` (config, seed, commit, versions, wall time, artifacts) and return it."""
        meta = run_metadata(
            self.config,
            self.seed,
            chapter=self.chapter,
            wall_time_s=round(time.perf_counter() - self._t0, 3),
            artifacts=list(self.artifacts),
            **extra,
        )
        (self.dir / "run.json").write_text(json.dumps(meta, indent=2, default=str))
        return meta

    def _record(self, filename: str) -> None:
        if filename not in self.artifacts:
            self.artifacts.append(filename)
