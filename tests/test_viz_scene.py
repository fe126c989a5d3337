"""The scene's mathematics against Pinocchio's own inertias, and its bad-input errors."""

from __future__ import annotations

import re

import numpy as np
import pinocchio as pin
import pytest
import umsgpack
from conftest import get_robot

from manip_id import InfeasibleTrajectoryError, InputError
from manip_id.viz import RobotScene, equivalent_ellipsoid, link_identifiability


@pytest.mark.parametrize("seed", range(5))
def test_ellipsoid_of_a_solid_ellipsoid_is_itself(seed):
    rng = np.random.default_rng(seed)
    mass = rng.uniform(0.5, 5.0)
    semi = np.sort(rng.uniform(0.02, 0.3, 3))
    placement = pin.SE3(pin.exp3(rng.normal(size=3)), rng.uniform(-0.2, 0.2, 3))
    # Pinocchio's solid ellipsoid (semi-axes along x, y, z), moved to a pose in the joint frame
    body = placement.act(pin.Inertia.FromEllipsoid(mass, *semi))
    ell = equivalent_ellipsoid(body.toDynamicParameters(), joint="j")
    assert ell.physical, ell.note
    assert ell.mass == pytest.approx(mass)
    np.testing.assert_allclose(ell.com, placement.translation, atol=1e-12)
    np.testing.assert_allclose(np.sort(ell.semi_axes), semi, rtol=1e-9)
    # the principal axes are the rotated x, y, z (up to sign and order)
    R = placement.rotation
    for k in range(3):
        cos = np.abs(R.T @ ell.axes[:, k])
        assert cos.max() == pytest.approx(1.0, abs=1e-8)
    # placement maps the ellipsoid frame into the joint frame
    np.testing.assert_allclose(ell.placement[:3, 3], placement.translation, atol=1e-12)


def test_non_physical_blocks_are_flagged_not_raised():
    good = pin.Inertia.FromEllipsoid(1.0, 0.1, 0.2, 0.3).toDynamicParameters()
    negative_mass = good.copy()
    negative_mass[0] = -1.0
    assert not equivalent_ellipsoid(negative_mass, "a").physical
    triangle = good.copy()
    triangle[4] = 10.0  # Ixx far larger than Iyy + Izz
    ell = equivalent_ellipsoid(triangle, "b")
    assert not ell.physical and "b" in ell.note
    with pytest.raises(InputError, match="10 parameters"):
        equivalent_ellipsoid(good[:9])


def test_link_identifiability_counts_per_link():
    robot = get_robot("ur5")
    flags = np.zeros(robot.n_parameters, bool)
    flags[:10] = True  # every parameter of the first body
    flags[10:15] = True  # half of the second
    ident = link_identifiability(robot, identifiable=flags)
    np.testing.assert_allclose(ident.share, [1.0, 0.5, 0, 0, 0, 0])
    rel = np.full(robot.n_parameters, 0.05)
    rel[0] = np.inf
    both = link_identifiability(robot, identifiable=flags, relative_std=rel, threshold=0.1)
    np.testing.assert_allclose(both.determined[:2], [9, 5])
    with pytest.raises(InputError, match="booleans"):
        link_identifiability(robot, identifiable=flags[:5])


def test_scene_rejects_trajectories_that_do_not_fit():
    robot = get_robot("ur5")
    t = np.linspace(0, 1, 5)
    with pytest.raises(InputError, match=r"robot.nq=6"):
        RobotScene(robot).animate(t, np.zeros((5, 5)))
    q = np.zeros((5, 6))
    q[2, 1] = 100.0
    with pytest.raises(InfeasibleTrajectoryError):
        RobotScene(robot).animate(t, q)
    with pytest.raises(InputError):
        RobotScene(robot).animate(t[::-1], np.zeros((5, 6)))


def test_grouped_terms_note_only_for_a_set_estimated_from_data():
    """The Panda's nominal link 1 is a rod 1.68 m long (its URDF's inertia): drawn as a
    given set ("true") the note says so; only a set estimated from data adds that the
    data fix only grouped terms."""
    panda = get_robot("panda")
    scene = RobotScene(panda)
    given = scene.add_inertia(panda.nominal_parameters, label="true")
    estimate = scene.add_inertia(panda.nominal_parameters, label="estimate", estimated=True)
    rods = [n for n in given if "panda_link1's ellipsoid is a rod" in n]  # named by its link
    assert len(rods) == 1 and "grouped terms" not in rods[0]
    assert not any("grouped terms" in n for n in given)
    assert any("panda_link1" in n and "rod" in n and "grouped terms" in n for n in estimate)


def test_ellipsoids_are_translucent_off_at_first_and_their_notes_folded():
    """Every parameter set starts hidden (its check box unticked) unless asked, is drawn
    translucent, and its notes sit in a closed <details> of the legend, one short line
    per body named by its link."""
    panda = get_robot("panda")
    scene = RobotScene(panda)
    scene.add_inertia(panda.nominal_parameters, label="nominal")
    scene.add_inertia(panda.nominal_parameters, label="identified", estimated=True)
    scene.add_inertia(panda.nominal_parameters, label="shown", visible=True)
    commands = [umsgpack.unpackb(c) for c in scene.commands()]
    visible = {
        c["path"]: c["value"]
        for c in commands
        if c["type"] == "set_property" and c["property"] == "visible" and "inertia" in c["path"]
    }
    assert visible == {
        "/meshcat/inertia/nominal": False,
        "/meshcat/inertia/identified": False,
        "/meshcat/inertia/shown": True,
    }
    materials = [
        c["object"]["materials"][0]
        for c in commands
        if c["type"] == "set_object" and "/inertia/" in c["path"]
    ]
    assert len(materials) == 3 * panda.n_bodies
    assert all(m["transparent"] and m["opacity"] <= 0.6 for m in materials)
    legend = scene.html().split('<aside id="legend">')[1].split("</aside>")[0]
    assert legend.count('type="checkbox" checked') == 1  # only "shown"
    folded = re.findall(r"<details><summary>(\d+) notes?</summary>(.*?)</details>", legend)
    assert [int(n) for n, _ in folded] == [3, 4, 3]  # rod, 2 discs (+ the grouped terms)
    lines = folded[0][1].split("<br>")
    assert "panda_link1: a rod, 1.68 m across" in lines[0]
    assert all(len(re.sub("<[^>]+>", "", line)) < 50 for line in lines)
    assert "panda_joint" not in legend.split("inertia ellipsoids")[1]
