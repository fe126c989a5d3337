"""The parameter layout against Pinocchio: body blocks, joint-term columns, DoF layout, limits."""

from __future__ import annotations

import math

import numpy as np
import pinocchio as pin
import pytest

from manip_id.errors import InputError
from manip_id.identifiability import analyze
from manip_id.robot.model import Robot, load_robot
from manip_id.robot.parameters import (
    INERTIAL_NAMES,
    JOINT_TERM_NAMES,
    UNSET_LIMIT,
    DofLayout,
    ParameterLayout,
    bounded_range,
    bounded_rate,
)
from manip_id.robot.regressor import regressor


@pytest.fixture(scope="module")
def panda_all():
    return load_robot("panda", armature=True, friction="viscous,coulomb,offset")


def _mixed_model() -> pin.Model:
    """Revolute Z, continuous (cos, sin) about Y, prismatic X: nq = 4, nv = 3."""
    model = pin.Model()
    parent = 0
    for k, joint in enumerate((pin.JointModelRZ(), pin.JointModelRUBY(), pin.JointModelPX())):
        placement = pin.SE3(np.eye(3), np.array([0.0, 0.0, 0.3]))
        parent = model.addJoint(parent, joint, placement, f"j{k}")
        inertia = pin.Inertia(1.0 + k, np.array([0.1, 0.02, -0.05]), np.diag([0.1, 0.2, 0.3]))
        model.appendBodyToJoint(parent, inertia, pin.SE3.Identity())
    return model


def test_body_blocks_are_pinocchios_dynamic_parameters(panda_all):
    robot = panda_all
    theta = robot.nominal_parameters
    layout = robot.layout
    for i in range(1, robot.model.njoints):
        name = robot.model.names[i]
        expected = robot.model.inertias[i].toDynamicParameters()
        np.testing.assert_array_equal(theta[layout.body_slice(name)], expected)
        np.testing.assert_array_equal(layout.rigid_blocks(theta)[i - 1], expected)
    assert layout.n_parameters == 10 * 7 + 4 * 7  # 7 bodies, 4 terms for each of 7 DoFs


def test_armature_columns_against_rnea(panda_all):
    """Y[:, joint_columns("Ia")] a == rnea with model.armature = a minus rnea without."""
    robot = panda_all
    q, dq, ddq = robot.random_states(5, seed=3)
    a = np.linspace(0.1, 0.7, robot.nv)  # [kg m^2]
    Y = regressor(robot, q, dq, ddq)
    with_a = robot.model.copy()
    with_a.armature = a
    without = robot.model.copy()
    without.armature = np.zeros(robot.nv)
    d1, d0 = with_a.createData(), without.createData()
    cols = robot.layout.joint_columns("Ia")
    for k in range(5):
        expected = pin.rnea(with_a, d1, q[k], dq[k], ddq[k]) - pin.rnea(
            without, d0, q[k], dq[k], ddq[k]
        )
        np.testing.assert_allclose(Y[k][:, cols] @ a, expected, rtol=1e-12, atol=1e-12)


@pytest.mark.parametrize("term", ["fv", "fc", "fo"])
def test_friction_columns_are_the_textbook_entries(panda_all, term):
    robot = panda_all
    q, dq, ddq = robot.random_states(4, seed=1)
    Y = regressor(robot, q, dq, ddq)
    expected = {"fv": dq, "fc": np.sign(dq), "fo": np.ones_like(dq)}[term]
    for j in range(robot.nv):
        col = robot.layout.joint_column(j, term)
        column = Y[:, :, col]
        np.testing.assert_array_equal(column[:, j], expected[:, j])
        others = np.delete(column, j, axis=1)
        assert not others.any()  # only row j carries joint j's term
        assert robot.parameter_names[col] == f"panda_joint{j + 1}.{term}"


def test_column_formula_and_owner(panda_all):
    layout = panda_all.layout
    nt = len(layout.terms)
    for j in range(layout.nv):
        for pos, t in enumerate(layout.terms):
            col = layout.joint_column(j, t)
            assert col == 10 * layout.n_bodies + j * nt + pos
            owner = layout.owner(col)
            assert (owner.kind, owner.index, owner.parameter) == ("joint", j, t)
            assert layout.names[col] == f"{owner.joint}.{t}"
    for col in range(layout.n_rigid):
        owner = layout.owner(col)
        assert owner.kind == "body"
        assert layout.names[col] == f"{owner.joint}.{INERTIAL_NAMES[col % 10]}"


def test_disabled_or_unknown_term_errors():
    robot = load_robot("ur5", friction="viscous")
    with pytest.raises(InputError, match="not modelled"):
        robot.layout.joint_column(0, "Ia")
    with pytest.raises(InputError, match="unknown joint term"):
        robot.layout.joint_column(0, "zz")
    with pytest.raises(InputError, match="out of range"):
        robot.layout.joint_column(robot.nv, "fv")
    with pytest.raises(InputError, match="n_parameters"):
        robot.layout.joint_block(np.zeros(3))


def test_joint_block_is_a_view():
    robot = load_robot("ur5", friction="viscous,coulomb")
    theta = np.zeros(robot.n_parameters)
    robot.layout.joint_block(theta)[2, 1] = 4.0
    assert theta[robot.layout.joint_column(2, "fc")] == 4.0


