"""The one door: the same file through ``identify(robot, files)`` and ``manip-id identify``.

Independent check: the command line's JSON is compared key by key with the library's
``to_dict()`` (timings aside), and the estimate with the truth of noise-free torques
``Y(q, dq, ddq) theta`` (the regressor of :mod:`tests._logs`).
"""

from __future__ import annotations

import json
import re

import numpy as np
import pytest
from _logs import log, save_npz, truth
from conftest import get_robot

from manip_id.cli import main
from manip_id.errors import InputError
from manip_id.identification import (
    FileOptions,
    PartitionOptions,
    PreprocessOptions,
    RunOptions,
    build_problem,
    identify,
    solve,
)
from manip_id.identification.selection import SelectionOptions

FRICTION = "viscous,coulomb"


def _strip(doc):
    """The document without run-time figures (timings, a solver's time)."""
    if isinstance(doc, dict):
        return {k: _strip(v) for k, v in doc.items() if k not in ("timings", "time")}
    if isinstance(doc, list):
        return [_strip(v) for v in doc]
    return doc


def _same(a, b, path="") -> None:
    """Equal documents: floats to 1e-9 relative (the same sums, the same solve)."""
    if isinstance(a, dict):
        assert set(a) == set(b), f"{path}: {sorted(set(a) ^ set(b))}"
        for k in a:
            _same(a[k], b[k], f"{path}.{k}")
    elif isinstance(a, list):
        assert len(a) == len(b), path
        for i, (x, y) in enumerate(zip(a, b, strict=True)):
            _same(x, y, f"{path}[{i}]")
    elif isinstance(a, float) and isinstance(b, float):
        assert np.isclose(a, b, rtol=1e-9, atol=1e-12), f"{path}: {a} != {b}"
    elif isinstance(a, str) and isinstance(b, str) and a != b:
        # printed expressions: round-off may flip a 4-digit coefficient's last digit
        number = r"\d+\.\d+(?:e[-+]\d+)?"
        assert re.sub(number, "#", a) == re.sub(number, "#", b), f"{path}: {a!r} != {b!r}"
        x, y = (np.array(re.findall(number, e), dtype=float) for e in (a, b))
        assert np.allclose(x, y, rtol=1e-3, atol=1.01e-4), f"{path}: {a!r} != {b!r}"
    else:
        assert a == b, f"{path}: {a!r} != {b!r}"


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    d = tmp_path_factory.mktemp("door")
    robot = get_robot("ur5", friction=FRICTION)
    train = save_npz(d / "train.npz", robot, *log(robot, n=600, seed=0))
    valid = save_npz(d / "valid.npz", robot, *log(robot, n=400, seed=1, t0=10.0))
    return robot, str(train), str(valid)


def _cli(tmp_path, capsys, argv):
    out = tmp_path / "out.json"
    capsys.readouterr()
    assert main([*argv, "--json", str(out), "--workers", "1"]) == 0
    printed = capsys.readouterr().out
    return json.loads(out.read_text()), printed


@pytest.mark.parametrize(
    "extra, kwargs",
    [
        ([], {}),
        (["--method", "wls"], {"method": "wls"}),
        (
            ["--per-file"],
            {"files": FileOptions(audit=False, partition=PartitionOptions(per_file=True))},
        ),
        (["--method", "rls"], {"method": "rls"}),
        pytest.param(["--consistent"], {"consistent": True}, marks=pytest.mark.slow),
    ],
    ids=["plain", "wls", "per-file", "online", "consistent"],
)
def test_python_door_equals_cli(files, tmp_path, capsys, extra, kwargs):
    robot, train, valid = files
    argv = ["identify", "ur5", "--friction", FRICTION, "--data", train, "--validate", valid]
    doc, printed = _cli(tmp_path, capsys, argv + extra)
    result = identify(robot, [train], validation=[valid], run=RunOptions(workers=1), **kwargs)
    mine = json.loads(json.dumps(result.to_dict()))
    _same(_strip(doc), _strip(mine))
    assert set(doc) == set(result.to_dict())  # --json keys == to_dict() keys
    if "files" not in kwargs:  # the pre-fit audit: in both, and printed
        assert doc["audit"] == mine["audit"] and mine["audit"]["files"]
        assert "audit" in printed.lower() or robot.name in printed
    if kwargs.get("method", "ols") == "ols":  # noise-free: the truth, in base parameters
        beta = result.base.to_base(truth(robot))
        np.testing.assert_allclose(result.estimate, beta, rtol=1e-6, atol=1e-6)


def test_friction_auto_same_in_both(files, tmp_path, capsys):
    robot, train, valid = files
    plain = get_robot("ur5")
    argv = ["identify", "ur5", "--friction", "auto", "--data", train, "--validate", valid]
    doc, printed = _cli(tmp_path, capsys, argv)
    opts = SelectionOptions()
    result = identify(
        plain,
        [train],
        validation=[valid],
        run=RunOptions(workers=1),
        files=FileOptions(select_friction=opts),
    )
    _same(_strip(doc), _strip(json.loads(json.dumps(result.to_dict()))))
    assert "friction_selection" in doc and "joint_terms_per_joint" in doc


def test_build_problem_then_solve_is_identify(files):
    robot, train, _ = files
    a = identify(robot, train, run=RunOptions(workers=1))
    problem = build_problem(robot, train, run=RunOptions(workers=1))
    b = solve(problem)
    np.testing.assert_allclose(a.estimate, b.estimate, rtol=1e-12)
    assert a.context["audit"] == b.context["audit"]


