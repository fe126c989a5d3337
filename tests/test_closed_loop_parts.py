"""The pieces of the closed-loop simulation: Plant, SensorNoise, Recorder and step.

Independent references: the plant's acceleration against pinocchio.rnea plus the
friction torques written here with numpy; one control period against semi-implicit
Euler written here with pinocchio.aba; the recorder's stride against numpy.arange.
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest
from conftest import get_robot

from manip_id.control.adaptive import SlotineLiController, default_gains
from manip_id.control.closed_loop import (
    ClosedLoopOptions,
    Plant,
    Recorder,
    SensorNoise,
    Setpoint,
    simulate,
    step,
)
from manip_id.errors import InputError, NumericalError
from manip_id.physics.consistency import PhysicalConsistencyError
from manip_id.simulation import perturb_parameters


def _friction_robot():
    robot = get_robot("ur5", armature=True, friction="viscous,coulomb")
    theta0 = robot.nominal_parameters.copy()
    theta0[robot.n_rigid :] = 0.05
    theta = perturb_parameters(robot, 0.3, seed=4, theta=theta0)
    return robot, theta


def test_plant_acceleration_solves_inverse_dynamics_with_friction():
    robot, theta = _friction_robot()
    plant = Plant(robot, theta, rate=1000.0)
    q, dq, _ = robot.random_states(1, seed=5)
    tau = np.random.default_rng(6).normal(size=robot.nv) * 5.0  # [N m]
    ddq = plant.acceleration(q[0], dq[0], tau)
    # independent: tau = rnea(theta) (with armature) + fv dq + fc sign(dq)
    ia, fv, fc = (
        np.array([theta[robot.layout.joint_column(j, t)] for j in range(robot.nv)])
        for t in ("Ia", "fv", "fc")
    )
    model = robot.with_parameters(theta)
    np.testing.assert_allclose(model.armature, ia, rtol=1e-12)
    rnea = pin.rnea(model, model.createData(), q[0], dq[0], ddq)
    np.testing.assert_allclose(rnea + fv * dq[0] + fc * np.sign(dq[0]), tau, atol=1e-9)
    assert plant.viscous is not None
    np.testing.assert_allclose(plant.viscous, fv, rtol=1e-12)


@pytest.mark.parametrize("substeps", [1, 3])
def test_plant_advance_is_semi_implicit_euler(substeps):
    robot, theta = _friction_robot()
    plant = Plant(robot, theta, rate=500.0, substeps=substeps)
    q, dq, _ = robot.random_states(1, seed=7)
    q, dq = q[0], dq[0]
    tau = np.full(robot.nv, 2.0)  # [N m]
    q1, dq1 = plant.advance(q, dq, tau)
    model = robot.with_parameters(theta)
    data = model.createData()
    fv = np.array([theta[robot.layout.joint_column(j, "fv")] for j in range(robot.nv)])
    fc = np.array([theta[robot.layout.joint_column(j, "fc")] for j in range(robot.nv)])
    h = 1.0 / (500.0 * substeps)  # [s]
    for _ in range(substeps):
        dq = dq + h * pin.aba(model, data, q, dq, tau - fv * dq - fc * np.sign(dq))
        q = q + h * dq
    np.testing.assert_allclose(dq1, dq, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(q1, q, rtol=1e-12, atol=1e-12)


def test_sensor_noise_on_continuous_joints_stays_on_the_circle():
    robot = get_robot("double_pendulum_continuous")
    theta = robot.nominal_parameters
    plant = Plant(robot, theta, rate=1000.0)
    q, dq, _ = robot.random_states(1, seed=2)
    noise = SensorNoise(0.01, 0.1, np.random.default_rng(3))
    qm, dqm = noise.measure(plant, q[0], dq[0])
    rng = np.random.default_rng(3)
    dv_q, dv_dq = 0.01 * rng.standard_normal(robot.nv), 0.1 * rng.standard_normal(robot.nv)
    np.testing.assert_allclose(qm, pin.integrate(robot.model, q[0], dv_q), atol=1e-14)
    np.testing.assert_allclose(dqm, dq[0] + dv_dq, atol=1e-14)
    np.testing.assert_allclose(np.hypot(qm[0::2], qm[1::2]), 1.0, atol=1e-12)


def test_recorder_stride_keeps_the_last_step():
    robot = get_robot("ur5")
    rec = Recorder(robot, 20, 1e-3, record_every=7, damping=np.eye(robot.nv))
    np.testing.assert_array_equal(rec.indices, [0, 7, 14, 19])
    theta = robot.nominal_parameters
    run = simulate(
        robot, theta, theta, options=ClosedLoopOptions(duration=0.02, rate=1000, record_every=7)
    )
    np.testing.assert_allclose(run.t, np.array([0, 7, 14, 19]) * 1e-3, atol=1e-15)


def test_step_raises_numerical_error_on_divergence():
    robot = get_robot("ur5")
    theta = robot.nominal_parameters
    plant = Plant(robot, theta, rate=10.0)
    ctrl = SlotineLiController(robot, theta, default_gains(robot, theta))
    rec = Recorder(robot, 1, plant.dt, damping=ctrl.kd)
    q = pin.neutral(robot.model)
    dq = np.full(robot.nv, 1e300)  # [rad/s]: overflows in one period
    z = np.zeros(robot.nv)
    with np.errstate(over="ignore", invalid="ignore"), pytest.raises(NumericalError):
        step(plant, ctrl, rec, 0, q, dq, Setpoint(q, z, z))


def test_plant_checks_its_inputs():
    robot = get_robot("ur5")
    theta = robot.nominal_parameters
    with pytest.raises(InputError, match="integrator"):
        Plant(robot, theta, rate=100.0, integrator="midpoint")
    with pytest.raises(InputError, match="substeps"):
        Plant(robot, theta, rate=100.0, substeps=0)
    with pytest.raises(InputError, match="theta"):
        Plant(robot, theta[:-1], rate=100.0)
    bad = theta.copy()
    bad[0] = -1.0  # a negative mass
    with pytest.raises(PhysicalConsistencyError, match="mass"):
        Plant(robot, bad, rate=100.0)
