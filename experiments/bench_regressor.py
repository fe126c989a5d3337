"""Per-sample cost of the regressors on a robot (default: the panda).

    python experiments/bench_regressor.py [--robot panda] [--samples 20000] [--repeat 5]

Prints microseconds per sample (best of ``--repeat`` runs) for:
the raw ``pinocchio.computeJointTorqueRegressor`` loop (the floor), one-sample
``regressor`` and ``slotine_li_regressor`` calls (the checked public API), the
hot-loop ``RegressorEvaluator`` calls, and batched evaluation over a trajectory
with ``iter_regressor`` / ``iter_slotine_li_regressor``.
"""

from __future__ import annotations

import argparse
import json
import time

import numpy as np
import pinocchio as pin

from manip_id import (
    iter_regressor,
    iter_slotine_li_regressor,
    load_robot,
    regressor,
    slotine_li_regressor,
)
from manip_id.robot.regressor import RegressorEvaluator


def best_of(fn, repeat: int, n: int) -> float:
    """Best wall time per item [us] over ``repeat`` runs of ``fn`` (which handles n items)."""
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return min(times) / n * 1e6


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--robot", default="panda")
    parser.add_argument("--friction", default="viscous,coulomb")
    parser.add_argument("--samples", type=int, default=20000)
    parser.add_argument("--repeat", type=int, default=5)
    parser.add_argument("--json", default=None)
    args = parser.parse_args()

    robot = load_robot(args.robot, friction=args.friction)
    n = args.samples
    q, dq, ddq = robot.random_states(n, seed=0)
    rng = np.random.default_rng(1)
    v, w = rng.normal(size=(2, n, robot.nv))
    model, data = robot.model, robot.model.createData()
    ev = RegressorEvaluator(robot)
    out = np.zeros((robot.nv, robot.n_parameters))
    m = min(n, 5000)

    def floor():
        f = pin.computeJointTorqueRegressor
        for k in range(n):
            f(model, data, q[k], dq[k], ddq[k])

    def one_sample():
        for k in range(m):
            regressor(robot, q[k], dq[k], ddq[k])

    def one_sample_sl():
        for k in range(m):
            slotine_li_regressor(robot, q[k], dq[k], v[k], w[k])

    def hot():
        for k in range(n):
            ev.regressor(q[k], dq[k], ddq[k], out)

    def hot_sl():
        for k in range(n):
            ev.slotine_li(q[k], dq[k], v[k], w[k], out)

    def batched():
        for _ in iter_regressor(robot, q, dq, ddq):
            pass

    def batched_sl():
        for _ in iter_slotine_li_regressor(robot, q, dq, v, w):
            pass

    rows = {
        "pinocchio computeJointTorqueRegressor (floor)": best_of(floor, args.repeat, n),
        "regressor, one checked call per sample": best_of(one_sample, args.repeat, m),
        "slotine_li_regressor, one checked call per sample": best_of(one_sample_sl, args.repeat, m),
        "RegressorEvaluator.regressor (hot loop)": best_of(hot, args.repeat, n),
        "RegressorEvaluator.slotine_li (hot loop)": best_of(hot_sl, args.repeat, n),
        "iter_regressor over a trajectory": best_of(batched, args.repeat, n),
        "iter_slotine_li_regressor over a trajectory": best_of(batched_sl, args.repeat, n),
    }
    print(f"{robot!r}, {n} samples, best of {args.repeat}")
    for label, us in rows.items():
        print(f"  {label:52s} {us:7.2f} us/sample")
    if args.json:
        with open(args.json, "w") as fh:
            json.dump({"robot": robot.name, "samples": n, "us_per_sample": rows}, fh, indent=2)


if __name__ == "__main__":
    main()
