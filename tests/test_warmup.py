"""The compile said and paid once (issue 39): the first use of a numba kernel with nothing
in numba's disk cache says so in one line, and ``manip-id warmup`` leaves every kernel
compiled in the cache, so that a later run compiles nothing.

Checked against numba's own state: the index files it writes, a function compiled in a
fresh module of the test's folder, and whole processes with their own ``NUMBA_CACHE_DIR``.
"""

from __future__ import annotations

import dataclasses
import importlib.util
import logging
import os
import subprocess
import sys
from pathlib import Path

import pytest

from manip_id import _numba
from manip_id.cli import main

pytest.importorskip("numba")

ROOT = Path(__file__).resolve().parents[1]
#: The kernels and the module they live in (numba names its cache files after both).
KERNELS = [
    ("_regressor_kernel", "block"),
    ("_regressor_kernel", "momentum"),
    ("_filter_kernel", "filtfilt"),
    ("_filter_kernel", "run_sections"),
    ("_csv_kernel", "_parse"),
]


def _fresh_kernel(folder: Path, name: str = "fresh_kernel"):
    """A ``numba.njit(cache=True)`` function of a new module in ``folder`` (its cache is
    ``folder/__pycache__``, empty)."""
    path = folder / f"{name}.py"
    path.write_text(
        "import numba\n\n\n@numba.njit(cache=True)\ndef twice(x):\n    return 2.0 * x\n"
    )
    spec = importlib.util.spec_from_file_location(name, path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module.twice


@pytest.fixture
def unsaid(monkeypatch):
    """This process as if no kernel had been announced yet."""
    monkeypatch.setattr(_numba, "_noted", False)
    monkeypatch.setattr(_numba, "_checked", set())


def test_the_first_compile_is_said_in_one_line_once(tmp_path, caplog, unsaid):
    twice = _fresh_kernel(tmp_path)
    assert not _numba.is_cached(twice)  # nothing on disk yet
    with caplog.at_level(logging.WARNING, logger="manip_id"):
        _numba.note_compile(twice)
        assert twice(2.0) == 4.0  # compiled here, written to the cache
        _numba.note_compile(twice)
    assert [r.getMessage() for r in caplog.records] == [_numba.COMPILE_NOTE]
    assert list((tmp_path / "__pycache__").glob("fresh_kernel.twice-*.nbi"))
    assert _numba.is_cached(twice)  # what numba wrote is what is_cached reads


def test_a_cached_kernel_is_not_announced(tmp_path, caplog, unsaid):
    _fresh_kernel(tmp_path, "cached_kernel")(1.0)  # compiled and cached by a first "run"
    again = _fresh_kernel(tmp_path, "cached_kernel")  # a new dispatcher: as a new process
    assert not again.overloads and _numba.is_cached(again)
    with caplog.at_level(logging.WARNING, logger="manip_id"):
        _numba.note_compile(again)
    assert caplog.records == []


def test_warmup_without_numba_has_nothing_to_compile(monkeypatch, capsys):
    monkeypatch.setattr("manip_id.cli._warmup.numba_available", lambda: False)
    assert main(["warmup"]) == 0
    assert "numba is not installed: nothing to compile" in capsys.readouterr().out


def _cli(args: list[str], cache: Path) -> subprocess.CompletedProcess:
    env = dict(os.environ, NUMBA_CACHE_DIR=str(cache), PYTHONPATH=str(ROOT))
    return subprocess.run(
        [sys.executable, "-m", "manip_id", *args], capture_output=True, text=True, env=env
    )


@pytest.mark.slow
def test_warmup_compiles_every_kernel_once_and_a_later_run_compiles_nothing(tmp_path):
    cache = tmp_path / "numba-cache"
    first = _cli(["warmup"], cache)
    assert first.returncode == 0, first.stderr
    assert first.stderr.count("compiling the numba kernels") == 1  # said once, one line
    assert "compiled and cached" in first.stdout
    for module, kernel in KERNELS:  # numba's index of each kernel, in the cache folder
        assert list(cache.rglob(f"{module}.{kernel}-*.nbi")), f"{module}.{kernel} not cached"
    # a real run on a log without accelerations (the filter, the compiled regressor)
    from manip_id import load_robot, random_trajectory, save_dataset, simulate

    robot = load_robot("ur5")
    sim = simulate(robot, random_trajectory(robot, seed=1), duration=4.0, rate=200.0)
    log = save_dataset(dataclasses.replace(sim.dataset, ddq=None), tmp_path / "log.npz")
    later = _cli(["identify", "ur5", "--data", str(log), "--regressor", "compiled"], cache)
    assert later.returncode == 0, later.stderr
    assert "compiling" not in later.stderr  # loaded from the cache, nothing compiled
    stamps = {p: p.stat().st_mtime_ns for p in cache.rglob("*.nbi")}
    assert _cli(["warmup", "--quiet"], cache).stdout == ""  # the second warmup: all cached
    assert {p: p.stat().st_mtime_ns for p in cache.rglob("*.nbi")} == stamps
