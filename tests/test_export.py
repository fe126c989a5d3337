"""The identified model back out as a URDF: checked by Pinocchio alone, sidecar read back.

Reference: the exported file is loaded with ``pinocchio.buildModelFromUrdf`` (not
our loader); its ``rnea`` plus the joint friction of ``<dynamics>`` must equal
``Y @ theta``, and its inertias the identified blocks.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET

import numpy as np
import pinocchio as pin
import pytest
from conftest import get_robot

from manip_id import load_robot, regressor
from manip_id.cli import main
from manip_id.consistency import PhysicalConsistencyError
from manip_id.errors import InputError
from manip_id.export import export_urdf, sidecar_path


def _consistent_theta(robot, seed: int = 0) -> np.ndarray:
    """Nominal inertias moved a little (each body scaled, CoM shifted) and positive terms."""
    rng = np.random.default_rng(seed)
    theta = robot.nominal_parameters.copy()
    for k in range(robot.n_bodies):
        block = theta[10 * k : 10 * k + 10]
        s = 1.0 + 0.2 * rng.uniform()  # scaling keeps a body physical
        theta[10 * k : 10 * k + 10] = s * block
    theta[robot.n_rigid :] = rng.uniform(0.05, 0.5, robot.n_parameters - robot.n_rigid)
    return theta


def _full_configuration(robot, full: pin.Model, q_red: np.ndarray) -> np.ndarray:
    """A configuration of the exported (unreduced) model: active joints from q_red, the
    others at the robot's locked reference configuration."""
    ref = robot._qref if robot._qref is not None else pin.neutral(full)
    q = np.array(ref, dtype=float).copy() if len(ref) == full.nq else pin.neutral(full)
    for i in range(1, robot.model.njoints):
        name = robot.model.names[i]
        jr, jf = robot.model.joints[i], full.joints[full.getJointId(name)]
        q[jf.idx_q : jf.idx_q + jf.nq] = q_red[jr.idx_q : jr.idx_q + jr.nq]
    return q


@pytest.mark.parametrize(
    "spec, active",
    [
        ("ur5", None),  # no locked joint; fixed tool links
        ("panda", None),  # finger joints locked, hand on a fixed joint
        (
            "panda",
            [f"panda_joint{i}" for i in (1, 2, 3, 4, 6, 7)],
        ),  # a middle joint locked too
    ],
)
def test_exported_urdf_gives_the_identified_dynamics_in_pinocchio_alone(tmp_path, spec, active):
    robot = load_robot(spec, friction="viscous,coulomb", active_joints=active)
    theta = _consistent_theta(robot)
    out = tmp_path / "robot_id.urdf"
    result = export_urdf(robot, theta, out)
    assert result.urdf == out and sidecar_path(out).is_file()

    model = pin.buildModelFromUrdf(str(out))
    data = model.createData()
    blocks = robot.rigid_body_parameters(theta)
    for name, block in zip(robot.joint_names, blocks, strict=True):
        got = model.inertias[model.getJointId(name)].toDynamicParameters()
        np.testing.assert_allclose(got, block, rtol=0, atol=1e-9 * np.abs(block).max())

    q, dq, ddq = robot.random_states(20, seed=2)
    Y = regressor(robot, q, dq, ddq)
    tau_ref = Y @ theta
    for k in range(q.shape[0]):
        qf = _full_configuration(robot, model, q[k])
        vf, af = np.zeros(model.nv), np.zeros(model.nv)
        idx = []
        for i in range(1, robot.model.njoints):
            jf = model.joints[model.getJointId(robot.model.names[i])]
            jr = robot.model.joints[i]
            vf[jf.idx_v] = dq[k, jr.idx_v]
            af[jf.idx_v] = ddq[k, jr.idx_v]
            idx.append(jf.idx_v)
        tau = pin.rnea(model, data, qf, vf, af)[idx]
        tau += model.damping[idx] * dq[k] + model.friction[idx] * np.sign(dq[k])
        scale = np.abs(tau_ref[k]).max()
        np.testing.assert_allclose(tau, tau_ref[k], rtol=0, atol=1e-9 * scale)


