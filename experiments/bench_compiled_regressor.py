"""The compiled block regressor against Pinocchio's per-sample call, whole processes.

    python experiments/bench_compiled_regressor.py [--samples 200000] [--rounds 3]

For ur10, panda and a 20-joint chain, each round runs three child processes, one after
the other: ``pinocchio`` (one ``computeJointTorqueRegressor`` call per sample into a
buffer: the floor), ``compiled`` (the kernel over the same states, numba's import and
the cached code's load included) and ``iter`` (the public ``iter_regressor`` in its
default mode, joint terms included). The table gives the median wall time of the
evaluation inside each child, the median whole-process time, and the ratios against
the floor measured in the same rounds (the machine is shared: only ratios mean much).
"""

from __future__ import annotations

import argparse
import json
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

CHILD = r"""
import json, sys, time
import numpy as np
import pinocchio as pin
from manip_id.robot.model import load_robot
from manip_id.robot import compiled_regressor as cr
from manip_id.robot.regressor import iter_regressor

kind, spec, n = sys.argv[1], sys.argv[2], int(sys.argv[3])
robot = load_robot(spec)
q, dq, ddq = robot.random_states(n, seed=0)
t0 = time.perf_counter()
if kind == "pinocchio":
    m, d = robot.model, robot.model.createData()
    out = np.empty((n, robot.nv, robot.n_rigid))
    f = pin.computeJointTorqueRegressor
    for k in range(n):
        out[k] = f(m, d, q[k], dq[k], ddq[k])
elif kind == "compiled":
    desc = cr.compile_model(robot.model)
    out = np.empty((n, robot.nv, robot.n_rigid))
    cr.rigid_block(desc, q[:1], dq[:1], ddq[:1], out[:1])  # numba's import and cache load
    warm = time.perf_counter() - t0
    t0 = time.perf_counter()
    for s in range(0, n, 1024):
        b = slice(s, s + 1024)
        cr.rigid_block(desc, q[b], dq[b], ddq[b], out[b])
else:
    for c in iter_regressor(robot, q, dq, ddq):
        pass
print(json.dumps({"seconds": time.perf_counter() - t0, "warm": locals().get("warm", 0.0)}))
"""


def _chain_urdf(path: Path, n: int = 20) -> None:
    links = ['<link name="l0"/>']
    joints = []
    for i in range(1, n + 1):
        links.append(
            f'<link name="l{i}"><inertial><origin xyz="0.05 0.01 0.1"/><mass value="1.0"/>'
            '<inertia ixx="0.02" ixy="0" ixz="0" iyy="0.02" iyz="0" izz="0.01"/></inertial></link>'
        )
        axis = ["1 0 0", "0 1 0", "0 0 1"][i % 3]
        joints.append(
            f'<joint name="j{i}" type="revolute"><parent link="l{i - 1}"/><child link="l{i}"/>'
            f'<origin xyz="0 0 0.1" rpy="0 0 0"/><axis xyz="{axis}"/>'
            '<limit lower="-3" upper="3" effort="100" velocity="5"/></joint>'
        )
    path.write_text('<robot name="chain20">' + "".join(links + joints) + "</robot>")


def _child(kind: str, spec: str, n: int) -> tuple[float, float, float]:
    """(evaluation seconds, whole-process seconds, kernel warm-up seconds) of one child."""
    import time

    t0 = time.perf_counter()
    out = subprocess.run(
        [sys.executable, "-c", CHILD, kind, spec, str(n)],
        capture_output=True,
        text=True,
        check=True,
        env={**__import__("os").environ, "OPENBLAS_NUM_THREADS": "1"},
    )
    whole = time.perf_counter() - t0
    doc = json.loads(out.stdout.strip().splitlines()[-1])
    return doc["seconds"], whole, doc["warm"]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--samples", type=int, default=200_000)
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--json", type=Path, default=None)
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        chain = Path(tmp) / "chain20.urdf"
        _chain_urdf(chain)
        robots = {"ur10": "ur10", "panda": "panda", "chain20": str(chain)}
        rows = {}
        for name, spec in robots.items():
            runs: dict[str, list[tuple[float, float, float]]] = {
                "pinocchio": [],
                "compiled": [],
                "iter": [],
            }
            for _ in range(args.rounds):
                for kind in runs:
                    runs[kind].append(_child(kind, spec, args.samples))
            med = {
                k: tuple(statistics.median(r[i] for r in v) for i in range(3))
                for k, v in runs.items()
            }
            rows[name] = med
            floor = med["pinocchio"][0]
            print(
                f"{name:8s} per sample [us]: "
                + ", ".join(
                    f"{k} {v[0] / args.samples * 1e6:.2f} (x{v[0] / floor:.2f}; "
                    f"process {v[1]:.2f} s; warm-up {v[2]:.2f} s)"
                    for k, v in med.items()
                )
            )
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps({"samples": args.samples, "rows": rows}, indent=2))


if __name__ == "__main__":
    main()
