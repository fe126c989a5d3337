"""The audit table of a synthetic UR5 log with one known defect each, and the repair table.

Run: ``python experiments/audit_defects.py`` (prints ``manip-id audit`` for each log,
then ``manip-id repair`` of a UR5 URDF with three non-physical bodies). The logs are
noise-free excitations at 200 Hz (Fourier series, rnea of the URDF model plus viscous
and Coulomb friction), written to a temporary folder that is removed at the end.
"""

from __future__ import annotations

import sys
import tempfile
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pinocchio as pin

from manip_id import load_robot
from manip_id.cli import main

RATE = 200.0
FV = np.array([0.8, 1.1, 0.6, 0.3, 0.25, 0.2])
FC = np.array([1.5, 2.0, 1.2, 0.5, 0.4, 0.3])


def excitation(robot, n, seed=3):
    rng = np.random.default_rng(seed)
    t = np.arange(n) / RATE
    w = 2 * np.pi * 0.2 * np.arange(1, 5)
    a, b = (rng.uniform(-1, 1, (4, robot.nv)) * 0.15 for _ in range(2))
    s, c = np.sin(np.outer(t, w)), np.cos(np.outer(t, w))
    q, dq = s @ a + c @ b, (c * w) @ a - (s * w) @ b
    ddq = -(s * w**2) @ a - (c * w**2) @ b
    return t, q, dq, ddq, torques(robot, q, dq, ddq)


def torques(robot, q, dq, ddq):
    data = robot.model.createData()
    tau = np.array([pin.rnea(robot.model, data, *x) for x in zip(q, dq, ddq, strict=True)])
    return tau + FV * dq + FC * np.sign(dq)


def save(path, robot, t, q, dq, ddq, tau):
    np.savez(path, t=t, q=q, dq=dq, ddq=ddq, tau=tau, joint_names=np.array(robot.dof_names))
    return str(path)


def logs(robot, folder: Path) -> dict[str, list[str]]:
    """name -> the audit command's arguments."""
    t, q, dq, ddq, tau = excitation(robot, 1500)
    out = {"clean": [save(folder / "clean.npz", robot, t, q, dq, ddq, tau)]}
    gains = np.array([0.1, 0.15, 0.2, 0.25, 0.3, 0.12])
    out["currents 0.1 .. 0.3"] = [save(folder / "cur.npz", robot, t, q, dq, ddq, tau * gains)]
    flip = tau.copy()
    flip[:, 2] *= -1
    out["sign flipped on elbow_joint"] = [save(folder / "sign.npz", robot, t, q, dq, ddq, flip)]
    tl, ql, dql, ddql, taul = excitation(robot, 1505)
    out["delay 25 ms at 200 Hz"] = [
        save(folder / "late.npz", robot, tl[5:], ql[5:], dql[5:], ddql[5:], taul[:-5])
    ]
    ns = save(folder / "ns.npz", robot, t * 1e9, q, dq, ddq, tau)
    out["stamps in ns"] = [ns]
    out["stamps in ns, --time-unit ns"] = [ns, "--time-unit", "ns"]
    rest = int(3 * RATE)
    data = robot.model.createData()
    still = [np.repeat(x, rest, axis=0) for x in (q[:1], q[-1:])]
    g = [np.array([pin.computeGeneralizedGravity(robot.model, data, x) for x in s]) for s in still]
    z = np.zeros((rest, robot.nv))
    out["standstill edges of 3 s"] = [
        save(
            folder / "edges.npz",
            robot,
            np.arange(t.size + 2 * rest) / RATE,
            np.vstack([still[0], q, still[1]]),
            np.vstack([z, dq, z]),
            np.vstack([z, ddq, z]),
            np.vstack([g[0], tau, g[1]]),
        )
    ]
    rng = np.random.default_rng(0)
    wild = tau.copy()
    wild[rng.choice(t.size, 50, replace=False), rng.integers(0, robot.nv, 50)] = 1e184
    out["50 rows at 1e184, --drop-bad-rows"] = [
        save(folder / "wild.npz", robot, t, q, dq, ddq, wild),
        "--drop-bad-rows",
    ]
    head = ["t", *(f"{f}_{n}" for f in ("q", "dq", "tau", "ddq") for n in robot.dof_names)]
    rows = [",".join(repr(float(x)) for x in r) for r in np.column_stack([t, q, dq, tau, ddq])]
    rows[-1] = rows[-1][: len(rows[-1]) // 2].rsplit(",", 1)[0]
    (folder / "cut.csv").write_text("\n".join([",".join(head), *rows]) + "\n")
    out["truncated last line, --drop-bad-rows"] = [str(folder / "cut.csv"), "--drop-bad-rows"]
    q0 = np.array([0.3, -1.2, 1.0, -0.5, 0.8, 0.1])
    qs = q0 + 1e-4 * rng.integers(-1, 2, (2000, robot.nv))
    dqs = 2e-3 * rng.standard_normal((2000, robot.nv))
    gs = np.array([pin.computeGeneralizedGravity(robot.model, data, x) for x in qs])
    ts = np.arange(2000) / RATE
    out["static file"] = [save(folder / "static.npz", robot, ts, qs, dqs, 0 * dqs, gs)]
    return out


def broken_urdf(folder: Path) -> str:
    tree = ET.parse(load_robot("ur5").source)
    links = {lk.get("name"): lk for lk in tree.getroot().findall("link")}
    links["shoulder_link"].find("inertial/inertia").set("ixx", "-0.01")
    links["forearm_link"].find("inertial/inertia").set("izz", "0.2")
    links["wrist_2_link"].find("inertial/mass").set("value", "-1.219")
    tree.write(folder / "ur5_broken.urdf")
    return str(folder / "ur5_broken.urdf")


def run() -> int:
    robot = load_robot("ur5")
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        for name, args in logs(robot, folder).items():
            print(f"\n### {name}", flush=True)
            main(["audit", "ur5", "--data", *args])
            sys.stdout.flush()
        print("\n### repair of a UR5 URDF with three non-physical bodies", flush=True)
        main(["repair", broken_urdf(folder), str(folder / "ur5_fixed.urdf")])
    return 0


if __name__ == "__main__":
    raise SystemExit(run())
