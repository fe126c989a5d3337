"""Throughput of the streamed identification pipeline and of the accumulator.

Random states of the panda (armature and viscous friction), torques from the
regressor and the nominal parameters (this benchmark measures speed, not
accuracy), ``--samples`` of them. Prints the seconds per stage of
:func:`manip_id.identification.identify` and the accumulator's cost per sample.

Run: ``.venv/bin/python experiments/bench_identification.py [--samples 100000]``
"""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # small matrices: threads only cost

import argparse  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
import tracemalloc  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from manip_id import load_robot  # noqa: E402
from manip_id.estimators import InformationAccumulator  # noqa: E402
from manip_id.identifiability import analyze  # noqa: E402
from manip_id.identification import (
    RunOptions,
    identify,  # noqa: E402
)
from manip_id.robot.regressor import iter_regressor  # noqa: E402


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--robot", default="panda")
    ap.add_argument("--samples", type=int, default=100_000)
    ap.add_argument("--chunk", type=int, default=1024)
    args = ap.parse_args(argv)
    robot = load_robot(args.robot, armature=True, friction="viscous")
    q, dq, ddq = robot.random_states(args.samples, seed=0)
    tau = np.empty((args.samples, robot.nv))
    for c in iter_regressor(robot, q, dq, ddq, chunk=args.chunk):
        tau[c.start : c.stop] = c.Y @ robot.nominal_parameters
    base = analyze(robot).base

    tracemalloc.start()
    t0 = time.perf_counter()
    res = identify(robot, (q, dq, ddq, tau), base=base, run=RunOptions(chunk=args.chunk))
    wall = time.perf_counter() - t0
    _, peak = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    print(
        f"identify {robot.name}: {args.samples} samples, r={base.n_base}, chunk {args.chunk}: "
        f"{wall:.2f} s, peak traced memory {peak / 2**20:.1f} MiB "
        f"(inputs {(q.nbytes + dq.nbytes + ddq.nbytes + tau.nbytes) / 2**20:.1f} MiB)"
    )
    for k, v in res.timings.items():
        print(f"  {k:20s} {v:8.3f} s  ({1e6 * v / args.samples:6.2f} us/sample)")

    Yb = np.random.default_rng(1).standard_normal((args.chunk, robot.nv, base.n_base))
    tb = np.random.default_rng(2).standard_normal((args.chunk, robot.nv))
    acc = InformationAccumulator(base.n_base, robot.nv)
    reps = max(1, args.samples // args.chunk)
    t0 = time.perf_counter()
    for _ in range(reps):
        acc.add(Yb, tb, check=False)
    dt = time.perf_counter() - t0
    print(
        f"InformationAccumulator.add: {1e6 * dt / (reps * args.chunk):.2f} us/sample "
        f"(nv={robot.nv}, r={base.n_base}, chunks of {args.chunk})"
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
