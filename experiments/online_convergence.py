"""Online laws on the panda: convergence to the batch estimate, and the cost of one step.

A persistently exciting trajectory: a finite Fourier series (5 harmonics, period
10 s, random coefficients of modest amplitude) around ``robot.neutral()``,
sampled at ``--rate`` Hz for ``--duration`` seconds; torques from
``pinocchio.rnea`` with the nominal parameters (plus optional white noise).
The batch estimate (streamed OLS on the base parameters) is the reference;
each law starts from zero and sees one sample per step, its regressor
evaluated in the loop by :class:`manip_id.robot.regressor.RegressorEvaluator`:

- RLS, ``P0 = p0 I``, no forgetting;
- RLS with forgetting 0.999 (bounded: trace(P) <= trace(P0));
- the normalized gradient law, ``Gamma = gamma I``, Euler step ``dt = 1/rate``;
- the same law with Euler step ``--step`` (default 1) per sample: the discrete
  normalized LMS, which the normalization keeps stable for steps below 2.

Reported: the time at which ``||theta_hat - theta_batch|| / ||theta_batch||``
falls below 1 % for good, the final distance, and microseconds per step (law
alone and with the regressor).

Run: ``.venv/bin/python experiments/online_convergence.py [--duration 120] [--json OUT]``
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
from manip_id.estimators import GradientEstimator, RLSEstimator  # noqa: E402
from manip_id.identifiability import analyze  # noqa: E402
from manip_id.identification import identify  # noqa: E402
from manip_id.robot.regressor import RegressorEvaluator  # noqa: E402
from manip_id.trajectories import FourierTrajectory  # noqa: E402


def time_below(history, reference, threshold=0.01):
    """First recorded time after which the relative distance to ``reference`` stays below."""
    rel = np.linalg.norm(history.theta - reference, axis=1) / np.linalg.norm(reference)
    above = np.nonzero(rel > threshold)[0]
    if above.size == 0:
        return float(history.t[0]), rel
    if above[-1] == rel.size - 1:
        return None, rel
    return float(history.t[above[-1] + 1]), rel


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--robot", default="panda")
    ap.add_argument("--duration", type=float, default=120.0, help="[s]")
    ap.add_argument("--rate", type=float, default=100.0, help="[Hz]")
    ap.add_argument("--noise", type=float, default=0.0, help="torque noise std [N m]")
    ap.add_argument("--p0", type=float, default=1e4)
    ap.add_argument("--gamma", type=float, default=1.0)
    ap.add_argument(
        "--step",
        type=float,
        default=1.0,
        help="Euler step of the discrete-time variant of the normalized law",
    )
    ap.add_argument("--seed", type=int, default=7)
    ap.add_argument("--json", metavar="OUT")
    args = ap.parse_args(argv)

    robot = load_robot(args.robot)
    rng = np.random.default_rng(args.seed)
    L = 5
    traj = FourierTrajectory(
        robot.neutral(),
        rng.normal(0, 0.25, (robot.nv, L)),
        rng.normal(0, 0.25, (robot.nv, L)),
        wf=2 * np.pi / 10,
    )
    dt = 1.0 / args.rate
    t = np.arange(0.0, args.duration, dt)
    q, dq, ddq = traj.sample(t)
    data = robot.model.createData()
    tau = np.array([pin.rnea(robot.model, data, q[k], dq[k], ddq[k]) for k in range(t.size)])
    tau += args.noise * rng.standard_normal(tau.shape)

    base = analyze(robot).base
    batch = identify(robot, (q, dq, ddq, tau), base=base)
    ref = batch.estimate
    r = base.n_base
    print(
        f"{robot.name}: {r} base parameters, {t.size} samples over {args.duration:g} s, "
        f"condition number {batch.condition_number:.1f}, batch relative error "
        f"{batch.relative_error.train:.2e}"
    )

    every = max(1, round(0.05 / dt))
    laws = {
        "rls": RLSEstimator(np.zeros(r), args.p0, record_every=every),
        "rls-forgetting-0.999": RLSEstimator(
            np.zeros(r), args.p0, forgetting=0.999, record_every=every
        ),
        "normalized-gradient": GradientEstimator(
            np.zeros(r), args.gamma, normalized=True, record_every=every
        ),
        f"normalized-gradient-step-{args.step:g}": GradientEstimator(
            np.zeros(r), args.gamma, normalized=True, record_every=every
        ),
    }
    steps = {name: dt for name in laws}
    steps[f"normalized-gradient-step-{args.step:g}"] = args.step
    ev = RegressorEvaluator(robot)
    ind = base.independent
    Y = np.zeros((robot.nv, robot.n_parameters))
    out = {
        "robot": robot.name,
        "n_base": r,
        "samples": int(t.size),
        "duration": args.duration,
        "rate": args.rate,
        "noise": args.noise,
        "laws": {},
    }
    for name, law in laws.items():
        # the law alone, on precomputed base regressors
        t_law = t_reg = 0.0
        h = steps[name]
        for k in range(t.size):
            t0 = time.perf_counter()
            ev.regressor(q[k], dq[k], ddq[k], out=Y)
            Yb = Y[:, ind]
            t1 = time.perf_counter()
            law.step(Yb, tau[k], h)
            t2 = time.perf_counter()
            t_reg += t1 - t0
            t_law += t2 - t1
        t_conv, rel = time_below(law.history, ref)
        if t_conv is not None:
            t_conv *= dt / h  # the law's clock ran at h per sample
        us_law = 1e6 * t_law / t.size
        us_all = 1e6 * (t_law + t_reg) / t.size
        conv = "not within the run" if t_conv is None else f"{t_conv:.2f} s"
        print(
            f"{name:22s} 1% of batch at {conv:>20s}; final distance {rel[-1]:.2e}; "
            f"{us_law:.1f} us/step (law), {us_all:.1f} us/step with regressor + gather"
        )
        out["laws"][name] = {
            "time_to_1pct": t_conv,
            "final_relative_distance": float(rel[-1]),
            "us_per_step_law": us_law,
            "us_per_step_with_regressor": us_all,
        }
    if args.json:
        write_json(args.json, out)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
