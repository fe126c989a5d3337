"""Closed-loop estimators with a known controller (manip_id.controller,
manip_id.control.closed_loop.tracking, manip_id.identification.closed_loop).

Independent checks: the simulated closed-loop log against the controller's law written out
here and against ``pinocchio.rnea`` of the true model; the IV and DIDIM estimates against
the truth of the simulation, as torques ``pinocchio.rnea`` predicts on a new noise-free
motion (not against the code's own outputs); the controller file's bad inputs.
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest
from conftest import get_robot

from manip_id.cli import main
from manip_id.control.closed_loop import simulate_tracking
from manip_id.controller import Controller, load_controller, read_reference
from manip_id.errors import InputError
from manip_id.identification import (
    ClosedLoopOptions,
    FileOptions,
    PreprocessOptions,
    RunOptions,
    identify,
)
from manip_id.simulation import MeasurementNoise
from manip_id.trajectories import random_trajectory

RATE = 1000.0  # [Hz]
FV = 0.05  # [N m s/rad]


def _truth(robot):
    theta = robot.nominal_parameters.copy()
    theta[robot.layout.joint_columns("fv")] = FV
    return theta


def _controller(robot, theta, wn):
    """Critically damped PD gains of natural frequency ``wn`` [rad/s] at the neutral pose."""
    model = robot.with_parameters(theta)
    mjj = np.diag(pin.crba(model, model.createData(), pin.neutral(model))).copy()
    return Controller(mjj * wn**2, 2 * mjj * wn, None)


def _write_toml(path, ctrl):
    path.write_text(f"kp = {ctrl.kp.tolist()}\nkd = {ctrl.kd.tolist()}\n")
    return path


def _save(path, log):
    d = log.dataset
    np.savez(path, t=d.t, q=d.q, dq=d.dq, tau=d.tau, qref=log.q_ref, dqref=log.dq_ref)
    return path


# ------------------------------------------------------------------ the log itself
def test_a_closed_loop_log_is_the_pd_law_and_the_true_dynamics():
    robot = get_robot("double_pendulum", friction="viscous")
    theta = _truth(robot)
    ctrl = _controller(robot, theta, 20.0)
    traj = random_trajectory(robot, harmonics=3, seed=4)
    log = simulate_tracking(robot, traj, ctrl, duration=2.0, rate=2000.0, theta=theta)
    d = log.dataset
    # the commanded torque is the PD law on the logged columns, written out here
    law = ctrl.kp * (log.q_ref - d.q) + ctrl.kd * (log.dq_ref - d.dq)
    np.testing.assert_allclose(d.tau, law, rtol=1e-12, atol=1e-12)
    # and the motion obeys the true dynamics: rnea(q, dq, ddq) = tau, ddq by differences
    model = robot.with_parameters(theta)
    data = model.createData()
    ddq = np.gradient(d.dq, d.t, axis=0)
    k = np.arange(100, len(d.t) - 100, 37)
    rnea = np.array([pin.rnea(model, data, d.q[i], d.dq[i], ddq[i]) for i in k]) + FV * d.dq[k]
    scale = np.abs(d.tau).max(axis=0)
    assert np.max(np.abs(rnea - d.tau[k]) / scale) < 0.02  # ZOH + first differences
    assert d.ddq is None  # a robot measures no accelerations


# ------------------------------------------------------------------ recovery
@pytest.fixture(scope="module")
def closed_loop(tmp_path_factory):
    """A PD closed-loop log of the double pendulum with noisy positions and 1 % torque noise,
    and the true torques on a new noise-free motion (rnea of the truth)."""
    robot = get_robot("double_pendulum", friction="viscous")
    theta = _truth(robot)
    ctrl = _controller(robot, theta, 30.0)
    traj = random_trajectory(robot, harmonics=3, seed=2)
    noise = MeasurementNoise(tau=0.01, q=1e-3)
    log = simulate_tracking(
        robot, traj, ctrl, duration=4.0, rate=RATE, theta=theta, noise=noise, seed=1
    )
    folder = tmp_path_factory.mktemp("closed_loop")
    path = _save(folder / "run.npz", log)
    new = random_trajectory(robot, harmonics=3, seed=7)
    t = np.arange(0.0, 5.0, 0.01)
    q, dq, ddq = new.sample(t)
    model = robot.with_parameters(theta)
    data = model.createData()
    tau = np.array([pin.rnea(model, data, q[i], dq[i], ddq[i]) for i in range(len(t))])
    tau += FV * dq
    return robot, ctrl, path, (q, dq, ddq, tau)


def _error(robot, result, motion) -> float:
    q, dq, ddq, tau = motion
    pred = result.predict(robot, q, dq, ddq)
    return float(np.linalg.norm(pred - tau) / np.linalg.norm(tau))


def test_iv_and_didim_beat_biased_least_squares(closed_loop):
    robot, ctrl, path, motion = closed_loop
    files = FileOptions(preprocess=PreprocessOptions(cutoff=60.0))
    run = RunOptions(workers=1)
    ols = identify(robot, [str(path)], method="ols", files=files, run=run)
    errors = {"ols": _error(robot, ols, motion)}
    for method in ("iv", "didim"):
        opts = FileOptions(preprocess=files.preprocess, closed_loop=ClosedLoopOptions(method, ctrl))
        res = identify(robot, [str(path)], method="ols", files=opts, run=run)
        rec = res.context["closed_loop"]
        assert res.method == method and rec["converged"] and rec["start"] == "ols"
        assert rec["iterations"] == len(rec["history"]) >= 2
        errors[method] = _error(robot, res, motion)
    assert errors["ols"] > 1e-3, errors  # least squares is biased here
    assert errors["iv"] < 0.85 * errors["ols"], errors
    assert errors["didim"] < 0.5 * errors["ols"], errors


# ------------------------------------------------------------------ the controller file
@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("kp = [1.0, 2.0]\n", "missing kd"),
        ("kp = [1.0, 2.0]\nkd = [1.0]\n", "kd must be a list of 2 gains"),
        ("kp = [1.0, -2.0]\nkd = [1.0, 1.0]\n", "kp[1] must be a number >= 0"),
        ('kp = [1.0, "a"]\nkd = [1.0, 1.0]\n', "kp[1] must be a finite number"),
        ("kp = [0.0, 0.0]\nkd = [1.0, 1.0]\n", "kp must hold a positive gain"),
        ("kp = [1.0, 2.0]\nkd = [1.0, 1.0]\nkv = [1.0, 1.0]\n", "unknown key 'kv'"),
        ("kp = [1.0, 2.0]\nkd = [1.0, 1.0]\nki = 3\n", "ki must be a non-empty list"),
        ('kp = [1, 2]\nkd = [1, 1]\n[reference]\nq = "q"\n', "reference.q must be a column"),
        ('kp = [1, 2]\nkd = [1, 1]\n[reference]\nq = "dqref"\n', "both 'dqref'"),
        ('kp = [1, 2]\nkd = [1, 1]\n[reference]\nq = "q_ref"\n', "starts like a measured"),
        ("kp = [1.0, 2.0\n", "cannot read controller file"),
    ],
)
def test_bad_controller_files_are_one_error_naming_file_and_key(tmp_path, text, message):
    path = tmp_path / "ctrl.toml"
    path.write_text(text)
    with pytest.raises(InputError) as info:
        load_controller(path, 2)
    assert message in str(info.value) and str(path) in str(info.value)


def test_a_pid_log_is_the_pid_law_and_its_csv_reads_back(tmp_path):
    robot = get_robot("double_pendulum", friction="viscous")
    path = tmp_path / "pid.toml"
    path.write_text(
        'kp = [12.0, 4.0]\nkd = [0.9, 0.3]\nki = [30.0, 10.0]\n[reference]\nq = "qd_ref"\n'
    )
    ctrl = load_controller(path, 2)
    assert ctrl.kind == "pid" and ctrl.to_dict()["reference"] == {"q": "qd_ref", "dq": "dqref"}
    traj = random_trajectory(robot, harmonics=3, seed=4)
    log = simulate_tracking(robot, traj, ctrl, duration=0.5, rate=1000.0)
    d = log.dataset
    e = log.q_ref - d.q
    law = ctrl.kp * e + ctrl.kd * (log.dq_ref - d.dq) + ctrl.ki * np.cumsum(e, axis=0) / 1000.0
    np.testing.assert_allclose(d.tau, law, rtol=1e-10, atol=1e-12)
    # a CSV log's reference columns qd_ref_<joint>, dqref_<joint> read back
    csv = tmp_path / "pid.csv"
    names = robot.joint_names
    head = ["t"] + [f"{f}_{j}" for f in ("q", "dq", "tau", "qd_ref", "dqref") for j in names]
    rows = np.column_stack([d.t, d.q, d.dq, d.tau, log.q_ref, log.dq_ref])
    np.savetxt(csv, rows, delimiter=",", header=",".join(head), comments="", fmt="%.17g")
    t, q_ref, dq_ref = read_reference(csv, ctrl, 2)
    np.testing.assert_allclose(q_ref, log.q_ref, rtol=1e-15)
    np.testing.assert_allclose(dq_ref, log.dq_ref, rtol=1e-15)


@pytest.mark.parametrize(
    ("extra", "message"),
    [
        (["--method", "iv"], "give the logs' controller with --controller"),
        (["--method", "didim"], "give the logs' controller with --controller"),
        (["--controller", "C"], "--controller applies to --method iv or didim"),
        (["--method", "iv", "--controller", "C", "--per-file"], "no --scheduler or --per-file"),
        (
            ["--method", "iv", "--controller", "C", "--refine", "output-error"],
            "both replace the estimate",
        ),
        (["--method", "didim", "--controller", "C", "--consistent"], "--consistent applies"),
    ],
)
def test_bad_closed_loop_options_fail_in_one_line(closed_loop, tmp_path, capsys, extra, message):
    robot, ctrl, path, _ = closed_loop
    toml = str(_write_toml(tmp_path / "ctrl.toml", ctrl))
    extra = [toml if a == "C" else a for a in extra]
    argv = ["identify", "double_pendulum", "--friction", "viscous", "--data", str(path)]
    assert main([*argv, *extra]) == 2
    err = capsys.readouterr().err
    assert message in err and err.count("\n") == 1, err


def test_a_log_without_the_reference_is_refused_before_work(closed_loop, tmp_path, capsys):
    robot, ctrl, path, _ = closed_loop
    with np.load(path) as z:
        plain = {k: z[k] for k in ("t", "q", "dq", "tau")}
    bare = tmp_path / "open_loop.npz"
    np.savez(bare, **plain)
    toml = str(_write_toml(tmp_path / "ctrl.toml", ctrl))
    argv = ["identify", "double_pendulum", "--friction", "viscous", "--data", str(bare)]
    assert main([*argv, "--method", "iv", "--controller", toml]) == 2
    err = capsys.readouterr().err
    assert "no reference arrays qref, dqref" in err and err.count("\n") == 1, err


def test_a_controller_of_another_size_is_refused(closed_loop, tmp_path, capsys):
    _, _, path, _ = closed_loop
    toml = tmp_path / "ctrl.toml"
    toml.write_text("kp = [1.0, 2.0, 3.0]\nkd = [1.0, 1.0, 1.0]\n")
    argv = ["identify", "double_pendulum", "--friction", "viscous", "--data", str(path)]
    assert main([*argv, "--method", "iv", "--controller", str(toml)]) == 2
    assert "kp must be a list of 2 gains" in capsys.readouterr().err


def test_simulate_writes_a_closed_loop_log_with_its_reference(tmp_path, capsys):
    robot = get_robot("double_pendulum", friction="viscous")
    ctrl = _controller(robot, robot.nominal_parameters, 20.0)
    toml = _write_toml(tmp_path / "ctrl.toml", ctrl)
    out = tmp_path / "sim"
    argv = ["simulate", "double_pendulum", "--friction", "viscous", "--out", str(out)]
    argv += ["--files", "1", "--duration", "1", "--rate", "500", "--controller", str(toml)]
    assert main([*argv, "--position-noise", "1e-4", "--quiet"]) == 0
    with np.load(out / "run_0.npz") as z:
        assert {"qref", "dqref", "t", "q", "dq", "tau"} <= set(z.files) and "ddq" not in z.files
        law = ctrl.kp * (z["qref"] - z["q"]) + ctrl.kd * (z["dqref"] - z["dq"])
        assert np.allclose(z["tau"], law, rtol=0.1, atol=0.1 * np.abs(law).max())
    assert main([*argv, "--format", "mcap", "--out", str(tmp_path / "m")]) == 2
    assert "--format npz or csv" in capsys.readouterr().err
