"""Fourier excitation trajectories: derivatives, limits, random and designed excitation."""

from __future__ import annotations

import math

import numpy as np
import pytest
from conftest import get_robot

from manip_id import InfeasibleTrajectoryError, InputError, regressor
from manip_id.trajectories import (
    DesignOptions,
    FourierTrajectory,
    RestFourier,
    base_columns,
    check_limits,
    design_excitation,
    excitation_condition_number,
    random_trajectory,
    trajectory_to_configuration,
)
from manip_id.trajectories.design import _Objective
from manip_id.trajectories.information import InformationModel


def _random_series(nv: int, L: int, wf: float, seed: int) -> FourierTrajectory:
    rng = np.random.default_rng(seed)
    return FourierTrajectory(
        rng.normal(size=nv), rng.normal(size=(nv, L)), rng.normal(size=(nv, L)), wf
    )


# ------------------------------------------------------------------- the series
@pytest.mark.parametrize(("nv", "L", "wf"), [(1, 1, 1.0), (3, 5, 2 * math.pi / 10), (7, 4, 3.0)])
def test_derivatives_match_central_differences(nv, L, wf):
    traj = _random_series(nv, L, wf, seed=nv + L)
    t = np.linspace(0.0, 2 * traj.period, 37)
    h = 1e-5
    q, dq, ddq = traj.sample(t)
    qp, dqp, _ = traj.sample(t + h)
    qm, dqm, _ = traj.sample(t - h)
    scale_v = np.abs(dq).max()
    scale_a = np.abs(ddq).max()
    np.testing.assert_allclose((qp - qm) / (2 * h), dq, atol=1e-7 * scale_v)
    np.testing.assert_allclose((dqp - dqm) / (2 * h), ddq, atol=1e-7 * scale_a)


def test_series_matches_its_formula_and_period():
    traj = _random_series(2, 3, 1.3, seed=4)
    t = 0.7
    q, dq, ddq = traj.sample(t)
    j = 1
    expect_q = traj.q0[j] + sum(
        traj.a[j, i] / ((i + 1) * 1.3) * math.sin((i + 1) * 1.3 * t)
        - traj.b[j, i] / ((i + 1) * 1.3) * math.cos((i + 1) * 1.3 * t)
        for i in range(3)
    )
    assert q.shape == (2,) and dq.shape == (2,) and ddq.shape == (2,)
    assert q[j] == pytest.approx(expect_q, rel=1e-14)
    for x, y in zip(traj.sample(t), traj.sample(t + 3 * traj.period), strict=True):
        np.testing.assert_allclose(x, y, atol=1e-12)


def test_mean_position_is_q0():
    traj = _random_series(3, 4, 0.5, seed=1)
    t = np.arange(400) * traj.period / 400
    np.testing.assert_allclose(traj.sample(t)[0].mean(axis=0), traj.q0, atol=1e-12)


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        (dict(q0=[0.0, 0.0], a=np.zeros((3, 2)), b=np.zeros((3, 2)), wf=1.0), "shape"),
        (dict(q0=[0.0], a=np.zeros((1, 2)), b=np.zeros((1, 3)), wf=1.0), "shape"),
        (dict(q0=[0.0], a=np.zeros((1, 2)), b=np.zeros((1, 2)), wf=0.0), "wf"),
        (dict(q0=[np.nan], a=np.zeros((1, 2)), b=np.zeros((1, 2)), wf=1.0), "q0"),
    ],
)
def test_bad_series(kwargs, match):
    with pytest.raises(InputError, match=match):
        FourierTrajectory(**kwargs)


# ------------------------------------------------------------ configurations
def test_continuous_joints_are_stored_as_cos_sin():
    robot = get_robot("double_pendulum_continuous")
    assert (robot.nq, robot.nv) == (4, 2)
    angles = np.array([[0.3, -2.0], [4.0, 1.0]])
    q = trajectory_to_configuration(robot, angles)
    np.testing.assert_allclose(q[:, [0, 2]], np.cos(angles))
    np.testing.assert_allclose(q[:, [1, 3]], np.sin(angles))
    q1 = trajectory_to_configuration(robot, angles[0])
    assert q1.shape == (4,)
    with pytest.raises(InputError, match="robot.nv=2"):
        trajectory_to_configuration(robot, np.zeros((5, 4)))


def test_revolute_configuration_is_the_angle():
    robot = get_robot("panda")
    angles = np.random.default_rng(0).normal(size=(3, 7))
    np.testing.assert_array_equal(trajectory_to_configuration(robot, angles), angles)


# --------------------------------------------------------------------- limits
def _constant(robot, q0, wf=1.0, L=1):
    return FourierTrajectory(q0, np.zeros((robot.nv, L)), np.zeros((robot.nv, L)), wf)


