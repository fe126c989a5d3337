"""What ``data`` is, for :func:`~manip_id.identification.identify`: one adapter, four kinds.

The one door takes the data of N samples ``(q, dq, ddq, tau)`` in whichever form the user
holds them; this module names that form once, so that every later stage dispatches on a
small typed value instead of probing the argument again:

    Samples     arrays ``(q, dq, ddq, tau[, temp])`` or a :class:`~manip_id.datasets.Dataset`
                q: (N, nq) [rad or m]; dq, ddq, tau: (N, nv); temp: (N, nv) or (N, 1) [deg C]
    Files       file specs ``PATH``, ``PATH@START:STOP`` [s], ``PATH@#A:#B`` [rows] or
                :class:`~manip_id.datasets.FileSpec` (NPZ, CSV, ROS 2 bags, Panda log folders)
    Blocks      an iterable of blocks ``(q, dq, ddq, tau)`` (a stream, accumulated in order)
    Parts       a list of parts ``(func, args)``, ``func(*args)`` yielding blocks (each one
                forked process or Dask task)
"""

from __future__ import annotations

import os
from collections.abc import Iterable
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..datasets import FileSpec
from ..errors import InputError


@dataclass(frozen=True)
class Samples:
    """N samples in memory.

    Attributes
    ----------
    q, dq, ddq, tau : array_like
        Shapes (N, nq), (N, nv), (N, nv) or None (the energy and momentum models need
        none), (N, nv).
    temp : array_like or None
        The measured temperature of the ``temperature`` friction law, (N, nv) or (N, 1).
    dt : float or None
        Mean sample time [s] when known (a dataset's stamps), for the energy and momentum
        models.
    """

    q: Any
    dq: Any
    ddq: Any
    tau: Any
    temp: Any = None
    dt: float | None = None

    def arrays(self) -> tuple:
        """``(q, dq, ddq, tau[, temp])``: a validation tuple of the array door."""
        return (self.q, self.dq, self.ddq, self.tau) + (() if self.temp is None else (self.temp,))


@dataclass(frozen=True)
class Files:
    """Log files, each read in chunks and preprocessed on its own.

    Attributes
    ----------
    specs : list of FileSpec or str
        The files as given (parsed later, with the run's window).
    """

    specs: list


@dataclass(frozen=True)
class Blocks:
    """Blocks ``(q, dq, ddq, tau)`` that arrive one after the other (accumulated in order)."""

    blocks: Iterable


@dataclass(frozen=True)
class Parts:
    """Parts ``(func, args)``, each accumulated in a forked process or a Dask task."""

    parts: list


Source = Samples | Files | Blocks | Parts

#: What ``data`` may be, in the words of the errors.
EXPECTED = (
    "arrays (q, dq, ddq, tau[, temp]), a Dataset, file specs (paths, 'PATH@START:STOP', "
    "FileSpec), an iterable of blocks (q, dq, ddq, tau) or a list of parts (func, args)"
)


def _is_file(item) -> bool:
    return isinstance(item, (str, os.PathLike, FileSpec))


def _is_part(item) -> bool:
    return isinstance(item, tuple) and len(item) == 2 and callable(item[0])


def _is_array(item) -> bool:
    """An array of samples: an ndarray, or a nested sequence of numbers (not a block)."""
    if isinstance(item, np.ndarray):
        return True
    if isinstance(item, (list, tuple)) and item and not isinstance(item[0], (tuple, np.ndarray)):
        return isinstance(item[0], (list, int, float, np.number))
    return False


def _is_dataset(data) -> bool:
    return all(hasattr(data, k) for k in ("t", "q", "dq", "tau")) and not isinstance(
        data, (tuple, list)
    )


def data_source(data, what: str = "data") -> Source:
    """``data`` as one of :class:`Samples`, :class:`Files`, :class:`Blocks`, :class:`Parts`.

    A tuple of 4 or 5 arrays (or None for ``ddq``) is :class:`Samples`; a path, a
    :class:`FileSpec` or a list of them :class:`Files`; a list of ``(func, args)``
    :class:`Parts`; any other iterable (a generator, a list of block tuples)
    :class:`Blocks`. Anything else is an :class:`~manip_id.errors.InputError` naming what
    came.
    """
    if data is None:
        raise InputError(f"{what} must be {EXPECTED}, got None")
    if isinstance(data, (Samples, Files, Blocks, Parts)):
        return data
    if _is_dataset(data):
        t = np.asarray(data.t, dtype=float)
        dt = float(np.mean(np.diff(t))) if t.size > 1 else None
        return Samples(data.q, data.dq, data.ddq, data.tau, getattr(data, "temp", None), dt)
    if _is_file(data):
        return Files([data])
    if isinstance(data, tuple) and len(data) in (4, 5) and _is_array(data[0]):
        arrays = [a for k, a in enumerate(data) if not (k in (2, 4) and a is None)]
        if all(_is_array(a) for a in arrays):
            return Samples(*data)
    if isinstance(data, (list, tuple)):
        items = list(data)
        if items and all(_is_file(x) for x in items):
            return Files(items)
        if items and all(_is_part(x) for x in items):
            return Parts(items)
        if any(_is_file(x) or _is_part(x) for x in items):
            kinds = sorted({type(x).__name__ for x in items})
            raise InputError(f"{what} mixes kinds ({', '.join(kinds)}): give {EXPECTED}")
        if not items:
            raise InputError(f"{what} is empty: give {EXPECTED}")
        if not all(isinstance(x, (tuple, list)) for x in items):
            names = ", ".join(sorted({type(x).__name__ for x in items}))
            raise InputError(f"{what} must be {EXPECTED}, got {type(data).__name__} of {names}")
        return Blocks(items)
    if isinstance(data, Iterable) and not isinstance(data, (bytes, dict, np.ndarray)):
        return Blocks(data)
    raise InputError(f"{what} must be {EXPECTED}, got {type(data).__name__}")


__all__ = ["EXPECTED", "Blocks", "Files", "Parts", "Samples", "Source", "data_source"]
