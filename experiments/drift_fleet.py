"""A drift report on a simulated fleet: which ur5 has worn, and which joint.

    python experiments/drift_fleet.py [--scheduler local:2] [--json OUT]

Simulates a fleet of ur5 robots (viscous and Coulomb friction, white torque noise of one
size per joint, 20 s at 200 Hz each, NPZ files in a temporary folder): three reference
runs, identified with ``manip-id identify --method wls``, then six robots of which
``robot3`` has +30 % viscous friction on elbow_joint and ``robot5`` +40 % Coulomb friction
on wrist_1_joint. Runs ``manip-id drift`` on the six (one task per file; with
``--scheduler`` on Dask) and prints its report.
"""

from __future__ import annotations

import argparse
import json
import tempfile
from pathlib import Path

import numpy as np

from manip_id import load_robot
from manip_id.cli import main as manip_id_main
from manip_id.datasets import Dataset, save_dataset
from manip_id.simulation import simulate
from manip_id.trajectories import random_trajectory

FV = np.array([2.0, 2.0, 1.5, 0.5, 0.5, 0.5])  # [N m s/rad]
FC = np.array([3.0, 3.0, 2.0, 1.0, 1.0, 1.0])  # [N m]
NOISE = np.array([0.3, 0.5, 0.3, 0.05, 0.05, 0.05])  # [N m]
WEAR = {"robot3": ("elbow_joint", "fv", 1.3), "robot5": ("wrist_1_joint", "fc", 1.4)}


def _save(robot, theta, seed: int, path: Path) -> str:
    traj = random_trajectory(robot, seed=500 + seed)
    ds = simulate(robot, traj, duration=20.0, rate=200.0, theta=theta).dataset
    tau = ds.tau + NOISE * np.random.default_rng(seed).standard_normal(ds.tau.shape)
    return str(save_dataset(Dataset(t=ds.t, q=ds.q, dq=ds.dq, tau=tau, ddq=ds.ddq), path))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scheduler", default=None)
    parser.add_argument("--json", default=None)
    args = parser.parse_args()
    robot = load_robot("ur5", friction="viscous,coulomb")
    theta = robot.nominal_parameters.copy()
    theta[robot.layout.joint_columns("fv")] = FV
    theta[robot.layout.joint_columns("fc")] = FC
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        refs = [_save(robot, theta, s, folder / f"reference{s}.npz") for s in range(3)]
        fleet = []
        for i in range(6):
            name = f"robot{i}"
            th = theta.copy()
            if name in WEAR:
                joint, term, factor = WEAR[name]
                th[robot.parameter_index(f"{joint}.{term}")] *= factor
            fleet.append(_save(robot, th, 100 + i, folder / f"{name}.npz"))
        ref = folder / "reference.json"
        base = ["ur5", "--friction", "viscous,coulomb"]
        argv = ["identify", *base, "--method", "wls", "--data", *refs, "--json", str(ref)]
        if manip_id_main(argv) != 0:
            raise SystemExit("reference identification failed")
        out = folder / "drift.json"
        argv = ["drift", *base, "--reference", str(ref), "--data", *fleet, "--json", str(out)]
        argv += ["--scheduler", args.scheduler] if args.scheduler else []
        print("\n$ manip-id " + " ".join(argv[:4]) + " ... (6 files)")
        if manip_id_main(argv) != 0:
            raise SystemExit("drift failed")
        doc = json.loads(out.read_text())
    if args.json:
        Path(args.json).write_text(json.dumps(doc, indent=2))


if __name__ == "__main__":
    main()
