"""Input validation shared by every boundary of the package."""

from __future__ import annotations

import numpy as np

from .errors import InputError


def as_float_array(x, name: str, ndim: int | tuple[int, ...] | None = None) -> np.ndarray:
    """``x`` as a C-contiguous float64 array, with a clear error otherwise."""
    try:
        arr = np.asarray(x, dtype=np.float64)
        if not arr.flags.c_contiguous:
            arr = np.ascontiguousarray(arr)
    except (TypeError, ValueError) as exc:
        raise InputError(f"{name} must be numeric array-like, got {type(x).__name__}") from exc
    if ndim is not None:
        allowed = (ndim,) if isinstance(ndim, int) else ndim
        if arr.ndim not in allowed:
            raise InputError(
                f"{name} must have {' or '.join(map(str, allowed))} dimensions, "
                f"got {name}.shape={arr.shape}"
            )
    return arr


def check_finite(arr: np.ndarray, name: str, columns=None) -> None:
    """Raise :class:`InputError` naming the first sample (row) and column holding NaN or Inf."""
    if np.isfinite(arr).all():
        return
    bad = np.argwhere(~np.isfinite(arr))[0]
    value = arr[tuple(bad)]
    if arr.ndim == 1:
        raise InputError(f"{name} holds {value} at sample {bad[0]}")
    col = int(bad[-1])
    label = columns[col] if columns is not None and col < len(columns) else f"column {col}"
    raise InputError(f"{name} holds {value} at sample {bad[0]}, {label}")


def check_width(arr: np.ndarray, name: str, width: int, what: str) -> None:
    """Raise unless the last axis of ``arr`` has ``width`` entries."""
    if arr.shape[-1] != width:
        raise InputError(f"{name}.shape={arr.shape} but {what}={width}")
