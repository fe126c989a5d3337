"""Every option explains itself, and a misspelt name gets a suggestion (difflib)."""

from __future__ import annotations

import argparse

import numpy as np
import pytest

from manip_id.cli import build_parser, main


def _commands() -> dict[str, argparse.ArgumentParser]:
    parser = build_parser()
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    return dict(sub.choices)


@pytest.mark.parametrize("command", sorted(_commands()))
def test_every_option_has_help_stating_its_default(command):
    parser = _commands()[command]
    for action in parser._actions:
        if isinstance(action, argparse._HelpAction) or action.help == argparse.SUPPRESS:
            continue
        name = "/".join(action.option_strings) or action.dest
        assert action.help, f"{command} {name}: no help"
        stated = action.default in (None, False, [], argparse.SUPPRESS) or not action.option_strings
        assert stated or "default" in action.help.lower(), f"{command} {name}: default not stated"


def test_joint_terms_state_their_defaults():
    identify = _commands()["identify"]
    helps = {a.dest: a.help for a in identify._actions}
    for dest in ("friction", "armature", "spring", "joints"):
        assert "default" in helps[dest], dest


def _error(argv, capsys) -> str:
    assert main(argv) == 2
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("manip-id"), lines
    return lines[0]


@pytest.mark.parametrize(
    "argv, want",
    [
        (["identify", "pandas", "--simulate"], "did you mean 'panda'?"),
        (["identify", "panda", "--simulate", "--frition", "viscous"], "'--friction'?"),
        (["identify", "panda", "--simulate", "--frition=viscous"], "'--friction'?"),
        (["identfy", "panda"], "did you mean 'identify'?"),
        (["identify", "panda", "--simulate", "--method", "olss"], "did you mean 'ols'?"),
        (["identify", "panda", "--simulate", "--joints", "panda_jiont2"], "'panda_joint2'?"),
    ],
)
def test_did_you_mean(argv, want, capsys):
    assert want in _error(argv, capsys)


def test_no_suggestion_for_a_name_far_from_all(capsys):
    line = _error(["identify", "zzzzzz", "--simulate"], capsys)
    assert "unknown robot 'zzzzzz'" in line and "did you mean" not in line


def test_misspelt_frame(tmp_path, capsys):
    t = 0.01 * np.arange(50)
    z = np.zeros((50, 2))
    path = tmp_path / "r.npz"
    np.savez(path, t=t, q=z, dq=z, ddq=z, tau=z)
    argv = ["payload", "double_pendulum", "--unloaded", str(path), "--loaded", str(path)]
    line = _error([*argv, "--frame", "lnk2"], capsys)
    assert "did you mean 'link2'?" in line and "frames on moving joints" in line


def test_csv_with_other_columns_hints_at_column(tmp_path, capsys):
    path = tmp_path / "other.csv"
    rows = ["stamp,pos1,pos2,vel1,vel2,eff1,eff2"] + [f"{0.01 * k},0,0,0,0,1,2" for k in range(5)]
    path.write_text("\n".join(rows) + "\n")
    line = _error(["identify", "double_pendulum", "--data", str(path)], capsys)
    assert "--column" in line and "stamp" in line and "--column t=stamp" in line
