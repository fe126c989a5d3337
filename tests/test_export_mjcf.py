"""The identified model as MuJoCo MJCF, checked by MuJoCo itself.

Reference: MuJoCo's own inverse dynamics (``mj_inverse``) of the exported file against
``Y @ theta`` of the identification (rigid bodies + armature + viscous + spring, 1e-6
relative); the Coulomb part separately, as MuJoCo's friction-loss constraint in steady
sliding (``qacc = 0``); and a rollout under gravity compensation. Skipped, with the
reason, when the optional ``mujoco`` package is not installed.
"""

from __future__ import annotations

import json
import warnings

import numpy as np
import pinocchio as pin
import pytest
from conftest import get_robot
from test_export import CASES, _consistent_theta

from manip_id import load_robot, regressor
from manip_id.cli import main
from manip_id.datasets import load_dataset
from manip_id.errors import ExportWarning, InputError
from manip_id.export import export_mjcf, sidecar_path
from manip_id.physics.consistency import PhysicalConsistencyError
from manip_id.simulation import simulate
from manip_id.trajectories import random_trajectory

mujoco = pytest.importorskip(
    "mujoco", reason="the MJCF checks need the optional mujoco package (pip install mujoco)"
)

OFF = mujoco.mjtDisableBit
JOINT = mujoco.mjtObj.mjOBJ_JOINT


def _load(path, *disabled) -> tuple:
    model = mujoco.MjModel.from_xml_path(str(path))
    for flag in disabled:
        model.opt.disableflags |= int(flag)
    return model, mujoco.MjData(model)


def _angle(model: pin.Model, i: int, q: np.ndarray) -> float:
    """MuJoCo's coordinate of Pinocchio joint ``i``: the angle of a continuous joint
    (stored as cos, sin), else the coordinate itself."""
    jm = model.joints[i]
    c = q[jm.idx_q : jm.idx_q + jm.nq]
    return float(np.arctan2(c[1], c[0])) if jm.nq == 2 else float(c[0])


def _inverse(model, data, robot, q, dq, ddq) -> np.ndarray:
    """``qfrc_inverse`` of the robot's joints at each sample, shape (N, nv); the other joints
    held at the robot's locked configuration (zero velocity and acceleration)."""
    full, qref, red = robot.full_model, robot.locked_configuration, robot.model
    out = np.empty((q.shape[0], robot.nv))
    ids = [mujoco.mj_name2id(model, JOINT, red.names[i]) for i in range(1, red.njoints)]
    adr = model.jnt_dofadr[ids]
    for jid in range(model.njnt):
        i = full.getJointId(mujoco.mj_id2name(model, JOINT, jid))
        data.qpos[model.jnt_qposadr[jid]] = _angle(full, i, qref)
    for k in range(q.shape[0]):
        data.qvel[:], data.qacc[:] = 0.0, 0.0
        for i, jid in enumerate(ids, start=1):
            data.qpos[model.jnt_qposadr[jid]] = _angle(red, i, q[k])
        data.qvel[adr], data.qacc[adr] = dq[k], ddq[k]
        mujoco.mj_inverse(model, data)
        out[k] = data.qfrc_inverse[adr]
    return out


def _coulomb(robot, theta, dq) -> np.ndarray:
    if not robot.terms.coulomb:
        return np.zeros_like(dq)
    fc = theta[robot.layout.joint_columns("fc")]
    return fc * np.sign(dq)


@pytest.mark.parametrize("spec, active", CASES)
def test_mujoco_inverse_dynamics_replays_the_identified_torques(tmp_path, spec, active):
    robot = load_robot(spec, armature=True, friction="viscous,coulomb", active_joints=active)
    theta = _consistent_theta(robot)
    out = tmp_path / "robot_id.xml"
    result = export_mjcf(robot, theta, out)
    assert result.path == out and sidecar_path(out).is_file()
    # identification data: an excitation trajectory, torques of theta (noise-free)
    sim = simulate(robot, random_trajectory(robot, 3, seed=1), duration=4.0, rate=25.0)
    ds = sim.dataset
    tau_id = (regressor(robot, ds.q, ds.dq, ds.ddq) @ theta).reshape(ds.n_samples, robot.nv)
    model, data = _load(out, OFF.mjDSBL_CONTACT, OFF.mjDSBL_LIMIT, OFF.mjDSBL_FRICTIONLOSS)
    tau_mj = _inverse(model, data, robot, ds.q, ds.dq, ds.ddq)
    want = tau_id - _coulomb(robot, theta, ds.dq)  # rigid bodies + armature + viscous
    err = np.linalg.norm(tau_mj - want, axis=0) / np.linalg.norm(want, axis=0)
    assert err.max() < 1e-6, err  # per joint
    # Coulomb: MuJoCo's friction loss, in steady sliding (qacc = 0) it is fc sign(dq)
    q, dq, ddq = robot.random_states(40, seed=3)
    coulomb = _coulomb(robot, theta, dq)
    zero = np.zeros_like(ddq)
    slide_off = _inverse(model, data, robot, q, dq, zero)
    model.opt.disableflags &= ~int(OFF.mjDSBL_FRICTIONLOSS)
    slide_on = _inverse(model, data, robot, q, dq, zero)
    np.testing.assert_allclose(slide_on - slide_off, coulomb, rtol=0, atol=1e-9)


