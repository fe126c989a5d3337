"""Shared fixtures: robots are loaded once per test session."""

from __future__ import annotations

import os

# One BLAS thread: small matrices gain nothing from threads, and on a loaded
# 2-core machine threaded BLAS is slower by orders of magnitude.
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")

import functools  # noqa: E402
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
