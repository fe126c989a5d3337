"""The scene camera's distance (manip_id.viz.camera) against the pinhole formula."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest
from conftest import get_robot

from manip_id.viz import RobotScene
from manip_id.viz.camera import (
    ASPECT,
    DIRECTION,
    FOV,
    image_coordinates,
    image_extent,
    place_camera,
    view_direction,
)


def _rod(h: float) -> np.ndarray:
    """A vertical rod of height ``h`` [m] through the origin, as points."""
    return np.column_stack([np.zeros(11), np.zeros(11), np.linspace(-h / 2, h / 2, 11)])


@pytest.mark.parametrize("h, fill", [(1.0, 0.8), (0.2, 0.7), (3.0, 0.62)])
def test_a_vertical_rod_seen_side_on(h, fill):
    # seen along x, the rod's ends are at +-h/2 over a distance D: fill = h / (2 D tan(fov/2))
    cam = place_camera(_rod(h), direction=(1.0, 0.0, 0.0), fill=fill)
    want = h / (2 * fill * np.tan(np.radians(FOV) / 2))
    assert np.linalg.norm(cam.position) == pytest.approx(want, rel=1e-6)
    assert cam.fill == pytest.approx(fill, rel=1e-6)


def _pinhole(points, position, fov=FOV, aspect=ASPECT):
    """Normalized image coordinates (y up, x right) of world ``points`` for a camera at
    ``position`` looking at the origin, z up: three.js's perspective camera."""
    p = np.asarray(position, dtype=float)
    forward = -p / np.linalg.norm(p)
    right = np.cross(forward, [0.0, 0.0, 1.0])
    right /= np.linalg.norm(right)
    up = np.cross(right, forward)
    rel = np.asarray(points) - p
    depth = rel @ forward
    t = np.tan(np.radians(fov) / 2)
    return rel @ up / (depth * t), rel @ right / (depth * t * aspect)


@pytest.mark.parametrize("name", ["ur5", "panda"])
def test_an_animated_scene_frames_every_pose_of_its_motion(name):
    """The camera frames the swept volume, not the start pose: the joint origins of every
    frame (Pinocchio's forward kinematics, through the pinhole above) stay inside the view,
    and over the motion they span a good part of it, more than the start pose alone."""
    robot = get_robot(name)
    lo, hi = robot.sampling_bounds()
    t = np.linspace(0.0, 4.0, 81)
    q = 0.5 * (lo + hi) + 0.3 * (hi - lo) * np.sin(2 * np.pi * t / 4.0)[:, None]
    scene = RobotScene(robot).animate(t, q)
    data = robot.model.createData()
    ys, xs = [], []
    for qk in q:
        pin.forwardKinematics(robot.model, data, qk)
        origins = np.array([data.oMi[i].translation for i in range(robot.model.njoints)])
        y, x = _pinhole(origins - scene.view_center, scene.camera.position)
        ys.append(y)
        xs.append(x)
    y, x = np.concatenate(ys), np.concatenate(xs)
    assert np.abs(y).max() < 0.95 and np.abs(x).max() < 0.95  # every frame in view
    assert max(np.ptp(y), np.ptp(x)) / 2 > 0.5  # and the motion fills the view
    assert np.ptp(ys[0]) < np.ptp(y)  # the start pose alone spans less


def test_the_target_centres_a_pose_stretched_towards_the_camera():
    # a rod along the viewing direction: its near end is drawn larger (perspective), so
    # the box's centre is not the image's; the target puts the image in the middle
    d = np.array([1.0, 0.7, 0.45]) / np.linalg.norm([1.0, 0.7, 0.45])
    rod = np.outer(np.linspace(-0.5, 0.5, 21), [1.0, 0.0, 0.0])
    pose = np.vstack([rod, [[0.5, 0.0, 0.3]]])  # [m]
    cam = place_camera(pose, direction=d)
    y, x = image_coordinates(pose - cam.target, cam.position)
    assert abs(y.max() + y.min()) / 2 < 2e-3 and abs(x.max() + x.min()) / 2 < 2e-3
    assert max(cam.fill, cam.width_fill) == pytest.approx(0.8, rel=1e-6)
    assert np.linalg.norm(cam.target) > 0.01  # the box's centre alone is off-centre


def test_points_behind_the_camera_have_no_extent():
    assert image_extent(_rod(1.0), (0.0, 0.0, 0.2)) == (np.inf, np.inf)


def _box_area(points, d) -> float:
    """Orthographic bounding-box area [m^2] of ``points`` seen along ``d`` (z up)."""
    d = np.asarray(d, dtype=float) / np.linalg.norm(d)
    r = np.cross(-d, [0.0, 0.0, 1.0])
    r /= np.linalg.norm(r)
    u = np.cross(r, -d)
    return float(np.ptp(points @ r) * np.ptp(points @ u))


def test_view_direction_shows_an_arm_along_the_line_of_sight_from_its_side():
    d0 = np.asarray(DIRECTION) / np.linalg.norm(DIRECTION)
    along = np.array([d0[0], d0[1], 0.0]) / np.hypot(d0[0], d0[1])
    arm = np.outer(np.linspace(-0.5, 0.5, 21), along) + [0.0, 0.0, 0.05]  # a 1 m rod [m]
    arm = np.vstack([arm, arm - [0.0, 0.0, 0.1]])
    d = view_direction(arm)
    assert np.isclose(np.linalg.norm(d), 1.0) and np.isclose(d[2], d0[2])  # same elevation
    assert abs(np.dot(d[:2], along[:2])) / np.hypot(*d[:2]) < 0.7  # over 45 deg from end-on
    assert _box_area(arm, d) > 3.0 * _box_area(arm, d0)


def test_view_direction_keeps_the_default_for_a_robot_alike_from_every_side():
    rng = np.random.default_rng(0)
    x = rng.standard_normal((400, 3))
    ball = x / np.linalg.norm(x, axis=1, keepdims=True)  # a unit sphere's points [m]
    ball[:, 2] *= 2.0  # tall
    d = view_direction(ball)
    d0 = np.asarray(DIRECTION) / np.linalg.norm(DIRECTION)
    assert np.degrees(np.arccos(np.clip(np.dot(d, d0), -1, 1))) < 16.0  # the nearest azimuth
