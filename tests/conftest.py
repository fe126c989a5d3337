"""Shared fixtures: robots are loaded once per test session."""

from __future__ import annotations

import os

# One BLAS thread: small matrices gain nothing from threads, and on a loaded
# 2-core machine threaded BLAS is slower by orders of magnitude.
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")

import ctypes  # noqa: E402
import functools  # noqa: E402
import gc  # noqa: E402
import sys  # noqa: E402
from pathlib import Path  # noqa: E402

import pytest  # noqa: E402

from manip_id import load_robot  # noqa: E402

SHARED_DATA = Path(__file__).resolve().parents[2] / "shared" / "data"
PANDA_LOG = SHARED_DATA / "panda_gaz2019"
#: CI (``CI=true`` in the environment) always has ../shared: missing data there fail, not skip.
IN_CI = os.environ.get("CI", "").strip().lower() in ("true", "1", "yes")


def require_shared_data(path: Path, what: str) -> Path:
    """``path`` when it exists; else skip, or fail on CI (where the shared data must be)."""
    if path.exists():
        return path
    message = f"{what} not found at {path}"
    if IN_CI:
        pytest.fail(f"{message} (CI=true: the shared data must be present)")
    pytest.skip(message)


@functools.cache
def _cached(spec: str, armature, friction, spring):
    return load_robot(spec, armature=armature, friction=friction, spring=spring)


def get_robot(spec, *, armature=None, friction=None, spring=None):
    """A robot loaded once per session (treat it as read-only)."""
    if isinstance(friction, list):
        friction = tuple(friction)
    return _cached(str(spec), armature, friction, spring)


@pytest.fixture(scope="session")
def panda_log() -> Path:
    """The real Panda log folder; skips when the shared data are absent (fails on CI)."""
    require_shared_data(PANDA_LOG / "rbt_log_time.txt", "real Panda log")
    return PANDA_LOG


# ------------------------------------------------------------------ memory between tests
#: Resident-set growth [bytes] since the last release after which the memory freed by the
#: tests is collected (cycles) and handed back to the system (glibc keeps freed heap pages
#: otherwise, and the suite's resident set only ever grows).
_RELEASE_STEP = 256 * 2**20
_released_at = [0]


def _rss() -> int:
    """This process's resident set [bytes] (0 where /proc is absent)."""
    try:
        with open("/proc/self/statm") as f:
            return int(f.read().split()[1]) * os.sysconf("SC_PAGE_SIZE")
    except (OSError, ValueError, IndexError):
        return 0


def _malloc_trim() -> None:
    try:
        ctypes.CDLL("libc.so.6").malloc_trim(0)
    except (OSError, AttributeError):  # not glibc
        pass


def _release() -> None:
    """Close the figures left open, collect the garbage, hand freed heap pages back."""
    pyplot = sys.modules.get("matplotlib.pyplot")
    if pyplot is not None:
        pyplot.close("all")
    gc.collect()
    _malloc_trim()
    _released_at[0] = _rss()


@pytest.hookimpl(trylast=True)
def pytest_runtest_teardown(item, nextitem):
    """After the last test of a module (its module fixtures are gone), and after a test
    whose leftovers grew the resident set by :data:`_RELEASE_STEP`: release the memory.
    Measured over the first 60 test files: 150-250 MiB less resident set after each file
    than with the growth rule alone (two workers of ``make test`` each keep it)."""
    if nextitem is None or nextitem.module is not item.module:
        _release()
    elif _rss() > _released_at[0] + _RELEASE_STEP:
        _release()
