"""`--report DIR [--force]` on identify, rank and adapt: contents, fail fast, never partial."""

from __future__ import annotations

import json
from html.parser import HTMLParser

import numpy as np
import pytest

from manip_id.cli import main
from manip_id.viz.figures import png_size

SIM = ["--simulate", "--duration", "2", "--rate", "100", "--seed", "1"]


class _Refs(HTMLParser):
    def __init__(self):
        super().__init__()
        self.refs = []

    def handle_starttag(self, tag, attrs):
        self.refs += [v for k, v in attrs if k in ("src", "href")]


def _refs(path):
    p = _Refs()
    p.feed(path.read_text())
    return p.refs


def _check_folder(rep, pngs):
    names = sorted(p.name for p in rep.iterdir())
    manifest = ".manip-id-report.json"  # marks the folder as ours (--force may replace it)
    assert names == sorted([manifest, "index.html", "result.json", "scene.html", *pngs])
    refs = _refs(rep / "index.html")
    for png in pngs:
        w, h = png_size(rep / png)
        assert w >= 800 and h >= 300
        assert png in refs
    assert "scene.html" in refs
    assert not [p for p in rep.parent.iterdir() if p.name.startswith(".")]


@pytest.mark.slow
def test_identify_report(tmp_path, capsys):
    rep, js = tmp_path / "rep", tmp_path / "r.json"
    argv = ["identify", "ur5", *SIM, "--split", "0.7", "--json", str(js), "--report", str(rep)]
    assert main(argv) == 0
    out = capsys.readouterr().out
    assert f"wrote the report to {rep}/index.html" in out
    _check_folder(rep, ["residuals.png", "singular_values.png", "torque_fit.png", "trajectory.png"])
    result = json.loads((rep / "result.json").read_text())
    given = json.loads(js.read_text())
    assert result == given
    index = (rep / "index.html").read_text()
    for p in result["base_parameters"]:
        assert f"<td>{p['name']}</td>" in index
    scene = (rep / "scene.html").read_text()
    assert "identifiability" in scene and "nominal" in scene


@pytest.mark.slow
def test_identify_report_refuses_a_non_empty_folder_before_working(tmp_path, capsys):
    rep = tmp_path / "rep"
    rep.mkdir()
    (rep / "keep.txt").write_text("mine")
    argv = ["identify", "ur5", *SIM, "--report", str(rep)]
    assert main(argv) == 2
    cap = capsys.readouterr()
    assert cap.out == ""  # nothing ran: no table printed
    assert len(cap.err.strip().splitlines()) == 1
    assert "not empty" in cap.err and "--force" in cap.err
    assert sorted(p.name for p in rep.iterdir()) == ["keep.txt"]
    # --force replaces only folders manip-id wrote (with a manifest): this one is the user's
    assert main([*argv, "--force"]) == 2
    assert "not written by manip-id" in capsys.readouterr().err
    assert sorted(p.name for p in rep.iterdir()) == ["keep.txt"]
    (rep / "keep.txt").unlink()
    assert main(argv) == 0  # an empty folder is used
    assert main([*argv, "--force"]) == 0  # and our own report is replaced
    assert (rep / "index.html").is_file()


def test_rank_report(tmp_path, capsys):
    rep = tmp_path / "rep"
    assert main(["rank", "ur5", "--samples", "60", "--report", str(rep)]) == 0
    _check_folder(rep, ["singular_values.png"])
    result = json.loads((rep / "result.json").read_text())
    assert result["robot"] == "ur5"
    index = (rep / "index.html").read_text()
    assert "base, alone" in index and "unidentifiable / regrouped" in index
    assert "identifiability" in (rep / "scene.html").read_text()


def test_rank_report_with_data(tmp_path, capsys):
    from manip_id import load_robot, random_trajectory, save_dataset, simulate

    robot = load_robot("ur5")
    sim = simulate(robot, random_trajectory(robot, seed=2), duration=2.0, rate=100.0)
    data = save_dataset(sim.dataset, tmp_path / "d.npz")
    rep = tmp_path / "rep"
    assert main(["rank", "ur5", "--samples", "60", "--data", str(data), "--report", str(rep)]) == 0
    _check_folder(rep, ["singular_values.png", "singular_values_data.png"])
    assert f"motion: {sim.dataset.n_samples} samples" in (rep / "scene.html").read_text()


def test_adapt_report(tmp_path, capsys):
    rep = tmp_path / "rep"
    argv = ["adapt", "ur5", "--duration", "0.3", "--rate", "500", "--report", str(rep)]
    assert main(argv) == 0
    _check_folder(rep, ["parameter_estimates.png", "tracking_error.png"])
    result = json.loads((rep / "result.json").read_text())
    index = (rep / "index.html").read_text()
    assert len(result["theta_true"]) == len(result["parameter_names"])
    name = result["parameter_names"][np.argmax(np.abs(result["theta_true"]))]
    assert f"<td>{name}</td>" in index
    scene = (rep / "scene.html").read_text()
    assert "inertia ellipsoids: true" in scene and "final_estimate" in scene


@pytest.mark.parametrize("command", [["rank", "ur5"], ["adapt", "ur5", "--duration", "0.1"]])
def test_rank_and_adapt_refuse_non_empty_folder(tmp_path, capsys, command):
    rep = tmp_path / "rep"
    rep.mkdir()
    (rep / "keep.txt").write_text("mine")
    assert main([*command, "--report", str(rep)]) == 2
    cap = capsys.readouterr()
    assert cap.out == "" and "not empty" in cap.err
    assert sorted(p.name for p in rep.iterdir()) == ["keep.txt"]