def test_position_violation_names_joint_limit_and_excess():
    robot = get_robot("panda")
    lo, hi = robot.lower, robot.upper
    q0 = 0.5 * (lo + hi)
    margin = 0.05
    q0[3] = hi[3] - margin * (hi[3] - lo[3]) + 0.1  # 0.1 rad past the margin
    with pytest.raises(InfeasibleTrajectoryError, match="panda_joint4") as info:
        check_limits(robot, _constant(robot, q0), margin=margin)
    err = info.value
    assert (err.joint, err.limit) == ("panda_joint4", "position")
    assert err.excess == pytest.approx(0.1, abs=1e-12)
    assert "position limit by 0.1 rad" in str(err)


def test_velocity_violation():
    robot = get_robot("panda")
    q0 = 0.5 * (robot.lower + robot.upper)
    a = np.zeros((7, 1))
    vmax = robot.velocity_limit
    a[5, 0] = vmax[5] + 0.2  # dq_5 = a cos(wf t): peak |a| at t = 0
    traj = FourierTrajectory(q0, a, np.zeros((7, 1)), wf=20.0)  # small position excursion
    with pytest.raises(InfeasibleTrajectoryError) as info:
        check_limits(robot, traj, margin=0.1)
    assert (info.value.joint, info.value.limit) == ("panda_joint6", "velocity")
    assert info.value.excess == pytest.approx(vmax[5] + 0.2 - 0.9 * vmax[5], rel=1e-12)
    assert "rad/s" in str(info.value)


def test_acceleration_violation_only_when_a_limit_is_given():
    robot = get_robot("panda")
    q0 = 0.5 * (robot.lower + robot.upper)
    b = np.zeros((7, 1))
    b[1, 0] = 1.0  # ddq_1 = b wf cos(wf t): peak 10 rad/s^2 at t = 0; |dq| <= 1 rad/s
    traj = FourierTrajectory(q0, np.zeros((7, 1)), b, wf=10.0)
    usage = check_limits(robot, traj)
    assert np.all(np.isnan(usage.acceleration))
    with pytest.raises(InfeasibleTrajectoryError) as info:
        check_limits(robot, traj, acceleration_limit=5.0)
    assert (info.value.joint, info.value.limit) == ("panda_joint2", "acceleration")
    assert info.value.excess == pytest.approx(10.0 - 0.95 * 5.0, rel=1e-12)


def test_feasible_usage_is_bounded_and_continuous_joints_have_no_position_limit():
    robot = get_robot("double_pendulum_continuous")
    traj = _constant(robot, [100.0, -50.0])  # far beyond any angle: no position limit
    usage = check_limits(robot, traj)
    assert np.all(np.isnan(usage.position))
    assert usage.worst == 0.0


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        (dict(margin=0.6), "margin"),
        (dict(duration=-1.0), "duration"),
        (dict(acceleration_limit=[1.0, 2.0]), "acceleration_limit"),
        (dict(acceleration_limit=-1.0), "positive"),
        (dict(n_points=1), "n_points"),
    ],
)
def test_check_limits_bad_input(kwargs, match):
    robot = get_robot("panda")
    traj = random_trajectory(robot, 2)
    with pytest.raises(InputError, match=match):
        check_limits(robot, traj, **kwargs)


def test_check_limits_wrong_joint_count():
    robot = get_robot("panda")
    with pytest.raises(InputError, match="robot.nv=7"):
        check_limits(robot, _random_series(3, 2, 1.0, 0))


# ---------------------------------------------------------- random trajectories
@pytest.mark.parametrize("name", ["panda", "ur5", "double_pendulum_continuous", "msd"])
@pytest.mark.parametrize("acc", [None, 3.0])
def test_random_trajectory_is_feasible_and_centered(name, acc):
    robot = get_robot(name)
    traj = random_trajectory(robot, 4, seed=7, acceleration_limit=acc)
    usage = check_limits(robot, traj, acceleration_limit=acc, n_points=5000)
    assert usage.worst <= 1.0
    if not np.all(np.isnan(usage.velocity)):  # the continuous pendulum sets no limit at all
        assert usage.worst > 0.9  # scaled up to the tightest limit (fill = 0.98)
    lo, hi = robot.sampling_bounds()
    if robot.nq == robot.nv:
        np.testing.assert_allclose(traj.q0, 0.5 * (lo + hi))
    again = random_trajectory(robot, 4, seed=7, acceleration_limit=acc)
    np.testing.assert_array_equal(traj.a, again.a)


