"""The hardening catalogue's shared parts: its fixtures' data, one case, and how a case is checked.

Used by ``tests/test_hardening.py`` (issue 14) and ``tests/test_hardening_outputs.py``
(issue 29). The data are made with numpy alone: the mass-spring-damper ``msd``
(``m ddq + c dq + k q = tau``, m = 2 kg, c = 0.8 N s/m, k = 5 N/m) and a two-link arm
URDF.
"""

from __future__ import annotations

import hashlib
import json
import os
import re
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from manip_id.cli import main

ARM = """<?xml version="1.0"?>
<robot name="arm">
  <link name="base"/>
  <link name="{l1}">
    <inertial><origin xyz="0.1 0 0"/><mass value="{m1}"/>
      <inertia ixx="{ixx}" ixy="0" ixz="0" iyy="0.02" iyz="0" izz="0.02"/></inertial>
  </link>
  <link name="l2">
    <inertial><origin xyz="0.1 0 0"/><mass value="1.0"/>
      <inertia ixx="0.01" ixy="0" ixz="0" iyy="0.01" iyz="0" izz="0.01"/></inertial>
  </link>
  <joint name="{j1}" type="revolute"><parent link="base"/><child link="{l1}"/>
    <axis xyz="0 0 1"/><limit lower="-3" upper="3" velocity="5" effort="50"/></joint>
  <joint name="j2" type="revolute"><parent link="{l1}"/><child link="l2"/>
    <origin xyz="0.3 0 0"/><axis xyz="0 1 0"/>
    <limit lower="-3" upper="3" velocity="5" effort="50"/></joint>
</robot>
"""


def arm_urdf(path: Path, m1="2.0", ixx="0.02", j1="j1", l1="l1") -> Path:
    path.write_text(ARM.format(m1=m1, ixx=ixx, j1=j1, l1=l1))
    return path


def msd_arrays(n: int = 400, seed: int = 0) -> dict[str, np.ndarray]:
    """Noise-free msd measurements: tau = 2 ddq + 0.8 dq + 5 q [N]."""
    t = np.arange(n) / 100.0  # [s]
    w = 2 * np.pi * np.array([0.3, 0.7, 1.3])
    a = np.array([0.5, 0.3, 0.2])
    q = (a * np.sin(np.outer(t, w) + seed)).sum(axis=1)[:, None]  # [m]
    dq = (a * w * np.cos(np.outer(t, w) + seed)).sum(axis=1)[:, None]
    ddq = (-a * w**2 * np.sin(np.outer(t, w) + seed)).sum(axis=1)[:, None]
    tau = 2.0 * ddq + 0.8 * dq + 5.0 * q  # [N]
    return {"t": t, "q": q, "dq": dq, "ddq": ddq, "tau": tau, "joint_names": np.array(["cart"])}


def write_npz(path: Path, **override) -> Path:
    arrays = msd_arrays()
    arrays.update(override)
    arrays = {k: v for k, v in arrays.items() if v is not None}
    with open(path, "wb") as fh:
        np.savez(fh, **arrays)
    return path


def write_csv(path: Path) -> Path:
    a = msd_arrays()
    table = np.column_stack([a["t"], a["q"], a["dq"], a["ddq"], a["tau"]])
    np.savetxt(path, table, delimiter=",", header="t,q_cart,dq_cart,ddq_cart,tau_cart", comments="")
    return path


def working_folder(tmp_path: Path, monkeypatch) -> Path:
    """``tmp_path`` as the current directory, holding the catalogue's inputs."""
    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv("OPENBLAS_NUM_THREADS", "1")
    write_npz(tmp_path / "log.npz")
    write_npz(tmp_path / "valid.npz", **{k: v for k, v in msd_arrays(seed=1).items()})
    write_csv(tmp_path / "log.csv")
    arm_urdf(tmp_path / "arm.urdf")
    (tmp_path / "data").mkdir()
    write_npz(tmp_path / "data" / "inner.npz")
    (tmp_path / "data" / "notes.txt").write_text("the user's notes\n")
    (tmp_path / "a_file.txt").write_text("a regular file\n")
    return tmp_path


def snapshot(root: Path) -> dict[str, str]:
    """Every file and folder under ``root``: relative path -> content hash ('dir' for folders)."""
    out = {}
    for p in sorted(root.rglob("*")):
        rel = str(p.relative_to(root))
        if p.is_symlink():
            out[rel] = "link:" + os.readlink(p)
        elif p.is_dir():
            out[rel] = "dir"
        elif not p.is_file():  # a FIFO: never read it (it would block)
            out[rel] = "special"
        else:
            out[rel] = hashlib.sha256(p.read_bytes()).hexdigest()
    return out


def error_lines(err: str) -> list[str]:
    return [line for line in err.splitlines() if line.strip()]


# ---------------------------------------------------------------- catalogue
@dataclass
class Case:
    """One CLI invocation in the working folder and what must come of it."""

    id: str
    argv: list[str]
    status: int = 2
    match: str = ""  # regex the (one) stderr line must contain
    setup: Callable[[Path], None] | None = None
    outputs: tuple[str, ...] = ()  # paths that must exist afterwards (status 0)
    warnings: int = 0  # exact number of `manip-id: warning:` lines (status 0)
    check: Callable[[Path], None] | None = None
    marks: list = field(default_factory=list)


def check_case(case: Case, work: Path, capfd) -> None:
    """Run ``case`` in ``work`` (set up already) and check everything the catalogue asks."""
    capfd.readouterr()
    before = snapshot(work)
    status = main(list(case.argv))
    out, err = capfd.readouterr()
    lines = error_lines(err)
    assert "Traceback" not in err, err
    assert status == case.status, (status, err)
    if case.status != 0:
        assert len(lines) == 1, lines
        assert re.match(r"manip-id( \w+)?: error: ", lines[0]), lines[0]
        assert re.search(case.match, lines[0]), lines[0]
    else:
        warned = [line for line in lines if line.startswith("manip-id: warning:")]
        saved: set[str] = set()  # the warnings of a JSON / report output are printed too
        docs = [work / o for o in case.outputs if o.endswith(".json")]
        docs += [work / o.split("/")[0] / "result.json" for o in case.outputs if "/" in o]
        for path in docs:
            try:
                doc = json.loads(path.read_text())
            except (OSError, ValueError):  # none there, or an output named .json of another kind
                continue
            saved |= set(doc.get("warnings") or []) if isinstance(doc, dict) else set()
        assert len(warned) == case.warnings + len(saved), lines
        assert not [line for line in lines if "error" in line], lines
    after = snapshot(work)
    # inputs byte-identical, nothing else left behind (but the expected outputs)
    for rel, digest in before.items():
        if case.status == 0 and any(
            rel == o or rel.startswith(o.split("/")[0] + "/") for o in case.outputs
        ):
            continue
        assert after.get(rel) == digest, f"{rel} changed or vanished"
    new = sorted(set(after) - set(before))
    expected = {o for o in case.outputs} | {o.split("/")[0] for o in case.outputs}
    stray = [p for p in new if p not in expected and p.split("/")[0] not in expected]
    assert stray == [], stray
    hidden = [
        p
        for p in after
        if Path(p).name.startswith(".") and (".tmp" in Path(p).name or ".old-" in Path(p).name)
    ]
    assert hidden == [], hidden
    for o in case.outputs:
        assert (work / o).is_file(), o
    if case.check is not None:
        case.check(work)
