"""The compiled block regressor against Pinocchio's ``computeJointTorqueRegressor``.

Every robot of the README's table and random URDF trees (revolute, prismatic and
continuous joints about unaligned axes, fixed joints between them, locked joints) are
checked sample by sample against Pinocchio's own call, the independent reference.
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from manip_id import _numba
from manip_id.errors import InputError
from manip_id.identification import identify
from manip_id.robot import compiled_regressor as cr
from manip_id.robot.model import load_robot
from manip_id.robot.regressor import iter_regressor, iter_slotine_li_regressor, slotine_li_regressor

pytest.importorskip("numba", reason="the compiled regressor needs numba (the 'fast' extra)")


@pytest.fixture(autouse=True)
def _compiled_mode(monkeypatch):
    """Every block through the kernel, whatever its size (the default waits for 2e5 samples)."""
    monkeypatch.setenv(cr.ENV, "compiled")


TABLE = [
    "msd",
    "panda",
    "ur3",
    "ur5",
    "ur10",
    "talos_arm",
    "z1",
    "xarm7",
    "kinova",
    "bravo7_no_ee",
    "bravo7_gripper",
    "baxter",
    "tiago_no_hand",
    "finger_edu",
    "asr_twodof",
    "double_pendulum",
    "double_pendulum_continuous",
]


def _reference(robot, q, dq, ddq) -> np.ndarray:
    m, d = robot.model, robot.model.createData()
    return np.stack(
        [pin.computeJointTorqueRegressor(m, d, q[k], dq[k], ddq[k]) for k in range(len(q))]
    ).reshape(len(q), robot.nv, robot.n_rigid)


def _compiled(robot, q, dq, ddq) -> np.ndarray:
    desc = cr.compile_model(robot.model)
    assert desc is not None, "the kernel should cover this model"
    out = np.full((len(q), robot.nv, robot.n_rigid), np.nan)
    cr.rigid_block(desc, q, dq, ddq, out)
    return out


def _close(got: np.ndarray, ref: np.ndarray) -> None:
    scale = max(1.0, float(np.abs(ref).max()))
    np.testing.assert_allclose(got, ref, rtol=0, atol=1e-10 * scale)


@pytest.mark.parametrize("name", TABLE)
def test_table_robots_equal_pinocchio(name):
    robot = load_robot(name)
    q, dq, ddq = robot.random_states(50, seed=3)
    _close(_compiled(robot, q, dq, ddq), _reference(robot, q, dq, ddq))


def _unit(rng) -> np.ndarray:
    v = rng.normal(size=3)
    return v / np.linalg.norm(v)


def _random_urdf(seed: int, n: int) -> str:
    """A random tree of n moving joints with fixed joints between some of them."""
    rng = np.random.default_rng(seed)
    links = ['<link name="base"/>']
    joints = []
    names = ["base"]
    for i in range(n):
        parent = names[int(rng.integers(0, len(names)))] if i else "base"
        if rng.random() < 0.3:  # a fixed joint and an intermediate link
            links.append(_link(f"mid{i}", rng))
            joints.append(_joint(f"fix{i}", "fixed", parent, f"mid{i}", rng))
            parent = f"mid{i}"
        kind = ["revolute", "prismatic", "continuous"][int(rng.integers(0, 3))]
        links.append(_link(f"l{i}", rng))
        joints.append(_joint(f"j{i}", kind, parent, f"l{i}", rng))
        names.append(f"l{i}")
    return '<robot name="random">' + "".join(links + joints) + "</robot>"


def _link(name: str, rng) -> str:
    m = rng.uniform(0.2, 3.0)
    c = rng.normal(scale=0.1, size=3)
    a = rng.uniform(0.01, 0.1, size=3)
    return (
        f'<link name="{name}"><inertial><origin xyz="{c[0]} {c[1]} {c[2]}" rpy="0 0 0"/>'
        f'<mass value="{m}"/><inertia ixx="{a[1] + a[2]}" ixy="0" ixz="0" iyy="{a[0] + a[2]}"'
        f' iyz="0" izz="{a[0] + a[1]}"/></inertial></link>'
    )


def _joint(name: str, kind: str, parent: str, child: str, rng) -> str:
    xyz = rng.normal(scale=0.3, size=3)
    rpy = rng.uniform(-np.pi, np.pi, size=3)
    axis = _unit(rng)
    limit = '<limit lower="-2" upper="2" effort="100" velocity="5"/>'
    return (
        f'<joint name="{name}" type="{kind}"><parent link="{parent}"/><child link="{child}"/>'
        f'<origin xyz="{xyz[0]} {xyz[1]} {xyz[2]}" rpy="{rpy[0]} {rpy[1]} {rpy[2]}"/>'
        f'<axis xyz="{axis[0]} {axis[1]} {axis[2]}"/>'
        + (limit if kind != "fixed" and kind != "continuous" else "")
        + "</joint>"
    )


@settings(max_examples=20, deadline=None)
@given(seed=st.integers(0, 10_000), n=st.integers(1, 9))
def test_random_trees_equal_pinocchio(tmp_path_factory, seed, n):
    path = tmp_path_factory.mktemp("urdf") / "random.urdf"
    path.write_text(_random_urdf(seed, n))
    robot = load_robot(path)
    q, dq, ddq = robot.random_states(20, seed=seed)
    _close(_compiled(robot, q, dq, ddq), _reference(robot, q, dq, ddq))


def test_locked_joints_equal_pinocchio():
    robot = load_robot("ur5", active_joints=["shoulder_pan_joint", "elbow_joint", "wrist_3_joint"])
    assert robot.nv == 3
    q, dq, ddq = robot.random_states(30, seed=5)
    _close(_compiled(robot, q, dq, ddq), _reference(robot, q, dq, ddq))


def test_twenty_joint_chain_equals_pinocchio(tmp_path):
    rng = np.random.default_rng(0)
    links = ['<link name="l0"/>'] + [_link(f"l{i}", rng) for i in range(1, 21)]
    joints = [_joint(f"j{i}", "revolute", f"l{i - 1}", f"l{i}", rng) for i in range(1, 21)]
    path = tmp_path / "chain.urdf"
    path.write_text('<robot name="chain">' + "".join(links + joints) + "</robot>")
    robot = load_robot(path)
    q, dq, ddq = robot.random_states(20, seed=1)
    _close(_compiled(robot, q, dq, ddq), _reference(robot, q, dq, ddq))


def test_slotine_li_blocks_equal_the_polarization_by_pinocchio():
    robot = load_robot("panda")
    q, dq, _ = robot.random_states(25, seed=2)
    rng = np.random.default_rng(2)
    v, w = rng.normal(size=(2, 25, robot.nv))
    got = np.concatenate([c.Y.copy() for c in iter_slotine_li_regressor(robot, q, dq, v, w, 7)])
    ref = np.stack([slotine_li_regressor(robot, q[k], dq[k], v[k], w[k]) for k in range(25)])
    _close(got, ref)


def test_uncovered_joints_and_the_switch_fall_back_to_pinocchio(monkeypatch):
    model = pin.buildSampleModelHumanoidRandom()  # free-flyer root: not covered
    assert cr.describe_model(model) is None
    robot = load_robot("ur5")
    monkeypatch.setenv(cr.ENV, "pinocchio")
    assert cr.compile_model(robot.model) is None
    monkeypatch.setenv(cr.ENV, "compiled")
    assert cr.compile_model(robot.model) is not None
    q, dq, ddq = robot.random_states(10, seed=4)
    got = np.concatenate(
        [c.Y[:, :, : robot.n_rigid].copy() for c in iter_regressor(robot, q, dq, ddq)]
    )
    _close(got, _reference(robot, q, dq, ddq))


def test_modes_and_auto_threshold(monkeypatch):
    robot = load_robot("double_pendulum")
    ev = robot.evaluator
    monkeypatch.setenv(cr.ENV, "auto")
    monkeypatch.setattr(cr, "_seen", 0)  # a fresh process: no samples evaluated yet
    monkeypatch.setattr(_numba, "_warm", False)  # ... and no numba kernel run
    assert ev.kernel_for(10) is None  # a small job keeps Pinocchio
    assert ev.kernel_for(cr.AUTO_SAMPLES) is not None  # a large one takes the kernel
    monkeypatch.setattr(cr, "_seen", 0)
    _numba.note_numba_warm()  # numba loaded by another kernel (the filter): no one-off cost left
    assert ev.kernel_for(10) is not None
    monkeypatch.setenv(cr.ENV, "pinocchio")
    assert ev.kernel_for(10**9) is None
    monkeypatch.setenv(cr.ENV, "fast")
    with pytest.raises(InputError, match="MANIP_ID_REGRESSOR must be one of auto, compiled"):
        cr.mode()
    with pytest.raises(InputError, match="the regressor must be one of"):
        cr.set_mode("numba")


@pytest.mark.parametrize("mode", ["compiled", "pinocchio"])
def test_identification_is_the_same_on_both_paths(monkeypatch, mode):
    robot = load_robot("ur5")
    q, dq, ddq = robot.random_states(3000, seed=1)
    m, d = robot.model, robot.model.createData()
    tau = np.array([pin.rnea(m, d, q[k], dq[k], ddq[k]) for k in range(len(q))])
    tau += np.random.default_rng(1).normal(scale=0.05, size=tau.shape)
    sim = (q, dq, ddq, tau)
    monkeypatch.setenv(cr.ENV, "pinocchio")
    ref = identify(robot, tuple(sim))
    monkeypatch.setenv(cr.ENV, mode)
    got = identify(robot, tuple(sim))
    np.testing.assert_allclose(got.estimate, ref.estimate, rtol=1e-9, atol=1e-9)


def _momentum_pair(spec, monkeypatch, **kw):
    """``(compiled, reference)`` momentum regressors of one robot at random states: the
    reference through Pinocchio's kinematic derivatives, one call per sample."""
    from manip_id.models import momentum_regressors

    robot = load_robot(spec, **kw)
    q, dq, _ = robot.random_states(30, seed=5)
    got = momentum_regressors(robot, q, dq)
    monkeypatch.setenv(cr.ENV, "pinocchio")
    ref = momentum_regressors(load_robot(spec, **kw), q, dq)
    monkeypatch.setenv(cr.ENV, "compiled")
    return robot, q, dq, got, ref