@pytest.mark.parametrize(
    "spec", ["xarm7", "z1", "talos_arm", "kinova", "double_pendulum_continuous", "finger_edu"]
)
def test_other_manipulators_replay_too(tmp_path, spec):
    """Unaligned axes, continuous joints (cos, sin in Pinocchio, an angle in MuJoCo),
    fixed tool links, holders lighter than their nominal links (finger_edu)."""
    robot = get_robot(spec, armature=True, friction="viscous")
    theta = robot.nominal_parameters.copy()
    theta[robot.n_rigid :] = 0.1  # [kg m^2], [N m s/rad]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ExportWarning)  # finger_edu: a scaled share
        export_mjcf(robot, theta, tmp_path / "r.xml")
    q, dq, ddq = robot.random_states(10, seed=2)
    want = (regressor(robot, q, dq, ddq) @ theta).reshape(10, robot.nv)
    model, data = _load(tmp_path / "r.xml", OFF.mjDSBL_CONTACT, OFF.mjDSBL_LIMIT)
    got = _inverse(model, data, robot, q, dq, ddq)
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-9 * np.abs(want).max())


def test_the_spring_of_a_prismatic_joint_is_mujocos_stiffness(tmp_path):
    robot = load_robot("msd")  # prismatic, viscous, spring
    assert robot.terms.spring and robot.is_prismatic(0)
    theta = robot.nominal_parameters.copy()
    theta[robot.parameter_index(f"{robot.dof_names[0]}.k")] = 35.0  # [N/m]
    out = tmp_path / "msd.xml"
    export_mjcf(robot, theta, out)
    q, dq, ddq = robot.random_states(20, seed=1)
    tau_id = (regressor(robot, q, dq, ddq) @ theta).reshape(q.shape[0], robot.nv)
    model, data = _load(out, OFF.mjDSBL_CONTACT, OFF.mjDSBL_LIMIT, OFF.mjDSBL_FRICTIONLOSS)
    tau_mj = _inverse(model, data, robot, q, dq, ddq)
    want = tau_id - _coulomb(robot, theta, dq)
    np.testing.assert_allclose(tau_mj, want, rtol=0, atol=1e-9 * np.abs(want).max())


def test_every_export_loads_in_mujoco_and_refuses_what_it_must(tmp_path):
    robot = get_robot("panda", friction="viscous,coulomb")
    theta = _consistent_theta(robot)
    out = tmp_path / "panda.xml"
    result = export_mjcf(robot, theta, out)
    model = mujoco.MjModel.from_xml_path(str(out))
    assert model.nq == robot.full_model.nq and model.ngeom > 0 and model.nmesh > 0
    assert all(name.endswith(".dae") for name in result.skipped)  # COLLADA visuals left out
    # every panda visual is COLLADA: the collision shapes are shown instead (group 0)
    assert {int(g) for g in model.geom_group} == {0}
    names = [mujoco.mj_id2name(model, JOINT, j) for j in range(model.njnt)]
    assert names == [robot.full_model.names[i] for i in range(1, robot.full_model.njoints)]
    side = json.loads(sidecar_path(out).read_text())
    assert side["composites"]["panda_joint7"]["carried"][0] == "panda_hand"
    # one motor per identified joint: ctrl is the joint torque, within the effort limit
    assert model.nu == robot.nv
    data = mujoco.MjData(model)
    data.ctrl[:] = np.linspace(-100.0, 100.0, robot.nv)  # [N m]
    mujoco.mj_forward(model, data)
    dofs = [model.jnt_dofadr[mujoco.mj_name2id(model, JOINT, n)] for n in robot.dof_names]
    want = np.clip(data.ctrl, -robot.effort_limit, robot.effort_limit)
    np.testing.assert_allclose(data.qfrc_actuator[dofs], want, rtol=1e-12)
    with pytest.raises(InputError, match="exists"):
        export_mjcf(robot, theta, out)
    with pytest.raises(InputError, match=r"\.xml"):
        export_mjcf(robot, theta, tmp_path / "panda.urdf")
    bad = theta.copy()
    bad[robot.parameter_index("panda_joint2.m")] = -1.0
    with pytest.raises(PhysicalConsistencyError, match="panda_joint2"):
        export_mjcf(robot, bad, tmp_path / "bad.xml")
    assert not (tmp_path / "bad.xml").exists()