def test_sidecar_reads_armature_and_offset_back(tmp_path):
    robot = load_robot("panda", friction="viscous,coulomb,offset", armature=True)
    theta = _consistent_theta(robot, seed=1)
    out = tmp_path / "panda_id.urdf"
    export_urdf(robot, theta, out)
    back = load_robot(out, identified=True)
    assert back.joint_names == robot.joint_names
    assert back.terms.enabled == robot.terms.enabled
    np.testing.assert_allclose(back.nominal_parameters, theta, rtol=1e-12, atol=1e-15)
    # an explicit sidecar path works too
    again = load_robot(out, identified=sidecar_path(out))
    np.testing.assert_allclose(again.nominal_parameters, theta, rtol=1e-12, atol=1e-15)


def test_everything_else_of_the_urdf_is_left_untouched(tmp_path):
    robot = get_robot("panda", friction="viscous,coulomb")
    out = tmp_path / "p.urdf"
    export_urdf(robot, _consistent_theta(robot), out)
    src, dst = ET.parse(robot.source).getroot(), ET.parse(out).getroot()
    for tag in ("visual", "collision", "limit", "axis", "mesh"):
        a = [ET.tostring(e) for e in src.iter(tag)]
        b = [ET.tostring(e) for e in dst.iter(tag)]
        assert a == b, tag
    assert [j.get("name") for j in src.iter("joint")] == [j.get("name") for j in dst.iter("joint")]


def test_export_refuses_non_physical_parameters_and_existing_files(tmp_path):
    robot = get_robot("panda", friction="viscous,coulomb")
    theta = _consistent_theta(robot)
    bad = theta.copy()
    bad[robot.parameter_index("panda_joint7.Izz")] = -0.011
    out = tmp_path / "p.urdf"
    with pytest.raises(PhysicalConsistencyError, match="panda_joint7"):
        export_urdf(robot, bad, out)
    assert not out.exists() and not sidecar_path(out).exists()
    export_urdf(robot, theta, out)
    with pytest.raises(InputError, match="exists"):
        export_urdf(robot, theta, out)
    export_urdf(robot, theta, out, force=True)
    with pytest.raises(InputError, match=r"\.urdf"):
        export_urdf(robot, theta, tmp_path / "p.xml")


def test_cli_consistent_export_and_bad_input(tmp_path, capsys):
    sim = ["--simulate", "--duration", "5", "--rate", "100", "--noise", "0.01"]
    base = ["identify", "ur5", "--friction", "viscous,coulomb", *sim]
    out = tmp_path / "ur5_id.urdf"
    assert main([*base, "--consistent", "--export-urdf", str(out)]) == 0
    captured = capsys.readouterr()
    assert "physically consistent yes" in captured.out
    model = pin.buildModelFromUrdf(str(out))
    assert model.nv == 6 and sidecar_path(out).is_file()
    cases = [
        ([*base, "--export-urdf", str(tmp_path / "a.urdf")], "needs a physically consistent"),
        ([*base, "--consistent", "--solver", "gurobi"], "solver must be one of"),
        ([*base, "--consistent", "--prior", "flat"], "prior must be one of"),
        ([*base, "--consistent", "--export-urdf", str(out)], "exists"),
    ]
    for argv, message in cases:
        assert main(argv) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and message in err[0], err
    assert main([*base, "--consistent", "--export-urdf", str(out), "--force"]) == 0


def test_report_draws_the_consistent_ellipsoids_beside_the_nominal_ones(tmp_path, capsys):
    rep = tmp_path / "rep"
    argv = ["identify", "ur5", "--friction", "viscous,coulomb", "--simulate", "--duration", "4"]
    assert main([*argv, "--rate", "100", "--consistent", "--report", str(rep)]) == 0
    capsys.readouterr()
    scene = (rep / "scene.html").read_text()
    assert "nominal: 6 of 6 bodies" in scene
    assert "identified (consistent): 6 of 6 bodies" in scene
