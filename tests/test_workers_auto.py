"""``workers="auto"`` and ``--regressor``: the default paths give the reference figures.

The reference is one process with one Pinocchio regressor call per sample
(``--regressor pinocchio --workers 1``); the default forks one process per core from
``FORK_MIN_SAMPLES`` samples on and uses the compiled regressor past ``AUTO_SAMPLES``.
Both thresholds are lowered here (and two cores granted) so that small problems take
the default large-input path; the answers must agree to 1e-9 relative.
"""

from __future__ import annotations

import importlib
import json

import numpy as np
import pytest

import manip_id.execution as execution
from manip_id import load_robot
from manip_id._numba import numba_available
from manip_id.cli import main
from manip_id.cli._common import REGRESSOR_ENV, REGRESSOR_MODES
from manip_id.datasets import Dataset, save_dataset
from manip_id.errors import InputError
from manip_id.identification import RunOptions, identify
from manip_id.robot.compiled_regressor import ENV, MODES
from manip_id.simulation import MeasurementNoise, simulate
from manip_id.trajectories import random_trajectory


@pytest.fixture
def large_input_path(monkeypatch):
    """The default path of a large input for a small one: forks at 100 samples on two
    cores, the compiled regressor (when numba is there) from the first sample."""
    monkeypatch.setenv(ENV, "auto")  # restored after the test, whatever --regressor sets
    monkeypatch.setattr(execution, "FORK_MIN_SAMPLES", 100)
    monkeypatch.setattr(execution, "available_cores", lambda: 2)
    monkeypatch.setattr(importlib.import_module("manip_id.robot.regressor"), "AUTO_SAMPLES", 0)


def _data(robot, duration=4.0, rate=200.0, seed=3):
    traj = random_trajectory(robot, harmonics=4, seed=seed)
    noise = MeasurementNoise(tau=0.01)
    return simulate(robot, traj, duration=duration, rate=rate, noise=noise, seed=seed)


def test_resolve_workers(monkeypatch):
    monkeypatch.setattr(execution, "available_cores", lambda: 3)
    n = execution.FORK_MIN_SAMPLES
    assert execution.resolve_workers("auto", n) == 3
    assert execution.resolve_workers("AUTO", n - 1) == 1
    assert execution.resolve_workers("auto", None) == 1
    assert execution.resolve_workers(2, 10) == 2 and execution.resolve_workers("4", n) == 4
    for bad in (0, -1, "two", 1.5, True, None):
        with pytest.raises(InputError, match="workers"):
            execution.resolve_workers(bad, n)
    assert RunOptions().workers == "auto" and RunOptions(workers="2").workers == 2
    with pytest.raises(InputError, match="workers"):
        RunOptions(workers="many")


def test_available_cores_is_the_affinity():
    affinity = getattr(__import__("os"), "sched_getaffinity", None)
    if affinity is None:
        pytest.skip("no sched_getaffinity on this platform")
    assert execution.available_cores() == len(affinity(0))


@pytest.mark.parametrize("method", ["ols", "wls"])
def test_library_default_equals_pinocchio_one_process(large_input_path, monkeypatch, method):
    robot = load_robot("ur10", friction=("viscous", "coulomb"))
    d = _data(robot).dataset
    default = identify(robot, (d.q, d.dq, d.ddq, d.tau), method=method)
    assert default.timings.get("accumulate_wall") is not None  # it forked
    monkeypatch.setenv(ENV, "pinocchio")
    ref = identify(robot, (d.q, d.dq, d.ddq, d.tau), method=method, run=RunOptions(workers=1))
    assert "accumulate_wall" not in ref.timings
    scale = np.abs(ref.estimate).max()
    np.testing.assert_allclose(default.estimate, ref.estimate, rtol=0, atol=1e-9 * scale)
    assert default.relative_error.train == pytest.approx(ref.relative_error.train, rel=1e-9)


def _values(path):
    report = json.loads(path.read_text())
    return np.array([p["value"] for p in report["base_parameters"]]), report


def _cli_pair(tmp_path, argv):
    default, ref = tmp_path / "default.json", tmp_path / "ref.json"
    assert main([*argv, "--json", str(default)]) == 0
    assert main([*argv, "--regressor", "pinocchio", "--workers", "1", "--json", str(ref)]) == 0
    (a, ra), (b, rb) = _values(default), _values(ref)
    np.testing.assert_allclose(a, b, rtol=0, atol=1e-9 * np.abs(b).max())
    assert ra["n_samples"] == rb["n_samples"]
    return ra, rb


def test_cli_simulation_default_equals_reference(large_input_path, tmp_path):
    argv = ["identify", "ur10", "--simulate", "--friction", "viscous", "--duration", "10"]
    ra, rb = _cli_pair(tmp_path, [*argv, "--rate", "50", "--split", "0.7"])
    assert ra["relative_error"]["validation"] == pytest.approx(
        rb["relative_error"]["validation"], rel=1e-9
    )


@pytest.mark.parametrize("fmt", ["npz", "csv"])
def test_cli_file_default_equals_reference(large_input_path, tmp_path, fmt):
    robot = load_robot("ur5", friction=("viscous", "coulomb"))
    d = _data(robot, duration=6.0, rate=250.0, seed=5).dataset
    ds = Dataset(d.t, d.q, d.dq, d.tau, joint_names=tuple(robot.dof_names))
    path = save_dataset(ds, tmp_path / f"log.{fmt}")
    _cli_pair(tmp_path, ["identify", "ur5", "--friction", "viscous,coulomb", "--data", str(path)])


@pytest.mark.skipif(not numba_available(), reason="numba is not installed")
def test_cli_regressor_option_sets_the_mode(monkeypatch, tmp_path):
    monkeypatch.setenv(ENV, "auto")
    out = tmp_path / "c.json"
    argv = ["identify", "ur5", "--simulate", "--duration", "2", "--regressor", "compiled"]
    assert main([*argv, "--json", str(out)]) == 0
    assert __import__("os").environ[ENV] == "compiled"
    assert main(["identify", "ur5", "--simulate", "--regressor", "numba"]) == 2


def test_cli_modes_are_the_regressor_modes():
    assert REGRESSOR_MODES == MODES
    assert REGRESSOR_ENV == ENV


def _auto_in_a_daemon(n):
    return execution.resolve_workers("auto", n)


def test_auto_is_serial_in_a_daemonic_process(monkeypatch):
    import multiprocessing as mp

    monkeypatch.setattr(execution, "available_cores", lambda: 2)
    n = 10 * execution.FORK_MIN_SAMPLES
    assert execution.resolve_workers("auto", n) == 2
    with mp.get_context("fork").Pool(1) as pool:  # pool workers are daemonic
        assert pool.apply(_auto_in_a_daemon, (n,)) == 1
