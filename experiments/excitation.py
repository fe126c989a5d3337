"""Optimized excitation: condition number of the base regressor, random vs optimized.

A finite Fourier series per joint (Swevers) with 5 harmonics and a 10 s period
(wf = 2 pi / 10 rad/s) is optimized to minimize cond(W), W the base regressor
stacked over 60 equally spaced times of one period, subject to the panda's
position and velocity limits with a 5% margin. Compared with random feasible
coefficients (scaled to use 98% of the tightest limit of each joint). Each
condition number is also given on a dense grid (1000 samples per period) to
show the optimum is not an artefact of the optimization grid.

Run: ``.venv/bin/python experiments/excitation.py [--robot panda] [--json OUT]``
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from manip_id import ManipIdError, load_robot  # noqa: E402
from manip_id.cli._common import write_json  # noqa: E402
from manip_id.trajectories import (  # noqa: E402
    ExcitationSearch,
    base_columns,
    excitation_condition_number,
    optimize_excitation,
    random_trajectory,
)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--robot", default="panda")
    parser.add_argument("--friction", default=None, help="e.g. viscous,coulomb,offset")
    parser.add_argument("--harmonics", type=int, default=5)
    parser.add_argument("--period", type=float, default=10.0, help="base period 2 pi / wf [s]")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--n-points", type=int, default=60)
    parser.add_argument("--maxiter", type=int, default=100)
    parser.add_argument("--n-random", type=int, default=10)
    parser.add_argument("--acceleration-limit", type=float, default=None, help="[rad/s^2]")
    parser.add_argument("--json", default=None, help="write the figures to this file")
    args = parser.parse_args(argv)
    try:
        robot = load_robot(args.robot, friction=args.friction)
        wf = 2 * math.pi / args.period
        base = base_columns(robot)
        res = optimize_excitation(
            robot,
            args.harmonics,
            wf,
            args.seed,
            acceleration_limit=args.acceleration_limit,
            base=base,
            search=ExcitationSearch(
                n_points=args.n_points, maxiter=args.maxiter, n_random=args.n_random
            ),
        )
        t0 = time.perf_counter()
        dense_opt = excitation_condition_number(robot, res.trajectory, 1000, base)
        dense_random = np.array(
            [
                excitation_condition_number(
                    robot,
                    random_trajectory(
                        robot,
                        args.harmonics,
                        wf,
                        args.seed + 1 + i,
                        acceleration_limit=args.acceleration_limit,
                    ),
                    1000,
                    base,
                )
                for i in range(args.n_random)
            ]
        )
        t_dense = time.perf_counter() - t0
    except ManipIdError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    rnd = res.condition_numbers_random
    print(
        f"robot {robot.name}: nv={robot.nv}, {base.size} base parameters, "
        f"{args.harmonics} harmonics, wf = 2 pi / {args.period:g} s, seed {args.seed}"
    )
    print(
        f"optimization: {res.iterations} SLSQP iterations, {res.evaluations} objective "
        f"evaluations, {res.time:.1f} s ({res.message})"
    )
    print(f"condition number on the {res.n_points}-sample optimization grid:")
    print(f"  start (random, seed {args.seed})  {res.condition_number_initial:10.2f}")
    if rnd.size:
        print(
            f"  random feasible (n={rnd.size})      median {res.condition_number_random:.2f}, "
            f"min {rnd.min():.2f}, max {rnd.max():.2f}"
        )
    print(f"  optimized                     {res.condition_number:10.2f}")
    print("condition number on a 1000-sample grid:")
    if dense_random.size:
        print(f"  random feasible median        {np.median(dense_random):10.2f}")
    print(f"  optimized                     {dense_opt:10.2f}   ({t_dense:.1f} s to evaluate)")
    print(
        "peak use of the limits (1 = limit with 5% margin): position "
        f"{np.nanmax(res.usage.position):.3f}, velocity {np.nanmax(res.usage.velocity):.3f}"
    )
    if args.json:
        write_json(
            args.json,
            {
                "robot": robot.name,
                "n_base": int(base.size),
                "harmonics": args.harmonics,
                "wf": wf,
                "seed": args.seed,
                "n_points": res.n_points,
                "condition_number_initial": res.condition_number_initial,
                "condition_number": res.condition_number,
                "condition_number_random_median": res.condition_number_random,
                "condition_numbers_random": rnd,
                "condition_number_dense": dense_opt,
                "condition_numbers_random_dense": dense_random,
                "iterations": res.iterations,
                "evaluations": res.evaluations,
                "time_s": res.time,
                "q0": res.trajectory.q0,
                "a": res.trajectory.a,
                "b": res.trajectory.b,
            },
        )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
