"""thesis_lib: the library behind the executable book of *Improving the Robustness of
Demonstration Learning* (Correia & Alexandre).

Sub-packages are imported on first use, so ``import thesis_lib`` is cheap and
``thesis_lib.dtw`` works without importing torch or gymnasium::

    >>> import thesis_lib
    >>> thesis_lib.dtw.dtw([0.0, 1.0, 2.0], [0.0, 0.0, 1.0, 2.0], metric="l1")
    0.0
"""

from __future__ import annotations

import importlib
import warnings
from typing import Any

# Executed notebooks have no ipywidgets (the built book is static HTML), so tqdm.auto falls back
# to text progress bars; its warning about that says nothing the reader can act on.
warnings.filterwarnings("ignore", message="IProgress not found")

__version__ = "0.1.0"

_SUBPACKAGES = ("book", "dtw", "rl", "seq", "data", "defender", "clfd", "mdlt", "ur3", "chapters")

__all__ = ["__version__", *_SUBPACKAGES]


def __getattr__(name: str) -> Any:
    if name in _SUBPACKAGES:
        module = importlib.import_module(f"{__name__}.{name}")
        globals()[name] = module
        return module
    raise AttributeError(f"module 'thesis_lib' has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_SUBPACKAGES))
