"""Each report kind's scene in headless Chromium: the robot frames the view beside the legend.

The scene of each report (identify --consistent, payload, adapt) is rendered at the size
it has in the report page (the iframe: about 1170 x 600 px), once as written and once with
the robot hidden (the same camera, ellipsoids kept); the pixels that differ are the robot's.
From them: the robot's bounding box spans >= 60 % of the canvas height (or, for a robot
wider than tall, of the canvas width beside the legend), and the legend's
box (the panel's own background colour, measured from the pixels) does not overlap it, and
no edge of the canvas cuts it.
"""

from __future__ import annotations

import numpy as np
import pytest
from conftest import get_robot
from test_cli_payload import _save
from test_payload import make_payload, make_runs
from test_viz_browser import CHROMIUM, screenshot

from manip_id.cli import main

pytestmark = [
    pytest.mark.skipif(CHROMIUM is None, reason="headless Chromium not found"),
    pytest.mark.slow,
]
#: The scene's size in a report page (index.html's iframe) [px].
SIZE = (1170, 600)
#: The legend panel's background (scene_page's CSS #f6f6f4).
LEGEND_RGB = np.array([0xF6, 0xF6, 0xF4]) / 255.0
HIDE_ROBOT = '<script>viewer.set_property(["meshcat", "robot"], "visible", false);</script>'


def framing(scene_html, tmp_path) -> dict:
    """The robot's height share of the canvas and its box against the legend's, from pixels."""
    text = scene_html.read_text()
    empty = tmp_path / "empty.html"
    empty.write_text(text.replace("</body>", HIDE_ROBOT + "</body>"))
    shown = screenshot(scene_html, tmp_path / "scene.png", tmp_path, "#t=0", size=SIZE)
    hidden = screenshot(empty, tmp_path / "empty.png", tmp_path, "#t=0", size=SIZE)
    robot = np.abs(shown - hidden).max(axis=2) > 0.08
    legend = np.abs(shown - LEGEND_RGB).max(axis=2) < 0.01
    legend_cols = np.nonzero(legend.mean(axis=0) > 0.5)[0]  # columns mostly panel
    rows, cols = np.nonzero(robot)
    assert rows.size > 0.005 * robot.size, "the robot is not drawn"
    return {
        "inside": bool(rows.min() > 0 and rows.max() < SIZE[1] - 1 and cols.max() < SIZE[0] - 1),
        "height": (rows.max() - rows.min() + 1) / SIZE[1],
        "width": (cols.max() - cols.min() + 1) / (SIZE[0] - 1 - legend_cols.max()),
        "robot_left": int(cols.min()),
        "legend_right": int(legend_cols.max()),
    }


def _check(fig: dict) -> None:
    # a tall robot fills the height; a wide one, seen from its side, the width beside the legend
    assert max(fig["height"], fig["width"]) >= 0.6, f"the robot spans {fig} of the canvas"
    assert fig["robot_left"] > fig["legend_right"], fig  # the legend never covers the robot
    assert fig["inside"], fig  # nothing of the robot cut by the canvas's edges


def test_payload_report_frames_the_robot(tmp_path):
    ur5 = get_robot("ur5")
    u, ld = make_runs(ur5, "tool0", make_payload(), n=300, noise=0.01)
    rep = tmp_path / "rep"
    argv = ["payload", "ur5", "--frame", "tool0", "--consistent", "--report", str(rep)]
    argv += ["--unloaded", _save(tmp_path / "u.npz", u, ur5)]
    argv += ["--loaded", _save(tmp_path / "l.npz", ld, ur5)]
    assert main(argv) == 0
    index = (rep / "index.html").read_text()
    assert index.index("What is the payload?") < index.index("Summary")
    assert "1 of 1 bodies" in (rep / "scene.html").read_text()  # the payload's ellipsoid
    _check(framing(rep / "scene.html", tmp_path))


def test_identify_consistent_report_frames_the_robot(tmp_path):
    rep = tmp_path / "rep"
    argv = ["identify", "ur5", "--simulate", "--duration", "4", "--consistent"]
    assert main([*argv, "--report", str(rep)]) == 0
    _check(framing(rep / "scene.html", tmp_path))


def test_adapt_report_frames_the_robot(tmp_path):
    rep = tmp_path / "rep"
    assert main(["adapt", "panda", "--duration", "0.5", "--report", str(rep)]) == 0
    _check(framing(rep / "scene.html", tmp_path))
