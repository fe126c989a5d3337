"""The ``--friction auto`` candidate table in the identify report (``--report``)."""

from __future__ import annotations

import html
import json

import numpy as np
from test_friction import RATE, _data

from manip_id import load_robot
from manip_id.cli import main
from manip_id.viz.report_tables import report_selection_rows


def test_report_shows_the_candidate_table(tmp_path, capsys):
    robot = load_robot("double_pendulum", friction=())
    paths = []
    for k, seed in enumerate((11, 12)):
        (q, dq, ddq, tau), _ = _data(robot, "stribeck", seed=seed, duration=15.0)
        t = np.arange(q.shape[0]) / RATE + 30.0 * k
        path = tmp_path / f"part{k}.npz"
        np.savez(path, t=t, q=q, dq=dq, ddq=ddq, tau=tau, joint_names=np.array(robot.dof_names))
        paths.append(str(path))
    out, folder = tmp_path / "auto.json", tmp_path / "report"
    argv = ["identify", "double_pendulum", "--data", paths[0], "--validate", paths[1]]
    assert main([*argv, "--friction", "auto", "--json", str(out), "--report", str(folder)]) == 0
    capsys.readouterr()
    doc = json.loads(out.read_text())
    page = html.unescape((folder / "index.html").read_text())
    assert "Friction model per joint (chosen by BIC on the training data)" in page
    for heading in (
        "joint",
        "model",
        "chosen",
        "parameters",
        "shape",
        "validation error [%] (not used)",
    ):
        assert f">{heading}<" in page
    rows = report_selection_rows(doc)
    table = doc["friction_selection"]
    assert len(rows) == sum(len(j["candidates"]) for j in table)
    names = {p["name"] for p in doc["base_parameters"]}
    for js in table:
        marked = [r["model"] for r in rows if r["joint"] == js["joint"] and r["chosen"]]
        assert marked == [js["chosen"]]
        for c in js["candidates"]:
            if c["validation_error"] is not None:  # the figure the page shows, from the JSON
                assert f"{100 * c['validation_error']:.4g}"[:5] in page
        # the chosen model's count: its joint's own base coefficients plus its shapes
        chosen = next(c for c in js["candidates"] if c["model"] == js["chosen"])
        own = [n for n in names if n.startswith(js["joint"] + ".") and "*" not in n]
        own = [n for n in own if n.split(".", 1)[1] in doc["joint_terms_per_joint"][js["joint"]]]
        assert chosen["n_parameters"] == len(own) + len(chosen["parameters"])
    cands = [c for js in table for c in js["candidates"]]
    vs = [c["parameters"]["vs"] for c in cands if c["model"] == "stribeck"]
    assert vs and all(v > 0 for v in vs)
    assert "vs = " in page and "rad/s" in page
