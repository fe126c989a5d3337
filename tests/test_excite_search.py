"""The excitation design's search and its ``--from`` torque limits, against independent
computations: the identified torques and their std from Pinocchio's regressor, their
Jacobian against central differences, the refinement's working set against every row of
the constraints, the report's camera against a pinhole projection of the world objects."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest
from conftest import get_robot

from manip_id.trajectories import DesignOptions, PriorInformation, RestFourier, design_excitation
from manip_id.trajectories.constraints import Bounds, linear_constraints
from manip_id.trajectories.excitation import base_columns
from manip_id.trajectories.fourier import trajectory_to_configuration
from manip_id.trajectories.identified_torque import IdentifiedTorques, UncertainTorqueConstraint
from manip_id.trajectories.working_set import feasible, near_rows

UR5_START = np.array([0.0, -1.57, 1.2, -1.2, -1.57, 0.0])


def _regressor_rows(robot, base, angles, dq, ddq):
    """Pinocchio's joint torque regressor (base columns), shape (n, nv, r)."""
    data = robot.model.createData()
    q = trajectory_to_configuration(robot, angles)
    return np.array([pin.computeJointTorqueRegressor(robot.model, data, a, v, w)[:, base]
                     for a, v, w in zip(q, dq, ddq, strict=True)])  # fmt: skip