def rollout_deviation(xml, urdf, q0, *, seconds: float = 2.0, scale: float = 1.0) -> float:
    """Largest joint excursion [rad or m] of a MuJoCo rollout of ``xml`` from rest at ``q0``
    (every joint of the unreduced model, Pinocchio order) with the torque
    ``scale * g(q)`` of the Pinocchio model of ``urdf`` applied (gravity compensation);
    friction loss off, so that only the compensation holds the robot."""
    model, data = _load(xml, OFF.mjDSBL_FRICTIONLOSS)
    pmodel = pin.buildModelFromUrdf(str(urdf))
    pdata = pmodel.createData()
    ids = [mujoco.mj_name2id(model, JOINT, pmodel.names[i]) for i in range(1, pmodel.njoints)]
    qadr, vadr = model.jnt_qposadr[ids], model.jnt_dofadr[ids]
    data.qpos[qadr] = q0
    for _ in range(int(round(seconds / model.opt.timestep))):
        g = pin.computeGeneralizedGravity(pmodel, pdata, data.qpos[qadr])
        data.qfrc_applied[vadr] = scale * g
        mujoco.mj_step(model, data)
    return float(np.abs(data.qpos[qadr] - q0).max())


@pytest.mark.parametrize("spec", ["ur5", "panda"])
def test_cli_export_holds_still_in_mujoco_under_gravity_compensation(tmp_path, spec, capsys):
    """identify --consistent on a simulated robot, --export-urdf and --export-mjcf: a 2 s
    MuJoCo rollout from rest, the identified gravity compensating, stays within 1 mrad;
    the compensation 2 % off does not (the check can fail)."""
    urdf, xml = tmp_path / f"{spec}_id.urdf", tmp_path / f"{spec}_id.xml"
    argv = ["identify", spec, "--friction", "viscous,coulomb", "--simulate", "--duration", "5"]
    argv += ["--rate", "100", "--noise", "0.01", "--consistent"]
    assert main([*argv, "--export-urdf", str(urdf), "--export-mjcf", str(xml)]) == 0
    assert f"wrote {xml} and its sidecar" in capsys.readouterr().out
    side = json.loads(sidecar_path(xml).read_text())
    assert side["provenance"]["options"]["simulate"] is True
    assert len(side["provenance"]["uncertainty"]["base_parameters"]) > 0
    full = pin.buildModelFromUrdf(str(urdf))
    q0 = 0.5 * (full.lowerPositionLimit + full.upperPositionLimit)
    q0[: 6 if spec == "ur5" else 7] += 0.3  # away from the middle, gravity loading the joints
    assert rollout_deviation(xml, urdf, q0) < 1e-3
    assert rollout_deviation(xml, urdf, q0, scale=0.98) > 1e-3


@pytest.mark.slow
def test_the_real_panda_export_simulates_in_mujoco(tmp_path, panda_log, capsys):
    """The issue's done-when on the real log: the command of the issue, then the full model's
    aba finite, and a 2 s MuJoCo rollout from rest at the log's first configuration under
    the identified gravity compensation within 1 mrad."""
    urdf, xml = tmp_path / "panda_id.urdf", tmp_path / "panda_id.xml"
    argv = ["identify", "panda", "--data", str(panda_log), "--friction", "viscous,coulomb,offset"]
    argv += ["--split", "0.7", "--consistent", "--export-urdf", str(urdf)]
    assert main([*argv, "--export-mjcf", str(xml)]) == 0
    captured = capsys.readouterr()
    assert "panda_joint7 (kept share" in captured.err  # the log has no hand: a scaled share
    model = pin.buildModelFromUrdf(str(urdf))
    data = model.createData()
    rng = np.random.default_rng(0)
    for q in rng.uniform(model.lowerPositionLimit, model.upperPositionLimit, (50, model.nq)):
        assert np.isfinite(pin.aba(model, data, q, np.zeros(9), np.zeros(9))).all()
    robot = get_robot("panda", friction="viscous,coulomb,offset")
    q0 = robot.locked_configuration
    q0[:7] = load_dataset(panda_log).q[0]  # the log's first configuration [rad]
    assert rollout_deviation(xml, urdf, q0) < 1e-3
