"""The same options say the same thing in every command (issue 35): ``--quiet`` in
``drive-gains`` and ``payload`` as in ``identify``, ``--torque-scale-from`` in ``payload``
as in ``identify`` and ``audit``.

Independent checks: the payload found through the drive-gains JSON equals the payload
found with the same gains typed as ``--torque-scale``; the simulation's known mass.
"""

from __future__ import annotations

import json

import pytest

from manip_id.cli import main

GAINS = "8,8,8,3,3,3"
FRAME = ["--frame", "wrist_3_joint"]


@pytest.fixture(scope="module")
def currents(tmp_path_factory):
    """ur5 logs of motor currents (gains GAINS), unloaded and with a 1.3 kg payload."""
    d = tmp_path_factory.mktemp("currents")
    assert main(["simulate", "ur5", "--out", str(d / "sim"), "--files", "1", "--duration", "10",
                 "--payload", "1.3", "--drive-gains", GAINS, "--quiet"]) == 0  # fmt: skip
    runs = ["--unloaded", str(d / "sim" / "run_0.npz"),
            "--loaded", str(d / "sim" / "payload_1.3kg_0.npz"), *FRAME]  # fmt: skip
    return d, runs


def test_drive_gains_quiet_prints_nothing_and_writes_the_json(currents, capsys):
    d, runs = currents
    out = d / "gains.json"
    capsys.readouterr()
    argv = ["drive-gains", "ur5", *runs, "--payload-mass", "1.3", "--json", str(out)]
    assert main([*argv, "--quiet"]) == 0
    assert capsys.readouterr().out == ""
    gains = [row["gain"] for row in json.loads(out.read_text())["drive_gains"]]
    assert gains == pytest.approx([8, 8, 8, 3, 3, 3], rel=0.05)
    assert main([*argv, "--quiet", "--verbose", "--force"]) == 2  # one or the other


def test_payload_takes_the_gains_drive_gains_wrote(currents, capsys):
    d, runs = currents
    gains_json = d / "gains_for_payload.json"
    argv = ["drive-gains", "ur5", *runs, "--payload-mass", "1.3", "--json", str(gains_json)]
    assert main([*argv, "--quiet"]) == 0
    typed = ",".join(repr(row["gain"]) for row in json.loads(gains_json.read_text())["drive_gains"])
    a, b = d / "from_file.json", d / "typed.json"
    assert main(["payload", "ur5", *runs, "--torque-scale-from", str(gains_json),
                 "--json", str(a), "--quiet"]) == 0  # fmt: skip
    assert capsys.readouterr().out == ""
    assert main(["payload", "ur5", *runs, "--torque-scale", typed, "--json", str(b),
                 "--quiet"]) == 0  # fmt: skip
    mass = [json.loads(p.read_text())["payload"]["mass"] for p in (a, b)]
    assert mass[0] == pytest.approx(mass[1], rel=1e-9)
    assert mass[0] == pytest.approx(1.3, rel=0.05)
    both = ["--torque-scale", typed, "--torque-scale-from", str(gains_json)]
    assert main(["payload", "ur5", *runs, *both]) == 2
    assert "not both" in capsys.readouterr().err
