"""Real-time factor of the closed-loop adaptive simulation.

    python experiments/bench_adaptive.py [--robot panda] [--duration 10] [--rate 1000] [--repeat 3]

Simulates ``--duration`` seconds of the robot under Slotine-Li adaptive control at
``--rate`` Hz (one semi-implicit Euler physics step per control step; per step:
two Pinocchio regressor calls, one ``aba``, the adaptation update; the composite
law adds three regressor calls and the filters). Prints, for the plain and the
composite law, the wall time of the simulation loop (best and median of
``--repeat`` runs), microseconds per control step and the real-time factor
``duration / wall time`` (the target: at least 10 for 10 s of panda at 1 kHz).
"""

from __future__ import annotations

import argparse
import os
import statistics

from manip_id import load_robot
from manip_id.cli._common import write_json
from manip_id.control.adaptive import default_gains
from manip_id.control.closed_loop import ClosedLoopOptions, simulate
from manip_id.simulation import perturb_parameters


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--robot", default="panda")
    parser.add_argument("--duration", type=float, default=10.0)
    parser.add_argument("--rate", type=float, default=1000.0)
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--json", default=None)
    args = parser.parse_args()

    robot = load_robot(args.robot)
    theta0 = robot.nominal_parameters
    theta = perturb_parameters(robot, 0.3, seed=1)
    steps = round(args.duration * args.rate)
    print(
        f"{robot!r}: {args.duration:g} s at {args.rate:g} Hz = {steps} control steps; "
        f"load average {os.getloadavg()[0]:.2f} on {os.cpu_count()} cores"
    )
    results = {}
    for law, kappa in (("plain", 0.0), ("composite", 50.0)):
        gains = default_gains(robot, theta0, composite=kappa)
        walls = []
        for _ in range(args.repeat):
            run = simulate(
                robot,
                theta,
                theta0,
                gains=gains,
                options=ClosedLoopOptions(duration=args.duration, rate=args.rate, record_every=100),
            )
            walls.append(run.wall_time)
        best, median = min(walls), statistics.median(walls)
        results[law] = {
            "wall_time_best": best,
            "wall_time_median": median,
            "us_per_step_best": best / steps * 1e6,
            "real_time_factor_best": args.duration / best,
            "real_time_factor_median": args.duration / median,
        }
        print(
            f"  {law:9s}: wall best {best:.3f} s, median {median:.3f} s; "
            f"{best / steps * 1e6:.1f} us/step; real-time factor best "
            f"{args.duration / best:.1f}, median {args.duration / median:.1f}"
        )
    if args.json:
        write_json(args.json, results)


if __name__ == "__main__":
    main()
