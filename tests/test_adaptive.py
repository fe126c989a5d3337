"""Slotine-Li adaptive control and its closed-loop simulation.

Independent references: the control torque against pinocchio.crba,
computeCoriolisMatrix and computeGeneralizedGravity; the Lyapunov function
(crba and Gamma^-1) against its predicted decrease; the composite filter
identity against the plant integrated with pinocchio.aba; payloads against the
textbook point-mass inertia.
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest
from conftest import get_robot

from manip_id.control.adaptive import (
    AdaptiveGains,
    CompositeLaw,
    SlotineLiController,
    default_gains,
    lyapunov_function,
)
from manip_id.control.closed_loop import (
    ClosedLoopOptions,
    compare_fixed,
    default_reference,
    simulate,
    with_payload,
)
from manip_id.errors import InfeasibleTrajectoryError, InputError
from manip_id.simulation import perturb_parameters
from manip_id.trajectories import FourierTrajectory

ROBOTS = ["panda", "ur5"]


def _sym(M):
    return np.triu(M) + np.triu(M, 1).T


def _viscous_robot(name):
    """Robot with armature and viscous friction (exact cancellation: V must not increase)."""
    robot = get_robot(name, armature=True, friction="viscous")
    theta0 = robot.nominal_parameters.copy()
    theta0[robot.n_rigid :] = 0.05
    theta = perturb_parameters(robot, 0.3, seed=2, theta=theta0)
    return robot, theta0, theta


# ------------------------------------------------------------------ control law
@pytest.mark.parametrize("name", ROBOTS)
def test_torque_matches_pinocchio_dynamics(name):
    robot, _, theta = _viscous_robot(name)
    gains = default_gains(robot, theta)
    ctrl = SlotineLiController(robot, theta, gains)
    q, dq, ddq = robot.random_states(2, seed=3)
    tau = ctrl.torque(q[0], dq[0], q[1], dq[1], ddq[1]).copy()
    model = robot.with_parameters(theta)
    data = model.createData()
    lam = np.diag(np.broadcast_to(gains.lam, (robot.nv,)))
    dq_r = dq[1] - lam @ (q[0] - q[1])
    ddq_r = ddq[1] - lam @ (dq[0] - dq[1])
    s = dq[0] - dq_r
    M = _sym(pin.crba(model, data, q[0]))  # includes the armature
    C = pin.computeCoriolisMatrix(model, data, q[0], dq[0])
    g = pin.computeGeneralizedGravity(model, data, q[0])
    fv = theta[robot.n_rigid + 1 :: 2]
    expected = M @ ddq_r + C @ dq_r + g + fv * dq_r - gains.kd @ s
    np.testing.assert_allclose(tau, expected, rtol=1e-10, atol=1e-9)
    np.testing.assert_allclose(ctrl.s, s, atol=1e-12)


def test_adaptation_step_is_minus_gamma_y_transpose_s():
    robot, theta0, _ = _viscous_robot("panda")
    rng = np.random.default_rng(0)
    A = rng.normal(size=(robot.n_parameters, robot.n_parameters))
    gamma = A @ A.T / robot.n_parameters + np.eye(robot.n_parameters)  # full SPD matrix
    ctrl = SlotineLiController(robot, theta0, AdaptiveGains(gamma=gamma))
    q, dq, ddq = robot.random_states(2, seed=4)
    ctrl.torque(q[0], dq[0], q[1], dq[1], ddq[1])
    Y, s = ctrl.Y.copy(), ctrl.s.copy()
    ctrl.adapt(1e-3)
    np.testing.assert_allclose(ctrl.theta_hat, theta0 - 1e-3 * gamma @ (Y.T @ s), rtol=1e-10)


# --------------------------------------------------------------------- Lyapunov
@pytest.mark.parametrize("name", ROBOTS)
@pytest.mark.parametrize("composite", [0.0, 50.0])
def test_lyapunov_function_does_not_increase(name, composite):
    robot, theta0, theta = _viscous_robot(name)
    gains = default_gains(robot, theta0, composite=composite)
    run = simulate(
        robot,
        theta,
        theta0,
        gains=gains,
        options=ClosedLoopOptions(duration=0.4, rate=5000, integrator="rk4"),
    )
    V = lyapunov_function(robot, theta, run.gamma, run.q, run.s, run.theta_hat)
    assert np.diff(V).max() <= 1e-9 * V[0]  # every step
    drop = V[0] - V[-1]
    assert drop > 0
    # dV/dt = -s^T (K_D + F_v) s - kappa |eps|^2: the decrease matches its integral
    assert drop == pytest.approx(run.dissipation, rel=5e-3)


@pytest.mark.parametrize("name", ROBOTS)
def test_composite_filter_identity_holds_on_the_plant(name):
    """With theta_hat = theta, eps = Y_f theta - W[tau] vanishes (no acceleration used)."""
    robot, _, theta = _viscous_robot(name)
    gains = default_gains(robot, theta, composite=50.0)
    run = simulate(
        robot,
        theta,
        theta,
        gains=gains,
        adapt=False,
        options=ClosedLoopOptions(duration=1.0, rate=1000, integrator="rk4"),
    )
    scale = np.linalg.norm(run.tau, axis=1).mean()
    assert run.filtered_prediction_error.max() < 1e-5 * scale


# ------------------------------------------------------------------- tracking
@pytest.mark.parametrize("name", ROBOTS)
def test_tracking_converges_and_beats_fixed_parameters(name):
    robot = get_robot(name)
    theta0 = robot.nominal_parameters
    theta = with_payload(robot, perturb_parameters(robot, 0.1, seed=1), 1.0)
    cmp = compare_fixed(
        robot, theta, theta0, options=ClosedLoopOptions(duration=4.0, rate=1000, record_every=50)
    )
    a, f = cmp.adaptive, cmp.fixed
    assert a.final_tracking_error < 0.1 * a.initial_tracking_error
    assert a.rms_tracking_error < f.rms_tracking_error
    assert a.rms_tracking_error_tail < 0.8 * f.rms_tracking_error_tail
    assert np.allclose(f.theta_hat, theta0)  # the baseline holds its estimate
    np.testing.assert_allclose(a.q_d, f.q_d)  # same reference


def test_continuous_joints_track_with_exact_parameters():
    robot = get_robot("double_pendulum_continuous")
    assert robot.nq != robot.nv
    theta = perturb_parameters(robot, 0.3, seed=0)
    run = simulate(
        robot, theta, theta, adapt=False, options=ClosedLoopOptions(duration=2.0, rate=1000)
    )
    assert run.final_tracking_error < 0.01 * run.initial_tracking_error
    # cos^2 + sin^2 = 1 is kept by pinocchio.integrate
    np.testing.assert_allclose(run.q[:, 0] ** 2 + run.q[:, 1] ** 2, 1.0, atol=1e-12)


def test_talos_arm_with_exact_parameters_tracks_to_integration_accuracy():
    """The plant is ``robot.with_parameters(theta)``: its URDF armature (0.1) must not be in it.

    With the controller's model equal to the plant's, the only tracking error left is the
    discretization (torque held over a control period): it shrinks in proportion to the
    period. A plant with the URDF armature kept gave a tail error of 4e-4 rad at any rate.
    """
    robot = get_robot("talos_arm")
    theta = robot.nominal_parameters
    tails = [
        simulate(
            robot,
            theta,
            theta,
            adapt=False,
            options=ClosedLoopOptions(duration=2.0, rate=rate, integrator="rk4"),
        ).rms_tracking_error_tail
        for rate in (1000, 4000)
    ]
    assert tails[0] < 1e-4  # [rad]
    assert tails[1] < 0.4 * tails[0]  # error ~ control period: integration, not model error


@pytest.mark.parametrize("name", ROBOTS)
def test_prediction_converges_and_composite_is_faster(name):
    robot = get_robot(name)
    theta0 = robot.nominal_parameters
    theta = with_payload(robot, perturb_parameters(robot, 0.1, seed=1), 1.0)
    ref = default_reference(robot)
    runs = {}
    for kappa in (0.0, 50.0):
        gains = default_gains(robot, theta0, composite=kappa)
        runs[kappa] = simulate(
            robot,
            theta,
            theta0,
            reference=ref,
            gains=gains,
            options=ClosedLoopOptions(duration=5.0, rate=1000, record_every=10),
        )
    plain, comp = runs[0.0], runs[50.0]
    assert plain.initial_prediction_error == comp.initial_prediction_error
    assert plain.final_prediction_error < 0.5 * plain.initial_prediction_error
    assert comp.final_prediction_error < 0.2 * comp.initial_prediction_error
    half = 0.5 * plain.initial_prediction_error
    assert comp.time_to_prediction_error(half) < plain.time_to_prediction_error(half)


# ---------------------------------------------------------- one degree of freedom
def _msd():
    """The 1-DoF mass-spring-damper (viscous and spring terms): Pinocchio returns its
    1 x 10 joint-torque regressor as a vector (10,), which the composite law must take."""
    robot = get_robot("msd")
    assert robot.nv == 1
    theta0 = robot.nominal_parameters.copy()
    return robot, theta0, perturb_parameters(robot, 0.3, seed=2, theta=theta0)


@pytest.mark.parametrize("composite", [5.0, 50.0])
def test_one_dof_composite_lyapunov_function_does_not_increase(composite):
    robot, theta0, theta = _msd()
    gains = default_gains(robot, theta0, composite=composite)
    run = simulate(
        robot,
        theta,
        theta0,
        gains=gains,
        options=ClosedLoopOptions(duration=0.4, rate=10000, integrator="rk4"),
    )
    V = lyapunov_function(robot, theta, run.gamma, run.q, run.s, run.theta_hat)
    assert np.diff(V).max() <= 1e-9 * V[0]  # every step
    drop = V[0] - V[-1]
    assert drop > 0.5 * V[0]
    assert drop == pytest.approx(run.dissipation, rel=5e-3)  # measured 2e-3 (step size)


def test_one_dof_composite_filter_identity_holds_on_the_plant():
    robot, _, theta = _msd()
    gains = default_gains(robot, theta, composite=50.0)
    run = simulate(
        robot,
        theta,
        theta,
        gains=gains,
        adapt=False,
        options=ClosedLoopOptions(duration=1.0, rate=1000, integrator="rk4"),
    )
    scale = np.linalg.norm(run.tau, axis=1).mean()
    assert run.filtered_prediction_error.max() < 1e-5 * scale  # measured 4.6e-6


@pytest.mark.parametrize(("gain", "bound"), [("constant", 0.5), ("rls", 0.05)])
def test_one_dof_composite_tracks_and_predicts(gain, bound):
    robot, theta0, theta = _msd()
    gains = default_gains(robot, theta0, composite=CompositeLaw(50.0, gain=gain))
    run = simulate(
        robot,
        theta,
        theta0,
        gains=gains,
        options=ClosedLoopOptions(duration=5.0, rate=1000, record_every=10),
    )
    assert np.isfinite(run.theta_hat).all()
    assert run.final_tracking_error < 0.01 * run.initial_tracking_error  # measured 4e-4
    # measured 0.41 (constant) and 0.011 (rls) of the initial prediction error
    assert run.final_prediction_error < bound * run.initial_prediction_error


# ---------------------------------------------------------------- robustness
def test_projection_keeps_the_estimate_within_bounds():
    robot = get_robot("panda")
    theta0 = robot.nominal_parameters
    theta = perturb_parameters(robot, 0.3, seed=1)
    lower = theta0 - 0.02 * np.abs(theta0)
    upper = theta0 + 0.02 * np.abs(theta0)
    gains = default_gains(robot, theta0)
    gains = AdaptiveGains(lam=gains.lam, kd=gains.kd, gamma=gains.gamma, lower=lower, upper=upper)
    run = simulate(
        robot, theta, theta0, gains=gains, options=ClosedLoopOptions(duration=1.0, record_every=10)
    )
    assert np.all(run.theta_hat >= lower - 1e-15) and np.all(run.theta_hat <= upper + 1e-15)
    assert np.any(np.isclose(run.theta_hat[-1], upper) | np.isclose(run.theta_hat[-1], lower))


def test_dead_zone_stops_adaptation_inside_it():
    robot = get_robot("panda")
    theta0 = robot.nominal_parameters
    theta = perturb_parameters(robot, 0.3, seed=1)
    g = default_gains(robot, theta0)
    wide = AdaptiveGains(lam=g.lam, kd=g.kd, gamma=g.gamma, dead_zone=10.0)
    run = simulate(
        robot, theta, theta0, gains=wide, options=ClosedLoopOptions(duration=0.5, record_every=10)
    )
    assert np.abs(run.s).max() < 10.0
    np.testing.assert_array_equal(run.theta_hat[-1], theta0)


def test_noisy_measurements_still_track():
    robot = get_robot("ur5")
    theta0 = robot.nominal_parameters
    theta = perturb_parameters(robot, 0.3, seed=1)
    g = default_gains(robot, theta0, dead_zone=0.01)
    run = simulate(
        robot,
        theta,
        theta0,
        gains=g,
        options=ClosedLoopOptions(duration=2.0, noise_q=1e-4, noise_dq=1e-3, record_every=20),
    )
    assert np.isfinite(run.theta_hat).all()
    assert run.final_tracking_error < 0.2 * run.initial_tracking_error


# ------------------------------------------------------------------- parameters
def test_payload_adds_a_point_mass():
    robot = get_robot("panda")
    theta0 = robot.nominal_parameters
    r = np.array([0.01, -0.02, 0.1])
    theta = with_payload(robot, theta0, 2.0, lever=r)
    d = (theta - theta0)[10 * (robot.n_bodies - 1) : 10 * robot.n_bodies]
    inertia = 2.0 * (r @ r * np.eye(3) - np.outer(r, r))  # about the joint frame origin
    expected = [
        2.0,
        *(2.0 * r),
        inertia[0, 0],
        inertia[0, 1],
        inertia[1, 1],
        inertia[0, 2],
        inertia[1, 2],
        inertia[2, 2],
    ]
    np.testing.assert_allclose(d, expected, atol=1e-14)
    assert np.count_nonzero(theta - theta0) == np.count_nonzero(expected)


# ------------------------------------------------------------------ bad input
@pytest.mark.parametrize(
    "gains, match",
    [
        (AdaptiveGains(lam=0.0), "lam"),
        (AdaptiveGains(lam=-1.0), "lam"),
        (AdaptiveGains(kd=-2.0), "kd"),
        (AdaptiveGains(kd=np.diag([1.0, 1, 1, 1, 1, 1, -1])), "kd.*positive definite"),
        (AdaptiveGains(gamma=0.0), "gamma"),
        (AdaptiveGains(composite=-1.0), "composite"),
        (AdaptiveGains(dead_zone=-0.1), "dead_zone"),
    ],
)
def test_bad_gains_raise(gains, match):
    robot = get_robot("panda")
    with pytest.raises(InputError, match=match):
        SlotineLiController(robot, robot.nominal_parameters, gains)


def test_gamma_must_be_spd():
    robot = get_robot("panda")
    p = robot.n_parameters
    asym = np.eye(p)
    asym[0, 1] = 0.5
    with pytest.raises(InputError, match="not symmetric"):
        SlotineLiController(robot, robot.nominal_parameters, AdaptiveGains(gamma=asym))
    indefinite = np.eye(p)
    indefinite[3, 3] = -1e-3
    with pytest.raises(InputError, match="smallest eigenvalue"):
        SlotineLiController(robot, robot.nominal_parameters, AdaptiveGains(gamma=indefinite))
    with pytest.raises(InputError, match=r"shape"):
        SlotineLiController(robot, robot.nominal_parameters, AdaptiveGains(gamma=np.eye(3)))


def test_reference_outside_limits_raises():
    robot = get_robot("panda")
    nv = robot.nv
    q0 = 0.5 * (robot.lower + robot.upper)
    a = np.zeros((nv, 1))
    a[3, 0] = 3.0  # joint 4 swings by 3 rad around the middle of a 3 rad range
    ref = FourierTrajectory(q0=q0, a=a, b=np.zeros((nv, 1)), wf=1.0)
    theta = robot.nominal_parameters
    with pytest.raises(InfeasibleTrajectoryError, match="panda_joint4") as info:
        simulate(robot, theta, theta, reference=ref, options=ClosedLoopOptions(duration=1.0))
    assert info.value.joint == "panda_joint4" and info.value.limit == "position"
    assert info.value.excess > 0


@pytest.mark.parametrize(
    "duration, rate", [(1.0, 333.3), (0.0105, 1000.0), (1.0, 0.0), (-1.0, 100.0)]
)
def test_rate_must_divide_duration(duration, rate):
    robot = get_robot("ur5")
    theta = robot.nominal_parameters
    with pytest.raises(InputError):
        simulate(robot, theta, theta, options=ClosedLoopOptions(duration=duration, rate=rate))


def test_bounds_and_shapes_are_checked():
    robot = get_robot("panda")
    theta = robot.nominal_parameters
    p = robot.n_parameters
    with pytest.raises(InputError, match="theta0"):
        SlotineLiController(robot, theta[:-1])
    with pytest.raises(InputError, match="outside the bounds"):
        SlotineLiController(robot, theta, AdaptiveGains(lower=theta + 1.0))
    with pytest.raises(InputError, match="lower <= upper"):
        SlotineLiController(robot, theta, AdaptiveGains(lower=np.zeros(p), upper=-np.ones(p)))
    with pytest.raises(InputError, match="payload"):
        with_payload(robot, theta, -1.0)
