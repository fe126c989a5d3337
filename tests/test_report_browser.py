"""Each report kind's scene in headless Chromium: the robot frames the view beside the legend.

The scene of each report (identify --consistent, payload, adapt, excite) is rendered at the size
it has in the report page (the iframe: about 1170 x 600 px) at several times of its motion,
and once with the robot hidden (the same camera); the pixels that differ are the robot's.
From them: the frames together span >= 60 % of the canvas height (or, for a motion wider
than tall, of the canvas width beside the legend), and in every frame the robot lies right
of the legend's box (the panel's own background colour, measured from the pixels) and no
edge of the canvas cuts it: the camera frames the whole motion, not its start.
"""

from __future__ import annotations

import pytest
from conftest import get_robot
from test_cli_payload import _save
from test_payload import make_payload, make_runs
from test_viz_browser import CHROMIUM, frames_in_view

from manip_id.cli import main

pytestmark = [
    pytest.mark.skipif(CHROMIUM is None, reason="headless Chromium not found"),
    pytest.mark.slow,
]
#: The scene's size in a report page (index.html's iframe) [px].
SIZE = (1170, 600)
#: The legend panel's background (scene_page's CSS #f6f6f4).


def framing(scene_html, tmp_path, times=(0,)) -> dict:
    """The robot's frames at ``times`` [s] against the canvas and the legend, from pixels
    (:func:`test_viz_browser.frames_in_view` at the report's iframe size)."""
    return frames_in_view(scene_html, tmp_path, times, size=SIZE)


def _check(fig: dict, least: float = 0.6) -> None:
    # the motion spans the canvas's height, or the width beside the legend for a wide one
    assert max(fig["height"], fig["width"]) >= least, f"the robot spans {fig} of the canvas"
    # every frame inside the canvas and right of the legend (the legend never covers it)
    assert all(fig["inside"]), fig


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
    _check(framing(rep / "scene.html", tmp_path, times=(0, 1.5, 3)))


def test_adapt_report_frames_the_robot(tmp_path):
    rep = tmp_path / "rep"
    assert main(["adapt", "panda", "--duration", "0.5", "--report", str(rep)]) == 0
    _check(framing(rep / "scene.html", tmp_path, times=(0, 0.25, 0.5)))


def test_excite_report_frames_the_robot(tmp_path):
    """The designed motion with the table and a box of the world file: the robot (hidden
    for the background, the world objects stay) framed over the whole motion, with the box."""
    world = tmp_path / "world.toml"
    world.write_text(
        "[[plane]]\nnormal = [0, 0, 1]\noffset = -0.01\n"
        "[[box]]\nsize = [0.3, 0.3, 0.3]\nposition = [0.6, 0.0, 0.15]\n"
    )
    rep = tmp_path / "rep"
    argv = ["excite", "panda", "--duration", "4", "--harmonics", "3", "--starts", "2"]
    argv += ["--maxiter", "10", "--rate", "100", "--world", str(world)]
    assert main([*argv, "--out", str(tmp_path / "t.csv"), "--report", str(rep)]) == 0
    assert "closest approach" in (rep / "scene.html").read_text()
    # the camera frames the box too (test_excite_search: a far box in view), so the robot
    # spans less of the canvas than alone
    _check(framing(rep / "scene.html", tmp_path, times=(0, 1, 2, 3)), least=0.45)
