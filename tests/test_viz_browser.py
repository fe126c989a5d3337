"""The exported meshcat page in a real browser: headless Chromium renders it offline.

Checks: the page renders the robot (pixels where it stands differ from the
same scene without the robot) and two times of the animation (opened paused
with ``#t=<seconds>``) give different pictures. ``make test`` installs the
Debian package ``chromium`` when missing; without it these tests skip.
"""

from __future__ import annotations

import shutil
import subprocess

import numpy as np
import pytest
from matplotlib.image import imread

from manip_id.robot.model import load_robot
from manip_id.viz import RobotScene

WIDTH, HEIGHT = 640, 480
CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")
pytestmark = [
    pytest.mark.skipif(
        CHROMIUM is None,
        reason="headless Chromium not found (Debian package 'chromium'; "
        "'make system-deps' installs it)",
    ),
    pytest.mark.slow,
]


def screenshot(html, png, tmp_path, hash_: str = "", size=(WIDTH, HEIGHT)) -> np.ndarray:
    """Render ``html`` in headless Chromium (software WebGL) in a window of ``size``
    (width, height) [px] and return the RGB image."""
    cmd = [
        CHROMIUM,
        "--headless",
        "--no-sandbox",
        "--use-gl=swiftshader",
        "--enable-unsafe-swiftshader",
        "--disable-background-networking",
        "--no-first-run",
        "--hide-scrollbars",
        f"--user-data-dir={tmp_path / 'chromium-profile'}",
        f"--window-size={size[0]},{size[1]}",
        f"--screenshot={png}",
        "--virtual-time-budget=4000",
        html.resolve().as_uri() + hash_,
    ]
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=180)
    assert proc.returncode == 0 and png.is_file(), proc.stderr[-2000:]
    img = imread(png)
    assert img.shape[:2] == (size[1], size[0])
    return img[..., :3]


def _changed(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Pixels whose color differs by more than 0.08 in some channel, shape (H, W)."""
    return np.abs(a - b).max(axis=2) > 0.08


def swing(robot, amplitude: float, n: int = 121, period: float = 4.0):
    """Every joint swinging around the middle of its range by ``amplitude`` of it, (n, nq)."""
    lo, hi = robot.sampling_bounds()
    t = np.linspace(0.0, period, n)
    s = np.sin(2 * np.pi * t / period)[:, None]
    return t, 0.5 * (lo + hi) + amplitude * (hi - lo) * s


# the camera frames the whole motion: the 20 cm cart of "msd" swings over 4 m of rail,
# so it moves by 5 % of the range to stay large enough on screen
@pytest.mark.parametrize(("name", "amplitude"), [("panda", 0.35), ("msd", 0.05)])
def test_robot_is_drawn_and_moves(name, amplitude, tmp_path):
    robot = load_robot(name)
    t, q = swing(robot, amplitude)
    scene = RobotScene(robot).animate(t, q)
    empty = RobotScene(robot, show_robot=False).animate(t, q)  # same camera, no meshes
    page, page_empty = tmp_path / "scene.html", tmp_path / "empty.html"
    scene.write_html(page)
    empty.write_html(page_empty)

    background = screenshot(page_empty, tmp_path / "empty.png", tmp_path, "#t=0")
    start = screenshot(page, tmp_path / "t0.png", tmp_path, "#t=0")
    quarter = screenshot(page, tmp_path / "t1.png", tmp_path, "#t=1")  # q at its extreme

    robot_px = _changed(start, background)
    share = robot_px.mean()
    assert share > 0.005, f"only {share:.4f} of the pixels show the robot"
    rows, cols = np.nonzero(robot_px)
    # the camera aims at the middle of the motion: the robot stands around the image centre
    assert abs(rows.mean() / HEIGHT - 0.5) < 0.25 and abs(cols.mean() / WIDTH - 0.5) < 0.25
    moved = _changed(start, quarter)
    assert moved.mean() > 0.002, f"frames at t=0 s and t=1 s differ in {moved.mean():.4f}"
    # what changed between the frames is robot, not background noise
    moved_robot = (moved & (robot_px | _changed(quarter, background))).sum()
    assert moved_robot / moved.sum() > 0.95


#: The default view of a scene page (a laptop browser window) [px].
VIEW = (1400, 900)


def frames_in_view(page, tmp_path, times, size=VIEW) -> dict:
    """Photograph ``page`` at each of ``times`` [s] and once with the robot hidden (the
    same camera; the background); from the pixels that differ, per frame and over all:
    whether the robot stays inside the canvas and right of the legend panel (found by its
    background colour #f6f6f4), and the share of the canvas the motion spans."""
    text = page.read_text()
    empty = tmp_path / "empty.html"
    hide = '<script>viewer.set_property(["meshcat", "robot"], "visible", false);</script>'
    empty.write_text(text.replace("</body>", hide + "</body>"))
    background = screenshot(empty, tmp_path / "empty.png", tmp_path, "#t=0", size=size)
    panel = np.abs(background - np.array([0xF6, 0xF6, 0xF4]) / 255.0).max(axis=2) < 0.01
    legend_right = int(np.nonzero(panel.mean(axis=0) > 0.5)[0].max())
    union = np.zeros(background.shape[:2], dtype=bool)
    inside = []
    for k, t in enumerate(times):
        shot = screenshot(page, tmp_path / f"t{k}.png", tmp_path, f"#t={t:g}", size=size)
        robot = _changed(shot, background)
        rows, cols = np.nonzero(robot)
        assert rows.size > 0.002 * robot.size, f"no robot drawn at t={t}"
        inside.append(
            bool(rows.min() > 0 and rows.max() < size[1] - 1)
            and bool(cols.min() > legend_right and cols.max() < size[0] - 1)
        )
        union |= robot
    rows, cols = np.nonzero(union)
    return {
        "inside": inside,
        "height": (rows.max() - rows.min() + 1) / size[1],
        "width": (cols.max() - cols.min() + 1) / (size[0] - 1 - legend_right),
    }


@pytest.mark.parametrize("name", ["panda", "ur5"])
def test_the_whole_motion_fills_the_default_view_beside_the_legend(name, tmp_path):
    """At 1400 x 900 px the camera frames the robot's swept volume: in every photographed
    frame of the motion the robot lies inside the canvas, right of the legend (a side
    panel, whatever the title's length), and over the frames it spans >= 70 % of the
    canvas's height or of its width beside the legend."""
    robot = load_robot(name)
    t, q = swing(robot, 0.1)  # 4 s: 1 s and 3 s are the swing's extremes
    scene = RobotScene(robot, title=f"{name}: a long title " * 4).animate(t, q)
    page = tmp_path / "scene.html"
    scene.write_html(page)
    fig = frames_in_view(page, tmp_path, (0, 1, 2.5, 3))
    assert all(fig["inside"]), fig
    assert max(fig["height"], fig["width"]) >= 0.7, fig
