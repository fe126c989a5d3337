"""One list of warnings: every warning of the JSON is printed on stderr, once, as
``manip-id: warning: ...`` (followed by ``Do: ...`` when an option addresses it), for
identify, payload and drive-gains."""

from __future__ import annotations

import json

import numpy as np
import pytest
from test_cli_payload import files  # noqa: F401 (the module's fixture of NPZ runs)

from manip_id.cli import main


def _one_line(text: str) -> str:
    return " ".join(str(text).split())


def _check(argv, out, capsys) -> dict:
    status = main(argv)
    cap = capsys.readouterr()
    assert status == 0, cap.err
    doc = json.loads(out.read_text())
    assert doc["warnings"], "the case must warn for the test to bite"
    lines = [ln for ln in cap.err.splitlines() if ln.startswith("manip-id: warning: ")]
    for w in doc["warnings"]:  # printed as saved, then what to do about it (if known)
        line = "manip-id: warning: " + _one_line(w)
        said = [ln for ln in lines if ln == line or ln.startswith(line + " Do: ")]
        assert len(said) == 1, (line, lines)
    return doc


def test_identify_prints_every_json_warning(tmp_path, capsys):
    out = tmp_path / "r.json"
    argv = ["identify", "double_pendulum", "--simulate", "--split", "0.7"]
    doc = _check([*argv, "--json", str(out)], out, capsys)
    assert any("repeat the training motion" in w for w in doc["warnings"])


def test_identify_from_a_file_prints_every_json_warning(files, tmp_path, capsys):  # noqa: F811
    out = tmp_path / "r.json"
    _check(["identify", "ur5", "--data", files["u"], "--json", str(out)], out, capsys)


def test_identify_quiet_still_prints_the_warnings(tmp_path, capsys):
    out = tmp_path / "r.json"
    argv = ["identify", "double_pendulum", "--simulate", "--split", "0.7"]
    _check([*argv, "--quiet", "--json", str(out)], out, capsys)


def test_payload_prints_every_json_warning(files, tmp_path, capsys):  # noqa: F811
    out = tmp_path / "p.json"
    argv = ["payload", "double_pendulum", "--unloaded", files["pu"], "--loaded", files["pl"]]
    _check([*argv, "--frame", "link2", "--consistent", "--json", str(out)], out, capsys)


def _flipped(src: str, dst) -> str:
    """The run of ``src`` with the current of the first joint recorded with the other sign."""
    with np.load(src) as z:
        data = {k: z[k] for k in z.files}
    data["tau"][:, 0] *= -1.0
    np.savez(dst, **data)
    return str(dst)


@pytest.mark.parametrize("method", ["ols", "ml"])
def test_drive_gains_prints_every_json_warning(files, tmp_path, capsys, method):  # noqa: F811
    out = tmp_path / "g.json"
    cu, cl = _flipped(files["cu"], tmp_path / "cu.npz"), _flipped(files["cl"], tmp_path / "cl.npz")
    mass = str(files["payload"].mass)
    argv = ["drive-gains", "ur5", "--unloaded", cu, "--loaded", cl, "--frame", "tool0"]
    doc = _check(
        [*argv, "--payload-mass", mass, "--method", method, "--json", str(out)], out, capsys
    )
    assert any("came out <= 0" in w for w in doc["warnings"])
