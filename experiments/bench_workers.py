"""Where forking pays: one process against one per core, by number of samples.

    python experiments/bench_workers.py [--sizes 5000 10000 20000 50000 100000 200000]
        [--repeat 3] [--regressor auto]

ur10 with viscous and Coulomb friction, simulated samples (a 5-harmonic trajectory at
1 kHz, 1 % torque noise) held in memory; ``identify(..., run=RunOptions(workers=W))``
with W = 1 and W = every core this process may use, timed in interleaved rounds (the
median of ``--repeat``). The smallest size from which the forked run is faster sets
``manip_id.execution.FORK_MIN_SAMPLES`` (with a margin: the machine may be busy).
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from manip_id import load_robot
from manip_id.execution import available_cores
from manip_id.identification import RunOptions, identify
from manip_id.robot.compiled_regressor import set_mode
from manip_id.simulation import MeasurementNoise, simulate
from manip_id.trajectories import random_trajectory


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", type=int, nargs="+", default=[5000, 20000, 50000, 200000])
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--regressor", default="auto")
    args = parser.parse_args()
    set_mode(args.regressor)
    robot = load_robot("ur10", friction=("viscous", "coulomb"))
    cores = available_cores()
    n_max = max(args.sizes)
    traj = random_trajectory(robot, harmonics=5, seed=0)
    noise = MeasurementNoise(tau=0.01)
    d = simulate(robot, traj, duration=n_max / 1000.0, rate=1000.0, noise=noise).dataset
    base = identify(robot, (d.q[:2000], d.dq[:2000], d.ddq[:2000], d.tau[:2000])).base
    print(f"ur10 + friction, {cores} cores, regressor {args.regressor}; median of {args.repeat}")
    print(f"{'samples':>9s} {'1 process s':>12s} {f'{cores} processes s':>14s} {'speed-up':>9s}")
    for n in args.sizes:
        times: dict[int, list[float]] = {1: [], cores: []}
        for _ in range(args.repeat):
            for w in times:
                t0 = time.perf_counter()
                identify(
                    robot,
                    (d.q[:n], d.dq[:n], d.ddq[:n], d.tau[:n]),
                    base=base,
                    run=RunOptions(workers=w),
                )
                times[w].append(time.perf_counter() - t0)
        t1, tc = float(np.median(times[1])), float(np.median(times[cores]))
        print(f"{n:9d} {t1:12.3f} {tc:14.3f} {t1 / tc:9.2f}", flush=True)


if __name__ == "__main__":
    main()
