"""Monte Carlo check of the predicted uncertainty of least squares on simulated manipulators.

For each robot: fixed random states within the limits, exact torques from
``pinocchio.rnea`` (inertias and armature) plus viscous friction, then ``--runs``
draws of white torque noise, each identified with :func:`manip_id.identification.identify`.
Per base parameter we compare the predicted standard deviation (mean over
runs of ``sqrt(diag(covariance))``) with the empirical one (spread of the
estimates over the runs).

- OLS with the same noise level on every joint (its assumption);
- WLS with a different level per joint (``sigma_j`` from 0.2 to 1 N m);
- OLS on that heteroscedastic noise, to show why WLS is needed: its single
  ``sigma^2`` mis-states the uncertainty.

With R runs the empirical std itself scatters by about ``1/sqrt(2(R-1))``
(10 % for R = 50), so a ratio within 20 % is a 2-sigma statement per
parameter at R = 50; use ``--runs 200`` for a sharper one.

Run: ``.venv/bin/python experiments/monte_carlo.py [--runs 50] [--samples 1000] [--json OUT]``
"""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # small matrices: threads only cost

import argparse  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402
import pinocchio as pin  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from manip_id import load_robot  # noqa: E402
from manip_id.cli._common import write_json  # noqa: E402
from manip_id.identifiability import analyze  # noqa: E402
from manip_id.identification import identify  # noqa: E402


def simulate(robot, theta, q, dq, ddq) -> np.ndarray:
    """Exact torques: rnea with the inertias/armature of theta, plus fv dq."""
    model = robot.with_parameters(theta)
    data = model.createData()
    tau = np.array([pin.rnea(model, data, q[k], dq[k], ddq[k]) for k in range(q.shape[0])])
    names = robot.parameter_names
    fv = np.array([theta[names.index(f"{d}.fv")] for d in robot.dof_names])
    return tau + fv * dq


def campaign(robot, base, states, tau0, sig, method, runs, rng):
    est, std = [], []
    for _ in range(runs):
        tau = tau0 + sig * rng.standard_normal(tau0.shape)
        res = identify(robot, *states, tau, method=method, base=base)
        est.append(res.estimate)
        std.append(res.std)
    est, std = np.array(est), np.array(std)
    ratio = std.mean(axis=0) / est.std(axis=0, ddof=1)
    return ratio, est


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--robots", default="panda,ur5")
    ap.add_argument("--runs", type=int, default=50)
    ap.add_argument("--samples", type=int, default=1000)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--json", metavar="OUT")
    args = ap.parse_args(argv)
    rng = np.random.default_rng(args.seed)
    out = {"runs": args.runs, "samples": args.samples, "robots": {}}
    print(
        f"{args.runs} runs, {args.samples} random states; ratio = predicted std / empirical std "
        f"(sampling scatter of the empirical std ~ {1 / np.sqrt(2 * (args.runs - 1)):.0%})"
    )
    for name in args.robots.split(","):
        robot = load_robot(name, armature=True, friction="viscous")
        theta = robot.nominal_parameters.copy()
        theta[robot.n_rigid :] = rng.uniform(0.05, 0.5, robot.n_parameters - robot.n_rigid)
        base = analyze(robot).base
        states = robot.random_states(args.samples, seed=args.seed + 1)
        tau0 = simulate(robot, theta, *states)
        hetero = np.linspace(0.2, 1.0, robot.nv)
        cases = [("ols", np.full(robot.nv, 0.5)), ("wls", hetero), ("ols-heteroscedastic", hetero)]
        out["robots"][name] = {}
        for label, sig in cases:
            t0 = time.perf_counter()
            ratio, est = campaign(robot, base, states, tau0, sig, label[:3], args.runs, rng)
            bias = np.abs(est.mean(axis=0) - base.to_base(theta)) / (
                est.std(axis=0, ddof=1) / np.sqrt(args.runs)
            )
            within = float(np.mean(np.abs(ratio - 1) <= 0.2))
            line = (
                f"{name:6s} {label:20s} r={base.n_base:3d}  ratio min {ratio.min():.3f} "
                f"median {np.median(ratio):.3f} max {ratio.max():.3f}  within 20%: "
                f"{within:.0%}  max |bias|/se {bias.max():.2f}  "
                f"({time.perf_counter() - t0:.1f} s)"
            )
            print(line)
            out["robots"][name][label] = {
                "noise_std_per_joint": sig,
                "ratio": ratio,
                "fraction_within_20pct": within,
                "ratio_median": float(np.median(ratio)),
                "max_bias_over_se": float(bias.max()),
            }
    if args.json:
        write_json(args.json, out)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
