"""The identified model back out as a URDF: checked by Pinocchio alone, sidecar read back.

Reference: the exported file is loaded with ``pinocchio.buildModelFromUrdf`` (not
our loader); its ``rnea`` plus the joint friction of ``<dynamics>`` must equal
``Y @ theta``, and its inertias the identified blocks.
"""

from __future__ import annotations

import json
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest
from conftest import get_robot

from manip_id import load_robot, regressor
from manip_id.cli import main
from manip_id.errors import CarriedInertiaError, ExportWarning, InputError
from manip_id.export import export_urdf, sidecar_path
from manip_id.export.links import SHARE_MARGIN
from manip_id.physics.consistency import PhysicalConsistencyError, pseudo_inertia
from manip_id.robot.model import JointSelection


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


def _locked_again(robot, model: pin.Model) -> pin.Model:
    """The exported (unreduced) model with the identification's locked joints locked at the
    robot's locked configuration."""
    ids = [
        model.getJointId(model.names[i])
        for i in range(1, model.njoints)
        if model.names[i] not in robot.joint_names
    ]
    return pin.buildReducedModel(model, ids, robot.locked_configuration) if ids else model


CASES = [
    ("ur5", None),  # no locked joint; fixed tool links
    ("panda", None),  # finger joints locked, hand on a fixed joint
    ("panda", [f"panda_joint{i}" for i in (1, 2, 3, 4, 6, 7)]),  # a middle joint locked too
]


@pytest.mark.parametrize("spec, active", CASES)
def test_exported_urdf_gives_the_identified_dynamics_in_pinocchio_alone(tmp_path, spec, active):
    robot = load_robot(spec, friction="viscous,coulomb", active_joints=active)
    theta = _consistent_theta(robot)
    out = tmp_path / "robot_id.urdf"
    result = export_urdf(robot, theta, out)
    assert result.urdf == out and sidecar_path(out).is_file()

    model = _locked_again(robot, pin.buildModelFromUrdf(str(out)))
    assert [model.names[i] for i in range(1, model.njoints)] == robot.joint_names
    data = model.createData()
    blocks = robot.rigid_body_parameters(theta)
    for name, block in zip(robot.joint_names, blocks, strict=True):
        got = model.inertias[model.getJointId(name)].toDynamicParameters()
        np.testing.assert_allclose(got, block, rtol=0, atol=1e-9 * np.abs(block).max())

    q, dq, ddq = robot.random_states(20, seed=2)
    Y = regressor(robot, q, dq, ddq)
    tau_ref = (Y @ theta).reshape(q.shape[0], robot.nv)
    for k in range(q.shape[0]):
        tau = pin.rnea(model, data, q[k], dq[k], ddq[k])
        tau += model.damping * dq[k] + model.friction * np.sign(dq[k])
        scale = np.abs(tau_ref[k]).max()
        np.testing.assert_allclose(tau, tau_ref[k], rtol=0, atol=1e-9 * scale)


@pytest.mark.parametrize("spec, active", CASES)
def test_the_full_exported_model_simulates(tmp_path, spec, active):
    """No joint locked: every body physical, crba positive definite, aba finite."""
    robot = load_robot(spec, friction="viscous,coulomb", active_joints=active)
    out = tmp_path / "robot_id.urdf"
    result = export_urdf(robot, _consistent_theta(robot), out)
    model = pin.buildModelFromUrdf(str(out))
    data = model.createData()
    for i in range(1, model.njoints):  # every moving body: pseudo-inertia positive definite
        lam = np.linalg.eigvalsh(pseudo_inertia(model.inertias[i].toDynamicParameters()))
        assert lam[0] > 1e-10 * lam[-1], model.names[i]
        assert result.min_eigenvalues[model.names[i]] == pytest.approx(lam[0])  # self-check
    rng = np.random.default_rng(5)
    lo, hi = model.lowerPositionLimit, model.upperPositionLimit
    for _ in range(20):
        q = rng.uniform(lo, hi)
        v, tau = rng.uniform(-1, 1, model.nv), rng.uniform(-10, 10, model.nv)
        M = pin.crba(model, data, q)
        M = np.triu(M) + np.triu(M, 1).T
        assert np.linalg.eigvalsh(M)[0] > 0
        ddq = pin.aba(model, data, q, v, tau)
        assert np.isfinite(ddq).all()
        # aba inverts rnea: an independent check that the model is well posed
        np.testing.assert_allclose(pin.rnea(model, data, q, v, ddq), tau, atol=1e-8)


