"""The report folders of payload, drive-gains and audit, on data made here with Pinocchio."""

from __future__ import annotations

import json

import numpy as np
from conftest import get_robot
from test_cli_payload import GAINS, _save
from test_payload import make_payload, make_runs, truth

from manip_id.cli import main
from manip_id.viz.payload_report import payload_rows


def _runs(tmp_path, gains=None):
    ur5 = get_robot("ur5")
    u, ld = make_runs(ur5, "tool0", make_payload(), n=300, gains=gains)
    return _save(tmp_path / "u.npz", u, ur5), _save(tmp_path / "l.npz", ld, ur5)


def test_payload_report_answers_first_with_the_truth(tmp_path):
    u, ld = _runs(tmp_path)
    rep = tmp_path / "rep"
    argv = ["payload", "ur5", "--frame", "tool0", "--unloaded", u, "--loaded", ld]
    assert main([*argv, "--report", str(rep)]) == 0
    page = (rep / "index.html").read_text()
    for q in ("What is the payload?", "Is it physical?", "Can I trust it?", "What to do next?"):
        assert page.index(q) < page.index("<h2>Summary</h2>")
    assert "centre of mass x" in page and "kg m^2" in page and "e+0" not in page
    # the table beside the payload Pinocchio's data were made with
    doc = json.loads((rep / "result.json").read_text())
    want = truth(make_payload())
    rows = payload_rows(doc["payload"], want)
    got = np.array([float(r["identified"]) for r in rows])
    np.testing.assert_allclose(got, want, rtol=1e-3, atol=1e-6)
    assert all(r["true"] != "not determined" for r in rows)


def test_drive_gain_report_lists_the_gains(tmp_path):
    u, ld = _runs(tmp_path, gains=GAINS)
    rep = tmp_path / "rep"
    argv = ["drive-gains", "ur5", "--frame", "tool0", "--unloaded", u, "--loaded", ld]
    assert main([*argv, "--payload-mass", "1.3", "--method", "ols", "--report", str(rep)]) == 0
    page = (rep / "index.html").read_text()
    assert page.index("What are the drive gains?") < page.index("<h2>Summary</h2>")
    assert "agrees with the maximum-likelihood gain" in page
    for g in GAINS:
        assert f"<td>{g:g}</td>" in page


def test_audit_report_names_the_fix(tmp_path):
    u, _ = _runs(tmp_path, gains=GAINS)  # currents in the torque columns
    rep = tmp_path / "rep"
    assert main(["audit", "ur5", "--data", u, "--report", str(rep)]) == 0
    page = (rep / "index.html").read_text()
    assert page.index("What is wrong with the data?") < page.index("What to fix?")
    assert "currents or a gear ratio" in page and "--torque-scale" in page
    assert "measured / nominal torque [-]" in page and "torque delay [ms]" in page
    assert main(["audit", "ur5", "--data", u, "--report", str(rep), "--force"]) == 0
