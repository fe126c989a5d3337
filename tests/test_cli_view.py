"""`manip-id view`: HTML of the robot along data or a simulation; bad trajectories exit 2."""

from __future__ import annotations

import numpy as np
import pytest

from manip_id.cli import build_parser, main


def _npz(path, q):
    n, nv = q.shape
    t = np.arange(n) * 0.01
    np.savez(path, t=t, q=q, dq=np.zeros((n, nv)), tau=np.zeros((n, nv)))
    return path


def test_view_simulated_writes_html(tmp_path, capsys):
    out = tmp_path / "v.html"
    assert main(["view", "ur5", "--simulate", "--duration", "1", "--html", str(out)]) == 0
    assert f"wrote {out}" in capsys.readouterr().out
    html = out.read_text()
    assert html.startswith("<!DOCTYPE html>")
    assert "random excitation (seed 0, 1 s)" in html
    assert "inertia ellipsoids: nominal" in html
    assert sorted(p.name for p in tmp_path.iterdir()) == ["v.html"]


def test_view_data(tmp_path, capsys):
    q = 0.3 * np.sin(np.linspace(0, 3, 100))[:, None] * np.ones(6)
    data = _npz(tmp_path / "d.npz", q)
    out = tmp_path / "v.html"
    assert main(["view", "ur5", "--data", str(data), "--no-inertia", "--html", str(out)]) == 0
    html = out.read_text()
    assert "motion: 100 samples" in html
    assert "inertia ellipsoids" not in html


@pytest.mark.parametrize(
    ("q", "message"),
    [
        (np.zeros((50, 5)), "q.shape=(50, 5) but robot.nq=6"),
        (np.full((50, 6), 4.0), "limits of elbow_joint"),
    ],
)
def test_trajectory_that_does_not_fit_is_an_error(tmp_path, capsys, q, message):
    data = _npz(tmp_path / "d.npz", q)
    out = tmp_path / "v.html"
    assert main(["view", "ur5", "--data", str(data), "--html", str(out)]) == 2
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1 and message in err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["d.npz"]


def test_nothing_to_do_is_an_error(capsys):
    assert main(["view", "ur5"]) == 2
    assert "--html" in capsys.readouterr().err


def test_serve_and_exclusive_sources_parse():
    args = build_parser().parse_args(["view", "ur5", "--simulate", "--serve"])
    assert args.serve and args.simulate and args.html is None
    with pytest.raises(SystemExit):
        build_parser().parse_args(["view", "ur5", "--simulate", "--data", "x.npz"])
