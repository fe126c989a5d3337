"""repair_nominal and ``manip-id repair`` on a URDF with non-physical bodies made by hand."""

from __future__ import annotations

import json
import xml.etree.ElementTree as ET

import numpy as np
import pytest
from conftest import get_robot

from manip_id.cli import main
from manip_id.physics.consistency import check_consistency
from manip_id.physics.repair import LENGTH_MIN, repair_body, repair_nominal
from manip_id.robot.model import load_robot

#: link -> (element, attribute, value): three ways of being non-physical
BREAKS = {
    "shoulder_link": ("inertial/inertia", "ixx", "-0.01"),  # a negative moment
    "forearm_link": ("inertial/inertia", "izz", "0.2"),  # I1 + I2 < I3
    "wrist_2_link": ("inertial/mass", "value", "-1.219"),  # a negative mass
}
BROKEN = {"shoulder_pan_joint", "elbow_joint", "wrist_2_joint"}  # their joints


@pytest.fixture(scope="module")
def broken_urdf(tmp_path_factory):
    src = get_robot("ur5").source
    tree = ET.parse(src)
    links = {lk.get("name"): lk for lk in tree.getroot().findall("link")}
    for link, (path, attr, value) in BREAKS.items():
        links[link].find(path).set(attr, value)
    out = tmp_path_factory.mktemp("urdf") / "ur5_broken.urdf"
    tree.write(out)
    return out


def _pseudo_inertia(block) -> np.ndarray:
    """J = [[0.5 tr(I) 1 - I, h], [h^T, m]] of [m, h, Ixx, Ixy, Iyy, Ixz, Iyz, Izz]."""
    m, hx, hy, hz, ixx, ixy, iyy, ixz, iyz, izz = block
    inertia = np.array([[ixx, ixy, ixz], [ixy, iyy, iyz], [ixz, iyz, izz]])
    J = np.zeros((4, 4))
    J[:3, :3] = 0.5 * np.trace(inertia) * np.eye(3) - inertia
    J[:3, 3] = J[3, :3] = [hx, hy, hz]
    J[3, 3] = m
    return J


def test_repair_nominal(broken_urdf):
    robot = load_robot(broken_urdf)
    before = robot.rigid_body_parameters(robot.nominal_parameters)
    assert {v.name for v in check_consistency(robot, robot.nominal_parameters).violations} == (
        BROKEN
    )
    result = repair_nominal(robot)
    assert result.consistency.consistent
    after = robot.rigid_body_parameters(result.theta)
    assert {b.body for b in result.bodies} == BROKEN
    for name, b0, b1 in zip(robot.joint_names, before, after, strict=True):
        assert np.linalg.eigvalsh(_pseudo_inertia(b1))[0] > 0
        if name not in BROKEN:
            np.testing.assert_allclose(b1, b0, rtol=1e-12, atol=0)  # untouched
        else:  # mass (its size) and centre of mass kept
            assert b1[0] == abs(b0[0])
            np.testing.assert_allclose(b1[1:4] / b1[0], b0[1:4] / abs(b0[0]), rtol=1e-12)
    # the forearm: moments I = (a, a, 0.2) about its CoM, a = 0.049443313556; second
    # moments S_x = S_y = (a + 0.2 - a) / 2 = 0.1 and S_z = (2a - 0.2) / 2 < 0, raised to
    # the floor 1e-3 max(S) = 1e-4; so I_x = I_y = S_y + S_z = 0.1001, I_z = 0.2
    fore = next(b for b in result.bodies if b.body == "elbow_joint")
    np.testing.assert_allclose(fore.moments_after, [0.1001, 0.1001, 0.2], rtol=1e-9)
    table = result.table()
    assert "triangle inequality" in table and "-1.219 -> 1.219" in table
    assert "passes the eigenvalue test" in table


def test_repair_body_keeps_a_physical_body_and_floors_a_flat_one():
    rod = np.array([2.0, 0.2, 0, 0, 0.1, 0, 0.1, 0, 0, 0.0])  # a thin rod along z: Izz = 0
    fixed = repair_body(rod)
    assert np.linalg.eigvalsh(_pseudo_inertia(fixed))[0] > 0
    h = fixed[1:4]  # second moments about the CoM: Sigma_o - h h^T / m (m = 2)
    sigma = np.linalg.eigvalsh(_pseudo_inertia(fixed)[:3, :3] - np.outer(h, h) / 2.0)
    assert sigma.min() >= 2.0 * LENGTH_MIN**2 * (1 - 1e-9)


def test_cli_repair_then_simulate(broken_urdf, tmp_path, capsys):
    out = tmp_path / "ur5_fixed.urdf"
    assert main(["identify", str(broken_urdf), "--simulate"]) == 2
    err = capsys.readouterr().err
    assert "bodies shoulder_pan_joint, elbow_joint, wrist_2_joint" in err
    assert "manip-id repair" in err
    report = tmp_path / "repair.json"
    assert main(["repair", str(broken_urdf), str(out), "--json", str(report)]) == 0
    assert "wrote" in capsys.readouterr().out
    assert main(["repair", str(broken_urdf), str(out)]) == 2  # exists: --force
    capsys.readouterr()
    doc = json.loads(report.read_text())["repair"]
    assert {b["body"] for b in doc["bodies"]} == BROKEN and doc["consistency"]["consistent"]
    fixed, orig = load_robot(out), load_robot(broken_urdf)
    assert check_consistency(fixed, fixed.nominal_parameters).consistent
    b0 = orig.rigid_body_parameters(orig.nominal_parameters)
    b1 = fixed.rigid_body_parameters(fixed.nominal_parameters)
    for i, name in enumerate(orig.joint_names):
        if name not in BROKEN:
            np.testing.assert_allclose(b1[i], b0[i], rtol=1e-12, atol=1e-15)
    res = tmp_path / "sim.json"
    args = ["identify", str(out), "--simulate", "--noise", "0", "--json", str(res)]
    assert main(args) == 0
    sim = json.loads(res.read_text())
    est = np.array([p["value"] for p in sim["base_parameters"]])
    true = np.array(sim["true_base_parameters"])
    np.testing.assert_allclose(est, true, rtol=1e-6, atol=1e-8 * np.abs(true).max())


def test_view_needs_no_inertias(broken_urdf, tmp_path):
    html = tmp_path / "v.html"
    assert main(["view", str(broken_urdf), "--simulate", "--html", str(html)]) == 0
    assert html.stat().st_size > 0
