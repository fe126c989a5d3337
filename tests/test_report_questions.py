"""Reports that answer a user's questions: flags, nominal model, convergence, geometry.

Checked against what the test builds itself: URDF joint offsets written here (the
capsules), relative errors recomputed with numpy (the history figure), residual counts
(the histograms), the known non-physical OLS values of the real Panda log.
"""

from __future__ import annotations

import io
import json
import re
import sys
from pathlib import Path

import numpy as np
import pytest
from matplotlib.patches import Rectangle

from manip_id.cli import _common as cli_common
from manip_id.cli import main
from manip_id.robot.model import load_robot
from manip_id.viz import figures
from manip_id.viz.meshcat_scene import RobotScene, decimate_mesh

SIM = ["--simulate", "--duration", "3", "--rate", "100", "--seed", "2"]
OFFSETS = [(0.0, 0.0, 0.1), (0.0, 0.0, 0.35), (0.3, 0.0, 0.0)]  # joint origins [m]


def _urdf(path: Path, visual: str) -> Path:
    """A 3-joint arm; ``visual`` is "missing" (meshes that do not exist) or "none"."""
    links, joints = ['<link name="base"/>'], []
    for k, xyz in enumerate(OFFSETS, start=1):
        vis = (
            f'<visual><geometry><mesh filename="meshes/link{k}.stl"/></geometry></visual>'
            if visual == "missing"
            else ""
        )
        links.append(
            f'<link name="l{k}"><inertial><origin xyz="0.1 0 0.02"/><mass value="{2.0 / k}"/>'
            '<inertia ixx="0.02" ixy="0" ixz="0" iyy="0.03" iyz="0" izz="0.025"/></inertial>'
            f"{vis}</link>"
        )
        axis = "0 0 1" if k == 1 else "0 1 0"
        parent = "base" if k == 1 else f"l{k - 1}"
        joints.append(
            f'<joint name="j{k}" type="revolute"><parent link="{parent}"/>'
            f'<child link="l{k}"/><origin xyz="{" ".join(map(str, xyz))}"/><axis xyz="{axis}"/>'
            '<limit lower="-2.5" upper="2.5" effort="50" velocity="3"/></joint>'
        )
    path.write_text(f'<robot name="bare">{"".join(links + joints)}</robot>')
    return path


@pytest.mark.parametrize("visual", ["missing", "none"])
def test_report_of_a_mesh_less_urdf(tmp_path, capsys, visual):
    urdf = _urdf(tmp_path / "bare.urdf", visual)
    rep = tmp_path / "rep"
    assert main(["identify", str(urdf), *SIM, "--split", "0.6", "--report", str(rep)]) == 0
    assert "wrote the report" in capsys.readouterr().out
    index = (rep / "index.html").read_text()
    assert "capsules between the joint frames" in index
    assert (rep / "scene.html").stat().st_size < 2_000_000
    # the capsules: one cylinder per joint-to-child offset, as long as the URDF's offset
    scene = RobotScene(load_robot(str(urdf)))
    assert scene.geometry == "capsules"
    lengths = sorted(
        round(float(np.linalg.norm(T[:3, 3])) * 2, 9)
        for path, _, T in scene._capsules
        if "segment" in path
    )
    want = sorted(
        [round(float(np.linalg.norm(o)), 9) for o in OFFSETS[1:]] + [round(np.hypot(0.1, 0.02), 9)]
    )
    assert lengths == pytest.approx(want)


def test_torque_figure_panels(tmp_path):
    rng = np.random.default_rng(0)
    t = np.concatenate([np.arange(0, 6, 0.01), np.arange(7, 10, 0.01)])  # a trimmed gap
    tau = np.sin(t)[:, None] * [1.0, 3.0]
    pred = tau + 0.01 * rng.standard_normal(tau.shape)
    nom = 1.2 * tau
    fig = figures.torque_comparison(
        tmp_path / "f.png",
        t,
        tau,
        pred,
        nom,
        validation_start=7.0,
        errors=[(0.01, 0.2), (0.02, 0.2)],
        options=figures.FigureOptions(zoom=1.0),
    )
    axes = fig.axes
    assert len(axes) == 6  # per joint: record, zoom, histogram
    main_ax, zoom_ax, hist_ax = axes[:3]
    lo, hi = zoom_ax.get_xlim()
    assert 7.0 - 0.1 <= lo and hi - lo < 1.5  # the zoom lies in the validation part
    bars = [p for p in hist_ax.patches if isinstance(p, Rectangle)]
    assert sum(b.get_height() for b in bars) == pytest.approx(2 * len(t), abs=0.02 * len(t))
    spans = [p for p in main_ax.patches if p.get_label() == "validation part"]
    assert spans and spans[0].get_x() == pytest.approx(7.0)
    head = main_ax.get_title(loc="left")
    assert "1.00 %" in head and "20.0 %" in head


