"""Robot loading: names, URDF paths, msd, options and bad input."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest
from conftest import get_robot

from manip_id import InputError, RobotError, available_robots, load_robot
from manip_id.robot.model import INERTIAL_NAMES, MANIPULATORS, JointSelection
from manip_id.robot.regressor import regressor
from manip_id.simulation import perturb_parameters

REQUIRED = ["panda", "ur3", "ur5", "ur10", "talos_arm", "z1", "xarm7", "kinova", "double_pendulum"]


@pytest.mark.parametrize("name", REQUIRED)
def test_required_manipulators_load(name):
    robot = get_robot(name)
    assert name in available_robots()
    assert robot.n_parameters == 10 * robot.n_bodies == len(robot.parameter_names)
    assert robot.nominal_parameters.shape == (robot.n_parameters,)
    assert len(robot.dof_names) == robot.nv
    # independent: the nominal parameters, through the regressor, give Pinocchio's rnea on the
    # URDF inertias (armature, not modelled here, removed from the reference model)
    reference = robot.model.copy()
    reference.armature = np.zeros(robot.nv)
    data = reference.createData()
    q, dq, ddq = robot.random_states(3, seed=4)
    Y = regressor(robot, q, dq, ddq)
    for k in range(3):
        tau = pin.rnea(reference, data, q[k], dq[k], ddq[k])
        np.testing.assert_allclose(
            Y[k] @ robot.nominal_parameters, tau, rtol=1e-9, atol=1e-9 * (1 + abs(tau).max())
        )


@pytest.mark.parametrize(("name", "armature"), [("talos_arm", False), ("talos_arm", True)])
def test_with_parameters_holds_exactly_the_dynamics_of_theta(name, armature):
    """talos_arm's URDF carries armature 0.1: a model without armature terms must drop it."""
    robot = get_robot(name, armature=armature)
    assert np.asarray(robot.model.armature).max() > 0  # the URDF value this test is about
    theta = perturb_parameters(robot, 0.2, seed=1)
    model = robot.with_parameters(theta)
    if armature:
        np.testing.assert_array_equal(model.armature, theta[robot.layout.joint_columns("Ia")])
    else:
        np.testing.assert_array_equal(model.armature, np.zeros(robot.nv))
    data = model.createData()
    q, dq, ddq = robot.random_states(3, seed=2)
    Y = regressor(robot, q, dq, ddq)
    for k in range(3):
        tau = pin.rnea(model, data, q[k], dq[k], ddq[k])
        np.testing.assert_allclose(Y[k] @ theta, tau, rtol=1e-9, atol=1e-9)


def test_every_listed_manipulator_is_fixed_base():
    for name in MANIPULATORS:
        robot = get_robot(name)
        assert robot.model.joints[1].shortname() != "JointModelFreeFlyer"


def test_panda_fingers_removed_by_default():
    robot = get_robot("panda")
    assert robot.nv == 7 and robot.nq == 7
    assert robot.joint_names == [f"panda_joint{i}" for i in range(1, 8)]
    full = load_robot(
        "panda", active_joints=[*robot.joint_names, "panda_finger_joint1", "panda_finger_joint2"]
    )
    assert full.nv == 9
    # locked fingers are merged into the hand: the arm's total mass is unchanged
    assert np.isclose(
        sum(i.mass for i in robot.model.inertias), sum(i.mass for i in full.model.inertias)
    )


def test_parameter_names_and_units():
    robot = get_robot("panda", armature=True, friction=("viscous", "coulomb", "offset"))
    names = robot.parameter_names
    assert names[:10] == [f"panda_joint1.{p}" for p in INERTIAL_NAMES]
    assert names[70:74] == [
        "panda_joint1.Ia",
        "panda_joint1.fv",
        "panda_joint1.fc",
        "panda_joint1.fo",
    ]
    assert names[-1] == "panda_joint7.fo"
    assert len(names) == len(set(names)) == 70 + 28
    units = dict(zip(names, robot.parameter_units, strict=True))
    assert units["panda_joint3.m"] == "kg"
    assert units["panda_joint3.mcy"] == "kg m"
    assert units["panda_joint3.Iyz"] == "kg m^2"
    assert units["panda_joint3.fv"] == "N m s/rad"
    # the panda URDF has joint damping 0.003: it is the nominal viscous coefficient
    assert robot.nominal_parameters[robot.parameter_index("panda_joint3.fv")] == pytest.approx(
        0.003
    )


def test_msd_nominal_values():
    robot = get_robot("msd")
    assert (robot.nq, robot.nv) == (1, 1)
    assert robot.terms.enabled == ("fv", "k")
    theta = dict(zip(robot.parameter_names, robot.nominal_parameters, strict=True))
    assert theta["cart.m"] == 2.0
    assert theta["cart.fv"] == 0.8
    assert theta["cart.k"] == 5.0
    assert robot.settings["input_gain"] == 1.5
    assert robot.parameter_units[robot.parameter_index("cart.k")] == "N/m"


def test_urdf_by_path_matches_name():
    from example_robot_data.robots_loader import ROBOTS

    path = ROBOTS["ur5"]().df_path
    by_path = load_robot(path, friction="viscous")
    by_name = get_robot("ur5")
    assert by_path.name == "ur5_robot"
    assert by_path.nv == 6
    np.testing.assert_allclose(by_path.nominal_parameters[:60], by_name.nominal_parameters)
    assert by_path.visual_model.ngeoms > 0


def test_active_joints_and_locked_configuration():
    robot = load_robot(
        "ur5",
        active_joints=JointSelection(
            ["shoulder_lift_joint", "elbow_joint"], locked_configuration={"wrist_1_joint": 0.3}
        ),
    )
    assert robot.nv == 2
    assert robot.joint_names == ["shoulder_lift_joint", "elbow_joint"]
    assert robot.n_parameters == 20


def test_unknown_name_lists_available():
    with pytest.raises(RobotError, match="available: .*panda.*ur5"):
        load_robot("no_such_robot")


def test_invalid_urdf_names_file(tmp_path):
    bad = tmp_path / "broken.urdf"
    bad.write_text("<robot name='x'><link name='a'></robot")
    with pytest.raises(RobotError, match="broken.urdf"):
        load_robot(bad)
    with pytest.raises(RobotError, match="no such file"):
        load_robot(tmp_path / "missing.urdf")


def test_floating_base_not_supported():
    with pytest.raises(RobotError, match="not supported"):
        load_robot("hector")


def test_unknown_joint_lists_valid():
    with pytest.raises(InputError, match="valid joints: .*elbow_joint"):
        load_robot("ur5", active_joints=["elbow"])


def test_unknown_friction_kind():
    with pytest.raises(InputError, match="viscous"):
        load_robot("ur5", friction="sticky")


def test_random_states_within_limits():
    robot = get_robot("panda")
    q, dq, ddq = robot.random_states(500, seed=3)
    assert np.all(q >= robot.lower) and np.all(q <= robot.upper)
    assert np.all(np.abs(dq) <= robot.velocity_limit)
    q2, _, _ = robot.random_states(500, seed=3)
    np.testing.assert_array_equal(q, q2)


def test_continuous_joint_states_are_unit_circle():
    robot = get_robot("kinova")
    q, _, _ = robot.random_states(50, seed=0)
    for i in range(1, robot.model.njoints):
        jm = robot.model.joints[i]
        if jm.nq == 2:
            np.testing.assert_allclose(np.hypot(q[:, jm.idx_q], q[:, jm.idx_q + 1]), 1.0)
