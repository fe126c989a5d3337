"""Simulated payload and drive-gain recovery: estimates against the truth, with standard deviations.

A ur5 (default; ``--robot``, ``--frame``) follows two random Fourier excitations
within its limits (``random_trajectory``, 5 harmonics), one without and one with a
payload at ``tool0``. The torques come from ``pinocchio.rnea`` of the plain model and
of the model whose wrist inertia carries the payload (``inertias[j] +=
placement.act(payload)``); nothing of manip_id computes them.

1. Payload: ``--runs`` draws of white torque noise (``--noise``, relative to each
   joint's RMS torque), each identified by :func:`manip_id.payload.identify_payload`
   (OLS, joint fit with the unloaded run). Per quantity: truth, mean estimate, the
   mean predicted std (delta method) and the empirical std over the runs, and the
   bias in predicted std.
2. Drive gains: the same motions logged as currents ``i_j = tau_j / g_j`` plus white
   current noise (``--current-noise`` [A]), estimated with the known payload mass by
   each method (ML, OLS, TLS): truth, mean, predicted and empirical std, bias in std.

With R runs the empirical std scatters by about ``1/sqrt(2(R-1))`` (16 % at R = 20).

Run: ``.venv/bin/python experiments/payload.py [--runs 20] [--duration 20] [--rate 100]``
"""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import argparse  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
import warnings  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402
import pinocchio as pin  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from manip_id import load_robot  # noqa: E402
from manip_id.identifiability import analyze  # noqa: E402
from manip_id.payload import (  # noqa: E402
    QUANTITY_NAMES,
    QUANTITY_UNITS,
    PayloadWarning,
    identify_drive_gains,
    identify_payload,
    payload_frame,
)
from manip_id.trajectories import random_trajectory, trajectory_to_configuration  # noqa: E402

SYM6 = ((0, 0), (0, 1), (1, 1), (0, 2), (1, 2), (2, 2))


def motion(robot, seed: int, duration: float, rate: float):
    traj = random_trajectory(robot, harmonics=5, seed=seed)
    t = np.arange(int(duration * rate) + 1) / rate
    angles, dq, ddq = traj.sample(t)
    return trajectory_to_configuration(robot, angles), dq, ddq


def torques(model, q, dq, ddq) -> np.ndarray:
    data = model.createData()
    return np.array([pin.rnea(model, data, q[k], dq[k], ddq[k]) for k in range(q.shape[0])])


def row(name, unit, true, est, pred):
    est = np.asarray(est, dtype=float)
    mean, emp = float(np.mean(est)), float(np.std(est, ddof=1))
    p = float(np.mean(pred))
    bias = (mean - true) / (p / np.sqrt(len(est))) if p > 0 else float("nan")
    return (
        f"  {name:<20} {unit:<7} {true:12.6g} {mean:12.6g} {p:10.3g} {emp:10.3g} "
        f"{emp / p if p > 0 else float('nan'):7.2f} {bias:8.2f}"
    )


HEADER = (
    f"  {'quantity':<20} {'unit':<7} {'truth':>12} {'mean':>12} {'pred std':>10} "
    f"{'emp std':>10} {'emp/pred':>7} {'bias/se':>8}"
)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--robot", default="ur5")
    ap.add_argument("--frame", default="tool0")
    ap.add_argument("--runs", type=int, default=20)
    ap.add_argument("--duration", type=float, default=20.0, help="seconds per motion")
    ap.add_argument("--rate", type=float, default=100.0, help="samples per second")
    ap.add_argument("--noise", type=float, default=0.01, help="torque noise / RMS torque")
    ap.add_argument("--current-noise", type=float, default=0.02, help="current noise [A]")
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args(argv)

    robot = load_robot(args.robot)
    pf = payload_frame(robot, args.frame)
    rot = pin.utils.rotate("z", 0.4) @ pin.utils.rotate("x", -0.3)
    payload = pin.Inertia(
        1.3, np.array([0.02, -0.03, 0.08]), rot @ np.diag([0.01, 0.012, 0.006]) @ rot.T
    )
    truth = np.r_[payload.mass, payload.lever, [payload.inertia[a, b] for a, b in SYM6]]
    m0 = robot.model.copy()
    m0.armature[:] = 0.0
    m1 = m0.copy()
    m1.inertias[pf.joint_id] = m1.inertias[pf.joint_id] + pf.placement.act(payload)
    su = motion(robot, args.seed, args.duration, args.rate)
    sl = motion(robot, args.seed + 1, args.duration, args.rate)
    tu, tl = torques(m0, *su), torques(m1, *sl)
    base = analyze(robot).base
    rng = np.random.default_rng(args.seed + 100)
    n = su[0].shape[0]
    print(
        f"{robot.name}, payload at {args.frame} (on {pf.joint_name}): {n} unloaded + {n} loaded "
        f"samples ({args.duration:g} s at {args.rate:g} Hz each), {args.runs} noise draws"
    )

    # ---------------------------------------------------------------- payload
    sig_u = args.noise * np.sqrt(np.mean(tu**2, axis=0))
    sig_l = args.noise * np.sqrt(np.mean(tl**2, axis=0))
    draws = [
        (
            tu + sig_u * rng.standard_normal(tu.shape),
            tl + sig_l * rng.standard_normal(tl.shape),
        )
        for _ in range(args.runs)
    ]
    for method in ("ols", "wls"):
        est, std = [], []
        t0 = time.perf_counter()
        for nu, nl in draws:
            p = identify_payload(robot, (*su, nu), (*sl, nl), args.frame, method=method, base=base)
            est.append(p.payload.values)
            std.append(p.payload.std)
        dt = (time.perf_counter() - t0) / args.runs
        est, std = np.array(est), np.array(std)
        print(
            f"\npayload ({method.upper()}, torque noise {100 * args.noise:g} % of each joint's "
            f"RMS; {dt:.2f} s per identification):"
        )
        print(HEADER)
        for i, (name, unit) in enumerate(zip(QUANTITY_NAMES, QUANTITY_UNITS, strict=True)):
            print(row(name, unit, truth[i], est[:, i], std[:, i]))

    # ------------------------------------------------------------ drive gains
    gains = np.linspace(0.45, 2.3, robot.nv)  # [N m / A]
    iu, il = tu / gains, tl / gains
    print(
        f"\ndrive gains (known mass {payload.mass:g} kg, current noise {args.current_noise:g} A; "
        "RMS currents unloaded: "
        + ", ".join(f"{v:.3g}" for v in np.sqrt(np.mean(iu**2, axis=0)))
        + " A):"
    )
    draws = [
        (
            iu + args.current_noise * rng.standard_normal(iu.shape),
            il + args.current_noise * rng.standard_normal(il.shape),
        )
        for _ in range(args.runs)
    ]
    for method in ("ml", "ols", "tls"):
        est, std = [], []
        t0 = time.perf_counter()
        for cu, cl in draws:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", PayloadWarning)
                res = identify_drive_gains(
                    robot, (*su, cu), (*sl, cl), args.frame, payload.mass, method=method, base=base
                )
            est.append(res.gains)
            std.append(res.gains_std)
        dt = (time.perf_counter() - t0) / args.runs
        est, std = np.array(est), np.array(std)
        print(f" {method.upper()} ({dt:.2f} s per estimate):")
        print(HEADER)
        for j, name in enumerate(robot.dof_names):
            print(row(name, "N m/A", gains[j], est[:, j], std[:, j]))
    return 0


if __name__ == "__main__":
    sys.exit(main())
