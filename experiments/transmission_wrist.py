"""A coupled-wrist, motor-side, positions-only log identified with one command.

The robot: ur5 with gear ratios 50-100 and motor 6 driving joints 5 and 6
(``theta_6 = 50 (q5 + q6)``), motor terms (rotor inertia, viscous, Coulomb, offset) on
every motor. The logs are what an industrial controller records: motor angles and motor
torques only (no time column, no velocities), 200 Hz, 1 % torque noise. Torques are
computed here without the package's regressor: ``pinocchio.rnea`` plus the motor terms
written out on the motor velocities, mapped by ``R^T``.

The user's path, as a whole process::

    manip-id identify ur5 --data train.npz --validate valid.npz --transmission wrist.toml \
        --rate 200 --cutoff auto --method ols --json out.json

Prints each joint's validation error against the noise floor (raw torques), the cut-off
the command chose, and the recovered motor terms against the truth with their std.

    python experiments/transmission_wrist.py [--out DIR]
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import pinocchio as pin

from manip_id.robot.model import load_robot

RATE, DURATION, NOISE = 200.0, 30.0, 0.01  # [Hz], [s], relative torque noise
TOML = """matrix = [[100, 0, 0, 0, 0, 0], [0, 100, 0, 0, 0, 0], [0, 0, 80, 0, 0, 0],
          [0, 0, 0, 60, 0, 0], [0, 0, 0, 0, 50, 0], [0, 0, 0, 0, 50, 50]]
signals = "motor"
motor_terms = ["inertia", "viscous", "coulomb", "offset"]
"""


def wrist_matrix() -> np.ndarray:
    R = np.diag([100.0, 100.0, 80.0, 60.0, 50.0, 50.0])
    R[5, 4] = 50.0
    return R


def motor_truth(n: int) -> np.ndarray:
    """Per motor [Ia, fv, fc, fo] (kg m^2, N m s/rad, N m, N m)."""
    return np.stack(
        [
            np.linspace(2e-4, 5e-5, n),
            np.linspace(4e-3, 1e-3, n),
            np.linspace(0.05, 0.02, n),
            np.linspace(0.01, -0.01, n),
        ],
        axis=1,
    )


def motion(nv: int, phase: float):
    """A smooth multi-sine joint motion with exact derivatives."""
    t = np.arange(0.0, DURATION, 1.0 / RATE)
    q, dq, ddq = (np.zeros((t.size, nv)) for _ in range(3))
    for j in range(nv):
        for k, f in enumerate((0.15, 0.35, 0.6)):
            a, w = 0.5 / (k + 1), 2 * np.pi * f * (1 + 0.1 * j)
            ph = phase + 0.7 * j + 1.3 * k
            q[:, j] += a * np.sin(w * t + ph)
            dq[:, j] += a * w * np.cos(w * t + ph)
            ddq[:, j] -= a * w**2 * np.sin(w * t + ph)
    return q, dq, ddq


def write_log(robot, path: Path, phase: float, rng) -> None:
    R, c = wrist_matrix(), motor_truth(robot.nv)
    q, dq, ddq = motion(robot.nv, phase)
    rows = zip(q, dq, ddq, strict=True)
    tau = np.array([pin.rnea(robot.model, robot.data, a, b, d) for a, b, d in rows])
    dth, ddth = dq @ R.T, ddq @ R.T
    tau += (c[:, 0] * ddth + c[:, 1] * dth + c[:, 2] * np.sign(dth) + c[:, 3]) @ R
    tau += NOISE * np.sqrt(np.mean(tau**2, axis=0)) * rng.standard_normal(tau.shape)
    # motor side: theta = R q, tau = R^T tau_m; positions and torques only
    np.savez(path, q=q @ R.T, tau=np.linalg.solve(R.T, tau.T).T)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=None, help="folder for the logs [temporary]")
    args = ap.parse_args()
    folder = args.out or Path(tempfile.mkdtemp(prefix="wrist_"))
    folder.mkdir(parents=True, exist_ok=True)
    robot = load_robot("ur5")
    rng = np.random.default_rng(5)
    for name, phase in (("train", 0.0), ("valid", 2.0)):
        write_log(robot, folder / f"{name}.npz", phase, rng)
    (folder / "wrist.toml").write_text(TOML)
    out = folder / "out.json"
    argv = [sys.executable, "-m", "manip_id", "identify", "ur5"]
    argv += ["--data", str(folder / "train.npz"), "--validate", str(folder / "valid.npz")]
    argv += ["--transmission", str(folder / "wrist.toml"), "--rate", str(RATE)]
    argv += ["--cutoff", "auto", "--method", "ols", "--json", str(out), "--force", "--quiet"]
    t0 = time.perf_counter()
    subprocess.run(argv, check=True)
    wall = time.perf_counter() - t0
    doc = json.loads(out.read_text())
    floor = NOISE / np.sqrt(1 + NOISE**2)
    raw = doc.get("relative_error_raw") or doc["relative_error"]
    per_joint = raw["per_joint_validation"]
    values = per_joint.values() if isinstance(per_joint, dict) else per_joint
    print(f"command: {' '.join(argv[2:])}  ({wall:.1f} s)")
    print("validation error / noise floor per joint (raw torques):")
    print("  " + "  ".join(f"{v / floor:.3f}" for v in values))
    pre = doc["files"][0]["preprocess"]
    print(f"cut-off chosen: {pre.get('cutoff')} Hz ({pre.get('cutoff_reason')})")
    rows = {r["name"]: r for r in doc["base_parameters"]}
    truth = motor_truth(robot.nv)
    print("motor term  truth       estimate    std        (estimate - truth) / std")
    for m in range(robot.nv):
        for k, term in enumerate(("Ia", "fv", "fc", "fo")):
            row = rows.get(f"motor{m + 1}.{term}")
            if row is None:
                continue  # regrouped with a link parameter (its base expression names it)
            std = row["std"] or float("nan")
            print(
                f"motor{m + 1}.{term:3s} {truth[m, k]: .4e} {row['value']: .4e} {std:.3e}  "
                f"{(row['value'] - truth[m, k]) / std: .2f}"
            )


if __name__ == "__main__":
    main()
