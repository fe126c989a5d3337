"""The scene camera's distance (manip_id.viz.camera) against the pinhole formula."""

from __future__ import annotations

import numpy as np
import pytest

from manip_id.viz.camera import (
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


def test_the_motion_never_pushes_the_start_pose_below_min_fill():
    start = _rod(1.0)
    motion = np.vstack([start, [[0.0, 5.0, 0.0], [0.0, -5.0, 4.0]]])  # a wide sweep
    cam = place_camera(start, motion, direction=(1.0, 0.0, 0.0), fill=0.8, min_fill=0.65)
    assert cam.fill == pytest.approx(0.65, rel=1e-6)
    small = np.vstack([start, [[0.0, 0.0, 0.6]]])  # a motion inside the view
    assert place_camera(start, small, direction=(1.0, 0.0, 0.0)).fill == pytest.approx(0.8)


def test_min_fill_holds_for_the_height_of_a_wide_start_pose():
    # a start pose 4 times wider than tall: the height share, not the width's, keeps min_fill
    # (the pinhole: 0.5 m tall at distance D spans 0.5 / (2 D tan(fov / 2)))
    start = np.column_stack([np.zeros(11), np.linspace(-1, 1, 11), np.zeros(11)])
    start = np.vstack([start, [[0.0, 0.0, 0.25], [0.0, 0.0, -0.25]]])
    motion = np.vstack([start, [[0.0, 8.0, 0.0], [0.0, -8.0, 6.0]]])
    cam = place_camera(start, motion, direction=(1.0, 0.0, 0.0), fill=0.8, min_fill=0.25)
    assert cam.fill == pytest.approx(0.25, rel=1e-6)  # the width share is 0.83
    d = np.linalg.norm(cam.position)
    assert 0.5 / (2 * d * np.tan(np.radians(FOV) / 2)) == pytest.approx(0.25, rel=1e-6)
    # taller than min_fill would push the start pose out of the view: it stays within 0.98
    cam = place_camera(start, motion, direction=(1.0, 0.0, 0.0), fill=0.8, min_fill=0.6)
    assert max(cam.fill, cam.width_fill) == pytest.approx(0.98, rel=1e-6)


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
