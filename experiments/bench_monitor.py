"""Per-step cost of the collision monitor (``CollisionMonitor.step``), whole processes.

    python experiments/bench_monitor.py [--robot panda] [--steps 100000] [--repeat 5] [--json OUT]

A simulated run of ``--steps`` samples at 1 kHz (the robot with viscous, Coulomb and
offset friction) is saved once; then child processes load it, build the monitor and run
either 0 or ``--steps`` calls of ``step(q, dq, tau, dt)`` (the default observer: gain
25 /s and the residual's second low-pass; and the first-order observer). The per-step
cost is the difference of the median wall times divided by the number of steps, so
start-up, loading and set-up cancel; the runs are interleaved (round-robin). Target
(issue 26): <= 50 us for a 7-joint arm. The in-process figure (``perf_counter`` around
the loop, median of the runs) is printed too.
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from _measure import machine, run  # noqa: E402

FRICTION = "viscous,coulomb,offset"


def _child(path: str, robot_name: str, steps: int, first_order: bool) -> None:
    from manip_id import load_robot
    from manip_id.monitor import CollisionMonitor

    robot = load_robot(robot_name, friction=FRICTION)
    data = np.load(path)
    t, q, dq, tau = data["t"], data["q"], data["dq"], data["tau"]
    kw = {"filter_gain": None} if first_order else {}
    mon = CollisionMonitor(robot, data["theta"], 1.0, **kw)
    t0 = time.perf_counter()
    for k in range(steps):
        mon.step(q[k], dq[k], tau[k], 1e-3 if k else 1.0)
    sys.stderr.write(f"{time.perf_counter() - t0}\n")
    del t


def _data(robot_name: str, steps: int, path: Path) -> None:
    from manip_id import load_robot
    from manip_id.simulation import simulate
    from manip_id.trajectories import random_trajectory

    robot = load_robot(robot_name, friction=FRICTION)
    theta = robot.nominal_parameters.copy()
    theta[robot.layout.joint_columns("fv")] = 0.5
    theta[robot.layout.joint_columns("fc")] = 0.8
    sim = simulate(
        robot, random_trajectory(robot, seed=1), duration=(steps - 1) / 1000.0, rate=1000.0,
        theta=theta,
    )  # fmt: skip
    ds = sim.dataset
    np.savez(path, t=ds.t, q=ds.q, dq=ds.dq, tau=ds.tau, theta=theta)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--robot", default="panda")
    parser.add_argument("--steps", type=int, default=100000)
    parser.add_argument("--repeat", type=int, default=5)
    parser.add_argument("--json", default=None)
    parser.add_argument("--child", nargs=4, default=None, help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.child is not None:
        path, name, steps, first = args.child
        _child(path, name, int(steps), first == "1")
        return
    out: dict = {"robot": args.robot, "steps": args.steps, "machine": machine(), "cases": {}}
    cases = {"default (K = K2 = 25 /s)": "0", "first-order": "1"}
    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / "run.npz"
        _data(args.robot, args.steps, path)
        runs: dict = {(c, n): [] for c in cases for n in (0, args.steps)}
        for _ in range(args.repeat):  # round-robin: a change of the machine's load hits all
            for label, first in cases.items():
                for steps in (0, args.steps):
                    cmd = [sys.executable, __file__, "--child", str(path), args.robot, str(steps)]
                    r = run([*cmd, first])
                    if r.status != 0:
                        raise RuntimeError(f"{' '.join(cmd)} exited {r.status}: {r.stderr[-400:]}")
                    runs[label, steps].append(r)
        for label in cases:
            full = statistics.median(r.seconds for r in runs[label, args.steps])
            setup = statistics.median(r.seconds for r in runs[label, 0])
            inproc = statistics.median(
                float(r.stderr.strip().splitlines()[-1]) for r in runs[label, args.steps]
            )
            case = {
                "per_step_us_whole_process": (full - setup) / args.steps * 1e6,
                "per_step_us_in_process": inproc / args.steps * 1e6,
                "wall_s_setup_only": setup,
                "wall_s_with_steps": full,
            }
            out["cases"][label] = case
            print(
                f"{args.robot} {label}: {case['per_step_us_whole_process']:.1f} us/step (whole "
                f"process, medians of {args.repeat}), {case['per_step_us_in_process']:.1f} "
                "us/step in process (target <= 50)"
            )
    if args.json:
        Path(args.json).write_text(json.dumps(out, indent=2))


if __name__ == "__main__":
    main()
