"""Simulated measurements: torques from rnea against the regressor, valid perturbations, noise."""

from __future__ import annotations

import math

import numpy as np
import pinocchio as pin
import pytest
from conftest import get_robot
from hypothesis import given, settings
from hypothesis import strategies as st

from manip_id import InputError, load_robot, regressor
from manip_id.datasets import Dataset
from manip_id.simulation import (
    MeasurementNoise,
    SimulatedData,
    inverse_dynamics,
    perturb_parameters,
    simulate,
)
from manip_id.trajectories import random_trajectory

ALL = dict(armature=True, friction=("viscous", "coulomb", "offset"))
ROBOTS = {
    "panda": lambda: get_robot("panda", **ALL),
    "ur5": lambda: get_robot("ur5", **ALL),
    "double_pendulum_continuous": lambda: get_robot(
        "double_pendulum_continuous", armature=True, friction=("viscous",), spring=True
    ),
    "msd": lambda: get_robot("msd", armature=True, friction=("viscous", "coulomb"), spring=True),
    "panda_rigid": lambda: get_robot("panda"),
}


def _theta_with_joint_terms(robot, seed=0):
    """Nominal rigid bodies, positive joint terms (the URDFs leave most at zero)."""
    theta = robot.nominal_parameters.copy()
    rng = np.random.default_rng(seed)
    theta[robot.n_rigid :] = rng.uniform(0.05, 0.5, size=theta.size - robot.n_rigid)
    return theta


# ------------------------------------------------------------- two independent paths
@pytest.mark.parametrize("name", list(ROBOTS))
@pytest.mark.parametrize("perturb", [0.0, 0.3])
def test_simulated_torques_equal_regressor_times_truth(name, perturb):
    robot = ROBOTS[name]()
    traj = random_trajectory(robot, 3, seed=1)
    sim = simulate(
        robot,
        traj,
        duration=4.0,
        rate=50.0,
        theta=_theta_with_joint_terms(robot),
        perturb=perturb,
        seed=5,
    )
    ds = sim.dataset
    Y = regressor(robot, ds.q, ds.dq, ds.ddq)
    scale = max(np.abs(ds.tau).max(), 1.0)
    np.testing.assert_allclose(Y @ sim.theta_true, ds.tau, rtol=0, atol=1e-9 * scale)
    np.testing.assert_array_equal(sim.tau_true, ds.tau)  # no noise asked


def test_rigid_torques_are_pinocchio_rnea_of_the_description():
    robot = get_robot("panda")
    traj = random_trajectory(robot, 2, seed=3)
    sim = simulate(robot, traj, duration=1.0, rate=20.0)
    data = robot.model.createData()
    ds = sim.dataset
    expect = np.array(
        [pin.rnea(robot.model, data, q, v, a) for q, v, a in zip(ds.q, ds.dq, ds.ddq, strict=True)]
    )
    np.testing.assert_allclose(ds.tau, expect, atol=1e-12)
    np.testing.assert_array_equal(sim.theta_true, robot.nominal_parameters)


def test_samples_follow_the_trajectory_at_the_rate():
    robot = get_robot("double_pendulum_continuous")
    traj = random_trajectory(robot, 3, seed=2)
    sim = simulate(robot, traj, duration=2.0, rate=100.0)
    ds = sim.dataset
    assert isinstance(sim, SimulatedData) and isinstance(ds, Dataset)
    assert ds.n_samples == 201
    np.testing.assert_allclose(np.diff(ds.t), 0.01, atol=1e-12)
    assert ds.joint_names == tuple(robot.dof_names)
    assert ds.q.shape == (201, 4) and ds.dq.shape == (201, 2)
    angles = np.arctan2(ds.q[:, [1, 3]], ds.q[:, [0, 2]])
    expect, dq, ddq = traj.sample(ds.t)
    np.testing.assert_allclose(np.angle(np.exp(1j * (angles - expect))), 0.0, atol=1e-12)
    np.testing.assert_array_equal(ds.dq, dq)
    np.testing.assert_array_equal(ds.ddq, ddq)


# ------------------------------------------------------------- perturbed parameters
def _assert_physical(robot, theta):
    for i, block in enumerate(robot.rigid_body_parameters(theta)):
        inertia = pin.Inertia.FromDynamicParameters(np.asarray(block))
        assert inertia.mass > 0, f"body {i}"
        lam = np.linalg.eigvalsh(inertia.inertia)
        assert lam.min() > 0, f"body {i}: {lam}"
        tol = 1e-12 * lam.max()
        assert lam[2] <= lam[0] + lam[1] + tol, f"body {i}: triangle inequality {lam}"
    joint = theta[robot.n_rigid :].reshape(robot.nv, len(robot.terms.enabled))
    for k, term in enumerate(robot.terms.enabled):
        if term != "fo":
            assert np.all(joint[:, k] >= 0), term


@settings(max_examples=25, deadline=None)
@given(
    seed=st.integers(0, 2**32 - 1),
    rel=st.floats(0.0, 1.0),
    name=st.sampled_from(["panda", "ur5", "msd"]),
)
def test_perturbed_parameters_are_physically_valid(seed, rel, name):
    robot = ROBOTS[name]()
    theta = perturb_parameters(robot, rel, seed=seed, theta=_theta_with_joint_terms(robot))
    _assert_physical(robot, theta)