def test_identified_torques_and_their_std_follow_the_regressor():
    robot = get_robot("ur5")
    base = base_columns(robot)
    rng = np.random.default_rng(0)
    theta = rng.standard_normal(base.size)
    A = rng.standard_normal((base.size, base.size))
    cov = 1e-3 * A @ A.T
    model = IdentifiedTorques(robot, base, theta, cov, 2.0)
    angles, dq, ddq = rng.uniform(-1, 1, (3, 5, robot.nv))
    Y = _regressor_rows(robot, base, angles, dq, ddq)
    tau, s = model.mean_std(angles, dq, ddq)
    np.testing.assert_allclose(tau, Y @ theta, rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(s, np.sqrt(np.einsum("kjr,rs,kjs->kj", Y, cov, Y)), rtol=1e-9)
    expected = Y @ theta + 2.0 * np.sign(Y @ theta) * s
    np.testing.assert_allclose(model.magnitude(angles, dq, ddq), expected, rtol=1e-9)


def test_uncertain_torque_jacobian_matches_central_differences():
    robot = get_robot("ur5", friction="viscous", armature=True)  # smooth joint terms
    base = base_columns(robot)
    rng = np.random.default_rng(1)
    theta = robot.nominal_parameters[base] + 0.1 * rng.standard_normal(base.size)
    A = rng.standard_normal((base.size, base.size))
    model = IdentifiedTorques(robot, base, theta, 1e-2 * A @ A.T, 3.0)
    fam = RestFourier(UR5_START, 3, 2 * np.pi / 5.0)
    effort = np.asarray(robot.effort_limit, float)
    con = UncertainTorqueConstraint(robot, fam, np.linspace(0.3, 4.7, 6), effort, model)
    z = 0.3 * rng.standard_normal(fam.n_free)
    J = con.jacobian(z)
    h = 1e-6
    for i in rng.choice(fam.n_free, 6, replace=False):
        e = np.zeros_like(z)
        e[i] = h
        fd = (con(z + e) - con(z - e)) / (2 * h)
        np.testing.assert_allclose(J[:, i], fd, rtol=1e-5, atol=1e-5 * np.abs(fd).max())


def test_near_rows_keep_the_local_minima_below_the_level_and_their_neighbours():
    slack = np.array([[5.0, 3.0, 1.0, 3.0, 5.0, 4.0, 0.2, 4.0], [9.0] * 8])
    keep = near_rows(slack, 10.0, level=0.5, width=1)
    assert keep[0].tolist() == [False, True, True, True, False, True, True, True]
    assert not keep[1].any()  # its least slack is 90 % of its room


def test_refined_design_beats_its_best_random_start_and_keeps_every_row():
    """The refinement must end feasible (every row, not only the working set's) and better
    than the best random start (before, SLSQP ended outside the rows at its iteration
    limit and the design fell back to the best random start)."""
    robot = get_robot("ur5")
    opts = DesignOptions(harmonics=3, start=UR5_START, starts=2, refine=1, maxiter=15,
                         rate=100.0, self_collision=False)  # fmt: skip
    design = design_excitation(robot, 4.0, options=opts)
    best_start = design_excitation(robot, 4.0, options=DesignOptions(**{**vars(opts), "refine": 0}))
    assert design.criterion < best_start.criterion - 1.0
    fam = RestFourier(UR5_START, 3, 2 * np.pi / 4.0)
    lo, hi = robot.model.lowerPositionLimit, robot.model.upperPositionLimit
    m = opts.margin
    bounds = Bounds(lo + m * (hi - lo), hi - m * (hi - lo), (1 - m) * robot.velocity_bounds(),
                    np.full(robot.nv, np.nan), np.full(robot.nv, np.nan))  # fmt: skip
    t = np.linspace(0, 4, 61)
    G, h = linear_constraints(fam, t, bounds)
    ab = np.hstack([design.trajectory.a, design.trajectory.b])  # back to the free coefficients
    z = (ab @ fam.null_space).ravel()
    assert feasible(z, G, h, [], tol=1e-6)


def test_from_design_keeps_identified_torque_plus_k_sigma_within_the_limits():
    """A prior whose covariance makes the torque uncertain: the designed motion keeps
    ``|tau| + k s`` (Pinocchio's regressor, 1 kHz) within the effort limits with the margin."""
    robot = get_robot("ur5")
    base = base_columns(robot)
    from manip_id.identifiability import analyze

    an = analyze(robot, seed=0)
    base = np.asarray(an.base.independent)
    theta = robot.nominal_parameters
    ref = theta[base] + an.base.K @ theta[an.base.dependent]
    cov = np.diag((0.3 * np.maximum(np.abs(ref), 1e-2)) ** 2)  # 30 % std
    prior = PriorInformation(np.linalg.inv(cov), base, list(an.base.base_names), ref,
                             0.01 * robot.effort_limit, covariance=cov)  # fmt: skip
    opts = DesignOptions(harmonics=3, start=UR5_START, starts=2, refine=1, maxiter=10,
                         rate=200.0, self_collision=False, sigma=3.0)  # fmt: skip
    design = design_excitation(robot, 4.0, options=opts, prior=prior)
    assert design.torque_model == "identified + 3 sigma"
    _, a, v, w = design.samples(1000.0)
    Y = _regressor_rows(robot, base, a, v, w)
    worst = np.abs(Y @ ref) + 3.0 * np.sqrt(np.einsum("kjr,rs,kjs->kj", Y, cov, Y))
    assert np.all(worst <= (1 - opts.margin) * robot.effort_limit * (1 + 1e-6))
    assert design.to_dict()["torque_model"] == "identified + 3 sigma"


def test_excite_scene_frames_a_far_world_object():
    """The camera sees every corner of a box far beside the robot (pinhole projection of
    the corners computed here, in the viewer's shifted world)."""
    pytest.importorskip("meshcat")
    from manip_id.trajectories.world import World
    from manip_id.viz.camera import image_coordinates
    from manip_id.viz.excite_report import _object_corners
    from manip_id.viz.meshcat_scene import RobotScene

    robot = get_robot("ur5")
    world = World.from_dict({"box": [{"size": [0.4, 0.4, 0.4], "position": [2.0, 1.2, 0.2]}]})
    scene = RobotScene(robot, q=robot.neutral())
    corners = np.array([[x, y, z] for x in (1.8, 2.2) for y in (1.0, 1.4) for z in (0.0, 0.4)])
    np.testing.assert_allclose(np.sort(_object_corners(world.objects[0]), 0), np.sort(corners, 0))
    before = image_coordinates(corners - scene.view_center, scene.camera.position)
    assert before is None or np.abs(np.concatenate(before)).max() > 1.0  # cut before
    scene.frame_points(corners)
    y, x = image_coordinates(corners - scene.view_center, scene.camera.position)
    assert np.abs(y).max() <= 1.0 and np.abs(x).max() <= 1.0
