"""Input checks shared by the DTW wrappers: every error says what was expected and what to do."""

from __future__ import annotations

import difflib
from collections.abc import Sequence
from typing import Any, Literal

import numpy as np

from thesis_lib.dtw import _kernels

Metric = Literal["l1", "l2", "sqeuclidean"]
"""Local cost d(x_i, y_j): ``"l1"`` sum of |x_i - y_j| (cityblock), ``"l2"`` Euclidean norm,
``"sqeuclidean"`` squared Euclidean norm."""

METRICS: dict[str, int] = {
    "l1": _kernels.L1,
    "l2": _kernels.L2,
    "sqeuclidean": _kernels.SQEUCLIDEAN,
}

_SCIPY_NAMES = {"cityblock": "l1", "manhattan": "l1", "euclidean": "l2", "minkowski": "l2"}


def metric_code(metric: str) -> int:
    """Kernel code of a metric name; ValueError listing the valid names otherwise."""
    try:
        return METRICS[metric]
    except (KeyError, TypeError):
        valid = ", ".join(repr(m) for m in METRICS)
        name = str(metric).lower()
        hint = (
            [_SCIPY_NAMES[name]]
            if name in _SCIPY_NAMES
            else difflib.get_close_matches(name, list(METRICS), n=1, cutoff=0.5)
        )
        did_you_mean = f" Did you mean {hint[0]!r}?" if hint else ""
        raise ValueError(f"Unknown metric {metric!r}.{did_you_mean} Valid: {valid}.") from None


def window_size(window: Any, name: str) -> int:
    """A window as the kernels take it: 0 for None (whole sequence), else a positive int."""
    if window is None:
        return 0
    if (
        isinstance(window, (bool, np.bool_))
        or not isinstance(window, (int, np.integer))
        or window < 1
    ):
        raise ValueError(
            f"{name} must be a positive int (keep the last {name} steps) or None (whole sequence), "
            f"got {window!r}."
        )
    return int(window)


def as_sequence(x: Any, name: str, *, check_finite: bool = True) -> np.ndarray:
    """Validate one sequence and return it as C-contiguous float64 of shape (N, F).

    1-D input (N,) becomes (N, 1).
    """
    try:
        arr = np.asarray(x)
    except (ValueError, TypeError) as err:
        raise ValueError(
            f"{name} could not be read as a numeric array ({err}). Pass an array of shape (N,) or (N, F)."
        ) from None
    if arr.dtype.kind not in "biuf":
        raise ValueError(
            f"{name} must be numeric (bool, int or float), got dtype {arr.dtype}. "
            f"Convert it first, e.g. np.asarray({name}, dtype=float)."
        )
    if arr.ndim == 1:
        arr = arr[:, None]
    elif arr.ndim != 2:
        raise ValueError(
            f"{name} must be 1-D (N,) or 2-D (N, F) with time on axis 0, got {arr.ndim}-D shape {arr.shape}. "
            "For many sequences use dtw_batch / dtw_matrix with a list of arrays or a 3-D (K, M, F) array."
        )
    if arr.shape[0] == 0 or arr.shape[1] == 0:
        raise ValueError(
            f"{name} is empty (shape {arr.shape}); DTW needs at least one time step with at least one feature."
        )
    arr = np.ascontiguousarray(arr, dtype=np.float64)
    if check_finite:
        check_all_finite(arr, name)
    return arr


def check_all_finite(arr: np.ndarray, name: str, offsets: np.ndarray | None = None) -> None:
    """ValueError naming the first NaN/inf (and, for packed data, which sequence holds it)."""
    finite = np.isfinite(arr)
    if finite.all():
        return
    row, feature = (int(v) for v in np.argwhere(~finite)[0])
    value = arr[row, feature]
    where = f"{name} at time step {row}, feature {feature}"
    if offsets is not None:
        k = int(np.searchsorted(offsets, row, side="right")) - 1
        where = f"{name}[{k}] at time step {row - int(offsets[k])}, feature {feature}"
    raise ValueError(
        f"{where} is {value}; DTW needs finite values. Drop or interpolate missing steps "
        "(e.g. pandas .interpolate()) before computing DTW."
    )


def check_same_features(x: np.ndarray, y: np.ndarray, x_name: str, y_name: str) -> None:
    if x.shape[1] != y.shape[1]:
        raise ValueError(
            f"{x_name} and {y_name} must have the same number of features, got {x_name} shape {x.shape} "
            f"and {y_name} shape {y.shape} (1-D input counts as (N, 1)). Compare sequences of the same "
            "observation space."
        )


def pack(sequences: Any, name: str) -> tuple[np.ndarray, np.ndarray]:
    """Validate many sequences and pack them as (data (sum M, F), offsets (K+1,) int64)."""
    if isinstance(sequences, np.ndarray):
        if sequences.ndim == 3:
            k, m, f = sequences.shape
            if k == 0:
                raise ValueError(
                    f"{name} is empty (shape {sequences.shape}); pass at least one sequence."
                )
            as_sequence(
                sequences[0], f"{name}[0]", check_finite=False
            )  # raises if non-numeric or empty
            data = np.ascontiguousarray(sequences.reshape(k * m, f), dtype=np.float64)
            offsets = np.arange(0, k * m + 1, m, dtype=np.int64)
            check_all_finite(data, name, offsets)
            return data, offsets
        raise ValueError(
            f"{name} as an array must be 3-D (K, M, F), got {sequences.ndim}-D shape {sequences.shape}. "
            f"A 2-D array is ambiguous: pass a list of sequences, or {name}[..., None] for K 1-D sequences."
        )
    if not isinstance(sequences, Sequence) or isinstance(sequences, (str, bytes)):
        raise ValueError(
            f"{name} must be a list of (M, F) or (M,) arrays or a 3-D (K, M, F) array, "
            f"got {type(sequences).__name__}."
        )
    if len(sequences) == 0:
        raise ValueError(f"{name} is empty; pass at least one sequence.")
    # Fast path: cheap attribute checks per sequence, one cast + copy in np.concatenate.
    # Anything unusual goes through as_sequence, which raises the specific error.
    arrays, lengths = [], []
    n_features = None
    for k, s in enumerate(sequences):
        a = s if type(s) is np.ndarray else None
        if a is None or a.dtype.kind not in "biuf" or a.ndim not in (1, 2) or a.size == 0:
            a = as_sequence(s, f"{name}[{k}]", check_finite=False)
        elif a.ndim == 1:
            a = a.reshape(-1, 1)
        if n_features is None:
            n_features, first_shape = a.shape[1], a.shape
        elif a.shape[1] != n_features:
            raise ValueError(
                f"{name}[{k}] has shape {a.shape} but {name}[0] has shape {first_shape}; "
                f"every sequence must have {n_features} feature(s)."
            )
        arrays.append(a)
        lengths.append(a.shape[0])
    offsets = np.zeros(len(arrays) + 1, dtype=np.int64)
    np.cumsum(lengths, out=offsets[1:])
    data = np.concatenate(arrays, axis=0, dtype=np.float64)
    check_all_finite(data, name, offsets)
    return data, offsets
