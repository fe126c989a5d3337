"""Whether numba, the optional compiler of manip_id's kernels, is here and already loaded.

A light module (no numba, no Pinocchio imported): the low-pass filter, the CSV reader and
the batched regressor each ask it before they choose their compiled or their plain path.
"""

from __future__ import annotations

import importlib.util
from functools import cache

#: whether a numba kernel has run in this process (e.g. the low-pass of the log
#: preprocessing): numba's code generation is then loaded, and another kernel costs about
#: 10 ms more to load, which about 3000 samples of the regressor repay
_warm = False


@cache
def numba_available() -> bool:
    """Whether numba can be imported (found on the path; not imported here)."""
    return importlib.util.find_spec("numba") is not None


def note_numba_warm() -> None:
    """Record that a numba kernel has run in this process (see :func:`numba_warm`)."""
    global _warm
    _warm = True


def numba_warm() -> bool:
    """Whether a numba kernel has run in this process: its one-off cost (importing numba,
    loading its code generation) is paid already."""
    return _warm
