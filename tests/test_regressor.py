"""Regressors against Pinocchio's own dynamics (rnea, crba, Coriolis, gravity)."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest
from conftest import get_robot
from hypothesis import given, settings
from hypothesis import strategies as st

from manip_id import (
    InputError,
    iter_regressor,
    iter_slotine_li_regressor,
    load_robot,
    regressor,
    slotine_li_regressor,
)
from manip_id.simulation import perturb_parameters

ALL_TERMS = dict(armature=True, friction=("viscous", "coulomb", "offset"))


def _ur5_by_path():
    from example_robot_data.robots_loader import ROBOTS

    return load_robot(ROBOTS["ur5"]().df_path, **ALL_TERMS)


ROBOTS = {
    "panda": lambda: get_robot("panda", **ALL_TERMS),
    "ur5": lambda: get_robot("ur5", **ALL_TERMS),
    "talos_arm": lambda: get_robot("talos_arm", **ALL_TERMS),
    "double_pendulum": lambda: get_robot("double_pendulum", **ALL_TERMS),
    "kinova": lambda: get_robot("kinova", **ALL_TERMS),
    "msd": lambda: get_robot(
        "msd", armature=True, friction=("viscous", "coulomb", "offset"), spring=True
    ),
    "ur5_urdf_path": _ur5_by_path,
}


def _theta(robot, seed=0):
    """Nominal parameters with random positive joint terms."""
    rng = np.random.default_rng(seed)
    theta = robot.nominal_parameters.copy()
    theta[robot.n_rigid :] = rng.uniform(0.05, 0.5, robot.n_parameters - robot.n_rigid)
    return theta


def _joint_torque_direct(robot, theta, q, dq, ddq):
    """Joint-level torques written out term by term (independent of the regressor)."""
    values = dict(zip(robot.parameter_names, theta, strict=True))
    tau = np.zeros(robot.nv)
    for j, dof in enumerate(robot.dof_names):
        jm = robot.model.joints[robot.model.getJointId(dof)]
        angle = q[jm.idx_q] if jm.nq == 1 else np.arctan2(q[jm.idx_q + 1], q[jm.idx_q])
        tau[j] += values.get(f"{dof}.fv", 0.0) * dq[j]
        tau[j] += values.get(f"{dof}.fc", 0.0) * np.sign(dq[j])
        tau[j] += values.get(f"{dof}.fo", 0.0)
        tau[j] += values.get(f"{dof}.k", 0.0) * angle
        # armature: part of rnea through model.armature
    return tau


@pytest.mark.parametrize("name", list(ROBOTS))
def test_regressor_matches_rnea(name):
    robot = ROBOTS[name]()
    theta = _theta(robot)
    model = robot.with_parameters(theta)  # inertias and armature of theta
    data = model.createData()
    q, dq, ddq = robot.random_states(20, seed=1)
    Y = regressor(robot, q, dq, ddq)
    assert Y.shape == (20, robot.nv, robot.n_parameters)
    for k in range(20):
        tau = pin.rnea(model, data, q[k], dq[k], ddq[k]) + _joint_torque_direct(
            robot, theta, q[k], dq[k], ddq[k]
        )
        np.testing.assert_allclose(Y[k] @ theta, tau, rtol=1e-9, atol=1e-9 * np.abs(tau).max())
        # one sample is Pinocchio's own call; a batch may be the compiled kernel (same math)
        single = regressor(robot, q[k], dq[k], ddq[k])
        np.testing.assert_allclose(Y[k], single, rtol=0, atol=1e-12 * np.abs(single).max())


def test_armature_column_is_ddq():
    robot = ROBOTS["talos_arm"]()
    q, dq, ddq = robot.random_states(3, seed=2)
    Y = regressor(robot, q, dq, ddq)
    for j, dof in enumerate(robot.dof_names):
        col = robot.parameter_index(f"{dof}.Ia")
        expected = np.zeros((3, robot.nv))
        expected[:, j] = ddq[:, j]
        np.testing.assert_array_equal(Y[:, :, col], expected)


def _dense_mass(model, data, q):
    M = pin.crba(model, data, q)
    return np.triu(M) + np.triu(M, 1).T


@pytest.mark.parametrize("name", list(ROBOTS))
def test_slotine_li_matches_crba_coriolis_gravity(name):
    robot = ROBOTS[name]()
    theta = _theta(robot, seed=4)
    model = robot.with_parameters(theta)
    data = model.createData()
    rng = np.random.default_rng(5)
    q, dq, _ = robot.random_states(15, seed=6)
    v, w = rng.normal(size=(2, 15, robot.nv))
    Y = slotine_li_regressor(robot, q, dq, v, w)
    for k in range(15):
        M = _dense_mass(model, data, q[k])  # includes armature
        C = pin.computeCoriolisMatrix(model, data, q[k], dq[k])
        g = pin.computeGeneralizedGravity(model, data, q[k])
        expected = M @ v[k] + C @ w[k] + g + _joint_torque_direct(robot, theta, q[k], w[k], v[k])
        np.testing.assert_allclose(
            Y[k] @ theta, expected, rtol=1e-9, atol=1e-9 * np.abs(expected).max()
        )


@pytest.mark.parametrize("name", list(ROBOTS))
def test_slotine_li_reduces_to_inverse_dynamics(name):
    robot = ROBOTS[name]()
    q, dq, ddq = robot.random_states(10, seed=7)
    np.testing.assert_allclose(
        slotine_li_regressor(robot, q, dq, ddq, dq),
        regressor(robot, q, dq, ddq),
        rtol=1e-12,
        atol=1e-10,
    )


@pytest.mark.parametrize("name", ["panda", "ur5", "talos_arm", "double_pendulum"])
def test_mdot_minus_2c_is_skew(name):
    robot = ROBOTS[name]()
    model = robot.with_parameters(_theta(robot))
    data = model.createData()
    q, dq, _ = robot.random_states(5, seed=8)
    h = 1e-6
    for k in range(5):
        dM = (
            _dense_mass(model, data, pin.integrate(model, q[k], dq[k] * h))
            - _dense_mass(model, data, pin.integrate(model, q[k], -dq[k] * h))
        ) / (2 * h)
        C = pin.computeCoriolisMatrix(model, data, q[k], dq[k])
        S = dM - 2 * C
        assert np.abs(S + S.T).max() < 1e-6 * max(1.0, np.abs(dM).max())
        # the Slotine-Li regressor at v = 0, w = e_0 gives column 0 of C (plus gravity, joint terms)
        theta = _theta(robot)
        model_t = robot.with_parameters(theta)
        data_t = model_t.createData()
        e0 = np.eye(robot.nv)[0]
        Y = slotine_li_regressor(robot, q[k], dq[k], np.zeros(robot.nv), e0)
        C_t = pin.computeCoriolisMatrix(model_t, data_t, q[k], dq[k])
        g = pin.computeGeneralizedGravity(model_t, data_t, q[k])
        expected = C_t[:, 0] + g + _joint_torque_direct(robot, theta, q[k], e0, np.zeros(robot.nv))
        np.testing.assert_allclose(
            Y @ theta, expected, atol=1e-9 * max(1.0, np.abs(expected).max())
        )


@settings(max_examples=25, deadline=None)
@given(seed=st.integers(0, 2**31 - 1), rel=st.floats(0.0, 0.8))
def test_any_parameters_any_state_match_rnea(seed, rel):
    """Y(q, dq, ddq) theta == rnea of the model holding theta, for drawn states and theta."""
    robot = get_robot("ur5")  # rigid bodies only: rnea is the whole reference
    theta = perturb_parameters(robot, rel, seed=seed)
    q, dq, ddq = robot.random_states(1, seed=seed)
    model = robot.with_parameters(theta)
    tau = pin.rnea(model, model.createData(), q[0], dq[0], ddq[0])
    Y = regressor(robot, q[0], dq[0], ddq[0])
    np.testing.assert_allclose(Y @ theta, tau, rtol=1e-9, atol=1e-9 * (1 + np.abs(tau).max()))


@settings(max_examples=15, deadline=None)
@given(n=st.integers(1, 40), chunk=st.integers(1, 17), seed=st.integers(0, 1000))
def test_chunked_equals_per_sample(n, chunk, seed):
    robot = ROBOTS["panda"]()
    q, dq, ddq = robot.random_states(n, seed=seed)
    rng = np.random.default_rng(seed)
    v, w = rng.normal(size=(2, n, robot.nv))
    got = np.concatenate([c.Y.copy() for c in iter_regressor(robot, q, dq, ddq, chunk=chunk)])
    # chunking changes nothing: equal to one whole block, bit for bit
    np.testing.assert_array_equal(got, regressor(robot, q, dq, ddq))
    # and the block (compiled kernel where available) equals Pinocchio's per-sample call
    ref = np.stack([regressor(robot, q[k], dq[k], ddq[k]) for k in range(n)])
    np.testing.assert_allclose(got, ref, rtol=0, atol=1e-12 * max(1.0, np.abs(ref).max()))
    got_sl = np.concatenate(
        [c.Y.copy() for c in iter_slotine_li_regressor(robot, q, dq, v, w, chunk=chunk)]
    )
    ref_sl = np.stack([slotine_li_regressor(robot, q[k], dq[k], v[k], w[k]) for k in range(n)])
    np.testing.assert_allclose(got_sl, ref_sl, rtol=0, atol=1e-12)


@settings(max_examples=20, deadline=None)
@given(width=st.integers(1, 12), n=st.integers(1, 5))
def test_shape_errors(width, n):
    robot = ROBOTS["ur5"]()
    good = np.zeros((n, 6))
    if width != 6:
        with pytest.raises(InputError, match=r"q.shape=.* but robot.nq=6"):
            regressor(robot, np.zeros((n, width)), good, good)
        with pytest.raises(InputError, match=r"ddq.shape=.* but robot.nv=6"):
            regressor(robot, good, good, np.zeros((n, width)))
    with pytest.raises(InputError, match="same number of samples"):
        regressor(robot, good, np.zeros((n + 1, 6)), good)
    with pytest.raises(InputError, match="1-D"):
        regressor(robot, good[0], good, good)


def test_nan_reports_sample_and_joint():
    robot = ROBOTS["ur5"]()
    q, dq, ddq = robot.random_states(10, seed=0)
    dq[7, 2] = np.nan
    with pytest.raises(InputError, match="dq holds nan at sample 7, elbow_joint"):
        regressor(robot, q, dq, ddq)
    ddq[3, 0] = np.inf
    with pytest.raises(InputError, match="sample 3"):
        slotine_li_regressor(robot, q, np.zeros_like(dq), ddq, ddq)


def test_bad_chunk():
    robot = ROBOTS["ur5"]()
    q, dq, ddq = robot.random_states(3, seed=0)
    with pytest.raises(InputError, match="chunk"):
        iter_regressor(robot, q, dq, ddq, chunk=0)