def test_dof_layout_of_a_mixed_model():
    model = _mixed_model()
    dofs = DofLayout.from_model(model)
    assert dofs.names == ("j0", "j1", "j2")
    np.testing.assert_array_equal(dofs.q_index, [0, 1, 3])  # j1 takes q[1:3] as (cos, sin)
    np.testing.assert_array_equal(dofs.continuous, [False, True, False])
    np.testing.assert_array_equal(dofs.prismatic, [False, False, True])
    angles = np.array([[0.3, 2.5, -0.2], [-1.0, -3.0, 0.4]])
    q = dofs.configuration(angles, model.nq)
    np.testing.assert_allclose(q[0], [0.3, math.cos(2.5), math.sin(2.5), -0.2])
    np.testing.assert_allclose(dofs.angles(q), angles, atol=1e-15)
    # the same configuration through Pinocchio's own integrate from neutral
    q_pin = pin.integrate(model, pin.neutral(model), angles[0])
    np.testing.assert_allclose(q_pin, q[0], atol=1e-15)


def test_units_follow_the_joint_kind():
    model = _mixed_model()
    layout = ParameterLayout(
        ["j0", "j1", "j2"], DofLayout.from_model(model), ("Ia", "fv", "fc", "k")
    )
    units = dict(zip(layout.names, layout.units, strict=True))
    assert units["j0.fv"] == "N m s/rad" and units["j2.fv"] == "N s/m"
    assert units["j1.Ia"] == "kg m^2" and units["j2.Ia"] == "kg"
    assert units["j2.k"] == "N/m" and units["j0.fc"] == "N m"
    assert units["j0.m"] == "kg" and units["j0.mcy"] == "kg m" and units["j0.Iyz"] == "kg m^2"
    with pytest.raises(InputError, match="column order"):
        ParameterLayout(["j0", "j1", "j2"], DofLayout.from_model(model), ("fv", "Ia"))


def test_spring_column_is_the_angle_of_a_continuous_joint():
    model = _mixed_model()
    robot = Robot("mixed", model, load_robot("msd").terms)  # viscous + spring
    assert robot.layout.terms == ("fv", "k")
    angles = np.array([0.2, -2.8, 0.05])
    q = robot.dofs.configuration(angles[None], robot.nq)[0]
    Y = regressor(robot, q, np.zeros(3), np.zeros(3))
    for j in range(3):
        assert Y[j, robot.layout.joint_column(j, "k")] == pytest.approx(angles[j], abs=1e-15)


def test_unset_limits():
    lo = np.array([-1.0, -np.inf, -1e10, 1.0, -400.0, np.nan])
    hi = np.array([1.0, 1.0, 1e10, 1.0, 400.0, 1.0])
    np.testing.assert_array_equal(bounded_range(lo, hi), [True, False, False, False, True, False])
    v = np.array([2.0, 0.0, -1.0, np.inf, 1e4, UNSET_LIMIT])
    np.testing.assert_array_equal(bounded_rate(v), [True, False, False, False, False, True])


def test_standard_base_maps_preserve_torques():
    robot = load_robot("ur5", friction="viscous")
    base = analyze(robot).base
    q, dq, ddq = robot.random_states(20, seed=5)
    Y = regressor(robot, q, dq, ddq).reshape(-1, robot.n_parameters)
    rng = np.random.default_rng(0)
    theta = rng.normal(size=robot.n_parameters)
    beta = base.to_base(theta)
    # the base regressor reproduces every torque of theta
    np.testing.assert_allclose(Y[:, base.independent] @ beta, Y @ theta, rtol=1e-9, atol=1e-9)
    back = base.from_base(beta)
    np.testing.assert_allclose(Y @ back, Y @ theta, rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(base.to_base(back), beta, rtol=1e-12, atol=1e-12)
    assert not back[base.dependent].any()
    with pytest.raises(InputError, match="theta_base"):
        base.from_base(beta[:-1])


def test_term_table_names_match_the_robot_flags():
    from manip_id.robot.model import JointTerms
    from manip_id.robot.parameters import JOINT_TERMS

    assert tuple(t.name for t in JOINT_TERMS) == JOINT_TERM_NAMES
    for t in JOINT_TERMS[:5]:  # the one-column terms: their flag alone
        assert JointTerms(**{t.flag: True}).enabled == (t.name,)
    for t in JOINT_TERMS[5:]:  # the friction laws of manip_id.robot.friction: their kind
        flags = {"harmonics": 4} if t.flag == "position" else {t.flag: True}
        assert t.name in JointTerms(**flags).enabled


def test_consistency_checks_are_reexported():
    consistency = pytest.importorskip("manip_id.physics.consistency")
    import manip_id.robot.parameters as parameters

    assert parameters.check_consistency is consistency.check_consistency


def test_pseudo_inertias_against_the_textbook_formula(panda_all):
    pytest.importorskip("manip_id.physics.consistency")
    robot = panda_all
    J = robot.layout.pseudo_inertias(robot.nominal_parameters)
    assert J.shape == (robot.n_bodies, 4, 4)
    for i in range(1, robot.model.njoints):
        inertia = robot.model.inertias[i]
        m, c = inertia.mass, np.asarray(inertia.lever)
        # inertia about the joint frame origin: parallel-axis theorem from the CoM inertia
        I_o = np.asarray(inertia.inertia) + m * (c @ c * np.eye(3) - np.outer(c, c))
        expected = np.zeros((4, 4))
        expected[:3, :3] = 0.5 * np.trace(I_o) * np.eye(3) - I_o
        expected[:3, 3] = expected[3, :3] = m * c
        expected[3, 3] = m
        np.testing.assert_allclose(J[i - 1], expected, rtol=1e-12, atol=1e-12)
        assert np.linalg.eigvalsh(expected).min() > 0  # the URDF bodies are physical
