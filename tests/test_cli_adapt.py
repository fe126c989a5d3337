"""`manip-id adapt`: figures, JSON output and bad input."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest

from manip_id.cli import main
from manip_id.control.closed_loop import with_payload
from manip_id.robot.model import load_robot
from manip_id.simulation import perturb_parameters


@pytest.mark.parametrize("extra", [[], ["--composite"]])
def test_adapt_prints_figures_and_writes_json(tmp_path, capsys, extra):
    out = tmp_path / "adapt.json"
    status = main(
        [
            "adapt",
            "ur5",
            "--duration",
            "3",
            "--rate",
            "500",
            "--perturb",
            "0.1",
            "--payload",
            "1",
            "--json",
            str(out),
            *extra,
        ]
    )
    assert status == 0
    text = capsys.readouterr().out
    assert "rms tracking error" in text and "real-time factor" in text
    data = json.loads(out.read_text())
    rms = data["rms_tracking_error"]
    assert set(rms) == {"adaptive", "fixed"}
    assert 0 < rms["adaptive"] < rms["fixed"]
    assert 0 <= data["final_prediction_error"] < data["initial_prediction_error"]
    assert data["real_time_factor"] > 0
    assert data["composite"] is bool(extra)
    # the true parameters are the documented perturbation (and payload) of the nominal ones
    robot = load_robot("ur5")
    expected = with_payload(robot, perturb_parameters(robot, 0.1, seed=0), 1.0)
    np.testing.assert_allclose(data["theta_true"], expected)
    np.testing.assert_allclose(data["theta0"], robot.nominal_parameters)
    assert len(data["theta_hat"]) == len(data["parameter_names"]) == robot.n_parameters


@pytest.mark.parametrize(
    "args, message",
    [
        (["--lam", "0"], "lam"),
        (["--kd-rate", "-1"], "kd"),
        (["--gamma", "-1"], "gamma"),
        (["--duration", "1", "--rate", "333.3"], "does not divide"),
        (["--amplitude", "0.9", "--period", "0.5"], "limit"),
        (["--perturb", "-0.5"], "rel"),
        (["--payload", "-2"], "payload"),
    ],
)
def test_bad_input_is_one_line_exit_2(tmp_path, capsys, args, message):
    out = tmp_path / "adapt.json"
    status = main(["adapt", "panda", "--duration", "0.5", "--json", str(out), *args])
    assert status == 2
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("manip-id: error:")
    assert message in lines[0]
    assert list(tmp_path.iterdir()) == []  # no output, not even a partial one


def test_bad_input_from_the_shell_has_no_traceback(tmp_path):
    out = tmp_path / "adapt.json"
    proc = subprocess.run(
        [
            sys.executable,
            "-m",
            "manip_id",
            "adapt",
            "panda",
            "--duration",
            "1",
            "--rate",
            "333.3",
            "--json",
            str(out),
        ],
        capture_output=True,
        text=True,
        check=False,
    )
    assert proc.returncode == 2, proc.stderr
    assert "Traceback" not in proc.stderr
    assert proc.stderr.strip().startswith("manip-id: error:")
    assert len(proc.stderr.strip().splitlines()) == 1
    assert not out.exists()
