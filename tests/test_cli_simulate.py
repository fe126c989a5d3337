"""``manip-id simulate``: the logs load through the real readers, their torques are Pinocchio's
inverse dynamics of the stated truth, and the commands recover that truth from them."""

from __future__ import annotations

import json

import numpy as np
import pinocchio as pin
import pytest

from manip_id import identify, load_dataset, load_robot, with_payload
from manip_id.cli import main


def _simulate(capsys, *argv) -> str:
    status = main(["simulate", *map(str, argv)])
    out = capsys.readouterr()
    assert status == 0, out.err
    return out.out


def _rnea(model, d) -> np.ndarray:
    data = model.createData()
    return np.array([pin.rnea(model, data, *s) for s in zip(d.q, d.dq, d.ddq, strict=True)])


@pytest.mark.parametrize("fmt", ["npz", "csv"])
def test_noise_free_logs_are_rnea_and_identify_recovers_the_base_parameters(tmp_path, capsys, fmt):
    out = tmp_path / "sim"
    _simulate(capsys, "panda", "--out", out, "--files", 2, "--duration", 8, "--noise", 0,
              "--format", fmt)  # fmt: skip
    robot = load_robot("panda")
    logs = [load_dataset(out / f"run_{k}.{fmt}") for k in range(2)]
    assert not np.allclose(logs[0].q, logs[1].q)  # two trajectories, not one repeated
    for d in logs:
        assert (
            d.joint_names == tuple(robot.joint_names) and d.n_samples == 8 * 200 + 1
        )  # t = 0 ... 8 s
        np.testing.assert_allclose(d.tau, _rnea(robot.model, d), rtol=0, atol=1e-9)
    truth = json.loads((out / "truth.json").read_text())
    theta = np.array([truth["parameters"][n] for n in robot.parameter_names])
    np.testing.assert_array_equal(theta, robot.nominal_parameters)
    d = logs[0]
    res = identify(robot, (d.q, d.dq, d.ddq, d.tau))
    beta = res.base.to_base(theta)
    assert np.linalg.norm(res.estimate - beta) <= 1e-6 * np.linalg.norm(beta)
    assert "noise" in (out / "README.txt").read_text()


def test_mcap_logs_read_back_as_the_npz_ones(tmp_path, capsys):
    args = ["ur5", "--files", 1, "--duration", 2, "--seed", 4]
    _simulate(capsys, *args, "--out", tmp_path / "a", "--format", "mcap")
    _simulate(capsys, *args, "--out", tmp_path / "b")
    bag, npz = (
        load_dataset(tmp_path / "a" / "run_0.mcap"),
        load_dataset(tmp_path / "b" / "run_0.npz"),
    )
    assert bag.ddq is None and bag.joint_names == npz.joint_names
    for name in ("t", "q", "dq", "tau"):
        np.testing.assert_allclose(getattr(bag, name), getattr(npz, name), rtol=0, atol=1e-9)


def test_payload_runs_carry_the_payload_and_the_payload_command_finds_its_mass(tmp_path, capsys):
    out = tmp_path / "sim"
    _simulate(capsys, "ur5", "--out", out, "--files", 2, "--duration", 10, "--noise", 0.005,
              "--payload", 1.3)  # fmt: skip
    robot = load_robot("ur5")
    loaded = load_dataset(out / "payload_1.3kg_0.npz")
    model = robot.model.copy()  # the truth: the nominal model with the point mass on it
    theta = with_payload(robot, robot.nominal_parameters, 1.3)
    model.inertias[-1] = pin.Inertia.FromDynamicParameters(theta[-10:])
    clean = _rnea(model, loaded)
    noise = (loaded.tau - clean).std(axis=0) / np.sqrt((clean**2).mean(axis=0))
    np.testing.assert_allclose(noise, 0.005, rtol=0.15)  # the stated relative noise
    truth = json.loads((out / "truth.json").read_text())["payload"]
    status = main(["payload", "ur5", "--unloaded", *map(str, sorted(out.glob("run_*.npz"))),
                   "--loaded", *map(str, sorted(out.glob("payload_*.npz"))),
                   "--frame", truth["frame"], "--json", str(tmp_path / "p.json")])  # fmt: skip
    assert status == 0, capsys.readouterr().err
    got = json.loads((tmp_path / "p.json").read_text())["payload"]
    assert abs(got["mass"] - 1.3) < 0.02 * 1.3
    np.testing.assert_allclose(got["com"], truth["com"], atol=0.01)  # [m]


def test_drive_gains_write_currents_and_the_drive_gains_command_finds_the_gains(tmp_path, capsys):
    out = tmp_path / "sim"
    _simulate(capsys, "ur5", "--out", out, "--files", 1, "--duration", 10, "--noise", 0.005,
              "--payload", 1.3, "--drive-gains", "8,8,8,3,3,3")  # fmt: skip
    gains = np.array([8.0, 8, 8, 3, 3, 3])  # [N m/A]
    d = load_dataset(out / "run_0.npz")
    clean = _rnea(load_robot("ur5").model, d)
    noise = (d.tau * gains - clean).std(axis=0) / np.sqrt((clean**2).mean(axis=0))
    np.testing.assert_allclose(noise, 0.005, rtol=0.15)
    status = main(["drive-gains", "ur5", "--unloaded", str(out / "run_0.npz"),
                   "--loaded", str(out / "payload_1.3kg_0.npz"), "--frame", "wrist_3_joint",
                   "--payload-mass", "1.3", "--json", str(tmp_path / "g.json")])  # fmt: skip
    assert status == 0, capsys.readouterr().err
    got = json.loads((tmp_path / "g.json").read_text())["drive_gains"]
    assert [g["joint"] for g in got] == load_robot("ur5").joint_names
    np.testing.assert_allclose([g["gain"] for g in got], gains, rtol=0.01)


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["--files", "0"], "--files must be >= 1, got 0"),
        (["--payload", "-1"], "--payload masses must be in (0, 10000]"),
        (["--noise", "-0.1"], "--noise must be in [0, 100]"),
        (["--drive-gains", "1,2"], "--drive-gains takes 1 or 6 gains"),
        (["--format", "xls"], "invalid choice: 'xls'"),
    ],
)
def test_bad_options_are_one_line_exit_2(tmp_path, capsys, argv, message):
    assert main(["simulate", "ur5", "--out", str(tmp_path / "sim"), *argv]) == 2
    err = capsys.readouterr().err
    assert message in err and err.count("\n") == 1 and err.startswith("manip-id")
    assert not (tmp_path / "sim").exists()


def test_an_existing_folder_is_refused_and_a_users_folder_never_replaced(tmp_path, capsys):
    out = tmp_path / "sim"
    argv = ["simulate", "ur5", "--out", str(out), "--files", "1", "--duration", "1"]
    assert main(argv) == 0
    first = (out / "run_0.npz").read_bytes()
    capsys.readouterr()
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert "exists and is not empty" in err and err.count("\n") == 1
    assert main([*argv, "--seed", "3", "--force"]) == 0  # a folder manip-id wrote
    assert (out / "run_0.npz").read_bytes() != first
    mine = tmp_path / "mine"
    mine.mkdir()
    (mine / "notes.txt").write_text("keep")
    capsys.readouterr()
    assert main(["simulate", "ur5", "--out", str(mine), "--force"]) == 2
    assert "not written by manip-id" in capsys.readouterr().err
    assert (mine / "notes.txt").read_text() == "keep"
