"""Recovery of the temperature friction law on a simulated double pendulum.

The torques are Pinocchio's ``rnea`` (nominal inertias) plus the law written out here in
numpy, ``(fv0 + fv1 (T - Tref)) dq + (fc0 + fc1 (T - Tref)) sign(dq)`` with ``Tref = 35
degC``, the temperature drifting linearly from 25 to 45 degC over the record (joint 2
4 K warmer), ``--noise`` relative torque noise and 0.05 K temperature noise; 60 s at 200
Hz, the first 70 % for training, the hottest 30 % for validation. Printed per noise
level: each coefficient's error (``fv``, ``fc`` compared at the fit's reference T0, the
training mean), and the validation error of the temperature model against viscous +
Coulomb alone.

Run: ``.venv/bin/python experiments/temperature_recovery.py [--noise 0.003 0.01] [--json OUT]``
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np
import pinocchio as pin

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from manip_id import load_robot  # noqa: E402
from manip_id.datasets import Dataset  # noqa: E402
from manip_id.identification import identify  # noqa: E402
from manip_id.trajectories import random_trajectory  # noqa: E402

RATE, TREF = 200.0, 35.0  # [Hz], [degC]
FV0, FV1 = np.array([0.3, 0.2]), np.array([-0.006, -0.004])  # [N m s/rad], [N m s/(rad K)]
FC0, FC1 = np.array([0.8, 0.5]), np.array([-0.012, -0.008])  # [N m], [N m/K]
OFFSET = np.array([0.0, 4.0])  # [K]


def record(robot, noise: float, seed: int = 1, duration: float = 60.0) -> Dataset:
    traj = random_trajectory(robot, harmonics=5, wf=0.3, seed=seed)
    t = np.arange(int(duration * RATE)) / RATE
    q, dq, ddq = traj.sample(t)
    m, d = robot.model, robot.model.createData()
    tau = np.array([pin.rnea(m, d, a, b, c) for a, b, c in zip(q, dq, ddq, strict=True)])
    temp = 25.0 + 20.0 * t[:, None] / t[-1] + OFFSET
    tau = tau + (FV0 + FV1 * (temp - TREF)) * dq + (FC0 + FC1 * (temp - TREF)) * np.sign(dq)
    rng = np.random.default_rng(seed + 100)
    tau = tau + noise * np.sqrt(np.mean(tau**2, axis=0)) * rng.standard_normal(tau.shape)
    temp = temp + 0.05 * rng.standard_normal(temp.shape)
    return Dataset(t=t, q=q, dq=dq, ddq=ddq, tau=tau, temp=temp)


def one(noise: float) -> dict:
    robot = load_robot("double_pendulum", friction=())
    train, valid = record(robot, noise).split(0.7)
    hot = load_robot("double_pendulum", friction="viscous,coulomb,temperature")
    res = identify(hot, train, validation=valid)
    plain = identify(
        load_robot("double_pendulum", friction="viscous,coulomb"), train, validation=valid
    )
    t0 = np.array(res.context["friction_shapes"]["temperature_reference"])
    truth = {"fv": FV0 + FV1 * (t0 - TREF), "fc": FC0 + FC1 * (t0 - TREF), "fvt": FV1,
             "fct": FC1}  # fmt: skip
    out: dict = {"noise": noise, "T0": t0.tolist()}
    for name, true in truth.items():
        got = np.array([res.estimate[res.names.index(f"{d}.{name}")] for d in hot.dof_names])
        out[name] = {"true": true.tolist(), "got": got.tolist(), "error": (got - true).tolist()}
    out["validation_error"] = {
        "temperature": float(res.relative_error.validation),
        "viscous_coulomb": float(plain.relative_error.validation),
    }
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--noise", type=float, nargs="+", default=[0.003, 0.01])
    ap.add_argument("--json", default=None)
    args = ap.parse_args()
    rows = [one(n) for n in args.noise]
    for r in rows:
        print(f"noise {100 * r['noise']:.1f} %, T0 = {r['T0'][0]:.2f}, {r['T0'][1]:.2f} degC")
        for name in ("fv", "fc", "fvt", "fct"):
            e = r[name]
            print(
                f"  {name:4s} true {np.round(e['true'], 5)} got {np.round(e['got'], 5)} "
                f"error {np.round(e['error'], 6)}"
            )
        v = r["validation_error"]
        print(
            f"  validation error: temperature {100 * v['temperature']:.3f} %, "
            f"viscous+coulomb {100 * v['viscous_coulomb']:.3f} %"
        )
    if args.json:
        Path(args.json).write_text(json.dumps(rows, indent=2))


if __name__ == "__main__":
    main()
