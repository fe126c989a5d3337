"""`manip-id identify`: simulated identification recovering the truth, data files, bad input."""

from __future__ import annotations

import json

import numpy as np
import pytest
from conftest import get_robot

from manip_id.cli import main
from manip_id.datasets import Dataset, save_dataset
from manip_id.robot.regressor import regressor
from manip_id.simulation import simulate
from manip_id.trajectories import random_trajectory

SIM = ["--simulate", "--duration", "10", "--rate", "100", "--seed", "3"]
ROBOT = ["ur5", "--friction", "viscous,coulomb"]


def _run(args, tmp_path, capsys):
    out = tmp_path / "out.json"
    status = main(["identify", *args, "--json", str(out)])
    captured = capsys.readouterr()
    return status, (json.loads(out.read_text()) if out.exists() else None), captured


def test_noise_free_simulation_is_recovered_exactly(tmp_path, capsys):
    status, report, captured = _run(
        [*ROBOT, *SIM, "--noise", "0", "--chunk", "128"], tmp_path, capsys
    )
    assert status == 0
    assert report["parameter_error"] < 1e-8
    assert report["relative_error"]["train"] < 1e-6
    assert "condition number" in captured.out
    # stderr is not a terminal: no progress bar, only the JSON's warnings
    assert all(ln.startswith("manip-id: warning: ") for ln in captured.err.splitlines())


def test_noisy_simulation_within_predicted_uncertainty(tmp_path, capsys):
    status, report, _ = _run(
        [*ROBOT, *SIM, "--noise", "0.02", "--method", "wls", "--split", "0.7"], tmp_path, capsys
    )
    assert status == 0
    for key in (
        "robot",
        "n_samples",
        "n_base",
        "condition_number",
        "relative_error",
        "base_parameters",
        "timings",
        "parameter_error",
    ):
        assert key in report
    robot = get_robot("ur5", friction="viscous,coulomb")
    assert report["robot"] == "ur5"
    assert report["n_base"] == len(report["base_parameters"]) < robot.n_parameters
    assert report["n_samples"] + report["n_validation_samples"] == 1001
    rel = report["relative_error"]
    assert len(rel["per_joint_validation"]) == robot.nv
    assert 0.01 < rel["validation"] < 0.04  # 2 % torque noise
    est = np.array([p["value"] for p in report["base_parameters"]])
    std = np.array([p["std"] for p in report["base_parameters"]])
    truth = np.array(report["true_base_parameters"])
    assert np.max(np.abs(est - truth) / std) < 4.5  # 48 parameters, Gaussian errors
    first = report["base_parameters"][0]
    assert set(first) >= {"expression", "value", "std_percent"}


def test_data_file_with_validation_file(tmp_path, capsys):
    """NPZ written with plain numpy (interchange format), noise-free: exact fit on both."""
    robot = get_robot("ur5", friction="viscous,coulomb")
    traj = random_trajectory(robot, harmonics=5, seed=1)
    files = []
    for k, (t0, seed) in enumerate(((0.0, 1), (5.0, 2))):
        sim = simulate(robot, traj, duration=4.0, rate=100.0, seed=seed)
        ds = sim.dataset
        # torques from the regressor of the package and the truth: independent of simulate's rnea
        np.testing.assert_allclose(
            regressor(robot, ds.q, ds.dq, ds.ddq) @ sim.theta_true, ds.tau, atol=1e-8
        )
        path = tmp_path / f"part{k}.npz"
        np.savez(
            path,
            t=ds.t + t0,
            q=ds.q,
            dq=ds.dq,
            tau=ds.tau,
            ddq=ds.ddq,
            joint_names=np.array(robot.dof_names),
        )
        files.append(path)
    status, report, _ = _run(
        [*ROBOT, "--data", str(files[0]), "--validate", str(files[1])], tmp_path, capsys
    )
    assert status == 0
    assert report["relative_error"]["train"] < 1e-6
    assert report["relative_error"]["validation"] < 1e-6
    assert report["preprocess"] is None  # ddq given: used as is


def test_csv_without_ddq_is_preprocessed(tmp_path, capsys):
    robot = get_robot("ur5", friction="viscous,coulomb")
    sim = simulate(
        robot, random_trajectory(robot, harmonics=5, seed=4), duration=20.0, rate=500.0, seed=4
    )
    ds = sim.dataset
    path = save_dataset(
        Dataset(t=ds.t, q=ds.q, dq=ds.dq, tau=ds.tau, joint_names=ds.joint_names),
        tmp_path / "log.csv",
    )
    status, report, _ = _run(
        [*ROBOT, "--data", str(path), "--cutoff", "5", "--split", "0.7"], tmp_path, capsys
    )
    assert status == 0
    assert report["preprocess"]["cutoff"] == 5.0
    # accelerations from filtered, differentiated velocities: close, not exact
    assert report["relative_error"]["validation"] < 2e-3


