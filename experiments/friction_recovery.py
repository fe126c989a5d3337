"""Recovery of each friction law on a simulated double pendulum, and the choice among them.

The torques are Pinocchio's ``rnea`` (nominal inertias) plus one law written out here
in numpy, with ``--noise`` relative torque noise; training 40 s and validation 20 s of
two different multisine trajectories at 200 Hz. For each law: the largest error of its
coefficients relative to the largest coefficient, the shape found by variable
projection (Stribeck ``vs``, sigmoid slope ``a``), the validation error, and the model
``select_model`` chooses per joint among all candidates.

Run: ``.venv/bin/python experiments/friction_recovery.py [--noise 0.003] [--json OUT]``
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
from manip_id.identification import identify  # noqa: E402
from manip_id.identification.selection import (  # noqa: E402
    SelectionOptions,
    candidate_terms,
    select_model,
)
from manip_id.trajectories import random_trajectory  # noqa: E402

RATE = 200.0  # [Hz]
VS, SLOPE = np.array([0.06, 0.15]), np.array([30.0, 12.0])  # [rad/s], [s/rad]
FV, FC, FO = np.array([0.3, 0.2]), np.array([0.8, 0.5]), np.array([0.1, -0.2])


def law_torque(law: str, q, dq, rigid) -> tuple[np.ndarray, dict]:
    """One law's torque [N m], (N, 2), and its true coefficients by parameter name."""
    s = np.sign(dq)
    base, coef = FV * dq + FO, {"fv": FV, "fo": FO}
    if law == "asymmetric":
        fvp, fvn = np.array([0.4, 0.2]), np.array([0.25, 0.35])
        return FO + np.where(dq > 0, fvp * dq, fvn * dq) + FC * s, {
            "fvp": fvp, "fvn": fvn, "fc": FC, "fo": FO,
        }  # fmt: skip
    if law == "stribeck":
        fs = np.array([1.4, 0.9])
        return base + (FC + (fs - FC) * np.exp(-((dq / VS) ** 2))) * s, {
            **coef, "fc": FC, "fs": fs - FC,
        }  # fmt: skip
    if law == "sigmoid":
        phi1 = np.array([1.5, 1.0])
        return base + phi1 * (1 / (1 + np.exp(-SLOPE * dq)) - 0.5), {**coef, "fsg": phi1}
    if law == "position":
        h1s, h2s = np.array([0.3, -0.2]), np.array([-0.15, 0.1])
        return base + FC * s + h1s * np.sin(q) + h2s * np.sin(2 * q), {
            **coef, "fc": FC, "h1s": h1s, "h2s": h2s,
        }  # fmt: skip
    if law == "load":
        fl = np.array([0.08, 0.05])
        return base + FC * s + fl * np.abs(rigid) * s, {**coef, "fc": FC, "fl": fl}
    return base + FC * s, {**coef, "fc": FC}


def data(robot, law: str, seed: int, duration: float, noise: float):
    traj = random_trajectory(robot, harmonics=5, wf=0.3, seed=seed)
    q, dq, ddq = traj.sample(np.arange(int(duration * RATE)) / RATE)
    m, d = robot.model, robot.model.createData()
    rigid = np.array([pin.rnea(m, d, a, b, c) for a, b, c in zip(q, dq, ddq, strict=True)])
    fr, coef = law_torque(law, q, dq, rigid)
    tau = rigid + fr
    rng = np.random.default_rng(seed + 100)
    tau = tau + noise * np.sqrt(np.mean(tau**2, axis=0)) * rng.standard_normal(tau.shape)
    return (q, dq, ddq, tau), coef


def coefficient_error(res, robot, coef) -> float:
    """Largest |estimate - truth| over the laws' parameters that are base parameters of
    their own, relative to the largest true coefficient."""
    worst, scale = 0.0, max(np.abs(v).max() for v in coef.values())
    for name, true in coef.items():
        for j, dof in enumerate(robot.dof_names):
            full = f"{dof}.{name}"
            if full in res.names:
                worst = max(worst, abs(res.estimate[res.names.index(full)] - true[j]))
    return worst / scale


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--noise", type=float, default=0.003, help="relative torque noise")
    ap.add_argument("--json", metavar="OUT", help="write the figures as JSON")
    args = ap.parse_args(argv)
    robot = load_robot("double_pendulum", friction=())
    rows = []
    for law in ("linear", "asymmetric", "position", "load", "stribeck", "sigmoid"):
        train, coef = data(robot, law, 1, 40.0, args.noise)
        valid, _ = data(robot, law, 2, 20.0, args.noise)

        def fit(r, train=train, valid=valid):
            return identify(r, tuple(train), validation=valid)

        row: dict = {"law": law}
        if law in ("stribeck", "sigmoid"):
            opts = SelectionOptions(candidates=(law,), combine=False)
            res, sel = select_model(fit, robot, opts)
            key = "vs" if law == "stribeck" else "slope"
            row["shape"] = [j.candidates[0].parameters[key] for j in sel.joints]
            row["true_shape"] = (VS if law == "stribeck" else SLOPE).tolist()
            r = robot.with_terms(sel.terms)
        else:
            r = robot.with_terms(candidate_terms(robot.terms, law, SelectionOptions()))
            res = fit(r)
        row["coefficient_error"] = coefficient_error(res, r, coef)
        row["validation_error"] = float(res.relative_error.validation)
        _, chosen = select_model(fit, robot, SelectionOptions(combine=False))
        row["chosen"] = [j.chosen for j in chosen.joints]
        rows.append(row)
        shape = (
            f", shape {np.round(row['shape'], 4).tolist()} (true {row['true_shape']})"
            if "shape" in row
            else ""
        )
        print(
            f"{law:10s} coefficients within {100 * row['coefficient_error']:.2f} % of the "
            f"largest, validation {100 * row['validation_error']:.3f} %{shape}; "
            f"chosen {row['chosen']}"
        )
    if args.json:
        Path(args.json).write_text(json.dumps(rows, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
