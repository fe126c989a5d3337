"""Transmissions: motor-side logs, couplings and motor terms (manip_id.robot.transmission).

The truth is computed here without the regressor: ``pinocchio.rnea`` plus the motor
terms written out by hand on the motor velocities, mapped by ``R^T``; the motor-side
log is converted by hand (``theta = R (q - offset)``, ``tau_m = R^-T tau``).
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

from manip_id.datasets import FileSpec
from manip_id.errors import DataError, InputError
from manip_id.identification import FileOptions, PreprocessOptions, identify
from manip_id.robot.model import load_robot
from manip_id.robot.regressor import regressor
from manip_id.robot.transmission import Transmission
from manip_id.signals.bandwidth import choose_cutoff

TERMS = ["inertia", "viscous", "coulomb", "offset"]


def wrist_matrix() -> np.ndarray:
    """Ratios 50-100, motor 6 driving joints 5 and 6 (theta_6 = 50 (q5 + q6))."""
    R = np.diag([100.0, 100.0, 80.0, 60.0, 50.0, 50.0])
    R[5, 4] = 50.0
    return R


def motor_truth(n: int) -> np.ndarray:
    """Per motor [Ia, fv, fc, fo] (kg m^2, N m s/rad, N m, N m), motor-major."""
    ia = np.linspace(2e-4, 5e-5, n)
    fv = np.linspace(4e-3, 1e-3, n)
    fc = np.linspace(0.05, 0.02, n)
    fo = np.linspace(0.01, -0.01, n)
    return np.stack([ia, fv, fc, fo], axis=1).ravel()


def trajectory(robot, rate: float, duration: float, phase: float):
    """A smooth multi-sine joint trajectory (exact derivatives), around the neutral pose."""
    t = np.arange(0.0, duration, 1.0 / rate)
    freqs = np.array([0.15, 0.35, 0.6])
    q, dq, ddq = (np.zeros((t.size, robot.nv)) for _ in range(3))
    for j in range(robot.nv):
        for k, f in enumerate(freqs):
            a = 0.5 / (k + 1)
            w = 2 * np.pi * f * (1 + 0.1 * j)
            ph = phase + 0.7 * j + 1.3 * k
            q[:, j] += a * np.sin(w * t + ph)
            dq[:, j] += a * w * np.cos(w * t + ph)
            ddq[:, j] -= a * w**2 * np.sin(w * t + ph)
    return t, q, dq, ddq


def true_torques(robot, tr: Transmission, coeffs, q, dq, ddq) -> np.ndarray:
    """rnea + R^T (Ia ddtheta + fv dtheta + fc sign(dtheta) + fo), by hand."""
    tau = np.array(
        [pin.rnea(robot.model, robot.data, a, b, c) for a, b, c in zip(q, dq, ddq, strict=False)]
    )
    R = tr.R
    c = np.asarray(coeffs).reshape(tr.n, 4)
    dth, ddth = dq @ R.T, ddq @ R.T
    tau_m = c[:, 0] * ddth + c[:, 1] * dth + c[:, 2] * np.sign(dth) + c[:, 3]
    return tau + tau_m @ R


def motor_log(path, tr, t, q, dq, ddq, tau, *, positions_only=False):
    """The motor-side NPZ, converted by hand."""
    R = tr.R
    theta = (q - tr.q0) @ R.T
    tau_m = np.linalg.solve(R.T, tau.T).T  # tau = R^T tau_m
    if positions_only:  # no t (a rate instead), no dq, no ddq
        np.savez(path, q=theta, tau=tau_m)
    else:
        np.savez(path, t=t, q=theta, dq=dq @ R.T, ddq=ddq @ R.T, tau=tau_m)
    return path


def test_conversion_round_trip_by_hand():
    R = np.array([[2.0, 0.0], [3.0, -4.0]])
    tr = Transmission(R, offset=[0.1, -0.2], signals="motor")
    q = np.array([0.5, 1.0])
    theta = tr.to_motor(q=q)[0]
    assert theta == pytest.approx([2 * 0.4, 3 * 0.4 - 4 * 1.2])
    tau_m = np.array([1.0, 2.0])
    tau = tr.to_joint(tau_motor=tau_m)[3]
    assert tau == pytest.approx([2 * 1 + 3 * 2, -4 * 2])  # R^T tau_m
    back = tr.to_joint(theta, [1.0, 1.0], [2.0, 0.0], tau_m)
    assert back[0] == pytest.approx(q)
    assert R @ back[1] == pytest.approx([1.0, 1.0])
    assert R @ back[2] == pytest.approx([2.0, 0.0])
    assert tr.to_motor(tau=back[3])[3] == pytest.approx(tau_m)


def test_bad_transmissions_say_what_came():
    with pytest.raises(InputError, match="square"):
        Transmission([[1.0, 2.0]])
    with pytest.raises(InputError, match="invertible"):
        Transmission([[1.0, 2.0], [2.0, 4.0]])
    with pytest.raises(InputError, match="signals"):
        Transmission(np.eye(2), signals="motors")
    with pytest.raises(InputError, match="motor_terms holds 'spring'"):
        Transmission(np.eye(2), motor_terms=["spring"])
    with pytest.raises(InputError, match="nv=6"):
        load_robot("ur5").with_transmission(Transmission(np.eye(2)))


def test_coupled_regressor_equals_rnea_plus_motor_terms():
    tr = Transmission(wrist_matrix(), signals="motor", motor_terms=TERMS)
    robot = load_robot("ur5").with_transmission(tr)
    assert robot.parameter_names[-4:] == ["motor6.Ia", "motor6.fv", "motor6.fc", "motor6.fo"]
    q, dq, ddq = robot.random_states(20, seed=3)
    theta = robot.nominal_parameters.copy()
    theta[robot.layout.motor_start :] = motor_truth(6)
    Y = regressor(robot, q, dq, ddq)
    want = true_torques(robot, tr, motor_truth(6), q, dq, ddq)
    assert np.abs(Y @ theta - want).max() < 1e-9 * np.abs(want).max()
    # motor 6's terms act on both joints it drives
    col = robot.parameter_index("motor6.fv")
    assert np.all(Y[:, 4, col] != 0) and np.all(Y[:, 5, col] != 0)


def test_diagonal_motor_terms_equal_scaled_joint_terms():
    R = np.diag([100.0, -80.0, 60.0, 50.0, 50.0, 40.0])
    tr = Transmission(R, motor_terms=["inertia", "viscous", "coulomb", "offset"])
    motor = load_robot("ur5").with_transmission(tr)
    joint = load_robot("ur5", armature=True, friction="viscous,coulomb,offset")
    q, dq, ddq = motor.random_states(10, seed=1)
    c = motor_truth(6)
    eq = tr.joint_equivalent(c)
    th_m = motor.nominal_parameters.copy()
    th_m[motor.layout.motor_start :] = c
    th_j = joint.nominal_parameters.copy()
    for short, values in eq.items():
        th_j[joint.layout.joint_columns(short)] = values
    a = regressor(motor, q, dq, ddq) @ th_m
    b = regressor(joint, q, dq, ddq) @ th_j
    assert np.abs(a - b).max() < 1e-9 * np.abs(b).max()


@pytest.fixture(scope="module")
def wrist(tmp_path_factory):
    folder = tmp_path_factory.mktemp("wrist")
    tr = Transmission(wrist_matrix(), signals="motor", motor_terms=TERMS)
    robot = load_robot("ur5").with_transmission(tr)
    coeffs = motor_truth(6)
    runs = {}
    for name, phase in (("train", 0.0), ("valid", 2.0)):
        t, q, dq, ddq = trajectory(robot, 200.0, 30.0, phase)
        runs[name] = (t, q, dq, ddq, true_torques(robot, tr, coeffs, q, dq, ddq))
    return folder, tr, robot, coeffs, runs


def _identify(robot, train, valid, options=None):
    files = FileOptions(preprocess=options or PreprocessOptions(), audit=False)
    return identify(robot, [train], validation=[valid], method="ols", files=files)


def _motor_estimates(result, coeffs, tr):
    got = {}
    for name, value, std in zip(result.names, result.estimate, result.std, strict=True):
        if name.startswith("motor") and name.endswith((".fv", ".fc")):
            got[name] = (value, std, coeffs[list(tr.parameter_names).index(name)])
    return got


def test_motor_side_log_identified_to_round_off(wrist):
    folder, tr, robot, coeffs, runs = wrist
    specs = [
        FileSpec(motor_log(folder / f"{k}.npz", tr, *runs[k]), transmission=tr)
        for k in ("train", "valid")
    ]
    result = _identify(robot, *specs)
    # normal equations (A = Y^T Y) of a regressor scaled by ratios up to 100: cond^2 round-off
    assert result.relative_error.validation < 1e-6
    got = _motor_estimates(result, coeffs, tr)
    assert {"motor6.fv", "motor6.fc", "motor1.fv"} <= set(got)
    for _name, (value, _, truth) in got.items():
        assert value == pytest.approx(truth, rel=1e-5, abs=1e-9)


def test_coupled_wrist_with_noise_at_the_noise_floor(wrist):
    folder, tr, robot, coeffs, runs = wrist
    rng = np.random.default_rng(7)
    specs = []
    for k in ("train", "valid"):
        t, q, dq, ddq, tau = runs[k]
        rms = np.sqrt(np.mean(tau**2, axis=0))
        noisy = tau + 0.01 * rms * rng.standard_normal(tau.shape)
        path = motor_log(folder / f"noisy_{k}.npz", tr, t, q, dq, ddq, noisy)
        specs.append(FileSpec(path, transmission=tr))
    result = _identify(robot, *specs)
    floor = 0.01 / np.sqrt(1 + 0.01**2)  # relative error of the truth itself
    ratio = np.asarray(result.relative_error.validation_per_joint) / floor
    assert np.all(ratio < 1.5), ratio  # the coupled joints 5 and 6 as well as the others
    for name, (value, std, truth) in _motor_estimates(result, coeffs, tr).items():
        assert abs(value - truth) < 3 * std + 1e-12, name


def test_positions_only_log_without_time_column(wrist):
    """dq derived from q (no t, no dq in the file) against the true dq, same preprocessing
    (the zero-phase filter, ddq differentiated, cut-off auto), 1 % torque noise."""
    folder, tr, robot, coeffs, runs = wrist
    errors = {}
    for mode in ("true_dq", "positions"):
        rng = np.random.default_rng(11)  # the same noise for both
        specs = []
        for k in ("train", "valid"):
            t, q, dq, ddq, tau = runs[k]
            rms = np.sqrt(np.mean(tau**2, axis=0))
            noisy = tau + 0.01 * rms * rng.standard_normal(tau.shape)
            path = folder / f"{mode}_{k}.npz"
            if mode == "positions":
                motor_log(path, tr, t, q, dq, ddq, noisy, positions_only=True)
            else:
                R = tr.R
                tau_m = np.linalg.solve(R.T, noisy.T).T
                np.savez(path, t=t, q=(q - tr.q0) @ R.T, dq=dq @ R.T, tau=tau_m)
            rate = 200.0 if mode == "positions" else None
            specs.append(FileSpec(path, transmission=tr, rate=rate))
        opts = PreprocessOptions(cutoff="auto")
        errors[mode] = _identify(robot, *specs, options=opts).relative_error.validation
    assert errors["positions"] < 1.2 * errors["true_dq"], errors


def test_positions_only_coupled_wrist_at_the_noise_floor(wrist):
    """The issue's "done when": a motor-side, positions-only, coupled-wrist log at 1 %
    torque noise, cut-off auto: every joint's validation error against the raw torques
    within 1.5x of the noise floor (1 % of each joint's torque RMS)."""
    folder, tr, robot, coeffs, runs = wrist
    rng = np.random.default_rng(5)
    specs = []
    for k in ("train", "valid"):
        t, q, dq, ddq, tau = runs[k]
        rms = np.sqrt(np.mean(tau**2, axis=0))
        noisy = tau + 0.01 * rms * rng.standard_normal(tau.shape)
        path = motor_log(folder / f"floor_{k}.npz", tr, t, q, dq, ddq, noisy, positions_only=True)
        specs.append(FileSpec(path, transmission=tr, rate=200.0))
    result = _identify(robot, *specs, options=PreprocessOptions(cutoff="auto"))
    raw = np.asarray(result.raw_error.validation_per_joint)
    floor = 0.01 / np.sqrt(1 + 0.01**2)
    assert np.all(raw / floor < 1.5), raw / floor


def test_file_without_time_or_rate_is_refused(tmp_path):
    np.savez(tmp_path / "a.npz", q=np.zeros((10, 2)), tau=np.zeros((10, 2)))
    from manip_id.datasets import open_source

    with pytest.raises(DataError, match="no time column.*--rate"):
        open_source(FileSpec(tmp_path / "a.npz"))


def test_derived_velocities_match_the_true_ones(wrist):
    folder, tr, robot, coeffs, runs = wrist
    t, q, dq, ddq, tau = runs["train"]
    np.savez(folder / "joint_positions.npz", q=q, tau=tau)
    from manip_id.datasets import load_dataset

    ds = load_dataset(folder / "joint_positions.npz", rate=200.0)
    assert ds.meta["dq"] == "central differences of q"
    # central differences: error (h^2 / 6) max|dddq| inside, one-sided O(h^2) at the ends
    h = 1.0 / 200.0
    dddq_max = np.abs(np.gradient(ddq, h, axis=0)).max()
    assert np.abs(ds.dq[1:-1] - dq[1:-1]).max() < 1.05 * h**2 / 6 * dddq_max


@pytest.mark.parametrize("rate", [100.0, 5000.0])
def test_cutoff_from_the_velocity_spectrum(rate):
    t = np.arange(0.0, 40.0, 1.0 / rate)
    q = np.stack([np.sin(2 * np.pi * 1.6 * t) + 0.2 * np.sin(2 * np.pi * 8.0 * t)], axis=1)
    q += np.random.default_rng(0).normal(0.0, 1e-4, q.shape)  # encoder noise
    choice = choose_cutoff(t, q)
    # 8 Hz holds 0.2^2 * 5^2 = 1 of the velocity power against 1 at 1.6 Hz: f_99 = 8 Hz,
    # within the Hann window's main lobe (+-2 bins of 1 / 10 s)
    assert choice.bandwidth[0] == pytest.approx(8.0, abs=0.2)
    want = min(3 * choice.bandwidth[0], rate / 5)  # 24 Hz, or capped at 20 Hz for 100 Hz
    assert choice.cutoff == pytest.approx(want)
    assert "99%" in choice.reason and ("3 x" in choice.reason or "capped" in choice.reason)


def test_slow_motion_gets_the_minimum_cutoff():
    t = np.arange(0.0, 30.0, 1e-3)
    choice = choose_cutoff(t, np.sin(2 * np.pi * 0.5 * t)[:, None])
    assert choice.bandwidth[0] == pytest.approx(0.5, abs=0.2)
    assert choice.cutoff == 20.0 and "minimum" in choice.reason


def test_sidecar_round_trip_carries_the_transmission(tmp_path):
    from manip_id.export import export_urdf

    tr = Transmission(wrist_matrix(), signals="motor", motor_terms=TERMS)
    robot = load_robot("ur5").with_transmission(tr)
    theta = robot.nominal_parameters.copy()
    theta[robot.layout.motor_start :] = motor_truth(6)
    out = export_urdf(robot, theta, tmp_path / "ur5_id.urdf")
    back = load_robot(out.path, identified=True)
    assert back.transmission is not None
    assert np.array_equal(back.transmission.R, tr.R)
    assert back.transmission.signals == "motor"
    assert back.parameter_names == robot.parameter_names
    q, dq, ddq = robot.random_states(10, seed=2)
    a = regressor(robot, q, dq, ddq) @ theta
    b = regressor(back, q, dq, ddq) @ back.nominal_parameters
    assert np.abs(a - b).max() < 1e-9 * np.abs(a).max()


def test_diagonal_transmission_written_as_urdf_transmissions(tmp_path):
    import xml.etree.ElementTree as ET

    from manip_id.export import export_urdf

    R = np.diag([100.0, -80.0, 60.0, 50.0, 50.0, 40.0])
    robot = load_robot("ur5").with_transmission(Transmission(R, motor_terms=["viscous"]))
    out = export_urdf(robot, robot.nominal_parameters, tmp_path / "ur5_diag.urdf")
    root = ET.parse(out.path).getroot()
    got = {
        t.find("joint").get("name"): float(t.find("actuator/mechanicalReduction").text)
        for t in root.findall("transmission")
    }
    assert got == dict(zip(robot.dof_names, np.diag(R).tolist(), strict=True))


def test_cutoff_on_the_real_panda_log():
    """The real Panda log (skips when absent): a slow excitation (below 1 Hz on every joint
    whose motion stands above its noise; joint 3 is noise-dominated and named), so the
    cut-off is the 20 Hz minimum."""
    from pathlib import Path

    from manip_id.datasets import load_dataset

    folder = Path("/work/shared/data/panda_gaz2019")
    if not folder.is_dir():
        pytest.skip("the real Panda log is not in /work/shared/data")
    ds = load_dataset(folder)
    choice = choose_cutoff(ds.t, ds.q, names=ds.joint_names)
    kept = [
        b for n, b in zip(ds.joint_names, choice.bandwidth, strict=True) if n not in choice.reason
    ]
    assert max(kept) < 1.0  # [Hz]
    assert choice.cutoff == 20.0 and "minimum" in choice.reason


def test_files_as_tasks_carry_the_drive_train(wrist):
    """Per-file estimates (files as tasks, the drift path) with a transmission: the workers'
    robot keeps its drive train (it was dropped: IndexError on the motor columns), and the
    pooled estimate equals the one of the file read here."""
    from manip_id.identification import PartitionOptions

    folder, tr, robot, coeffs, runs = wrist
    spec = FileSpec(motor_log(folder / "tasks.npz", tr, *runs["train"]), transmission=tr)
    here = identify(robot, [spec], method="ols", files=FileOptions(audit=False))
    tasks = identify(
        robot,
        [spec],
        method="ols",
        files=FileOptions(audit=False, partition=PartitionOptions(per_file=True)),
    )
    np.testing.assert_allclose(tasks.estimate, here.estimate, rtol=1e-9, atol=1e-12)
    assert tasks.per_file[0].error is None


def test_monitor_and_drift_read_motor_side_logs_through_the_drive_train(tmp_path, capsys):
    """A motor-side log of a robot with gear ratios (no motor terms): monitor converts it as
    identify does (no alarm on a collision-free run), drift finds it unchanged; a model with
    motor terms is refused by the monitor in one line (it does not model them)."""
    import json

    from manip_id.cli import main

    gears = tmp_path / "gears.toml"
    gears.write_text(
        "matrix = [[100, 0, 0, 0, 0, 0], [0, 100, 0, 0, 0, 0], [0, 0, 80, 0, 0, 0],\n"
        "          [0, 0, 0, 60, 0, 0], [0, 0, 0, 0, 50, 0], [0, 0, 0, 0, 50, 50]]\n"
        'signals = "motor"\n'
    )
    sim, ref = tmp_path / "sim", tmp_path / "ref.json"
    argv = ["simulate", "ur5", "--out", str(sim), "--files", "3", "--duration", "4"]
    assert main([*argv, "--transmission", str(gears), "--friction", "viscous", "--quiet"]) == 0
    run = [str(sim / f"run_{k}.npz") for k in range(3)]
    fit = ["identify", "ur5", "--friction", "viscous", "--transmission", str(gears)]
    assert main([*fit, "--data", run[0], "--validate", run[1], "--json", str(ref), "--quiet"]) == 0
    out = tmp_path / "monitor.json"
    argv = ["monitor", "ur5", "--model", str(ref), "--calibrate", run[1], "--data", run[2]]
    assert main([*argv, "--json", str(out)]) == 0
    doc = json.loads(out.read_text())
    assert doc["detections"] == [] and doc["files"][0]["n_samples"] > 700
    assert main(["drift", "ur5", "--reference", str(ref), "--data", run[2]]) == 0
    assert "unchanged" in capsys.readouterr().out
    motors = tmp_path / "motors.toml"
    motors.write_text(gears.read_text() + 'motor_terms = ["viscous"]\n')
    ref_m = tmp_path / "ref_m.json"
    fit_m = ["identify", "ur5", "--friction", "viscous", "--transmission", str(motors)]
    assert main([*fit_m, "--data", run[0], "--json", str(ref_m), "--quiet"]) == 0
    capsys.readouterr()
    assert main(["monitor", "ur5", "--model", str(ref_m), "--calibrate", run[1],
                 "--data", run[2]]) == 2  # fmt: skip
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "does not model motor terms" in err[0], err
