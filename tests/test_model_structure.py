"""A result carries the model it was identified with, and the commands that read a saved
result take it from there (issue 35): no --friction repeated, a contradicting one
refused in one line.

Independent checks: the reloaded robot's parameter names and joint terms against a robot
loaded with the options by hand; the commands' exit status and message.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

from manip_id import load_robot
from manip_id.cli import main
from manip_id.identification import identify, load_result
from manip_id.robot.sidecar import model_structure
from manip_id.simulation import MeasurementNoise, simulate
from manip_id.trajectories import random_trajectory


@pytest.fixture(scope="module")
def logs(tmp_path_factory):
    """Two simulated ur5 logs and a result identified with viscous friction only."""
    d = tmp_path_factory.mktemp("structure")
    assert main(["simulate", "ur5", "--out", str(d / "sim"), "--files", "2", "--duration", "6",
                 "--friction", "viscous", "--quiet"]) == 0  # fmt: skip
    ref = d / "ref.json"
    argv = ["identify", "ur5", "--friction", "viscous", "--data", str(d / "sim" / "run_0.npz")]
    assert main([*argv, "--json", str(ref), "--quiet"]) == 0
    return d


def test_the_result_records_its_model_and_load_robot_rebuilds_it():
    robot = load_robot("panda", friction="viscous,offset", armature=True)
    sim = simulate(robot, random_trajectory(robot, seed=0), duration=4.0, rate=200.0,
                   noise=MeasurementNoise(tau=0.01), seed=1)  # fmt: skip
    d = sim.dataset
    doc = identify(robot, (d.q, d.dq, d.ddq, d.tau)).to_dict()
    structure = json.loads(json.dumps(doc["model_structure"]))  # as saved
    assert structure["joint_terms"] == list(robot.terms.enabled) == ["Ia", "fv", "fo"]
    assert structure["active_joints"] == list(robot.joint_names)
    assert set(structure["locked_joints"]) == {"panda_finger_joint1", "panda_finger_joint2"}
    again = load_robot("panda", identified=structure)
    assert again.parameter_names == robot.parameter_names
    assert again.terms.enabled == robot.terms.enabled
    np.testing.assert_allclose(again.locked_configuration, robot.locked_configuration)
    # explicit options still win over the structure
    assert load_robot("panda", identified=structure, friction="coulomb").terms.enabled != (
        robot.terms.enabled
    )
    assert model_structure(again) == structure


def test_a_saved_result_reloads_with_its_structure(logs):
    result = load_result(logs / "ref.json")
    assert result.context["model_structure"]["joint_terms"] == ["fv"]


@pytest.mark.parametrize("command", ["monitor", "drift", "validate"])
def test_commands_take_the_model_from_the_result(logs, command, capsys):
    ref, run_1 = str(logs / "ref.json"), str(logs / "sim" / "run_1.npz")
    argv = {
        "monitor": ["monitor", "ur5", "--model", ref, "--calibrate", run_1, "--data", run_1],
        "drift": ["drift", "ur5", "--reference", ref, "--data", run_1],
        "validate": ["validate", "ur5", "--model", ref, "--data", run_1, "--horizon", "0.05",
                     "--starts", "3"],
    }[command]  # fmt: skip
    assert main(argv) == 0  # no --friction: the result's (viscous) is used
    capsys.readouterr()
    assert main([*argv, "--friction", "viscous,coulomb"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "['fv']" in err[0] and "['fv', 'fc']" in err[0], err


def test_a_result_of_another_robot_is_refused(logs, capsys):
    ref, run_1 = str(logs / "ref.json"), str(logs / "sim" / "run_1.npz")
    assert main(["drift", "panda", "--reference", ref, "--data", run_1]) == 2
    assert "robot 'ur5', not of 'panda'" in capsys.readouterr().err


def test_payload_takes_the_joint_model_of_its_known_base(logs, tmp_path, capsys):
    """payload --known-base: the result's joint terms, no --friction repeated; a
    contradicting one refused in one line."""
    sim = tmp_path / "loaded"
    argv = ["simulate", "ur5", "--out", str(sim), "--files", "1", "--duration", "6"]
    assert main([*argv, "--friction", "viscous", "--payload", "1.5", "--seed", "5", "--quiet"]) == 0
    loaded = sorted(p for p in sim.glob("*.npz") if "payload" in p.name or "1.5" in p.name)
    assert loaded, sorted(p.name for p in sim.iterdir())
    out = tmp_path / "payload.json"
    argv = ["payload", "ur5", "--known-base", str(logs / "ref.json"), "--loaded", str(loaded[0]),
            "--frame", "wrist_3_link", "--quiet"]  # fmt: skip
    assert main([*argv, "--json", str(out)]) == 0
    assert json.loads(out.read_text())["payload"]["mass"] == pytest.approx(1.5, rel=0.05)
    capsys.readouterr()
    assert main([*argv, "--friction", "viscous,coulomb"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "['fv']" in err[0], err


def test_simulate_an_identified_model(logs, tmp_path):
    """simulate --model: the logs' torques are the result's model, Y(q, dq, ddq) theta with
    the identified base parameters (the regressor, independent of the simulation)."""
    from manip_id.robot.regressor import regressor

    plain = logs / "ref.json"  # plain least squares: fv < 0 on a joint, not simulable
    argv = ["simulate", "ur5", "--files", "1", "--duration", "2", "--noise", "0", "--quiet"]
    assert main([*argv, "--model", str(plain), "--out", str(tmp_path / "no")]) == 2
    assert not (tmp_path / "no").exists()
    ref = tmp_path / "consistent.json"
    run_0 = str(logs / "sim" / "run_0.npz")
    fit = ["identify", "ur5", "--friction", "viscous", "--data", run_0, "--consistent"]
    assert main([*fit, "--json", str(ref), "--quiet"]) == 0
    out = tmp_path / "again"
    assert main([*argv, "--model", str(ref), "--out", str(out)]) == 0
    truth = json.loads((out / "truth.json").read_text())
    assert truth["joint_terms"] == ["fv"] and truth["differs_from_urdf"]["model"] == str(ref)
    result = load_result(ref)
    robot = load_robot("ur5", friction="viscous")
    with np.load(next(out.glob("*.npz"))) as z:
        Y = regressor(robot, z["q"], z["dq"], z["ddq"])[:, :, result.base.independent]
        # base columns: Y_b beta (beta the identified base parameters)
        tau = np.einsum("nvk,k->nv", Y, result.estimate)
        np.testing.assert_allclose(z["tau"], tau, rtol=1e-7, atol=1e-7)


def test_export_writes_a_saved_consistent_result_as_identify_would(logs, tmp_path, capsys):
    """manip-id export: the URDF of a saved --consistent result equals the one identify
    wrote in the same run (provenance aside); Pinocchio reads the result's masses from it;
    a plain result, an existing file and a contradicting --friction are refused."""
    import pinocchio as pin

    run_0 = str(logs / "sim" / "run_0.npz")
    ref, direct = tmp_path / "ref.json", tmp_path / "direct.urdf"
    fit = ["identify", "ur5", "--friction", "viscous", "--data", run_0, "--consistent"]
    assert main([*fit, "--json", str(ref), "--export-urdf", str(direct), "--quiet"]) == 0
    again = tmp_path / "again.urdf"
    base = ["export", "ur5", "--model", str(ref)]
    assert main([*base, "--export-urdf", str(again), "--export-mjcf", str(tmp_path / "a.xml")]) == 0

    def body(path):
        return [ln for ln in path.read_text().splitlines() if "provenance" not in ln]

    assert body(again) == body(direct)
    masses = {
        r["name"]: r["value"]
        for r in json.loads(ref.read_text())["standard_parameters"]
        if r["name"].endswith(".m")
    }
    model = pin.buildModelFromUrdf(str(again))
    for j in range(1, model.njoints):
        name = model.names[j]
        assert model.inertias[j].mass == pytest.approx(masses[f"{name}.m"], rel=1e-6), name
    capsys.readouterr()
    for argv, says in (
        ([*base, "--export-urdf", str(again)], "exists"),
        ([*base, "--friction", "viscous,coulomb", "--export-urdf", str(tmp_path / "b.urdf")],
         "['fv']"),
        (["export", "ur5", "--model", str(logs / "ref.json"), "--export-urdf",
          str(tmp_path / "c.urdf")], "no physically consistent"),
        (base, "--export-urdf"),
    ):  # fmt: skip
        assert main(argv) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and says in err[0], err
    assert not (tmp_path / "b.urdf").exists() and not (tmp_path / "c.urdf").exists()
