"""One way to write a file so that no reader ever sees half of it, and one lock for work that two
processes must not do twice.

Every file the library writes that another process may read at the same time (a study task's
record, a training checkpoint, a cached feature array, a demonstration set, an exported expert)
goes through :func:`atomic_write`: the content is written to a temporary file of its own in the
destination's folder, then renamed over the destination (``os.replace``, atomic on POSIX and on
Windows within one volume). Two workers writing the same file each rename their own complete
copy; a process killed mid-write leaves the previous file (or none), never a truncated one.

:func:`file_lock` serialises work that two study workers could otherwise both start (making the
same demonstrations, training the same encoder): the second waits, then finds the first's
result.
"""

from __future__ import annotations

import contextlib
import hashlib
import os
import tempfile
from collections.abc import Callable, Iterable, Iterator
from pathlib import Path

__all__ = ["atomic_write", "file_lock", "hash_arrays"]

_UMASK = os.umask(0)
os.umask(_UMASK)


def atomic_write(
    dest: str | os.PathLike, save: Callable[[Path], object], *, keep_suffix: bool = False
) -> Path:
    """Write ``dest`` by calling ``save(tmp)`` on a temporary path, then renaming it over ``dest``.

    ``tmp`` is a hidden file of its own in ``dest``'s folder (created if needed), named
    ``.<dest stem>.<random>.tmp``: a reader that lists ``*<suffix>`` there (the sweep store's
    ``*.json``) never sees it. ``keep_suffix=True`` ends it in ``.tmp<dest suffix>`` instead,
    for writers that append their suffix when it is missing (``np.save``, ``np.savez``); use it
    only where nothing lists the folder by suffix. The file gets the permissions a plain
    ``open`` would give it (``mkstemp``'s 0600 is widened to 0666 less the umask). If ``save`` raises, the temporary file is removed and
    ``dest`` is left as it was. Returns ``dest`` as a ``Path``.
    """
    dest = Path(dest)
    dest.parent.mkdir(parents=True, exist_ok=True)
    fd, name = tempfile.mkstemp(
        dir=dest.parent,
        prefix=f".{dest.stem}.",
        suffix=".tmp" + (dest.suffix if keep_suffix else ""),
    )
    os.close(fd)
    tmp = Path(name)
    try:
        save(tmp)
        os.chmod(tmp, 0o666 & ~_UMASK)
        os.replace(tmp, dest)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    return dest


@contextlib.contextmanager
def file_lock(path: str | os.PathLike) -> Iterator[Path]:
    """Hold an exclusive lock on ``path`` (created, with its folder, if needed) for the block.

    An advisory ``fcntl.flock``: every process that takes the same path waits for the holder;
    the lock goes with the process if it dies. POSIX only, as the study workers are.
    """
    import fcntl

    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path, "w") as fh:
        fcntl.flock(fh, fcntl.LOCK_EX)
        try:
            yield path
        finally:
            fcntl.flock(fh, fcntl.LOCK_UN)


def hash_arrays(h: hashlib._Hash, arrays: Iterable) -> hashlib._Hash:
    """Feed each array's dtype, shape and bytes (C order) into the hash ``h``; returns ``h``.

    The one content hash of the library's array fingerprints (demonstration sets, rendered and
    synthesised data sets): two arrays of equal bytes but another dtype or shape differ.
    """
    import numpy as np

    for arr in arrays:
        a = np.ascontiguousarray(arr)
        h.update(str((a.dtype.str, a.shape)).encode())
        h.update(a.tobytes())
    return h
