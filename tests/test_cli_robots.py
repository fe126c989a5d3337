"""`manip-id robots` and the CLI's handling of bad input."""

from __future__ import annotations

import subprocess
import sys

from manip_id.cli import main


def test_robots_lists_the_named_rows(capsys):
    """Published sizes: panda 7 DoF (fingers locked by robots/panda.toml), ur5 6, msd 1."""
    assert main(["robots", "panda", "ur5", "msd"]) == 0
    out = capsys.readouterr().out
    rows = {line.split()[0]: line.split()[1:] for line in out.splitlines()[1:-1] if line.split()}
    assert set(rows) == {"panda", "ur5", "msd"}  # only the rows asked for were loaded
    assert rows["panda"] == ["7", "7", "70", "panda.toml"]
    assert rows["ur5"] == ["6", "6", "60", "-"]
    assert rows["msd"] == ["1", "1", "12", "msd.toml"]


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


def test_an_unknown_robot_named_is_one_error_line(capsys):
    """A name the user asks for that does not load: exit 2, one line naming it, no table."""
    assert main(["robots", "ur5", "nosuch"]) == 2
    captured = capsys.readouterr()
    err = captured.err.strip().splitlines()
    assert len(err) == 1 and "'nosuch'" in err[0] and "ur5" in err[0], err
    assert captured.out == ""