def test_the_panda_fingers_are_no_longer_massless_the_nan_case(tmp_path):
    """The issue's case: a consistent Panda export, aba at the neutral configuration."""
    robot = get_robot("panda", friction="viscous,coulomb")
    out = tmp_path / "panda_id.urdf"
    result = export_urdf(robot, _consistent_theta(robot), out)
    model = pin.buildModelFromUrdf(str(out))
    data = model.createData()
    assert model.nq == 9
    z = np.zeros(model.nv)
    assert np.isfinite(pin.aba(model, data, pin.neutral(model), z, z)).all()
    src = pin.buildModelFromUrdf(robot.source)
    for finger in ("panda_finger_joint1", "panda_finger_joint2"):
        i, k = model.getJointId(finger), src.getJointId(finger)  # nominal finger inertias kept
        np.testing.assert_allclose(
            model.inertias[i].toDynamicParameters(), src.inertias[k].toDynamicParameters()
        )
    (comp,) = [c for c in result.composites if c.carried]
    assert comp.joint == "panda_joint7" and comp.share == 1.0
    assert comp.carried == ["panda_hand", "panda_leftfinger", "panda_rightfinger"]


def test_meshes_load_from_where_the_export_is_written(tmp_path):
    robot = get_robot("panda", friction="viscous,coulomb")
    out = tmp_path / "deep" / "panda_id.urdf"
    result = export_urdf(robot, _consistent_theta(robot), out)
    assert result.unresolved == []
    names = [m.get("filename") for m in ET.parse(out).getroot().iter("mesh")]
    assert names and all(Path(n).is_absolute() and Path(n).is_file() for n in names)
    wrapper = pin.RobotWrapper.BuildFromURDF(str(out))  # no package_dirs
    assert len(wrapper.visual_model.geometryObjects) == len(
        ET.parse(robot.source).getroot().findall("link/visual")
    )
    kept = export_urdf(robot, _consistent_theta(robot), tmp_path / "k.urdf", meshes="keep")
    assert kept.unresolved == []
    assert all(
        m.get("filename").startswith("package://")
        for m in ET.parse(tmp_path / "k.urdf").getroot().iter("mesh")
    )


def _heavy_hand(robot) -> np.ndarray:
    """A consistent theta whose last body is lighter than the nominal hand it carries."""
    theta = _consistent_theta(robot)
    k = robot.joint_names.index("panda_joint7")
    theta[10 * k : 10 * k + 10] *= 0.3
    return theta


def test_a_body_too_light_for_its_nominal_links_is_named_or_scaled(tmp_path):
    robot = get_robot("panda", friction="viscous,coulomb")
    theta = _heavy_hand(robot)
    with pytest.raises(CarriedInertiaError, match="panda_joint7.*panda_hand") as info:
        export_urdf(robot, theta, tmp_path / "a.urdf", carried="nominal")
    assert list(info.value.bodies) == ["panda_joint7"]
    assert not (tmp_path / "a.urdf").exists()
    with pytest.warns(ExportWarning, match="panda_joint7"):
        result = export_urdf(robot, theta, tmp_path / "b.urdf")
    (comp,) = [c for c in result.composites if c.carried]
    assert 0 < comp.share < 1
    model = pin.buildModelFromUrdf(str(tmp_path / "b.urdf"))
    for i in range(1, model.njoints):
        lam = np.linalg.eigvalsh(pseudo_inertia(model.inertias[i].toDynamicParameters()))
        assert lam[0] > 0, model.names[i]
    reduced = _locked_again(robot, model)  # the composite is still the identified one
    block = theta[10 * 6 : 10 * 7]
    got = reduced.inertias[reduced.getJointId("panda_joint7")].toDynamicParameters()
    np.testing.assert_allclose(got, block, rtol=0, atol=1e-9 * np.abs(block).max())
    side = json.loads(sidecar_path(tmp_path / "b.urdf").read_text())
    assert side["composites"]["panda_joint7"]["share"] == pytest.approx(comp.share)
    # the share is SHARE_MARGIN of the one that makes the holder singular
    J = pseudo_inertia(block)
    Jc = pseudo_inertia(comp.carried_parameters.sum(axis=0))
    at_limit = np.linalg.eigvalsh(J - (comp.share / SHARE_MARGIN) * Jc)
    assert abs(at_limit[0]) < 1e-9 * np.abs(at_limit).max()
    assert np.linalg.eigvalsh(J - comp.share * Jc)[0] > 0
    with pytest.raises(InputError, match="carried must be one of"):
        export_urdf(robot, theta, tmp_path / "c.urdf", carried="all")


