"""Designed vs random excitation: information, identified std, design time (ur5, panda).

For each robot: ``design_excitation`` (20 s, 5 harmonics, D-optimal, torque limits, self-
collision and a table plane 1 cm under the base) against random trajectories of the same
family within the same limits, torques and clearance (one random start of the design, no
refinement, the same final check), and, beside, classical random Fourier trajectories
within the joint limits only (``random_trajectory``: they may cross the table and the
torque limits, so they are not an alternative a user could run). Each motion is simulated
(nominal parameters, 1 % torque noise relative to each joint's RMS torque, 200 Hz) and
identified (OLS on the structural base); the figures are the D criterion of the motion
(``-log det F``, same weights), the geometric mean and the worst relative std of the base
parameters (std / |nominal base value|, over the parameters whose nominal value is not
about zero) and the design time. The ratio designed / random median is measured in the
same run.

Sequential (``--sequential``): a poor 10 s log (three joints moving) gives the prior
information (its regressor information with its noise, plus a weak prior of 100 % of each
nominal value: alone it is rank-deficient); a 10 s design from that prior is compared with
a random 10 s addition: predicted worst relative std of the parameters the prior left above
10 %, and realized (OLS on the poor log plus the addition: its std and its error).

Run: ``.venv/bin/python experiments/excite_benchmark.py [--robots ur5,panda] [--random 5]
[--sequential | --sequential-only] [--json OUT]``
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from manip_id import identify, load_robot  # noqa: E402
from manip_id.identifiability import analyze  # noqa: E402
from manip_id.simulation import MeasurementNoise, simulate  # noqa: E402
from manip_id.trajectories import (  # noqa: E402
    DesignOptions,
    PriorInformation,
    World,
    design_excitation,
    random_trajectory,
)
from manip_id.trajectories.information import InformationModel, criterion_value  # noqa: E402

STARTS = {"ur5": [0.0, -1.57, 1.2, -1.2, -1.57, 0.0], "panda": None}
TABLE = World.from_dict({"plane": [{"normal": [0, 0, 1], "offset": -0.01}]})
RATE = 200.0  # [Hz] of the simulated logs


def _identified(robot, base, traj, duration: float, seed: int):
    sim = simulate(robot, traj, duration=duration, rate=RATE, noise=MeasurementNoise(tau=0.01),
                   seed=seed)  # fmt: skip
    d = sim.dataset
    return sim, identify(robot, (d.q, d.dq, d.ddq, d.tau), base=base, method="ols")


def _relative(result, reference: np.ndarray, keep: np.ndarray) -> np.ndarray:
    return np.asarray(result.std, float)[keep] / np.abs(reference[keep])


def _d_criterion(robot, base, traj, duration: float) -> float:
    info = InformationModel(robot, base, 0.01 * robot.effort_limit)
    t = np.arange(int(duration * 20)) / 20.0
    W = info.matrix(*traj.sample(t))
    return criterion_value(info.information(W, RATE / 20.0), "d")[0]


def _figures(robot, base, traj, ref, keep) -> dict:
    _, r = _identified(robot, base, traj, 20.0, seed=1)
    rel = _relative(r, ref, keep)
    return {
        "criterion": _d_criterion(robot, base.independent, traj, 20.0),
        "gmean_rel_std": float(np.exp(np.mean(np.log(rel)))),
        "worst_rel_std": float(rel.max()),
    }


def information_benchmark(name: str, n_random: int) -> dict:
    robot = load_robot(name)
    an = analyze(robot, seed=0)
    base = an.base
    theta = robot.nominal_parameters
    ref = theta[base.independent] + base.K @ theta[base.dependent]
    keep = np.abs(ref) > 1e-3 * np.abs(ref).max()
    start = None if STARTS[name] is None else np.array(STARTS[name])
    t0 = time.perf_counter()
    design = design_excitation(robot, 20.0, options=DesignOptions(start=start), world=TABLE)
    wall = time.perf_counter() - t0
    _, res = _identified(robot, base, design.trajectory, 20.0, seed=1)
    rel_d = _relative(res, ref, keep)
    rows, unsafe = [], []
    for s in range(n_random):
        # a random member of the same family within the same limits, torques and clearance:
        # one random start, no refinement (and the same final check)
        opts = DesignOptions(start=start, starts=1, refine=0, seed=100 + s)
        traj = design_excitation(robot, 20.0, options=opts, world=TABLE).trajectory
        rows.append(_figures(robot, base, traj, ref, keep))
        # and a classical random Fourier trajectory (joint limits only: it may hit the table)
        traj = random_trajectory(robot, 5, 2 * math.pi / 20.0, seed=100 + s)
        unsafe.append(_figures(robot, base, traj, ref, keep))
    med = {k: float(np.median([r[k] for r in rows])) for k in rows[0]}
    med_unsafe = {k: float(np.median([r[k] for r in unsafe])) for k in unsafe[0]}
    out = {
        "robot": name,
        "design_time": design.design_time,
        "design_wall": wall,
        "designed": {
            "criterion": _d_criterion(robot, base.independent, design.trajectory, 20.0),
            "gmean_rel_std": float(np.exp(np.mean(np.log(rel_d)))),
            "worst_rel_std": float(rel_d.max()),
            "min_clearance": design.check.min_clearance,
            "max_usage": design.check.max_usage(),
        },
        "random_median": med,
        "random": rows,
        "joint_limits_only_random_median": med_unsafe,
    }
    out["gmean_ratio"] = out["designed"]["gmean_rel_std"] / med["gmean_rel_std"]
    out["worst_ratio"] = out["designed"]["worst_rel_std"] / med["worst_rel_std"]
    return out


def sequential_benchmark(name: str) -> dict:
    robot = load_robot(name)
    an = analyze(robot, seed=0)
    base = an.base
    theta = robot.nominal_parameters
    ref = theta[base.independent] + base.K @ theta[base.dependent]
    start = None if STARTS[name] is None else np.array(STARTS[name])
    opts = DesignOptions(start=start, starts=1, refine=0, seed=5)  # a random safe motion
    full = design_excitation(robot, 10.0, options=opts, world=TABLE).trajectory
    still = np.arange(robot.nv) >= 3  # three joints moving, the others still at rest
    q0 = np.where(still, full.sample(0.0)[0], full.q0)
    a, b = full.a.copy(), full.b.copy()
    a[still], b[still] = 0.0, 0.0
    poor_traj = type(full)(q0, a, b, full.wf)
    # the poor log is rank-deficient on its own (four joints still), so its "result" is its
    # information plus a weak prior (std = 100 % of each nominal value, at least 1e-3)
    sim0 = simulate(robot, poor_traj, duration=10.0, rate=RATE, noise=MeasurementNoise(tau=0.01))
    sigma = np.sqrt(np.mean((sim0.dataset.tau - sim0.tau_true) ** 2, axis=0))  # [N m] the noise
    info0 = InformationModel(robot, base.independent, sigma)
    W0 = info0.matrix(
        sim0.dataset.q, sim0.dataset.dq, sim0.dataset.ddq
    )  # angles = q for these robots
    F0 = info0.information(W0) + np.diag(1.0 / np.maximum(np.abs(ref), 1e-3) ** 2)
    cov0 = np.linalg.inv(F0)
    std0 = np.sqrt(np.diag(cov0))
    rel0 = std0 / np.maximum(np.abs(ref), 1e-12)
    keep = np.abs(ref) > 1e-3 * np.abs(ref).max()
    poor = np.flatnonzero(keep & (rel0 > 0.1))
    prior = PriorInformation(F0, base.independent, list(base.base_names), ref, sigma)
    t0 = time.perf_counter()
    design = design_excitation(robot, 10.0, options=DesignOptions(start=start), world=TABLE,
                               prior=prior)  # fmt: skip
    wall = time.perf_counter() - t0
    opts = DesignOptions(start=start, starts=1, refine=0, seed=11)
    rand = design_excitation(robot, 10.0, options=opts, world=TABLE).trajectory
    out = {"robot": name, "n_poor": int(poor.size), "design_wall": wall,
           "prior_worst_rel_std": float(rel0[poor].max())}  # fmt: skip
    for label, traj in (("designed", design.trajectory), ("random", rand)):
        sim = simulate(robot, traj, duration=10.0, rate=RATE, noise=MeasurementNoise(tau=0.01),
                       seed=3)  # fmt: skip
        W = info0.matrix(sim.dataset.q, sim.dataset.dq, sim.dataset.ddq)
        F = F0 + info0.information(W)
        pred = np.sqrt(np.diag(np.linalg.inv(F)))[poor] / np.abs(ref[poor])
        q = np.vstack([sim0.dataset.q, sim.dataset.q])
        dq, ddq = (
            np.vstack([sim0.dataset.dq, sim.dataset.dq]),
            np.vstack([sim0.dataset.ddq, sim.dataset.ddq]),
        )
        tau = np.vstack([sim0.dataset.tau, sim.dataset.tau])
        res = identify(robot, (q, dq, ddq, tau), base=base, method="ols")
        real = np.abs(np.asarray(res.estimate) - ref)[poor] / np.abs(ref[poor])
        out[label] = {
            "predicted_worst_rel_std": float(pred.max()),
            "realized_worst_rel_std": float((np.asarray(res.std)[poor] / np.abs(ref[poor])).max()),
            "worst_rel_error": float(real.max()),
        }
    return out


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--robots", default="ur5,panda")
    parser.add_argument("--random", type=int, default=5, help="random trajectories per robot")
    parser.add_argument("--sequential", action="store_true")
    parser.add_argument("--sequential-only", action="store_true", help="skip the information part")
    parser.add_argument("--json", default=None)
    args = parser.parse_args(argv)
    report = {"information": [], "sequential": []}
    args.sequential |= args.sequential_only
    for name in args.robots.split(","):
        if args.sequential_only:
            s = sequential_benchmark(name)
            report["sequential"].append(s)
            print(json.dumps(s), flush=True)
            continue
        r = information_benchmark(name, args.random)
        report["information"].append(r)
        d, m = r["designed"], r["random_median"]
        print(f"{name}: design {r['design_time']:.1f} s; D criterion {d['criterion']:.1f} vs "
              f"random median {m['criterion']:.1f}; geometric-mean rel std "
              f"{d['gmean_rel_std']:.3g} vs {m['gmean_rel_std']:.3g} (ratio "
              f"{r['gmean_ratio']:.2f}); worst rel std {d['worst_rel_std']:.3g} vs "
              f"{m['worst_rel_std']:.3g} (ratio {r['worst_ratio']:.2f}); min clearance "
              f"{d['min_clearance']:.3f} m", flush=True)  # fmt: skip
        if args.sequential:
            s = sequential_benchmark(name)
            report["sequential"].append(s)
            print(f"{name} sequential: {s['n_poor']} poorly identified (worst prior "
                  f"{s['prior_worst_rel_std']:.3g}); designed: predicted "
                  f"{s['designed']['predicted_worst_rel_std']:.3g}, realized "
                  f"{s['designed']['realized_worst_rel_std']:.3g}; random: predicted "
                  f"{s['random']['predicted_worst_rel_std']:.3g}, realized "
                  f"{s['random']['realized_worst_rel_std']:.3g}", flush=True)  # fmt: skip
    if args.json:
        Path(args.json).write_text(json.dumps(report, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