def test_arrays_dataset_blocks_agree(files):
    """Arrays, blocks and the file of the same samples: the same estimate."""
    robot, _, _ = files
    t, q, dq, ddq, tau = log(robot, n=600, seed=0)
    a = identify(robot, (q, dq, ddq, tau))
    blocks = [
        (q[i : i + 100], dq[i : i + 100], ddq[i : i + 100], tau[i : i + 100])
        for i in range(0, 600, 100)
    ]
    b = identify(robot, iter(blocks))
    np.testing.assert_allclose(a.estimate, b.estimate, rtol=1e-9, atol=1e-9)


@pytest.mark.parametrize(
    "data, message",
    [
        (42, "got int"),
        ([], "empty"),
        ((1, 2), "got tuple of int"),
    ],
)
def test_bad_data_one_clear_error(files, data, message):
    robot, _, _ = files
    with pytest.raises(InputError, match=message):
        identify(robot, data)


def test_file_options_only_for_files(files):
    robot, _, _ = files
    t, q, dq, ddq, tau = log(robot, n=300, seed=0)
    with pytest.raises(InputError, match="files= applies to log files"):
        identify(robot, (q, dq, ddq, tau), files=FileOptions(preprocess=PreprocessOptions()))


def test_temperature_reference_same_in_both(files, tmp_path, capsys):
    """The temperature law's T0 (the training files' mean temperature) is set by the file
    pipeline of the library, for Python and the command line alike."""
    _, train, _ = files
    friction = "viscous,coulomb,temperature"
    robot = get_robot("ur5", friction=friction)
    with np.load(train) as z:
        arrays = dict(z)
    t = arrays["t"]
    arrays["temp"] = 30.0 + 5.0 * np.sin(0.3 * t)[:, None] + np.arange(robot.nv)  # [deg C]
    path = tmp_path / "hot.npz"
    np.savez(path, **arrays)
    argv = ["identify", "ur5", "--friction", friction, "--data", str(path)]
    doc, printed = _cli(tmp_path, capsys, argv)
    result = identify(robot, str(path), run=RunOptions(workers=1))
    mine = json.loads(json.dumps(result.to_dict()))
    _same(_strip(doc), _strip(mine))
    t0 = mine["friction_shapes"]["temperature_reference"]
    np.testing.assert_allclose(t0, arrays["temp"].mean(axis=0), rtol=1e-9)  # the mean
    assert "temperature law: T0" in printed


@pytest.mark.slow
def test_dask_run_same_in_both(files, tmp_path, capsys):
    """Files as Dask tasks (a local cluster of one worker, started and stopped by the run):
    the command line and the library give the same document, and the serial run's estimate."""
    robot, train, valid = files
    argv = ["identify", "ur5", "--friction", FRICTION, "--data", train, "--validate", valid]
    out = tmp_path / "dask.json"
    capsys.readouterr()
    assert main([*argv, "--scheduler", "local:1", "--json", str(out)]) == 0
    doc = json.loads(out.read_text())
    result = identify(robot, [train], validation=[valid], run=RunOptions(scheduler="local:1"))
    mine = json.loads(json.dumps(result.to_dict()))
    _same(_strip(doc), _strip(mine))
    assert doc["source"]["scheduler"] == mine["source"]["scheduler"]
    # the tasks scan their own files: no pre-fit audit on this path, in both alike
    assert "audit" not in doc and "audit" not in mine
    serial = identify(robot, [train], validation=[valid], run=RunOptions(workers=1))
    np.testing.assert_allclose(result.estimate, serial.estimate, rtol=1e-9, atol=1e-9)


@pytest.mark.parametrize("method", ["iv", pytest.param("didim", marks=pytest.mark.slow)])
def test_closed_loop_estimators_same_in_both(tmp_path, capsys, method):
    """A closed-loop log (PD tracking, noisy positions): ``--method iv/didim --controller``
    and ``FileOptions(closed_loop=...)`` from OLS give the same document (didim: the same
    path, slow)."""
    import pinocchio as pin

    from manip_id.control.closed_loop import simulate_tracking
    from manip_id.controller import load_controller
    from manip_id.identification import ClosedLoopOptions
    from manip_id.simulation import MeasurementNoise
    from manip_id.trajectories import random_trajectory

    robot = get_robot("ur5", friction="viscous")
    model = robot.model
    mjj = np.diag(pin.crba(model, model.createData(), pin.neutral(model)))
    toml = tmp_path / "pd.toml"
    toml.write_text(f"kp = {(mjj * 900).tolist()}\nkd = {(mjj * 60).tolist()}\n")
    ctrl = load_controller(toml, robot.nv)
    traj = random_trajectory(robot, harmonics=3, seed=3)
    noise = MeasurementNoise(tau=0.01, q=1e-4)
    log = simulate_tracking(robot, traj, ctrl, duration=2.0, rate=500.0, noise=noise, seed=2)
    d = log.dataset
    path = tmp_path / "loop.npz"
    np.savez(path, t=d.t, q=d.q, dq=d.dq, tau=d.tau, qref=log.q_ref, dqref=log.dq_ref)
    argv = ["identify", "ur5", "--friction", "viscous", "--data", str(path), "--cutoff", "20"]
    doc, printed = _cli(tmp_path, capsys, [*argv, "--method", method, "--controller", str(toml)])
    files = FileOptions(
        preprocess=PreprocessOptions(cutoff=20.0), closed_loop=ClosedLoopOptions(method, ctrl)
    )
    result = identify(robot, str(path), method="ols", files=files, run=RunOptions(workers=1))
    mine = json.loads(json.dumps(result.to_dict()))
    _same(_strip(doc), _strip(mine))
    assert set(doc) == set(result.to_dict())  # --json keys == to_dict() keys
    assert doc["method"] == method and doc["closed_loop"]["iterations"] >= 1
    assert f"{method}: " in printed and "iterations from ols" in printed
