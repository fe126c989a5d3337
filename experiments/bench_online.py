"""One online step on the panda, regressor included: median microseconds over many steps.

    python experiments/bench_online.py [--robot panda] [--steps 20000] [--json OUT]

Per step: the regressor Y(q, dq, ddq) of one sample (``RegressorEvaluator``, the
hot-loop path), its base columns, then one update of the law on the base
parameters: recursive least squares (``RLSEstimator``, block update of the
nv outputs) or the gradient law (``GradientEstimator``, plain and normalized).
Each step is timed on its own with ``perf_counter_ns``; the median is robust to
the machine's other load. The regressor alone is timed the same way. The laws record
their history every 100 steps.
"""

from __future__ import annotations

import argparse
import json
import os
import time

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np  # noqa: E402

from manip_id import load_robot  # noqa: E402
from manip_id.estimators import GradientEstimator, RLSEstimator  # noqa: E402
from manip_id.identifiability import analyze  # noqa: E402
from manip_id.robot.regressor import RegressorEvaluator  # noqa: E402


def timed_steps(step, q, dq, ddq, tau) -> np.ndarray:
    """Time ``step(k)`` for every sample; returns microseconds per step."""
    out = np.empty(q.shape[0])
    clock = time.perf_counter_ns
    for k in range(q.shape[0]):
        t0 = clock()
        step(k)
        out[k] = (clock() - t0) * 1e-3
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--robot", default="panda")
    parser.add_argument("--steps", type=int, default=20000)
    parser.add_argument("--json", default=None)
    args = parser.parse_args()

    robot = load_robot(args.robot)
    base = analyze(robot).base
    ind = base.independent
    ev = RegressorEvaluator(robot)
    q, dq, ddq = robot.random_states(args.steps, seed=0)
    theta = base.to_base(robot.nominal_parameters)
    Y = np.zeros((robot.nv, robot.n_parameters))
    tau = np.stack(
        [ev.regressor(q[k], dq[k], ddq[k], Y)[:, ind] @ theta for k in range(args.steps)]
    )
    r = base.n_base
    laws = {
        "regressor only": None,
        "RLS (forgetting 0.999)": RLSEstimator(
            np.zeros(r), 1e3, forgetting=0.999, record_every=100
        ),
        "gradient law": GradientEstimator(np.zeros(r), 1e-3, record_every=100),
        "normalized gradient law": GradientEstimator(
            np.zeros(r), 1.0, normalized=True, record_every=100
        ),
    }
    rows = {}
    for label, law in laws.items():
        if law is None:

            def step(k):
                ev.regressor(q[k], dq[k], ddq[k], Y)

        else:
            update = law.step

            def step(k, update=update):
                update(ev.regressor(q[k], dq[k], ddq[k], Y)[:, ind], tau[k], 1e-3)

        us = timed_steps(step, q, dq, ddq, tau)
        rows[label] = {"median_us": float(np.median(us)), "p90_us": float(np.percentile(us, 90))}
    print(f"{robot!r}, {r} base parameters, {args.steps} steps; load {os.getloadavg()[0]:.2f}")
    print(f"  {'step (regressor included)':28s} {'median us':>10s} {'p90 us':>8s}")
    for label, row in rows.items():
        print(f"  {label:28s} {row['median_us']:10.1f} {row['p90_us']:8.1f}")
    if args.json:
        with open(args.json, "w") as fh:
            json.dump({"robot": robot.name, "n_base": r, "steps": rows}, fh, indent=2)


if __name__ == "__main__":
    main()