def test_random_trajectory_bad_input():
    robot = get_robot("panda")
    with pytest.raises(InputError, match="harmonics"):
        random_trajectory(robot, 0)
    with pytest.raises(InputError, match="wf"):
        random_trajectory(robot, 3, wf=-1.0)


# ------------------------------------------------------------------- excitation
@pytest.mark.parametrize(
    ("friction", "expected"), [(None, 43), (("viscous", "coulomb", "offset"), 64)]
)
def test_panda_base_count_is_the_published_one(friction, expected):
    # Gaz et al. 2019: 43 rigid-body base parameters, 64 with viscous, Coulomb and offset friction
    robot = get_robot("panda", friction=friction)
    assert base_columns(robot).size == expected


def test_base_columns_span_the_regressor():
    robot = get_robot("ur5")
    base = base_columns(robot)
    q, dq, ddq = robot.random_states(100, seed=11)
    Y = regressor(robot, q, dq, ddq).reshape(-1, robot.n_parameters)
    rank = np.linalg.matrix_rank(Y)
    assert rank == base.size == np.linalg.matrix_rank(Y[:, base])


def test_condition_number_matches_numpy():
    robot = get_robot("double_pendulum")
    traj = random_trajectory(robot, 3, seed=2)
    base = base_columns(robot)
    t = np.arange(40) * traj.period / 40
    angles, dq, ddq = traj.sample(t)
    W = regressor(robot, trajectory_to_configuration(robot, angles), dq, ddq)[:, :, base]
    expected = np.linalg.cond(W.reshape(-1, base.size))
    assert excitation_condition_number(robot, traj, 40) == pytest.approx(expected, rel=1e-10)


@pytest.mark.parametrize("name", ["double_pendulum", "msd"])
def test_design_beats_random_coefficients(name):
    robot = get_robot(name, friction=("viscous", "coulomb"))
    opts = DesignOptions(harmonics=3, acceleration_limit=20.0, starts=3, maxiter=20, rate=100.0)
    res = design_excitation(robot, 6.0, options=opts)
    assert res.criterion < res.criterion_random
    check_limits(robot, res.trajectory, acceleration_limit=20.0)  # the limits' own check
    q, dq, ddq = res.trajectory.sample(np.array([0.0, 6.0]))
    np.testing.assert_allclose(dq, 0.0, atol=1e-12)
    np.testing.assert_allclose(ddq, 0.0, atol=1e-12)
    assert res.design_time > 0 and np.all(res.predicted_std > 0)


def test_design_bad_input():
    robot = get_robot("msd")
    with pytest.raises(InputError, match="harmonics"):
        design_excitation(robot, 5.0, options=DesignOptions(harmonics=1))
    with pytest.raises(InputError, match="criterion"):
        design_excitation(robot, 5.0, options=DesignOptions(criterion="a"))
    with pytest.raises(InputError, match="whole number of periods"):
        design_excitation(robot, 5.0, options=DesignOptions(base_frequency=0.3))
    with pytest.raises(InputError, match="duration"):
        design_excitation(robot, -1.0)


@pytest.mark.parametrize(
    ("name", "kw"),
    [
        ("panda", {}),
        (
            "double_pendulum_continuous",
            dict(armature=True, friction=("viscous", "offset"), spring=True),
        ),
        ("msd", dict(armature=True, friction=("viscous", "coulomb"))),
    ],
)
def test_design_gradient_matches_central_differences(name, kw):
    robot = get_robot(name, **kw)
    base = base_columns(robot)
    info = InformationModel(robot, base, np.ones(robot.nv))
    fam = RestFourier(np.zeros(robot.nv) + 0.1, 2, 1.0)
    t = np.arange(25) * (2 * math.pi / 25)
    obj = _Objective(info, fam, t, np.eye(base.size) * 1e-3, 1.0, "d")
    z = np.random.default_rng(3).standard_normal(fam.n_free)
    value, grad = obj.value_and_gradient(z)
    assert value == pytest.approx(obj.value(z), rel=1e-12)
    h = 1e-5
    numeric = np.array(
        [(obj.value(z + h * e) - obj.value(z - h * e)) / (2 * h) for e in np.eye(z.size)]
    )
    np.testing.assert_allclose(grad, numeric, atol=1e-5 * np.abs(numeric).max())


def test_coefficient_vector_round_trip():
    traj = _random_series(3, 4, 0.7, seed=8)
    x = traj.to_vector()
    assert x.shape == (3 * (1 + 2 * 4),)
    back = FourierTrajectory.from_vector(x, 3, 4, 0.7)
    for name in ("q0", "a", "b"):
        np.testing.assert_array_equal(getattr(back, name), getattr(traj, name))
    with pytest.raises(InputError, match="nv"):
        FourierTrajectory.from_vector(x[:-1], 3, 4, 0.7)