def test_perturbation_size_follows_rel():
    robot = get_robot("panda", **ALL)
    nominal = _theta_with_joint_terms(robot)
    masses = nominal[: robot.n_rigid : 10]
    logs = []
    for seed in range(40):
        theta = perturb_parameters(robot, 0.1, seed=seed, theta=nominal)
        logs.append(np.log(theta[: robot.n_rigid : 10] / masses))
    # log(m'/m) = 0.1 e with e standard normal: its std is 0.1 (280 draws: within 15%)
    assert np.std(logs) == pytest.approx(0.1, rel=0.15)
    np.testing.assert_array_equal(perturb_parameters(robot, 0.0, theta=nominal), nominal)
    a = perturb_parameters(robot, 0.2, seed=3, theta=nominal)
    np.testing.assert_array_equal(a, perturb_parameters(robot, 0.2, seed=3, theta=nominal))
    assert not np.array_equal(a, perturb_parameters(robot, 0.2, seed=4, theta=nominal))


def test_zero_perturbation_keeps_the_inertias_exactly():
    robot = get_robot("ur5")
    theta = perturb_parameters(robot, 1e-12, seed=0)
    np.testing.assert_allclose(theta, robot.nominal_parameters, rtol=1e-9, atol=1e-12)


# ------------------------------------------------------------------------- noise
def test_noise_statistics_and_independent_streams():
    robot = get_robot("panda")
    traj = random_trajectory(robot, 5, seed=4)
    kw = dict(duration=10.0, rate=500.0, seed=9)
    sim = simulate(robot, traj, noise=MeasurementNoise(tau=0.05, q=1e-3, dq=2e-3), **kw)
    ds = sim.dataset
    rms = np.sqrt(np.mean(sim.tau_true**2, axis=0))
    e = (ds.tau - sim.tau_true) / rms  # 5001 x 7 standard draws times 0.05
    n = e.size
    assert np.std(e) == pytest.approx(0.05, rel=0.02)  # std error of the std: 0.4%
    np.testing.assert_allclose(np.std(e, axis=0), 0.05, rtol=0.05)
    assert abs(np.mean(e)) < 5 * 0.05 / math.sqrt(n)
    clean = simulate(robot, traj, **kw).dataset
    dq_err = ds.q - clean.q
    assert np.std(dq_err) == pytest.approx(1e-3, rel=0.03)
    assert np.std(ds.dq - clean.dq) == pytest.approx(2e-3, rel=0.03)
    np.testing.assert_array_equal(ds.ddq, clean.ddq)
    # correlation between torque noise and position noise is that of independent draws
    corr = np.corrcoef(e.ravel(), dq_err.ravel())[0, 1]
    assert abs(corr) < 5 / math.sqrt(n)
    # switching the position noise off leaves the torque noise as it was
    tau_only = simulate(robot, traj, noise=MeasurementNoise(tau=0.05), **kw).dataset
    np.testing.assert_array_equal(tau_only.tau, ds.tau)
    np.testing.assert_array_equal(tau_only.q, clean.q)


def test_noise_on_continuous_joints_is_on_the_angle():
    robot = get_robot("double_pendulum_continuous")
    traj = random_trajectory(robot, 2, seed=0)
    kw = dict(duration=20.0, rate=200.0, seed=1)
    noisy = simulate(robot, traj, noise=MeasurementNoise(q=0.01), **kw).dataset
    clean = simulate(robot, traj, **kw).dataset
    np.testing.assert_allclose(np.linalg.norm(noisy.q.reshape(-1, 2, 2), axis=2), 1.0, atol=1e-12)
    d = np.arctan2(noisy.q[:, [1, 3]], noisy.q[:, [0, 2]]) - np.arctan2(
        clean.q[:, [1, 3]], clean.q[:, [0, 2]]
    )
    d = np.angle(np.exp(1j * d))
    assert np.std(d) == pytest.approx(0.01, rel=0.05)


# ------------------------------------------------------------------- bad input
@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        (dict(duration=0.0, rate=10.0), "duration"),
        (dict(duration=1.0, rate=-1.0), "rate"),
        (dict(duration=0.05, rate=10.0), "fewer than 2"),
        (dict(duration=1.0, rate=10.0, noise=MeasurementNoise(tau=-0.1)), "noise.tau"),
        (dict(duration=1.0, rate=10.0, perturb=math.nan), "perturb"),
        (dict(duration=1.0, rate=10.0, theta=np.zeros(3)), "n_parameters"),
    ],
)
def test_simulate_bad_input(kwargs, match):
    robot = get_robot("panda")
    traj = random_trajectory(robot, 2)
    with pytest.raises(InputError, match=match):
        simulate(robot, traj, **kwargs)


def test_simulate_wrong_trajectory():
    robot = get_robot("panda")
    with pytest.raises(InputError, match="robot.nv=7"):
        simulate(robot, random_trajectory(get_robot("ur5"), 2), duration=1.0, rate=10.0)
    with pytest.raises(InputError, match="FourierTrajectory"):
        simulate(robot, "circle", duration=1.0, rate=10.0)


def test_inverse_dynamics_ignores_an_unmodelled_armature():
    robot = load_robot("panda")  # own copy: its model is changed below
    assert not robot.terms.armature
    robot.model.armature = np.full(7, 0.5)  # present in the description, absent from theta
    q, dq, ddq = robot.random_states(5, seed=1)
    tau = inverse_dynamics(robot, robot.nominal_parameters, q, dq, ddq)
    model = robot.model.copy()
    model.armature = np.zeros(7)
    data = model.createData()
    expect = np.array([pin.rnea(model, data, *s) for s in zip(q, dq, ddq, strict=True)])
    np.testing.assert_allclose(tau, expect, atol=1e-12)
    np.testing.assert_allclose(
        regressor(robot, q, dq, ddq) @ robot.nominal_parameters, tau, atol=1e-9
    )
