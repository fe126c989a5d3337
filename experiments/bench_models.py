"""Per-sample cost of the dynamic, momentum and energy models, side by side.

    python experiments/bench_models.py [--robot ur10] [--samples 200000] [--repeat 3]
                                       [--regressor auto]

Each model runs in its own child process on the same seeded random states of the robot
(viscous and Coulomb friction): the dynamic model accumulates ``Y(q, dq, ddq)`` into the
information sums (what ``identify`` does), the momentum and energy models run
:func:`manip_id.models.accumulate_momentum` / :func:`~manip_id.models.accumulate_energy`
at the default window. The child times its accumulation (imports and state generation
excluded) inside a run announced with ``planned_samples`` (so ``auto`` uses the
compiled kernel from the first block, as ``identify`` does); the parent records the
whole process's wall time. The models alternate in each repeat, and
the printed ratios are medians of the per-repeat ratios against the dynamic model
measured in the same repeat (the machine is shared).
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
MODELS = ("dynamic", "momentum", "energy")


def child(model: str, robot_name: str, n: int, regressor: str) -> None:
    """One model's accumulation over ``n`` samples; prints ``{"seconds": ...}``."""
    sys.path.insert(0, str(ROOT))
    from manip_id.estimators import InformationAccumulator
    from manip_id.models import accumulate_energy, accumulate_momentum
    from manip_id.robot import compiled_regressor as cr
    from manip_id.robot.model import load_robot
    from manip_id.robot.regressor import iter_regressor

    cr.set_mode(regressor)
    robot = load_robot(robot_name, friction=["viscous", "coulomb"])
    q, dq, ddq = robot.random_states(n, seed=0)
    tau = dq.copy()  # any finite torques: the cost does not depend on them
    dt = 0.002
    with cr.planned_samples(n):
        t0 = time.perf_counter()
        if model == "dynamic":
            acc = InformationAccumulator(robot.n_parameters, robot.nv)
            for c in iter_regressor(robot, q, dq, ddq):
                acc.add(c.Y, tau[c.start : c.stop], check=False)
        elif model == "momentum":
            acc = accumulate_momentum(robot, q, dq, tau, dt=dt)
        else:
            acc = accumulate_energy(robot, q, dq, tau, dt=dt)
        seconds = time.perf_counter() - t0
    print(json.dumps({"seconds": seconds, "rows": int(acc.n)}))


def measure(model: str, args) -> dict:
    """One child process: its in-process accumulation time and its wall time."""
    cmd = [sys.executable, __file__, "--child", model, "--robot", args.robot]
    cmd += ["--samples", str(args.samples), "--regressor", args.regressor]
    env = dict(os.environ, OPENBLAS_NUM_THREADS="1", PYTHONPATH=str(ROOT))
    t0 = time.perf_counter()
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, env=env)
    out, err = proc.communicate()
    wall = time.perf_counter() - t0
    if proc.returncode != 0:
        raise RuntimeError(f"{model} exited {proc.returncode}: {err.decode()[-400:]}")
    res = json.loads(out.decode().strip().splitlines()[-1])
    res["wall"] = wall
    return res


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--robot", default="ur10")
    ap.add_argument("--samples", type=int, default=200_000)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--regressor", default="auto", choices=("auto", "compiled", "pinocchio"))
    ap.add_argument("--child", choices=MODELS)
    args = ap.parse_args(argv)
    if args.child:
        child(args.child, args.robot, args.samples, args.regressor)
        return 0
    runs: dict[str, list[dict]] = {m: [] for m in MODELS}
    for _ in range(args.repeat):
        for m in MODELS:
            runs[m].append(measure(m, args))
    print(
        f"{args.robot}, {args.samples} samples, regressor {args.regressor}, "
        f"{args.repeat} repeats (medians; ratios per repeat against the dynamic model)"
    )
    print(f"{'model':<10}{'us/sample':>11}{'x dynamic':>11}{'process s':>11}{'rows':>10}")
    for m in MODELS:
        per = [r["seconds"] / args.samples * 1e6 for r in runs[m]]
        ratio = [a["seconds"] / b["seconds"] for a, b in zip(runs[m], runs["dynamic"], strict=True)]
        wall = statistics.median(r["wall"] for r in runs[m])
        print(
            f"{m:<10}{statistics.median(per):>11.2f}{statistics.median(ratio):>11.2f}"
            f"{wall:>11.2f}{runs[m][0]['rows']:>10}"
        )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