def _bad_files(tmp_path):
    good = tmp_path / "good.csv"
    t = np.arange(50) * 0.01
    rows = np.column_stack([t, np.zeros((50, 18))])
    names = get_robot("ur5").dof_names
    head = ",".join(["t", *(f"{p}_{n}" for p in ("q", "dq", "tau") for n in names)])
    np.savetxt(good, rows, delimiter=",", header=head, comments="")
    back = tmp_path / "back.csv"
    rows_b = rows.copy()
    rows_b[10, 0] = 0.0
    np.savetxt(back, rows_b, delimiter=",", header=head, comments="")
    nan = tmp_path / "nan.csv"
    rows_n = rows.copy()
    rows_n[7, 3] = np.nan
    np.savetxt(nan, rows_n, delimiter=",", header=head, comments="")
    three = tmp_path / "three.npz"
    np.savez(three, t=t, q=np.zeros((50, 3)), dq=np.zeros((50, 3)), tau=np.zeros((50, 3)))
    (tmp_path / "x.parquet").write_text("x")
    return {
        "missing": str(tmp_path / "nope.npz"),
        "back": str(back),
        "nan": str(nan),
        "three": str(three),
        "format": str(tmp_path / "x.parquet"),
    }


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--data", "{missing}"], "no such data file"),
        (["--data", "{format}"], "unknown data format"),
        (["--data", "{three}"], "the data have 3 joints"),
        (["--data", "{back}"], "time must increase strictly: t[10]"),
        (["--data", "{nan}"], "q holds nan at sample 7"),
        (["--data", "{three}", "--duration", "3"], "--duration applies to --simulate only"),
        (["--simulate", "--split", "1.5"], "--split must be a fraction in (0, 1)"),
        (["--simulate", "--rate", "-5"], "--rate must be positive"),
        (["--simulate", "--validate", "{missing}"], "no such data file"),
    ],
)
def test_bad_input_one_line_exit_2_nothing_written(tmp_path, capsys, args, message):
    files = _bad_files(tmp_path)
    out = tmp_path / "result.json"
    argv = ["identify", *ROBOT, *(a.format(**files) for a in args), "--json", str(out)]
    assert main(argv) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("manip-id: error:")
    assert message in err[0]
    assert not out.exists()


def test_csv_with_a_column_map(tmp_path, capsys):
    """Another layout (time last, other names) read through --column; noise-free: exact fit."""
    robot = get_robot("ur5", friction="viscous,coulomb")
    sim = simulate(robot, random_trajectory(robot, harmonics=5, seed=5), duration=3.0, rate=100.0)
    ds = sim.dataset
    nv = robot.nv
    head = [f"{p}{j}" for p in ("pos", "vel", "acc", "effort") for j in range(nv)] + ["stamp"]
    path = tmp_path / "other.csv"
    np.savetxt(
        path,
        np.column_stack([ds.q, ds.dq, ds.ddq, ds.tau, ds.t]),
        delimiter=",",
        header=",".join(head),
        comments="",
        fmt="%.17g",
    )
    cols = [
        "--column",
        "t=stamp",
        "--column",
        "q=pos*",
        "--column",
        "dq=vel*",
        "--column",
        "ddq=acc*",
        "--column",
        "tau=" + ",".join(f"effort{j}" for j in range(nv)),
    ]
    status, report, _ = _run([*ROBOT, "--data", str(path), *cols], tmp_path, capsys)
    assert status == 0
    assert report["relative_error"]["train"] < 1e-6
    (tmp_path / "out.json").unlink()
    status, report, captured = _run(
        [*ROBOT, "--data", str(path), "--column", "q=angle*"], tmp_path, capsys
    )
    assert status == 2 and report is None
    assert "pattern 'angle*' of 'q' matches no column" in captured.err


def test_workers_give_the_serial_figures(tmp_path):
    serial, parallel = tmp_path / "serial.json", tmp_path / "parallel.json"
    common = ["identify", "ur5", "--simulate", "--duration", "5", "--split", "0.7"]
    assert main([*common, "--json", str(serial)]) == 0
    assert main([*common, "--workers", "2", "--json", str(parallel)]) == 0
    a, b = json.loads(serial.read_text()), json.loads(parallel.read_text())
    va = np.array([p["value"] for p in a["base_parameters"]])
    vb = np.array([p["value"] for p in b["base_parameters"]])
    np.testing.assert_allclose(vb, va, rtol=0, atol=1e-9 * np.abs(va).max())


def test_workers_need_a_least_squares_method(capsys):
    assert main(["identify", "ur5", "--simulate", "--method", "rls", "--workers", "2"]) == 2
    assert "--workers applies to ols and wls" in capsys.readouterr().err
