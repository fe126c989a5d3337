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
    """The real Panda log folder; skips when the shared data are absent."""
    if not (PANDA_LOG / "rbt_log_time.txt").is_file():
        pytest.skip(f"real Panda log not found at {PANDA_LOG}")
    return PANDA_LOG