@pytest.mark.parametrize("name", ["panda", "ur10", "tiago_no_hand", "baxter", "asr_twodof"])
def test_momentum_regressors_equal_the_derivative_path(name, monkeypatch):
    robot, q, dq, got, ref = _momentum_pair(
        name, monkeypatch, friction=["viscous", "coulomb"], armature=True
    )
    for a, b in zip(got, ref, strict=True):
        _close(a, b)
    # and against crba / the Coriolis matrix: Y_p theta = M dq, Y_h theta = g - C^T dq + ...
    theta = robot.nominal_parameters
    rigid = np.r_[theta[: robot.n_rigid], np.zeros(theta.size - robot.n_rigid)]
    model = robot.with_parameters(rigid)
    data = model.createData()
    for k in range(3):
        M = pin.crba(model, data, q[k])
        M = np.triu(M) + np.triu(M, 1).T
        C = pin.computeCoriolisMatrix(model, data, q[k], dq[k])
        g = pin.computeGeneralizedGravity(model, data, q[k])
        np.testing.assert_allclose(got[0][k] @ rigid, M @ dq[k], rtol=1e-10, atol=1e-10)
        np.testing.assert_allclose(got[1][k] @ rigid, g - C.T @ dq[k], rtol=1e-10, atol=1e-9)


@settings(max_examples=10, deadline=None)
@given(seed=st.integers(0, 10_000), n=st.integers(1, 7))
def test_momentum_regressors_of_random_trees(tmp_path_factory, seed, n):
    path = tmp_path_factory.mktemp("urdf") / "random.urdf"
    path.write_text(_random_urdf(seed, n))
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv(cr.ENV, "compiled")
        *_, got, ref = _momentum_pair(path, mp)
    for a, b in zip(got, ref, strict=True):
        _close(a, b)
