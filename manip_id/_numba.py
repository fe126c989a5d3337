"""Whether numba, the optional compiler of manip_id's kernels, is here and already loaded;
and the one line that says when a kernel is compiled rather than loaded from the cache.

A light module (no numba, no Pinocchio imported): the low-pass filter, the CSV reader and
the batched regressor each ask it before they choose their compiled or their plain path.

The kernels are compiled on their first call and cached on disk (``cache=True``: next
to the package's sources, or in ``NUMBA_CACHE_DIR``); later processes load them. A
compilation takes seconds, so the first use of a kernel with nothing cached says so once
per process (:func:`note_compile`, on the ``manip_id`` logger, which prints warnings on
stderr when nothing else is configured); ``manip-id warmup`` compiles them all ahead.
"""

from __future__ import annotations

import importlib.util
import logging
from functools import cache

#: The one line said before the first kernel of a process compiles.
COMPILE_NOTE = (
    "manip_id: compiling the numba kernels, once (seconds; cached on disk for later runs; "
    "'manip-id warmup' compiles them ahead)"
)
#: whether :data:`COMPILE_NOTE` was said in this process
_noted = False
#: the dispatchers already checked in this process (their cache is read once)
_checked: set[int] = set()

#: whether a numba kernel has run in this process (e.g. the low-pass of the log
#: preprocessing): numba's code generation is then loaded, and another kernel costs about
#: 10 ms more to load, which about 3000 samples of the regressor repay
_warm = False


@cache
def numba_available() -> bool:
    """Whether numba can be imported (found on the path; not imported here)."""
    return importlib.util.find_spec("numba") is not None


def is_cached(dispatcher) -> bool:
    """Whether numba's disk cache holds compiled code of ``dispatcher`` (a ``numba.njit``
    function) for its current source; True when that cannot be told (nothing is said)."""
    try:
        return bool(dispatcher._cache._cache_file._load_index())  # numba's index of the file
    except Exception:  # another numba version's internals: unknown
        return True


def note_compile(*dispatchers) -> None:
    """Say :data:`COMPILE_NOTE` once per process when one of ``dispatchers`` is about to be
    compiled (nothing in the disk cache for it, and not compiled in this process yet)."""
    global _noted
    fresh = [d for d in dispatchers if id(d) not in _checked]
    if _noted or not fresh:
        return
    _checked.update(id(d) for d in fresh)
    if any(not d.overloads and not is_cached(d) for d in fresh):
        _noted = True
        logging.getLogger("manip_id").warning(COMPILE_NOTE)


def note_numba_warm() -> None:
    """Record that a numba kernel has run in this process (see :func:`numba_warm`)."""
    global _warm
    _warm = True


def numba_warm() -> bool:
    """Whether a numba kernel has run in this process: its one-off cost (importing numba,
    loading its code generation) is paid already."""
    return _warm