def test_history_figure_shows_relative_errors(tmp_path):
    rng = np.random.default_rng(1)
    t = np.linspace(0, 10, 300)
    ref = np.array([1.0, -2.0, 0.5, 3.0])
    th = ref * (1 + np.exp(-t)[:, None] * rng.standard_normal(4))
    err = np.exp(-t) + 1e-3
    fig = figures.online_history(
        tmp_path / "h.png", t, th, names=list("abcd"), reference=ref, prediction_error=err
    )
    top = fig.axes[0]
    median = [ln for ln in top.get_lines() if ln.get_label().startswith("median")][0]
    want = np.median(np.abs(th - ref) / np.abs(ref), axis=1)
    np.testing.assert_allclose(median.get_ydata(), np.maximum(want, 1e-6), rtol=1e-12)
    assert len(fig.axes) == 2 and (tmp_path / "h.png").stat().st_size > 0


def test_gradient_report_has_the_history_and_the_warning(tmp_path, capsys):
    rep = tmp_path / "rep"
    argv = ["identify", "double_pendulum", *SIM, "--method", "gradient", "--report", str(rep)]
    assert main(argv) == 0
    assert (rep / "parameter_history.png").is_file()
    doc = json.loads((rep / "result.json").read_text())
    assert doc["convergence"]["prediction_change"] > 0.01
    assert any("has not converged" in w for w in doc["warnings"])
    assert "has not converged" in (rep / "index.html").read_text()
    capsys.readouterr()


def test_real_panda_report(panda_log, tmp_path, capsys):
    rep = tmp_path / "rep"
    # OLS: the figures below are plain least squares' (WLS, the default, gives 0.724 %)
    argv = ["identify", "panda", "--friction", "viscous,coulomb,offset", "--split", "0.7"]
    argv += ["--method", "ols"]
    assert main([*argv, "--data", str(panda_log), "--report", str(rep)]) == 0
    capsys.readouterr()
    index = (rep / "index.html").read_text()
    rows = re.findall(r"<tr( class=\"(\w+)\")?><td>([\w.]+)</td>", index)
    names = [r[2] for r in rows]
    bad = [r[2] for r in rows if r[1] == "bad"]
    assert sorted(bad) == ["panda_joint6.fv", "panda_joint7.Izz"]
    first_flagged = min(i for i, r in enumerate(rows) if r[1])
    assert all(not r[1] for r in rows[:first_flagged]) and names.index(bad[0]) > first_flagged
    assert "0.741 % (nominal model 18.009 %)" in index  # summary_rows, the one rendering
    assert "low-pass 3 Hz" in index and "trimmed" in index
    assert "<h2>Data quality</h2>" in index
    assert (rep / "scene.html").stat().st_size < 5_000_000  # decimated meshes


def test_scene_assets_external(tmp_path, capsys):
    rep = tmp_path / "rep"
    argv = ["identify", "ur5", *SIM, "--report", str(rep), "--scene-assets", "external"]
    assert main(argv) == 0
    page = (rep / "scene.html").read_text()
    assert '<script src="meshcat.min.js">' in page and (rep / "meshcat.min.js").is_file()
    assert (rep / "scene-data.js").read_text().startswith("var commands = [")
    assert (rep / "scene.html").stat().st_size < 50_000
    capsys.readouterr()


def test_decimation_keeps_the_shape():
    # a sphere of 20k triangles: decimated below 3000, vertices within one cell of it
    u, v = np.meshgrid(np.linspace(0, np.pi, 101), np.linspace(0, 2 * np.pi, 101))
    V = np.stack([np.sin(u) * np.cos(v), np.sin(u) * np.sin(v), np.cos(u)], -1).reshape(-1, 3)
    idx = np.arange(101 * 101).reshape(101, 101)
    a, b, c, d = idx[:-1, :-1], idx[1:, :-1], idx[:-1, 1:], idx[1:, 1:]
    F = np.concatenate([np.stack([a, b, c], -1), np.stack([b, d, c], -1)]).reshape(-1, 3)
    V2, F2 = decimate_mesh(V, F, 3000)
    assert 500 < len(F2) <= 3000 and F2.max() < len(V2)
    r = np.linalg.norm(V2, axis=1)
    assert np.all(np.abs(r - 1) < 2 * np.sqrt(3) * 2 / 12)  # within a cell of the surface


class _Terminal(io.StringIO):
    def isatty(self) -> bool:
        return True


def test_progress_bar_on_a_terminal_and_quiet(tmp_path, capsys, monkeypatch):
    monkeypatch.setattr(cli_common, "PROGRESS_DELAY", 0.0)
    term = _Terminal()
    monkeypatch.setattr(sys, "stderr", term)
    assert main(["identify", "double_pendulum", *SIM]) == 0
    assert "identify" in term.getvalue() and "samples" in term.getvalue()
    assert "condition number" in capsys.readouterr().out
    term.seek(0)
    term.truncate()
    out = tmp_path / "r.json"
    assert main(["identify", "double_pendulum", *SIM, "--quiet", "--json", str(out)]) == 0
    doc = json.loads(out.read_text())
    assert capsys.readouterr().out == ""  # quiet: no bar, no table; the warnings remain
    lines = term.getvalue().splitlines()  # each warning, then what to do about it
    pairs = zip(lines, doc["warnings"], strict=True)
    assert all(a.startswith(f"manip-id: warning: {w}") for a, w in pairs)
    assert doc["robot"] == "double_pendulum"
