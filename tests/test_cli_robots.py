"""`manip-id robots` and the CLI's handling of bad input."""

from __future__ import annotations

import subprocess
import sys

from manip_id.cli import main


def test_robots_lists_names(capsys):
    assert main(["robots"]) == 0
    out = capsys.readouterr().out
    rows = {line.split()[0]: line.split()[1:] for line in out.splitlines()[1:] if line.split()}
    assert rows["panda"][:3] == ["7", "7", "70"]
    assert rows["ur5"][:3] == ["6", "6", "60"]
    assert rows["msd"][:3] == ["1", "1", "12"]


def test_bad_input_is_one_line_exit_2():
    proc = subprocess.run(
        [sys.executable, "-m", "manip_id", "rank", "no_such_robot"],
        capture_output=True,
        text=True,
        check=False,
    )
    assert proc.returncode == 2
    lines = proc.stderr.strip().splitlines()
    assert "Traceback" not in proc.stderr
    assert lines[-1].startswith("manip-id: error:")