def test_cli_export_mjcf_checks_before_the_work(tmp_path, capsys):
    base = ["identify", "ur5", "--friction", "viscous", "--simulate", "--duration", "2"]
    base += ["--rate", "50"]
    (tmp_path / "there.xml").write_text("mine")
    cases = [
        ([*base, "--export-mjcf", str(tmp_path / "a.xml")], "needs a physically consistent"),
        ([*base, "--consistent", "--export-mjcf", str(tmp_path / "a.urdf")], ".xml file"),
        ([*base, "--consistent", "--export-mjcf", str(tmp_path / "there.xml")], "exists"),
        (
            [*base, "--consistent", "--export-mjcf", str(tmp_path / "no" / "a.xml")],
            "does not exist",
        ),
    ]
    for argv, message in cases:
        assert main(argv) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and message in err[0], err
    assert (tmp_path / "there.xml").read_text() == "mine"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["there.xml"]


def test_sidecar_reads_armature_and_offset_back(tmp_path):
    opened = {"panda_finger_joint1": 0.03, "panda_finger_joint2": 0.03}  # [m], not the default
    robot = load_robot(
        "panda",
        friction="viscous,coulomb,offset",
        armature=True,
        active_joints=JointSelection(locked_configuration=opened),
    )
    theta = _consistent_theta(robot, seed=1)
    out = tmp_path / "panda_id.urdf"
    export_urdf(robot, theta, out)
    back = load_robot(out, identified=True)  # the fingers locked where they were
    assert back.joint_names == robot.joint_names
    np.testing.assert_array_equal(back.locked_configuration, robot.locked_configuration)
    assert back.terms.enabled == robot.terms.enabled
    np.testing.assert_allclose(back.nominal_parameters, theta, rtol=1e-12, atol=1e-15)
    # an explicit sidecar path works too
    again = load_robot(out, identified=sidecar_path(out))
    np.testing.assert_allclose(again.nominal_parameters, theta, rtol=1e-12, atol=1e-15)


def test_everything_else_of_the_urdf_is_left_untouched(tmp_path):
    robot = get_robot("panda", friction="viscous,coulomb")
    out = tmp_path / "p.urdf"
    result = export_urdf(robot, _consistent_theta(robot), out, meshes="keep")
    src, dst = ET.parse(robot.source).getroot(), ET.parse(out).getroot()
    holders = {c.holder for c in result.composites}
    for a, b in zip(src.findall("link"), dst.findall("link"), strict=True):
        if a.get("name") not in holders:  # carried and other links: their own inertial
            assert ET.tostring(a) == ET.tostring(b), a.get("name")
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
    assert "; physically consistent" in captured.out  # the answer's estimate line
    assert "NOT physically consistent" not in captured.out
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


_TWO_LINKS = """<robot name="two">
  <link name="base"/>
  <link name="l1"><inertial><origin xyz="0.1 0 0"/><mass value="2"/>
    <inertia ixx="0.01" iyy="0.02" izz="0.02" ixy="0" ixz="0" iyz="0"/></inertial></link>
  <link name="tip"/>
  <joint name="j1" type="revolute"><parent link="base"/><child link="l1"/>
    <axis xyz="0 0 1"/><limit lower="-2" upper="2" effort="10" velocity="2"/></joint>
  <joint name="j2" type="revolute"><parent link="l1"/><child link="tip"/>
    <origin xyz="0.2 0 0"/><axis xyz="0 0 1"/>
    <limit lower="-2" upper="2" effort="10" velocity="2"/></joint>
</robot>
"""


def test_a_locked_link_without_inertia_is_named(tmp_path):
    """The unreduced model cannot simulate when a locked joint carries nothing: the export
    (of a correct identified model) says which body."""
    src = tmp_path / "two.urdf"
    src.write_text(_TWO_LINKS)
    robot = load_robot(src, active_joints=["j1"])
    with pytest.warns(ExportWarning, match="bodies of j2"):
        result = export_urdf(robot, robot.nominal_parameters, tmp_path / "two_id.urdf")
    assert result.min_eigenvalues["j1"] > 0 and result.min_eigenvalues["j2"] == 0
