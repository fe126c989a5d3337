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
